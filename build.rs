//! Build script: records the git commit the binary is built from, for the
//! flight log's metadata (`DROGUE_VISION_GIT_HASH`). Without git or outside
//! a checkout (a source tarball) nothing is set and the log says "unknown".

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let text = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!text.is_empty()).then_some(text)
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let Some(hash) = git(&["rev-parse", "HEAD"]) else {
        return;
    };
    println!("cargo:rustc-env=DROGUE_VISION_GIT_HASH={hash}");
    // Rebuild when HEAD moves: HEAD itself, and the branch it points to.
    if let Some(head) = git(&["rev-parse", "--git-path", "HEAD"]) {
        println!("cargo:rerun-if-changed={head}");
    }
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"])
        && let Some(path) = git(&["rev-parse", "--git-path", &branch])
    {
        println!("cargo:rerun-if-changed={path}");
    }
    if let Some(packed) = git(&["rev-parse", "--git-path", "packed-refs"])
        // A path that does not exist would make cargo rerun this every build.
        && std::path::Path::new(&packed).exists()
    {
        println!("cargo:rerun-if-changed={packed}");
    }
}
