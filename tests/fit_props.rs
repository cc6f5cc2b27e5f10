//! The ellipse fitters against generated rims with exact truth
//! (`fit::synth`): accuracy targets, the default against the paper's
//! Algorithm 1 on occluded rims, robustness to structured outliers, no panic
//! on any input, and determinism per seed.

use drogue_vision::config::Config;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::fit::synth::{self, Occluder, RimSet, Scenario};
use drogue_vision::measure::fit::{FitConfig, FitError, FitMethod, Fitter, fit_with};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn cfg() -> FitConfig {
    Config::embedded().fit
}

fn sets(sc: &Scenario, count: usize, seed: u64) -> Vec<RimSet> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| synth::generate(&synth::random_spec(sc, &mut rng), &mut rng))
        .collect()
}

/// Absolute errors |dcx|, |dcy|, |da|, |db| (px) and |dtheta| (deg).
fn errors(fit: &Ellipse, truth: &Ellipse) -> [f64; 5] {
    [
        (fit.cx - truth.cx).abs(),
        (fit.cy - truth.cy).abs(),
        (fit.a - truth.a).abs(),
        (fit.b - truth.b).abs(),
        fit.theta_error_rad(truth).to_degrees(),
    ]
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Per-parameter error quantiles of `method` over `sets`; a failed fit counts
/// as an infinite error. theta is only scored where the ellipse is clearly
/// not a circle (b/a < 0.95), since it is undefined for a circle.
struct Stats {
    median: [f64; 5],
    p95: [f64; 5],
    failures: usize,
}

fn stats(method: FitMethod, sets: &[RimSet]) -> Stats {
    let c = cfg();
    let mut cols: [Vec<f64>; 5] = Default::default();
    let mut failures = 0;
    for (k, s) in sets.iter().enumerate() {
        let err = match fit_with(method, &c, &s.points, k as u64) {
            Ok(r) => errors(&r.ellipse, &s.truth),
            Err(_) => {
                failures += 1;
                [f64::INFINITY; 5]
            }
        };
        for i in 0..4 {
            cols[i].push(err[i]);
        }
        if s.truth.b / s.truth.a < 0.95 {
            cols[4].push(err[4]);
        }
    }
    let mut median = [0.0; 5];
    let mut p95 = [0.0; 5];
    for i in 0..5 {
        median[i] = quantile(&mut cols[i], 0.5);
        p95[i] = quantile(&mut cols[i], 0.95);
    }
    Stats {
        median,
        p95,
        failures,
    }
}

fn print(title: &str, rows: &[(FitMethod, Stats)]) {
    println!("\n{title}");
    println!(
        "method          | median cx cy a b (px), theta (deg) | p95 cx cy a b, theta | failed"
    );
    for (m, s) in rows {
        println!(
            "{:<15} | {:.3} {:.3} {:.3} {:.3} {:.3} | {:.3} {:.3} {:.3} {:.3} {:.3} | {}",
            m.name(),
            s.median[0],
            s.median[1],
            s.median[2],
            s.median[3],
            s.median[4],
            s.p95[0],
            s.p95[1],
            s.p95[2],
            s.p95[3],
            s.p95[4],
            s.failures
        );
    }
}

#[test]
fn default_meets_the_accuracy_target_on_clean_arcs() {
    // Clean 60-100 % arcs, 0.1 px noise, semi-axes 10-400 px.
    let data = sets(&Scenario::clean(), 300, 11);
    let rows: Vec<_> = FitMethod::ALL
        .iter()
        .map(|&m| (m, stats(m, &data)))
        .collect();
    print("clean 60-100 % arcs, 0.1 px noise (300 sets)", &rows);
    let s = &rows[0].1;
    assert_eq!(rows[0].0, FitMethod::Adaptive);
    assert_eq!(s.failures, 0);
    for i in 0..4 {
        assert!(s.median[i] <= 0.1, "median {:?}", s.median);
        assert!(s.p95[i] <= 0.5, "p95 {:?}", s.p95);
    }
    assert!(s.median[4] <= 0.2, "theta median {} deg", s.median[4]);
}

#[test]
fn default_is_at_least_as_accurate_as_algorithm1_on_occluded_rims() {
    // 60-70 % arcs, the rest a structured outlier run, plus scattered points.
    let data = sets(&Scenario::occluded(), 300, 12);
    let rows: Vec<_> = FitMethod::ALL
        .iter()
        .map(|&m| (m, stats(m, &data)))
        .collect();
    print(
        "occluded: 60-70 % arcs + structured run + scattered (300 sets)",
        &rows,
    );
    let ours = &rows[0].1;
    let paper = &rows[1].1;
    assert_eq!(rows[1].0, FitMethod::Algorithm1);
    for i in 0..5 {
        assert!(
            ours.median[i] <= paper.median[i],
            "param {i}: adaptive {} vs algorithm1 {}",
            ours.median[i],
            paper.median[i]
        );
        assert!(ours.p95[i] <= paper.p95[i], "param {i} p95");
    }
    assert!(ours.failures <= paper.failures);
}

/// A rim recipe from proptest's values (the points are drawn from a seeded
/// generator, so a failing case shrinks to a reproducible seed).
fn spec_from(
    (log_a, ratio, theta, vis, start, noise, occ, scattered): (
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        usize,
        usize,
    ),
) -> synth::RimSpec {
    let a = log_a.exp();
    let b = a * ratio;
    let perimeter = std::f64::consts::TAU * ((a * a + b * b) / 2.0).sqrt();
    let occluders = [
        Occluder::Gap,
        Occluder::Chord,
        Occluder::Wedge,
        Occluder::Tube,
        Occluder::InnerArc,
    ];
    synth::RimSpec {
        truth: Ellipse::new(640.0, 480.0, a, b, theta),
        visible_start: start,
        visible_fraction: vis,
        rim_points: (perimeter as usize).clamp(40, 2000),
        noise_px: noise,
        occluder: occluders[occ],
        scattered,
    }
}

fn rim_strategy() -> impl Strategy<Value = (f64, f64, f64, f64, f64, f64, usize, usize)> {
    (
        (30.0f64).ln()..(400.0f64).ln(),
        0.5f64..1.0,
        -1.5f64..1.5,
        0.6f64..1.0,
        0.0f64..std::f64::consts::TAU,
        0.05f64..0.3,
        0usize..5,
        0usize..6,
    )
}

proptest! {
    // A fixed seed: the same 256 rims on every run (CI stays reproducible);
    // a failure shrinks to a case that can be replayed.
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: proptest::test_runner::RngSeed::Fixed(2026),
        ..ProptestConfig::default()
    })]

    /// Random ellipses (semi-axes 30-400 px), noise 0.05-0.3 px, up to 40 %
    /// of the rim replaced by a structured outlier run plus scattered
    /// points: the default fit stays within 1 px (or 1 % of the size) of the
    /// truth, keeps no point far from the rim and at least 90 % of the rim.
    #[test]
    fn default_fit_survives_structured_outliers(params in rim_strategy(), seed in 0u64..1000) {
        let spec = spec_from(params);
        let set = synth::generate(&spec, &mut ChaCha8Rng::seed_from_u64(seed));
        prop_assume!(set.outlier_fraction() <= 0.4);
        let r = Fitter::new(&cfg()).fit(&set.points, seed).unwrap();
        let err = errors(&r.ellipse, &set.truth);
        let tol = (0.01 * set.truth.a).max(1.0);
        prop_assert!(err[..4].iter().all(|e| *e <= tol), "err {:?} tol {}", err, tol);
        // Kept points lie near the true rim, and most rim points are kept.
        let truth = set.truth.to_conic();
        for (p, _) in set.points.iter().zip(&r.inliers).filter(|(_, k)| **k) {
            let d = truth.sampson_distance(p[0], p[1]);
            prop_assert!(d <= tol + 2.0, "kept a point {} px off the rim", d);
        }
        let rim = set.outlier.iter().filter(|o| !**o).count();
        let rim_kept = r.inliers.iter().zip(&set.outlier).filter(|(k, o)| **k && !**o).count();
        prop_assert!(rim_kept * 10 >= rim * 9, "kept {} of {} rim points", rim_kept, rim);
    }

}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Any input at all: no panic, and a result is a finite ellipse with one
    /// flag per input point.
    #[test]
    fn no_panic_on_any_points(
        raw in prop::collection::vec(
            (prop_oneof![any::<f64>(), -2000.0f64..2000.0, Just(f64::NAN), Just(f64::INFINITY), Just(0.0)],
             prop_oneof![any::<f64>(), -2000.0f64..2000.0, Just(f64::NEG_INFINITY), Just(0.0)]),
            0..40),
        seed in any::<u64>(),
    ) {
        let points: Vec<[f64; 2]> = raw.into_iter().map(|(x, y)| [x, y]).collect();
        for m in FitMethod::ALL {
            if let Ok(r) = fit_with(m, &cfg(), &points, seed) {
                prop_assert_eq!(r.inliers.len(), points.len());
                let e = r.ellipse;
                prop_assert!([e.cx, e.cy, e.a, e.b, e.theta].iter().all(|v| v.is_finite()));
                prop_assert!(e.a >= e.b && e.b > 0.0);
                prop_assert!(r.rms_residual_px.is_finite());
            }
        }
    }

    /// Degenerate shapes: points on a line (with or without noise), a few
    /// points repeated many times. No panic; a line is never an ellipse.
    #[test]
    fn degenerate_inputs_do_not_panic(
        n in 5usize..200,
        slope in -10.0f64..10.0,
        distinct in 1usize..6,
        noise in prop_oneof![Just(0.0), 1e-9f64..1e-3],
        seed in any::<u64>(),
    ) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        use rand::Rng;
        let line: Vec<[f64; 2]> = (0..n)
            .map(|k| {
                let x = k as f64;
                [x + noise * rng.random::<f64>(), slope * x + 3.0 + noise * rng.random::<f64>()]
            })
            .collect();
        let repeated: Vec<[f64; 2]> = (0..n).map(|k| [(k % distinct) as f64 * 7.0, ((k % distinct) as f64).powi(2)]).collect();
        for m in FitMethod::ALL {
            let r = fit_with(m, &cfg(), &line, seed);
            if noise == 0.0 {
                prop_assert!(r.is_err(), "{:?} fitted a line: {:?}", m, r);
            }
            let _ = fit_with(m, &cfg(), &repeated, seed);
        }
    }
}

#[test]
fn the_same_seed_gives_the_same_result() {
    let data = sets(&Scenario::occluded(), 20, 3);
    let c = cfg();
    for (k, s) in data.iter().enumerate() {
        for m in FitMethod::ALL {
            let first = fit_with(m, &c, &s.points, k as u64);
            let again = fit_with(m, &c, &s.points, k as u64);
            assert_eq!(first, again, "{m:?}");
        }
        // The Fitter is the configured method, and keeps no state between
        // calls that could change a result.
        let mut f = Fitter::new(&c);
        let a = f.fit(&s.points, 9);
        let _ = f.fit(&data[0].points, 1);
        assert_eq!(a, f.fit(&s.points, 9));
        assert_eq!(a, fit_with(FitMethod::Adaptive, &c, &s.points, 9));
    }
}

#[test]
fn too_few_points_is_an_error_not_a_guess() {
    let e = Ellipse::new(10.0, 10.0, 5.0, 3.0, 0.0);
    let four: Vec<[f64; 2]> = (0..4).map(|k| e.point_at(k as f64)).collect();
    let mut with_nan = four.clone();
    with_nan.push([f64::NAN, 0.0]);
    let mut f = Fitter::new(&cfg());
    assert_eq!(f.fit(&four, 0), Err(FitError::TooFewPoints(4)));
    assert_eq!(f.fit(&with_nan, 0), Err(FitError::TooFewPoints(4)));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// Ellipse -> conic -> ellipse is the identity, for any scaling of the
    /// conic; the centre agrees with the paper's closed forms (eqs. 3-4) and
    /// the axis direction with eq. 7 (which gives it modulo 90 deg).
    #[test]
    fn ellipse_conic_round_trip(
        cx in -2000.0f64..2000.0,
        cy in -2000.0f64..2000.0,
        a in 1.0f64..1000.0,
        ratio in 0.05f64..1.0,
        theta in -1.57f64..1.57,
        k in prop_oneof![-1.0e3f64..-1.0e-3, 1.0e-3f64..1.0e3],
    ) {
        let e = Ellipse::new(cx, cy, a, a * ratio, theta);
        let c = e.to_conic();
        let scaled = drogue_vision::measure::ellipse::Conic {
            a: c.a * k, b: c.b * k, c: c.c * k, d: c.d * k, e: c.e * k, f: c.f * k,
        };
        let back = scaled.to_ellipse().unwrap();
        let tol = 1e-7 * (a + cx.abs() + cy.abs());
        prop_assert!(back.max_param_error_px(&e) < tol, "{:?} {:?}", e, back);
        if ratio < 0.99 {
            prop_assert!(back.theta_error_rad(&e) < 1e-6);
            // Eq. 7: theta = atan(B / (A - C)) / 2, modulo 90 deg.
            let t7 = 0.5 * (c.b / (c.a - c.c)).atan();
            let d = (t7 - e.theta).rem_euclid(std::f64::consts::FRAC_PI_2);
            prop_assert!(d.min(std::f64::consts::FRAC_PI_2 - d) < 1e-6, "eq 7: {} vs {}", t7, e.theta);
        }
        // Eqs. 3-4.
        let den = 4.0 * c.a * c.c - c.b * c.b;
        let xe = (c.b * c.e - 2.0 * c.c * c.d) / den;
        let ye = (c.b * c.d - 2.0 * c.a * c.e) / den;
        prop_assert!((xe - cx).abs() < tol && (ye - cy).abs() < tol);
        // Points of the ellipse are on the conic.
        for t in [0.0, 1.0, 2.5, 4.0] {
            let [u, v] = e.point_at(t);
            prop_assert!(c.sampson_distance(u, v) < 1e-6 * a.max(1.0));
        }
    }
}
