//! Ellipse fitting: the paper's least squares (A+C=1) and Algorithm 1, the
//! fixed-threshold RANSAC the paper compares against, and our adaptive default.
//!
//! All methods share the same front end (`Points`): non-finite points are
//! dropped (and flagged as outliers), and the rest are moved to their centroid
//! and scaled to unit RMS radius, so that every algebraic fit is well
//! conditioned whatever the pixel coordinates. Distances and thresholds are
//! given in pixels at the interface and converted inside.

mod adaptive;
mod algorithm1;
mod cluster;
mod geometric;
mod guard;
mod least_squares;
mod ransac;
pub mod synth;
mod taubin;

use super::ellipse::Ellipse;
use serde::{Deserialize, Serialize};

/// Which fitter runs (`[fit] method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FitMethod {
    /// Our default: Algorithm 1 with a scale-aware parameter distance,
    /// consensus among the biggest clusters, and an unbiased refit
    /// (Taubin, then orthogonal-distance refinement).
    Adaptive,
    /// The paper's Algorithm 1, as published.
    Algorithm1,
    /// Fixed-threshold RANSAC with an A+C=1 refit of the consensus set.
    Ransac,
    /// The paper's least squares (A+C=1) over all points, no robustness.
    LeastSquares,
}

impl FitMethod {
    /// Every method, the default first.
    pub const ALL: [FitMethod; 4] = [
        FitMethod::Adaptive,
        FitMethod::Algorithm1,
        FitMethod::Ransac,
        FitMethod::LeastSquares,
    ];

    /// The method's name in the config (`[fit] method`).
    pub fn name(self) -> &'static str {
        match self {
            FitMethod::Adaptive => "adaptive",
            FitMethod::Algorithm1 => "algorithm1",
            FitMethod::Ransac => "ransac",
            FitMethod::LeastSquares => "least_squares",
        }
    }
}

/// Fit tunables (`[fit]` in the config; the defaults and their comments live
/// in `config/default.toml`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// Which fitter runs.
    pub method: FitMethod,
    /// Algorithm 1: number of random subsets N.
    pub algorithm1_subsets: usize,
    /// Algorithm 1: points per subset n (>= 5).
    pub algorithm1_subset_size: usize,
    /// Algorithm 1: clustering stop threshold T, in eq. 8's units (pixels
    /// and radians mixed, as in the paper).
    pub algorithm1_cluster_threshold: f64,
    /// Algorithm 1: a point whose deviation from M* is below this is an edge
    /// point of P*, pixels.
    pub algorithm1_inlier_threshold_px: f64,
    /// RANSAC: maximum number of random 5-point samples.
    pub ransac_iterations: usize,
    /// RANSAC: fixed inlier threshold, pixels.
    pub ransac_threshold_px: f64,
    /// RANSAC: stop early once this fraction of the points agrees (N_T).
    pub ransac_consensus_fraction: f64,
    /// Adaptive: most random subsets drawn (the RANSAC bound decides how
    /// many, from `adaptive_min_subsets` up to this).
    pub adaptive_subsets: usize,
    /// Adaptive: subsets drawn first; more only when the best model's
    /// inlier share asks for them.
    pub adaptive_min_subsets: usize,
    /// Adaptive: wanted probability of at least one outlier-free subset,
    /// given the best model's inlier share (the RANSAC bound), (0, 1).
    pub adaptive_confidence: f64,
    /// Adaptive: points per subset (>= 5).
    pub adaptive_subset_size: usize,
    /// Adaptive: classes merge while their distance is below
    /// `adaptive_cluster_relative * rms_radius + adaptive_cluster_px`, where
    /// `rms_radius` is the points' RMS distance from their centroid.
    pub adaptive_cluster_relative: f64,
    /// Adaptive: absolute part of the cluster tolerance, pixels.
    pub adaptive_cluster_px: f64,
    /// Adaptive: how many class centres (most support in the first band)
    /// are optimised locally and compete by consensus.
    pub adaptive_clusters_scored: usize,
    /// Adaptive: initial inlier band around a class centre's ellipse,
    /// relative to the points' RMS radius (plus `adaptive_inlier_min_px`).
    pub adaptive_initial_band_relative: f64,
    /// Adaptive: the inlier band shrinks to this many robust sigmas of the
    /// residuals.
    pub adaptive_inlier_sigmas: f64,
    /// Adaptive: the inlier band never gets narrower than this, pixels
    /// (not the cap of stage 5's comparison, which is the rim's noise).
    pub adaptive_inlier_min_px: f64,
    /// Adaptive: at most this many rounds of (select inliers, Taubin refit)
    /// per candidate.
    pub adaptive_refine_rounds: usize,
    /// Adaptive: Levenberg-Marquardt iterations of the orthogonal-distance
    /// refinement.
    pub geometric_iterations: usize,
}

impl FitConfig {
    /// Checks the values serde cannot (ranges); the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            (
                "algorithm1_cluster_threshold",
                self.algorithm1_cluster_threshold,
            ),
            (
                "algorithm1_inlier_threshold_px",
                self.algorithm1_inlier_threshold_px,
            ),
            ("ransac_threshold_px", self.ransac_threshold_px),
            ("adaptive_inlier_sigmas", self.adaptive_inlier_sigmas),
            ("adaptive_inlier_min_px", self.adaptive_inlier_min_px),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("fit.{key} must be > 0 (got {v})"));
            }
        }
        let non_negative = [
            ("adaptive_cluster_relative", self.adaptive_cluster_relative),
            ("adaptive_cluster_px", self.adaptive_cluster_px),
            (
                "adaptive_initial_band_relative",
                self.adaptive_initial_band_relative,
            ),
        ];
        for (key, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("fit.{key} must be >= 0 (got {v})"));
            }
        }
        if self.adaptive_cluster_relative + self.adaptive_cluster_px <= 0.0 {
            return Err(
                "fit.adaptive_cluster_relative and fit.adaptive_cluster_px cannot both be 0".into(),
            );
        }
        if !(self.adaptive_confidence > 0.0 && self.adaptive_confidence < 1.0) {
            return Err(format!(
                "fit.adaptive_confidence must be in (0, 1) (got {})",
                self.adaptive_confidence
            ));
        }
        if !(self.ransac_consensus_fraction > 0.0 && self.ransac_consensus_fraction <= 1.0) {
            return Err(format!(
                "fit.ransac_consensus_fraction must be in (0, 1] (got {})",
                self.ransac_consensus_fraction
            ));
        }
        for (key, v) in [
            ("algorithm1_subset_size", self.algorithm1_subset_size),
            ("adaptive_subset_size", self.adaptive_subset_size),
        ] {
            if v < 5 {
                return Err(format!("fit.{key} must be >= 5 (got {v})"));
            }
        }
        for (key, v) in [
            ("algorithm1_subsets", self.algorithm1_subsets),
            ("ransac_iterations", self.ransac_iterations),
            ("adaptive_subsets", self.adaptive_subsets),
            ("adaptive_min_subsets", self.adaptive_min_subsets),
            ("adaptive_clusters_scored", self.adaptive_clusters_scored),
            ("adaptive_refine_rounds", self.adaptive_refine_rounds),
        ] {
            if v == 0 {
                return Err(format!("fit.{key} must be >= 1"));
            }
        }
        // The clustering is O(N^2) in time: keep N sane.
        for (key, v) in [
            ("algorithm1_subsets", self.algorithm1_subsets),
            ("adaptive_subsets", self.adaptive_subsets),
            ("adaptive_min_subsets", self.adaptive_min_subsets),
        ] {
            if v > 1000 {
                return Err(format!("fit.{key} must be <= 1000 (got {v})"));
            }
        }
        Ok(())
    }
}

/// A fitted ellipse and which points it kept.
#[derive(Clone, Debug, PartialEq)]
pub struct FitResult {
    /// The ellipse, in the points' pixels.
    pub ellipse: Ellipse,
    /// One flag per input point: kept by the robust fit.
    pub inliers: Vec<bool>,
    /// RMS geometric residual of the inliers, pixels (first-order
    /// orthogonal distance).
    pub rms_residual_px: f64,
}

/// Why no ellipse came out of a fit.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    /// Fewer than 5 usable (finite, distinct) points.
    #[error("too few points: {0}")]
    TooFewPoints(usize),
    /// No ellipse fits the points (every candidate is degenerate, not an
    /// ellipse, or without support).
    #[error("no ellipse fits the points")]
    NoEllipse,
    /// A `[fit]` setting is unusable.
    #[error("invalid fit config: {0}")]
    Config(String),
}

/// Runs the configured fit method; deterministic for a given seed.
#[derive(Clone)]
pub struct Fitter {
    cfg: FitConfig,
    config_error: Option<String>,
}

impl Fitter {
    /// A fitter for `cfg`. An out-of-range value is reported by every
    /// [`Fitter::fit`] call (use [`FitConfig::validate`] to catch it early).
    pub fn new(cfg: &FitConfig) -> Self {
        Self {
            cfg: cfg.clone(),
            config_error: cfg.validate().err(),
        }
    }

    /// Fits an ellipse to points in undistorted pixels.
    pub fn fit(&mut self, points_px: &[[f64; 2]], seed: u64) -> Result<FitResult, FitError> {
        if let Some(e) = &self.config_error {
            return Err(FitError::Config(e.clone()));
        }
        fit_with(self.cfg.method, &self.cfg, points_px, seed)
    }

    /// `fitted` (a fit of `points_px`) refitted without the inliers beside a
    /// hidden stretch of the rim (see `guard`): an orthogonal-distance
    /// refinement of the remaining inliers from `fitted`'s ellipse. Those
    /// points are no longer inliers in the result. Unchanged when no point
    /// is beside a hidden stretch, when fewer than half the inliers would
    /// remain, when the refit fails, and for the methods other than
    /// `adaptive` (the paper's, kept as published for comparison).
    pub fn without_occluder_edges(&self, points_px: &[[f64; 2]], fitted: FitResult) -> FitResult {
        if self.cfg.method != FitMethod::Adaptive {
            return fitted;
        }
        let e = &fitted.ellipse;
        let beside = guard::beside_hidden_rim(points_px, [e.cx, e.cy], &fitted.inliers);
        let keep: Vec<bool> = fitted
            .inliers
            .iter()
            .zip(&beside)
            .map(|(&inlier, &beside)| inlier && !beside)
            .collect();
        let inliers = fitted.inliers.iter().filter(|&&k| k).count();
        let mut kept: Vec<[f64; 2]> = Vec::with_capacity(inliers);
        kept.extend(
            points_px
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| *p),
        );
        if kept.len() == inliers || 2 * kept.len() < inliers {
            return fitted;
        }
        let Ok(pts) = Points::new(&kept) else {
            return fitted;
        };
        let start = pts.px_to_normalised(e);
        let refined = geometric::refine(&pts.xy, &start, self.cfg.geometric_iterations);
        let all = vec![true; pts.xy.len()];
        match pts.result(&refined, &all) {
            Ok(r) => FitResult {
                ellipse: r.ellipse,
                inliers: keep,
                rms_residual_px: r.rms_residual_px,
            },
            Err(_) => fitted,
        }
    }
}

/// Fits with an explicit method (for comparisons on the same points).
/// Deterministic for a given seed.
pub fn fit_with(
    method: FitMethod,
    cfg: &FitConfig,
    points_px: &[[f64; 2]],
    seed: u64,
) -> Result<FitResult, FitError> {
    cfg.validate().map_err(FitError::Config)?;
    let pts = Points::new(points_px)?;
    let (ellipse_n, inliers_n) = match method {
        FitMethod::Adaptive => adaptive::fit(&pts, cfg, seed)?,
        FitMethod::Algorithm1 => algorithm1::fit(&pts, cfg, seed)?,
        FitMethod::Ransac => ransac::fit(&pts, cfg, seed)?,
        FitMethod::LeastSquares => {
            let e = least_squares::fit_ellipse(&pts.xy).ok_or(FitError::NoEllipse)?;
            (e, vec![true; pts.xy.len()])
        }
    };
    pts.result(&ellipse_n, &inliers_n)
}

/// The usable input points in normalised coordinates, `(p - mean) / scale`.
/// Every fit here is invariant under this similarity, so it only improves the
/// conditioning.
pub(crate) struct Points {
    /// Normalised coordinates of the finite points.
    pub xy: Vec<[f64; 2]>,
    /// Index into the caller's slice of each point in `xy`.
    pub index: Vec<usize>,
    /// Number of points the caller passed.
    pub total: usize,
    pub mean: [f64; 2],
    /// Pixels per normalised unit.
    pub scale: f64,
}

impl Points {
    fn new(points_px: &[[f64; 2]]) -> Result<Self, FitError> {
        // Sized for every point (a filtered collect grows by reallocations).
        let mut index: Vec<usize> = Vec::with_capacity(points_px.len());
        index.extend((0..points_px.len()).filter(|&i| points_px[i].iter().all(|c| c.is_finite())));
        if index.len() < 5 {
            return Err(FitError::TooFewPoints(index.len()));
        }
        let n = index.len() as f64;
        // Two-pass mean and RMS radius; the per-point division keeps sums of
        // huge coordinates finite.
        let mut mean = [0.0; 2];
        for &i in &index {
            mean[0] += points_px[i][0] / n;
            mean[1] += points_px[i][1] / n;
        }
        let mut ms = 0.0;
        for &i in &index {
            let (dx, dy) = (points_px[i][0] - mean[0], points_px[i][1] - mean[1]);
            ms += (dx * dx + dy * dy) / n;
        }
        let scale = ms.sqrt();
        if !(scale.is_finite() && scale > 0.0 && mean.iter().all(|m| m.is_finite())) {
            return Err(FitError::NoEllipse);
        }
        let xy = index
            .iter()
            .map(|&i| {
                [
                    (points_px[i][0] - mean[0]) / scale,
                    (points_px[i][1] - mean[1]) / scale,
                ]
            })
            .collect();
        Ok(Self {
            xy,
            index,
            total: points_px.len(),
            mean,
            scale,
        })
    }

    /// An ellipse in normalised coordinates, in pixels.
    pub fn normalised_to_px(&self, e: &Ellipse) -> Ellipse {
        Ellipse {
            cx: e.cx * self.scale + self.mean[0],
            cy: e.cy * self.scale + self.mean[1],
            a: e.a * self.scale,
            b: e.b * self.scale,
            theta: e.theta,
        }
    }

    /// An ellipse in pixels, in normalised coordinates.
    pub fn px_to_normalised(&self, e: &Ellipse) -> Ellipse {
        Ellipse {
            cx: (e.cx - self.mean[0]) / self.scale,
            cy: (e.cy - self.mean[1]) / self.scale,
            a: e.a / self.scale,
            b: e.b / self.scale,
            theta: e.theta,
        }
    }

    /// The caller-facing result of a fit in normalised coordinates.
    fn result(&self, e: &Ellipse, inliers_n: &[bool]) -> Result<FitResult, FitError> {
        let ellipse = self.normalised_to_px(e);
        let finite = [ellipse.cx, ellipse.cy, ellipse.a, ellipse.b, ellipse.theta]
            .iter()
            .all(|v| v.is_finite());
        if !finite || ellipse.b <= 0.0 {
            return Err(FitError::NoEllipse);
        }
        let mut inliers = vec![false; self.total];
        let mut sum_sq = 0.0;
        let mut count = 0usize;
        // First-order (Sampson) distance: exact to first order for points
        // near the curve, which inliers are, and much cheaper than the foot
        // point.
        let conic = e.to_conic();
        for (k, &keep) in inliers_n.iter().enumerate() {
            if keep {
                inliers[self.index[k]] = true;
                let d = conic.sampson_distance(self.xy[k][0], self.xy[k][1]);
                sum_sq += d * d;
                count += 1;
            }
        }
        let rms_residual_px = if count > 0 {
            (sum_sq / count as f64).sqrt() * self.scale
        } else {
            0.0
        };
        Ok(FitResult {
            ellipse,
            inliers,
            rms_residual_px,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn cfg() -> FitConfig {
        Config::embedded().fit
    }

    fn ring(e: &Ellipse, n: usize, arc: f64) -> Vec<[f64; 2]> {
        (0..n)
            .map(|k| e.point_at(arc * k as f64 / n as f64))
            .collect()
    }

    #[test]
    fn every_method_recovers_an_exact_ellipse() {
        let truth = Ellipse::new(640.5, 480.25, 120.0, 70.0, 0.4);
        let pts = ring(&truth, 200, std::f64::consts::TAU);
        for m in FitMethod::ALL {
            let r = fit_with(m, &cfg(), &pts, 1).unwrap();
            assert!(
                r.ellipse.max_param_error_px(&truth) < 1e-6,
                "{m:?} {:?}",
                r.ellipse
            );
            assert!(r.ellipse.theta_error_rad(&truth) < 1e-8, "{m:?}");
            assert!(r.rms_residual_px < 1e-6, "{m:?} {}", r.rms_residual_px);
            assert_eq!(r.inliers.len(), pts.len());
        }
    }

    #[test]
    fn the_points_beside_a_probe_are_left_out_of_the_refit() {
        // A disc's rim every 2 degrees; the probe's outline (10 points, far
        // off the rim) hides 40-58 degrees, and pulls the rim point on
        // each side of it 0.3 px outward.
        let truth = Ellipse::new(400.0, 300.0, 60.0, 45.0, 0.3);
        let mut pts = ring(&truth, 180, std::f64::consts::TAU);
        let outward = |p: [f64; 2], by: f64| {
            let (c, s) = (p[0] - truth.cx, p[1] - truth.cy);
            let r = c.hypot(s);
            [p[0] + by * c / r, p[1] + by * s / r]
        };
        for p in &mut pts[20..30] {
            *p = outward(*p, 10.0);
        }
        for k in [19, 30] {
            pts[k] = outward(pts[k], 0.3);
        }
        let mut fitter = Fitter::new(&cfg());
        let fitted = fitter.fit(&pts, 3).unwrap();
        assert!(
            fitted.inliers[19] && fitted.inliers[30],
            "the pulled points pass as inliers"
        );
        let pulled = (fitted.ellipse.a - truth.a).abs() + (fitted.ellipse.b - truth.b).abs();
        let guarded = fitter.without_occluder_edges(&pts, fitted);
        assert!(!guarded.inliers[19] && !guarded.inliers[30]);
        let left_out: Vec<usize> = (0..180).filter(|&i| !guarded.inliers[i]).collect();
        assert_eq!(left_out, (19..=30).collect::<Vec<_>>());
        let e = guarded.ellipse;
        let left = (e.a - truth.a).abs() + (e.b - truth.b).abs();
        assert!(pulled > 1e-3, "the pull moved the first fit: {pulled}");
        assert!(left < 1e-6, "{e:?}");
        assert!((e.cx - truth.cx).abs() < 1e-6 && (e.cy - truth.cy).abs() < 1e-6);
    }

    /// A rim seen as in the simulator with the probe over a third of it
    /// (sweep seed 15, probe occlusion 30-40 %, frame 15): rim points every
    /// 1.5 degrees with 0.06 px noise; from -66 to -12 degrees the rays find
    /// the probe's outline instead, 0-10 px outside the rim, whose concave
    /// bottom comes within 4 px of it; -12 to 50 degrees found nothing.
    fn rim_beside_a_probe(seed: u64) -> (Ellipse, Vec<[f64; 2]>) {
        use rand::SeedableRng;
        let truth = Ellipse::new(622.86, 657.57, 76.57, 75.84, -1.309);
        // Outward offset of the probe's outline (degrees, pixels).
        let outline = [
            (-66.0, 0.8),
            (-58.0, 4.7),
            (-51.0, 5.8),
            (-44.0, 4.9),
            (-34.0, 3.9),
            (-28.0, 4.5),
            (-20.0, 6.3),
            (-12.0, 10.5),
        ];
        let offset = |deg: f64| {
            outline.windows(2).find_map(|w| {
                let ((d0, o0), (d1, o1)) = (w[0], w[1]);
                (d0..=d1)
                    .contains(&deg)
                    .then(|| o0 + (o1 - o0) * (deg - d0) / (d1 - d0))
            })
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut pts = Vec::new();
        for k in 0..240 {
            let deg = -180.0 + 1.5 * f64::from(k);
            if (-12.0..50.0).contains(&deg) {
                continue;
            }
            let t = deg.to_radians();
            let radius =
                radius_towards(&truth, t) + offset(deg).unwrap_or(0.0) + 0.06 * normal(&mut rng);
            pts.push([truth.cx + radius * t.cos(), truth.cy + radius * t.sin()]);
        }
        (truth, pts)
    }

    /// The distance from `e`'s centre to its rim in direction `t` (radians).
    fn radius_towards(e: &Ellipse, t: f64) -> f64 {
        let (u, v) = (t.cos(), t.sin());
        let (s, c) = e.theta.sin_cos();
        let (x, y) = (u * c + v * s, -u * s + v * c);
        1.0 / ((x / e.a).powi(2) + (y / e.b).powi(2)).sqrt()
    }

    /// One standard normal draw (Box-Muller).
    fn normal(rng: &mut impl rand::Rng) -> f64 {
        let (p, q): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
        (-2.0 * p.ln()).sqrt() * (std::f64::consts::TAU * q).cos()
    }

    /// A rim seen as in the simulator with the probe's body across the
    /// disc's lower side (sweep seed 15, probe occlusion 30-40 %, frame
    /// 46, where the edge passes 1.15 px outside): rim points every 0.9
    /// degrees with 0.07 px noise; from 87 to 124 degrees the rays find the
    /// probe's straight lower edge, which passes 0.9 px outside the rim at
    /// 105 degrees; 40-87 and 124-157 degrees found nothing.
    fn rim_beside_a_probe_edge(seed: u64) -> (Ellipse, Vec<[f64; 2]>) {
        use rand::SeedableRng;
        let truth = Ellipse::new(390.76, 737.08, 63.75, 61.17, -1.054);
        let closest = 105f64.to_radians();
        let edge_distance = radius_towards(&truth, closest) + 0.9;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut pts = Vec::new();
        for k in 0..400 {
            let deg = 0.9 * f64::from(k);
            if (40.0..87.0).contains(&deg) || (124.0..157.0).contains(&deg) {
                continue;
            }
            let t = deg.to_radians();
            let radius = if (87.0..124.0).contains(&deg) {
                edge_distance / (t - closest).cos()
            } else {
                radius_towards(&truth, t)
            } + 0.07 * normal(&mut rng);
            pts.push([truth.cx + radius * t.cos(), truth.cy + radius * t.sin()]);
        }
        (truth, pts)
    }

    /// Fits 40 draws of `rim` (seeds 0-39: its truth and points) and its
    /// refit without the occluder's edges, and asserts each within 0.1 px
    /// of the truth, centre and axes.
    fn fits_within_a_tenth_of_a_pixel(rim: fn(u64) -> (Ellipse, Vec<[f64; 2]>)) {
        let mut fitter = Fitter::new(&cfg());
        for seed in 0..40 {
            let (truth, pts) = rim(seed);
            let fitted = fitter.fit(&pts, seed).unwrap();
            let e = fitter.without_occluder_edges(&pts, fitted).ellipse;
            let centre = (e.cx - truth.cx).hypot(e.cy - truth.cy);
            let axes = (e.a - truth.a).abs().max((e.b - truth.b).abs());
            assert!(
                centre < 0.1 && axes < 0.1,
                "seed {seed}: centre {centre:.3} px, axes {axes:.3} px off"
            );
        }
    }

    #[test]
    fn a_probe_outline_near_the_rim_does_not_bend_the_fit() {
        // Before the isolated-run check, some seeds took the outline's
        // bottom as rim, left out the true rim beside it, and came out
        // about 2 px too big and 1.7 px off centre.
        fits_within_a_tenth_of_a_pixel(rim_beside_a_probe);
    }

    #[test]
    fn a_probe_edge_a_pixel_outside_the_rim_does_not_bend_the_fit() {
        // Before the comparison priced a left-out point by the points'
        // noise rather than the band's 0.5 px floor, the edge's points
        // within that floor bent the fit toward them in 38 of these 40
        // seeds (seed 0: 0.35 px off centre, an axis 0.38 px too long). An
        // edge 0.6 px outside still bends it in about half the seeds: see
        // README, "Ellipse fitting", *Why the noise caps the cost*.
        fits_within_a_tenth_of_a_pixel(rim_beside_a_probe_edge);
    }

    #[test]
    fn a_whole_rim_is_not_refitted() {
        let truth = Ellipse::new(400.0, 300.0, 60.0, 45.0, 0.3);
        let pts = ring(&truth, 120, std::f64::consts::TAU);
        let mut fitter = Fitter::new(&cfg());
        let fitted = fitter.fit(&pts, 3).unwrap();
        assert_eq!(fitter.without_occluder_edges(&pts, fitted.clone()), fitted);
    }

    #[test]
    fn non_finite_points_are_dropped_and_flagged() {
        let truth = Ellipse::new(100.0, 50.0, 30.0, 20.0, -0.3);
        let mut pts = ring(&truth, 60, std::f64::consts::TAU);
        pts[3] = [f64::NAN, 1.0];
        pts[10] = [1.0, f64::INFINITY];
        let r = Fitter::new(&cfg()).fit(&pts, 7).unwrap();
        assert!(!r.inliers[3] && !r.inliers[10]);
        assert!(r.ellipse.max_param_error_px(&truth) < 1e-6);
    }

    #[test]
    fn too_few_and_degenerate_inputs_are_errors() {
        let mut f = Fitter::new(&cfg());
        assert_eq!(f.fit(&[], 0), Err(FitError::TooFewPoints(0)));
        let four = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
        assert_eq!(f.fit(&four, 0), Err(FitError::TooFewPoints(4)));
        let same = [[3.0, 4.0]; 50];
        assert!(f.fit(&same, 0).is_err());
        let line: Vec<[f64; 2]> = (0..50).map(|k| [k as f64, 2.0 * k as f64 + 1.0]).collect();
        for m in FitMethod::ALL {
            assert!(fit_with(m, &cfg(), &line, 0).is_err(), "{m:?}");
        }
    }

    #[test]
    fn invalid_config_is_reported_by_key() {
        let mut c = cfg();
        c.adaptive_subset_size = 4;
        let e = c.validate().unwrap_err();
        assert!(e.contains("fit.adaptive_subset_size"), "{e}");
        let mut f = Fitter::new(&c);
        let truth = Ellipse::new(0.0, 0.0, 3.0, 2.0, 0.0);
        assert!(matches!(
            f.fit(&ring(&truth, 20, 6.0), 0),
            Err(FitError::Config(_))
        ));
    }

    #[test]
    fn method_names_match_the_config_spelling() {
        for m in FitMethod::ALL {
            let toml = format!("[fit]\nmethod = \"{}\"\n", m.name());
            let c = Config::from_toml_str(&toml, "t.toml").unwrap();
            assert_eq!(c.fit.method, m);
        }
        assert!(Config::from_toml_str("[fit]\nmethod = \"hough\"\n", "t.toml").is_err());
    }
}
