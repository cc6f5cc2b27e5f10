//! The modules' dependencies point one way (ARCHITECTURE.md, "Modules"):
//! every `crate::` path in a module's non-test code names a module of a
//! lower layer. A new import that runs back up (and would close a circle)
//! fails here, naming the file and the path.

use std::path::{Path, PathBuf};

/// Layers from the top; a module may use only modules of later rows.
const LAYERS: &[&[&str]] = &[
    &["commands"],
    &["pipeline"],
    &["config"],
    &["source"],
    &["log"],
    &["link", "record"],
    &["measure", "image_io"],
    &["camera", "frame", "clock", "priority", "spatial"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|row| row.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The file's code up to its `#[cfg(test)]` module (tests may use anything),
/// without comments.
fn non_test_code(text: &str) -> String {
    text.lines()
        .take_while(|l| l.trim() != "#[cfg(test)]")
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn every_module_uses_only_lower_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut checked = 0;
    let mut wrong = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).expect("under src");
        // A module's `tests.rs` is its `#[cfg(test)] mod tests`.
        if rel.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let first = rel.components().next().expect("component");
        let own = first
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string();
        let Some(own_layer) = layer_of(&own) else {
            // main.rs, lib.rs, testing.rs: the top, above every layer.
            continue;
        };
        let code = non_test_code(&std::fs::read_to_string(file).expect("read"));
        for (i, _) in code.match_indices("crate::") {
            let name: String = code[i + 7..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if name == own {
                continue;
            }
            checked += 1;
            match layer_of(&name) {
                Some(l) if l > own_layer => {}
                _ => wrong.push(format!("{}: crate::{name}", rel.display())),
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} crate:: paths found: is src where it was?"
    );
    assert!(
        wrong.is_empty(),
        "imports that run up (or sideways) the layers:\n{}",
        wrong.join("\n")
    );
}

/// Every "ARCHITECTURE.md section N" cited in the code and the default
/// config names a section the file has.
#[test]
fn every_cited_architecture_section_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.push(root.join("config/default.toml"));
    let mut cited = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).expect("read");
        for (i, _) in text.match_indices("ARCHITECTURE.md section ") {
            let n: String = text[i + 24..]
                .chars()
                .take_while(char::is_ascii_digit)
                .collect();
            cited += 1;
            assert!(
                doc.contains(&format!("\n## {n}. ")),
                "{} cites ARCHITECTURE.md section {n}, which it does not have",
                file.display()
            );
        }
    }
    assert!(cited >= 5, "only {cited} citations found");
}
