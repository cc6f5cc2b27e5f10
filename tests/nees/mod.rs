//! Consistency of the position covariance, shared by `tests/pose_nees.rs`
//! and `examples/pose_nees.rs`: the normalised estimation error squared
//! (NEES, `e^T C^-1 e` for the position error `e` against the truth and the
//! reported covariance `C`) per detected frame, gathered per set (a
//! reference set, a simulator sweep level, a simulator scenario run) and
//! summarised per set, never pooled. For an honest covariance and Gaussian
//! errors NEES follows chi-square with 3 degrees of freedom: median 2.37,
//! mean 3, 90th percentile 6.25, 1 % above 11.34.
//!
//! Every truth comes from the simulator or the reference files, never from
//! the code under test.
#![allow(dead_code)]

use drogue_sim::camera::SimCamera;
use drogue_sim::sweep::{Level, Sweep};
use drogue_sim::{Scenario, Simulator};
use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::measure::{Detection, Measurer};
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// chi-square(3)'s 99 % point: an honest covariance leaves 1 % above it.
pub const CHI2_3_P99: f64 = 11.345;
/// chi-square(3)'s median.
pub const CHI2_3_MEDIAN: f64 = 2.366;
/// A detection more than this share of the range off is a wrong detection
/// (another object, a wrong rim), not a measurement error: counted apart.
pub const GROSS_POSITION_REL: f64 = 0.05;
/// The sweep's seed for NEES runs: other frames than the robustness sweep's.
pub const SEED: u64 = 15;

/// One detected frame.
#[derive(Clone, Debug)]
pub struct FrameNees {
    pub label: String,
    pub nees: f64,
    /// Position error, metres.
    pub error_m: f64,
    /// sqrt(trace C), metres.
    pub sigma_m: f64,
    pub range_m: f64,
    pub inliers: usize,
    pub rms_px: f64,
    /// Error along the line of sight and its reported sigma, metres.
    pub error_range_m: f64,
    pub sigma_range_m: f64,
    /// Error across the line of sight, and the reported sigma in its direction.
    pub error_lateral_m: f64,
    pub sigma_lateral_m: f64,
}

/// NEES of a set's detections.
#[derive(Clone, Debug, Default)]
pub struct SetNees {
    pub name: String,
    /// Frames where a detection was expected.
    pub expected: usize,
    pub frames: Vec<FrameNees>,
    /// Detections more than [`GROSS_POSITION_REL`] off (not scored).
    pub gross: usize,
    /// Detections without a usable covariance (NaN or singular).
    pub no_covariance: usize,
    /// Detections whose normal is the mirror solution's (the single-circle
    /// ambiguity settled wrongly or not at all): scored against the mirror
    /// pose's centre, which images to the very same ellipse (the position
    /// covariance is that of the ellipse; which branch is right is the
    /// disambiguation's to say, reported apart).
    pub wrong_branch: usize,
    /// Score every frame against the true centre, also when the solution
    /// given is the mirror's (the error PX4 gets when the ambiguity is
    /// settled wrongly).
    pub against_truth: bool,
}

/// The q-quantile (0..1), linear between order statistics; NaN for none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let x = q * (v.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    if i + 1 < v.len() {
        v[i] + f * (v[i + 1] - v[i])
    } else {
        v[i]
    }
}

impl SetNees {
    /// The same frames with every standard deviation multiplied by `scale`
    /// (as `[link] target_relative_std_scale` does for TARGET_RELATIVE).
    pub fn scaled(&self, scale: f64) -> SetNees {
        let mut out = self.clone();
        out.name = format!("{} (std x {scale})", self.name);
        for f in &mut out.frames {
            f.nees /= scale * scale;
        }
        out
    }

    pub fn values(&self) -> Vec<f64> {
        self.frames.iter().map(|f| f.nees).collect()
    }
    pub fn count(&self) -> usize {
        self.frames.len()
    }
    pub fn median(&self) -> f64 {
        quantile(&self.values(), 0.5)
    }
    pub fn mean(&self) -> f64 {
        let v = self.values();
        v.iter().sum::<f64>() / v.len() as f64
    }
    pub fn p90(&self) -> f64 {
        quantile(&self.values(), 0.9)
    }
    /// Share of the scored frames above chi-square(3)'s 99 % point.
    pub fn share_above_p99(&self) -> f64 {
        let v = self.values();
        v.iter().filter(|&&x| x > CHI2_3_P99).count() as f64 / v.len() as f64
    }
    /// Frames above chi-square(3)'s 99 % point.
    pub fn above_p99(&self) -> usize {
        self.frames.iter().filter(|f| f.nees > CHI2_3_P99).count()
    }

    /// One markdown row: set | n | median | mean | p90 | share > 11.34 | gross.
    pub fn row(&self) -> String {
        format!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.0} % ({}) | {} | {} |",
            self.name,
            self.count(),
            self.median(),
            self.mean(),
            self.p90(),
            100.0 * self.share_above_p99(),
            self.above_p99(),
            self.gross,
            self.wrong_branch,
        )
    }

    pub fn header() -> &'static str {
        "| set | frames | NEES median | mean | p90 | > 11.34 | gross | mirror |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    }

    /// Scores one measurement against the true centre (camera frame).
    /// The NEES is taken in the body frame, where the covariance is given
    /// (it is the same in any rotated frame).
    fn score(
        &mut self,
        label: String,
        measurer: &Measurer,
        detection: Option<&Detection>,
        truth: [Vector3<f64>; 4],
    ) {
        let [true_centre_camera, true_normal, alt_centre, alt_normal] = truth;
        self.expected += 1;
        let Some(d) = detection else {
            return;
        };
        let n = d.pose_camera.normal_camera;
        let angle = |a: &Vector3<f64>, b: &Vector3<f64>| a.cross(b).norm().atan2(a.dot(b));
        let wrong = angle(&n, &alt_normal) < angle(&n, &true_normal);
        self.wrong_branch += usize::from(wrong);
        let centre = if wrong && !self.against_truth {
            alt_centre
        } else {
            true_centre_camera
        };
        let e_camera = *d.pose_camera.centre_camera_m - centre;
        let range = true_centre_camera.norm();
        if e_camera.norm() > GROSS_POSITION_REL * range {
            self.gross += 1;
            return;
        }
        // A displacement: rotated into body axes, no translation.
        let e = measurer.mount().q_body_camera() * e_camera;
        let c: Matrix3<f64> = d.position_cov_body_m2;
        let Some(nees) = c
            .cholesky()
            .map(|ch| e.dot(&ch.solve(&e)))
            .filter(|x| x.is_finite())
        else {
            self.no_covariance += 1;
            return;
        };
        let u = measurer.mount().q_body_camera() * true_centre_camera.normalize();
        let along = e.dot(&u);
        let lateral = e - u * along;
        let lateral_dir = lateral.try_normalize(1e-15).unwrap_or(u);
        self.frames.push(FrameNees {
            error_range_m: along,
            sigma_range_m: u.dot(&(c * u)).max(0.0).sqrt(),
            error_lateral_m: lateral.norm(),
            sigma_lateral_m: lateral_dir.dot(&(c * lateral_dir)).max(0.0).sqrt(),
            label,
            nees,
            error_m: e.norm(),
            sigma_m: c.trace().max(0.0).sqrt(),
            range_m: range,
            inliers: d.quality.inliers,
            rms_px: d.quality.rms_residual_px,
        });
    }
}

fn v3(v: &Value) -> Option<Vector3<f64>> {
    let a = v.as_array()?;
    Some(Vector3::new(a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?))
}

/// The reference set `name` in `dir`, each frame unrelated (the track is
/// forgotten before each). Panics when the set is missing: a run on purpose
/// must never pass without measuring.
pub fn reference_set(dir: &Path, name: &str) -> SetNees {
    reference_set_scored(dir, name, false)
}

/// [`reference_set`], scored against the true centre also where the
/// solution given is the mirror's when `against_truth`.
pub fn reference_set_scored(dir: &Path, name: &str, against_truth: bool) -> SetNees {
    let set = dir.join(name);
    let truth = std::fs::read_to_string(set.join("truth.jsonl"))
        .unwrap_or_else(|e| panic!("{}: {e}", set.join("truth.jsonl").display()));
    let camera = CameraModel::load(&set.join("camera.yaml")).expect("camera.yaml");
    let mut measurer = Measurer::new(camera, &Config::embedded().measure()).expect("measurer");
    let mut out = SetNees {
        name: name.to_string(),
        against_truth,
        ..Default::default()
    };
    for (seq, line) in truth.lines().filter(|l| !l.trim().is_empty()).enumerate() {
        let t: Value = serde_json::from_str(line).expect("truth line");
        if t["expect"].as_str() != Some("detect") {
            continue;
        }
        let (Some(file), Some(centre)) = (t["frame"].as_str(), v3(&t["position_camera"])) else {
            continue;
        };
        let image = drogue_vision::image_io::read_gray8(&set.join(file), None).expect("frame");
        measurer.forget_track();
        let m = measurer.measure(&Frame {
            seq: seq as u64,
            capture_time_ns: 0,
            image,
            origin: FrameOrigin::File(set.join(file)),
        });
        let truth = [
            centre,
            v3(&t["normal_camera"]).expect("normal_camera"),
            v3(&t["alt_position_camera"]).expect("alt_position_camera"),
            v3(&t["alt_normal_camera"]).expect("alt_normal_camera"),
        ];
        let scene = &t["scene"];
        let label = format!(
            "{file} {} blur {:.1} noise {:.1} tilt {:.0} range {:.1} probe {:.2}",
            t["group"].as_str().unwrap_or("-"),
            scene["blur"]["len"].as_f64().unwrap_or(0.0),
            scene["noise_sigma"].as_f64().unwrap_or(0.0),
            t["tilt_deg"].as_f64().unwrap_or(f64::NAN),
            t["range_m"].as_f64().unwrap_or(f64::NAN),
            t["probe_rim_frac"].as_f64().unwrap_or(0.0),
        );
        out.score(label, &measurer, m.detection.as_ref(), truth);
    }
    out
}

/// drogue-vision's model of a simulator camera.
fn camera_model(cam: &SimCamera) -> CameraModel {
    let k = Matrix3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0);
    CameraModel::new("sweep", cam.width, cam.height, k, cam.distortion)
        .expect("the sweep's camera is valid")
}

/// `frames` frames of a sweep level (unrelated views, the simulator's
/// exact truth). Frames the truth does not expect detected are skipped.
pub fn sweep_level(sweep: &mut Sweep, level: &Level, frames: u64) -> SetNees {
    let mut out = SetNees {
        name: format!("sim {}", level.label()),
        ..Default::default()
    };
    let mut measurers: Vec<([f64; 5], Measurer)> = Vec::new();
    for index in 0..frames {
        let f = sweep.frame(level, index);
        let Some(t) = f.drogue.filter(|t| t.expect_detect) else {
            continue;
        };
        let i = match measurers
            .iter()
            .position(|(d, _)| *d == f.camera.distortion)
        {
            Some(i) => i,
            None => {
                let m = Measurer::new(camera_model(&f.camera), &Config::embedded().measure())
                    .expect("measurer");
                measurers.push((f.camera.distortion, m));
                measurers.len() - 1
            }
        };
        let measurer = &mut measurers[i].1;
        measurer.forget_track();
        let m = measurer.measure(&Frame {
            seq: index,
            capture_time_ns: 0,
            image: f.image,
            origin: FrameOrigin::File(PathBuf::from(format!("sweep/{}/{index}", level.label()))),
        });
        let c = &f.settings;
        let label = format!(
            "{} #{index} tilt {:.0} range {:.1} probe {:.2} blur {:.1} noise {:.1} haze {:.2} gain {:.2} glare {:.0}",
            level.label(),
            t.tilt_deg,
            t.range_m,
            t.probe_rim_frac,
            c.blur_px,
            c.read_noise_dn,
            c.haze,
            c.gain,
            c.glare_width_px.unwrap_or(0.0),
        );
        let truth = [
            t.position_camera,
            t.normal_camera,
            t.alt_position_camera,
            t.alt_normal_camera,
        ]
        .map(|c| Vector3::new(c[0], c[1], c[2]));
        out.score(label, measurer, m.detection.as_ref(), truth);
    }
    out
}

/// Frames `skip..skip + count` of a built-in scenario, in sequence (tracked,
/// as `run` measures them), every `stride`-th frame scored... all frames
/// are measured so that the track is the one `run` has.
pub fn scenario(name: &str, skip: usize, count: usize) -> SetNees {
    let mut sim = Simulator::new(Scenario::builtin(name).expect("scenario")).expect("simulator");
    let mut config = Config::embedded();
    config.mount = drogue_vision::source::sim::mount_config(sim.mount());
    config.drogue.inner_radius_m = sim.inner_radius_m();
    config.drogue.canopy_radius_m = sim.canopy_radius_m();
    let camera = drogue_vision::source::sim::camera_model(&sim).expect("camera");
    let mut measurer = Measurer::new(camera, &config.measure()).expect("measurer");
    let mut out = SetNees {
        name: format!("sim scenario {name} {skip}-{}", skip + count),
        ..Default::default()
    };
    for (image, truth) in sim.by_ref().skip(skip).take(count) {
        let frame = Frame {
            seq: truth.seq,
            capture_time_ns: (truth.t * 1e9) as u64,
            image,
            origin: FrameOrigin::File(PathBuf::from(format!("sim/{name}/{}", truth.seq))),
        };
        let m = measurer.measure(&frame);
        if !(truth.expect == "detect" && truth.probe_rim_frac <= 0.4) {
            continue;
        }
        let label = format!(
            "{name} #{} tilt {:.0} range {:.1} probe {:.2}",
            truth.seq, truth.tilt_deg, truth.range_m, truth.probe_rim_frac
        );
        let t = [
            truth.position_camera,
            truth.normal_camera,
            truth.alt_position_camera,
            truth.alt_normal_camera,
        ]
        .map(|c| Vector3::new(c[0], c[1], c[2]));
        out.score(label, &measurer, m.detection.as_ref(), t);
    }
    out
}
