//! Shared helpers of the integration tests: truth comparison and statistics.
//! Every expected value comes from the simulator's or the reference data's
//! truth, never from the code under test. The reference folder, its truth
//! records and the fixtures that benches share too are in
//! `drogue_vision::testing`.
#![allow(dead_code)]

use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::image_io::read_gray8;
use drogue_vision::measure::{Measurement, Measurer};
use drogue_vision::testing::{Truth, read_truths};
use nalgebra::Vector3;
use std::path::Path;

/// Measures every frame of a reference set (its `camera.yaml`, its
/// `truth.jsonl` order) as an unrelated view: the track is forgotten before
/// each frame, so no frame borrows from the one before.
pub fn measure_reference_set(set: &Path, config: &Config) -> Vec<(Truth, Measurement)> {
    let camera = CameraModel::load(&set.join("camera.yaml")).expect("camera.yaml");
    let mut measurer = Measurer::new(camera, &config.measure()).expect("measurer");
    read_truths(set)
        .into_iter()
        .enumerate()
        .map(|(seq, t)| {
            let path = set.join(&t.frame);
            let image = read_gray8(&path, None).expect("reference frame");
            measurer.forget_track();
            let m = measurer.measure(&Frame {
                seq: seq as u64,
                capture_time_ns: 0,
                image,
                origin: FrameOrigin::File(path),
            });
            (t, m)
        })
        .collect()
}

/// Errors of one detected frame against its truth.
#[derive(Clone, Copy, Debug)]
pub struct FrameErrors {
    pub centre_px: f64,
    pub axes_px: f64,
    /// Only for clearly elliptic images (a/b > 1.05): theta is undefined for a circle.
    pub theta_deg: Option<f64>,
    /// Position error over range.
    pub position_rel: f64,
    /// Angle between the normal given and the truth normal.
    pub normal_deg: f64,
    pub range_m: f64,
}

pub fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

pub fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.dot(b) / (a.norm() * b.norm()))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Compares a measurement with the truth; `None` when either has no drogue.
pub fn errors(m: &Measurement, t: &Truth) -> Option<FrameErrors> {
    let d = m.detection.as_ref()?;
    let te = t.ellipse?;
    let tp = v3(t.position_camera?);
    let tn = v3(t.normal_camera?);
    let e = d.ellipse_px;
    let range = t.range_m.unwrap_or_else(|| tp.norm());
    Some(FrameErrors {
        centre_px: ((e.cx - te.cx).powi(2) + (e.cy - te.cy).powi(2)).sqrt(),
        axes_px: (e.a - te.a).abs().max((e.b - te.b).abs()),
        theta_deg: (te.a / te.b > 1.05).then(|| e.theta_error_rad(&te).to_degrees()),
        position_rel: (*d.pose_camera.centre_camera_m - tp).norm() / range,
        normal_deg: angle_deg(&d.pose_camera.normal_camera, &tn),
        range_m: range,
    })
}

/// The q-quantile (0..1) of some values (nearest rank); NaN for none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let idx = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[idx]
}

/// Median and 95th percentile of a field over frames.
pub fn med_p95(errs: &[FrameErrors], f: impl Fn(&FrameErrors) -> Option<f64>) -> (f64, f64) {
    let v: Vec<f64> = errs.iter().filter_map(f).collect();
    (quantile(&v, 0.5), quantile(&v, 0.95))
}

/// One line summarising accuracy, printed by the tests (run with --nocapture).
pub fn report(name: &str, errs: &[FrameErrors]) -> String {
    let (c50, c95) = med_p95(errs, |e| Some(e.centre_px));
    let (a50, a95) = med_p95(errs, |e| Some(e.axes_px));
    let (t50, t95) = med_p95(errs, |e| e.theta_deg);
    let (p50, p95) = med_p95(errs, |e| Some(e.position_rel * 100.0));
    let (n50, n95) = med_p95(errs, |e| Some(e.normal_deg));
    format!(
        "{name}: {} frames | centre px med {c50:.3} p95 {c95:.3} | axes px med {a50:.3} p95 {a95:.3} \
         | theta deg med {t50:.3} p95 {t95:.3} | position %range med {p50:.3} p95 {p95:.3} \
         | normal deg med {n50:.3} p95 {n95:.3}",
        errs.len()
    )
}
