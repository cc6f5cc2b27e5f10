//! The MAVLink frame finder on arbitrary bytes, as datagrams and as a
//! stream split at a point the input chooses: never a panic, the buffer
//! bounded, and the CRC work bounded per byte.
#![no_main]

use drogue_vision::link::frame::{BUFFER_CAP, DecodeCounts, FrameDecoder, MAX_FRAME};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&split, bytes)) = data.split_first() else {
        return;
    };
    let mut out = Vec::new();
    let mut counts = DecodeCounts::default();
    let mut d = FrameDecoder::new();
    d.feed(bytes, true, None, &mut counts, &mut out);
    assert_eq!(d.pending(), 0);
    let mut d = FrameDecoder::new();
    for part in bytes.chunks(usize::from(split).max(1)) {
        d.feed(part, false, None, &mut counts, &mut out);
        assert!(d.pending() <= BUFFER_CAP);
    }
    // At most one CRC over a whole frame for each byte received.
    assert!(counts.crc_bytes <= 2 * (bytes.len() as u64) * MAX_FRAME as u64);
});
