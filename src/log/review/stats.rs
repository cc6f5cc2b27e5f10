//! Bounded-memory statistics for the review: a fixed-bin histogram for
//! percentiles and per-range error sums.

use std::fmt;

/// Histogram width, ms: percentiles are exact to this.
const BIN_MS: f64 = 0.01;
/// Histogram span, ms; values above land in the last bin (max is exact).
const SPAN_MS: f64 = 2000.0;

/// Milliseconds in 10 µs bins up to 2 s: 800 KB at most, any log length.
#[derive(Clone, Debug, Default)]
pub struct Histogram {
    bins: Vec<u32>,
    count: u64,
    max: f64,
}

impl Histogram {
    /// Counts one sample, ms; negative or non-finite ones are left out.
    pub fn add(&mut self, ms: f64) {
        if !ms.is_finite() || ms < 0.0 {
            return;
        }
        if self.bins.is_empty() {
            self.bins = vec![0; (SPAN_MS / BIN_MS) as usize + 1];
        }
        let i = ((ms / BIN_MS) as usize).min(self.bins.len() - 1);
        self.bins[i] = self.bins[i].saturating_add(1);
        self.count += 1;
        self.max = self.max.max(ms);
    }

    /// Samples counted.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest sample, ms (exact, even beyond the bins); 0 when empty.
    pub fn max(&self) -> f64 {
        self.max
    }

    /// The value below which a share `q` of the samples lie (bin centre;
    /// nearest-rank), ms. 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((q * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0u64;
        for (i, &n) in self.bins.iter().enumerate() {
            seen += u64::from(n);
            if seen >= rank {
                return ((i as f64 + 0.5) * BIN_MS).min(self.max);
            }
        }
        self.max
    }

    /// (bin start ms, count) of the non-empty bins, merged into `width_ms`.
    pub fn coarse(&self, width_ms: f64) -> Vec<(f64, u64)> {
        let per = ((width_ms / BIN_MS).round() as usize).max(1);
        self.bins
            .chunks(per)
            .enumerate()
            .map(|(i, c)| {
                (
                    i as f64 * per as f64 * BIN_MS,
                    c.iter().map(|&n| u64::from(n)).sum(),
                )
            })
            .filter(|&(_, n)| n > 0)
            .collect()
    }
}

/// Errors against truth for one range interval.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RangeBin {
    /// Lower edge of the interval, metres (inclusive).
    pub lo_m: f64,
    /// Upper edge of the interval, metres (exclusive).
    pub hi_m: f64,
    /// Frames with a truth range in the interval.
    pub frames: u64,
    /// Of those, frames detected (the error sums are over these).
    pub detected: u64,
    /// Sum of the position errors, metres.
    pub sum_pos_err_m: f64,
    /// Sum of the squared position errors, square metres.
    pub sum_pos_err2_m2: f64,
    /// Largest position error, metres.
    pub max_pos_err_m: f64,
    /// Sum of the normal's angular errors, degrees.
    pub sum_normal_err_deg: f64,
    /// Largest angular error of the normal, degrees.
    pub max_normal_err_deg: f64,
}

impl RangeBin {
    /// Mean position error over the detected frames, metres.
    pub fn mean_pos_err_m(&self) -> f64 {
        self.sum_pos_err_m / self.detected.max(1) as f64
    }
    pub(crate) fn rms_pos_err_m(&self) -> f64 {
        (self.sum_pos_err2_m2 / self.detected.max(1) as f64).sqrt()
    }
    pub(crate) fn mean_normal_err_deg(&self) -> f64 {
        self.sum_normal_err_deg / self.detected.max(1) as f64
    }
}

/// Range interval edges, metres.
const RANGE_EDGES_M: [f64; 9] = [0.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 50.0, f64::INFINITY];

pub fn range_bins() -> Vec<RangeBin> {
    RANGE_EDGES_M
        .windows(2)
        .map(|w| RangeBin {
            lo_m: w[0],
            hi_m: w[1],
            ..Default::default()
        })
        .collect()
}

/// Counts a frame with truth at `range_m`; `errors` = (position m, normal deg)
/// when it was detected.
pub fn add_to_bins(bins: &mut [RangeBin], range_m: f64, errors: Option<(f64, f64)>) {
    let Some(b) = bins
        .iter_mut()
        .find(|b| range_m >= b.lo_m && range_m < b.hi_m)
    else {
        return;
    };
    b.frames += 1;
    if let Some((pe, ne)) = errors {
        b.detected += 1;
        b.sum_pos_err_m += pe;
        b.sum_pos_err2_m2 += pe * pe;
        b.max_pos_err_m = b.max_pos_err_m.max(pe);
        b.sum_normal_err_deg += ne;
        b.max_normal_err_deg = b.max_normal_err_deg.max(ne);
    }
}

impl fmt::Display for RangeBin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let range = if self.hi_m.is_finite() {
            format!("{:>4.0}-{:<4.0}", self.lo_m, self.hi_m)
        } else {
            format!("{:>4.0}+    ", self.lo_m)
        };
        write!(
            f,
            "{range}    {:>7}  {:>8}  {:>7.3} / {:>7.3} / {:>7.3}    {:>7.2} / {:>7.2}",
            self.frames,
            self.detected,
            self.mean_pos_err_m(),
            self.rms_pos_err_m(),
            self.max_pos_err_m,
            self.mean_normal_err_deg(),
            self.max_normal_err_deg
        )
    }
}

/// The dropped-item total of the writer's own report line
/// ("log items dropped so far: N (queue full), M (write errors)").
pub fn dropped_in_report(message: &str) -> Option<u64> {
    let rest = message.strip_prefix("log items dropped so far: ")?;
    let mut total = 0u64;
    for part in rest.split(',') {
        let n: u64 = part.trim().split(' ').next()?.parse().ok()?;
        total += n;
    }
    Some(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_sample() {
        let mut h = Histogram::default();
        // 1..=100 ms: nearest-rank p50 = 50, p95 = 95, p99 = 99.
        for i in 1..=100 {
            h.add(f64::from(i));
        }
        assert!((h.quantile(0.5) - 50.0).abs() <= BIN_MS);
        assert!((h.quantile(0.95) - 95.0).abs() <= BIN_MS);
        assert!((h.quantile(0.99) - 99.0).abs() <= BIN_MS);
        assert_eq!(h.max(), 100.0);
        assert_eq!(h.count(), 100);
    }

    #[test]
    fn errors_land_in_their_range_bin() {
        let mut bins = range_bins();
        add_to_bins(&mut bins, 12.0, Some((0.3, 2.0)));
        add_to_bins(&mut bins, 14.0, Some((0.4, 4.0)));
        add_to_bins(&mut bins, 14.5, None);
        let b = &bins[3];
        assert_eq!((b.lo_m, b.hi_m, b.frames, b.detected), (10.0, 15.0, 3, 2));
        assert!((b.mean_pos_err_m() - 0.35).abs() < 1e-12);
        assert!((b.rms_pos_err_m() - (0.125f64).sqrt()).abs() < 1e-12);
        assert_eq!(b.max_normal_err_deg, 4.0);
    }

    #[test]
    fn reads_the_writers_drop_report() {
        assert_eq!(
            dropped_in_report("log items dropped so far: 3 (queue full), 4 (write errors)"),
            Some(7)
        );
        assert_eq!(dropped_in_report("something else"), None);
    }
}
