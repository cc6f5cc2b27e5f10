//! One frame of the robustness sweep, looked at closely: what it was drawn
//! with, its truth, what the measurement gave and how far off it is, and
//! (with `--crop DIR`) the frame around the drogue written as a PNG (at least
//! 1.3 times its semi-major axis each way, twice its size up to 400 px a
//! side); on a drogue-free frame around what was taken for one, if
//! anything was.
//!
//! `cargo run --release --example sweep_frame -- SEED LEVEL INDEX [--crop DIR]`
//!
//! LEVEL is a level's label as the sweep's table and `SWEEP_TRACE=1` print
//! it (`everything`, `glare streak 30 px wide`, `glare glow sigma 135 px`,
//! `no drogue: crescent`).
//! `RUST_LOG=drogue_vision::measure::detect=debug` adds the detector's line
//! per candidate (where it was, what kind of seed, why it was dropped), and
//! `=trace` each rim pass; the line `truth in the frame` gives the disc's
//! centre in the same (distorted) pixels as those lines, so that the seeds
//! on the disc can be told from the rest. This is how a miss of the sweep
//! is studied: the sweep names the frame, this shows why. The frame is then
//! measured again with the truth's ellipse given as the tracking hint
//! (`seeded at the truth`): a miss that verifies there is the search's, one
//! that does not is the evidence's at the true rim (the lines after `--
//! seeded at the truth --` give its reason).

#[path = "../tests/sweep/mod.rs"]
mod sweep;

use drogue_sim::geometry::V3;
use drogue_sim::sweep::{Sweep, standard_levels};
use drogue_vision::config::Config;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::testing;

fn usage(message: &str) -> ! {
    eprintln!("{message}\nusage: sweep_frame SEED LEVEL INDEX [--crop DIR]");
    std::process::exit(2)
}

/// Half the side of the crop around the drogue, frame pixels.
const CROP_HALF_PX: i64 = 100;

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .with_ansi(false)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (seed, label, index, crop) = match args.as_slice() {
        [seed, label, index] => (seed, label, index, None),
        [seed, label, index, flag, dir] if flag == "--crop" => (seed, label, index, Some(dir)),
        _ => usage("three arguments, then optionally --crop DIR"),
    };
    let seed: u64 = seed
        .parse()
        .unwrap_or_else(|_| usage("SEED: a whole number"));
    let index: u64 = index
        .parse()
        .unwrap_or_else(|_| usage("INDEX: a whole number"));
    let levels = standard_levels();
    let Some(level) = levels.iter().find(|l| l.label() == *label) else {
        let labels: Vec<String> = levels.iter().map(drogue_sim::sweep::Level::label).collect();
        usage(&format!(
            "no level {label:?}; the levels: {}",
            labels.join(", ")
        ))
    };

    let frame = Sweep::new(seed).frame(level, index);
    let s = &frame.settings;
    println!(
        "drawn with: range {:.2} m, tilt {:.0} deg, gain {:.2}, read noise {:.1} DN, vignette {:.2}, \
         haze {:.2}, blur {:.1} px, glare streak {}, glare glow {}, probe {}, distractors {}{}, throat shadow {:.2}, lens k1 {:.2}",
        s.range_m,
        s.tilt_deg,
        s.gain,
        s.read_noise_dn,
        s.vignette,
        s.haze,
        s.blur_px,
        s.glare_width_px
            .map_or("none".into(), |w| format!("{w:.0} px wide")),
        s.glare_glow_sigma_px
            .map_or("none".into(), |w| format!("sigma {w:.0} px")),
        s.probe_bin.map_or("none".into(), |(lo, hi)| format!(
            "over {:.0}-{:.0} % of the rim",
            100.0 * lo,
            100.0 * hi
        )),
        s.distractors,
        if s.star_distractors { " and stars" } else { "" },
        s.throat_shade,
        s.distortion[0],
    );
    let (m, truth) = sweep::measure_one(seed, level, index);
    match &truth {
        Some(t) => println!(
            "truth: ellipse centre ({:.2}, {:.2}) axes {:.2}/{:.2} px (undistorted), range {:.2} m, \
             tilt {:.1} deg, {:.0} % of the rim visible",
            t.ellipse.cx,
            t.ellipse.cy,
            t.ellipse.a,
            t.ellipse.b,
            t.range_m,
            t.tilt_deg,
            100.0 * t.visible_rim_frac
        ),
        None => println!("truth: no drogue"),
    }
    // Where the disc's ellipse centre lies in the frame itself (distorted
    // pixels, as the detector's debug lines give seeds and candidates), to
    // tell which seed was on the disc; its orientation (undistorted).
    if let Some(t) = &truth {
        let c = frame.camera.distort_px([t.ellipse.cx, t.ellipse.cy]);
        println!(
            "truth in the frame: centre ({:.1}, {:.1}) px (distorted), major axis at {:.3} rad (undistorted)",
            c[0], c[1], t.ellipse.theta
        );
    }
    match (&m.detection, &truth) {
        (None, _) => println!("measured: {}", sweep::not_detected(&m)),
        (Some(d), t) => {
            let e = &d.ellipse_px;
            println!(
                "measured: ellipse centre ({:.2}, {:.2}) axes {:.2}/{:.2} px, {:?}",
                e.cx, e.cy, e.a, e.b, d.disambiguation
            );
            if let Some(t) = t {
                let p = &d.pose_camera.centre_camera_m;
                let off = |q: [f64; 3]| {
                    100.0 * (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt() / t.range_m
                };
                // The normal given against the truth's and its mirror's,
                // degrees: the sweep counts more than 10 from the truth's
                // as a false answer.
                let n = &d.pose_camera.normal_camera;
                let normal_off = |q: [f64; 3]| {
                    let dot = (0..3).map(|i| n[i] * q[i]).sum::<f64>();
                    let norm = (0..3).map(|i| q[i] * q[i]).sum::<f64>().sqrt() * n.norm();
                    (dot / norm).clamp(-1.0, 1.0).acos().to_degrees()
                };
                println!(
                    "off: centre {:.3} px, position {:.3} % of range from the truth, {:.3} % from its mirror; normal {:.2} / {:.2} degrees",
                    (e.cx - t.ellipse.cx).hypot(e.cy - t.ellipse.cy),
                    off(t.position_camera),
                    off(t.alt_position_camera),
                    normal_off(t.normal_camera),
                    normal_off(t.alt_normal_camera)
                );
                // The position's reported sigma (root of the covariance's
                // trace) beside its error, mm: whether the covariance
                // covers the answer given.
                let err_m = off(t.position_camera) * t.range_m / 100.0;
                // Along the line of sight (the covariance's long axis):
                // the range's sigma beside the range's error.
                let los = d.position_body_m.vector().normalize();
                let range_sigma_m = (los.transpose() * d.position_cov_body_m2 * los)[(0, 0)]
                    .max(0.0)
                    .sqrt();
                let true_range_m = t.position_camera.iter().map(|x| x * x).sum::<f64>().sqrt();
                println!(
                    "reported position sigma {:.1} mm (root of the trace) for an error of {:.1} mm; range sigma {:.1} mm for a range error of {:+.1} mm",
                    1e3 * d.position_cov_body_m2.trace().max(0.0).sqrt(),
                    1e3 * err_m,
                    1e3 * range_sigma_m,
                    1e3 * (p.norm() - true_range_m)
                );
            }
        }
    }

    // The same frame with the truth's ellipse given as the tracking hint:
    // whether the disc verifies at its true rim, which tells a miss of the
    // search from one of the evidence (as `seeded_frame` does for the
    // reference sets). The detector falls back on a full-frame search when
    // the hint fails; the debug line `not at the tracked ellipse` gives the
    // hint's own reason.
    if let Some(t) = &truth {
        let camera = testing::camera_from_sim(&frame.camera, "sweep");
        let mut detector = testing::detector(&Config::embedded(), &camera);
        let e = &t.ellipse;
        let hint = Ellipse::new(e.cx, e.cy, e.a, e.b, e.theta);
        eprintln!("-- seeded at the truth --");
        match detector.detect_explained(&frame.image, Some(&hint)) {
            Ok(c) => println!(
                "seeded at the truth: verified, centre ({:.2}, {:.2}) axes {:.2}/{:.2} px, score {:.3}",
                c.ellipse_px.cx, c.ellipse_px.cy, c.ellipse_px.a, c.ellipse_px.b, c.score
            ),
            Err(miss) => println!(
                "seeded at the truth: not verified; the full-frame search after it: {}",
                miss.reason
            ),
        }
    }

    if let Some(dir) = crop {
        // Around where the drogue is in the frame (distorted pixels); on a
        // drogue-free frame around what was taken for one (a false
        // detection), else the frame's middle.
        let (w, h) = (frame.image.width(), frame.image.height());
        let centre = truth
            .and_then(|t| {
                let c = t.position_camera;
                frame.camera.project_px(&V3::new(c[0], c[1], c[2]))
            })
            .or_else(|| {
                // The detection's centre is in undistorted pixels: its
                // ray, projected through the lens.
                let c = &frame.camera;
                let e = &m.detection.as_ref()?.ellipse_px;
                c.project_px(&V3::new((e.cx - c.cx) / c.fx, (e.cy - c.cy) / c.fy, 1.0))
            })
            .unwrap_or([f64::from(w) / 2.0, f64::from(h) / 2.0]);
        // At least the disc (or what was taken for it) and some canopy.
        let a = truth
            .map(|t| t.ellipse.a)
            .or_else(|| m.detection.as_ref().map(|d| d.ellipse_px.a))
            .unwrap_or(0.0);
        let half = CROP_HALF_PX.max((1.3 * a).ceil() as i64);
        let clamp = |v: f64, side: u32| {
            (v.round() as i64 - half).clamp(0, (i64::from(side) - 2 * half).max(0)) as u32
        };
        let (x0, y0) = (clamp(centre[0], w), clamp(centre[1], h));
        let side = 2 * half as u32;
        let cut =
            image::imageops::crop_imm(&frame.image, x0, y0, side.min(w), side.min(h)).to_image();
        // Twice its size while that stays under 800 px a side.
        let zoom = if side <= 400 { 2 } else { 1 };
        let big = image::imageops::resize(
            &cut,
            zoom * cut.width(),
            zoom * cut.height(),
            image::imageops::FilterType::Nearest,
        );
        let path = std::path::Path::new(dir).join(format!(
            "sweep_{seed}_{}_{index}.png",
            label.replace([' ', ':', '%', ','], "_")
        ));
        match big.save(&path) {
            Ok(()) => println!(
                "crop ({x0}, {y0}) + {side} px, {zoom} times its size: {}",
                path.display()
            ),
            Err(e) => {
                eprintln!("could not write {}: {e}", path.display());
                std::process::exit(1)
            }
        }
    }
}
