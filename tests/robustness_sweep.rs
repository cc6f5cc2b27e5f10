//! The robustness sweep (issue 12): the project's own simulator renders
//! randomised unrelated frames, one factor at a time and all together
//! (`drogue_sim::sweep`), every frame is measured on its own and scored
//! against the simulator's exact truth, and each level is held to the limits
//! in [`LIMITS`]. The scenes come from a fixed seed, so the same frames are
//! measured on every run and a regression in any level shows.
//!
//! The limits are the detector's measured figures (detection rate and false
//! detections exactly; accuracy medians at 1.5 times the measured value plus
//! a small floor): raise them as the detector improves. Print the table with
//! `cargo run --release --example robustness_sweep`.

mod sweep;

use drogue_sim::TruthEllipse;
use drogue_sim::sweep::standard_levels;
use drogue_vision::measure::ellipse::Ellipse;
use sweep::LevelStats;

/// Frames per level (the example's default is the same).
const FRAMES: u64 = 10;

/// What one level must achieve. `None`: not checked (no detection expected,
/// or none accurate enough to have a median).
struct Limit {
    /// `factor setting`, as `Level::label` gives it.
    level: &'static str,
    /// Smallest detection rate on frames with a drogue, percent.
    min_detected_pct: Option<u32>,
    /// Most false detections: any on drogue-free frames, and detections
    /// more than 5 % of the range or 10 degrees (the answer given) off.
    max_false: usize,
    /// Most detections whose ellipse is not the disc's (a wrong pose
    /// whatever the ambiguity; `sweep::WRONG_CENTRE_SHARE`).
    max_wrong_ellipse: usize,
    /// Largest medians over the other detections: ellipse centre error
    /// (undistorted px), position error (% of range), normal error (deg).
    max_centre_px: Option<f64>,
    max_position_pct: Option<f64>,
    max_normal_deg: Option<f64>,
}

const fn limit(
    level: &'static str,
    min_detected_pct: Option<u32>,
    max_false: usize,
    max_wrong_ellipse: usize,
    max_centre_px: Option<f64>,
    max_position_pct: Option<f64>,
    max_normal_deg: Option<f64>,
) -> Limit {
    Limit {
        level,
        min_detected_pct,
        max_false,
        max_wrong_ellipse,
        max_centre_px,
        max_position_pct,
        max_normal_deg,
    }
}

/// The limits, one row per level (seed `sweep::SEED`, `FRAMES` frames each),
/// set from the detector of this commit. At 12-16 m the false detections are
/// the unresolved answer's mirror half (`unresolved`: both solutions are
/// reported, the first is scored); so are those under 16-32 px of blur,
/// whose ellipses are right (no wrong ellipse) since the long ramps are
/// smoothed for their own rise (eighth session: 32 px 50 -> 60 % detected,
/// its 4 wrong ellipses -> 0, the false count 4 -> 5 mirror halves; its
/// position median is of one frame). `everything` gained two detections,
/// one of them wrong (a disc cut by a glare streak and the probe, its left
/// part taken for the disc with 63 % canopy evidence): counted here. It
/// found its last disc (90 -> 100 %) when the edge source's circles were
/// looked for again past what lies inside them, and lost its wrong one
/// (the false count 3 -> 2) when steps into glare stopped giving rim
/// points (fourteenth session). Its accuracy limits rose with the throat
/// shadow it draws since the seventeenth session (medians centre 0.048 ->
/// 0.061 px, position 0.094 -> 0.200 %, normal 0.36 -> 0.71 degrees: the
/// shadow moves wide steps' mid-level crossings outward). Under haze 0.4
/// and 0.6 the canopy's end a band's width inside the rim now settles the
/// ambiguity: their false detections, mirror halves of unresolved
/// answers, went 2 -> 0 each; under 16 px of blur the rim judged where
/// the blur runs along it took the same count 6 -> 3, and the rim's lean
/// ordering an unresolved answer took 32 px's 5 -> 4. Measuring on every
/// pixel of the rim (eighteenth session, `rim_point_spacing_px` 2 -> 1 px)
/// lowered the centre median on 119 of 135 levels of the seeds 12, 3 and 7
/// (30 frames) and detected the same frames; on these frames two limits
/// rose: the 30 px glare streak's position median (0.021 -> 0.031 %, a
/// median of 7 frames; over 30 frames of the seeds 12, 3 and 7 it went
/// 0.021 -> 0.015, 0.016 -> 0.028 and 0.044 -> 0.025 %), and exposure
/// 0.7's false count 0 -> 1 (an unresolved answer's mirror half first).
/// The edge source's votes without the edges that rise into a glare
/// (nineteenth session) found the 30 px streak's three missed discs (70 ->
/// 100 %), one of them an unresolved answer whose mirror half comes first
/// (false 0 -> 1); over 30 frames of the seeds 1-16 that level went 443 ->
/// 457 of 480 with no wrong ellipse left. Placing sharp steps for the
/// curvature of a streak's skirt (forty-fourth session) took that level's
/// position median 0.031 -> 0.023 % and its false count 1 -> 2: frame 2,
/// an unresolved answer whose mirror half comes first, its normal 9.95 ->
/// 10.01 degrees from the truth's (the true half 0.35 -> 0.46), where more
/// than 10 counts (`sweep_frame` prints both). Over the seeds 1-32 (30
/// frames a level) the level's position median went 0.0292 -> 0.0195 %,
/// with 951 of 960 detected (952 before). The `probe tip` levels
/// (forty-seventh session: the probe's rounded tip over the disc's middle,
/// with blur and `everything`'s imaging) are held to what the detector of
/// that commit gives; over the seeds 1-32 (30 frames a level) they detect
/// 933, 916 and 819 of 960 with 0, 6 and 34 wrong ellipses (README,
/// "Robustness sweep").
#[rustfmt::skip]
const LIMITS: &[Limit] = &[
    //    level                                  detected %  false  wrong  centre px     position %    normal deg
    limit("baseline", Some(100), 0, 0, Some(0.02), Some(0.052), Some(0.13)),
    limit("haze 0.2", Some(100), 0, 0, Some(0.02), Some(0.019), Some(0.22)),
    limit("haze 0.4", Some(100), 0, 0, Some(0.022), Some(0.019), Some(0.15)),
    limit("haze 0.6", Some(100), 0, 0, Some(0.015), Some(0.024), Some(0.32)),
    limit("glare streak 4 px wide", Some(100), 1, 0, Some(0.02), Some(0.035), Some(0.16)),
    limit("glare streak 12 px wide", Some(100), 1, 0, Some(0.022), Some(0.044), Some(0.2)),
    limit("glare streak 30 px wide", Some(100), 2, 0, Some(0.029), Some(0.047), Some(1.36)),
    limit("glare glow sigma 30 px", Some(100), 0, 0, Some(0.02), Some(0.037), Some(0.17)),
    limit("glare glow sigma 70 px", Some(100), 0, 0, Some(0.02), Some(0.031), Some(0.15)),
    limit("glare glow sigma 135 px", Some(100), 0, 0, Some(0.031), Some(0.049), Some(0.16)),
    limit("motion blur 4 px", Some(100), 0, 0, Some(0.02), Some(0.059), Some(0.67)),
    limit("motion blur 8 px", Some(100), 0, 0, Some(0.027), Some(0.095), Some(0.98)),
    limit("motion blur 16 px", Some(100), 3, 0, Some(0.043), Some(0.443), Some(1.2)),
    limit("motion blur 32 px", Some(60), 4, 0, Some(0.24), Some(0.78), Some(4.94)),
    limit("noise sigma 2", Some(100), 0, 0, Some(0.02), Some(0.056), Some(0.31)),
    limit("noise sigma 5", Some(100), 0, 0, Some(0.013), Some(0.034), Some(0.16)),
    limit("noise sigma 10", Some(100), 0, 0, Some(0.038), Some(0.079), Some(0.25)),
    limit("noise sigma 20", Some(100), 1, 0, Some(0.079), Some(0.161), Some(0.55)),
    limit("exposure gain 0.4", Some(100), 0, 0, Some(0.022), Some(0.024), Some(0.13)),
    limit("exposure gain 0.7", Some(100), 1, 0, Some(0.02), Some(0.032), Some(0.19)),
    limit("exposure gain 1.3", Some(100), 0, 0, Some(0.019), Some(0.031), Some(0.15)),
    limit("vignetting 0.4", Some(100), 0, 0, Some(0.017), Some(0.027), Some(0.16)),
    limit("vignetting 0.7", Some(100), 0, 0, Some(0.019), Some(0.025), Some(0.15)),
    limit("distortion k1 -0.12", Some(100), 1, 0, Some(0.028), Some(0.041), Some(0.17)),
    limit("distortion k1 -0.25", Some(100), 0, 0, Some(0.016), Some(0.024), Some(0.13)),
    limit("range 1 m", Some(100), 0, 0, Some(0.01), Some(0.008), Some(0.07)),
    limit("range 2 m", Some(100), 0, 0, Some(0.011), Some(0.011), Some(0.1)),
    limit("range 3 m", Some(100), 0, 0, Some(0.016), Some(0.019), Some(0.13)),
    limit("range 5 m", Some(100), 0, 0, Some(0.022), Some(0.027), Some(0.17)),
    limit("range 8 m", Some(100), 0, 0, Some(0.029), Some(0.043), Some(0.29)),
    limit("range 12 m", Some(100), 6, 0, Some(0.034), Some(0.072), Some(0.47)),
    limit("range 16 m", Some(100), 5, 0, Some(0.027), Some(0.329), Some(0.76)),
    limit("tilt 0 deg", Some(100), 0, 0, Some(0.015), Some(0.024), Some(1.96)),
    limit("tilt 15 deg", Some(100), 0, 0, Some(0.017), Some(0.028), Some(0.13)),
    limit("tilt 30 deg", Some(100), 0, 0, Some(0.02), Some(0.02), Some(0.08)),
    limit("tilt 45 deg", Some(100), 0, 0, Some(0.019), Some(0.019), Some(0.08)),
    limit("tilt 60 deg", Some(100), 0, 0, Some(0.02), Some(0.034), Some(0.08)),
    limit("tilt 75 deg", Some(100), 0, 0, Some(0.028), Some(0.083), Some(0.08)),
    limit("probe occlusion 0-10 %", Some(100), 0, 0, Some(0.029), Some(0.019), Some(0.16)),
    limit("probe occlusion 10-20 %", Some(100), 0, 0, Some(0.02), Some(0.019), Some(0.16)),
    limit("probe occlusion 20-30 %", Some(100), 0, 0, Some(0.026), Some(0.028), Some(0.14)),
    limit("probe occlusion 30-40 %", Some(100), 0, 0, Some(0.04), Some(0.026), Some(0.32)),
    limit("probe tip 10-20 %", Some(100), 4, 0, Some(0.22), Some(0.71), Some(1.65)),
    limit("probe tip 20-30 %", Some(100), 2, 0, Some(0.25), Some(0.49), Some(0.75)),
    limit("probe tip 30-40 %", Some(90), 2, 0, Some(0.83), Some(1.4), Some(1.14)),
    limit("distractors 1", Some(100), 0, 0, Some(0.013), Some(0.029), Some(0.17)),
    limit("distractors 3", Some(100), 0, 0, Some(0.017), Some(0.024), Some(0.17)),
    limit("star distractors 2", Some(100), 0, 0, Some(0.023), Some(0.022), Some(0.22)),
    limit("throat shadow 15 %", Some(100), 0, 0, Some(0.02), Some(0.02), Some(0.13)),
    limit("throat shadow 30 %", Some(100), 0, 0, Some(0.02), Some(0.053), Some(0.13)),
    limit("everything", Some(100), 2, 0, Some(0.092), Some(0.30), Some(1.07)),
    limit("no drogue: crescent", None, 0, 0, None, None, None),
    limit("no drogue: disc without canopy", None, 0, 0, None, None, None),
    limit("no drogue: ring without canopy", None, 0, 0, None, None, None),
    limit("no drogue: dark blobs, rectangles", None, 0, 0, None, None, None),
    limit("no drogue: stars, flowers", None, 0, 0, None, None, None),
];

fn check(stats: &LevelStats, limit: &Limit) -> Vec<String> {
    let mut failures = Vec::new();
    let name = &limit.level;
    if let Some(min) = limit.min_detected_pct {
        let rate = 100.0 * stats.detection_rate();
        // NaN (nothing expected) fails too.
        if rate.is_nan() || rate + 1e-9 < f64::from(min) {
            failures.push(format!("{name}: detected {rate:.0} % < {min} %"));
        }
    }
    if stats.wrong_ellipse > limit.max_wrong_ellipse {
        failures.push(format!(
            "{name}: {} wrong ellipses > {}",
            stats.wrong_ellipse, limit.max_wrong_ellipse
        ));
    }
    if stats.false_detections > limit.max_false {
        failures.push(format!(
            "{name}: {} false detections > {}",
            stats.false_detections, limit.max_false
        ));
    }
    let medians = [
        ("centre px", stats.centre_px_median(), limit.max_centre_px),
        (
            "position % of range",
            stats.position_pct_median(),
            limit.max_position_pct,
        ),
        (
            "normal deg",
            stats.normal_deg_median(),
            limit.max_normal_deg,
        ),
    ];
    for (what, median, max) in medians {
        if let Some(max) = max
            && (median.is_nan() || median > max)
        {
            failures.push(format!("{name}: {what} median {median:.3} > {max}"));
        }
    }
    failures
}

#[test]
fn robustness_sweep_meets_its_limits() {
    let levels = standard_levels();
    let stats = sweep::run(&levels, FRAMES, sweep::SEED, None);
    eprintln!("{}", sweep::markdown(&stats));
    let mut failures = Vec::new();
    for s in &stats {
        match LIMITS.iter().find(|l| l.level == s.label()) {
            Some(limit) => failures.extend(check(s, limit)),
            None => failures.push(format!("{}: no limit in LIMITS", s.label())),
        }
    }
    for l in LIMITS {
        if !stats.iter().any(|s| s.label() == l.level) {
            failures.push(format!(
                "{}: a limit for a level the sweep has not",
                l.level
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Vignetted corners make dark regions larger than the disc whose seeds
/// find no step at all (`NoRim`). In the `everything` level's frame 19 of
/// seed 7 (a 71x36 px disc cut in two by a glare streak, the probe's end
/// over it), four corners and the probe took the budget of
/// `max_candidates` regions, largest first, and neither half of the disc
/// was tried; the edge source's circles missed it too. The regions
/// without a rim now give their places to the next ones. In frame 5 of
/// seed 29 (a 28x26 px disc at 8.2 m in haze 0.48, vignette 0.36) the
/// places one refund gave back went to two dark regions beside the disc
/// (its hose and probe, by where they lie) and a fifth corner, whose place
/// was not given back again: the refunds go on batch after batch.
#[test]
fn regions_without_a_rim_leave_the_budget_to_the_disc() {
    let levels = standard_levels();
    let everything = levels.iter().find(|l| l.label() == "everything").unwrap();
    for (seed, index, centre_px, axis_share) in [(7, 19, 0.2, 0.01), (29, 5, 0.5, 0.025)] {
        let (m, truth) = sweep::measure_one(seed, everything, index);
        let truth = truth.expect("a drogue frame").ellipse;
        let found = m
            .detection
            .unwrap_or_else(|| panic!("seed {seed} frame {index}: the disc is not detected"))
            .ellipse_px;
        let centre = (found.cx - truth.cx).hypot(found.cy - truth.cy);
        assert!(
            centre < centre_px
                && (found.a / truth.a - 1.0).abs() < axis_share
                && (found.b / truth.b - 1.0).abs() < axis_share,
            "seed {seed} frame {index}: {found:?} for {truth:?}"
        );
    }
}

/// A glare streak across the disc whose core over it stays below
/// saturation is a light bar cutting the disc in two. Its edges are steps
/// from the disc's dark up to a light far above the canopy's, and past the
/// bar the level falls back to the disc's: no rim (`verify::light_bars`).
/// Taken for rim, they made one side of the disc verify as a smaller
/// ellipse (the bar's edge its chord), or a distractor beside the bar win:
/// in these five `everything` frames (seeds 1, 6, 10 and 15) the answer's
/// axes were 0.34-0.87 of the disc's, its centre 8-56 px off: a wrong pose.
/// Each is now the disc, right by the sweep's own measure, except `10/009`:
/// its canopy rim stands within two noise sigmas, so the canopy test's
/// noise floor (`NOISE_BRIGHTENING_SIGMAS`) leaves it undetected, which is
/// not a wrong answer. Since the probe has its nozzle collar (forty-sixth
/// session) `6/13`, 11 px of blur across a 31 px disc that the probe and
/// the streak cross, is refused as blurred beyond what can be measured
/// (0.27 of its full-density steps clipped): not a wrong answer either.
#[test]
fn a_light_bar_across_the_disc_gives_no_rim() {
    let wrong = everything_frames_not_the_disc(&[
        (1, 29, true),
        (6, 13, false),
        (10, 9, false),
        (15, 8, true),
        (15, 13, true),
    ]);
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The `everything` frames (seed, index, whether it must be detected)
/// whose answer is not the disc by the sweep's own measure, or that are
/// not detected though they must be.
fn everything_frames_not_the_disc(frames: &[(u64, u64, bool)]) -> Vec<String> {
    frames_not_the_disc("everything", frames)
}

/// The same for the frames of level `label`.
fn frames_not_the_disc(label: &str, frames: &[(u64, u64, bool)]) -> Vec<String> {
    frames_off(label, frames, |found, truth| {
        let centre = (found.cx - truth.cx).hypot(found.cy - truth.cy);
        (centre > sweep::WRONG_CENTRE_SHARE * truth.b
            || (found.a / truth.a - 1.0).abs() > sweep::WRONG_ELLIPSE_SHARE
            || (found.b / truth.b - 1.0).abs() > sweep::WRONG_ELLIPSE_SHARE)
            .then(|| format!("{found:?} for {truth:?}"))
    })
}

/// The frames (seed, index, whether it must be detected) of level `label`
/// whose answer `off` finds wrong against the simulator's ellipse (both in
/// undistorted pixels), with its reason, or that are not detected though
/// they must be.
fn frames_off(
    label: &str,
    frames: &[(u64, u64, bool)],
    off: impl Fn(&Ellipse, &TruthEllipse) -> Option<String>,
) -> Vec<String> {
    let levels = standard_levels();
    let level = levels.iter().find(|l| l.label() == label).unwrap();
    let mut wrong = Vec::new();
    for &(seed, index, must_detect) in frames {
        let (m, truth) = sweep::measure_one(seed, level, index);
        let truth = truth.expect("a drogue frame").ellipse;
        match m.detection.map(|d| d.ellipse_px) {
            Some(found) => {
                if let Some(why) = off(&found, &truth) {
                    wrong.push(format!("seed {seed} frame {index}: {why}"));
                }
            }
            None if must_detect => wrong.push(format!("seed {seed} frame {index}: not detected")),
            None => {}
        }
    }
    wrong
}

/// A glare streak across the disc: where it saturates, each step onto it
/// is the glare's, and where it does not, its edge is a straight line
/// across the rays. Either way it was the strongest rise on every ray of
/// a seed's wide pass that met it, and the ellipse hugging the streak's
/// edge drew more of those points than the disc's rim: the seed failed,
/// and with it the frame. The wide pass now drops steps into saturation
/// as the narrow passes do, and a seed that fails is tried once more
/// without up to two straight edges (`conic_fit::straight_edge`). These
/// eight `everything` frames (seeds 3-15) were undetected, each with the
/// disc plain to see beside the streak; each is now the disc, right by
/// the sweep's own measure. Since the probe has its nozzle collar
/// (forty-sixth session) `6/27`, a 22 px disc at 9 m in haze 0.51 with
/// the collar beside its rim, shows its canopy rim at 0.13 and is missed:
/// not a wrong answer, which is what this holds it to.
#[test]
fn a_glare_streak_across_the_disc_leaves_its_rim_found() {
    let wrong = everything_frames_not_the_disc(&[
        (3, 13, true),
        (6, 27, false),
        (9, 9, true),
        (9, 20, true),
        (9, 22, true),
        (11, 3, true),
        (13, 23, true),
        (15, 22, true),
    ]);
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A saturated glare streak 30 px wide across a disc of 50 px hides half
/// its rim or more. Steps onto the glare give no rim points, and the
/// narrow pass's 24-28 rays (6 px apart) left 7-11 on the rest, short of
/// `min_rim_points` (12): these frames (seeds 2-23) were lost with the
/// disc's other half and its canopy plain to see. A pass whose rim the
/// glare hides that far now looks again at twice the density, counting
/// only steps with nothing saturated inward of them: past the glare lies
/// the canopy's edge, not the disc's (seed 19's frame 12, whose disc shows
/// only a cap and a sliver, then gave a 32 % too tall ellipse; it must not
/// be a wrong answer). Each of the others is now the disc, right by the
/// sweep's own measure.
#[test]
fn a_disc_mostly_under_a_glare_streak_is_found_from_the_rest_of_its_rim() {
    let wrong = frames_not_the_disc(
        "glare streak 30 px wide",
        &[
            (2, 7, true),
            (2, 10, true),
            (11, 11, true),
            (16, 16, true),
            (19, 10, true),
            (21, 3, true),
            (23, 15, true),
            (19, 12, false),
        ],
    );
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A saturated glare streak 30 px wide across the middle of a 25-34 px
/// disc leaves two dark slivers of it. The canopy's rim band, whole but for
/// the streak's width, is then the roundest dark edge of the frame: the
/// edge source's circle there has the disc's centre and the band's radius
/// (the band's votes outnumber the slivers'), and verified as the disc it
/// shows no canopy beyond it (`NoCanopy`) or a light inside (`LightInside`).
/// The regions' seeds fell on the slivers and the struts. These ten frames
/// (seeds 1-30) were undetected with the drogue plain to see; the disc
/// concentric inside such a circle, at `r / R` of its size, is now tried
/// when nothing else verified, and each is the disc, right by the sweep's
/// own measure.
#[test]
fn a_disc_cut_in_two_by_glare_is_found_inside_its_canopy_ring() {
    let wrong = frames_not_the_disc(
        "glare streak 30 px wide",
        &[
            (1, 14, true),
            (4, 11, true),
            (4, 13, true),
            (6, 15, true),
            (8, 12, true),
            (9, 13, true),
            (16, 23, true),
            (28, 3, true),
            (29, 25, true),
            (30, 11, true),
        ],
    );
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The probe's body across the disc's lower side, its straight edge a
/// pixel or so outside the rim: the fit took the few points of that edge
/// within its band's 0.5 px floor for rim and bent toward them, because
/// the fit without them was charged that floor for each point it left
/// out. Priced at the rim's noise instead, the fit without them wins.
/// These frames (seeds 1-32, probe over 30-40 % of the rim, and seed 15's
/// frame 46 of `pose_nees`) were each 0.38-0.68 px off centre; each must
/// now be within 0.15 px of the simulator's ellipse, centre and axes (the
/// level's centre median is about 0.015 px).
#[test]
fn the_probes_edge_beside_the_rim_does_not_bend_the_fit() {
    let off = frames_off(
        "probe occlusion 30-40 %",
        &[
            (1, 23, true),
            (4, 16, true),
            (5, 21, true),
            (10, 23, true),
            (13, 15, true),
            (15, 12, true),
            (15, 46, true),
            (17, 20, true),
            (18, 14, true),
            (20, 2, true),
            (21, 9, true),
            (22, 29, true),
            (26, 22, true),
            (27, 28, true),
            (29, 13, true),
            (30, 1, true),
            (30, 15, true),
            (32, 1, true),
        ],
        |found, truth| {
            let centre = (found.cx - truth.cx).hypot(found.cy - truth.cy);
            let axes = (found.a - truth.a).abs().max((found.b - truth.b).abs());
            (centre > 0.15 || axes > 0.15)
                .then(|| format!("centre {centre:.3} px, axes {axes:.3} px off"))
        },
    );
    assert!(off.is_empty(), "{off:#?}");
}

/// The disc looked for inside a ring finds none where there is no drogue:
/// on these drogue-free rings without a canopy and crescents (seeds 1-32)
/// the edge source's circle verified as a ring (`LightInside`), the disc
/// inside it was tried (their miss reason is now that seed's, `NoCanopy`
/// at 0-0.03), and none is detected.
#[test]
fn the_inside_of_a_ring_without_a_canopy_is_no_drogue() {
    let mut found = detections_on(
        "no drogue: ring without canopy",
        &[
            (1, 25),
            (3, 0),
            (5, 9),
            (7, 18),
            (9, 1),
            (12, 10),
            (17, 1),
            (32, 26),
        ],
    );
    found.extend(detections_on("no drogue: crescent", &[(10, 20), (26, 8)]));
    assert!(found.is_empty(), "{found:#?}");
}

/// A glare streak 30 px wide across a disc of about 26 px radius at 7-8 m
/// leaves two slivers of it; the seeds on them settle on the slivers' own
/// outlines, and the seed that settles on the canopy's outer rim (the
/// roundest edge there, whole but for the streak) shows no canopy beyond
/// it (`NoCanopy`). The disc is now looked for inside every settled rim
/// that shows no canopy, concentric at `r / R` of its size, by the narrow
/// passes (which take no rim point on a step into saturation). These
/// frames (seeds 1-32) were undetected; each is now the disc, right by the
/// sweep's own measure. (Seed 19 frame 1 was one of them until the canopy
/// test took the fit's spread into account: its disc, 0.6 px off, is a
/// weak candidate whose canopy rim the fit no longer lets judge, and is
/// refused as `weak_unjudged`.)
#[test]
fn the_disc_is_looked_for_inside_a_rim_that_shows_no_canopy() {
    let mut wrong =
        frames_not_the_disc("glare streak 30 px wide", &[(23, 21, true), (28, 9, true)]);
    wrong.extend(everything_frames_not_the_disc(&[(1, 27, true)]));
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A candidate verified on the sparse rim is checked again at full
/// density by passes that settle; on a blurred or streaked disc they can
/// walk off it or run into the widest window. One full-density pass where
/// the sparse rim settled now holds the candidate when its canopy shows
/// beyond the doubt of its reading (0.76-0.87 on these three, which were
/// `not_at_full_density`). `everything` seed 19's frame 17, whose single
/// pass shows its canopy at 0.53 only, within that doubt, came out 3.7 px
/// off centre and 18 % short when any verified single pass was taken: it
/// must be no wrong answer.
#[test]
fn one_full_density_pass_holds_a_candidate_whose_settling_passes_walk_off() {
    let mut wrong =
        everything_frames_not_the_disc(&[(21, 3, true), (26, 15, true), (19, 17, false)]);
    wrong.extend(frames_not_the_disc("motion blur 32 px", &[(9, 12, true)]));
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A glare's glow beside the disc saturates the canopy around it: the
/// disc, lightened to a mid grey, is darker than no global threshold
/// separates, and every step of its rim runs straight into saturated
/// pixels, which the edge source takes for the glare's own skirt. The
/// local-contrast source, tried on frames where a glare saturates part of
/// the frame, finds it as darker than its neighbourhood. These frames were
/// not detected without it (`implausible`, the last candidate tried being
/// elsewhere); each must be the disc.
#[test]
fn a_disc_on_a_canopy_a_glow_saturated_is_found_by_its_local_contrast() {
    let mut wrong = frames_not_the_disc("glare glow sigma 135 px", &[(1, 6, true), (14, 28, true)]);
    wrong.extend(frames_not_the_disc(
        "glare glow sigma 70 px",
        &[(1, 28, true)],
    ));
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// Clear drogues in noise (`everything`: read noise 2-8 DN, haze): the
/// canopy test's polarity-free edge took the drogue's end at the outermost
/// box mean off the sky's level by `min_contrast_gray`, and in noise a
/// mean out in the sky does that now and then; the profile inside that
/// "end" was then mostly sky and the point refused, the canopy shown at
/// 0.36-0.47 and the frame lost (seed 17's frame 0: a 44 px disc at 5.3 m
/// with its canopy 40 gray levels over the sky). The end is now followed
/// out from a step noise does not make, and must be a step. These frames
/// (seeds 11-17) must be the disc; seed 15's frame 24, whose fit then
/// came out 15 % longer than the rim the detector verified, must be no
/// wrong answer.
#[test]
fn a_drogue_in_noise_shows_its_canopy_past_the_skys_blips() {
    let wrong = frames_not_the_disc(
        "everything",
        &[
            (11, 17, true),
            (11, 22, true),
            (12, 21, true),
            (14, 16, true),
            (15, 11, true),
            (17, 0, true),
            (15, 24, false),
        ],
    );
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// Motion blur leaves the steps where the rim runs along it as sharp as a
/// sharp step, which measures about 2.6 px itself; the `Soft` test (a blob
/// out of focus has no sharp step) counted a step sharp only within 4 px
/// (or 0.2 of the minor radius) in all, and a small disc blurred half its
/// minor radius had one sharp step in 71. These frames (blur 7-32 px over
/// discs of 14-21 px minor semi-axis) were undetected; each must be the
/// disc.
#[test]
fn a_blurred_discs_steps_along_the_blur_count_as_sharp() {
    let mut wrong = everything_frames_not_the_disc(&[(9, 12, true), (17, 17, true)]);
    wrong.extend(frames_not_the_disc(
        "motion blur 16 px",
        &[(5, 20, true), (11, 20, true)],
    ));
    wrong.extend(frames_not_the_disc("motion blur 32 px", &[(24, 6, true)]));
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A star or flower on a drogue-free frame can pass for the disc: its
/// core's rim, and its arms' edges where a canopy's rim would be. Its
/// score stays low (0.30-0.39), and for neither pose does the canopy rim
/// tell anything, although the ellipse is tilted enough for the two rims
/// to lie apart: such a weak candidate is now not a detection
/// (`UNJUDGED_TILTED_MIN_SCORE` in `src/measure/mod.rs`). These five
/// drogue-free frames (seeds 2, 7, 9, 12 and 15) were false detections.
#[test]
fn a_star_whose_canopy_says_nothing_is_no_drogue() {
    let found = detections_among_stars(&[(2, 4), (7, 0), (9, 13), (12, 28), (15, 3)]);
    assert!(found.is_empty(), "{found:#?}");
}

/// The canopy's end must be a step (`outer_edge_offset` in
/// `src/measure/detect/canopy.rs`): the predicted canopy rim of an ellipse
/// through a flower's lobes, or round dark blobs, lies in the sky, and a
/// sky brightening slowly across it left the background's level somewhere
/// on many of its points. Seeds 25 and 28 (stars and flowers, dark blobs),
/// never looked at while the rule was written, were false detections
/// before it; seed 23's flower was one once the drogue's end was followed
/// past the noise without it.
#[test]
fn a_sky_brightening_across_a_look_alikes_rim_is_no_canopy() {
    let mut found = detections_among_stars(&[(23, 6), (25, 2), (28, 8)]);
    found.extend(detections_on(
        "no drogue: dark blobs, rectangles",
        &[(28, 8)],
    ));
    assert!(found.is_empty(), "{found:#?}");
}

/// The scoring itself: truth and measurement meet in the same (undistorted)
/// pixels, also through a strongly distorting lens; a drogue-free level
/// expects nothing; and the limits catch a level that gets worse.
#[test]
fn scoring_and_limits_count_what_they_should() {
    let levels = standard_levels();
    let pick = |label: &str| *levels.iter().find(|l| l.label() == label).unwrap();
    let stats = sweep::run(
        &[pick("baseline"), pick("distortion k1 -0.25")],
        3,
        sweep::SEED,
        None,
    );
    for s in &stats {
        assert_eq!((s.frames, s.expected), (3, 3), "{}", s.label());
        assert!(
            !s.centre_px.is_empty(),
            "{}: no accurate detection",
            s.label()
        );
        assert!(
            s.centre_px.iter().all(|&c| c < 0.5),
            "{}: centre errors {:?}",
            s.label(),
            s.centre_px
        );
    }
    let free = sweep::run(&[pick("no drogue: crescent")], 2, sweep::SEED, None);
    assert_eq!(free[0].expected, 0);
    assert!(free[0].detection_rate().is_nan());

    let limit = LIMITS.iter().find(|l| l.level == "baseline").unwrap();
    let mut worse = stats[0].clone();
    worse.expected = 10;
    worse.detected = 9;
    worse.false_detections = limit.max_false + 1;
    worse.centre_px = vec![1.0];
    worse.position_rel = vec![0.0];
    worse.normal_deg = vec![0.0];
    let failures = check(&worse, limit);
    assert_eq!(failures.len(), 3, "{failures:?}");
}

/// A flower's petal on a drogue-free frame is a dark ellipse joined to
/// the flower at one end, as a disc is to the probe or hose; in a noisy
/// frame the plain sky around it showed half a canopy rim on noise alone,
/// enough for the canopy test (`NOISE_BRIGHTENING_SIGMAS` in
/// `src/measure/detect/canopy.rs`). These eight drogue-free frames (seeds
/// 1, 2, 3, 8, 9, 11, 12 and 16; frame noise estimated at 5 to 8 gray
/// levels) were false detections, scoring 0.45 to 0.62.
#[test]
fn a_petal_in_noise_shows_no_canopy_rim() {
    let found = detections_among_stars(&[
        (1, 0),
        (2, 23),
        (3, 2),
        (8, 11),
        (9, 25),
        (11, 26),
        (12, 11),
        (16, 0),
    ]);
    assert!(found.is_empty(), "{found:#?}");
}

/// A canopy-less disc (seed 3) and a crescent (seed 24, a seed never
/// looked at while the detector was built) on drogue-free frames passed the
/// full-frame search's full-density check with a canopy share just above
/// `min_canopy_fraction`, read at 48 points round the predicted rim. Such
/// a share is in doubt (`DOUBT_SIGMAS` in `src/measure/detect/canopy.rs`):
/// the points half-way between are read too, and at 96 points each shows
/// less than that and is no drogue. They were the sweep's only false
/// detections over seeds 1-24 (30 frames a level).
#[test]
fn a_canopy_less_disc_and_a_crescent_read_again_in_doubt_are_no_drogue() {
    let mut found = detections_on("no drogue: disc without canopy", &[(3, 26)]);
    found.extend(detections_on("no drogue: crescent", &[(24, 12)]));
    assert!(found.is_empty(), "{found:#?}");
}

/// The detections on the drogue-free stars and flowers level's frames
/// `(seed, index)`, one line each.
fn detections_among_stars(frames: &[(u64, u64)]) -> Vec<String> {
    detections_on("no drogue: stars, flowers", frames)
}

/// The detections on the drogue-free level `label`'s frames
/// `(seed, index)`, one line each.
fn detections_on(label: &str, frames: &[(u64, u64)]) -> Vec<String> {
    let levels = standard_levels();
    let level = levels.iter().find(|l| l.label() == label).unwrap();
    let mut found = Vec::new();
    for &(seed, index) in frames {
        let (m, truth) = sweep::measure_one(seed, level, index);
        assert!(truth.is_none(), "a drogue-free frame");
        if let Some(d) = m.detection {
            found.push(format!("seed {seed} frame {index}: {:?}", d.ellipse_px));
        }
    }
    found
}

/// A full-frame candidate whose minor semi-axis is below the smallest
/// radius at which the canopy rim can be judged (6.1 px: a 2 px step is
/// judged up to 15 % of the canopy rim's radius, 2.2 disc radii) rests on
/// its darkness alone (`canopy::smallest_judged_radius_px`). Over the
/// sweep's seeds 1-24 every such answer was wrong: these drogue-free frames
/// (crescents on seeds 3 and 16, a ring on seed 6, a star on seed 24) gave
/// false detections 6.7-11.4 px long and 3.1-4.8 px wide, and these drogue
/// frames (32 px of blur on seeds 4 and 12, `everything` on seed 6, a
/// 30 px glare streak on seed 23) gave 4-11 px ellipses 18-103 px from a
/// 22-30 px disc. None of them is now a wrong answer: the drogue-free
/// frames give none, the drogue frames none or the disc (the glare
/// streak's, since a rim mostly under a glare is looked at again, is found
/// as the disc: `a_disc_mostly_under_a_glare_streak_is_found_from_the_rest_of_its_rim`);
/// no right answer was lost (the smallest right one is 11.5 px wide).
#[test]
fn a_candidate_too_thin_for_its_canopy_to_be_judged_is_no_drogue() {
    let mut found = detections_on("no drogue: crescent", &[(3, 1), (16, 8)]);
    found.extend(detections_on("no drogue: ring without canopy", &[(6, 24)]));
    found.extend(detections_on("no drogue: stars, flowers", &[(24, 28)]));
    found.extend(frames_not_the_disc(
        "motion blur 32 px",
        &[(4, 11, false), (12, 27, false)],
    ));
    found.extend(everything_frames_not_the_disc(&[(6, 21, false)]));
    found.extend(frames_not_the_disc(
        "glare streak 30 px wide",
        &[(23, 15, false)],
    ));
    assert!(found.is_empty(), "{found:#?}");
}
