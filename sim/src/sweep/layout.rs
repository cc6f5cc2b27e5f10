//! Where a sweep frame puts things: the drogue at a random place and tilt
//! in the field of view, the share of its rim the frame edge and the probe
//! hide, the probe placed to occlude a chosen share, and the frame's truth
//! (image ellipse, pose, mirror pose) from the geometry. Nothing here draws.

use super::{CANOPY_RADIUS_M, DrogueTruth, INNER_RADIUS_M, RIM_POINTS, Settings};
use crate::TruthEllipse;
use crate::camera::SimCamera;
use crate::conic::{circle_image_conic, conic_to_ellipse, mirror_pose};
use crate::geometry::{V3, perpendicular};
use crate::render::{DrogueView, Tube};
use crate::simulator::MIN_VISIBLE_RIM;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

/// A drogue view that is not drawn (drogue-free frames).
pub(super) fn placeholder_drogue() -> DrogueView {
    DrogueView {
        centre: V3::new(0.0, 0.0, 10.0),
        normal: V3::new(0.0, 0.0, -1.0),
        e1: V3::x(),
        e2: V3::y(),
        inner_radius: INNER_RADIUS_M,
        canopy_radius: CANOPY_RADIUS_M,
        rim_width: 0.018,
        struts: 0,
        strut_width: 0.0,
        disc: 0.1,
        canopy: 0.72,
        rim: 0.38,
        strut: 0.4,
        throat_shade: 0.0,
        throat_shade_width: 0.03,
    }
}

/// A plane at `centre` tilted from facing the camera by `tilt` radians about
/// a random axis, with a random in-plane turn: (normal toward the camera,
/// e1, e2).
pub(super) fn random_plane(centre: &V3, tilt: f64, rng: &mut ChaCha8Rng) -> (V3, V3, V3) {
    let los = -centre.normalize();
    let p = perpendicular(&los);
    let q = los.cross(&p);
    let phi = rng.random_range(0.0..TAU);
    let axis = p * phi.cos() + q * phi.sin();
    let normal = (los * tilt.cos() + axis.cross(&los) * tilt.sin()).normalize();
    let b = perpendicular(&normal);
    let roll = rng.random_range(0.0..TAU);
    let e1 = b * roll.cos() + normal.cross(&b) * roll.sin();
    let e2 = normal.cross(&e1);
    (normal, e1, e2)
}

/// A point at `range` metres along the ray of a random pixel at least
/// `margin` pixels inside the frame (the centre when the margin leaves none).
pub(super) fn random_point(cam: &SimCamera, range: f64, margin: f64, rng: &mut ChaCha8Rng) -> V3 {
    let pick = |rng: &mut ChaCha8Rng, size: u32, centre: f64| {
        let (lo, hi) = (margin, size as f64 - 1.0 - margin);
        if lo < hi {
            rng.random_range(lo..hi)
        } else {
            centre
        }
    };
    let u = pick(rng, cam.width, cam.cx);
    let v = pick(rng, cam.height, cam.cy);
    let ray = cam.ray_camera([u, v]).unwrap_or(V3::new(0.0, 0.0, 1.0));
    ray.normalize() * range
}

/// Shares of the inner rim (circle of `radius` about `centre` in the plane
/// e1, e2) hidden by the probe and visible: (probe, visible, all in image).
pub(super) fn rim_shares(
    cam: &SimCamera,
    centre: &V3,
    e1: &V3,
    e2: &V3,
    radius: f64,
    probe: Option<&Tube>,
    hose: Option<&Tube>,
) -> (f64, f64, bool) {
    let (mut by_probe, mut visible, mut in_image) = (0usize, 0usize, 0usize);
    for k in 0..RIM_POINTS {
        let a = k as f64 * TAU / RIM_POINTS as f64;
        let p = centre + (e1 * a.cos() + e2 * a.sin()) * radius;
        if p.z <= 1e-6 {
            continue;
        }
        let ray = p / p.z;
        let hid_probe = probe.is_some_and(|t| t.occludes(&ray, p.z));
        let hid_hose = hose.is_some_and(|t| t.occludes(&ray, p.z));
        let inside = cam.project_px(&p).is_some_and(|q| cam.in_image(q));
        by_probe += hid_probe as usize;
        in_image += inside as usize;
        visible += (inside && !hid_probe && !hid_hose) as usize;
    }
    let n = RIM_POINTS as f64;
    (
        by_probe as f64 / n,
        visible as f64 / n,
        in_image == RIM_POINTS,
    )
}

/// Farthest the probe's tip lies from the disc's centre on the probe-tip
/// levels, in inner radii (seen across the line of sight).
pub(super) const TIP_NEAR_CENTRE: f64 = 0.3;
/// The probe's radius at its far end over its tip's (0.06 over 0.035 m
/// for the sliding probe).
const TIP_TO_BASE: f64 = 1.7;

/// The drogue, its hose, the probe (occlusion levels) and the truth.
pub(super) fn lay_out_drogue(
    cam: &SimCamera,
    s: &Settings,
    rng: &mut ChaCha8Rng,
) -> (DrogueView, Tube, Option<Tube>, DrogueTruth) {
    let canopy_px = cam.fx * CANOPY_RADIUS_M / s.range_m;
    let inner_px = cam.fx * INNER_RADIUS_M / s.range_m;
    // The whole inner rim in the image (tried a few times, then the centre).
    let mut centre = V3::new(0.0, 0.0, s.range_m);
    let mut plane = random_plane(&centre, s.tilt_deg.to_radians(), rng);
    for attempt in 0..20 {
        let margin = if attempt < 19 {
            (1.1 * canopy_px).max(2.0 * inner_px + 10.0)
        } else {
            f64::INFINITY
        };
        let c = random_point(cam, s.range_m, margin, rng);
        let pl = random_plane(&c, s.tilt_deg.to_radians(), rng);
        let (_, _, all_in) = rim_shares(cam, &c, &pl.1, &pl.2, INNER_RADIUS_M, None, None);
        (centre, plane) = (c, pl);
        if all_in {
            break;
        }
    }
    let (normal, e1, e2) = plane;
    let drogue = DrogueView {
        centre,
        normal,
        e1,
        e2,
        inner_radius: INNER_RADIUS_M,
        canopy_radius: CANOPY_RADIUS_M,
        rim_width: 0.018,
        struts: 8,
        strut_width: 0.018,
        disc: 0.10,
        canopy: 0.72,
        rim: 0.38,
        strut: 0.40,
        throat_shade: 0.0,
        throat_shade_width: 0.03,
    };
    // The hose leaves the coupling behind the disc, toward the tanker
    // (ahead and above).
    let hose = Tube {
        a: centre - normal * 0.05,
        b: centre
            + V3::new(
                rng.random_range(-3.0..3.0),
                -rng.random_range(3.0..8.0),
                rng.random_range(10.0..25.0),
            ),
        radius_a: 0.045,
        radius_b: 0.045,
        radiance: 0.09,
        collar: None,
    };
    let probe = s.probe_bin.and_then(|bin| {
        if s.probe_tip {
            place_probe_tip(cam, &drogue, &hose, bin, rng)
        } else {
            place_probe(cam, &drogue, &hose, bin, rng)
        }
    });
    let (probe_frac, visible, _) = rim_shares(
        cam,
        &centre,
        &e1,
        &e2,
        INNER_RADIUS_M,
        probe.as_ref(),
        Some(&hose),
    );
    let ellipse = circle_image_conic(cam, &centre, &normal, INNER_RADIUS_M)
        .and_then(|c| conic_to_ellipse(&c))
        .unwrap_or(TruthEllipse {
            cx: f64::NAN,
            cy: f64::NAN,
            a: f64::NAN,
            b: f64::NAN,
            theta: f64::NAN,
        });
    let (alt_c, alt_n) =
        mirror_pose(cam, &centre, &normal, INNER_RADIUS_M).unwrap_or((centre, normal));
    let range = centre.norm();
    let truth = DrogueTruth {
        ellipse,
        position_camera: centre.into(),
        normal_camera: normal.into(),
        alt_position_camera: alt_c.into(),
        alt_normal_camera: alt_n.into(),
        range_m: range,
        tilt_deg: (normal.dot(&(-centre)) / range)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees(),
        probe_rim_frac: probe_frac,
        visible_rim_frac: visible,
        expect_detect: visible >= MIN_VISIBLE_RIM && ellipse.a.is_finite(),
    };
    (drogue, hose, probe, truth)
}

/// A probe whose rounded tip lies over the disc's middle (its centre within
/// [`TIP_NEAR_CENTRE`] of the inner radius of the disc's centre, as seen
/// from the camera) hiding a share of the inner rim within `bin`: a tube at
/// 45-70 % of the drogue's depth from a random side, as wide as the share
/// asks (its tip's radius up to the inner radius, as seen). The other
/// renderer's probes are drawn this way: the tip where the nozzle meets the
/// coupling, the tube's width what hides the rim.
pub(super) fn place_probe_tip(
    cam: &SimCamera,
    d: &DrogueView,
    hose: &Tube,
    bin: (f64, f64),
    rng: &mut ChaCha8Rng,
) -> Option<Tube> {
    place_probe_nearest(cam, d, hose, bin, rng, |rng, way| {
        // The tip's centre: a uniform point of the disc of radius
        // TIP_NEAR_CENTRE * r about the drogue's centre, across the line
        // of sight.
        let (rho, phi) = (
            TIP_NEAR_CENTRE * d.inner_radius * rng.random_range(0.0..1.0f64).sqrt(),
            rng.random_range(0.0..TAU),
        );
        let (along, across) = (rho * phi.cos(), rho * phi.sin());
        (0..=60)
            .map(|step| {
                // The tip's radius as seen, 0.1-1.0 of the inner radius.
                let share = 0.1 + 0.9 * f64::from(step) / 60.0;
                let radius_b = way.k * share * d.inner_radius;
                Tube {
                    a: way.at(d, across, along + 3.0),
                    b: way.at(d, across, along),
                    radius_a: radius_b * TIP_TO_BASE,
                    radius_b,
                    radiance: 0.16,
                    collar: None,
                }
            })
            .collect()
    })
}

/// A probe between the camera and the drogue hiding a share of the inner
/// rim within `bin` (as near as the geometry allows): a tube at 45-70 % of
/// the drogue's depth coming in from a random side, its tip just past the
/// disc's centre line, moved sideways until the share is in the bin.
pub(super) fn place_probe(
    cam: &SimCamera,
    d: &DrogueView,
    hose: &Tube,
    bin: (f64, f64),
    rng: &mut ChaCha8Rng,
) -> Option<Tube> {
    place_probe_nearest(cam, d, hose, bin, rng, |rng, way| {
        let tip_along = -rng.random_range(0.1..0.5) * d.inner_radius;
        let reach = d.inner_radius + 0.25;
        (0..=80)
            .map(|step| {
                let offset = -reach + 2.0 * reach * f64::from(step) / 80.0;
                Tube {
                    a: way.at(d, offset, tip_along + 3.0),
                    b: way.at(d, offset, tip_along),
                    radius_a: 0.06,
                    radius_b: 0.035,
                    radiance: 0.16,
                    collar: None,
                }
            })
            .collect()
    })
}

/// The way a probe comes in: at `k` of the drogue's depth, along `dir`
/// (across the line of sight), `side` across it.
struct ProbeWay {
    /// The probe's depth over the drogue's (0.45-0.7).
    k: f64,
    /// Unit vector, camera frame, across the line of sight to the drogue.
    dir: V3,
    /// Unit vector, camera frame, across both the line of sight and `dir`.
    side: V3,
}

impl ProbeWay {
    /// The point `across` to the side and `along` the way from the
    /// drogue's centre, at the drogue's depth scaled by `k` (the same
    /// image position).
    fn at(&self, d: &DrogueView, across: f64, along: f64) -> V3 {
        (d.centre + self.side * across + self.dir * along) * self.k
    }
}

/// The probe of those `tubes` gives for up to eight random ways in whose
/// share of the rim hidden is nearest a target drawn from `bin` (stopping
/// once one is within 0.01 of it).
fn place_probe_nearest(
    cam: &SimCamera,
    d: &DrogueView,
    hose: &Tube,
    bin: (f64, f64),
    rng: &mut ChaCha8Rng,
    tubes: impl Fn(&mut ChaCha8Rng, &ProbeWay) -> Vec<Tube>,
) -> Option<Tube> {
    let target = rng.random_range(bin.0.max(0.02)..bin.1);
    let c_hat = d.centre.normalize();
    let (x, y) = (perpendicular(&c_hat), c_hat.cross(&perpendicular(&c_hat)));
    let mut best: Option<(f64, Tube)> = None;
    for _ in 0..8 {
        let k = rng.random_range(0.45..0.7);
        let psi = rng.random_range(0.0..TAU);
        let dir = x * psi.cos() + y * psi.sin();
        let way = ProbeWay {
            k,
            dir,
            side: c_hat.cross(&dir),
        };
        for tube in tubes(rng, &way) {
            let (frac, _, _) = rim_shares(
                cam,
                &d.centre,
                &d.e1,
                &d.e2,
                d.inner_radius,
                Some(&tube),
                Some(hose),
            );
            let miss = (frac - target).abs();
            if best.as_ref().is_none_or(|(m, _)| miss < *m) {
                best = Some((miss, tube));
            }
        }
        if best.as_ref().is_some_and(|(m, _)| *m < 0.01) {
            break;
        }
    }
    best.map(|(_, t)| t)
}
