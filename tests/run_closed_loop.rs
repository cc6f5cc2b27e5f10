//! SITL closed loop: `run --source sim:... --vehicle-pose mavlink` against a
//! scripted autopilot in this process (rust-mavlink framing; HEARTBEAT,
//! ATTITUDE, LOCAL_POSITION_NED at 50 Hz, TIMESYNC answered). The autopilot
//! holds, steps 1 m to its right, holds, turns 4 degrees right, holds, and
//! goes silent for half a second.
//!
//! Every expected number comes from analytic geometry of the test scenario
//! (calm air, no bow wave: the drogue trails the tanker rigidly) and the
//! script, never from the code under test:
//! - placement (the documented anchoring, tanker mode): at the first pose the
//!   drogue is where the scenario's receiver sees it at t = 0, i.e. at
//!   `probe_tip_body - start_offset` in the vehicle's heading-aligned level
//!   axes, and it keeps that place in the autopilot's NED (the placement
//!   moves with the tanker): `drogue_ned = p0 + Rz(yaw0) (tip - offset)`;
//! - the body position at a capture time: `R(t)^T (drogue_ned - p(t))`
//!   with the scripted pose; the camera position through the mount; the
//!   image centre through the pinhole.

mod run_support;

use mavlink::dialects::ardupilotmega::MavFrame;
use run_support::*;
use std::sync::Arc;
use std::time::Duration;

type V = [f64; 3];

/// One paced run at a time: two at once on a 2-core machine make each one
/// drop frames.
static ONE_RUN_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_run_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_RUN_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

const SCENARIO: &str = r#"
name = "closed_loop_test"
seed = 7
fps = 30.0
duration_s = 9.5
[camera]
fx = 1336.2
fy = 1335.4
cx = 646.3
cy = 473.8
[mount]
position_body_m = [2.5, 0.3, -0.9]
roll_deg = 0.0
pitch_deg = 2.0
yaw_deg = 6.0
probe_tip_body_m = [6.0, 0.75, -0.85]
[tanker]
heading_deg = 30.0
[turbulence]
intensity = "none"
[bow_wave]
enabled = false
[whip]
enabled = false
[receiver]
start_offset_m = [-10.0, -0.6, -0.3]
end_offset_m = [-10.0, -0.6, -0.3]
approach_start_s = 0.0
approach_end_s = 0.0
tracking_lag_s = 0.0
roll_deg = 0.0
pitch_deg = 0.0
yaw_deg = 0.0
wobble_deg = 0.0
"#;
// The same numbers as the scenario above, for the expectations.
const FX: f64 = 1336.2;
const FY: f64 = 1335.4;
const CX: f64 = 646.3;
const CY: f64 = 473.8;
const CAMERA_BODY_M: V = [2.5, 0.3, -0.9];
const MOUNT_RPY_DEG: V = [0.0, 2.0, 6.0];
const PROBE_TIP_BODY_M: V = [6.0, 0.75, -0.85];
const START_OFFSET_M: V = [-10.0, -0.6, -0.3];

// The scripted autopilot: first pose, then a step and a turn.
const P0: V = [150.0, -40.0, -25.0];
const RPY0: V = [0.02, 0.04, -1.2];
const STEP_M: f64 = 1.0;
const TURN_RAD: f64 = 4.0 * std::f64::consts::PI / 180.0;
const STEP_S: (f64, f64) = (3.0, 4.0);
const TURN_S: (f64, f64) = (6.0, 7.0);
const SILENT_S: (f64, f64) = (7.8, 8.3);
/// How old the pose a frame is rendered or converted with may be: the
/// telemetry comes at 50 Hz, the link uses samples within 0.1 s of a time,
/// plus scheduling delays of this test's peer thread on a busy machine. The
/// motion in this window is all the slack a check gets: while the vehicle
/// holds still the checks are exact.
const LATE_S: f64 = 0.25;

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The scripted pose `s` seconds after the script's start, as sent (f32).
fn scripted(s: f64) -> ReportedPose {
    let step = STEP_M * smoothstep((s - STEP_S.0) / (STEP_S.1 - STEP_S.0));
    let yaw = RPY0[2] + TURN_RAD * smoothstep((s - TURN_S.0) / (TURN_S.1 - TURN_S.0));
    // The vehicle's right at its first heading, NED.
    let right = [-RPY0[2].sin(), RPY0[2].cos(), 0.0];
    ReportedPose {
        position_ned_m: [0, 1, 2].map(|i| (P0[i] + step * right[i]) as f32),
        rpy_rad: [RPY0[0] as f32, RPY0[1] as f32, yaw as f32],
    }
}

/// R = Rz(yaw) Ry(pitch) Rx(roll), row-major (written out here, not taken
/// from the code under test).
fn rot_zyx(roll: f64, pitch: f64, yaw: f64) -> [[f64; 3]; 3] {
    let (cr, sr) = (roll.cos(), roll.sin());
    let (cp, sp) = (pitch.cos(), pitch.sin());
    let (cy, sy) = (yaw.cos(), yaw.sin());
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

fn mul(r: &[[f64; 3]; 3], v: V) -> V {
    [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
}

fn mul_t(r: &[[f64; 3]; 3], v: V) -> V {
    [0, 1, 2].map(|i| r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2])
}

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn norm(a: V) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn pose_f64(p: &ReportedPose) -> (V, [[f64; 3]; 3]) {
    let [r, pi, y] = p.rpy_rad.map(f64::from);
    (p.position_ned_m.map(f64::from), rot_zyx(r, pi, y))
}

/// The drogue centre in the autopilot's NED: the anchoring places it at the
/// scenario's pre-contact offset ahead of the first pose, along its heading.
fn drogue_ned() -> V {
    let (p0, _) = pose_f64(&scripted(0.0));
    let yaw0 = f64::from(scripted(0.0).rpy_rad[2]);
    add(
        p0,
        mul(
            &rot_zyx(0.0, 0.0, yaw0),
            sub(PROBE_TIP_BODY_M, START_OFFSET_M),
        ),
    )
}

fn body_of(pose: &ReportedPose) -> V {
    let (p, r) = pose_f64(pose);
    mul_t(&r, sub(drogue_ned(), p))
}

/// Camera frame (x right, y down, z forward) of a body position.
fn camera_of(body: V) -> V {
    let [r, p, y] = MOUNT_RPY_DEG.map(f64::to_radians);
    let r_body_cam0 = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let m = rot_zyx(r, p, y);
    // R_body_cam = m * r_body_cam0; camera = R_body_cam^T (body - camera_pos).
    let d = mul_t(&m, sub(body, CAMERA_BODY_M));
    mul_t(&r_body_cam0, d)
}

/// Script seconds from `before_s` before `s` to `after_s` after it, in
/// `step_s` steps: the poses a frame captured at `s` may have been rendered
/// or converted with (the latest telemetry sample before it, or the link's
/// interpolation).
fn window(s: f64, before_s: f64, after_s: f64, step_s: f64) -> Vec<f64> {
    let n = ((before_s + after_s) / step_s).round() as usize;
    (0..=n).map(|k| s - before_s + k as f64 * step_s).collect()
}

/// `run` on the simulated `scenario` with the autopilot's pose
/// (`--vehicle-pose mavlink`) from `autopilot`, `config` laid over the
/// default, logging to `tmp/logs`; it must end well. The LANDING_TARGETs the
/// autopilot received and the run's stderr.
fn closed_loop_run(
    tmp: &std::path::Path,
    scenario: &std::path::Path,
    config: &std::path::Path,
    autopilot: Autopilot,
) -> (Vec<Received>, String) {
    let PeerRun {
        status,
        received,
        stderr,
    } = run_with_peer(
        &[
            "--source".into(),
            format!("sim:{}", scenario.display()),
            "--vehicle-pose".into(),
            "mavlink".into(),
        ],
        autopilot,
        &tmp.join("logs"),
        config,
        &tmp.join("stderr.txt"),
    );
    assert!(status.success(), "run ended with {status:?}:\n{stderr}");
    (received, stderr)
}

/// The simulator's truth of every logged frame (`/sim/truth`).
fn logged_truths(log: &[Logged]) -> Vec<Truth> {
    log.iter()
        .filter(|m| m.topic == "/sim/truth")
        .map(|m| serde_json::from_slice(&m.data).unwrap())
        .collect()
}

#[derive(serde::Deserialize)]
struct Truth {
    capture_time_ns: u64,
    ned_frame: String,
    position_ned: V,
    receiver_position_ned: V,
    position_body: V,
    ellipse: Option<Ellipse>,
}

#[derive(serde::Deserialize)]
struct Ellipse {
    cx: f64,
    cy: f64,
}

#[test]
fn the_view_and_landing_target_ned_follow_the_autopilot() {
    let _one = one_run_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let scenario = tmp.path().join("closed_loop_test.toml");
    std::fs::write(&scenario, SCENARIO).unwrap();
    let config = tmp.path().join("closed_loop.toml");
    std::fs::write(
        &config,
        "[link]\nmessages = [\"landing_target\", \"landing_target_ned\"]\nmax_rate_hz = 0.0\n",
    )
    .unwrap();
    let logs = tmp.path().join("logs");

    let t0_ns = unix_now_ns();
    let secs = move |ns: u64| (ns as f64 - t0_ns as f64) * 1e-9;
    let script: Script = Arc::new(move |now_ns| {
        let s = secs(now_ns);
        (!(SILENT_S.0..SILENT_S.1).contains(&s)).then(|| scripted(s))
    });
    let autopilot = Autopilot::start(Some(script), 50.0);
    let (received, stderr) = closed_loop_run(tmp.path(), &scenario, &config, autopilot);

    // Every frame is logged, each with its truth in the autopilot's frame;
    // on a starved machine the log writer (nice 10, below the measurement)
    // may fall behind and drop a few items, which the summary then counts.
    let frames = frames_in_summary(&stderr);
    let not_logged = not_logged_in_summary(&stderr);
    assert!(
        not_logged <= frames / 20,
        "{not_logged} log items dropped of {frames} frames"
    );
    let log = read_log(&only_log(&logs));
    let images = log.iter().filter(|m| m.topic == "/camera/image").count() as u64;
    let truths = logged_truths(&log);
    assert!(
        images <= frames && images + not_logged >= frames,
        "{images} images of {frames} frames, {not_logged} items not logged"
    );
    assert!(truths.len() as u64 <= frames && truths.len() as u64 + not_logged >= frames);
    // Frames the rendering was too late for are dropped (as a camera drops
    // them); a few at most.
    assert!(frames >= 250, "only {frames} frames of the 285");

    // The truth: the drogue stays where the anchoring put it, the receiver
    // is where the autopilot said, and the view follows the autopilot.
    let drogue = drogue_ned();
    let (mut u_before, mut u_after) = (Vec::new(), Vec::new());
    for t in &truths {
        assert_eq!(t.ned_frame, "autopilot");
        let e = norm(sub(t.position_ned, drogue));
        assert!(e < 0.002, "truth drogue {:?} vs {drogue:?}", t.position_ned);
        let s = secs(t.capture_time_ns);
        // Rendered from the latest sample at or before the capture.
        let near = window(s, LATE_S, 0.0, 0.001);
        let receiver_err = near
            .iter()
            .map(|&w| norm(sub(t.receiver_position_ned, pose_f64(&scripted(w)).0)))
            .fold(f64::INFINITY, f64::min);
        assert!(
            receiver_err < 1e-3,
            "receiver at {s:.3} s off by {receiver_err}"
        );
        let (best, body_err) = near
            .iter()
            .map(|&w| (w, norm(sub(t.position_body, body_of(&scripted(w))))))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert!(body_err < 0.002, "truth body at {s:.3} s off by {body_err}");
        let c = camera_of(body_of(&scripted(best)));
        let (u, v) = (FX * c[0] / c[2] + CX, FY * c[1] / c[2] + CY);
        let ell = t.ellipse.as_ref().expect("the drogue is in view");
        assert!(
            (ell.cx - u).abs() < 0.5 && (ell.cy - v).abs() < 0.5,
            "ellipse centre ({}, {}) vs projected ({u}, {v}) at {s:.3} s",
            ell.cx,
            ell.cy
        );
        if s < STEP_S.0 {
            u_before.push(ell.cx);
        } else if s > STEP_S.1 && s < TURN_S.0 {
            u_after.push(ell.cx);
        }
    }
    // A 1 m step to the right moves the drogue about 100 px left in the image.
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let shift = mean(&u_after) - mean(&u_before);
    let expect_shift = {
        let u = |s: f64| {
            let c = camera_of(body_of(&scripted(s)));
            FX * c[0] / c[2]
        };
        u(5.0) - u(1.0)
    };
    assert!(
        !u_before.is_empty() && !u_after.is_empty() && expect_shift < -80.0,
        "{expect_shift}"
    );
    assert!(
        (shift - expect_shift).abs() < 0.5,
        "{shift} vs {expect_shift}"
    );

    // LANDING_TARGET from the measured frames.
    let body: Vec<_> = received
        .iter()
        .filter(|r| r.target.frame == MavFrame::MAV_FRAME_BODY_FRD)
        .collect();
    let ned: Vec<_> = received
        .iter()
        .filter(|r| r.target.frame == MavFrame::MAV_FRAME_LOCAL_NED)
        .collect();
    assert!(
        body.len() as u64 >= frames * 8 / 10,
        "{} LANDING_TARGET (body) for {frames} frames",
        body.len()
    );
    let range = norm(body_of(&scripted(0.0)));
    let mut worst_body: f64 = 0.0;
    for r in &body {
        let s = secs(r.target.time_usec * 1000);
        let m = [r.target.x, r.target.y, r.target.z].map(f64::from);
        let err = window(s, LATE_S, 0.0, 0.001)
            .iter()
            .map(|&w| norm(sub(m, body_of(&scripted(w)))))
            .fold(f64::INFINITY, f64::min);
        worst_body = worst_body.max(err / range);
        assert!(
            err <= 0.01 * range,
            "body LANDING_TARGET at {s:.3} s: {m:?}, off by {err:.3} m (range {range:.1} m)"
        );
    }
    // LOCAL_NED: the drogue's fixed place in the autopilot's frame, up to the
    // difference between the pose the frame was rendered with and the one
    // the link converts with (each one within LATE_S of the capture).
    let mut worst_ned: f64 = 0.0;
    for r in &ned {
        let s = secs(r.target.time_usec * 1000);
        assert!(
            !(SILENT_S.0 + 0.12..SILENT_S.1 - 0.12).contains(&s),
            "LANDING_TARGET in LOCAL_NED at {s:.3} s, while the autopilot was silent"
        );
        let m = [r.target.x, r.target.y, r.target.z].map(f64::from);
        let w = window(s, LATE_S, LATE_S, 0.01);
        let mut allowance: f64 = 0.0;
        for &a in &w {
            for &b in &w {
                let (pa, ra) = pose_f64(&scripted(a));
                let via = add(pa, mul(&ra, body_of(&scripted(b))));
                allowance = allowance.max(norm(sub(via, drogue)));
            }
        }
        let err = norm(sub(m, drogue));
        worst_ned = worst_ned.max(err / range);
        assert!(
            err <= 0.01 * range + allowance,
            "LOCAL_NED LANDING_TARGET at {s:.3} s: {m:?} vs {drogue:?}: {err:.3} m"
        );
    }
    assert!(
        ned.len() as u64 >= frames * 7 / 10,
        "{} LANDING_TARGET (LOCAL_NED) for {frames} frames",
        ned.len()
    );
    eprintln!(
        "closed loop: {frames} frames, {} body / {} NED LANDING_TARGET, worst error \
         {:.3} % / {:.3} % of range; image shift {shift:.1} px (expected {expect_shift:.1})",
        body.len(),
        ned.len(),
        100.0 * worst_body,
        100.0 * worst_ned
    );

    // The silence was noticed, the last pose held, and the pose came back.
    assert!(stderr.contains("pose is stale"), "{stderr}");
    assert!(stderr.contains("pose is back"), "{stderr}");
    assert!(stderr.contains("held autopilot pose"), "{stderr}");
}

/// `sitl_anchor = "world"`: the autopilot's frame is fixed in the scenario's
/// world, so the vehicle must fly along with the tanker (here 30 m/s, as a
/// fixed-wing SITL would), and the drogue moves at that speed in the
/// autopilot's NED. A frame's pose is interpolated between the reports
/// around its capture (`vehicle_pose_delay_ms`), so a fast vehicle is
/// rendered where it was, not where it was one report earlier (0.6 m at
/// 30 m/s and 50 Hz).
#[test]
fn world_anchor_vehicle_flying_with_the_tanker() {
    let _one = one_run_at_a_time();
    const SPEED_MPS: f64 = 30.0;
    let tmp = tempfile::tempdir().unwrap();
    let scenario = tmp.path().join("closed_loop_world.toml");
    let text = SCENARIO
        .replace("duration_s = 9.5", "duration_s = 6.0")
        .replace(
            "heading_deg = 30.0",
            "heading_deg = 30.0\nairspeed_mps = 30.0",
        );
    std::fs::write(&scenario, text).unwrap();
    let config = tmp.path().join("world.toml");
    std::fs::write(
        &config,
        "[run]\nsitl_anchor = \"world\"\n[link]\nmessages = [\"landing_target_ned\"]\nmax_rate_hz = 0.0\n",
    )
    .unwrap();
    let logs = tmp.path().join("logs");

    let t0_ns = unix_now_ns();
    let secs = move |ns: u64| (ns as f64 - t0_ns as f64) * 1e-9;
    let yaw0 = RPY0[2];
    let ahead = [yaw0.cos(), yaw0.sin(), 0.0];
    let right = [-yaw0.sin(), yaw0.cos(), 0.0];
    // Flying along its heading at the tanker's speed, one metre to the right
    // between 2.5 and 3.5 s.
    let flown = move |s: f64| -> ReportedPose {
        let step = STEP_M * smoothstep(s - 2.5);
        ReportedPose {
            position_ned_m: [0, 1, 2]
                .map(|i| (P0[i] + SPEED_MPS * s * ahead[i] + step * right[i]) as f32),
            rpy_rad: RPY0.map(|a| a as f32),
        }
    };
    let script: Script = Arc::new(move |now_ns| Some(flown(secs(now_ns))));
    let autopilot = Autopilot::start(Some(script), 50.0);
    let (received, _) = closed_loop_run(tmp.path(), &scenario, &config, autopilot);

    // The drogue at a capture time, autopilot NED: ahead of the vehicle's
    // track by the scenario's pre-contact offset, moving with it.
    let offset = mul(
        &rot_zyx(0.0, 0.0, f64::from(RPY0[2] as f32)),
        sub(PROBE_TIP_BODY_M, START_OFFSET_M),
    );
    let drogue_at = |s: f64| {
        let track = [0, 1, 2].map(|i| P0[i] + SPEED_MPS * s * ahead[i]);
        add(track, offset)
    };
    let log = read_log(&only_log(&logs));
    let truths = logged_truths(&log);
    assert!(truths.len() >= 150, "{} frames", truths.len());
    // Interpolated, not held: the receiver is where the script had it at the
    // capture. A held report lags by 0 to 20 ms, 0 to 0.6 m at 30 m/s (a
    // sixth of its frames within 0.1 m); an interpolated one is off by the
    // error of the autopilot clock's offset only (TIMESYNC, or the arrival
    // time before it converges): on an idle machine a median of 0.2 mm, but
    // a CI run on a machine busy compiling once had 0 of 180 frames within
    // 1 cm (not reproduced since; the offset's error over a loaded local
    // link is the likely cause). 0.1 m is 3.3 ms: it still tells
    // interpolated from held. The interpolation's accuracy itself is
    // `link::telemetry`'s unit tests'.
    const RECEIVER_TOLERANCE_M: f64 = 0.1;
    let mut receiver_ok = 0;
    let mut receiver_errors = Vec::new();
    for t in &truths {
        let s = secs(t.capture_time_ns);
        let e = norm(sub(t.position_ned, drogue_at(s)));
        // The telemetry's time stamps are good to about a millisecond: 3 cm
        // at 30 m/s.
        assert!(e < 0.03, "truth drogue at {s:.3} s off by {e:.4} m");
        let flown_at = flown(s).position_ned_m.map(f64::from);
        let e = norm(sub(t.receiver_position_ned, flown_at));
        receiver_ok += usize::from(e < RECEIVER_TOLERANCE_M);
        receiver_errors.push(e);
    }
    receiver_errors.sort_by(f64::total_cmp);
    eprintln!(
        "world anchor: receiver at capture time off by median {:.4} m, max {:.4} m",
        receiver_errors[receiver_errors.len() / 2],
        receiver_errors[receiver_errors.len() - 1]
    );
    assert!(
        receiver_ok * 10 >= truths.len() * 9,
        "receiver at its capture-time pose (within {RECEIVER_TOLERANCE_M} m) on {receiver_ok} of {} frames",
        truths.len()
    );

    let range = norm(offset);
    let mut errors: Vec<f64> = received
        .iter()
        .map(|r| {
            let s = secs(r.target.time_usec * 1000);
            let m = [r.target.x, r.target.y, r.target.z].map(f64::from);
            norm(sub(m, drogue_at(s))) / range
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    assert!(
        errors.len() * 10 >= truths.len() * 8,
        "{} LANDING_TARGET for {} frames",
        errors.len(),
        truths.len()
    );
    let within = errors.iter().filter(|e| **e <= 0.01).count();
    eprintln!(
        "world anchor at {SPEED_MPS} m/s: {} frames, {} LOCAL_NED LANDING_TARGET, error / range \
         median {:.3} %, {within} within 1 %",
        truths.len(),
        errors.len(),
        100.0 * errors[errors.len() / 2]
    );
    assert!(
        within * 10 >= errors.len() * 9,
        "{within} of {}",
        errors.len()
    );
}

#[test]
fn without_the_autopilots_pose_the_run_ends_with_status_1() {
    let tmp = tempfile::tempdir().unwrap();
    let config = tmp.path().join("timeout.toml");
    std::fs::write(&config, "[run]\nvehicle_pose_timeout_s = 1.0\n").unwrap();
    // An autopilot that answers but never reports its pose.
    let autopilot = Autopilot::start(None, 50.0);
    let stderr_path = tmp.path().join("stderr.txt");
    let mut child = spawn_run(
        &[
            "--vehicle-pose".into(),
            "mavlink".into(),
            "--mavlink".into(),
            autopilot.address(),
            "--log-dir".into(),
            tmp.path().join("logs").display().to_string(),
            "--config".into(),
            config.display().to_string(),
        ],
        &stderr_path,
    );
    let status = wait_with_limit(&mut child, Duration::from_secs(20));
    autopilot.finish();
    let stderr = std::fs::read_to_string(&stderr_path).unwrap();
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert_eq!(
        stderr.matches("waiting for the autopilot's pose").count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("no pose from the autopilot within 1 s"),
        "{stderr}"
    );
    // The log is complete and readable, with no frame.
    let log = read_log(&only_log(&tmp.path().join("logs")));
    assert!(!log.iter().any(|m| m.topic == "/camera/image"));
}

#[test]
fn closed_loop_setup_errors_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let late = tmp.path().join("late.toml");
    std::fs::write(&late, "[run]\nvehicle_pose_delay_ms = 300\n").unwrap();
    let late = late.display().to_string();
    for (args, says) in [
        (
            vec!["--source", "dir:/tmp"],
            "--vehicle-pose mavlink needs a simulated source",
        ),
        (vec!["--fast"], "drop --fast"),
        (
            vec!["--config", late.as_str()],
            "vehicle_pose_delay_ms = 300",
        ),
    ] {
        let out = std::process::Command::new(BIN)
            .args(["run", "--vehicle-pose", "mavlink"])
            .args(&args)
            .args([
                "--mavlink",
                "udpout:127.0.0.1:9",
                "--log-dir",
                "/nonexistent",
            ])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// The log items the run's summary says were not logged (0 when it says
/// nothing).
fn not_logged_in_summary(stderr: &str) -> u64 {
    stderr
        .lines()
        .find_map(|l| {
            let (before, _) = l.split_once(" items not logged")?;
            before.rsplit(['(', ' ']).next()?.parse().ok()
        })
        .unwrap_or(0)
}
