//! Config files: loaded (every number within its range) or refused with a
//! message naming the file.
#![no_main]

use drogue_vision::config::Config;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Err(e) = Config::from_toml_str(text, "fuzz.toml") {
        assert!(e.to_string().starts_with("config fuzz.toml"), "{e}");
    }
});
