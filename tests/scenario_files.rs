//! Every scenario file shipped in `sim/scenarios/` loads, including the ones
//! that are not built in (the two-minute `endurance` run of the README).

use drogue_sim::Scenario;

#[test]
fn every_shipped_scenario_file_loads() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("sim/scenarios");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let s = Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(s.fps > 0.0 && s.duration_s > 0.0, "{}", path.display());
            names.push(s.name);
        }
    }
    names.sort();
    for builtin in Scenario::builtin_names() {
        assert!(names.iter().any(|n| n == builtin), "{builtin} has no file");
    }
    let endurance = Scenario::load(&dir.join("endurance.toml")).unwrap();
    // Two minutes at 30 fps: the README's speed measurement.
    assert_eq!((endurance.duration_s * endurance.fps).round(), 3600.0);
}
