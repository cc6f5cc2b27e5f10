//! MCAP files as replay and recover read them: every frame decoded or an
//! error, then a recovery into a new file; never a panic, never more memory
//! than the record limit.
#![no_main]

use drogue_vision::log::recover;
use drogue_vision::source::replay;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("drogue-fuzz-mcap-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let input = dir.join("in.mcap");
    let output = dir.join("out.mcap");
    if std::fs::write(&input, data).is_err() {
        return;
    }
    if let Ok(reader) = replay::open(&input) {
        for frame in reader.take(64) {
            let _ = frame.map(|f| f.image.dimensions());
        }
    }
    let _ = replay::ReplayReader::first_camera(&input);
    let _ = std::fs::remove_file(&output);
    let _ = recover::recover(&input, &output);
});
