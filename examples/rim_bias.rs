//! Calibration aid for the pose covariance's systematic term: on simulator
//! sweep frames (exact truth), the detector's inlier rim points against the
//! TRUE ellipse. Per frame: the mean step width, the mean signed offset of
//! the points from the true rim (outward +), the least-squares `beta` in
//! `offset_i ~ beta * width_i`, and the points' scatter about that, with
//! the settings the frame was drawn with; per level, the mean offset of its
//! blurred and its sharp frames apart.
//!
//! `cargo run --release --example rim_bias -- [--frames N] [--only TEXT]
//! [--throat-shade S] [--reference DIR]`: `--throat-shade` draws every
//! frame with a throat shadow of strength S (from 0 up to but not 1, the
//! canopy's share darkened at the disc's edge), so that blur's effect over
//! a shaded canopy can be told from blur's alone (README, "Blur over a
//! shaded canopy").

use drogue_sim::sweep::{Sweep, standard_levels};
use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::measure::detect::Detector;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::fit::Fitter;
use nalgebra::{Matrix2, Matrix3, Vector2};

fn signed_distance(e: &Ellipse, p: [f64; 2]) -> f64 {
    // Scale along the point's own ray from the centre: first order the
    // distance along the normal for near-circles; enough for the mean.
    let (s, c) = e.theta.sin_cos();
    let rot = Matrix2::new(c, -s, s, c);
    let q = rot.transpose() * Vector2::new(p[0] - e.cx, p[1] - e.cy);
    let rho = ((q.x / e.a).powi(2) + (q.y / e.b).powi(2)).sqrt();
    let dist = q.norm();
    // Point on the ellipse along the same ray is at dist / rho.
    let radial = dist - dist / rho;
    // Project the radial offset onto the normal there.
    let on = q / rho;
    let n = Vector2::new(on.x / (e.a * e.a), on.y / (e.b * e.b)).normalize();
    radial * n.dot(&(q / dist))
}

/// One frame: (mean width, mean offset, beta, scatter, rms, n, b).
fn frame_bias(
    config: &Config,
    camera: &CameraModel,
    image: &image::GrayImage,
    te: &Ellipse,
    seed: u64,
) -> Option<[f64; 9]> {
    let mut det = Detector::new(
        &config.detect,
        camera,
        drogue_vision::testing::drogue_circles(config),
    );
    let c = det.detect(image, None)?;
    let fit = Fitter::new(&config.fit)
        .fit(&c.rim_points_undistorted_px, seed)
        .ok()?;
    let (mut sdw, mut sww, mut sd, mut sw, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut sdq, mut sqq) = (0.0, 0.0);
    let mut pts = Vec::new();
    for ((p, w), keep) in c
        .rim_points_undistorted_px
        .iter()
        .zip(&c.rim_step_widths_px)
        .zip(&fit.inliers)
    {
        if !keep {
            continue;
        }
        let d = signed_distance(te, *p);
        let q = w * w / curvature_radius(te, *p);
        sdq += d * q;
        sqq += q * q;
        sdw += d * w;
        sww += w * w;
        sd += d;
        sw += w;
        n += 1.0;
        pts.push((d, *w));
    }
    let beta = sdw / sww;
    let scatter = (pts.iter().map(|(d, w)| (d - beta * w).powi(2)).sum::<f64>() / n).sqrt();
    let _ = &mut pts;
    Some([
        sw / n,
        sd / n,
        beta,
        scatter,
        fit.rms_residual_px,
        n,
        te.b,
        sdq / sqq,
        fit.rms_residual_px.powi(2) / sqq,
    ])
}

/// Radius of curvature of `e` at the point nearest in angle to `p`.
fn curvature_radius(e: &Ellipse, p: [f64; 2]) -> f64 {
    let (s, c) = e.theta.sin_cos();
    let (x, y) = (p[0] - e.cx, p[1] - e.cy);
    let (u, v) = (c * x + s * y, -s * x + c * y);
    let t = (v / e.b).atan2(u / e.a);
    let (st, ct) = t.sin_cos();
    (e.a * e.a * st * st + e.b * e.b * ct * ct).powf(1.5) / (e.a * e.b)
}

/// The usage, after what was wrong with the arguments; exit status 2.
fn usage(message: &str) -> ! {
    eprintln!(
        "{message}\nusage: rim_bias [--frames N] [--only TEXT] [--throat-shade S] [--reference DIR]"
    );
    std::process::exit(2)
}

fn main() {
    let mut frames = 20u64;
    let mut only: Option<String> = None;
    let mut reference: Option<std::path::PathBuf> = None;
    let mut throat_shade: Option<f64> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| {
            args.next()
                .unwrap_or_else(|| usage(&format!("{name} needs a value")))
        };
        match a.as_str() {
            "--frames" => {
                frames = value("--frames")
                    .parse()
                    .unwrap_or_else(|_| usage("--frames: a whole number"));
            }
            "--only" => only = Some(value("--only")),
            "--reference" => reference = Some(value("--reference").into()),
            "--throat-shade" => {
                throat_shade = Some(
                    value("--throat-shade")
                        .parse()
                        .unwrap_or_else(|_| usage("--throat-shade: a number")),
                );
            }
            other => usage(&format!("unknown argument {other}")),
        }
    }
    let config = Config::embedded();
    if let Some(dir) = reference {
        for set in drogue_vision::testing::DROGUE_REFERENCE_SETS {
            let d = dir.join(set);
            let camera = CameraModel::load(&d.join("camera.yaml")).unwrap();
            for line in std::fs::read_to_string(d.join("truth.jsonl"))
                .unwrap()
                .lines()
            {
                let t: serde_json::Value = serde_json::from_str(line).unwrap();
                if t["expect"].as_str() != Some("detect") {
                    continue;
                }
                let e = &t["ellipse"];
                let f = |k: &str| e[k].as_f64().unwrap();
                let te = Ellipse::new(f("cx"), f("cy"), f("a"), f("b"), f("theta"));
                let file = t["frame"].as_str().unwrap();
                let image = drogue_vision::image_io::read_gray8(&d.join(file), None).unwrap();
                if let Some(r) = frame_bias(&config, &camera, &image, &te, 0) {
                    println!(
                        "{set:<10} {file} blur {:5.1} noise {:4.1} b {:6.1} w {:6.2} d {:+.3} beta {:+.4} scatter {:.3} rms {:.3} n {} c {:+.4}",
                        t["scene"]["blur"]["len"].as_f64().unwrap_or(0.0),
                        t["scene"]["noise_sigma"].as_f64().unwrap_or(0.0),
                        r[6],
                        r[0],
                        r[1],
                        r[2],
                        r[3],
                        r[4],
                        r[5],
                        r[7]
                    );
                }
            }
        }
        return;
    }
    let mut sweep = match throat_shade {
        Some(strength) => Sweep::new(15)
            .with_throat_shade(strength)
            .unwrap_or_else(|| usage("--throat-shade: from 0 up to but not 1")),
        None => Sweep::new(15),
    };
    let mut all_c: Vec<f64> = Vec::new();
    for level in standard_levels()
        .into_iter()
        .filter(|l| l.factor.has_drogue())
    {
        if !only.as_deref().is_none_or(|o| level.label().contains(o)) {
            continue;
        }
        let (mut betas, mut sum_w, mut cs) = (Vec::new(), 0.0, Vec::<f64>::new());
        let mut cvars = Vec::<f64>::new();
        let mut ks = Vec::<(f64, f64)>::new();
        // Mean offsets of the frames drawn with and without motion blur.
        let (mut blurred, mut sharp) = (Vec::<f64>::new(), Vec::<f64>::new());
        for index in 0..frames {
            let f = sweep.frame(&level, index);
            let Some(t) = f.drogue.filter(|t| t.expect_detect) else {
                continue;
            };
            let cam = &f.camera;
            let k = Matrix3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0);
            let camera = CameraModel::new("s", cam.width, cam.height, k, cam.distortion).unwrap();
            let te = Ellipse::new(
                t.ellipse.cx,
                t.ellipse.cy,
                t.ellipse.a,
                t.ellipse.b,
                t.ellipse.theta,
            );
            let Some(r) = frame_bias(&config, &camera, &f.image, &te, index) else {
                continue;
            };
            let set = &f.settings;
            println!(
                "{:<24} #{index:2} n {:4} b {:6.1} w mean {:6.2} d mean {:+.3} beta {:+.4} scatter {:.3} rms {:.3} c {:+.4} | blur {:.1} noise {:.1} haze {:.2} gain {:.2} glare {} probe {} throat {:.2}",
                level.label(),
                r[5],
                r[6],
                r[0],
                r[1],
                r[2],
                r[3],
                r[4],
                r[7],
                set.blur_px,
                set.read_noise_dn,
                set.haze,
                set.gain,
                set.glare_width_px
                    .map_or("-".into(), |w| format!("{w:.0}px")),
                set.probe_bin.map_or("-".into(), |(lo, hi)| format!(
                    "{:.0}-{:.0}%",
                    100.0 * lo,
                    100.0 * hi
                )),
                set.throat_shade
            );
            if set.blur_px > 0.0 {
                blurred.push(r[1]);
            } else {
                sharp.push(r[1]);
            }
            betas.push(r[2]);
            cs.push(r[7]);
            cvars.push(r[8]);
            // Common-mode offset in units of the points' scatter, its own
            // noise (1 / n) removed below.
            ks.push(((r[1] - r[7].clamp(-1.0, 1.0) * 0.0) / r[4], 1.0 / r[5]));
            sum_w += r[0];
        }
        let rms_c = (cs.iter().map(|c| c * c).sum::<f64>() / cs.len() as f64).sqrt();
        let mean_c = cs.iter().sum::<f64>() / cs.len() as f64;
        all_c.extend(cs.iter().copied());
        // The estimate's own noise (the points' scatter) removed: c^2 = E[c_hat^2] - var.
        let corrected = (cs.iter().zip(&cvars).map(|(c, v)| c * c - v).sum::<f64>()
            / cs.len() as f64)
            .max(0.0)
            .sqrt();
        let kappa = (ks.iter().map(|(k, v)| k * k - v).sum::<f64>() / ks.len() as f64)
            .max(0.0)
            .sqrt();
        println!(
            "== {}: kappa = mean offset / scatter, noise-corrected rms {kappa:.4}",
            level.label()
        );
        println!(
            "== {}: c = offset / (w^2 / rho): rms {rms_c:.4} mean {mean_c:+.4} noise-corrected rms {corrected:.4}",
            level.label()
        );
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        println!(
            "== {}: mean offset (outward +), px: blurred frames {:+.3} ({}), sharp frames {:+.3} ({})",
            level.label(),
            mean(&blurred),
            blurred.len(),
            mean(&sharp),
            sharp.len()
        );
        let ms = betas.iter().map(|b| b * b).sum::<f64>() / betas.len() as f64;
        println!(
            "== {}: frames {} mean width {:.2} rms beta {:.4} mean beta {:+.4}",
            level.label(),
            betas.len(),
            sum_w / betas.len() as f64,
            ms.sqrt(),
            betas.iter().sum::<f64>() / betas.len() as f64
        );
    }
    let rms = (all_c.iter().map(|c| c * c).sum::<f64>() / all_c.len() as f64).sqrt();
    let mut sorted = all_c.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "== all levels: {} frames, c rms {rms:.4} (1 / {:.1}), median {:+.4}, mean {:+.4}",
        all_c.len(),
        1.0 / rms,
        sorted[sorted.len() / 2],
        all_c.iter().sum::<f64>() / all_c.len() as f64
    );
}
