//! The fields of each topic the review reads, as serde views of the JSON
//! records (the rest of each record is skipped unparsed): what the review
//! depends on in the log's contract (ARCHITECTURE.md section 7).

use serde::Deserialize;

/// The fields of `/drogue/detection` the review reads.
#[derive(Deserialize)]
pub(super) struct DetectionLite {
    pub(super) detected: bool,
    pub(super) position_camera: Option<[f64; 3]>,
    pub(super) normal_camera: Option<[f64; 3]>,
    pub(super) position_body: Option<[f64; 3]>,
    pub(super) times_us: Option<TimesLite>,
    /// Absent in logs written before records said why.
    pub(super) not_detected: Option<NotDetectedLite>,
}

/// The reason code of a frame without a drogue.
#[derive(Deserialize)]
pub(super) struct NotDetectedLite {
    reason: String,
}

impl NotDetectedLite {
    /// The reason's code as written, when it is one (lower-case letters and
    /// underscores: nothing to quote in the CSV or to escape on a terminal);
    /// `unknown` for anything else a log may hold.
    pub(super) fn code(&self) -> &str {
        let plain = !self.reason.is_empty()
            && self.reason.len() <= 32
            && self
                .reason
                .chars()
                .all(|c| c.is_ascii_lowercase() || c == '_');
        if plain { &self.reason } else { "unknown" }
    }
}

#[derive(Deserialize)]
pub(super) struct TimesLite {
    pub(super) total_us: f64,
}

/// The fields of `/sim/truth` the review reads.
#[derive(Deserialize, Clone, Copy)]
pub(super) struct TruthLite {
    pub(super) position_camera: [f64; 3],
    pub(super) normal_camera: [f64; 3],
    pub(super) range_m: f64,
    /// Absent in logs of older simulators.
    pub(super) position_body: Option<[f64; 3]>,
}

#[derive(Deserialize)]
pub(super) struct LinkLite {
    pub(super) name: String,
    /// When the message went out, ns since the Unix epoch.
    pub(super) time_ns: Option<u64>,
    /// Capture time of the frame a pose message was built from.
    pub(super) capture_time_ns: Option<u64>,
}

/// The fields of `/drogue/stats` the review reads.
#[derive(Deserialize)]
pub(super) struct StatsLite {
    pub(super) time_ns: u64,
    pub(super) cpu_pct: CpuPctLite,
    pub(super) cpu_s_total: CpuTotalLite,
    pub(super) rss_bytes: Option<u64>,
    pub(super) queues: QueuesLite,
}

#[derive(Deserialize)]
pub(super) struct CpuPctLite {
    pub(super) pipeline: f64,
}

#[derive(Deserialize, Clone, Copy)]
pub(super) struct CpuTotalLite {
    pub(super) process: f64,
    pub(super) source: f64,
    /// Absent in logs written before the writer's CPU was measured.
    #[serde(default)]
    pub(super) log_writer: f64,
}

#[derive(Deserialize)]
pub(super) struct QueuesLite {
    pub(super) log: u64,
    pub(super) link_events: u64,
}

#[cfg(test)]
mod tests {
    use super::NotDetectedLite;

    #[test]
    fn a_reason_from_the_log_is_passed_on_only_as_a_plain_code() {
        let code = |reason: &str| {
            NotDetectedLite {
                reason: reason.to_string(),
            }
            .code()
            .to_string()
        };
        assert_eq!(code("no_canopy"), "no_canopy");
        for odd in [
            "",
            "a,b",
            "x\ny",
            "\u{1b}[31mred",
            "Blurred",
            &"a".repeat(33),
        ] {
            assert_eq!(code(odd), "unknown", "{odd:?}");
        }
    }
}
