//! What a frame shows, as the renderer takes it: the drogue, the hose and
//! probe tubes, decals and a glare streak in the camera frame, and the
//! scene-wide look. Plain data; the simulator and the sweep build it, the
//! renderer only reads it.

use super::tube::TubeAxis;
use crate::geometry::{M3, V3};

/// A tube (hose, probe): axis segment a -> b in the camera frame, radii.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tube {
    /// Axis start, camera frame, metres.
    pub a: V3,
    /// Axis end, camera frame, metres.
    pub b: V3,
    /// Radius at `a`, metres.
    pub radius_a: f64,
    /// Radius at `b`, metres.
    pub radius_b: f64,
    /// Relative radiance 0..1.
    pub radiance: f64,
    /// A lighter ring round the tube near its `b` end (a probe's nozzle
    /// collar), if any.
    pub collar: Option<Collar>,
}

/// A band round a tube, measured along its axis back from the `b` end
/// (the probe's tip: the centre of its rounded end), drawn with a radiance
/// of its own: the light metal collar behind a refuelling probe's nozzle,
/// which crosses the drogue's disc when the probe points into it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Collar {
    /// Where the band starts, metres back from `b` along the axis.
    pub from_tip_m: f64,
    /// Where it ends, metres back from `b` (more than `from_tip_m`).
    pub to_tip_m: f64,
    /// Relative radiance 0..1 of the band.
    pub radiance: f64,
}

impl Tube {
    /// The radiance at axis position `s` (metres from `a`, the axis
    /// `len_m` long): the collar's within its band, the tube's elsewhere.
    #[inline]
    pub(super) fn radiance_at(&self, s: f64, len_m: f64) -> f64 {
        match self.collar {
            Some(c) if (c.from_tip_m..=c.to_tip_m).contains(&(len_m - s)) => c.radiance,
            _ => self.radiance,
        }
    }

    /// Closest approach of the ray t * d (d = (x, y, 1), t = depth) to the
    /// tube's axis: (depth t, distance beyond the surface in metres,
    /// distance from the axis over the radius).
    #[inline]
    pub fn probe_ray(&self, d: &V3) -> Option<(f64, f64, f64)> {
        TubeAxis::new(self)?.probe_ray(d)
    }

    /// Whether the ray hits the tube nearer than `depth` (z, metres).
    pub fn occludes(&self, d: &V3, depth: f64) -> bool {
        matches!(self.probe_ray(d), Some((t, sd, _)) if sd < 0.0 && t < depth)
    }

    /// The part of the tube in front of the plane z = `near`.
    pub fn clipped(&self, near: f64) -> Option<Tube> {
        let (za, zb) = (self.a.z, self.b.z);
        if za < near && zb < near {
            return None;
        }
        let mut t = *self;
        if za < near || zb < near {
            let f = (near - za) / (zb - za);
            let p = self.a + (self.b - self.a) * f;
            let r = self.radius_a + (self.radius_b - self.radius_a) * f;
            if za < near {
                t.a = p;
                t.radius_a = r;
            } else {
                t.b = p;
                t.radius_b = r;
            }
        }
        Some(t)
    }
}

/// The drogue in the camera frame.
#[derive(Clone, Copy, Debug)]
pub struct DrogueView {
    /// Centre of the inner circle, camera frame, metres.
    pub centre: V3,
    /// Unit normal toward the camera.
    pub normal: V3,
    /// In-plane basis; struts are laid out from `e1`.
    pub e1: V3,
    /// Second in-plane axis, `normal` x `e1`.
    pub e2: V3,
    /// Radius of the dark inner circle, metres.
    pub inner_radius: f64,
    /// Radius of the canopy's outer rim, metres.
    pub canopy_radius: f64,
    /// Width of the darker band at the canopy's edge, metres.
    pub rim_width: f64,
    /// Number of struts across the canopy (0 = none).
    pub struts: u32,
    /// Width of a strut, metres.
    pub strut_width: f64,
    /// Radiance of the inner disc, 0..1.
    pub disc: f64,
    /// Radiance of the canopy, 0..1.
    pub canopy: f64,
    /// Radiance of the rim band, 0..1.
    pub rim: f64,
    /// Radiance of the struts, 0..1.
    pub strut: f64,
    /// Share of the canopy's radiance lost at the disc's edge to the
    /// throat's shadow (0: none), falling off outward as
    /// `exp(-(rho - inner_radius) / throat_shade_width)`. A real canopy
    /// darkens steeply toward the coupling; under blur that steep part lies
    /// inside the edge's ramp, where a linear shading model cannot see it.
    pub throat_shade: f64,
    /// E-folding width of the throat's shadow, metres (> 0).
    pub throat_shade_width: f64,
}

impl DrogueView {
    /// The canopy fabric's radiance at in-plane radius `rho` and in-plane x
    /// (metres), before struts and the rim band: a gentle linear shading
    /// from the disc to the rim, the throat's shadow and a side light.
    #[inline]
    pub fn canopy_radiance(&self, rho: f64, x: f64) -> f64 {
        let beyond_disc = (rho - self.inner_radius).max(0.0);
        let radial_f = (beyond_disc / (self.canopy_radius - self.inner_radius)).min(1.0);
        let throat = if self.throat_shade > 0.0 && self.throat_shade_width > 0.0 {
            1.0 - self.throat_shade * (-beyond_disc / self.throat_shade_width).exp()
        } else {
            1.0
        };
        self.canopy * (0.82 + 0.18 * radial_f) * throat * (1.0 + 0.06 * x / rho.max(1e-9))
    }
}

/// Everything one frame needs, in the camera frame.
#[derive(Clone, Debug)]
pub struct FrameScene {
    /// The drogue.
    pub drogue: DrogueView,
    /// The hose behind the drogue, if in front of the camera.
    pub hose: Option<Tube>,
    /// The receiver's probe, if in front of the camera.
    pub probe: Option<Tube>,
    /// Camera -> NED rotation (for the sky).
    pub r_ned_cam: M3,
    /// Image motion of the drogue during the exposure, pixels.
    pub blur_px: [f64; 2],
    /// Seed of this frame's sensor noise.
    pub noise_seed: u64,
    /// Leave the drogue out (drogue-free frames); default false.
    pub without_drogue: bool,
    /// Flat shapes behind the drogue and the tubes, painted in order; empty
    /// by default.
    pub decals: Vec<Decal>,
    /// A sun-glare streak; `None` by default.
    pub glare_streak: Option<GlareStreak>,
    /// The glow about the sun's image; `None` by default.
    pub glare_glow: Option<GlareGlow>,
}

/// Outline of a [`Decal`] in its plane, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DecalShape {
    /// A disc (a dark disc without a canopy, a blob, a balloon).
    Disc {
        /// Radius, metres.
        radius: f64,
    },
    /// An annulus between two radii (a dark ring without a canopy).
    Ring {
        /// Inner radius, metres.
        inner: f64,
        /// Outer radius, metres.
        outer: f64,
    },
    /// A rectangle with half-sizes along `e1` and `e2`.
    Rect {
        /// Half-size along `e1`, metres.
        half_1: f64,
        /// Half-size along `e2`, metres.
        half_2: f64,
    },
    /// An irregular blob: radius `radius * (1 + wobble * w(phi))` with
    /// w a fixed mix of the 2nd and 3rd harmonics (|w| <= 1) turned by
    /// `phase` radians; `wobble` within 0..0.5.
    Blob {
        /// Mean radius, metres.
        radius: f64,
        /// Relative size of the wobble, 0..0.5.
        wobble: f64,
        /// Turn of the wobble pattern, radians.
        phase: f64,
    },
    /// A star or flower of `arms` rounded arms: radius
    /// `radius * (1 - depth * (1 - cos(arms * (phi - phase))) / 2)`, the
    /// arms' tips at `radius`, the waists between them at
    /// `radius * (1 - depth)`. An arm's tip is a dark rounded end joined to
    /// other dark arms: a disc-like candidate whose surround is partly dark.
    Star {
        /// Radius at the arms' tips, metres.
        radius: f64,
        /// Number of arms (at least 2).
        arms: u32,
        /// Depth of the waists, 0..1.
        depth: f64,
        /// Direction of the first arm, radians.
        phase: f64,
    },
}

/// A flat, uniformly bright shape in the camera frame (plane through
/// `centre` with unit normal `normal`, in-plane orthonormal axes `e1`, `e2`).
/// Decals are background: the drogue, hose and probe are drawn over them,
/// and they are neither blurred nor shaded, but hazed like every object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decal {
    /// A point of the plane (the shape's centre), camera frame, metres.
    pub centre: V3,
    /// Unit normal of the plane, camera frame.
    pub normal: V3,
    /// First in-plane axis (unit).
    pub e1: V3,
    /// Second in-plane axis (unit).
    pub e2: V3,
    /// The outline in the plane.
    pub shape: DecalShape,
    /// Relative radiance 0..1.
    pub radiance: f64,
}

impl Decal {
    /// A crescent: a dark disc of `radius` partly covered by a lighter disc
    /// of `cover_radius` whose centre is `offset` metres along `e1`. The
    /// crescent's outer arc is the dark disc's own circle, so its image is
    /// a fine ellipse arc. Paint the two in the returned order.
    #[allow(clippy::too_many_arguments)]
    pub fn crescent(
        centre: V3,
        normal: V3,
        e1: V3,
        e2: V3,
        radius: f64,
        dark: f64,
        cover_radius: f64,
        offset: f64,
        light: f64,
    ) -> [Decal; 2] {
        let disc = |centre: V3, radius: f64, radiance: f64| Decal {
            centre,
            normal,
            e1,
            e2,
            shape: DecalShape::Disc { radius },
            radiance,
        };
        [
            disc(centre, radius, dark),
            disc(centre + e1 * offset, cover_radius, light),
        ]
    }

    /// Radius of a circle about `centre` that holds the whole shape, metres.
    pub(super) fn bounding_radius(&self) -> f64 {
        match self.shape {
            DecalShape::Disc { radius } => radius,
            DecalShape::Ring { outer, .. } => outer,
            DecalShape::Rect { half_1, half_2 } => half_1.hypot(half_2),
            DecalShape::Blob { radius, wobble, .. } => radius * (1.0 + wobble.abs()),
            DecalShape::Star { radius, .. } => radius,
        }
    }

    /// Signed distance (metres, negative inside) of the in-plane point
    /// (x, y) to the outline (for `Blob` and `Star` the radial distance,
    /// close enough for anti-aliasing).
    pub(super) fn signed_distance(&self, x: f64, y: f64) -> f64 {
        match self.shape {
            DecalShape::Disc { radius } => x.hypot(y) - radius,
            DecalShape::Ring { inner, outer } => {
                let rho = x.hypot(y);
                (rho - outer).max(inner - rho)
            }
            DecalShape::Rect { half_1, half_2 } => {
                let (qx, qy) = (x.abs() - half_1, y.abs() - half_2);
                qx.max(0.0).hypot(qy.max(0.0)) + qx.max(qy).min(0.0)
            }
            DecalShape::Blob {
                radius,
                wobble,
                phase,
            } => {
                let phi = y.atan2(x);
                let w = 0.6 * (2.0 * phi + phase).sin() + 0.4 * (3.0 * phi + 2.0 * phase).sin();
                x.hypot(y) - radius * (1.0 + wobble * w)
            }
            DecalShape::Star {
                radius,
                arms,
                depth,
                phase,
            } => {
                let phi = y.atan2(x);
                let waist = 0.5 * (1.0 - (f64::from(arms) * (phi - phase)).cos());
                x.hypot(y) - radius * (1.0 - depth * waist)
            }
        }
    }
}

/// A sun-glare streak: a straight band of light added at the sensor (after
/// vignetting, before noise), Gaussian across with full width at half
/// maximum `width_px`, running across the whole frame. With a `strength`
/// near 1 or more it saturates the pixels it crosses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlareStreak {
    /// A point of the band's centre line, pixels.
    pub through_px: [f64; 2],
    /// Direction of the centre line from +u toward +v, radians.
    pub angle_rad: f64,
    /// Full width at half maximum, pixels (> 0).
    pub width_px: f64,
    /// Radiance added on the centre line (relative, like the scene's).
    pub strength: f64,
}

/// The glow about the sun's image (veiling glare): light added at the
/// sensor (after vignetting, before noise), Gaussian about `centre_px`
/// with standard deviation `sigma_px`, over whatever lies there. With a
/// `strength` above the scene's radiance headroom its core saturates, and
/// it lightens a disc and its canopy alike: a veil, not an edge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlareGlow {
    /// The glow's centre, pixels (it may lie off the frame).
    pub centre_px: [f64; 2],
    /// Its standard deviation, pixels (> 0).
    pub sigma_px: f64,
    /// Radiance added at its centre (relative, like the scene's).
    pub strength: f64,
}

/// Scene-wide look (from the scenario).
#[derive(Clone, Debug)]
pub struct Look {
    /// Sky radiance at the zenith, 0..1.
    pub sky_zenith: f64,
    /// Sky radiance at the horizon, 0..1.
    pub sky_horizon: f64,
    /// Radiance of the undercast below the horizon, 0..1.
    pub ground: f64,
    /// Cloud cover, 0..1.
    pub cloud_cover: f64,
    /// Radiance of the clouds, 0..1.
    pub cloud_radiance: f64,
    /// Unit direction toward the sun, NED.
    pub sun_ned: V3,
    /// Strength of lens glare from the sun (0 = none).
    pub glare: f64,
    /// Haze 0..1: mixes object radiance toward `haze_radiance`.
    pub haze: f64,
    /// Radiance the haze mixes toward, 0..1.
    pub haze_radiance: f64,
    /// Exposure gain: digital number = 255 * gain * radiance.
    pub gain: f64,
    /// Read noise, digital numbers (RMS).
    pub read_noise_dn: f64,
    /// Shot noise: variance in DN^2 per DN of signal.
    pub shot_noise_dn: f64,
    /// Vignetting: relative fall-off at the image corner (0 = none).
    pub vignette: f64,
    /// Seed of the cloud pattern.
    pub cloud_seed: u32,
}
