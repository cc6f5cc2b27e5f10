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

#[test]
#[ignore]
fn debug_worst_cases() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let sc = Scenario::occluded();
    let c = cfg();
    for k in 0..300u64 {
        let spec = synth::random_spec(&sc, &mut rng);
        let s = synth::generate(&spec, &mut rng);
        if std::env::var("CASE").is_ok_and(|v| v != k.to_string()) {
            continue;
        }
        eprintln!("truth {:?}", s.truth);
        let r = match fit_with(FitMethod::Adaptive, &c, &s.points, k) {
            Ok(r) => r,
            Err(e) => {
                println!("{k}: {e} {spec:?}");
                continue;
            }
        };
        let e = errors(&r.ellipse, &s.truth);
        if e[..4].iter().any(|v| *v > 0.5) {
            let kept = r.inliers.iter().filter(|x| **x).count();
            let kept_out = r
                .inliers
                .iter()
                .zip(&s.outlier)
                .filter(|(i, o)| **i && **o)
                .count();
            println!(
                "{k}: {:?} a={:.1} b/a={:.2} vis={:.2} noise={:.2} n={} kept={} kept_out={} err={:?}",
                spec.occluder,
                spec.truth.a,
                spec.truth.b / spec.truth.a,
                spec.visible_fraction,
                spec.noise_px,
                s.points.len(),
                kept,
                kept_out,
                e
            );
        }
    }
}
