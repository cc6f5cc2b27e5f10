//! The simulator: scenario -> (frame, truth) for every frame, in order.

use crate::FrameTruth;
use crate::camera::SimCamera;
use crate::conic::{circle_image_conic, conic_to_ellipse, mirror_pose};
use crate::error::SimError;
use crate::geometry::{
    M3, V3, matrix_from_quat, perpendicular, quat_from_matrix, r_body_cam, to_array,
};
use crate::render::{DrogueView, FrameScene, Look, Renderer, Tube};
use crate::scenario::{MountSpec, Scenario};
use crate::trajectory::{World, WorldState};
use image::GrayImage;

/// Rim points used for the occlusion shares and the `expect` decision.
const RIM_POINTS: usize = 360;
/// Share of the inner rim that must be visible for `expect = detect`.
pub const MIN_VISIBLE_RIM: f64 = 0.6;

/// Renders a scenario frame by frame, each with its exact truth.
pub struct Simulator {
    scenario: Scenario,
    camera: SimCamera,
    r_body_cam: M3,
    world: World,
    look: Look,
    /// Built at the first frame rendered: its per-pixel ray table costs
    /// milliseconds, which callers that only want the truth never pay.
    renderer: Option<Renderer>,
    seq: u64,
    frame_count: u64,
    last_scene: Option<FrameScene>,
}

impl Simulator {
    /// A simulator at the scenario's first frame; fails on an unusable camera.
    pub fn new(scenario: Scenario) -> Result<Simulator, SimError> {
        let camera = scenario.camera_model()?;
        let m = &scenario.mount;
        let r_body_cam = r_body_cam(m.roll_deg, m.pitch_deg, m.yaw_deg);
        let sc = &scenario.scene;
        let (az, el) = (
            sc.sun_azimuth_deg.to_radians(),
            sc.sun_elevation_deg.to_radians(),
        );
        let look = Look {
            sky_zenith: sc.sky_zenith,
            sky_horizon: sc.sky_horizon,
            ground: sc.ground,
            cloud_cover: sc.cloud_cover,
            cloud_radiance: sc.cloud_radiance,
            sun_ned: V3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin()),
            glare: sc.glare,
            haze: sc.haze,
            haze_radiance: sc.haze_radiance,
            gain: scenario.camera.gain,
            read_noise_dn: scenario.camera.read_noise_dn,
            shot_noise_dn: scenario.camera.shot_noise_dn,
            vignette: scenario.camera.vignette,
            cloud_seed: (scenario.seed as u32).wrapping_mul(2_654_435_761),
        };
        Ok(Simulator {
            world: World::new(&scenario),
            frame_count: scenario.frame_count(),
            scenario,
            camera,
            r_body_cam,
            look,
            renderer: None,
            seq: 0,
            last_scene: None,
        })
    }

    /// The scenario being run.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The simulated camera (intrinsics and distortion).
    pub fn camera(&self) -> &SimCamera {
        &self.camera
    }

    /// ROS camera_info YAML of the simulated camera.
    pub fn camera_yaml(&self) -> String {
        self.camera.ros_yaml("drogue_sim")
    }

    /// Where the camera and the probe sit on the receiver.
    pub fn mount(&self) -> &MountSpec {
        &self.scenario.mount
    }

    /// Frame rate, frames per second.
    pub fn fps(&self) -> f64 {
        self.scenario.fps
    }

    /// Frames in the whole run (duration times frame rate).
    pub fn frame_count(&self) -> u64 {
        self.frame_count
    }

    /// Capture time of frame 0, ns since the Unix epoch.
    pub fn start_time_ns(&self) -> u64 {
        self.scenario.start_time_ns
    }

    /// Radius of the drogue's inner circle, metres.
    pub fn inner_radius_m(&self) -> f64 {
        self.scenario.drogue.inner_radius_m
    }

    /// Radius of the canopy's outer rim, metres.
    pub fn canopy_radius_m(&self) -> f64 {
        self.scenario.drogue.canopy_radius_m
    }

    /// SITL closed loop: from now on the receiver is at this pose (body
    /// origin in local NED, metres; attitude body -> NED, w first). A
    /// non-finite or zero quaternion is ignored.
    pub fn set_receiver_pose(&mut self, position_ned_m: [f64; 3], q_ned_body: [f64; 4]) {
        let p = V3::from(position_ned_m);
        if let (true, Some(r)) = (
            p.iter().all(|v| v.is_finite()),
            matrix_from_quat(q_ned_body),
        ) {
            self.world.set_receiver_pose(p, r);
        }
    }

    /// Renders the next frame with its truth; `None` after the last.
    pub fn next_frame(&mut self) -> Option<(GrayImage, FrameTruth)> {
        if self.seq >= self.frame_count {
            return None;
        }
        let state = self.world.advance();
        let (scene, truth) = self.frame_scene(&state);
        let img = self.renderer().render(&scene);
        self.last_scene = Some(scene);
        self.seq += 1;
        Some((img, truth))
    }

    /// The camera-frame scene of the last rendered frame (for benchmarks).
    pub fn last_scene(&self) -> Option<&FrameScene> {
        self.last_scene.as_ref()
    }

    /// Renders a scene again (for benchmarks: the renderer alone).
    pub fn render_scene(&mut self, scene: &FrameScene) -> GrayImage {
        self.renderer().render(scene)
    }

    fn renderer(&mut self) -> &mut Renderer {
        let (camera, look) = (&self.camera, &self.look);
        self.renderer
            .get_or_insert_with(|| Renderer::new(camera, look.clone()))
    }

    /// Truth only (no rendering), for fast trajectory runs.
    pub fn next_truth(&mut self) -> Option<FrameTruth> {
        if self.seq >= self.frame_count {
            return None;
        }
        let state = self.world.advance();
        let (_, truth) = self.frame_scene(&state);
        self.seq += 1;
        Some(truth)
    }

    fn frame_scene(&self, st: &WorldState) -> (FrameScene, FrameTruth) {
        let sc = &self.scenario;
        let m = &sc.mount;
        let r_ned_cam = st.r_ned_body * self.r_body_cam;
        let cam_ned = st.receiver_ned + st.r_ned_body * V3::from(m.position_body_m);
        let to_cam = |p_ned: &V3| r_ned_cam.transpose() * (p_ned - cam_ned);
        let centre = to_cam(&st.drogue_ned);
        let mut normal = r_ned_cam.transpose() * st.drogue_aft_ned;
        if normal.dot(&centre) > 0.0 {
            normal = -normal;
        }
        // Strut layout: from the drogue's "up" (NED -z) projected in its plane.
        let up_cam = r_ned_cam.transpose() * V3::new(0.0, 0.0, -1.0);
        let up_in_plane = up_cam - normal * up_cam.dot(&normal);
        let e1 = if up_in_plane.norm() > 1e-6 {
            up_in_plane.normalize()
        } else {
            perpendicular(&normal)
        };
        let roll = sc.drogue.roll_deg.to_radians();
        let e2 = normal.cross(&e1);
        let (e1, e2) = (
            e1 * roll.cos() + e2 * roll.sin(),
            e2 * roll.cos() - e1 * roll.sin(),
        );
        let dr = &sc.drogue;
        let drogue = DrogueView {
            centre,
            normal,
            e1,
            e2,
            inner_radius: dr.inner_radius_m,
            canopy_radius: dr.canopy_radius_m,
            rim_width: dr.rim_width_m,
            struts: dr.struts,
            strut_width: dr.strut_width_m,
            disc: dr.disc_radiance,
            canopy: dr.canopy_radiance,
            rim: dr.rim_radiance,
            strut: dr.strut_radiance,
            throat_shade: dr.throat_shade,
            throat_shade_width: dr.throat_shade_width_m,
        };
        let hose_exit = to_cam(&st.hose_exit_ned);
        // The hose leaves the coupling, just ahead of (behind, seen from the
        // camera) the inner circle.
        let hose_start = centre - normal * 0.05;
        let hose = Tube {
            a: hose_start,
            b: hose_exit,
            radius_a: dr.hose_radius_m,
            radius_b: dr.hose_radius_m,
            radiance: dr.hose_radiance,
            collar: None,
        };
        let body_to_cam = |p_body: [f64; 3]| {
            self.r_body_cam.transpose() * (V3::from(p_body) - V3::from(m.position_body_m))
        };
        let probe = Tube {
            a: body_to_cam(m.probe_base_body_m),
            b: body_to_cam(m.probe_tip_body_m),
            radius_a: m.probe_base_radius_m,
            radius_b: m.probe_tip_radius_m,
            radiance: dr.probe_radiance,
            collar: None,
        };
        // Image motion of the drogue during the exposure.
        let blur_px = if sc.scene.motion_blur && sc.camera.exposure_ms > 0.0 {
            let v_rel = r_ned_cam.transpose() * (st.drogue_velocity_ned - st.receiver_velocity_ned);
            let half = v_rel * (sc.camera.exposure_ms * 1e-3 / 2.0);
            match (
                self.camera.project_px(&(centre - half)),
                self.camera.project_px(&(centre + half)),
            ) {
                (Some(a), Some(b)) => [b[0] - a[0], b[1] - a[1]],
                _ => [0.0, 0.0],
            }
        } else {
            [0.0, 0.0]
        };
        let scene = FrameScene {
            drogue,
            hose: Some(hose),
            probe: Some(probe),
            r_ned_cam,
            blur_px,
            noise_seed: sc.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
                ^ self.seq.wrapping_mul(0xbf58_476d_1ce4_e5b9),
            without_drogue: false,
            decals: Vec::new(),
            glare_streak: None,
            glare_glow: None,
        };
        let truth = self.truth(st, &scene, &hose, &probe);
        (scene, truth)
    }

    fn truth(&self, st: &WorldState, scene: &FrameScene, hose: &Tube, probe: &Tube) -> FrameTruth {
        let d = &scene.drogue;
        let r = d.inner_radius;
        let (centre, normal) = (d.centre, d.normal);
        let ellipse = if centre.z > 0.0 {
            circle_image_conic(&self.camera, &centre, &normal, r).and_then(|c| conic_to_ellipse(&c))
        } else {
            None
        };
        let (alt_c, alt_n) =
            mirror_pose(&self.camera, &centre, &normal, r).unwrap_or((centre, normal));
        // Rim visibility.
        let (mut by_probe, mut by_hose, mut in_image, mut visible) =
            (0usize, 0usize, 0usize, 0usize);
        for k in 0..RIM_POINTS {
            let a = k as f64 * std::f64::consts::TAU / RIM_POINTS as f64;
            let p = centre + (d.e1 * a.cos() + d.e2 * a.sin()) * r;
            if p.z <= 1e-6 {
                continue;
            }
            let ray = p / p.z;
            let hid_probe = probe.occludes(&ray, p.z);
            let hid_hose = hose.occludes(&ray, p.z);
            by_probe += hid_probe as usize;
            by_hose += hid_hose as usize;
            let inside = self
                .camera
                .project_px(&p)
                .is_some_and(|q| self.camera.in_image(q))
                && (ray.x.abs() < 2.0 && ray.y.abs() < 2.0);
            in_image += inside as usize;
            visible += (inside && !hid_probe && !hid_hose) as usize;
        }
        let n = RIM_POINTS as f64;
        let centre_in_image = centre.z > 0.0
            && self
                .camera
                .project_px(&centre)
                .is_some_and(|q| self.camera.in_image(q));
        let expect =
            if centre_in_image && visible as f64 / n >= MIN_VISIBLE_RIM && ellipse.is_some() {
                "detect"
            } else {
                "no_detect"
            };
        let range = centre.norm();
        let tilt = (normal.dot(&(-centre)) / range)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let m = &self.scenario.mount;
        let position_body = self.r_body_cam * centre + V3::from(m.position_body_m);
        let normal_body = self.r_body_cam * normal;
        let t = st.t;
        FrameTruth {
            frame: format!("frame_{:06}.png", self.seq),
            seq: self.seq,
            t,
            expect: expect.into(),
            radius: r,
            position_camera: to_array(&centre),
            normal_camera: to_array(&normal),
            alt_position_camera: to_array(&alt_c),
            alt_normal_camera: to_array(&alt_n),
            ellipse,
            range_m: range,
            tilt_deg: tilt,
            probe_rim_frac: by_probe as f64 / n,
            hose_rim_frac: by_hose as f64 / n,
            rim_fully_in_image: in_image == RIM_POINTS,
            position_body: to_array(&position_body),
            normal_body: to_array(&normal_body),
            ned_frame: crate::NED_FRAME_SCENARIO.into(),
            position_ned: to_array(&st.drogue_ned),
            receiver_position_ned: to_array(&st.receiver_ned),
            receiver_q_ned_body: quat_from_matrix(&st.r_ned_body),
            capture_time_ns: self.scenario.start_time_ns + (t * 1e9).round() as u64,
            canopy_radius: d.canopy_radius,
            visible_rim_frac: visible as f64 / n,
            coupled: st.coupled,
            blur_px: scene.blur_px,
        }
    }
}

impl Iterator for Simulator {
    type Item = (GrayImage, FrameTruth);

    fn next(&mut self) -> Option<Self::Item> {
        self.next_frame()
    }
}
