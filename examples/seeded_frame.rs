//! One reference frame measured from its true ellipse: the detector is
//! given the truth's ellipse as a tracking hint, so only the narrow passes
//! around it and the evidence run. Tells a miss whose canopy test fails at
//! the true rim from one whose search never found that rim (README, the
//! two misses of the reference sets). With
//! `RUST_LOG=drogue_vision::measure=debug` the evidence's figures (canopy
//! share, fill, rise) are printed too. `hard_b/frame_0016` verifies there
//! (canopy 0.62, score 0.42) where the full-frame search fails;
//! `hard_c/frame_0007` does not (its narrow pass fits the disc 5 px short
//! across, under the probe's tip: score 0.27).
//!
//! `cargo run --release --example seeded_frame -- SET_DIR FRAME`
//! (`FRAME` as in the set's `truth.jsonl`, `frame_0007.png`).

use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::image_io::read_gray8;
use drogue_vision::testing;
use std::path::PathBuf;

fn usage(message: &str) -> ! {
    eprintln!("{message}\nusage: seeded_frame SET_DIR FRAME");
    std::process::exit(2);
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [set, frame] = args.as_slice() else {
        usage("two arguments");
    };
    let set = PathBuf::from(set);
    let camera = CameraModel::load(&set.join("camera.yaml"))
        .unwrap_or_else(|e| usage(&format!("camera.yaml: {e}")));
    let truth = testing::read_truths(&set)
        .into_iter()
        .find(|t| &t.frame == frame)
        .unwrap_or_else(|| usage(&format!("{frame} is not in the set's truth.jsonl")));
    let Some(ellipse) = truth.ellipse else {
        usage(&format!("{frame} has no true ellipse (no drogue)"));
    };
    let image = read_gray8(&set.join(frame), None).unwrap_or_else(|e| usage(&e));
    let config = Config::embedded();
    let mut detector = testing::detector(&config, &camera);
    println!(
        "truth: centre ({:.2}, {:.2}) axes {:.2}/{:.2} px (undistorted)",
        ellipse.cx, ellipse.cy, ellipse.a, ellipse.b
    );
    match detector.detect_explained(&image, Some(&ellipse)) {
        Ok(c) => {
            let e = &c.ellipse_px;
            println!(
                "seeded at the truth: verified, centre ({:.2}, {:.2}) axes {:.2}/{:.2} px, score {:.3}, {} rim points",
                e.cx,
                e.cy,
                e.a,
                e.b,
                c.score,
                c.rim_points_px.len()
            );
        }
        // The detector falls back on a full-frame search when the hint
        // fails: the reason is the search's; the debug line `not at the
        // tracked ellipse` gives the hint's own.
        Err(miss) => println!(
            "seeded at the truth: not verified; the full-frame search after it: {}",
            miss.reason
        ),
    }
}
