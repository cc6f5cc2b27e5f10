//! The full-frame search: the candidates of both sources (dark regions
//! and edge voting), their seeds, the budget and order in which they are
//! verified, and the inner disc preferred to the canopy's rim.

use super::canopy;
use super::coarse::{self, Blob};
use super::edges::EdgeCircle;
use super::{Detector, Reject, SATURATED_LEVEL, Verified};
use crate::measure::ellipse::Ellipse;
use image::GrayImage;
use std::cmp::Reverse;

/// Wide-pass reach of seeds whose radius is not a rim's (the deepest
/// point's inscribed circle, the point ringed by light, an edge-voting
/// peak, whose radius comes from whatever edges voted for it), in their
/// radii.
const UNSURE_SEED_REACH: f64 = 5.0;

/// An inner disc (see [`Detector::prefer_inner_disc`]) is within this share
/// of `r / R` of its outer ellipse's size, its centre within this many of
/// its radii of the outer's, and its rim step at least this share of the
/// outer's.
const INNER_SIZE_TOLERANCE: f64 = 0.25;
const INNER_OFFSET_RADII: f64 = 0.3;
const INNER_CONTRAST_SHARE: f64 = 0.5;
/// The inner disc's rays reach this share of the outer ellipse's radius.
const INNER_REACH_OUTER_RADII: f64 = 0.8;

/// Random stream of an inner-disc seed, apart from its outer seed's.
const INNER_SEED_STREAM: u64 = 0x1_0000;

/// Kind of the seed of the disc inside an edge circle that did not verify
/// ([`Detector::disc_inside`]).
const KIND_INSIDE_EDGE_CIRCLE: u8 = 10;

/// Circles of the edge source verified per frame, strongest first.
const EDGE_SEEDS: usize = 4;
/// Circles the edge source gives around its first ones once their rims are
/// taken out ([`super::edges::EdgeVoter::nested`]), tried when no candidate
/// verified at all.
const NESTED_SEEDS: usize = 2;
/// A first ray pass that looks for an edge circle's own rim, past whatever
/// lies inside it, starts at this share of its radius and reaches this
/// many radii: the radius is measured from the circle's own rim (to a
/// decimated pixel or two). A nested circle's inside is the smaller
/// circle's rim, tried before; a disc's can be the probe's tip.
const OWN_RIM_FROM: f64 = 0.5;
const OWN_RIM_REACH: f64 = 2.0;

/// Regions of the locally normalised frame verified per frame (over all
/// its windows), whole and round ones first, then larger first.
const LOCAL_REGIONS: usize = 4;
/// A pixel belongs to a dark region of the locally normalised frame at
/// this many standard deviations below its neighbourhood's mean.
const LOCAL_DARK_SIGMAS: f64 = 1.0;
/// The local deviation's floor, as a share of the smallest rim step
/// (`min_contrast_gray`): in flat sky a pixel must be this far below the
/// mean besides, so that noise does not make regions.
const LOCAL_FLOOR_CONTRAST: f64 = 0.25;
/// A candidate whose canopy rim shows along at least this share of where
/// its pose puts it is the drogue, whatever part of its own rim a probe or
/// hose hides: it ends the search as a score of `accept` does. Over the
/// simulator's sweep (seeds 1-4, 30 frames a level: 6,000 frames, 10,800
/// candidates verified) no candidate but the disc showed more than 0.65.
pub(super) const CANOPY_CONFIRMS: f64 = 0.8;

/// Whether a verified candidate ends the search: it scores `accept`, or
/// its canopy confirms it ([`CANOPY_CONFIRMS`]); nothing less does.
fn ends_search(v: &Verified, accept: f64) -> bool {
    v.score >= accept || v.canopy.is_some_and(|c| c >= CANOPY_CONFIRMS)
}

/// Whether `inner` lies where the disc inside `outer` (its canopy's outer
/// rim) must: its size within [`INNER_SIZE_TOLERANCE`] of `ratio` (`r /
/// R`) of `outer`'s, its centre within [`INNER_OFFSET_RADII`] of its
/// radius of `outer`'s.
fn nested_disc(inner: &Ellipse, outer: &Ellipse, ratio: f64) -> bool {
    let size = inner.a / outer.a;
    let offset = (inner.cx - outer.cx).hypot(inner.cy - outer.cy);
    (size - ratio).abs() <= INNER_SIZE_TOLERANCE * ratio && offset <= INNER_OFFSET_RADII * inner.a
}

fn any_accepted(verified: &[Verified], accept: f64) -> bool {
    verified.iter().any(|v| ends_search(v, accept))
}

/// Kinds of the local source's seeds: its regions' kinds 0-2 plus this.
const LOCAL_KIND_OFFSET: u8 = 5;
/// A region of a window is a disc of that window's sizes when its
/// moment radius is from this share of the window's smallest disc radius
/// to this many of its largest (a disc merged with a probe is longer).
const LOCAL_MIN_RADIUS_SHARE: f64 = 0.5;
const LOCAL_MAX_RADIUS_SHARE: f64 = 1.5;

/// How the edge source's circles are tried: the first ray pass's reach and
/// start (multiples of the radius), the seeds' kind, and the first of their
/// random streams (one per circle, by its place in the list).
#[derive(Clone, Copy)]
struct EdgeSeeds {
    reach: f64,
    from: f64,
    kind: u8,
    stream: u64,
}

/// Where and how large a coarse candidate is, full-res distorted pixels.
#[derive(Clone, Debug)]
pub(super) struct Seed {
    pub(super) centre_px: [f64; 2],
    pub(super) a_px: f64,
    pub(super) b_px: f64,
    pub(super) theta: f64,
    /// How far the first ray pass looks, in multiples of the seed's radius.
    pub(super) reach: f64,
    /// Where the first ray pass starts, in multiples of the seed's radius
    /// (0: at the centre).
    pub(super) from: f64,
    /// Which point of its blob: 0 the centroid, 1 the deepest point, 2 the
    /// point best ringed by light; 3 a circle of the edge source; 4 the
    /// disc looked for inside a verified ellipse (see
    /// [`Detector::prefer_inner_disc`]); 5-7 as 0-2, of a region of the
    /// locally normalised frame ([`Detector::try_local_contrast`]); 8 a
    /// circle of the edge source nested with a stronger one; 9 a circle of
    /// the edge source looked for past what lies inside it; 10 the disc
    /// looked for inside a circle of the edge source that did not verify
    /// as the disc (see [`Detector::disc_inside`]).
    pub(super) kind: u8,
}

impl Seed {
    /// Nearly the same seed: centres within a tenth of the smaller radius,
    /// axes within 10 %, the same reach, and (unless both are near-circles)
    /// the same orientation within 0.1 rad.
    fn same_as(&self, other: &Seed) -> bool {
        let close = |x: f64, y: f64| (x / y - 1.0).abs() <= 0.1;
        let r = self.b_px.min(other.b_px);
        let d =
            (self.centre_px[0] - other.centre_px[0]).hypot(self.centre_px[1] - other.centre_px[1]);
        let round = |s: &Seed| s.a_px <= 1.1 * s.b_px;
        let dtheta = (self.theta - other.theta).rem_euclid(std::f64::consts::PI);
        let aligned = dtheta.min(std::f64::consts::PI - dtheta) <= 0.1;
        self.reach == other.reach
            && d <= 0.1 * r
            && close(self.a_px, other.a_px)
            && close(self.b_px, other.b_px)
            && ((round(self) && round(other)) || aligned)
    }
}

/// A dark region's seeds, in the order tried: the centroid with the moment
/// ellipse, the deepest point with its inscribed circle (on the disc even
/// when a hose or probe has merged with it) and the point best ringed by
/// light, each when apart from the ones before. A region that is cut by the
/// border or elongated (`round` false) is mostly not a disc: its centroid
/// lies off any disc in it, the point ringed by light is the likeliest disc
/// centre, then the deepest point. Kinds 0-2 plus `kind_offset`.
fn region_seeds(b: &Blob, round: bool, kind_offset: u8) -> Vec<Seed> {
    let mut seeds = vec![Seed {
        centre_px: b.centre_px,
        a_px: b.a_px,
        b_px: b.b_px,
        theta: b.theta,
        reach: 1.8,
        from: 0.0,
        kind: kind_offset,
    }];
    let off = (b.core_px[0] - b.centre_px[0]).hypot(b.core_px[1] - b.centre_px[1]);
    if off > 0.3 * b.core_radius_px {
        seeds.push(Seed {
            centre_px: b.core_px,
            a_px: b.core_radius_px,
            b_px: b.core_radius_px,
            theta: 0.0,
            reach: UNSURE_SEED_REACH,
            from: 0.0,
            kind: kind_offset + 1,
        });
    }
    let off = (b.ringed_px[0] - b.centre_px[0]).hypot(b.ringed_px[1] - b.centre_px[1]);
    let off_core = (b.ringed_px[0] - b.core_px[0]).hypot(b.ringed_px[1] - b.core_px[1]);
    if b.ringed_light >= 0.5
        && off > 0.3 * b.ringed_radius_px
        && off_core > 0.3 * b.ringed_radius_px
    {
        seeds.push(Seed {
            centre_px: b.ringed_px,
            a_px: b.ringed_radius_px,
            b_px: b.ringed_radius_px,
            theta: 0.0,
            reach: UNSURE_SEED_REACH,
            from: 0.0,
            kind: kind_offset + 2,
        });
    }
    if !round {
        seeds.reverse();
    }
    seeds
}

/// The blobs of up to `budget` regions of `blobs` (sorted by region, larger
/// regions first), from index `from`: each region's largest part at each
/// threshold. Returns their indices and the index where the next region
/// begins.
fn select_regions(blobs: &[Blob], from: usize, budget: usize) -> (Vec<usize>, usize) {
    let mut selected: Vec<usize> = Vec::new();
    let mut regions = 0usize;
    for i in from..blobs.len() {
        let b = &blobs[i];
        let new_region = i == from || blobs[i - 1].region != b.region;
        if new_region {
            if regions >= budget {
                return (selected, i);
            }
            regions += 1;
        }
        let same_region = |k: &usize| blobs[*k].region == b.region;
        if selected
            .iter()
            .rev()
            .take_while(|k| same_region(k))
            .any(|&k| blobs[k].level == b.level)
        {
            continue;
        }
        selected.push(i);
    }
    (selected, blobs.len())
}

impl Detector {
    /// The candidates of all three sources, verified on the sparse rim, in the
    /// order tried; the search ends at the first that scores `accept` or
    /// that its canopy confirms ([`ends_search`]).
    pub(super) fn verify_candidates(&mut self, image: &GrayImage, accept: f64) -> Vec<Verified> {
        // The dark regions and the edges are both found on the decimated
        // frame.
        self.decimated
            .update(image, self.cfg.decimation.clamp(1, 16) as usize);
        let mut verified: Vec<Verified> = Vec::new();
        let mut tried: Vec<Seed> = Vec::new();
        let regions = self.try_dark_regions(image, accept, &mut tried, &mut verified);
        // The edge source, when the dark regions gave no clear drogue: a
        // disc merged with the hose, probe or a glare streak, or washed out
        // by haze, still has its rim.
        if !any_accepted(&verified, accept) {
            self.try_edge_source(image, accept, &mut tried, &mut verified);
        }
        // The third source, when neither gave a clear drogue and a glare
        // saturates part of the frame: dark regions relative to their own
        // neighbourhood (a disc that a glare's glow lifted above every
        // global threshold, its rim's steps running into the saturated
        // canopy, which the edge source takes for the glare's skirt).
        // Without a glare it is not tried: on the drogue-free reference
        // frames it found nothing and added three fifths to the search.
        // Nor where a candidate already shows its canopy rim beyond doubt:
        // that is the drogue, and the disc this source is for is one that
        // nothing else found.
        if self.cfg.local_contrast_source
            && !any_accepted(&verified, accept)
            && !verified.iter().any(|v| self.canopy_shown(v))
            && self.decimated.any_at_least(SATURATED_LEVEL)
        {
            self.try_local_contrast(image, accept, &mut tried, &mut verified);
        }
        tracing::debug!(
            regions = regions,
            seeds = tried.len(),
            verified = verified.len(),
            best = ?verified.iter().map(|v| v.score).max_by(f64::total_cmp),
            "full-frame search"
        );
        verified
    }

    /// The first source: the dark regions of the decimated frame at the
    /// configured thresholds, seeded within a budget of regions (below),
    /// until a candidate scores `accept` or its canopy confirms it. Seeds
    /// go into `tried`, candidates that verify into `verified`; returns how
    /// many regions were tried.
    fn try_dark_regions(
        &mut self,
        image: &GrayImage,
        accept: f64,
        tried: &mut Vec<Seed>,
        verified: &mut Vec<Verified>,
    ) -> usize {
        let f = self.decimated.factor as f64;
        // Smallest disc: a third of its area must make dark blocks.
        let min_area = ((std::f64::consts::PI * (self.min_radius_px / f).powi(2)) / 3.0)
            .floor()
            .max(2.0) as usize;
        let mut blobs = std::mem::take(&mut self.blobs);
        self.finder.find(
            &self.decimated,
            &self.cfg.threshold_fractions,
            min_area,
            self.cfg.min_contrast_gray,
            &mut blobs,
        );
        blobs.retain(|b| b.a_px >= 0.5 * self.min_radius_px && b.b_px >= 0.5);
        // The budget of candidates counts distinct dark regions (at the
        // highest threshold; the lower thresholds' regions are their parts),
        // larger first: small ones are mostly noise and thin shapes. A large
        // region broken into many parts (a shaded probe) must not use up the
        // budget before a small disc elsewhere in the frame is tried.
        // Within a region, its largest part at each threshold is tried.
        blobs.sort_by(|x, y| {
            y.region_area
                .cmp(&x.region_area)
                .then(x.region.cmp(&y.region))
                .then(y.area.cmp(&x.area))
        });
        // The budget: the regions, and within each its largest part at
        // each threshold. The regions whose rays find no step at all
        // (a vignetted corner, a cloud's soft shadow: every seed `NoRim`)
        // are no candidates: they give their places to the next regions in
        // size order (below), so that such regions cannot use up the
        // budget before a disc (or the part of it a glare streak leaves) is
        // tried.
        let mut kept: Vec<Blob> = Vec::new();
        let mut regions = 0usize;
        let (mut from, mut budget, mut offset) = (0, self.cfg.max_candidates as usize, 0);
        'batches: while budget > 0 {
            let (selected, next) = select_regions(&blobs, from, budget);
            if selected.is_empty() {
                break;
            }
            from = next;
            let mut batch: Vec<u32> = selected.iter().map(|&i| blobs[i].region).collect();
            batch.dedup();
            regions += batch.len();
            // Verified in order of how disc-like their moments are (whole
            // and round first, the rest as they were), so that a clear view
            // of the drogue ends the search before the probe and hose are
            // looked at. The stable sort keeps the size order within each
            // group.
            let round: Vec<bool> = selected
                .iter()
                .map(|&i| blobs[i].whole_and_round(&self.decimated, self.cfg.min_axis_ratio))
                .collect();
            let mut order: Vec<usize> = (0..selected.len()).collect();
            order.sort_by_key(|&k| !round[k]);
            let mut with_rim: Vec<u32> = Vec::new();
            for &k in &order {
                let index = selected[k];
                // The deepest and best-ringed points cost a distance
                // transform of the region: only for the blobs that get this
                // far.
                self.finder
                    .describe_core(&self.decimated, &mut blobs[index]);
                let b = &blobs[index];
                // Drop near-duplicates (the same region at several thresholds).
                let dup = kept.iter().any(|k| {
                    let near =
                        |p: [f64; 2], q: [f64; 2], r: f64| (p[0] - q[0]).hypot(p[1] - q[1]) < r;
                    let r = 0.25 * k.b_px.min(b.b_px);
                    near(k.centre_px, b.centre_px, r)
                        && near(k.core_px, b.core_px, r)
                        && near(k.ringed_px, b.ringed_px, r)
                        && (k.a_px / b.a_px - 1.0).abs() < 0.25
                });
                if dup {
                    continue;
                }
                kept.push(b.clone());
                let region = b.region;
                let seeds = region_seeds(b, round[k], 0);
                for seed in &seeds {
                    // The same region at another threshold often gives
                    // nearly the same seed: its rays would find the same
                    // edges.
                    if tried.iter().any(|t| t.same_as(seed)) {
                        continue;
                    }
                    tried.push(seed.clone());
                    // The seed's random stream is fixed by its blob's place
                    // in the size order and its kind, not by the order of
                    // trying.
                    let stream = 3 * (offset + k) as u64 + seed.kind as u64;
                    match self.try_seed(image, seed, stream, accept, verified) {
                        Ok(true) => break 'batches,
                        Err(Reject::NoRim(_)) => {}
                        _ => {
                            if !with_rim.contains(&region) {
                                with_rim.push(region);
                            }
                        }
                    }
                }
            }
            offset += selected.len();
            // The places of the regions without a rim go to the next
            // regions, batch after batch: a region whose rays meet no step
            // is no chance of a wrong candidate, and the regions with a rim
            // stay within `max_candidates` (each batch is as large as the
            // last one's regions without a rim).
            budget = batch.len() - with_rim.len();
        }
        self.blobs = blobs;
        regions
    }

    /// The second source: the edge voter's circles, tried as seeds in
    /// three ways until one scores `accept` (seeds tried before skipped).
    fn try_edge_source(
        &mut self,
        image: &GrayImage,
        accept: f64,
        tried: &mut Vec<Seed>,
        verified: &mut Vec<Verified>,
    ) {
        let circles = self.voter.find(
            &self.decimated,
            self.cfg.min_contrast_gray,
            self.min_radius_px,
            self.max_radius_px,
            EDGE_SEEDS,
        );
        let first = EdgeSeeds {
            reach: UNSURE_SEED_REACH,
            from: 0.0,
            kind: 3,
            stream: 1000,
        };
        let mut rings = self.try_edge_circles(image, &circles, first, accept, tried, verified);
        // Circles nested with those (the disc around the probe's tip),
        // when still no candidate scored `accept`: their first pass
        // starts inside their own rim, so that it does not take the
        // smaller circle's rim again. A weaker candidate verified
        // before (the probe's tip, a small dark spot judged without
        // its canopy) does not stop them: the best score is the answer.
        if !any_accepted(verified, accept) {
            let nested = self.voter.nested(&self.decimated, &circles, NESTED_SEEDS);
            let around = EdgeSeeds {
                reach: OWN_RIM_REACH,
                from: OWN_RIM_FROM,
                kind: 8,
                stream: 1500,
            };
            rings.extend(self.try_edge_circles(image, &nested, around, accept, tried, verified));
        }
        // The first circles again, their first pass starting past
        // what lies inside them, when still none scored `accept`: the
        // probe's tip over the middle of a hazed disc is darker than
        // the disc, its outline the strongest step from any point
        // inside, and the tip is dropped as a circle inside a larger
        // dark shape ([`super::Reject::Nested`]).
        if !any_accepted(verified, accept) {
            let past_inside = EdgeSeeds {
                reach: OWN_RIM_REACH,
                from: OWN_RIM_FROM,
                kind: 9,
                stream: 1700,
            };
            rings.extend(self.try_edge_circles(
                image,
                &circles,
                past_inside,
                accept,
                tried,
                verified,
            ));
        }
        // Last, the disc inside each circle that was a ring or showed no
        // canopy, when still none scored `accept`.
        if !any_accepted(verified, accept) {
            self.try_discs_inside(image, &rings, accept, tried, verified);
        }
    }

    /// Tries the edge source's `circles` as seeds of `how`, strongest
    /// first, until one scores `accept`; seeds tried before are skipped.
    /// Gives the seeds (with their random streams) that verified as a ring
    /// or without a canopy, for [`Self::try_discs_inside`].
    fn try_edge_circles(
        &mut self,
        image: &GrayImage,
        circles: &[EdgeCircle],
        how: EdgeSeeds,
        accept: f64,
        tried: &mut Vec<Seed>,
        verified: &mut Vec<Verified>,
    ) -> Vec<(Seed, u64)> {
        let mut rings = Vec::new();
        for (i, c) in circles.iter().enumerate() {
            let seed = Seed {
                centre_px: c.centre_px,
                a_px: c.radius_px,
                b_px: c.radius_px,
                theta: 0.0,
                reach: how.reach,
                from: how.from,
                kind: how.kind,
            };
            if tried.iter().any(|t| t.same_as(&seed)) {
                continue;
            }
            tried.push(seed.clone());
            tracing::debug!(strength = c.strength, kind = how.kind, "edge source circle");
            let index = how.stream + i as u64;
            match self.try_seed(image, &seed, index, accept, verified) {
                Ok(true) => break,
                // A ring (light inside), or a circle whose predicted canopy
                // does not show: it may be the canopy's own rim band.
                Err(Reject::NoCanopy(_) | Reject::LightInside(_)) => rings.push((seed, index)),
                _ => {}
            }
        }
        rings
    }

    /// The discs inside the edge source's `rings` (seeds with their random
    /// streams), tried as seeds ([`Self::disc_inside`]) until one scores
    /// `accept`. A saturated glare streak across the disc leaves two dark
    /// slivers of it, and the canopy's rim band, whole but for the streak's
    /// width, is then the frame's roundest dark edge: its circle takes the
    /// disc's votes with its own (one centre), and verified as the disc it
    /// shows no canopy beyond it. Cold: only frames where nothing else
    /// verified get here.
    #[cold]
    fn try_discs_inside(
        &mut self,
        image: &GrayImage,
        rings: &[(Seed, u64)],
        accept: f64,
        tried: &mut Vec<Seed>,
        verified: &mut Vec<Verified>,
    ) {
        for (ring, index) in rings {
            let Some(inner) = self
                .disc_inside(ring, KIND_INSIDE_EDGE_CIRCLE)
                .filter(|s| s.b_px >= self.min_radius_px)
            else {
                continue;
            };
            if tried.iter().any(|t| t.same_as(&inner)) {
                continue;
            }
            tried.push(inner.clone());
            let stream = index ^ INNER_SEED_STREAM;
            if self.try_seed(image, &inner, stream, accept, verified) == Ok(true) {
                break;
            }
        }
    }

    /// Whether a block of the decimated frame within the canopy's reach of
    /// region `b` (its centre, `R / r` times its major semi-axis and two
    /// blocks more each way) averages `SATURATED_LEVEL` or more.
    fn glare_within_canopy(&self, b: &Blob) -> bool {
        let dec = &self.decimated;
        let f = dec.factor.max(1) as f64;
        let ratio = self.disc_share().map_or(1.0, |share| 1.0 / share);
        let reach = ratio * b.a_px / f + 2.0;
        let (cx, cy) = (b.centre_px[0] / f, b.centre_px[1] / f);
        let span = |c: f64, n: usize| {
            let hi = ((c + reach).ceil().max(0.0) as usize).min(n);
            let lo = ((c - reach).floor().max(0.0) as usize).min(hi);
            lo..hi
        };
        let (xs, ys) = (span(cx, dec.width), span(cy, dec.height));
        ys.into_iter().any(|y| {
            dec.pixels[y * dec.width..][xs.clone()]
                .iter()
                .any(|&p| p >= SATURATED_LEVEL)
        })
    }

    /// The disc's size as a share of the canopy rim's, `r / R`, when it is
    /// one (a configuration may give no canopy larger than the disc).
    fn disc_share(&self) -> Option<f64> {
        let ratio = self.drogue.inner_radius_m / self.drogue.canopy_radius_m;
        (ratio.is_finite() && ratio > 0.0 && ratio < 1.0).then_some(ratio)
    }

    /// The seed of the disc concentric inside `outer` at `r / R` of its
    /// size, as `kind`, for where `outer` may be the canopy's outer rim
    /// (under haze or a glare its step to the sky can be the strongest
    /// round one): its first ray pass looks from the centre out to well
    /// inside the outer rim ([`INNER_REACH_OUTER_RADII`]), where the disc's
    /// step is the strongest rise. `None` without a share `r / R`
    /// ([`Self::disc_share`]).
    fn disc_inside(&self, outer: &Seed, kind: u8) -> Option<Seed> {
        let ratio = self.disc_share()?;
        Some(Seed {
            centre_px: outer.centre_px,
            a_px: outer.a_px * ratio,
            b_px: outer.b_px * ratio,
            theta: outer.theta,
            // The wide pass reaches `reach * r + 4` px (r the seed's radius).
            reach: ((INNER_REACH_OUTER_RADII * outer.b_px - 4.0) / (ratio * outer.b_px)).max(1.0),
            from: 0.0,
            kind,
        })
    }

    /// The local-contrast source ([`coarse::LocalContrast`]): in each of the
    /// windows for the disc sizes searched, the regions darker than their
    /// neighbourhood by [`LOCAL_DARK_SIGMAS`] whose size is a disc's of that
    /// window; [`LOCAL_REGIONS`] of them (whole and round first, then
    /// larger), their seeds tried as a dark region's are.
    pub(super) fn try_local_contrast(
        &mut self,
        image: &GrayImage,
        accept: f64,
        tried: &mut Vec<Seed>,
        verified: &mut Vec<Verified>,
    ) {
        let dec = &self.decimated;
        let f = dec.factor as f64;
        let sides = coarse::window_sides(
            self.min_radius_px / f,
            self.max_radius_px / f,
            dec.width.min(dec.height),
        );
        if sides.is_empty() {
            return;
        }
        self.local.prepare(dec);
        let floor = LOCAL_FLOOR_CONTRAST * self.cfg.min_contrast_gray;
        let mut blobs = std::mem::take(&mut self.blobs);
        // Each window's disc-sized regions, described while its labels are
        // the finder's, with whether they are whole and round.
        let mut regions: Vec<(bool, Blob)> = Vec::new();
        for &(side, r) in &sides {
            self.local.dark_mask(side, floor, LOCAL_DARK_SIGMAS);
            let mask = &self.local.mask;
            let min_area = ((std::f64::consts::PI * r * r) / 3.0).floor().max(2.0) as usize;
            self.local_finder.find_below(
                mask,
                &[coarse::LOCAL_MASK_THRESHOLD],
                min_area,
                &mut blobs,
            );
            let (r_min, r_max) = (
                LOCAL_MIN_RADIUS_SHARE * r * f,
                LOCAL_MAX_RADIUS_SHARE * coarse::LOCAL_RADIUS_RATIO * r * f,
            );
            for b in &mut blobs {
                let radius = (b.a_px * b.b_px).sqrt();
                if !(r_min..=r_max).contains(&radius) {
                    continue;
                }
                self.local_finder.describe_core(mask, b);
                let round = b.whole_and_round(mask, self.cfg.min_axis_ratio);
                regions.push((round, b.clone()));
            }
        }
        self.blobs = blobs;
        // The disc this source is for lies in a glare's glow, its canopy
        // saturated: the regions with a saturated block within their
        // canopy's reach first (the sky beyond the glow makes larger dark
        // patches), then whole and round ones, then larger ones.
        regions.sort_by_cached_key(|(round, b)| {
            Reverse((self.glare_within_canopy(b), *round, b.area))
        });
        let mut taken: Vec<&Blob> = Vec::new();
        'regions: for (i, (round, b)) in regions.iter().enumerate() {
            if taken.len() >= LOCAL_REGIONS {
                break;
            }
            // The same dark patch in two windows: centres within the
            // smaller one's minor radius.
            if taken.iter().any(|t| {
                let r = t.b_px.min(b.b_px);
                (t.centre_px[0] - b.centre_px[0]).hypot(t.centre_px[1] - b.centre_px[1]) < r
            }) {
                continue;
            }
            taken.push(b);
            for seed in region_seeds(b, *round, LOCAL_KIND_OFFSET) {
                if tried.iter().any(|t| t.same_as(&seed)) {
                    continue;
                }
                tried.push(seed.clone());
                let index = 2000 + 3 * i as u64 + u64::from(seed.kind - LOCAL_KIND_OFFSET);
                if self.try_seed(image, &seed, index, accept, verified) == Ok(true) {
                    break 'regions;
                }
            }
        }
    }

    /// Verifies a seed (its random stream `index`), keeps it in `verified`
    /// when it passes, and says whether it ends the search
    /// ([`ends_search`]), or why it did not pass. A seed inside a candidate
    /// its canopy shows ([`Self::within_shown_canopy`]) is not verified:
    /// [`Reject::Known`], and not counted as a candidate tried.
    fn try_seed(
        &mut self,
        image: &GrayImage,
        seed: &Seed,
        index: u64,
        accept: f64,
        verified: &mut Vec<Verified>,
    ) -> Result<bool, Reject> {
        if let Some(shown) = verified.iter().find(|v| self.within_shown_canopy(v, seed)) {
            tracing::debug!(
                centre_px = ?[seed.centre_px[0].round(), seed.centre_px[1].round()],
                kind = seed.kind,
                drogue_px = ?[shown.ellipse.cx.round(), shown.ellipse.cy.round()],
                "inside the canopy of a candidate verified with it: not tried"
            );
            return Err(Reject::Known);
        }
        let r = self.verify_seed(image, seed, index, verified);
        tracing::debug!(
            centre_px = ?[seed.centre_px[0].round(), seed.centre_px[1].round()],
            radius_px = seed.a_px.round(),
            kind = seed.kind,
            result = ?r.as_ref().map(|v| (v.score, v.canopy)),
            "candidate"
        );
        let kept = r.and_then(|v| {
            let v = self.prefer_inner_disc(image, v, index);
            // Verification by the drogue's structure: a candidate too thin
            // for its canopy rim to be judged along its minor axis rests on
            // its darkness alone.
            let minor_px = v.ellipse.a.min(v.ellipse.b);
            if minor_px < canopy::smallest_judged_radius_px(self.drogue) {
                tracing::debug!(
                    centre_px = ?[v.ellipse.cx.round(), v.ellipse.cy.round()],
                    minor_px,
                    "too thin for its canopy rim to be judged: not the drogue"
                );
                return Err(Reject::TooSmall(minor_px));
            }
            Ok(v)
        });
        self.misses
            .tried(kept.as_ref().map(|_| ()).map_err(|why| *why));
        let v = kept?;
        let ends = ends_search(&v, accept);
        verified.push(v);
        Ok(ends)
    }

    /// Whether `seed`'s centre lies inside the canopy's outer rim of `candidate`,
    /// a candidate that verified with its canopy shown beyond doubt
    /// ([`canopy::shown_beyond_doubt`] of `min_canopy_fraction`): a seed
    /// there is that drogue's own disc, probe, hose or canopy, and whatever
    /// it verifies as is that drogue again. Not trying it spares a frame
    /// the wide pass, fits and evidence of every such seed (most of a found
    /// drogue's search when its score stays below `accept_score`). A
    /// candidate whose canopy share is within the doubt does not: its
    /// ellipse may have taken in the probe's outline, and a seed inside it
    /// gives the rim. The canopy's rim is
    /// [`canopy::DrogueCircles::canopy_rim_around`] the candidate's ellipse.
    pub(super) fn within_shown_canopy(&self, candidate: &Verified, seed: &Seed) -> bool {
        if !self.canopy_shown(candidate) {
            return false;
        }
        // The seed's centre, undistorted pixels, as the ellipse is.
        let [u, v] = self.camera.undistort_px(seed.centre_px);
        self.drogue
            .canopy_rim_around(&candidate.ellipse)
            .contains(u, v)
    }

    /// Whether `candidate` verified with its canopy rim shown beyond the
    /// doubt of reading it ([`canopy::shown_beyond_doubt`] of
    /// `min_canopy_fraction`).
    pub(super) fn canopy_shown(&self, candidate: &Verified) -> bool {
        let needed = self.cfg.min_canopy_fraction;
        candidate
            .canopy
            .is_some_and(|shown| canopy::shown_beyond_doubt(shown, needed))
    }

    /// The disc inside `outer` (undistorted), a settled rim whose own
    /// canopy did not show: where that rim is the canopy's outer rim, the
    /// disc is concentric inside it at `r / R` of its size, and narrow
    /// passes there find the parts of its rim a glare streak leaves. Kept
    /// only when it settles nested in `outer` ([`INNER_SIZE_TOLERANCE`],
    /// [`INNER_OFFSET_RADII`]) with its canopy judged and shown: the rim it
    /// predicts is `outer`'s.
    pub(super) fn disc_inside_rim(
        &mut self,
        image: &GrayImage,
        outer: &Ellipse,
    ) -> Option<Verified> {
        let ratio = self.disc_share()?;
        let predicted = outer.scaled(ratio);
        if !self.plausible(&predicted, 1.0) {
            return None;
        }
        let inner = self.verify_as_scout(image, &predicted).ok()?;
        let nested = nested_disc(&inner.ellipse, outer, ratio);
        let shown = inner
            .canopy
            .is_some_and(|c| c >= self.cfg.min_canopy_fraction);
        tracing::debug!(
            outer_axes_px = ?[outer.a.round(), outer.b.round()],
            inner_axes_px = ?[inner.ellipse.a.round(), inner.ellipse.b.round()],
            nested,
            canopy = ?inner.canopy,
            "disc inside a rim without a canopy"
        );
        (nested && shown).then_some(inner)
    }

    /// The canopy's outer rim taken for the disc (under haze its step to
    /// the sky can be the strongest on every ray) has the disc inside it,
    /// concentric, at `r / R` of its size. When that inner ellipse verifies
    /// as a rim of its own (narrow passes where it must be, else a wide
    /// pass from the centre), with a step of comparable contrast and its
    /// canopy shown better than the outer rim's, it is the disc. Inside a
    /// true disc there is no such rim: the shading of its inside gives
    /// steps far weaker than its rim's, and the probe's end seen there
    /// predicts a canopy on the disc's own.
    pub(super) fn prefer_inner_disc(
        &mut self,
        image: &GrayImage,
        outer: Verified,
        index: u64,
    ) -> Verified {
        let e = outer.ellipse;
        // The verified ellipse where a seed would be: its centre in the
        // frame's (distorted) pixels, as seeds are; its own reach and kind
        // are not used, the disc inside it gets its own.
        let as_seed = Seed {
            centre_px: self.camera.distort_px([e.cx, e.cy]),
            a_px: e.a,
            b_px: e.b,
            theta: e.theta,
            reach: 1.0,
            from: 0.0,
            kind: 4,
        };
        let (Some(ratio), Some(seed)) = (self.disc_share(), self.disc_inside(&as_seed, 4)) else {
            return outer;
        };
        // First the narrow passes where the disc must be, concentric at
        // `r / R` of the outer rim: their window (a tenth of the radius)
        // holds the disc's own step, where the wide pass's strongest rise
        // can be the outline of the probe over the disc (nearer, so darker
        // under haze than the disc is).
        let predicted = e.scaled(ratio);
        let narrow = self.verify_as_scout(image, &predicted);
        if let Err(why) = &narrow {
            tracing::debug!(?why, "no inner disc where predicted: the wide pass");
        }
        let inner = match narrow
            .or_else(|_| self.verify_seed(image, &seed, index ^ INNER_SEED_STREAM, &[]))
        {
            Ok(inner) => inner,
            Err(why) => {
                tracing::debug!(outer_axes_px = ?[e.a.round(), e.b.round()], ?why, "no inner disc");
                return outer;
            }
        };
        let nested = nested_disc(&inner.ellipse, &e, ratio);
        let strong = inner.rim_contrast >= INNER_CONTRAST_SHARE * outer.rim_contrast;
        tracing::debug!(
            outer_axes_px = ?[e.a.round(), e.b.round()],
            inner_axes_px = ?[inner.ellipse.a.round(), inner.ellipse.b.round()],
            nested,
            inner_contrast = inner.rim_contrast,
            outer_contrast = outer.rim_contrast,
            "inner disc"
        );
        // The two nested rims each predict where the canopy's rim is: the
        // inner one is kept only when the frame shows its canopy better
        // (the probe's tip inside a hazed disc is nested and strong too,
        // but its predicted canopy falls on the disc's own canopy).
        let better_canopy = match (inner.canopy, outer.canopy) {
            (Some(i), Some(o)) => i > o,
            _ => true,
        };
        if nested && strong && better_canopy {
            inner
        } else {
            outer
        }
    }
}
