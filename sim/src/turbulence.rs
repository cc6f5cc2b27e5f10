//! Dryden turbulence (MIL-F-8785C) and the drogue sway it drives.
//!
//! Gust velocities: the Dryden spectra of MIL-F-8785C for medium/high
//! altitude (above 2000 ft: scale length L = 1750 ft, sigma from the
//! probability-of-exceedance curves of its Figure 7, light = 1e-2,
//! moderate = 1e-3, severe = 1e-5), realised as shaping filters driven by
//! unit white noise (two-sided PSD 1):
//! lateral/vertical  H(s) = sigma sqrt(L/V) (1 + sqrt(3) T s) / (1 + T s)^2,
//! T = L/V, whose output variance is exactly sigma^2.
//!
//! Sway: the drogue hangs on the hose in the relative wind; a cross gust v
//! turns that wind by v/V, so the drogue settles at a lateral (or vertical)
//! displacement `hose_lever_m * v / V`, reached through a first-order lag of
//! time constant `sway_lag_s` (the drogue's drag dynamics):
//! d' = (hose_lever_m * v / V - d) / sway_lag_s.
//! Filter and lag are one linear system per axis, discretised exactly
//! (Van Loan) for the frame period, so the statistics do not depend on the
//! frame rate.

use nalgebra::{Matrix3, Matrix6, RowVector3, SymmetricEigen, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

const FT: f64 = 0.3048;

/// Turbulence intensity of MIL-F-8785C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Intensity {
    /// No gusts.
    #[default]
    None,
    /// Light: exceeded with probability 1e-2.
    Light,
    /// Moderate: exceeded with probability 1e-3.
    Moderate,
    /// Severe: exceeded with probability 1e-5.
    Severe,
}

/// MIL-F-8785C Figure 7 (via JSBSim's table): altitude (ft) columns and
/// sigma (ft/s) for exceedance probabilities 1e-2, 1e-3, 1e-5.
const ALT_FT: [f64; 12] = [
    500.0, 1750.0, 3750.0, 7500.0, 15000.0, 25000.0, 35000.0, 45000.0, 55000.0, 65000.0, 75000.0,
    80000.0,
];
const SIGMA_LIGHT_FTPS: [f64; 12] = [6.6, 6.9, 7.4, 6.7, 4.6, 2.7, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0];
const SIGMA_MODERATE_FTPS: [f64; 12] =
    [8.6, 9.6, 10.6, 10.1, 8.0, 6.6, 5.0, 4.2, 2.7, 0.0, 0.0, 0.0];
const SIGMA_SEVERE_FTPS: [f64; 12] = [
    15.6, 17.6, 23.0, 23.6, 22.1, 20.0, 16.0, 15.1, 12.1, 7.9, 6.2, 5.1,
];

/// Lowest altitude of the medium/high-altitude model, metres (2000 ft).
pub const MIN_ALTITUDE_M: f64 = 2000.0 * FT;
/// Scale length above 2000 ft, metres (1750 ft).
pub const SCALE_LENGTH_M: f64 = 1750.0 * FT;

/// RMS gust velocity (m/s) of an intensity at an altitude (m, >= 2000 ft).
pub fn sigma_mps(intensity: Intensity, altitude_m: f64) -> f64 {
    let table = match intensity {
        Intensity::None => return 0.0,
        Intensity::Light => &SIGMA_LIGHT_FTPS,
        Intensity::Moderate => &SIGMA_MODERATE_FTPS,
        Intensity::Severe => &SIGMA_SEVERE_FTPS,
    };
    let h = altitude_m / FT;
    let i = ALT_FT.iter().rposition(|a| *a <= h).unwrap_or(0);
    let j = (i + 1).min(ALT_FT.len() - 1);
    let f = if j == i {
        0.0
    } else {
        ((h - ALT_FT[i]) / (ALT_FT[j] - ALT_FT[i])).clamp(0.0, 1.0)
    };
    (table[i] + f * (table[j] - table[i])) * FT
}

/// One sway axis (lateral or vertical): Dryden filter + drogue lag.
#[derive(Clone, Debug)]
pub struct SwayAxis {
    phi: Matrix3<f64>,
    /// Square root of the discrete process-noise covariance.
    noise_sqrt: Matrix3<f64>,
    a: Matrix3<f64>,
    gust_out: RowVector3<f64>,
    state: Vector3<f64>,
}

/// Square root (V sqrt(L)) of a symmetric positive semi-definite matrix.
fn psd_sqrt(m: &Matrix3<f64>) -> Matrix3<f64> {
    let e = SymmetricEigen::new((m + m.transpose()) * 0.5);
    let d = Matrix3::from_diagonal(&e.eigenvalues.map(|l| l.max(0.0).sqrt()));
    e.eigenvectors * d
}

impl SwayAxis {
    /// `sigma_mps` gust RMS, `scale_length_m` L, `airspeed_mps` V,
    /// `hose_lever_m` and `sway_lag_s` of the sway model, `dt_s` the step.
    pub fn new(
        sigma_mps: f64,
        scale_length_m: f64,
        airspeed_mps: f64,
        hose_lever_m: f64,
        sway_lag_s: f64,
        dt_s: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let t = scale_length_m / airspeed_mps;
        let k = sigma_mps * t.sqrt();
        // Controllable canonical form of K (1 + sqrt3 T s) / (T s + 1)^2.
        let gust_out = RowVector3::new(k / (t * t), k * 3f64.sqrt() / t, 0.0);
        let g = hose_lever_m / airspeed_mps / sway_lag_s;
        let a = Matrix3::new(
            0.0,
            1.0,
            0.0,
            -1.0 / (t * t),
            -2.0 / t,
            0.0,
            g * gust_out[0],
            g * gust_out[1],
            -1.0 / sway_lag_s,
        );
        let b = Vector3::new(0.0, 1.0, 0.0);
        // Van Loan: exp([[-A, B B^T], [0, A^T]] dt) = [[., Phi^-1 Qd], [0, Phi^T]].
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-a));
        m.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(b * b.transpose()));
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&a.transpose());
        let e = (m * dt_s).exp();
        let phi: Matrix3<f64> = e.fixed_view::<3, 3>(3, 3).transpose();
        let qd = phi * e.fixed_view::<3, 3>(0, 3);
        // Stationary covariance P = Phi P Phi^T + Qd, so the run starts in
        // statistical equilibrium.
        let mut p = qd;
        let steps = ((20.0 * t.max(sway_lag_s)) / dt_s).ceil() as usize;
        for _ in 0..steps.clamp(10, 200_000) {
            p = phi * p * phi.transpose() + qd;
        }
        let mut axis = SwayAxis {
            phi,
            noise_sqrt: psd_sqrt(&qd),
            a,
            gust_out,
            state: Vector3::zeros(),
        };
        axis.state = psd_sqrt(&p) * normal3(rng);
        axis
    }

    /// Advances the axis by one time step (`dt_s` of [`SwayAxis::new`]).
    pub fn step(&mut self, rng: &mut impl Rng) {
        self.state = self.phi * self.state + self.noise_sqrt * normal3(rng);
    }

    /// Gust velocity along the axis, m/s.
    pub fn gust_mps(&self) -> f64 {
        (self.gust_out * self.state)[0]
    }

    /// Drogue displacement along the axis, m.
    pub fn displacement_m(&self) -> f64 {
        self.state[2]
    }

    /// Drogue velocity along the axis, m/s.
    pub fn rate_mps(&self) -> f64 {
        (self.a.row(2) * self.state)[0]
    }
}

fn normal3(rng: &mut impl Rng) -> Vector3<f64> {
    Vector3::new(
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn table_values() {
        // 7500 ft column, ft/s -> m/s.
        assert!((sigma_mps(Intensity::Moderate, 7500.0 * FT) - 10.1 * FT).abs() < 1e-12);
        assert!((sigma_mps(Intensity::Severe, 11250.0 * FT) - 22.85 * FT).abs() < 1e-9);
        assert_eq!(sigma_mps(Intensity::None, 3000.0), 0.0);
    }

    /// Variance of the lagged Dryden output from the spectrum itself:
    /// (1/2pi) int |H(jw)|^2 g^2 / (1 + tau^2 w^2) dw, integrated numerically
    /// over x = T w = tan(u).
    fn sway_variance_from_spectrum(sigma: f64, t: f64, gain: f64, tau: f64) -> f64 {
        let n = 200_000;
        let h = std::f64::consts::PI / n as f64;
        let mut sum = 0.0;
        for i in 0..n {
            let u = -std::f64::consts::FRAC_PI_2 + (i as f64 + 0.5) * h;
            let x = u.tan();
            let w = x / t;
            let spec = sigma * sigma * t * (1.0 + 3.0 * x * x) / (1.0 + x * x).powi(2);
            let lag = gain * gain / (1.0 + tau * tau * w * w);
            sum += spec * lag * (1.0 + x * x) * h / t; // dw = sec^2(u) du / T
        }
        sum / (2.0 * std::f64::consts::PI)
    }

    #[test]
    fn sway_statistics_match_the_dryden_model() {
        let altitude = 3000.0;
        let v = 120.0;
        let (lever, lag) = (15.0, 0.8);
        for intensity in [Intensity::Light, Intensity::Moderate, Intensity::Severe] {
            let sigma = sigma_mps(intensity, altitude);
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let dt = 1.0 / 30.0;
            let mut axis = SwayAxis::new(sigma, SCALE_LENGTH_M, v, lever, lag, dt, &mut rng);
            let n = 1_500_000; // 50 000 s, about 11 000 scale times
            let (mut g2, mut d2, mut dm) = (0.0, 0.0, 0.0);
            for _ in 0..n {
                axis.step(&mut rng);
                g2 += axis.gust_mps().powi(2);
                d2 += axis.displacement_m().powi(2);
                dm += axis.displacement_m();
            }
            let gust_var = g2 / n as f64;
            let disp_var = d2 / n as f64;
            let t = SCALE_LENGTH_M / v;
            let expected = sway_variance_from_spectrum(sigma, t, lever / v, lag);
            // Sampling error of a variance over ~11 000 correlation times is
            // about 1.5 %; allow 6 %.
            assert!(
                (gust_var / (sigma * sigma) - 1.0).abs() < 0.06,
                "{intensity:?} gust {gust_var} vs {}",
                sigma * sigma
            );
            assert!(
                (disp_var / expected - 1.0).abs() < 0.06,
                "{intensity:?} sway {disp_var} vs {expected}"
            );
            assert!((dm / n as f64).abs() < 0.1 * expected.sqrt());
        }
    }
}
