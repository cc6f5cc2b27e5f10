//! MAVLink 2 framing: encoding (sequence numbers, signing) and a validating
//! decoder that counts every byte it has to throw away.
//!
//! The crate's own readers skip bad input silently; the link must count it
//! (garbage, MAVLink 1, bad CRC, truncated frames, bad signatures), so frames
//! are found and checked here with the crate's CRC, signature and payload
//! code. Memory is bounded: the buffer never holds more than [`BUFFER_CAP`]
//! bytes, whatever arrives.
//!
//! Work is bounded too: a CRC is computed only over a start that passes the
//! cheap header checks (a known message id; MAVLink 1: exactly that message's
//! payload length; MAVLink 2: valid flags and a payload of at least one
//! byte). A flood of magic bytes (0xFE, 0xFD) fails those checks at once, so
//! it costs a few comparisons per byte, not a CRC over up to 280 bytes at
//! each marker ([`DecodeCounts::crc_bytes`] counts the CRC work; a test holds
//! it at zero for such floods).

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message, SigningData};

const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;
const V1_HEADER: usize = 6; // STX, len, seq, sysid, compid, msgid
const V2_HEADER: usize = 10; // STX, len, incompat, compat, seq, sysid, compid, msgid x3
const CRC_LEN: usize = 2;
const SIGNATURE_LEN: usize = 13;
const IFLAG_SIGNED: u8 = 0x01;
/// Largest MAVLink 2 frame: header, 255 payload bytes, CRC, signature.
pub const MAX_FRAME: usize = V2_HEADER + 255 + CRC_LEN + SIGNATURE_LEN;
/// Most bytes the decoder ever buffers.
pub const BUFFER_CAP: usize = 8 * MAX_FRAME;

/// A valid, accepted message.
#[derive(Clone, Debug)]
pub struct Incoming {
    /// Sequence number, system and component of the sender.
    pub header: MavHeader,
    /// The decoded message (`ardupilotmega` dialect).
    pub message: MavMessage,
    /// The frame carried a signature (checked when a signing key is set).
    pub signed: bool,
}

/// What the decoder had to refuse since the last call, for the counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecodeCounts {
    /// Frames decoded and passed on.
    pub accepted: u64,
    /// Bytes skipped: no frame start, a bad CRC, or a frame cut off at the end.
    pub bad_bytes: u64,
    /// MAVLink 1 frames, refused (the link speaks MAVLink 2 only).
    pub mavlink1: u64,
    /// Frames whose signature failed (signing on).
    pub bad_signature: u64,
    /// CRC-valid frames whose payload did not decode (an unknown message, or bad fields).
    pub bad_payload: u64,
    /// Bytes run through a CRC (accepted or not): the decoder's work.
    pub crc_bytes: u64,
}

enum Candidate {
    /// Not enough bytes yet to judge the frame starting here.
    NeedMore,
    /// Not a frame: skip one byte and hunt for the next marker.
    Invalid,
    /// A MAVLink 1 frame with a valid CRC, this long.
    V1(usize),
    /// A MAVLink 2 frame with a valid CRC, this long.
    V2(usize),
}

fn known_id(id: u32) -> bool {
    MavMessage::all_ids().binary_search(&id).is_ok()
}

/// MAVLink 1 payload length of each known message id (ids 0..=255; 0: not
/// a message MAVLink 1 can carry). MAVLink 1 never truncates payloads, so a
/// frame is only plausible with exactly this length.
fn v1_len(id: u8) -> usize {
    static LENS: std::sync::OnceLock<[u8; 256]> = std::sync::OnceLock::new();
    let lens = LENS.get_or_init(|| {
        let mut lens = [0u8; 256];
        let mut buf = [0u8; 255];
        for id in 0..=255u32 {
            if let Some(m) = MavMessage::default_message_from_id(id) {
                lens[id as usize] = u8::try_from(m.ser(MavlinkVersion::V1, &mut buf)).unwrap_or(0);
            }
        }
        lens
    });
    usize::from(lens[usize::from(id)])
}

/// Judges the bytes at the start of `b` (which start with a marker).
fn candidate(b: &[u8], counts: &mut DecodeCounts) -> Candidate {
    match b[0] {
        STX_V2 => {
            if b.len() < V2_HEADER {
                return Candidate::NeedMore;
            }
            let flags = b[2];
            if flags & !IFLAG_SIGNED != 0 {
                return Candidate::Invalid;
            }
            let len = b[1] as usize;
            // MAVLink 2 keeps at least one payload byte when it truncates.
            if len == 0 {
                return Candidate::Invalid;
            }
            let sig = if flags & IFLAG_SIGNED != 0 {
                SIGNATURE_LEN
            } else {
                0
            };
            let total = V2_HEADER + len + CRC_LEN + sig;
            let id = u32::from_le_bytes([b[7], b[8], b[9], 0]);
            if !known_id(id) {
                return Candidate::Invalid;
            }
            if b.len() < total {
                return Candidate::NeedMore;
            }
            let crc_at = V2_HEADER + len;
            let crc = u16::from_le_bytes([b[crc_at], b[crc_at + 1]]);
            counts.crc_bytes += crc_at as u64;
            if mavlink::calculate_crc(&b[1..crc_at], MavMessage::extra_crc(id)) == crc {
                Candidate::V2(total)
            } else {
                Candidate::Invalid
            }
        }
        _ => {
            if b.len() < V1_HEADER {
                return Candidate::NeedMore;
            }
            let len = b[1] as usize;
            let total = V1_HEADER + len + CRC_LEN;
            let id = u32::from(b[5]);
            if !known_id(id) || len != v1_len(b[5]) {
                return Candidate::Invalid;
            }
            if b.len() < total {
                return Candidate::NeedMore;
            }
            let crc_at = V1_HEADER + len;
            let crc = u16::from_le_bytes([b[crc_at], b[crc_at + 1]]);
            counts.crc_bytes += crc_at as u64;
            if mavlink::calculate_crc(&b[1..crc_at], MavMessage::extra_crc(id)) == crc {
                Candidate::V1(total)
            } else {
                Candidate::Invalid
            }
        }
    }
}

/// Finds frames in a byte stream or in datagrams.
#[derive(Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self {
            buf: Vec::with_capacity(BUFFER_CAP),
        }
    }

    /// Bytes held back, waiting for the rest of a frame.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Adds `bytes` and appends every complete, valid message to `out`.
    /// `datagram_end`: no more bytes will complete what is left (a UDP
    /// datagram ended), so a truncated frame is given up at once.
    /// `signing`: verify signatures (and refuse unsigned frames when the
    /// config requires it); `None` accepts signed and unsigned frames unchecked.
    pub fn feed(
        &mut self,
        bytes: &[u8],
        datagram_end: bool,
        signing: Option<&SigningData>,
        counts: &mut DecodeCounts,
        out: &mut Vec<Incoming>,
    ) {
        for chunk in bytes.chunks(BUFFER_CAP - MAX_FRAME) {
            self.buf.extend_from_slice(chunk);
            self.scan(false, signing, counts, out);
        }
        if datagram_end {
            self.scan(true, signing, counts, out);
        }
    }

    fn scan(
        &mut self,
        flush: bool,
        signing: Option<&SigningData>,
        counts: &mut DecodeCounts,
        out: &mut Vec<Incoming>,
    ) {
        let mut pos = 0;
        while pos < self.buf.len() {
            let Some(off) = self.buf[pos..]
                .iter()
                .position(|&b| b == STX_V2 || b == STX_V1)
            else {
                counts.bad_bytes += (self.buf.len() - pos) as u64;
                pos = self.buf.len();
                break;
            };
            counts.bad_bytes += off as u64;
            pos += off;
            match candidate(&self.buf[pos..], counts) {
                Candidate::NeedMore if !flush => break,
                Candidate::NeedMore | Candidate::Invalid => {
                    counts.bad_bytes += 1;
                    pos += 1;
                }
                Candidate::V1(len) => {
                    counts.mavlink1 += 1;
                    pos += len;
                }
                Candidate::V2(len) => {
                    if let Some(m) = accept_v2(&self.buf[pos..pos + len], signing, counts) {
                        out.push(m);
                    }
                    pos += len;
                }
            }
        }
        self.buf.drain(..pos);
    }
}

/// Checks the signature and decodes the payload of a CRC-valid frame.
fn accept_v2(
    frame: &[u8],
    signing: Option<&SigningData>,
    counts: &mut DecodeCounts,
) -> Option<Incoming> {
    let signed = frame[2] & IFLAG_SIGNED != 0;
    if let Some(signing) = signing {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.as_mut_slice()[..frame.len()].copy_from_slice(frame);
        if !signing.verify_signature(&raw) {
            counts.bad_signature += 1;
            return None;
        }
    }
    let len = frame[1] as usize;
    let id = u32::from_le_bytes([frame[7], frame[8], frame[9], 0]);
    match MavMessage::parse(MavlinkVersion::V2, id, &frame[V2_HEADER..V2_HEADER + len]) {
        Ok(message) => {
            counts.accepted += 1;
            Some(Incoming {
                header: MavHeader {
                    sequence: frame[4],
                    system_id: u32::from(frame[5]),
                    component_id: frame[6],
                },
                message,
                signed,
            })
        }
        Err(_) => {
            counts.bad_payload += 1;
            None
        }
    }
}

/// Builds our outgoing frames: MAVLink 2, sequence numbers in write order,
/// signed when a key is set.
pub struct FrameEncoder {
    system_id: u8,
    component_id: u8,
    sequence: u8,
}

impl FrameEncoder {
    /// An encoder sending as `system_id`/`component_id`, sequence from 0.
    pub fn new(system_id: u8, component_id: u8) -> Self {
        Self {
            system_id,
            component_id,
            sequence: 0,
        }
    }

    /// One frame holding `msg` (of any dialect); its bytes are `raw.raw_bytes()`.
    pub fn encode<M: Message>(
        &mut self,
        msg: &M,
        signing: Option<&SigningData>,
    ) -> MAVLinkV2MessageRaw {
        let header = MavHeader {
            system_id: u32::from(self.system_id),
            component_id: self.component_id,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let mut raw = MAVLinkV2MessageRaw::new();
        match signing {
            Some(s) => {
                raw.serialize_message_for_signing(header, msg);
                s.sign_message(&mut raw);
            }
            None => raw.serialize_message(header, msg),
        }
        raw
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::autopilot_heartbeat;
    use mavlink::SigningConfig;

    /// A frame written by the crate's own writer (an independent encoder).
    fn crate_frame(version: MavlinkVersion, seq: u8) -> Vec<u8> {
        let mut v = Vec::new();
        let h = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        mavlink::write_versioned_msg(&mut v, version, h, &autopilot_heartbeat(7)).unwrap();
        v
    }

    fn decode(bytes: &[u8], datagram_end: bool) -> (Vec<Incoming>, DecodeCounts) {
        let mut d = FrameDecoder::new();
        let mut out = Vec::new();
        let mut c = DecodeCounts::default();
        d.feed(bytes, datagram_end, None, &mut c, &mut out);
        (out, c)
    }

    #[test]
    fn decodes_frames_split_anywhere() {
        let mut stream = Vec::new();
        for s in 0..5 {
            stream.extend(crate_frame(MavlinkVersion::V2, s));
        }
        for split in [1, 3, 7, 11, 29] {
            let mut d = FrameDecoder::new();
            let mut out = Vec::new();
            let mut c = DecodeCounts::default();
            for part in stream.chunks(split) {
                d.feed(part, false, None, &mut c, &mut out);
            }
            assert_eq!(out.len(), 5, "split {split}");
            assert_eq!(c.bad_bytes, 0);
            let seqs: Vec<u8> = out.iter().map(|m| m.header.sequence).collect();
            assert_eq!(seqs, vec![0, 1, 2, 3, 4]);
            assert_eq!(out[0].message, autopilot_heartbeat(7));
        }
    }

    #[test]
    fn garbage_bad_crc_v1_and_truncation_are_counted() {
        let good = crate_frame(MavlinkVersion::V2, 9);
        let v1 = crate_frame(MavlinkVersion::V1, 1);
        let mut bad_crc = good.clone();
        let last = bad_crc.len() - 1;
        bad_crc[last] ^= 0xFF;
        let truncated = &good[..good.len() - 3];
        let garbage = [0x00u8, 0x55, 0x13, 0x37];

        let mut bytes = Vec::new();
        bytes.extend_from_slice(&garbage);
        bytes.extend_from_slice(&v1);
        bytes.extend_from_slice(&bad_crc);
        bytes.extend_from_slice(&good);
        let (out, c) = decode(&bytes, true);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].header.sequence, 9);
        assert_eq!(c.mavlink1, 1);
        assert_eq!(c.bad_bytes, (garbage.len() + bad_crc.len()) as u64);

        // A datagram cut short: all its bytes are given up at its end.
        let (out, c) = decode(truncated, true);
        assert!(out.is_empty());
        assert_eq!(c.bad_bytes, truncated.len() as u64);
        // In a stream, the same bytes wait for the rest.
        let (out, c) = decode(truncated, false);
        assert!(out.is_empty());
        assert_eq!(c.bad_bytes, 0);
    }

    #[test]
    fn memory_stays_bounded_under_a_flood() {
        let mut d = FrameDecoder::new();
        let mut out = Vec::new();
        let mut c = DecodeCounts::default();
        // Markers followed by a plausible header, forever incomplete.
        let mut junk = Vec::new();
        for i in 0..20_000u32 {
            junk.extend_from_slice(&[STX_V2, 255, 0, 0, (i % 256) as u8, 1, 1, 0, 0, 0]);
        }
        for part in junk.chunks(1000) {
            d.feed(part, false, None, &mut c, &mut out);
            assert!(d.pending() <= BUFFER_CAP);
        }
        // Good frames after the flood still get through: once enough bytes
        // arrive to refute the last junk candidate (it claims 255 payload
        // bytes), the scan resumes and finds them.
        for seq in 0..20 {
            d.feed(
                &crate_frame(MavlinkVersion::V2, seq),
                false,
                None,
                &mut c,
                &mut out,
            );
        }
        for seq in 0..10 {
            assert!(
                out.iter().any(|m| m.header.sequence == seq),
                "frame {seq} lost"
            );
        }
        assert!(d.pending() <= BUFFER_CAP);
    }

    /// Frames with a valid CRC but arbitrary payloads, for every known
    /// message id: decoded or counted, never a panic.
    #[test]
    fn random_payloads_with_valid_crc_never_panic() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut d = FrameDecoder::new();
        let mut out = Vec::new();
        let mut c = DecodeCounts::default();
        let mut frames = 0u64;
        for &id in MavMessage::all_ids() {
            for _ in 0..4 {
                let len: usize = rng.random_range(1..=255);
                let mut f = vec![STX_V2, len as u8, 0, 0, 0, 1, 1];
                f.extend_from_slice(&id.to_le_bytes()[..3]);
                f.extend((0..len).map(|_| rng.random::<u8>()));
                let crc = mavlink::calculate_crc(&f[1..], MavMessage::extra_crc(id));
                f.extend_from_slice(&crc.to_le_bytes());
                d.feed(&f, true, None, &mut c, &mut out);
                frames += 1;
            }
        }
        assert_eq!(c.accepted + c.bad_payload, frames);
        assert_eq!(out.len() as u64, c.accepted);
    }

    /// The MAVLink 1 lengths are the crate's own: a V1 frame the crate
    /// writes is recognised (and refused as MAVLink 1), for many ids.
    #[test]
    fn v1_lengths_match_the_crate_writer() {
        assert_eq!(v1_len(0), 9); // HEARTBEAT: 9 bytes in MAVLink 1
        let (_, c) = decode(&crate_frame(MavlinkVersion::V1, 3), true);
        assert_eq!((c.mavlink1, c.bad_bytes), (1, 0));
    }

    /// Floods of magic bytes cost no CRC at all, and arbitrary bytes cost a
    /// bounded number of CRC bytes per input byte; frames after them decode.
    #[test]
    fn floods_cost_bounded_work() {
        for magic in [STX_V1, STX_V2] {
            let mut d = FrameDecoder::new();
            let (mut out, mut c) = (Vec::new(), DecodeCounts::default());
            for _ in 0..1000 {
                d.feed(&[magic; 1400], true, None, &mut c, &mut out);
            }
            assert_eq!(c.crc_bytes, 0, "magic {magic:#x}");
            assert_eq!(c.bad_bytes, 1_400_000);
            d.feed(
                &crate_frame(MavlinkVersion::V2, 1),
                true,
                None,
                &mut c,
                &mut out,
            );
            assert_eq!(out.len(), 1);
        }
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut d = FrameDecoder::new();
        let (mut out, mut c) = (Vec::new(), DecodeCounts::default());
        let bytes: Vec<u8> = (0..1_000_000).map(|_| rng.random()).collect();
        d.feed(&bytes, true, None, &mut c, &mut out);
        // About 2/256 of random bytes are markers, and few of those pass the
        // header checks: far below one CRC byte per input byte.
        assert!(c.crc_bytes < bytes.len() as u64 / 4, "{}", c.crc_bytes);
    }

    #[test]
    fn our_frames_decode_with_the_crate_reader() {
        let mut enc = FrameEncoder::new(1, 197);
        let a = enc.encode(&autopilot_heartbeat(7), None);
        let b = enc.encode(&autopilot_heartbeat(7), None);
        let mut bytes = a.raw_bytes().to_vec();
        bytes.extend_from_slice(b.raw_bytes());
        let mut r = mavlink::MavlinkReader::new(bytes.as_slice());
        let (h1, m1) = r.read_message::<MavMessage>(MavlinkVersion::V2).unwrap();
        let (h2, _) = r.read_message::<MavMessage>(MavlinkVersion::V2).unwrap();
        assert_eq!((h1.system_id, h1.component_id, h1.sequence), (1, 197, 0));
        assert_eq!(h2.sequence, 1);
        assert_eq!(m1, autopilot_heartbeat(7));
    }

    #[test]
    fn signatures_are_checked() {
        let key = [42u8; 32];
        let sign = SigningData::from_config(SigningConfig::new(key, 3, true, false));
        let mut enc = FrameEncoder::new(1, 1);
        let signed = enc
            .encode(&autopilot_heartbeat(7), Some(&sign))
            .raw_bytes()
            .to_vec();
        let unsigned = enc
            .encode(&autopilot_heartbeat(7), None)
            .raw_bytes()
            .to_vec();
        let mut forged = signed.clone();
        let n = forged.len();
        forged[n - 1] ^= 1; // last byte of the 6-byte signature

        let required = SigningData::from_config(SigningConfig::new(key, 0, true, false));
        let mut d = FrameDecoder::new();
        let mut out = Vec::new();
        let mut c = DecodeCounts::default();
        for f in [&forged, &unsigned, &signed] {
            d.feed(f, true, Some(&required), &mut c, &mut out);
        }
        assert_eq!(out.len(), 1);
        assert!(out[0].signed);
        assert_eq!(c.bad_signature, 2);

        // Optional signing: unsigned accepted, a bad signature still refused.
        let optional = SigningData::from_config(SigningConfig::new(key, 0, true, true));
        let mut out = Vec::new();
        let mut c = DecodeCounts::default();
        let signed2 = enc
            .encode(&autopilot_heartbeat(7), Some(&sign))
            .raw_bytes()
            .to_vec();
        for f in [&unsigned, &forged, &signed2] {
            d.feed(f, true, Some(&optional), &mut c, &mut out);
        }
        assert_eq!(out.len(), 2);
        assert_eq!(c.bad_signature, 1);
    }
}
