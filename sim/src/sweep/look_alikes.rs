//! Distractors for the drogue-free frames and the distractor levels: dark
//! blobs and rectangles, crescents, canopy-less discs and rings, stars and
//! flowers, placed far behind the drogue as flat decals.

use super::Factor;
use super::layout::{random_plane, random_point};
use crate::camera::SimCamera;
use crate::geometry::V3;
use crate::render::{Decal, DecalShape};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

/// A dark blob or rectangle (or, with `star`, a star or flower) far behind
/// the drogue, 15-120 px across (a star's arms reach 1.5 times as far),
/// near `near_px` (within 350 px) half the time when given, else anywhere.
pub(super) fn dark_shape(
    cam: &SimCamera,
    rng: &mut ChaCha8Rng,
    near_px: Option<[f64; 2]>,
    star: bool,
) -> Decal {
    let depth = rng.random_range(15.0..80.0);
    let size_px = rng.random_range(15.0..120.0);
    let size_m = size_px * depth / cam.fx / 2.0;
    let centre = match near_px {
        Some(p) if rng.random_bool(0.5) => {
            let (a, r) = (rng.random_range(0.0..TAU), rng.random_range(0.0..350.0));
            let q = [
                (p[0] + r * a.cos()).clamp(0.0, cam.width as f64 - 1.0),
                (p[1] + r * a.sin()).clamp(0.0, cam.height as f64 - 1.0),
            ];
            cam.ray_camera(q).unwrap_or(V3::z()).normalize() * depth
        }
        _ => random_point(cam, depth, 0.0, rng),
    };
    let (normal, e1, e2) = random_plane(&centre, rng.random_range(0.0..0.7), rng);
    let shape = if star {
        star_shape(1.5 * size_m, rng)
    } else if rng.random_bool(0.5) {
        DecalShape::Blob {
            radius: size_m,
            wobble: rng.random_range(0.1..0.35),
            phase: rng.random_range(0.0..TAU),
        }
    } else {
        let aspect: f64 = rng.random_range(1.0..4.0);
        DecalShape::Rect {
            half_1: size_m,
            half_2: size_m / aspect,
        }
    };
    Decal {
        centre,
        normal,
        e1,
        e2,
        shape,
        radiance: rng.random_range(0.05..0.3),
    }
}

/// The look-alikes of a drogue-free level.
pub(super) fn look_alikes(factor: Factor, cam: &SimCamera, rng: &mut ChaCha8Rng) -> Vec<Decal> {
    let range = rng.random_range(2.0..10.0);
    let tilt = rng.random_range(0.0f64..50.0).to_radians();
    let radius = rng.random_range(0.1..0.35);
    let margin = 2.5 * cam.fx * radius / range + 10.0;
    let centre = random_point(cam, range, margin, rng);
    let (normal, e1, e2) = random_plane(&centre, tilt, rng);
    let dark = rng.random_range(0.05..0.2);
    let shape = |shape: DecalShape| Decal {
        centre,
        normal,
        e1,
        e2,
        shape,
        radiance: dark,
    };
    match factor {
        Factor::Crescent => Decal::crescent(
            centre,
            normal,
            e1,
            e2,
            radius,
            dark,
            radius * rng.random_range(1.0..1.4),
            radius * rng.random_range(0.5..1.3),
            rng.random_range(0.55..0.8),
        )
        .to_vec(),
        Factor::CanopylessDisc => vec![shape(DecalShape::Disc { radius })],
        Factor::DarkRing => vec![shape(DecalShape::Ring {
            inner: radius,
            outer: radius * rng.random_range(1.3..2.2),
        })],
        // Arms whose rounded tips are about the disc's size.
        Factor::DarkStars => {
            let radius = radius * rng.random_range(1.5..3.0);
            vec![shape(star_shape(radius, rng))]
        }
        _ => (0..rng.random_range(2..=4))
            .map(|_| dark_shape(cam, rng, None, false))
            .collect(),
    }
}

/// A star or flower of `radius` (metres): 3-6 arms, its waists at 15-50 %
/// of its radius, turned at random.
fn star_shape(radius: f64, rng: &mut ChaCha8Rng) -> DecalShape {
    DecalShape::Star {
        radius,
        arms: rng.random_range(3..=6),
        depth: rng.random_range(0.5..0.85),
        phase: rng.random_range(0.0..TAU),
    }
}
