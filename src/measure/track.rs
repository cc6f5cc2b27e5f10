//! Temporal tracking: the ambiguity settled by the canopy rim or by
//! continuity, a constant-velocity prediction of the ellipse for the ROI
//! search and of the rim's motion during the exposure (the motion blur
//! the next frame should show), and track epochs (MAVLink `reset_counter`).
//!
//! A track lives while detections keep coming no more than `max_gap_ms`
//! apart; a longer gap (or time running backwards, e.g. a replay jumping)
//! ends it, and the next detection starts a new track with the next epoch.
//!
//! Continuity is stricter than the track: it settles the ambiguity only when
//! the last detection is at most `continuity_max_gap_ms` old and the new
//! centre is within what the drogue can move in that time
//! (`continuity_max_speed_mps`, plus [`CONTINUITY_POSITION_NOISE`] of the
//! range for the measurement's own scatter). A folder of unrelated images
//! processed as a sequence (`process` without `--independent` stamps them
//! 33 ms apart) then does not hand one image's normal to the next: their
//! drogues are not where the last one was.

use super::Disambiguation;
use super::ellipse::{Ellipse, ExposureSweep};
use super::pose::{CirclePose, EllipseParams, ellipse_from_params, ellipse_params};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

/// `[track]` in the config.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackConfig {
    /// A track without a detection for longer than this ends, milliseconds.
    pub max_gap_ms: f64,
    /// The canopy rim settles the ambiguity when the two solutions' supports
    /// (0..1) differ by at least this much...
    pub canopy_min_difference: f64,
    /// ...and the better one has at least this support (0..1).
    pub canopy_min_support: f64,
    /// Continuity settles it when one solution's normal is closer to the
    /// tracked normal (extrapolated at constant angular velocity) than the
    /// other's by at least this, degrees.
    pub continuity_margin_deg: f64,
    /// Continuity may settle the ambiguity only when the last detection is at
    /// most this old, milliseconds.
    #[serde(default = "default_continuity_max_gap_ms")]
    pub continuity_max_gap_ms: f64,
    /// ... and the drogue's centre has moved no faster than this since,
    /// metres per second (relative to the camera).
    #[serde(default = "default_continuity_max_speed_mps")]
    pub continuity_max_speed_mps: f64,
}

fn default_continuity_max_gap_ms() -> f64 {
    100.0
}

fn default_continuity_max_speed_mps() -> f64 {
    5.0
}

/// Scatter of a measured centre allowed on top of the motion, as a share of
/// the range: the position error is ~0.1 % of the range on clear frames and
/// a few tenths of a percent on hard ones.
pub const CONTINUITY_POSITION_NOISE: f64 = 0.01;

/// The tracker's decision for one frame.
#[derive(Clone, Copy, Debug)]
pub struct Choice {
    /// The solution given, camera frame.
    pub pose: CirclePose,
    /// The other solution while unresolved.
    pub alternative: Option<CirclePose>,
    /// How the ambiguity was settled.
    pub how: Disambiguation,
    /// Incremented each time the track is lost and found again.
    pub track_epoch: u32,
}

/// What the track remembers of its last detection.
#[derive(Clone, Copy, Debug)]
struct TrackState {
    time_ns: u64,
    ellipse: EllipseParams,
    /// Rate of change of `ellipse` per second, once two detections are known.
    velocity_per_s: Option<EllipseParams>,
    normal_camera: Vector3<f64>,
    /// Centre of the chosen pose, camera frame, metres.
    centre_camera_m: Vector3<f64>,
    /// The tracked normal came from a settled ambiguity (rim or continuity
    /// from a settled one), so continuity may settle the next frame.
    resolved: bool,
}

/// The track across frames: predicts the next ellipse (the search
/// window) and settles the ambiguity by the canopy, else by continuity.
#[derive(Clone)]
pub struct Tracker {
    max_gap_ns: u64,
    canopy_min_difference: f64,
    canopy_min_support: f64,
    continuity_margin_rad: f64,
    continuity_max_gap_ns: u64,
    continuity_max_speed_mps: f64,
    track: Option<TrackState>,
    /// The current track's last chosen normals with their times, oldest first.
    normals: VecDeque<(u64, Vector3<f64>)>,
    epoch: u32,
    tracked_before: bool,
}

fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// Chosen normals remembered for the continuity prediction.
const NORMAL_HISTORY: usize = 8;

/// Longest extrapolation of the normal, radians (about 11 degrees): a
/// prediction further out than that is no better than the last normal.
const MAX_NORMAL_EXTRAPOLATION_RAD: f64 = 0.2;

/// The normal expected at `time_ns` from the track's recent normals (oldest
/// first, at least one): a least-squares straight line through them in time,
/// i.e. constant angular velocity, fitted over several frames so that the
/// fit's noise does not drive it. This matters when the drogue swings through
/// a frontal view: there the two solutions meet and part again, the true one
/// carrying on, the mirror one turning back; the last normal alone cannot
/// tell them apart.
fn predicted_normal(history: &VecDeque<(u64, Vector3<f64>)>, time_ns: u64) -> Option<Vector3<f64>> {
    let &(last_ns, last) = history.back()?;
    let seconds = |t: u64| (t as f64 - last_ns as f64) * 1e-9;
    let n = history.len() as f64;
    let mean_t = history.iter().map(|(t, _)| seconds(*t)).sum::<f64>() / n;
    let mean_n = history.iter().map(|(_, v)| v).sum::<Vector3<f64>>() / n;
    let (mut s_tt, mut s_tn) = (0.0, Vector3::zeros());
    for (t, v) in history {
        let dt = seconds(*t) - mean_t;
        s_tt += dt * dt;
        s_tn += dt * (v - mean_n);
    }
    if s_tt <= 0.0 {
        return Some(last);
    }
    let rate = s_tn / s_tt;
    let predicted = mean_n + rate * (seconds(time_ns) - mean_t);
    let mut step = predicted - last;
    let len = step.norm();
    if len > MAX_NORMAL_EXTRAPOLATION_RAD {
        step *= MAX_NORMAL_EXTRAPOLATION_RAD / len;
    }
    Some((last + step).try_normalize(f64::EPSILON).unwrap_or(last))
}

impl Tracker {
    /// A tracker with no track yet; the config is checked here, and a value
    /// out of range is named in the error.
    pub fn new(cfg: &TrackConfig) -> Result<Self, String> {
        let checks = [
            ("max_gap_ms", cfg.max_gap_ms, 0.0, 3.6e6),
            ("canopy_min_difference", cfg.canopy_min_difference, 0.0, 1.0),
            ("canopy_min_support", cfg.canopy_min_support, 0.0, 1.0),
            (
                "continuity_margin_deg",
                cfg.continuity_margin_deg,
                0.0,
                90.0,
            ),
            (
                "continuity_max_gap_ms",
                cfg.continuity_max_gap_ms,
                0.0,
                cfg.max_gap_ms,
            ),
            (
                "continuity_max_speed_mps",
                cfg.continuity_max_speed_mps,
                0.0,
                1000.0,
            ),
        ];
        for (key, value, min, max) in checks {
            if !(min..=max).contains(&value) {
                return Err(format!("{key} = {value}: expected {min} to {max}"));
            }
        }
        Ok(Self {
            max_gap_ns: (cfg.max_gap_ms * 1e6) as u64,
            canopy_min_difference: cfg.canopy_min_difference,
            canopy_min_support: cfg.canopy_min_support,
            continuity_margin_rad: cfg.continuity_margin_deg.to_radians(),
            continuity_max_gap_ns: (cfg.continuity_max_gap_ms * 1e6) as u64,
            continuity_max_speed_mps: cfg.continuity_max_speed_mps,
            track: None,
            normals: VecDeque::with_capacity(NORMAL_HISTORY),
            epoch: 0,
            tracked_before: false,
        })
    }

    /// The current track, if it is still fresh at `time_ns`.
    fn fresh_track(&self, time_ns: u64) -> Option<&TrackState> {
        self.track
            .as_ref()
            .filter(|t| time_ns >= t.time_ns && time_ns - t.time_ns <= self.max_gap_ns)
    }

    /// The predicted ellipse (undistorted pixels) at `capture_time_ns` to
    /// search near, while the track is fresh: constant velocity from the last
    /// two detections (the last ellipse itself until there are two).
    pub fn search_hint(&self, capture_time_ns: u64) -> Option<Ellipse> {
        let track = self.fresh_track(capture_time_ns)?;
        let dt_s = (capture_time_ns - track.time_ns) as f64 * 1e-9;
        let predicted = match track.velocity_per_s {
            Some(v) => track.ellipse + v * dt_s,
            None => track.ellipse,
        };
        ellipse_from_params(&predicted).or_else(|| ellipse_from_params(&track.ellipse))
    }

    /// Where the track predicts the rim at the start and at the end of an
    /// exposure of `exposure` centred on `capture_time_ns` (constant
    /// velocity, as [`Self::search_hint`]): the motion blur the frame
    /// should show. `None` while the track is not fresh or has no velocity
    /// yet (one detection).
    pub fn exposure_sweep(
        &self,
        capture_time_ns: u64,
        exposure: Duration,
    ) -> Option<ExposureSweep> {
        let track = self.fresh_track(capture_time_ns)?;
        let velocity = track.velocity_per_s?;
        let dt_s = (capture_time_ns - track.time_ns) as f64 * 1e-9;
        let half_s = 0.5 * exposure.as_secs_f64();
        let at = |t_s: f64| ellipse_from_params(&(track.ellipse + velocity * t_s));
        Some(ExposureSweep {
            start: at(dt_s - half_s)?,
            end: at(dt_s + half_s)?,
        })
    }

    /// Whether the track's last pose is close enough in time and space to
    /// `centre_camera_m` at `time_ns` for continuity to settle the ambiguity.
    fn continuity_applies(
        &self,
        t: &TrackState,
        centre_camera_m: &Vector3<f64>,
        time_ns: u64,
    ) -> bool {
        let dt_ns = time_ns.saturating_sub(t.time_ns);
        if time_ns < t.time_ns || dt_ns > self.continuity_max_gap_ns {
            return false;
        }
        let moved = (centre_camera_m - t.centre_camera_m).norm();
        let allowed = self.continuity_max_speed_mps * dt_ns as f64 * 1e-9
            + CONTINUITY_POSITION_NOISE * centre_camera_m.norm();
        moved <= allowed
    }

    /// Picks one of the two cone solutions and updates the track:
    /// the canopy rim when it decides, else continuity with a settled track
    /// whose last pose is close in time and space, else unresolved (the
    /// solution nearest the track's predicted normal; without a track, the
    /// one the rim leans to ([`canopy_lean`]), else the first; the other
    /// reported as `alternative`).
    pub fn choose(
        &mut self,
        solutions: [CirclePose; 2],
        canopy_support: [Option<f64>; 2],
        capture_time_ns: u64,
        ellipse_px: &Ellipse,
    ) -> Choice {
        let previous = self.fresh_track(capture_time_ns).copied();
        if previous.is_none() {
            self.normals.clear();
            // A new track: after an earlier one, that is a re-acquisition.
            if self.tracked_before {
                self.epoch = self.epoch.wrapping_add(1);
            }
            self.tracked_before = true;
        }

        let by_canopy = match canopy_support {
            [Some(s0), Some(s1)]
                if s0.max(s1) >= self.canopy_min_support
                    && (s0 - s1).abs() >= self.canopy_min_difference =>
            {
                Some(if s0 >= s1 { 0 } else { 1 })
            }
            _ => None,
        };
        let nearest_to_track = previous.map(|t| {
            let expected =
                predicted_normal(&self.normals, capture_time_ns).unwrap_or(t.normal_camera);
            let a0 = angle(&solutions[0].normal_camera, &expected);
            let a1 = angle(&solutions[1].normal_camera, &expected);
            let apart = angle(&solutions[0].normal_camera, &solutions[1].normal_camera);
            // Decisive if one is clearly nearer, or if the two solutions are
            // the same pose to within the margin (then either is right).
            let decisive =
                (a0 - a1).abs() >= self.continuity_margin_rad || apart < self.continuity_margin_rad;
            let near = self.continuity_applies(&t, &solutions[0].centre_camera_m, capture_time_ns);
            (if a0 <= a1 { 0 } else { 1 }, decisive && near && t.resolved)
        });
        let (index, how) = match (by_canopy, nearest_to_track) {
            (Some(i), _) => (i, Disambiguation::CanopyRim),
            (None, Some((i, true))) => (i, Disambiguation::Continuity),
            (None, Some((i, false))) => (i, Disambiguation::Unresolved),
            (None, None) => (
                canopy_lean(canopy_support).unwrap_or(0),
                Disambiguation::Unresolved,
            ),
        };
        let pose = solutions[index];

        let params = ellipse_params(ellipse_px);
        let dt_s = previous.map(|t| (capture_time_ns - t.time_ns) as f64 * 1e-9);
        let velocity_per_s = match (previous, dt_s) {
            (Some(t), Some(dt)) if dt > 0.0 => Some((params - t.ellipse) / dt),
            _ => None,
        };
        if self.normals.len() == NORMAL_HISTORY {
            self.normals.pop_front();
        }
        self.normals
            .push_back((capture_time_ns, *pose.normal_camera));
        self.track = Some(TrackState {
            time_ns: capture_time_ns,
            ellipse: params,
            velocity_per_s,
            normal_camera: *pose.normal_camera,
            centre_camera_m: *pose.centre_camera_m,
            resolved: how != Disambiguation::Unresolved,
        });
        Choice {
            pose,
            alternative: (how == Disambiguation::Unresolved).then_some(solutions[1 - index]),
            how,
            track_epoch: self.epoch,
        }
    }

    /// Forgets the track entirely (the epoch starts again from 0).
    pub fn reset(&mut self) {
        self.track = None;
        self.normals.clear();
        self.epoch = 0;
        self.tracked_before = false;
    }

    /// No detection in the frame captured at `capture_time_ns`: the track
    /// ends once the gap since its last detection exceeds `max_gap_ms`.
    pub fn lost(&mut self, capture_time_ns: u64) {
        if self.fresh_track(capture_time_ns).is_none() {
            self.track = None;
        }
    }
}

/// The solution the canopy rim leans to when it does not decide: its
/// supports passed the rim's own tests of a real difference
/// (`ambiguity::canopy_supports`) but the better one is below
/// `canopy_min_support` or the difference below `canopy_min_difference`.
/// The answer stays `unresolved`, with the other solution reported; only
/// which is given first follows the rim. (On the simulator's sweep, the
/// rim's choice at half the support asked was wrong on 2 of about 60 more
/// frames it would have decided: far better than the first solution's even
/// odds, far short of a decision.)
fn canopy_lean(canopy_support: [Option<f64>; 2]) -> Option<usize> {
    match canopy_support {
        [Some(s0), Some(s1)] if s0 != s1 => Some(if s0 > s1 { 0 } else { 1 }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::{Direction, Point};

    const MS: u64 = 1_000_000;

    fn config() -> TrackConfig {
        TrackConfig {
            max_gap_ms: 500.0,
            canopy_min_difference: 0.2,
            canopy_min_support: 0.5,
            continuity_margin_deg: 3.0,
            continuity_max_gap_ms: 100.0,
            continuity_max_speed_mps: 5.0,
        }
    }

    fn pose(nx: f64) -> CirclePose {
        CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.0, 0.0, 5.0)),
            normal_camera: Direction::new(Vector3::new(nx, 0.0, -1.0).normalize()),
        }
    }

    fn ellipse(cx: f64) -> Ellipse {
        Ellipse::new(cx, 200.0, 50.0, 30.0, 0.2)
    }

    #[test]
    fn canopy_then_continuity_then_unresolved_after_a_loss() {
        let mut t = Tracker::new(&config()).unwrap();
        // Frame 1: the rim supports the second solution.
        let c = t.choose(
            [pose(0.5), pose(-0.5)],
            [Some(0.1), Some(0.9)],
            0,
            &ellipse(100.0),
        );
        assert_eq!(c.how, Disambiguation::CanopyRim);
        assert_eq!(c.pose, pose(-0.5));
        assert!(c.alternative.is_none());
        assert_eq!(c.track_epoch, 0);
        // Frame 2: rim hidden; continuity keeps the same branch even though
        // the solutions come in the other order.
        let c = t.choose(
            [pose(0.48), pose(-0.48)],
            [None, None],
            40 * MS,
            &ellipse(104.0),
        );
        assert_eq!(c.how, Disambiguation::Continuity);
        assert_eq!(c.pose, pose(-0.48));
        // Undecided rim (both supported alike) still leaves it to continuity.
        let c = t.choose(
            [pose(-0.47), pose(0.47)],
            [Some(0.8), Some(0.75)],
            80 * MS,
            &ellipse(108.0),
        );
        assert_eq!(c.how, Disambiguation::Continuity);
        assert_eq!(c.pose, pose(-0.47));
        // Lost for longer than the gap: the track ends; a new one is unresolved.
        t.lost(200 * MS);
        assert!(t.search_hint(300 * MS).is_some(), "still within the gap");
        t.lost(700 * MS);
        assert!(t.search_hint(700 * MS).is_none());
        let c = t.choose(
            [pose(0.4), pose(-0.4)],
            [None, None],
            720 * MS,
            &ellipse(50.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        assert_eq!(c.alternative, Some(pose(-0.4)));
        assert_eq!(c.track_epoch, 1);
        // An unresolved track stays unresolved by continuity alone, but keeps
        // to the same branch.
        let c = t.choose(
            [pose(-0.41), pose(0.41)],
            [None, None],
            760 * MS,
            &ellipse(52.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        assert_eq!(c.pose, pose(0.41));
        // reset forgets everything.
        t.reset();
        assert!(t.search_hint(800 * MS).is_none());
        let c = t.choose(
            [pose(0.4), pose(-0.4)],
            [None, None],
            800 * MS,
            &ellipse(50.0),
        );
        assert_eq!(c.track_epoch, 0);
    }

    #[test]
    fn a_rim_that_leans_but_does_not_decide_orders_the_unresolved_answer() {
        // Supports that passed the rim's own tests but stay below
        // canopy_min_support: unresolved, the leaned-to solution first.
        for (support, first) in [
            ([Some(0.3), Some(0.02)], pose(0.5)),
            ([Some(0.02), Some(0.3)], pose(-0.5)),
            ([None, None], pose(0.5)),
        ] {
            let mut t = Tracker::new(&config()).unwrap();
            let c = t.choose([pose(0.5), pose(-0.5)], support, 0, &ellipse(100.0));
            assert_eq!(c.how, Disambiguation::Unresolved, "{support:?}");
            assert_eq!(c.pose, first, "{support:?}");
            let other = if first == pose(0.5) {
                pose(-0.5)
            } else {
                pose(0.5)
            };
            assert_eq!(c.alternative, Some(other));
        }
    }

    #[test]
    fn prediction_is_constant_velocity() {
        let mut t = Tracker::new(&config()).unwrap();
        assert!(t.search_hint(0).is_none());
        t.choose([pose(0.3), pose(-0.3)], [None, None], 0, &ellipse(100.0));
        // One detection: the hint is the last ellipse.
        let h = t.search_hint(40 * MS).unwrap();
        assert!(h.max_param_error_px(&ellipse(100.0)) < 1e-9);
        t.choose(
            [pose(0.3), pose(-0.3)],
            [None, None],
            40 * MS,
            &Ellipse::new(110.0, 196.0, 52.0, 31.0, 0.2),
        );
        // 10 px / 40 ms right, 4 px / 40 ms up, axes growing: 80 ms later.
        let h = t.search_hint(120 * MS).unwrap();
        let expected = Ellipse::new(130.0, 188.0, 56.0, 33.0, 0.2);
        assert!(h.max_param_error_px(&expected) < 1e-6, "{h:?}");
        assert!(h.theta_error_rad(&expected) < 1e-9);
        // Time running backwards ends the track.
        assert!(t.search_hint(10 * MS).is_none());
        t.lost(10 * MS);
        let c = t.choose(
            [pose(0.3), pose(-0.3)],
            [None, None],
            20 * MS,
            &ellipse(1.0),
        );
        assert_eq!(c.track_epoch, 1);
    }

    #[test]
    fn the_exposure_sweep_is_the_track_at_the_exposures_ends() {
        let mut t = Tracker::new(&config()).unwrap();
        let exposure = Duration::from_millis(20);
        t.choose([pose(0.3), pose(-0.3)], [None, None], 0, &ellipse(100.0));
        // One detection: no velocity, no predicted blur.
        assert!(t.exposure_sweep(40 * MS, exposure).is_none());
        t.choose(
            [pose(0.3), pose(-0.3)],
            [None, None],
            40 * MS,
            &Ellipse::new(110.0, 196.0, 52.0, 31.0, 0.2),
        );
        // 250 px/s right, 100 px/s up, the axes growing 50 and 25 px/s: a
        // frame at 80 ms is exposed from 70 to 90 ms.
        let s = t.exposure_sweep(80 * MS, exposure).unwrap();
        let start = Ellipse::new(117.5, 193.0, 53.5, 31.75, 0.2);
        let end = Ellipse::new(122.5, 191.0, 54.5, 32.25, 0.2);
        assert!(s.start.max_param_error_px(&start) < 1e-9, "{s:?}");
        assert!(s.end.max_param_error_px(&end) < 1e-9, "{s:?}");
        // A stale track predicts nothing.
        assert!(t.exposure_sweep(40 * MS + 501 * MS, exposure).is_none());
    }

    #[test]
    fn bad_config_is_named() {
        let mut c = config();
        c.max_gap_ms = f64::NAN;
        assert!(Tracker::new(&c).err().unwrap().contains("max_gap_ms"));
        let mut c = config();
        c.canopy_min_support = 1.5;
        assert!(
            Tracker::new(&c)
                .err()
                .unwrap()
                .contains("canopy_min_support")
        );
    }

    fn pose_at(nx: f64, centre: [f64; 3]) -> CirclePose {
        CirclePose {
            centre_camera_m: Point::new(Vector3::new(centre[0], centre[1], centre[2])),
            ..pose(nx)
        }
    }

    /// Unrelated images stamped 33 ms apart (a folder processed as a
    /// sequence): the drogue is elsewhere, so the rim-settled first image's
    /// normal is not handed to the second.
    #[test]
    fn continuity_needs_the_last_pose_near_in_space() {
        let mut t = Tracker::new(&config()).unwrap();
        let c = t.choose(
            [
                pose_at(0.5, [0.0, 0.0, 5.0]),
                pose_at(-0.5, [0.0, 0.0, 5.0]),
            ],
            [Some(0.9), Some(0.1)],
            0,
            &ellipse(100.0),
        );
        assert_eq!(c.how, Disambiguation::CanopyRim);
        // 33 ms later 1 m away (30 m/s): not the same drogue's motion.
        let c = t.choose(
            [
                pose_at(0.48, [1.0, 0.0, 5.0]),
                pose_at(-0.48, [1.0, 0.0, 5.0]),
            ],
            [None, None],
            33 * MS,
            &ellipse(300.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        assert!(c.alternative.is_some());
        // The unresolved frame leaves the track unsettled: the next frame,
        // near it, is not settled by continuity either.
        let c = t.choose(
            [
                pose_at(0.47, [1.0, 0.0, 5.0]),
                pose_at(-0.47, [1.0, 0.0, 5.0]),
            ],
            [None, None],
            66 * MS,
            &ellipse(300.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        // Within reach (0.1 m in 33 ms = 3 m/s, below 5 m/s + 1 % of range):
        // continuity after a rim-settled frame.
        t.reset();
        t.choose(
            [
                pose_at(0.5, [0.0, 0.0, 5.0]),
                pose_at(-0.5, [0.0, 0.0, 5.0]),
            ],
            [Some(0.9), Some(0.1)],
            0,
            &ellipse(100.0),
        );
        let c = t.choose(
            [
                pose_at(-0.48, [0.1, 0.0, 5.0]),
                pose_at(0.48, [0.1, 0.0, 5.0]),
            ],
            [None, None],
            33 * MS,
            &ellipse(104.0),
        );
        assert_eq!(c.how, Disambiguation::Continuity);
        assert_eq!(c.pose, pose_at(0.48, [0.1, 0.0, 5.0]));
    }

    /// A gap longer than `continuity_max_gap_ms` (but within the track's
    /// `max_gap_ms`) keeps the track for the search but not for continuity.
    #[test]
    fn continuity_needs_the_last_pose_near_in_time() {
        let mut t = Tracker::new(&config()).unwrap();
        t.choose(
            [pose(0.5), pose(-0.5)],
            [Some(0.9), Some(0.1)],
            0,
            &ellipse(100.0),
        );
        assert!(t.search_hint(200 * MS).is_some());
        let c = t.choose(
            [pose(0.5), pose(-0.5)],
            [None, None],
            200 * MS,
            &ellipse(100.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        assert_eq!(c.track_epoch, 0, "the track itself lives on");
    }

    #[test]
    fn continuity_gap_beyond_the_track_gap_is_refused() {
        let mut c = config();
        c.continuity_max_gap_ms = 600.0;
        let e = Tracker::new(&c).err().unwrap();
        assert!(e.contains("continuity_max_gap_ms"), "{e}");
        let mut c = config();
        c.continuity_max_speed_mps = -1.0;
        assert!(
            Tracker::new(&c)
                .err()
                .unwrap()
                .contains("continuity_max_speed_mps")
        );
    }

    #[test]
    fn weak_or_equal_rim_support_does_not_decide() {
        let mut t = Tracker::new(&config()).unwrap();
        // Both weak (rim hidden): no decision even with a large difference
        // in relative terms.
        let c = t.choose(
            [pose(0.5), pose(-0.5)],
            [Some(0.05), Some(0.3)],
            0,
            &ellipse(1.0),
        );
        assert_eq!(c.how, Disambiguation::Unresolved);
        t.reset();
        let c = t.choose([pose(0.5), pose(-0.5)], [Some(0.9), None], 0, &ellipse(1.0));
        assert_eq!(c.how, Disambiguation::Unresolved);
    }
}
