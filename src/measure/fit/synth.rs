//! Synthetic rim point sets with exact truth, for the fitters' tests and
//! benchmarks: points on a known ellipse plus Gaussian noise, with part of
//! the rim replaced by the kind of outliers a real frame gives: a contiguous
//! run along a smooth curve (the probe's or the hose's outline, a smaller
//! arc) and a few scattered points.
//!
//! The truth is the ellipse the points were drawn from, never a fit.

use crate::measure::ellipse::Ellipse;
use rand::Rng;
use std::f64::consts::{FRAC_PI_2, TAU};

/// What replaces the hidden part of the rim.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Occluder {
    /// Nothing: the hidden arc just has no points.
    Gap,
    /// A straight run across the hidden arc's chord (a probe edge crossing
    /// the disc).
    Chord,
    /// Two straight runs from the hidden arc's ends to a point inside the
    /// disc (a tapered probe seen end-on).
    Wedge,
    /// Two parallel runs leaving the rim outward (a dark tube: probe or hose
    /// touching the rim).
    Tube,
    /// An arc of a smaller, offset circle (a rounded probe tip).
    InnerArc,
}

impl Occluder {
    pub(crate) const STRUCTURED: [Occluder; 4] = [
        Occluder::Chord,
        Occluder::Wedge,
        Occluder::Tube,
        Occluder::InnerArc,
    ];
}

/// The recipe of one rim point set.
#[derive(Clone, Debug)]
pub struct RimSpec {
    /// The ellipse the points are drawn from, pixels.
    pub truth: Ellipse,
    /// Ellipse parameter (radians) where the visible arc starts.
    pub visible_start: f64,
    /// Visible part of the rim, 0..=1 of the full turn.
    pub visible_fraction: f64,
    /// Points along the full rim (the visible arc gets its share).
    pub rim_points: usize,
    /// Standard deviation of the Gaussian noise on each coordinate, pixels.
    pub noise_px: f64,
    /// What hides part of the visible arc.
    pub occluder: Occluder,
    /// Uniform outliers in the ellipse's bounding box (grown by half).
    pub scattered: usize,
}

/// A generated point set and which points are outliers.
#[derive(Clone, Debug)]
pub struct RimSet {
    /// The ellipse the points were drawn from, pixels.
    pub truth: Ellipse,
    /// The points, rim and outliers mixed, pixels.
    pub points: Vec<[f64; 2]>,
    /// One flag per point: an outlier, not a rim point.
    pub outlier: Vec<bool>,
}

impl RimSet {
    /// Share of the points that are outliers, 0..1.
    pub fn outlier_fraction(&self) -> f64 {
        self.outlier.iter().filter(|o| **o).count() as f64 / self.points.len().max(1) as f64
    }
}

/// One standard normal draw (Box-Muller).
fn gauss(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

fn lerp(p: [f64; 2], q: [f64; 2], s: f64) -> [f64; 2] {
    [p[0] + (q[0] - p[0]) * s, p[1] + (q[1] - p[1]) * s]
}

/// Draws the points of `spec`.
pub fn generate(spec: &RimSpec, rng: &mut impl Rng) -> RimSet {
    let e = spec.truth;
    let vis = spec.visible_fraction.clamp(0.0, 1.0);
    let n_vis = ((spec.rim_points as f64) * vis).round() as usize;
    let n_hidden = spec.rim_points.saturating_sub(n_vis);
    // Noise-free points and their outlier flags; noise is added at the end.
    let mut clean: Vec<([f64; 2], bool)> = Vec::with_capacity(spec.rim_points);
    let mut push = |p: [f64; 2], out: bool| clean.push((p, out));
    let span = TAU * vis;
    let t0 = spec.visible_start;
    for k in 0..n_vis {
        let t = t0 + span * (k as f64 + 0.5) / n_vis as f64;
        push(e.point_at(t), false);
    }
    // The hidden arc runs from t1 (end of the visible arc) to t0 + TAU.
    let t1 = t0 + span;
    let (p1, p0) = (e.point_at(t1), e.point_at(t0 + TAU));
    let mid_t = 0.5 * (t1 + t0 + TAU);
    let rim_mid = e.point_at(mid_t);
    let centre = [e.cx, e.cy];
    let m = n_hidden;
    match spec.occluder {
        Occluder::Gap => {}
        Occluder::Chord => {
            for k in 0..m {
                push(lerp(p1, p0, (k as f64 + 0.5) / m as f64), true);
            }
        }
        Occluder::Wedge => {
            // Apex between the chord's middle and the centre.
            let apex = lerp(lerp(p1, p0, 0.5), centre, 0.6);
            let half = m / 2;
            for k in 0..half {
                push(lerp(p1, apex, (k as f64 + 0.5) / half as f64), true);
            }
            for k in 0..(m - half) {
                let s = (k as f64 + 0.5) / (m - half) as f64;
                push(lerp(apex, p0, s), true);
            }
        }
        Occluder::Tube => {
            // Two runs from p1 and p0, parallel, leaving along the outward
            // direction of the hidden arc's middle, as long as the chord.
            let out = [rim_mid[0] - centre[0], rim_mid[1] - centre[1]];
            let norm = out[0].hypot(out[1]).max(f64::MIN_POSITIVE);
            let len = (p1[0] - p0[0]).hypot(p1[1] - p0[1]).max(0.2 * e.b);
            let dir = [out[0] / norm * len, out[1] / norm * len];
            let half = m / 2;
            for k in 0..half {
                let s = (k as f64 + 0.5) / half as f64;
                push([p1[0] + dir[0] * s, p1[1] + dir[1] * s], true);
            }
            for k in 0..(m - half) {
                let s = (k as f64 + 0.5) / (m - half) as f64;
                push([p0[0] + dir[0] * s, p0[1] + dir[1] * s], true);
            }
        }
        Occluder::InnerArc => {
            // A circle through p1 and p0 bulging inward: centre on the far
            // side, radius 0.6 of the mean semi-axis, or the chord's half if
            // larger.
            let half_chord = 0.5 * (p1[0] - p0[0]).hypot(p1[1] - p0[1]);
            let r = (0.6 * 0.5 * (e.a + e.b)).max(half_chord * 1.05);
            let mid = lerp(p1, p0, 0.5);
            let inward = [centre[0] - rim_mid[0], centre[1] - rim_mid[1]];
            let norm = inward[0].hypot(inward[1]).max(f64::MIN_POSITIVE);
            let u = [inward[0] / norm, inward[1] / norm];
            // Centre c with |c - p1| = r on the outward side of the chord, so
            // the arc through p1, p0 bulges inward.
            let h = (r * r - half_chord * half_chord).max(0.0).sqrt();
            let c = [mid[0] - u[0] * h, mid[1] - u[1] * h];
            let a1 = (p1[1] - c[1]).atan2(p1[0] - c[0]);
            let a0 = (p0[1] - c[1]).atan2(p0[0] - c[0]);
            // Take the arc passing nearest the ellipse centre.
            let mut d = a0 - a1;
            while d > std::f64::consts::PI {
                d -= TAU;
            }
            while d < -std::f64::consts::PI {
                d += TAU;
            }
            let probe = [
                c[0] + r * (a1 + 0.5 * d).cos(),
                c[1] + r * (a1 + 0.5 * d).sin(),
            ];
            let other = [
                c[0] - r * (a1 + 0.5 * d).cos(),
                c[1] - r * (a1 + 0.5 * d).sin(),
            ];
            let dist = |p: [f64; 2]| (p[0] - centre[0]).hypot(p[1] - centre[1]);
            if dist(other) < dist(probe) {
                d = if d > 0.0 { d - TAU } else { d + TAU };
            }
            for k in 0..m {
                let a = a1 + d * (k as f64 + 0.5) / m as f64;
                push([c[0] + r * a.cos(), c[1] + r * a.sin()], true);
            }
        }
    }
    let mut points = Vec::with_capacity(clean.len() + spec.scattered);
    let mut outlier = Vec::with_capacity(points.capacity());
    for (p, out) in clean {
        let (nx, ny) = (gauss(rng), gauss(rng));
        points.push([p[0] + spec.noise_px * nx, p[1] + spec.noise_px * ny]);
        outlier.push(out);
    }
    let (hx, hy) = (1.5 * e.a, 1.5 * e.a);
    for _ in 0..spec.scattered {
        let p = [
            e.cx + rng.random_range(-hx..hx),
            e.cy + rng.random_range(-hy..hy),
        ];
        points.push(p);
        outlier.push(true);
    }
    RimSet {
        truth: e,
        points,
        outlier,
    }
}

/// Ranges for [`random_spec`].
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Semi-major axis, pixels (drawn log-uniformly).
    pub major_px: (f64, f64),
    /// Minor / major ratio (cos of the tilt).
    pub axis_ratio: (f64, f64),
    /// Visible part of the rim, 0..=1 of the full turn.
    pub visible_fraction: (f64, f64),
    /// Standard deviation of the points' noise, pixels.
    pub noise_px: (f64, f64),
    /// Occluders to choose from (uniformly).
    pub occluders: Vec<Occluder>,
    /// Scattered outliers, up to this many.
    pub scattered_max: usize,
    /// Point density along the rim: about one point per this many pixels of
    /// perimeter, at least 40 and at most 2000 points.
    pub spacing_px: f64,
}

impl Scenario {
    /// Clean rims: 60-100 % visible, 0.1 px noise, nothing else.
    pub fn clean() -> Self {
        Self {
            major_px: (10.0, 400.0),
            axis_ratio: (0.5, 1.0),
            visible_fraction: (0.6, 1.0),
            noise_px: (0.1, 0.1),
            occluders: vec![Occluder::Gap],
            scattered_max: 0,
            spacing_px: 1.0,
        }
    }

    /// Occluded rims: 60-70 % visible, the rest replaced by a structured run,
    /// a few scattered outliers.
    pub fn occluded() -> Self {
        Self {
            visible_fraction: (0.6, 0.7),
            noise_px: (0.05, 0.3),
            occluders: Occluder::STRUCTURED.to_vec(),
            scattered_max: 5,
            ..Self::clean()
        }
    }
}

/// A random spec within `sc`, the ellipse inside a 1280x960 image.
pub fn random_spec(sc: &Scenario, rng: &mut impl Rng) -> RimSpec {
    let uniform = |rng: &mut dyn rand::RngCore, r: (f64, f64)| {
        if r.1 > r.0 {
            rng.random_range(r.0..r.1)
        } else {
            r.0
        }
    };
    let a = uniform(rng, (sc.major_px.0.ln(), sc.major_px.1.ln())).exp();
    let b = a * uniform(rng, sc.axis_ratio);
    let theta = uniform(rng, (-FRAC_PI_2, FRAC_PI_2));
    let cx = uniform(rng, (100.0, 1180.0));
    let cy = uniform(rng, (100.0, 860.0));
    let perimeter = TAU * ((a * a + b * b) / 2.0).sqrt();
    let rim_points = ((perimeter / sc.spacing_px) as usize).clamp(40, 2000);
    let occluder = sc.occluders[rng
        .random_range(0..sc.occluders.len().max(1))
        .min(sc.occluders.len().saturating_sub(1))];
    let scattered = if sc.scattered_max > 0 {
        rng.random_range(0..=sc.scattered_max)
    } else {
        0
    };
    RimSpec {
        truth: Ellipse::new(cx, cy, a, b, theta),
        visible_start: uniform(rng, (0.0, TAU)),
        visible_fraction: uniform(rng, sc.visible_fraction),
        rim_points,
        noise_px: uniform(rng, sc.noise_px),
        occluder,
        scattered,
    }
}
