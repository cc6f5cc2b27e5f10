//! Why a frame gave no drogue: the reason of the candidate that came
//! closest ("the candidate" in the words below), in words a user can act
//! on. It goes into the per-frame record
//! (`not_detected`), the MCAP `/drogue/detection` topic and `review`'s
//! summary, so that a miss is explained without rerunning with
//! `RUST_LOG=debug` (README, "Why a frame was not detected").

use serde::{Deserialize, Serialize};
use std::fmt;

/// Why the frame gave no drogue. The detector's reasons are those of the
/// candidate that got furthest through verification (each check below
/// comes after the ones above it); the last four are the measurement's,
/// after a candidate was found.
#[derive(Clone, Debug, PartialEq)]
pub enum MissReason {
    /// No dark region at any level and no round edge became a candidate.
    NoCandidate,
    /// No candidate had edges all round that fit an ellipse.
    NoRim,
    /// The closest candidate's ellipse is no disc at any allowed range and tilt.
    Implausible,
    /// Too few edges lie on its ellipse (how many).
    FewRimPoints(usize),
    /// Its rim's median step is fainter than `min_contrast_gray` (gray levels).
    LowContrast(f64),
    /// Its inside is not dark all over, as a crescent's or a ring's is not
    /// (the share that is).
    LightInside(f64),
    /// Blurred beyond what can be measured: this share of its rim's steps
    /// run into the ends of the widest window.
    Blurred(f64),
    /// Soft all round, a blob out of focus (the share of sharp steps).
    Soft(f64),
    /// A dark shape inside a larger one, such as the probe's tip inside the
    /// disc (the rise beyond its rim over its step).
    Nested(f64),
    /// No canopy around it (the share of its predicted canopy rim seen).
    NoCanopy(f64),
    /// Its evidence score is below `min_score`.
    LowScore(f64),
    /// Too thin for its canopy rim to be judged (minor semi-axis, pixels).
    TooSmall(f64),
    /// It verified on the sparse rim but not on the full-density one (why).
    NotAtFullDensity(Box<MissReason>),
    /// The ellipse fit refused its rim points (the fit's message).
    FitRefused(String),
    /// The fit took another edge for the rim than the detector verified.
    FitNotTheRim,
    /// The ellipse gives no circle pose.
    NoPose,
    /// A weak candidate, tilted, whose canopy rim cannot be judged for either pose.
    WeakUnjudged,
}

impl MissReason {
    /// A short stable code, for scripts and the review's counts.
    pub fn code(&self) -> &'static str {
        match self {
            Self::NoCandidate => "no_candidate",
            Self::NoRim => "no_rim",
            Self::Implausible => "implausible",
            Self::FewRimPoints(_) => "few_rim_points",
            Self::LowContrast(_) => "low_contrast",
            Self::LightInside(_) => "light_inside",
            Self::Blurred(_) => "blurred",
            Self::Soft(_) => "soft",
            Self::Nested(_) => "nested",
            Self::NoCanopy(_) => "no_canopy",
            Self::LowScore(_) => "low_score",
            Self::TooSmall(_) => "too_small",
            Self::NotAtFullDensity(_) => "not_at_full_density",
            Self::FitRefused(_) => "fit_refused",
            Self::FitNotTheRim => "fit_not_the_rim",
            Self::NoPose => "no_pose",
            Self::WeakUnjudged => "weak_unjudged",
        }
    }
}

impl fmt::Display for MissReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoCandidate => write!(f, "nothing in the frame looks like a dark disc"),
            Self::NoRim => write!(f, "no candidate has a rim that fits an ellipse"),
            Self::Implausible => {
                write!(f, "the candidate is no disc at any allowed range and tilt")
            }
            Self::FewRimPoints(n) => write!(f, "only {n} edges lie on the candidate's rim"),
            Self::LowContrast(c) => {
                write!(f, "the candidate's rim is too faint ({c:.0} gray levels)")
            }
            Self::LightInside(s) => write!(
                f,
                "the candidate is not dark inside (only {s:.2} of it is): a crescent or a ring"
            ),
            Self::Blurred(s) => write!(
                f,
                "blurred beyond what can be measured: {s:.2} of the rim's steps run into the widest window's ends"
            ),
            Self::Soft(s) => write!(
                f,
                "the candidate is soft all round (only {s:.2} of its steps are sharp): out of focus"
            ),
            Self::Nested(r) => write!(
                f,
                "the candidate is a dark shape inside a larger one (rise beyond its rim {r:.2} of its step), such as the probe's tip"
            ),
            Self::NoCanopy(s) => write!(
                f,
                "no canopy around the candidate ({s:.2} of its predicted canopy rim seen)"
            ),
            Self::LowScore(s) => write!(f, "the candidate scores {s:.2}, below min_score"),
            Self::TooSmall(px) => write!(
                f,
                "the candidate is too thin ({px:.1} px) for its canopy rim to be judged"
            ),
            Self::NotAtFullDensity(why) => write!(
                f,
                "a candidate verified on the sparse rim failed on the full-density one: {why}"
            ),
            Self::FitRefused(e) => write!(f, "the ellipse fit refused the rim points: {e}"),
            Self::FitNotTheRim => write!(f, "the fit took another edge for the rim"),
            Self::NoPose => write!(f, "the ellipse gives no circle pose"),
            Self::WeakUnjudged => write!(
                f,
                "a weak tilted candidate whose canopy rim cannot be judged for either pose"
            ),
        }
    }
}

/// A frame without a drogue: why, and how many candidates were tried.
#[derive(Clone, Debug, PartialEq)]
pub struct NotDetected {
    /// Why.
    pub reason: MissReason,
    /// Candidates verified by the full-frame search (0 on a tracked frame
    /// found at its predicted ellipse whose measurement then failed).
    pub candidates: u32,
}

/// The record's form of [`NotDetected`]: `{"reason", "detail", "candidates"}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NotDetectedRecord {
    /// [`MissReason::code`].
    pub reason: String,
    /// The reason in words, with its figure.
    pub detail: String,
    /// Candidates verified.
    pub candidates: u32,
}

impl From<&NotDetected> for NotDetectedRecord {
    fn from(n: &NotDetected) -> Self {
        Self {
            reason: n.reason.code().to_string(),
            detail: n.reason.to_string(),
            candidates: n.candidates,
        }
    }
}

/// Misses counted by reason code, most first (then by code): `no_canopy
/// 6, blurred 4`, as `process` and `review` print them.
pub fn counts_line(counts: &std::collections::BTreeMap<String, u64>) -> String {
    let mut by_count: Vec<(&String, &u64)> = counts.iter().collect();
    by_count.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    let list: Vec<String> = by_count.iter().map(|(r, n)| format!("{r} {n}")).collect();
    list.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_reason_has_its_own_code() {
        let all = [
            MissReason::NoCandidate,
            MissReason::NoRim,
            MissReason::Implausible,
            MissReason::FewRimPoints(3),
            MissReason::LowContrast(4.0),
            MissReason::LightInside(0.3),
            MissReason::Blurred(0.6),
            MissReason::Soft(0.01),
            MissReason::Nested(0.5),
            MissReason::NoCanopy(0.1),
            MissReason::LowScore(0.2),
            MissReason::TooSmall(3.0),
            MissReason::NotAtFullDensity(Box::new(MissReason::NoCanopy(0.2))),
            MissReason::FitRefused("too few points".into()),
            MissReason::FitNotTheRim,
            MissReason::NoPose,
            MissReason::WeakUnjudged,
        ];
        let mut codes: Vec<&str> = all.iter().map(MissReason::code).collect();
        codes.sort_unstable();
        codes.dedup();
        assert_eq!(codes.len(), all.len());
    }

    #[test]
    fn counts_are_listed_most_first_then_by_code() {
        let counts = [("blurred", 4), ("no_canopy", 6), ("nested", 4)]
            .into_iter()
            .map(|(r, n)| (r.to_string(), n))
            .collect();
        assert_eq!(counts_line(&counts), "no_canopy 6, blurred 4, nested 4");
    }

    #[test]
    fn the_record_carries_the_code_the_words_and_the_count() {
        let miss = NotDetected {
            reason: MissReason::Blurred(0.62),
            candidates: 7,
        };
        let json = serde_json::to_value(NotDetectedRecord::from(&miss)).unwrap();
        assert_eq!(json["reason"], "blurred");
        assert_eq!(json["candidates"], 7);
        let detail = json["detail"].as_str().unwrap();
        assert!(detail.contains("0.62"), "{detail}");
    }
}
