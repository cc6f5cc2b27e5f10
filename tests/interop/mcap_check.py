#!/usr/bin/env python3
"""Independent check of drogue-vision MCAP logs with the Python `mcap` and
`mcap-protobuf-support` packages (not the Rust code that wrote them).

    mcap_check.py LOG.mcap [LOG.mcap ...]           complete, indexed logs
    mcap_check.py --cut LOG.mcap                    a log cut short by a crash
    mcap_check.py --require /camera/image,/tf LOG   other required topics
    mcap_check.py --compression zstd LOG            every chunk zstd (or lz4, none)
    mcap_check.py --metadata drogue_vision.run LOG  this metadata record is present

Every message of every topic is decoded: protobuf ones with their embedded
schema (which must be a foxglove.* schema), JSON ones with json; PNG frames
are inflated with Python's own zlib (chunk CRCs checked, size and filter
bytes of every row), JPEG frames (`image_encoding = "jpeg"`) decoded with
Pillow to an 8-bit gray image of the calibration's size, and the crop mode's
`/camera/crop` PNGs checked against `/camera/crop_info` (same size, inside
the frame). A complete log
must open through its summary/index and its message counts must match the
summary's statistics. A --cut log is streamed up to the cut. Exit status 0 only
if every check passed.
"""
import argparse
import json
import math
import struct
import sys
import zlib

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

DEFAULT_REQUIRED = [
    "/camera/image",
    "/camera/calibration",
    "/drogue/annotations",
    "/drogue/detection",
    "/drogue/pose",
    "/tf",
    "/log",
]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class Checker:
    def __init__(self, path):
        self.path = path
        self.failures = []
        self.counts = {}
        self.last_frame_time = {}
        self.image_size = None
        # seq -> (width, height) of /camera/crop and of /camera/crop_info.
        self.crop_sizes = {}
        self.crop_infos = {}
        self.decoders = {}
        self.factory = DecoderFactory()

    def fail(self, msg):
        if len(self.failures) < 20:
            print(f"FAIL {self.path}: {msg}", file=sys.stderr)
        self.failures.append(msg)

    def decoder(self, schema):
        key = schema.id
        if key not in self.decoders:
            self.decoders[key] = self.factory.decoder_for("protobuf", schema)
        return self.decoders[key]

    def check(self, schema, channel, message):
        topic = channel.topic
        self.counts[topic] = self.counts.get(topic, 0) + 1
        if channel.message_encoding == "protobuf":
            if schema is None or schema.encoding != "protobuf":
                return self.fail(f"{topic}: protobuf channel without a protobuf schema")
            if not schema.name.startswith("foxglove."):
                return self.fail(f"{topic}: schema {schema.name} is not a foxglove.* schema")
            decode = self.decoder(schema)
            if decode is None:
                return self.fail(f"{topic}: no decoder for {schema.name}")
            try:
                obj = decode(message.data)
            except Exception as e:  # noqa: BLE001 - any decode failure is a failure
                return self.fail(f"{topic}: cannot decode {schema.name}: {e}")
            self.check_content(topic, schema.name, obj, message)
        elif channel.message_encoding == "json":
            try:
                obj = json.loads(message.data)
            except ValueError as e:
                return self.fail(f"{topic}: invalid JSON: {e}")
            if not isinstance(obj, dict):
                self.fail(f"{topic}: JSON message is not an object")
            if topic == "/drogue/detection" and "detected" not in obj:
                self.fail(f"{topic}: no 'detected' field")
            if topic == "/camera/crop_info":
                x, y, w, h = (obj.get(k, -1) for k in ("x", "y", "width", "height"))
                iw, ih = obj.get("image_width", 0), obj.get("image_height", 0)
                if min(x, y) < 0 or min(w, h) < 1 or x + w > iw or y + h > ih:
                    self.fail(f"{topic}: crop {x},{y} {w}x{h} not inside {iw}x{ih}")
                self.crop_infos[message.sequence] = (w, h)
        else:
            self.fail(f"{topic}: unexpected message encoding {channel.message_encoding}")

    def check_content(self, topic, name, obj, message):
        if name == "foxglove.RawImage":
            if obj.encoding != "mono8" or len(obj.data) != obj.step * obj.height or obj.width < 1:
                self.fail(f"{topic}: bad RawImage {obj.width}x{obj.height} {obj.encoding}")
            self.frame_order(topic, message)
        elif name == "foxglove.CompressedImage":
            if obj.format == "jpeg" and topic == "/camera/image":
                problem, size = check_jpeg(bytes(obj.data))
                if problem:
                    self.fail(f"{topic}: JPEG: {problem}")
                elif self.image_size is not None and size != self.image_size:
                    self.fail(f"{topic}: JPEG {size}, calibration {self.image_size}")
            elif obj.format != "png" or not obj.data.startswith(PNG_SIGNATURE):
                self.fail(f"{topic}: CompressedImage is not PNG ({obj.format})")
            else:
                problem, size = check_png(bytes(obj.data))
                if problem:
                    self.fail(f"{topic}: PNG: {problem}")
                elif topic == "/camera/crop":
                    self.crop_sizes[message.sequence] = size
            self.frame_order(topic, message)
        elif name == "foxglove.CameraCalibration":
            if len(obj.K) != 9 or obj.K[0] <= 0 or obj.width < 1:
                self.fail(f"{topic}: bad CameraCalibration K={list(obj.K)}")
            self.image_size = (obj.width, obj.height)
        elif name == "foxglove.PoseInFrame":
            q = obj.pose.orientation
            if abs(math.sqrt(q.x**2 + q.y**2 + q.z**2 + q.w**2) - 1.0) > 1e-6:
                self.fail(f"{topic}: orientation is not a unit quaternion")
            if obj.frame_id != "camera":
                self.fail(f"{topic}: frame_id {obj.frame_id}")
        elif name == "foxglove.FrameTransforms":
            if not obj.transforms:
                self.fail(f"{topic}: no transforms")
            for t in obj.transforms:
                r = t.rotation
                if abs(math.sqrt(r.x**2 + r.y**2 + r.z**2 + r.w**2) - 1.0) > 1e-6:
                    self.fail(f"{topic}: {t.parent_frame_id}->{t.child_frame_id} rotation not unit")
        elif name == "foxglove.Log":
            if not 0 <= obj.level <= 5:
                self.fail(f"{topic}: log level {obj.level}")

    def frame_order(self, topic, message):
        last = self.last_frame_time.get(topic)
        if last is not None and message.log_time < last:
            self.fail(f"{topic}: frames out of order")
        self.last_frame_time[topic] = message.log_time

    def check_crops(self):
        """Every /camera/crop has its /camera/crop_info, of its size."""
        if self.crop_sizes.keys() != self.crop_infos.keys():
            self.fail(f"{len(self.crop_sizes)} crops, {len(self.crop_infos)} crop_info records")
        for seq, size in self.crop_sizes.items():
            if self.crop_infos.get(seq, size) != size:
                self.fail(f"crop {seq}: PNG {size}, crop_info {self.crop_infos[seq]}")


def check_jpeg(data):
    """Decodes a JPEG with Pillow: (what is wrong or None, (width, height))."""
    import io

    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.format != "JPEG" or im.mode != "L":
                return f"{im.format} {im.mode}, not an 8-bit gray JPEG", None
            im.load()
            return None, im.size
    except Exception as e:  # noqa: BLE001 - any decode failure is a failure
        return f"Pillow: {e}", None


def check_png(data):
    """Inflates a gray PNG with zlib: chunk CRCs, row count and length, filter
    bytes. Returns (what is wrong or None, (width, height))."""
    problem = png_problem(data)
    if problem:
        return problem, None
    width, height = struct.unpack(">II", data[16:24])
    return None, (width, height)


def png_problem(data):
    pos, idat, ihdr = len(PNG_SIGNATURE), [], None
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        if zlib.crc32(kind + body) != crc:
            return f"bad CRC in {kind!r}"
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if ihdr is None:
        return "no IHDR"
    width, height, depth, colour = ihdr[:4]
    if (depth, colour) != (8, 0):
        return f"not 8-bit gray: depth {depth} colour type {colour}"
    try:
        raw = zlib.decompress(b"".join(idat))
    except zlib.error as e:
        return f"zlib: {e}"
    if len(raw) != height * (width + 1):
        return f"{len(raw)} bytes inflated, {height * (width + 1)} expected"
    if any(raw[r * (width + 1)] > 4 for r in range(height)):
        return "a row has an invalid filter type"
    return None


def check_complete(path, required, compression=None, metadata=()):
    c = Checker(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if compression is not None and summary is not None:
            want = "" if compression == "none" else compression
            found = {ci.compression for ci in summary.chunk_indexes}
            if found != {want}:
                c.fail(f"chunk compression {sorted(found)}, expected {want!r}")
        names = {m.name for m in reader.iter_metadata()}
        for name in metadata:
            if name not in names:
                c.fail(f"no metadata record {name} (found {sorted(names)})")
        if summary is None or summary.statistics is None:
            c.fail("no summary section (not a complete, indexed file)")
        elif not summary.chunk_indexes:
            c.fail("no chunk index")
        for schema, channel, message in reader.iter_messages():
            c.check(schema, channel, message)
        if summary is not None and summary.statistics is not None:
            by_topic = {}
            for cid, n in summary.statistics.channel_message_counts.items():
                topic = summary.channels[cid].topic
                by_topic[topic] = by_topic.get(topic, 0) + n
            if by_topic != c.counts:
                c.fail(f"summary counts {by_topic} differ from messages read {c.counts}")
    finish(c, required)
    return c


def check_cut(path, required):
    """Streams a cut-short file up to the cut; the cut itself is expected."""
    c = Checker(path)
    schemas, channels = {}, {}
    cut = None
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    ch = channels.get(record.channel_id)
                    if ch is None:
                        c.fail(f"message on unknown channel {record.channel_id}")
                        continue
                    c.check(schemas.get(ch.schema_id), ch, record)
        except (McapError, EOFError, ValueError, OSError) as e:
            cut = f"{type(e).__name__}: {e}"
    print(f"{path}: cut at: {cut}")
    finish(c, required)
    return c


def finish(c, required):
    c.check_crops()
    for topic in required:
        if c.counts.get(topic, 0) == 0:
            c.fail(f"no messages on {topic}")
    total = sum(c.counts.values())
    status = "OK" if not c.failures else f"{len(c.failures)} FAILURES"
    print(f"{c.path}: {total} messages decoded {status}")
    for topic in sorted(c.counts):
        print(f"  {topic:24} {c.counts[topic]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--cut", action="store_true", help="the logs were cut short by a crash")
    ap.add_argument("--require", default=",".join(DEFAULT_REQUIRED),
                    help="comma-separated topics that must have messages ('' for none)")
    ap.add_argument("--compression", choices=["zstd", "lz4", "none"],
                    help="every chunk must be compressed so")
    ap.add_argument("--metadata", default="",
                    help="comma-separated metadata record names that must be present")
    args = ap.parse_args()
    required = [t for t in args.require.split(",") if t]
    metadata = [t for t in args.metadata.split(",") if t]
    failed = False
    for path in args.logs:
        try:
            if args.cut:
                c = check_cut(path, required)
            else:
                c = check_complete(path, required, args.compression, metadata)
            failed |= bool(c.failures)
        except Exception as e:  # noqa: BLE001 - report, never crash silently
            print(f"FAIL {path}: {type(e).__name__}: {e}", file=sys.stderr)
            failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
