//! Randomised single frames for a robustness sweep: one factor at a time
//! (haze, glare streak over the disc, motion blur, noise, exposure,
//! vignetting, lens distortion, range, tilt, probe occlusion, distractors,
//! star distractors, the canopy's throat shadow), the probe's rounded tip
//! over the disc's middle with blur and harsh imaging (`probe tip`),
//! and everything at once, plus drogue-free frames with look-alikes
//! (crescents, canopy-less discs and rings, dark blobs and rectangles,
//! stars and flowers).
//!
//! Every frame is an unrelated view with a drogue at a random place in the
//! field on top of a mild baseline (range 2-8 m, tilt 0-45 degrees, hose,
//! light clouds, read noise 1.5 DN, vignetting 0.15), with the level's factor
//! applied. It is deterministic for (seed, level, index): a regression shows
//! as a change in the same frames. The truth (image ellipse, pose, mirror
//! pose, rim shares) comes from the geometry through [`crate::conic`], never
//! from the pixels.

use crate::TruthEllipse;
use crate::camera::SimCamera;
use crate::geometry::{V3, r_body_cam};
use crate::render::{Collar, FrameScene, GlareGlow, GlareStreak, Look, Renderer, Tube};
use image::GrayImage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{PI, TAU};

mod layout;
mod look_alikes;

use layout::{lay_out_drogue, placeholder_drogue};
use look_alikes::{dark_shape, look_alikes};

/// Radius of the dark inner circle, metres (the reference data's).
pub const INNER_RADIUS_M: f64 = 0.15;
/// Radius of the canopy's outer rim, metres.
pub const CANOPY_RADIUS_M: f64 = 0.33;
/// Rim points for the occlusion shares.
const RIM_POINTS: usize = 360;

/// Strongest throat shadow the `everything` level draws: up to 30 % of the
/// canopy's radiance lost at the disc's edge, a canopy in its coupling's
/// shadow.
const MAX_THROAT_SHADE: f64 = 0.3;

/// Range of the throat shadow's e-folding width, metres: an eighth to a
/// third of the inner radius, from a tight shadow line to a soft one.
const THROAT_SHADE_WIDTH_M: (f64, f64) = (0.02, 0.05);

/// Most radiance a glare glow adds at the disc's nearest rim: the disc
/// (radiance about 0.1) stays below saturation, a darker shape beside the
/// light however strong the glow (but where the glow's faint streak
/// crosses it close to the glow).
const MAX_GLOW_AT_RIM: f64 = 0.7;

/// Salt of the throat shadow's random stream.
const THROAT_STREAM: u64 = 0x7468_726f_6174;

/// Salt of the probe collar's random stream.
const COLLAR_STREAM: u64 = 0x636f_6c6c_6172;

/// Where a probe's nozzle collar starts and how long it is, in tip radii
/// along the axis back from the centre of the probe's rounded end, and its
/// radiance as a multiple of the probe's: a light metal ring a little
/// behind the nozzle, as refuelling probes have (and as the independent
/// renderer's reference frames draw it, a band across the probe from
/// about a quarter of a tip radius behind the tip to about one).
const COLLAR_FROM_TIP_RADII: (f64, f64) = (0.15, 0.45);
const COLLAR_LENGTH_RADII: (f64, f64) = (0.45, 0.75);
const COLLAR_RADIANCE_TIMES: (f64, f64) = (1.5, 2.5);

/// What a sweep level varies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Factor {
    /// The baseline alone.
    Baseline,
    /// Haze (value: 0..1, the share of the haze radiance mixed in).
    Haze,
    /// A saturating sun-glare streak crossing the disc (value: its full
    /// width at half maximum, pixels).
    Glare,
    /// Linear motion blur of the drogue (value: length, pixels).
    Blur,
    /// Sensor read noise (value: sigma, grey levels).
    Noise,
    /// Exposure gain (value: 1 = nominal).
    Exposure,
    /// Vignetting (value: relative fall-off at the corner).
    Vignetting,
    /// Barrel distortion (value: k1; k2 = -k1 / 3).
    Distortion,
    /// Range (value: metres), tilt 20 degrees.
    Range,
    /// Tilt (value: degrees), range 2.5-4 m.
    Tilt,
    /// The probe over a share of the inner rim (value: lower end of a
    /// 10 % bin, 0..0.3), range 2.5-4 m.
    Occlusion,
    /// Dark blobs and rectangles around the drogue (value: how many).
    Distractors,
    /// Everything at once (like the reference `hard` sets).
    Everything,
    /// Drogue-free: a dark disc partly covered by a lighter one.
    Crescent,
    /// Drogue-free: a dark disc without a canopy.
    CanopylessDisc,
    /// Drogue-free: a dark ring without a canopy.
    DarkRing,
    /// Drogue-free: dark blobs and rectangles only.
    DarkShapes,
    /// Drogue-free: dark stars and flowers (rounded arms joined at a body).
    DarkStars,
    /// Dark stars and flowers around the drogue (value: how many).
    StarDistractors,
    /// The canopy darkened toward the disc by the throat's shadow (value:
    /// the share of its radiance lost at the disc's edge).
    ThroatShadow,
    /// The glow about the sun's image near the disc, with a faint streak
    /// through it (value: the glow's standard deviation, pixels).
    GlareGlow,
    /// The probe's rounded tip over the disc's middle, as wide as the
    /// share asks (value: lower end of a 10 % bin of the rim hidden), at
    /// 3-7 m, tilt 20-60 degrees, blur 8-15 px and the `everything`
    /// level's imaging. Last: a level's frames are seeded from its
    /// factor's place in this list.
    ProbeTip,
}

impl Factor {
    /// The factor in words, for reports.
    pub fn name(self) -> &'static str {
        match self {
            Factor::Baseline => "baseline",
            Factor::Haze => "haze",
            Factor::Glare => "glare streak",
            Factor::GlareGlow => "glare glow",
            Factor::Blur => "motion blur",
            Factor::Noise => "noise",
            Factor::Exposure => "exposure",
            Factor::Vignetting => "vignetting",
            Factor::Distortion => "distortion",
            Factor::Range => "range",
            Factor::Tilt => "tilt",
            Factor::Occlusion => "probe occlusion",
            Factor::ProbeTip => "probe tip",
            Factor::Distractors => "distractors",
            Factor::StarDistractors => "star distractors",
            Factor::ThroatShadow => "throat shadow",
            Factor::Everything => "everything",
            Factor::Crescent => "no drogue: crescent",
            Factor::CanopylessDisc => "no drogue: disc without canopy",
            Factor::DarkRing => "no drogue: ring without canopy",
            Factor::DarkShapes => "no drogue: dark blobs, rectangles",
            Factor::DarkStars => "no drogue: stars, flowers",
        }
    }

    /// Whether the level's frames show a drogue.
    pub fn has_drogue(self) -> bool {
        !matches!(
            self,
            Factor::Crescent
                | Factor::CanopylessDisc
                | Factor::DarkRing
                | Factor::DarkShapes
                | Factor::DarkStars
        )
    }
}

/// One row of the sweep: a factor at one setting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Level {
    /// What is varied.
    pub factor: Factor,
    /// Its setting, in the factor's unit (see each [`Factor`]).
    pub value: f64,
}

impl Level {
    /// A level of `factor` at `value`.
    pub const fn new(factor: Factor, value: f64) -> Level {
        Level { factor, value }
    }

    /// The setting in words, e.g. `16 px`, `20-30 %`.
    pub fn setting(&self) -> String {
        let v = self.value;
        match self.factor {
            Factor::Haze => format!("{v:.1}"),
            Factor::Glare => format!("{v:.0} px wide"),
            Factor::GlareGlow => format!("sigma {v:.0} px"),
            Factor::Blur => format!("{v:.0} px"),
            Factor::Noise => format!("sigma {v:.0}"),
            Factor::Exposure => format!("gain {v:.1}"),
            Factor::Vignetting => format!("{v:.1}"),
            Factor::Distortion => format!("k1 {v:.2}"),
            Factor::Range => format!("{v:.0} m"),
            Factor::Tilt => format!("{v:.0} deg"),
            Factor::Occlusion | Factor::ProbeTip => {
                format!("{:.0}-{:.0} %", v * 100.0, v * 100.0 + 10.0)
            }
            Factor::Distractors | Factor::StarDistractors => format!("{v:.0}"),
            Factor::ThroatShadow => format!("{:.0} %", v * 100.0),
            _ => "-".into(),
        }
    }

    /// `factor setting`, for tables and messages.
    pub fn label(&self) -> String {
        match self.setting().as_str() {
            "-" => self.factor.name().to_string(),
            s => format!("{} {s}", self.factor.name()),
        }
    }
}

/// The sweep's levels: each factor over its range, then everything at once,
/// then the drogue-free kinds.
pub fn standard_levels() -> Vec<Level> {
    use Factor::{
        Baseline, Blur, CanopylessDisc, Crescent, DarkRing, DarkShapes, DarkStars, Distortion,
        Distractors, Everything, Exposure, Glare, GlareGlow, Haze, Noise, Occlusion, ProbeTip,
        Range, StarDistractors, ThroatShadow, Tilt, Vignetting,
    };
    let mut levels = vec![Level::new(Baseline, 0.0)];
    let mut add = |f: Factor, values: &[f64]| {
        levels.extend(values.iter().map(|&v| Level::new(f, v)));
    };
    add(Haze, &[0.2, 0.4, 0.6]);
    add(Glare, &[4.0, 12.0, 30.0]);
    add(GlareGlow, &[30.0, 70.0, 135.0]);
    add(Blur, &[4.0, 8.0, 16.0, 32.0]);
    add(Noise, &[2.0, 5.0, 10.0, 20.0]);
    add(Exposure, &[0.4, 0.7, 1.3]);
    add(Vignetting, &[0.4, 0.7]);
    add(Distortion, &[-0.12, -0.25]);
    add(Range, &[1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 16.0]);
    add(Tilt, &[0.0, 15.0, 30.0, 45.0, 60.0, 75.0]);
    add(Occlusion, &[0.0, 0.1, 0.2, 0.3]);
    add(ProbeTip, &[0.1, 0.2, 0.3]);
    add(Distractors, &[1.0, 3.0]);
    add(StarDistractors, &[2.0]);
    add(ThroatShadow, &[0.15, 0.3]);
    add(Everything, &[0.0]);
    add(Crescent, &[0.0]);
    add(CanopylessDisc, &[0.0]);
    add(DarkRing, &[0.0]);
    add(DarkShapes, &[0.0]);
    add(DarkStars, &[0.0]);
    levels
}

/// The truth of a frame's drogue, camera frame (x right, y down, z forward).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrogueTruth {
    /// Exact image ellipse of the inner circle, undistorted pixels.
    pub ellipse: TruthEllipse,
    /// Inner circle centre, metres.
    pub position_camera: [f64; 3],
    /// Unit normal toward the camera.
    pub normal_camera: [f64; 3],
    /// The mirror pose imaging to the same ellipse.
    pub alt_position_camera: [f64; 3],
    /// Normal of the mirror pose.
    pub alt_normal_camera: [f64; 3],
    /// Distance to the inner circle's centre, metres.
    pub range_m: f64,
    /// Angle between the drogue normal and the line of sight, degrees.
    pub tilt_deg: f64,
    /// Share of the inner rim hidden by the probe, 0..1.
    pub probe_rim_frac: f64,
    /// Share of the inner rim visible (in the image, not hidden), 0..1.
    pub visible_rim_frac: f64,
    /// Enough of the rim is visible for a detection to be expected
    /// (the simulator's own rule, [`MIN_VISIBLE_RIM`](crate::simulator::MIN_VISIBLE_RIM)).
    pub expect_detect: bool,
}

/// One rendered sweep frame.
#[derive(Clone, Debug)]
pub struct SweepFrame {
    /// The level the frame belongs to.
    pub level: Level,
    /// Index of the frame within its level (seeds its randomness).
    pub index: u64,
    /// The camera the frame was rendered through.
    pub camera: SimCamera,
    /// The rendered 8-bit image.
    pub image: GrayImage,
    /// `None` on drogue-free frames.
    pub drogue: Option<DrogueTruth>,
    /// The settings the frame was drawn with.
    pub settings: Settings,
}

/// Renders sweep frames; keeps one renderer per lens (the ray table is the
/// expensive part of a renderer).
pub struct Sweep {
    seed: u64,
    renderers: Vec<(SimCamera, Renderer)>,
    /// Throat shadow strength every drogue frame is drawn with, in place of
    /// its level's ([`Sweep::with_throat_shade`]).
    throat_shade: Option<f64>,
}

/// The reference data's camera (the paper's 5 mm lens on 3.75 um pixels),
/// with the given plumb_bob distortion.
pub fn camera(distortion: [f64; 5]) -> SimCamera {
    SimCamera {
        width: 1280,
        height: 960,
        fx: 1336.2,
        fy: 1335.4,
        cx: 646.3,
        cy: 473.8,
        distortion,
    }
}

/// splitmix64: decorrelates the per-frame seeds.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Scene settings of one frame before it is laid out: what a frame's
/// error can be traced back to.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Range asked for, metres.
    pub range_m: f64,
    /// Tilt asked for, degrees.
    pub tilt_deg: f64,
    /// Exposure gain (1: nominal).
    pub gain: f64,
    /// Read noise, digital numbers (gray levels) rms.
    pub read_noise_dn: f64,
    /// Vignetting strength at the corners.
    pub vignette: f64,
    /// Haze, share of the scene replaced by the sky's level.
    pub haze: f64,
    /// Linear motion blur length, pixels.
    pub blur_px: f64,
    /// Width of a glare streak over the disc, pixels, if any.
    pub glare_width_px: Option<f64>,
    /// Standard deviation of a glare glow near the disc, pixels, if any.
    pub glare_glow_sigma_px: Option<f64>,
    /// Share of the rim the probe may hide (low, high), if a probe.
    pub probe_bin: Option<(f64, f64)>,
    /// The probe's tip lies over the disc's middle, its width chosen for
    /// the share (else the probe of fixed width slides sideways).
    pub probe_tip: bool,
    /// Dark distractor shapes.
    pub distractors: usize,
    /// The distractors are stars and flowers (else blobs and rectangles).
    pub star_distractors: bool,
    /// Plumb-bob distortion (k1, k2, p1, p2, k3).
    pub distortion: [f64; 5],
    /// Share of the canopy's radiance the throat's shadow takes at the
    /// disc's edge ([`crate::render::DrogueView::throat_shade`]).
    pub throat_shade: f64,
    /// E-folding width of the throat's shadow, metres.
    pub throat_shade_width_m: f64,
}

impl Sweep {
    /// A sweep whose frames are seeded from `seed`.
    pub fn new(seed: u64) -> Sweep {
        Sweep {
            seed,
            renderers: Vec::new(),
            throat_shade: None,
        }
    }

    /// The same sweep with every drogue frame's throat shadow of this
    /// strength (the share of the canopy's radiance it takes at the disc's
    /// edge, from 0 up to but not 1; its width still drawn per frame),
    /// whatever its level: to tell the shadow's effect apart from another
    /// factor's (blur merges the shadow with the disc's step,
    /// `examples/rim_bias.rs`). The scenes are otherwise the same frame for
    /// frame (the shadow has its own random stream). `None` for a strength
    /// outside that range (NaN included).
    pub fn with_throat_shade(mut self, strength: f64) -> Option<Sweep> {
        if !(0.0..1.0).contains(&strength) {
            return None;
        }
        self.throat_shade = Some(strength);
        Some(self)
    }

    fn renderer(&mut self, distortion: [f64; 5], look: Look) -> (SimCamera, &mut Renderer) {
        let i = match self
            .renderers
            .iter()
            .position(|(c, _)| c.distortion == distortion)
        {
            Some(i) => i,
            None => {
                let cam = camera(distortion);
                let r = Renderer::new(&cam, look.clone());
                self.renderers.push((cam, r));
                self.renderers.len() - 1
            }
        };
        let (cam, r) = &mut self.renderers[i];
        r.set_look(look);
        (cam.clone(), r)
    }

    /// Frame `index` of `level`.
    pub fn frame(&mut self, level: &Level, index: u64) -> SweepFrame {
        let key = mix(self.seed
            ^ mix(level.factor as u64 + 1)
            ^ mix(level.value.to_bits()).rotate_left(17)
            ^ mix(index).rotate_left(41));
        let mut rng = ChaCha8Rng::seed_from_u64(key);
        let mut s = settings(level, &mut rng);
        (s.throat_shade, s.throat_shade_width_m) = throat_shadow(level, key);
        if let Some(strength) = self.throat_shade {
            s.throat_shade = strength;
        }
        let look = Look {
            sky_zenith: 0.50,
            sky_horizon: 0.68,
            ground: 0.55,
            cloud_cover: rng.random_range(0.0..0.6),
            cloud_radiance: 0.85,
            sun_ned: {
                let (az, el) = (
                    rng.random_range(0.0..TAU),
                    rng.random_range(10f64..70.0).to_radians(),
                );
                V3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin())
            },
            glare: 0.0,
            haze: s.haze,
            haze_radiance: 0.75,
            gain: s.gain,
            read_noise_dn: s.read_noise_dn,
            shot_noise_dn: 0.02,
            vignette: s.vignette,
            cloud_seed: rng.random(),
        };
        let r_ned_cam = r_body_cam(
            rng.random_range(-15.0..15.0),
            rng.random_range(-3.0..12.0),
            rng.random_range(0.0..360.0),
        );
        let cam = camera(s.distortion);
        let noise_seed = rng.random();
        let mut scene = FrameScene {
            drogue: placeholder_drogue(),
            hose: None,
            probe: None,
            r_ned_cam,
            blur_px: [0.0, 0.0],
            noise_seed,
            without_drogue: true,
            decals: Vec::new(),
            glare_streak: None,
            glare_glow: None,
        };
        let mut truth = None;
        if level.factor.has_drogue() {
            let (mut drogue, hose, probe, t) = lay_out_drogue(&cam, &s, &mut rng);
            drogue.throat_shade = s.throat_shade;
            drogue.throat_shade_width = s.throat_shade_width_m;
            let centre_px = cam.project_px(&drogue.centre).unwrap_or([cam.cx, cam.cy]);
            if let Some(width_px) = s.glare_width_px {
                let a_px = t.ellipse.a;
                let off = rng.random_range(-0.5..0.5) * a_px;
                let angle = rng.random_range(0.0..PI);
                scene.glare_streak = Some(GlareStreak {
                    through_px: [
                        centre_px[0] - angle.sin() * off,
                        centre_px[1] + angle.cos() * off,
                    ],
                    angle_rad: angle,
                    width_px,
                    strength: rng.random_range(1.0..1.6),
                });
            }
            if let Some(sigma_px) = s.glare_glow_sigma_px {
                (scene.glare_glow, scene.glare_streak) =
                    glow_near(centre_px, t.ellipse.a, sigma_px, &mut rng);
            }
            let phi = rng.random_range(0.0..TAU);
            scene.blur_px = [s.blur_px * phi.cos(), s.blur_px * phi.sin()];
            scene.drogue = drogue;
            scene.hose = Some(hose);
            scene.probe = probe.map(|p| with_collar(p, key));
            scene.without_drogue = false;
            for _ in 0..s.distractors {
                scene.decals.push(dark_shape(
                    &cam,
                    &mut rng,
                    Some(centre_px),
                    s.star_distractors,
                ));
            }
            truth = Some(t);
        } else {
            scene.decals = look_alikes(level.factor, &cam, &mut rng);
        }
        let (camera, renderer) = self.renderer(s.distortion, look);
        let image = renderer.render(&scene);
        SweepFrame {
            level: *level,
            index,
            camera,
            image,
            drogue: truth,
            settings: s,
        }
    }
}

/// A glare glow of `sigma_px` whose centre lies half to two and a half
/// standard deviations beyond the rim of the disc (centre `centre_px`,
/// major semi-axis `a_px`), in any direction, and the faint streak through
/// it that a lens's flare draws (a tenth to a quarter of the scene's
/// radiance, a quarter to one standard deviation wide). The glow lightens
/// the disc more on one side than the other and saturates the canopy
/// about it when strong; its strength (0.4-1.2) is held to at most 0.7 at
/// the disc's nearest rim, so that the disc stays below saturation (but
/// where the streak, up to 0.25 more, crosses it close to the glow): a
/// person still sees it, a darker shape on the light.
fn glow_near(
    centre_px: [f64; 2],
    a_px: f64,
    sigma_px: f64,
    rng: &mut ChaCha8Rng,
) -> (Option<GlareGlow>, Option<GlareStreak>) {
    let (bearing, beyond) = (rng.random_range(0.0..TAU), rng.random_range(0.5..2.5));
    let apart = a_px + beyond * sigma_px;
    let at_rim_cap = MAX_GLOW_AT_RIM * (0.5 * beyond * beyond).exp();
    let glow = GlareGlow {
        centre_px: [
            centre_px[0] + apart * bearing.cos(),
            centre_px[1] + apart * bearing.sin(),
        ],
        sigma_px,
        strength: rng.random_range(0.4..1.2f64).min(at_rim_cap),
    };
    let streak = GlareStreak {
        through_px: glow.centre_px,
        angle_rad: rng.random_range(0.0..PI),
        width_px: rng.random_range(0.25..1.0) * sigma_px,
        strength: rng.random_range(0.1..0.25),
    };
    (Some(glow), Some(streak))
}

/// The baseline, with the level's factor applied.
fn settings(level: &Level, rng: &mut ChaCha8Rng) -> Settings {
    let mut s = Settings {
        range_m: rng.random_range(2.0..8.0),
        tilt_deg: rng.random_range(0.0..45.0),
        gain: 1.0,
        read_noise_dn: 1.5,
        vignette: 0.15,
        haze: 0.0,
        blur_px: 0.0,
        glare_width_px: None,
        glare_glow_sigma_px: None,
        probe_bin: None,
        probe_tip: false,
        distractors: 0,
        star_distractors: false,
        distortion: [0.0; 5],
        throat_shade: 0.0,
        throat_shade_width_m: THROAT_SHADE_WIDTH_M.0,
    };
    let v = level.value;
    match level.factor {
        Factor::Haze => s.haze = v,
        Factor::Glare => s.glare_width_px = Some(v),
        Factor::GlareGlow => s.glare_glow_sigma_px = Some(v),
        Factor::Blur => s.blur_px = v,
        Factor::Noise => s.read_noise_dn = v,
        Factor::Exposure => s.gain = v,
        Factor::Vignetting => s.vignette = v,
        Factor::Distortion => s.distortion = [v, -v / 3.0, 0.0, 0.0, 0.0],
        Factor::Range => {
            s.range_m = v;
            s.tilt_deg = 20.0;
        }
        Factor::Tilt => {
            s.range_m = rng.random_range(2.5..4.0);
            s.tilt_deg = v;
        }
        Factor::Occlusion => {
            s.range_m = rng.random_range(2.5..4.0);
            s.probe_bin = Some((v, v + 0.1));
        }
        Factor::ProbeTip => {
            s.range_m = rng.random_range(3.0..7.0);
            s.tilt_deg = rng.random_range(20.0..60.0);
            harsh_imaging(&mut s, rng);
            s.blur_px = rng.random_range(8.0..15.0);
            s.probe_bin = Some((v, v + 0.1));
            s.probe_tip = true;
        }
        Factor::Distractors => s.distractors = v as usize,
        Factor::StarDistractors => {
            s.distractors = v as usize;
            s.star_distractors = true;
        }
        Factor::Everything => {
            s.distortion = [-0.25, 0.08, 0.0, 0.0, 0.0];
            s.range_m = rng.random_range(2.0..10.0);
            s.tilt_deg = rng.random_range(0.0..60.0);
            harsh_imaging(&mut s, rng);
            if rng.random_bool(0.5) {
                s.blur_px = rng.random_range(3.0..15.0);
            }
            if rng.random_bool(0.5) {
                s.glare_width_px = Some(rng.random_range(4.0..20.0));
            }
            if rng.random_bool(0.6) {
                let lo = rng.random_range(0.03..0.2);
                s.probe_bin = Some((lo, lo + 0.05));
            }
            if rng.random_bool(0.25) {
                s.distractors = 1;
            }
        }
        // Arms among noise and haze: where a chance edge is most often
        // taken for the canopy's rim.
        Factor::DarkStars => {
            s.distortion = [-0.25, 0.08, 0.0, 0.0, 0.0];
            harsh_imaging(&mut s, rng);
        }
        Factor::Baseline
        | Factor::ThroatShadow
        | Factor::Crescent
        | Factor::CanopylessDisc
        | Factor::DarkRing
        | Factor::DarkShapes => {}
    }
    s
}

/// `probe` with a nozzle collar drawn from a stream of its own (so that
/// every other draw of a frame is what it was before probes had collars).
fn with_collar(probe: Tube, key: u64) -> Tube {
    let mut rng = ChaCha8Rng::seed_from_u64(mix(key ^ COLLAR_STREAM));
    let r = probe.radius_b;
    let from_tip_m = r * rng.random_range(COLLAR_FROM_TIP_RADII.0..COLLAR_FROM_TIP_RADII.1);
    let length_m = r * rng.random_range(COLLAR_LENGTH_RADII.0..COLLAR_LENGTH_RADII.1);
    let radiance =
        probe.radiance * rng.random_range(COLLAR_RADIANCE_TIMES.0..COLLAR_RADIANCE_TIMES.1);
    Tube {
        collar: Some(Collar {
            from_tip_m,
            to_tip_m: from_tip_m + length_m,
            radiance,
        }),
        ..probe
    }
}

/// The canopy's throat shadow (strength, e-folding width in metres): the
/// level's own strength, a random one for `everything`, none otherwise.
/// Drawn from a stream of its own, so that every other draw of a frame is
/// what it was before the canopy had a shadow.
fn throat_shadow(level: &Level, key: u64) -> (f64, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(mix(key ^ THROAT_STREAM));
    let width_m = rng.random_range(THROAT_SHADE_WIDTH_M.0..THROAT_SHADE_WIDTH_M.1);
    let strength = match level.factor {
        Factor::ThroatShadow => level.value,
        Factor::Everything => rng.random_range(0.0..MAX_THROAT_SHADE),
        _ => 0.0,
    };
    (strength, width_m)
}

/// The `everything` level's imaging: read noise 2-8 DN, gain 0.4-1.3,
/// vignetting 0.1-0.5 and, half the time, haze 0.3-0.6.
fn harsh_imaging(s: &mut Settings, rng: &mut ChaCha8Rng) {
    s.read_noise_dn = rng.random_range(2.0..8.0);
    s.gain = rng.random_range(0.4..1.3);
    s.vignette = rng.random_range(0.1..0.5);
    if rng.random_bool(0.5) {
        s.haze = rng.random_range(0.3..0.6);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use layout::TIP_NEAR_CENTRE;

    #[test]
    fn frames_are_deterministic_and_levels_distinct() {
        let mut a = Sweep::new(7);
        let mut b = Sweep::new(7);
        let level = Level::new(Factor::Everything, 0.0);
        let (fa, fb) = (a.frame(&level, 3), b.frame(&level, 3));
        assert_eq!(fa.image, fb.image);
        assert_eq!(fa.drogue, fb.drogue);
        let other = a.frame(&level, 4);
        assert_ne!(fa.image, other.image);
    }

    #[test]
    fn a_frame_carries_the_setting_its_level_asked_for() {
        let mut sweep = Sweep::new(3);
        let blur = sweep.frame(&Level::new(Factor::Blur, 16.0), 0).settings;
        assert_eq!(blur.blur_px, 16.0);
        let noise = sweep.frame(&Level::new(Factor::Noise, 12.0), 0).settings;
        assert_eq!((noise.read_noise_dn, noise.blur_px), (12.0, 0.0));
        let haze = sweep.frame(&Level::new(Factor::Haze, 0.4), 1).settings;
        assert_eq!(haze.haze, 0.4);
        assert_eq!(haze.throat_shade, 0.0);
        let throat = sweep
            .frame(&Level::new(Factor::ThroatShadow, 0.3), 2)
            .settings;
        assert_eq!(throat.throat_shade, 0.3);
        let (lo, hi) = THROAT_SHADE_WIDTH_M;
        assert!((lo..hi).contains(&throat.throat_shade_width_m));
    }

    /// A throat shadow asked of the whole sweep shades the canopy next to
    /// the disc of a level that has none, and changes nothing else: the
    /// same scene, the same truth, the canopy darker where the shadow
    /// lies and nowhere lighter.
    #[test]
    fn a_throat_shadow_asked_for_shades_only_the_canopy_of_the_same_scene() {
        let level = Level::new(Factor::Blur, 8.0);
        let plain = Sweep::new(5).frame(&level, 1);
        let shaded = Sweep::new(5)
            .with_throat_shade(0.3)
            .unwrap()
            .frame(&level, 1);
        assert_eq!(plain.settings.throat_shade, 0.0);
        assert_eq!(shaded.settings.throat_shade, 0.3);
        assert_eq!(plain.drogue, shaded.drogue);
        let (mut darker, mut lighter) = (0usize, 0usize);
        for (p, q) in plain.image.pixels().zip(shaded.image.pixels()) {
            // The read noise is seeded per frame: the same in both.
            darker += usize::from(q.0[0] + 2 < p.0[0]);
            lighter += usize::from(q.0[0] > p.0[0] + 2);
        }
        assert!(darker > 100, "{darker} pixels darker");
        assert_eq!(lighter, 0);
        assert!(Sweep::new(5).with_throat_shade(1.0).is_none());
        assert!(Sweep::new(5).with_throat_shade(f64::NAN).is_none());
    }

    #[test]
    fn probe_tip_levels_put_the_tip_over_the_middle_and_hide_their_share() {
        let cam = camera([0.0; 5]);
        for lo in [0.1, 0.2, 0.3] {
            let level = Level::new(Factor::ProbeTip, lo);
            for i in 0..4 {
                let mut rng = ChaCha8Rng::seed_from_u64(100 * i + (10.0 * lo) as u64);
                let s = settings(&level, &mut rng);
                let (drogue, _, probe, t) = lay_out_drogue(&cam, &s, &mut rng);
                let tip = probe.expect("a probe");
                // The tip's centre seen from the camera, carried along its
                // ray to the drogue's depth: b = k (c + o) with o across the
                // line of sight, so b |c|^2 / (b . c) = c + o.
                let c = drogue.centre;
                let k = tip.b.dot(&c) / c.norm_squared();
                let across = (tip.b / k - c).norm();
                assert!(
                    across <= TIP_NEAR_CENTRE * INNER_RADIUS_M + 1e-9,
                    "bin {lo}, frame {i}: tip {across} m from the centre"
                );
                // As wide as seen as the disc at most.
                assert!(tip.radius_b / k <= INNER_RADIUS_M + 1e-9);
                assert!(tip.radius_a > tip.radius_b);
                assert!(
                    t.probe_rim_frac >= lo - 0.015 && t.probe_rim_frac <= lo + 0.115,
                    "bin {lo}, frame {i}: {}",
                    t.probe_rim_frac
                );
                assert!(t.expect_detect);
            }
            // The level draws what it says.
            let f = Sweep::new(3).frame(&level, 0);
            assert!(f.settings.probe_tip);
            assert!((8.0..15.0).contains(&f.settings.blur_px));
            assert!((3.0..7.0).contains(&f.settings.range_m));
        }
    }

    #[test]
    fn probe_levels_hide_their_share_of_the_rim() {
        let mut sweep = Sweep::new(1);
        for lo in [0.0, 0.1, 0.2, 0.3] {
            for i in 0..3 {
                let f = sweep.frame(&Level::new(Factor::Occlusion, lo), i);
                let t = f.drogue.unwrap();
                assert!(
                    t.probe_rim_frac >= lo.max(0.02) - 0.015 && t.probe_rim_frac <= lo + 0.115,
                    "bin {lo}: {}",
                    t.probe_rim_frac
                );
                assert!(t.expect_detect);
            }
        }
    }

    #[test]
    fn drogue_frames_have_the_rim_in_view_and_the_dark_disc_where_the_truth_says() {
        let mut sweep = Sweep::new(2);
        for level in standard_levels().iter().filter(|l| l.factor.has_drogue()) {
            let f = sweep.frame(level, 0);
            let t = f.drogue.unwrap();
            assert!(t.expect_detect, "{}", level.label());
            // The truth ellipse's centre (undistorted) back through the lens
            // lands on a dark pixel when nothing covers it.
            if matches!(
                level.factor,
                Factor::Baseline | Factor::Range | Factor::Tilt
            ) {
                let [u, v] = f.camera.distort_px([t.ellipse.cx, t.ellipse.cy]);
                let g = f.image.get_pixel(u.round() as u32, v.round() as u32)[0];
                assert!(g < 60, "{}: grey {g} at the disc centre", level.label());
            }
        }
    }
}
