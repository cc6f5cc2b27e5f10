//! Detection on every reference set of the independent renderer, per set
//! (`$DROGUE_REFERENCE_DIR`): detection rate, false detections, gross errors
//! and accuracy, each against its own floor, so that one bad set cannot hide
//! in a pooled figure. Every frame is an unrelated view (no tracking).
//!
//! The floors are what the detector reaches on these files today (a
//! regression guard); the targets of issue 12 are above them for the `hard`
//! sets, and the README says where the detector stands.

mod common;

use common::{angle_deg, measure_reference_set, quantile, v3};
use drogue_vision::config::Config;
use drogue_vision::measure::Disambiguation;
use drogue_vision::testing::reference_set;
use std::path::Path;

/// Floors per set: smallest detection share of the `detect` frames, most
/// gross errors (position > 5 % of range or normal > 10 degrees, the answer
/// given; both normals of an unresolved answer are given), and the largest
/// median centre error (px) and position error (% of range).
struct Floor {
    set: &'static str,
    min_detected: f64,
    max_gross: usize,
    max_centre_median_px: f64,
    max_position_median_pct: f64,
}

const FLOORS: [Floor; 9] = [
    floor("paper10", 1.0, 0),
    floor("range", 1.0, 0),
    floor("tilt", 1.0, 0),
    floor("occlusion", 1.0, 0),
    floor("noise", 1.0, 0),
    // Issue 12 asks 95 % and at most 1 % gross errors of these sets; the
    // floors hold what this detector does (19 of 20 in each; it reports a
    // miss rather than a rim that does not verify at full density).
    floor("hard", 0.95, 0),
    floor("hard_b", 0.95, 0),
    floor("hard_c", 0.95, 0),
    floor("negative", 1.0, 0),
];

const fn floor(set: &'static str, min_detected: f64, max_gross: usize) -> Floor {
    Floor {
        set,
        min_detected,
        max_gross,
        max_centre_median_px: 0.05,
        max_position_median_pct: 0.3,
    }
}

#[derive(Debug, Default)]
struct SetResult {
    expected: usize,
    detected: usize,
    false_detections: usize,
    gross: Vec<String>,
    centre_px: Vec<f64>,
    position_pct: Vec<f64>,
}

fn measure_set(set: &Path) -> SetResult {
    let mut r = SetResult::default();
    for (t, m) in measure_reference_set(set, &Config::embedded()) {
        let Some(d) = m.detection else {
            if t.expect == "detect" {
                r.expected += 1;
            }
            continue;
        };
        if t.expect != "detect" {
            r.false_detections += 1;
            continue;
        }
        r.expected += 1;
        r.detected += 1;
        let (te, tp, tn) = (
            t.ellipse.expect("truth ellipse"),
            v3(t.position_camera.expect("truth position")),
            v3(t.normal_camera.expect("truth normal")),
        );
        let range = t.range_m.unwrap_or_else(|| tp.norm());
        let e = d.ellipse_px;
        let centre = (e.cx - te.cx).hypot(e.cy - te.cy);
        let position = 100.0 * (*d.pose_camera.centre_camera_m - tp).norm() / range;
        let mut normal = angle_deg(&d.pose_camera.normal_camera, &tn);
        if d.disambiguation == Disambiguation::Unresolved
            && let Some(alt) = &d.alt_pose_camera
        {
            normal = normal.min(angle_deg(&alt.normal_camera, &tn));
        }
        r.centre_px.push(centre);
        r.position_pct.push(position);
        if position > 5.0 || normal > 10.0 {
            r.gross.push(format!(
                "{}: centre {centre:.2} px, position {position:.2} %, normal {normal:.1} deg",
                t.frame
            ));
        }
    }
    r
}

#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn every_reference_set_meets_its_floor() {
    let mut failures = Vec::new();
    for f in &FLOORS {
        let r = measure_set(&reference_set(f.set));
        let share = if r.expected == 0 {
            1.0
        } else {
            r.detected as f64 / r.expected as f64
        };
        let (c50, p50) = (quantile(&r.centre_px, 0.5), quantile(&r.position_pct, 0.5));
        println!(
            "{:9} detected {}/{} ({:.0} %), false {}, gross {}, centre median {c50:.3} px, \
             position median {p50:.3} % of range",
            f.set,
            r.detected,
            r.expected,
            100.0 * share,
            r.false_detections,
            r.gross.len()
        );
        for g in &r.gross {
            println!("          gross: {g}");
        }
        if share < f.min_detected {
            failures.push(format!("{}: detected {:.0} %", f.set, 100.0 * share));
        }
        if r.false_detections > 0 {
            failures.push(format!(
                "{}: {} false detections",
                f.set, r.false_detections
            ));
        }
        if r.gross.len() > f.max_gross {
            failures.push(format!("{}: {} gross errors", f.set, r.gross.len()));
        }
        if r.detected > 0 && !(c50 <= f.max_centre_median_px && p50 <= f.max_position_median_pct) {
            failures.push(format!(
                "{}: centre median {c50:.3} px, position {p50:.3} %",
                f.set
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
