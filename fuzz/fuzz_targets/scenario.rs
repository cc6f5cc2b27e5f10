//! Scenario files: refused naming the file, or accepted and set up as a
//! simulation whose first truth is computed (rendering is left to the
//! renderer's own tests: at ~5 ms a frame it would slow the search 1000x).
#![no_main]

use drogue_sim::{Scenario, Simulator};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Scenario::from_toml_str(text, "fuzz.toml") {
        Ok(s) => {
            if let Ok(mut sim) = Simulator::new(s) {
                let _ = sim.next_truth();
            }
        }
        Err(e) => assert!(e.to_string().starts_with("fuzz.toml"), "{e}"),
    }
});
