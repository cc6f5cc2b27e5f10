#!/usr/bin/env python3
"""Interop check of drogue-vision's MAVLink output against pymavlink.

Listens on a UDP port on 127.0.0.1, runs

    drogue-vision run --source sim:approach --max-frames 150 \
        --mavlink udpout:127.0.0.1:PORT --log-dir TMP --config TMP/link.toml

and checks, with pymavlink (an implementation independent of the Rust
`mavlink` crate), that every datagram is one MAVLink 2 frame with a valid CRC
and a valid signature (key = SHA-256 of the passphrase, MAVProxy's
convention). The decoded LANDING_TARGET and VISION_POSITION_ESTIMATE values
are compared with the simulator's truth (`drogue-vision sim --scenario
approach --out TMP --frames 150`, truth.jsonl: position_body, t, seq),
matched by capture time: time_usec - t must be one constant (the run's start)
for every message. Position error must stay within 1 % of the range + 5 mm.
The capture -> arrival latency is reported.

Exit status 0: pass; 1: a check failed; 2: could not run.

Without the `run` command (or to check this script), `--sender CMD` runs CMD
instead, with LINK_INTEROP_PORT, LINK_INTEROP_CONFIG and LINK_INTEROP_TRUTH in
its environment; CMD writes the truth file itself (tests/link_interop.rs).
"""

import argparse
import glob
import hashlib
import json
import math
import os
import shlex
import socket
import statistics
import subprocess
import sys
import tempfile
import time

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402

MAV_FRAME_BODY_FRD = 12
LANDING_TARGET_TYPE_VISION_OTHER = 3


def fail(msg):
    print(f"FAIL: {msg}")
    return 1


def run_sim(binary, scenario, frames, out_dir):
    cmd = [binary, "sim", "--scenario", scenario, "--out", out_dir, "--frames", str(frames)]
    print("truth:", " ".join(cmd))
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return os.path.join(out_dir, "truth.jsonl")


def load_truth(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                rows.append(json.loads(line))
    return rows


def frame_ok(data, signed_required):
    """MAVLink 2 framing of one datagram: exactly one whole frame."""
    if len(data) < 12:
        return "shorter than a MAVLink 2 frame"
    if data[0] != 0xFD:
        return f"start byte 0x{data[0]:02x}, not MAVLink 2 (0xFD)"
    signed = bool(data[2] & 0x01)
    if data[2] & ~0x01:
        return f"unknown incompat flags 0x{data[2]:02x}"
    expect = 10 + data[1] + 2 + (13 if signed else 0)
    if len(data) != expect:
        return f"length {len(data)}, frame says {expect}"
    if signed_required and not signed:
        return "unsigned frame while signing is configured"
    return None


def match_offset(messages, truth, tol_us):
    """The constant capture-time offset (us) that matches most messages to
    truth frames: time_usec = offset + t * 1e6."""
    ts = sorted(round(r["t"] * 1e6) for r in truth)
    best = (0, None)
    for m in messages[:10]:
        for t in ts:
            off = m["time_usec"] - t
            n = sum(1 for x in messages if nearest(ts, x["time_usec"] - off) <= tol_us)
            if n > best[0]:
                best = (n, off)
    return best


def offset_from_log(log_dir, truth):
    """The capture-time offset (us) of a `run`: its log's first /camera/image
    is the scenario's first frame. Frames are evenly spaced, so matching by
    times alone cannot tell a shift of whole frames; the log anchors it.
    None when there is no log (a --sender run)."""
    logs = sorted(glob.glob(os.path.join(log_dir, "*.mcap")))
    if not logs:
        return None
    from mcap.reader import make_reader

    with open(logs[0], "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(topics=["/camera/image"]):
            t0 = min(r["t"] for r in truth)
            return message.log_time / 1000 - round(t0 * 1e6)
    return None


def nearest(sorted_ts, v):
    import bisect

    i = bisect.bisect_left(sorted_ts, v)
    d = float("inf")
    for j in (i - 1, i):
        if 0 <= j < len(sorted_ts):
            d = min(d, abs(sorted_ts[j] - v))
    return d


def rot_zyx(roll, pitch, yaw):
    """R = Rz(yaw) Ry(pitch) Rx(roll), as nested lists."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--binary", default="target/release/drogue-vision")
    ap.add_argument("--scenario", default="approach")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--passphrase", default="drogue-vision interop")
    ap.add_argument("--sender", default="", help="command to run instead of `drogue-vision run`")
    ap.add_argument("--match-tolerance-ms", type=float, default=2.0)
    ap.add_argument("--timeout-s", type=float, default=120.0)
    args = ap.parse_args()

    tmp = tempfile.mkdtemp(prefix="mavlink-check-")
    config = os.path.join(tmp, "link.toml")
    with open(config, "w") as f:
        f.write(
            "[link]\n"
            'messages = ["landing_target", "vision_position_estimate"]\n'
            f"signing_passphrase = {json.dumps(args.passphrase)}\n"
            "max_rate_hz = 0.0\n"
        )
    key = hashlib.sha256(args.passphrase.encode()).digest()

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.2)
    port = sock.getsockname()[1]

    truth_path = os.path.join(tmp, "truth.jsonl")
    env = dict(os.environ)
    if args.sender:
        env.update(LINK_INTEROP_PORT=str(port), LINK_INTEROP_CONFIG=config, LINK_INTEROP_TRUTH=truth_path)
        cmd = shlex.split(args.sender)
    else:
        try:
            truth_path = run_sim(args.binary, args.scenario, args.frames, os.path.join(tmp, "sim"))
        except (OSError, subprocess.CalledProcessError) as e:
            print(f"cannot make the truth: {e}")
            return 2
        cmd = [
            args.binary, "run", "--source", f"sim:{args.scenario}", "--max-frames", str(args.frames),
            "--mavlink", f"udpout:127.0.0.1:{port}", "--log-dir", os.path.join(tmp, "logs"), "--config", config,
        ]
    print("sender:", " ".join(cmd))
    try:
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    except OSError as e:
        print(f"cannot start the sender: {e}")
        return 2

    received = []  # (arrival ns, bytes)
    deadline = time.time() + args.timeout_s
    done_at = None
    while time.time() < deadline:
        try:
            data, _ = sock.recvfrom(4096)
            received.append((time.time_ns(), data))
        except socket.timeout:
            pass
        if proc.poll() is not None:
            done_at = done_at or time.time()
            if time.time() - done_at > 1.0:
                break
    if proc.poll() is None:
        proc.kill()
        return fail(f"sender still running after {args.timeout_s} s")
    stderr = proc.stderr.read() if proc.stderr else ""
    if proc.returncode != 0:
        print(stderr[-3000:])
        return fail(f"sender exited with {proc.returncode}")

    # --- framing, CRC, signature: pymavlink decodes every datagram --------
    mav = apm.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = False
    mav.signing.allow_unsigned_callback = None  # unsigned -> rejected
    errors = []
    msgs = []
    for at, data in received:
        why = frame_ok(data, signed_required=True)
        if why:
            errors.append(why)
            continue
        try:
            m = mav.decode(bytearray(data))
        except apm.MAVError as e:
            errors.append(str(e))
            continue
        msgs.append((at, m))
    counts = {}
    for _, m in msgs:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    print(f"{len(received)} datagrams, decoded {counts}, signatures good {mav.signing.goodsig_count}, "
          f"bad {mav.signing.badsig_count}")
    status = 0
    if errors:
        status = fail(f"{len(errors)} frames refused by pymavlink, e.g. {errors[:3]}")
    if not msgs:
        return fail("nothing decoded")
    for _, m in msgs:
        if (m.get_srcSystem(), m.get_srcComponent()) != (1, 197):
            status = fail(f"{m.get_type()} from {m.get_srcSystem()}/{m.get_srcComponent()}, expected 1/197")
            break
    if counts.get("HEARTBEAT", 0) < 1:
        status = fail("no HEARTBEAT")

    # --- values against the simulator's truth ------------------------------
    truth = load_truth(truth_path)
    lts = [dict(at=at, time_usec=m.time_usec, m=m) for at, m in msgs if m.get_type() == "LANDING_TARGET"]
    vpes = [dict(at=at, time_usec=m.usec, m=m) for at, m in msgs if m.get_type() == "VISION_POSITION_ESTIMATE"]
    if not lts or not vpes:
        return fail(f"need LANDING_TARGET and VISION_POSITION_ESTIMATE, got {counts}")
    tol_us = args.match_tolerance_ms * 1000
    offset = offset_from_log(os.path.join(tmp, "logs"), truth)
    if offset is None:
        n_matched, offset = match_offset(lts, truth, tol_us)
    else:
        n_matched = sum(1 for x in lts if nearest(sorted(round(r["t"] * 1e6) for r in truth),
                                                  x["time_usec"] - offset) <= tol_us)
    if offset is None or n_matched < 0.9 * len(lts):
        return fail(f"only {n_matched} of {len(lts)} LANDING_TARGETs match a truth frame by capture time")
    by_t = {round(r["t"] * 1e6): r for r in truth}
    ts = sorted(by_t)

    def truth_for(time_usec):
        import bisect

        v = time_usec - offset
        i = bisect.bisect_left(ts, v)
        cands = [ts[j] for j in (i - 1, i) if 0 <= j < len(ts)]
        best = min(cands, key=lambda c: abs(c - v))
        return by_t[best] if abs(best - v) <= tol_us else None

    worst_lt = 0.0
    lt_errors = []
    for x in lts:
        m, tr = x["m"], truth_for(x["time_usec"])
        if tr is None:
            status = fail(f"LANDING_TARGET at {x['time_usec']} matches no frame")
            continue
        if tr.get("expect", "detect") != "detect":
            status = fail(f"LANDING_TARGET sent for frame {tr.get('seq')} without a detection")
            continue
        p = tr["position_body"]
        rng = math.sqrt(sum(c * c for c in p))
        err = math.sqrt((m.x - p[0]) ** 2 + (m.y - p[1]) ** 2 + (m.z - p[2]) ** 2)
        lt_errors.append(err / rng)
        worst_lt = max(worst_lt, err / rng)
        limit = 0.01 * rng + 0.005
        if err > limit:
            status = fail(f"frame {tr.get('seq')}: LANDING_TARGET error {err:.4f} m > {limit:.4f} m (range {rng:.2f} m)")
        if m.frame != MAV_FRAME_BODY_FRD or m.position_valid != 1 or m.type != LANDING_TARGET_TYPE_VISION_OTHER:
            status = fail(f"LANDING_TARGET frame/position_valid/type = {m.frame}/{m.position_valid}/{m.type}")
        if abs(m.distance - math.sqrt(m.x ** 2 + m.y ** 2 + m.z ** 2)) > 1e-3 * max(1.0, m.distance):
            status = fail("LANDING_TARGET distance is not |xyz|")

    # VISION_POSITION_ESTIMATE: the receiver in the drogue frame. Rotating it
    # back with its own roll/pitch/yaw must give the drogue centre in body
    # (centre_body = -R_drogue_body^T p), which is compared with the truth;
    # the drogue frame's x axis (-normal) is compared with the truth normal.
    worst_vpe = 0.0
    worst_axis_deg = 0.0
    for x in vpes:
        m, tr = x["m"], truth_for(x["time_usec"])
        if tr is None or tr.get("expect", "detect") != "detect":
            status = fail(f"VISION_POSITION_ESTIMATE at {x['time_usec']} matches no detected frame")
            continue
        r = rot_zyx(m.roll, m.pitch, m.yaw)  # R_drogue_body
        pd = (m.x, m.y, m.z)
        centre = [-sum(r[i][k] * pd[i] for i in range(3)) for k in range(3)]  # -R^T p
        p = tr["position_body"]
        rng = math.sqrt(sum(c * c for c in p))
        err = math.sqrt(sum((centre[k] - p[k]) ** 2 for k in range(3)))
        worst_vpe = max(worst_vpe, err / rng)
        if err > 0.01 * rng + 0.005:
            status = fail(f"frame {tr.get('seq')}: VISION_POSITION_ESTIMATE implies the drogue {err:.4f} m off")
        if "normal_body" in tr:
            axis = [r[0][k] for k in range(3)]  # drogue x axis in body = -normal
            n = tr["normal_body"]
            dot = -sum(axis[k] * n[k] for k in range(3)) / math.sqrt(sum(c * c for c in n))
            worst_axis_deg = max(worst_axis_deg, math.degrees(math.acos(max(-1.0, min(1.0, dot)))))
        if len(m.covariance) != 21 or not all(math.isfinite(c) for c in m.covariance) or m.covariance[0] <= 0:
            status = fail("VISION_POSITION_ESTIMATE covariance missing or not finite")

    detected_frames = sum(1 for r in truth if r.get("expect", "detect") == "detect")
    print(f"LANDING_TARGET: {len(lts)} for {detected_frames} detected frames, "
          f"error/range median {statistics.median(lt_errors) * 100:.3f} %, worst {worst_lt * 100:.3f} %")
    print(f"VISION_POSITION_ESTIMATE: {len(vpes)}, worst implied-centre error/range {worst_vpe * 100:.3f} %, "
          f"worst drogue-axis error {worst_axis_deg:.2f} deg")
    if len(lts) < 0.5 * detected_frames:
        status = fail(f"only {len(lts)} poses for {detected_frames} detected frames")

    # --- latency: capture -> arrival here (wall clock) ----------------------
    lat_ms = sorted((x["at"] - x["time_usec"] * 1000) / 1e6 for x in lts)
    if abs(offset - time.time_ns() / 1000) < 3600e6:
        print(f"capture -> arrival latency: median {statistics.median(lat_ms):.2f} ms, "
              f"p95 {lat_ms[int(0.95 * (len(lat_ms) - 1))]:.2f} ms, max {lat_ms[-1]:.2f} ms")
    else:
        print("capture -> arrival latency: n/a (capture times are not wall-clock times)")
    print("PASS" if status == 0 else "FAILED")
    return status


if __name__ == "__main__":
    sys.exit(main())
