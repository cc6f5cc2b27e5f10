//! Detector tests on synthetic frames with exact truth: an anti-aliased dark
//! ellipse inside a light canopy with a darker outer band, on a sky gradient,
//! with sensor noise, optional blur, and occluders.

use super::*;
use crate::config::Config;
use image::Luma;
use nalgebra::Matrix3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use verify::{MAX_WIDEN, WIDEN_STEP};

fn camera(w: u32, h: u32) -> CameraModel {
    let k = Matrix3::new(
        1336.2,
        0.0,
        w as f64 / 2.0,
        0.0,
        1335.4,
        h as f64 / 2.0,
        0.0,
        0.0,
        1.0,
    );
    CameraModel::new("test", w, h, k, [0.0; 5]).unwrap()
}

fn detector(cam: &CameraModel) -> Detector {
    crate::testing::detector(&Config::embedded(), cam)
}

/// Implicit "radius" of a point in an ellipse's frame: 1 on the ellipse.
fn ellipse_level(e: &Ellipse, u: f64, v: f64) -> f64 {
    let (s, c) = e.theta.sin_cos();
    let (du, dv) = (u - e.cx, v - e.cy);
    let (x, y) = (c * du + s * dv, -s * du + c * dv);
    ((x / e.a).powi(2) + (y / e.b).powi(2)).sqrt()
}

/// A scene: returns the reflectance-like gray level at a point.
struct Scene {
    disc: Ellipse,
    disc_level: f64,
    canopy_level: f64,
    band_level: f64,
    /// Outer band from 2.1 to 2.2 times the disc (the canopy rim).
    with_canopy: bool,
    /// Occluding bar (probe): from `bar_from` toward +v (down), half-width.
    bar: Option<([f64; 2], f64, f64)>,
    rects: Vec<[f64; 4]>,
    /// Dark rectangles [u0, v0, u1, v1] with their own gray level.
    patches: Vec<([f64; 4], f64)>,
    /// Hose: from `from` toward -v (up), length, half-width, level; in front.
    hose: Option<([f64; 2], f64, f64, f64)>,
    /// A light disc (centre, radius) in front of the dark one: with it the
    /// dark disc is a crescent.
    bite: Option<([f64; 2], f64)>,
    /// Sky level at the top of the frame (it brightens by 0.03 a row).
    sky_level: f64,
    /// A dark circle (centre, radius, level) in front of the disc: the
    /// probe's tip.
    tip: Option<([f64; 2], f64, f64)>,
    /// The canopy's throat shadow: the share of its level lost at the
    /// disc's edge, and its e-folding width in disc radii.
    throat_shadow: Option<(f64, f64)>,
    /// Dark spots (centre, radius, level) on the sky, behind everything
    /// else: small round distractors.
    spots: Vec<([f64; 2], f64, f64)>,
}

impl Scene {
    fn new(disc: Ellipse) -> Self {
        Self {
            disc,
            disc_level: 30.0,
            canopy_level: 175.0,
            band_level: 85.0,
            with_canopy: true,
            bar: None,
            rects: Vec::new(),
            patches: Vec::new(),
            hose: None,
            bite: None,
            sky_level: 130.0,
            tip: None,
            throat_shadow: None,
            spots: Vec::new(),
        }
    }

    fn level(&self, u: f64, v: f64) -> f64 {
        if let Some((c, r, level)) = self.tip
            && (u - c[0]).hypot(v - c[1]) <= r
        {
            return level;
        }
        if let Some((from, length, half_width, level)) = self.hose
            && v <= from[1]
            && v >= from[1] - length
            && (u - from[0]).abs() <= half_width
        {
            return level;
        }
        for (r, level) in &self.patches {
            if u >= r[0] && u <= r[2] && v >= r[1] && v <= r[3] {
                return *level;
            }
        }
        if let Some((from, half_width, level)) = self.bar
            && v >= from[1]
            && (u - from[0]).abs() <= half_width
        {
            return level;
        }
        for r in &self.rects {
            if u >= r[0] && u <= r[2] && v >= r[1] && v <= r[3] {
                return 25.0;
            }
        }
        if let Some((c, r)) = self.bite
            && (u - c[0]).hypot(v - c[1]) <= r
        {
            return self.canopy_level;
        }
        let k = ellipse_level(&self.disc, u, v);
        if self.disc.a > 0.0 && k <= 1.0 {
            self.disc_level
        } else if self.with_canopy && k <= 2.1 {
            let shadow = self
                .throat_shadow
                .map_or(0.0, |(share, width)| share * (-(k - 1.0) / width).exp());
            self.canopy_level * (1.0 - shadow)
        } else if self.with_canopy && k <= 2.2 {
            self.band_level
        } else if let Some(&(_, _, level)) = self
            .spots
            .iter()
            .find(|(c, r, _)| (u - c[0]).hypot(v - c[1]) <= *r)
        {
            level
        } else {
            self.sky_level + 0.03 * v
        }
    }

    /// Pixel-area average (8 x 8 samples) plus Gaussian noise.
    fn render(&self, w: u32, h: u32, noise: f64, seed: u64) -> GrayImage {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        GrayImage::from_fn(w, h, |x, y| {
            let (u, v) = (x as f64, y as f64);
            let mut sum = 0.0;
            for i in 0..8 {
                for j in 0..8 {
                    sum += self.level(
                        u - 0.5 + (i as f64 + 0.5) / 8.0,
                        v - 0.5 + (j as f64 + 0.5) / 8.0,
                    );
                }
            }
            let n = noise * gauss(&mut rng);
            Luma([(sum / 64.0 + n).round().clamp(0.0, 255.0) as u8])
        })
    }
}

/// Linear motion blur: the mean of `taps` copies shifted along `(du, dv)`
/// (pixels, centred), sampled bilinearly.
fn motion_blur(img: &GrayImage, du: f64, dv: f64, taps: usize) -> GrayImage {
    GrayImage::from_fn(img.width(), img.height(), |x, y| {
        let mut sum = 0.0;
        for k in 0..taps {
            let t = (k as f64 + 0.5) / taps as f64 - 0.5;
            let (u, v) = (f64::from(x) + t * du, f64::from(y) + t * dv);
            let u = u.clamp(0.0, f64::from(img.width() - 1));
            let v = v.clamp(0.0, f64::from(img.height() - 1));
            sum += f64::from(rim::sample(img, u, v).unwrap_or(0.0));
        }
        Luma([(sum / taps as f64).round() as u8])
    })
}

/// A standard normal draw (Box-Muller).
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let (r1, r2): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
    (-2.0 * r1.ln()).sqrt() * (std::f64::consts::TAU * r2).cos()
}

/// `img` plus Gaussian noise of deviation `sigma` (sensor noise comes after
/// the optics' blur).
fn add_noise(img: &GrayImage, sigma: f64, seed: u64) -> GrayImage {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    GrayImage::from_fn(img.width(), img.height(), |x, y| {
        let n = sigma * gauss(&mut rng);
        Luma([(f64::from(img.get_pixel(x, y)[0]) + n)
            .round()
            .clamp(0.0, 255.0) as u8])
    })
}

/// Asserts that ellipse `e` is `truth` to within `centre_px` (its centre)
/// and `axes_px` (each semi-axis).
fn assert_near(e: &Ellipse, truth: &Ellipse, centre_px: f64, axes_px: f64) {
    let centre = (e.cx - truth.cx).hypot(e.cy - truth.cy);
    assert!(centre < centre_px, "centre off by {centre} px: {e:?}");
    assert!(
        (e.a - truth.a).abs() < axes_px && (e.b - truth.b).abs() < axes_px,
        "{e:?} for {truth:?}"
    );
}

/// Plain least-squares ellipse of the rim points (no trimming), to test the
/// points themselves.
fn fit_points(c: &RimCandidate) -> Ellipse {
    conic_fit::fit_ellipse(&c.rim_points_px).unwrap()
}

#[test]
fn clean_disc_gives_subpixel_rim_points() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(201.37, 148.81, 48.3, 31.7, 0.52);
    let img = Scene::new(truth).render(w, h, 2.0, 1);
    let c = detector(&cam).detect(&img, None).expect("detected");
    assert!(c.score > 0.8, "score {}", c.score);
    assert!(c.rim_points_px.len() > 120);
    let e = fit_points(&c);
    assert!(truth.max_param_error_px(&e) < 0.05, "{e:?}");
    assert!(truth.theta_error_rad(&e).to_degrees() < 0.2, "{e:?}");
}

/// A 400x300 frame whose disc (the returned truth) has a bar from below,
/// as wide as the disc and reaching past its centre: it hides the lower
/// ~40 % of the rim and merges with the disc.
fn probe_scene() -> (CameraModel, Ellipse, GrayImage) {
    let (w, h) = (400, 300);
    let truth = Ellipse::new(190.6, 120.2, 50.0, 47.0, 0.1);
    let mut scene = Scene::new(truth);
    scene.bar = Some(([190.6, 128.0], 46.0, 42.0));
    (camera(w, h), truth, scene.render(w, h, 2.0, 2))
}

#[test]
fn probe_hiding_forty_percent_of_the_rim() {
    let (cam, truth, img) = probe_scene();
    let c = detector(&cam).detect(&img, None).expect("detected");
    let inliers: Vec<[f64; 2]> = {
        let conic = truth.to_conic();
        c.rim_points_px
            .iter()
            .copied()
            .filter(|p| conic.sampson_distance(p[0], p[1]) < 0.5)
            .collect()
    };
    assert!(inliers.len() as f64 >= 0.6 * c.rim_points_px.len() as f64);
    let e = conic_fit::fit_ellipse(&inliers).unwrap();
    assert!(truth.max_param_error_px(&e) < 0.15, "{e:?}");
}

/// A far disc, 7 px in radius (0.15 m at about 29 m), is found and
/// measured; one whose minor semi-axis is below the smallest radius at
/// which its canopy can be judged (6.1 px, `canopy::smallest_judged_radius_px`)
/// rests on its darkness alone and is not (6.2 x 5.6 px: about 33 m).
#[test]
fn small_far_disc_is_found() {
    let (w, h) = (320, 240);
    let cam = camera(w, h);
    let truth = Ellipse::new(151.3, 97.6, 7.0, 6.5, 0.3);
    let img = Scene::new(truth).render(w, h, 1.5, 3);
    let c = detector(&cam).detect(&img, None).expect("detected");
    let e = fit_points(&c);
    assert!(truth.max_param_error_px(&e) < 0.15, "{e:?}");
    let too_thin = Ellipse::new(151.3, 97.6, 6.2, 5.6, 0.3);
    let img = Scene::new(too_thin).render(w, h, 1.5, 3);
    assert!(detector(&cam).detect(&img, None).is_none());
}

#[test]
fn dark_shapes_without_a_drogue_are_not_detected() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let mut scene = Scene::new(Ellipse::new(0.0, 0.0, 0.0, 0.0, 0.0));
    scene.with_canopy = false;
    scene.rects = vec![
        [40.0, 40.0, 160.0, 80.0],
        [250.0, 150.0, 290.0, 190.0],
        // A cross.
        [100.0, 180.0, 180.0, 200.0],
        [130.0, 150.0, 150.0, 230.0],
    ];
    let img = scene.render(w, h, 2.0, 4);
    assert!(detector(&cam).detect(&img, None).is_none());
}

#[test]
fn tracking_hint_is_used_and_a_wrong_hint_falls_back_to_the_full_search() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(220.4, 160.9, 40.0, 36.0, -0.4);
    let img = Scene::new(truth).render(w, h, 2.0, 5);
    let mut det = detector(&cam);
    let near = Ellipse::new(222.0, 159.0, 42.0, 35.0, -0.3);
    let c = det.detect(&img, Some(&near)).expect("tracked");
    assert!(truth.max_param_error_px(&fit_points(&c)) < 0.05);
    let wrong = Ellipse::new(60.0, 60.0, 20.0, 20.0, 0.0);
    let c = det.detect(&img, Some(&wrong)).expect("full search");
    assert!(truth.max_param_error_px(&fit_points(&c)) < 0.05);
}

#[test]
fn hostile_frames_do_not_panic() {
    let cam = camera(640, 480);
    let mut det = detector(&cam);
    let weird = Ellipse::new(f64::NAN, 1.0, 1e9, 0.0, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let frames = [
        GrayImage::new(1, 1),
        GrayImage::new(20000, 1),
        GrayImage::new(1, 5000),
        GrayImage::from_pixel(640, 480, Luma([0])),
        GrayImage::from_pixel(640, 480, Luma([255])),
        GrayImage::from_fn(640, 480, |_, _| Luma([rng.random::<u8>()])),
        GrayImage::from_fn(640, 480, |x, _| Luma([if x % 2 == 0 { 0 } else { 255 }])),
    ];
    for (i, img) in frames.iter().enumerate() {
        let found = det.detect(img, None);
        assert!(
            found.is_none(),
            "frame {i}: {:?}",
            found.map(|c| (c.ellipse_px, c.score))
        );
        let _ = det.detect(img, Some(&weird));
    }
}

#[test]
fn small_disc_with_a_hose_beside_a_large_dark_area_in_many_parts() {
    // A far drogue (13 px disc, hose attached above) and, elsewhere, a large
    // dark area made of darker and lighter stripes (a shaded probe): at the
    // lowest threshold it breaks into several parts, each larger than the
    // disc. Those parts are one dark area and must not use up the budget of
    // candidates before the disc is tried.
    let (w, h) = (640, 480);
    let cam = camera(w, h);
    let truth = Ellipse::new(200.4, 300.7, 13.2, 13.0, 0.3);
    let mut scene = Scene::new(truth);
    scene.hose = Some(([200.4, 300.7], 60.0, 3.5, 35.0));
    scene.patches = (0..10)
        .map(|k| {
            let u0 = 330.0 + 28.0 * k as f64;
            let level = if k % 2 == 0 { 25.0 } else { 55.0 };
            ([u0, 180.0, u0 + 28.0, 250.0], level)
        })
        .collect();
    let img = scene.render(w, h, 2.0, 7);
    let c = detector(&cam).detect(&img, None).expect("detected");
    let on_rim: Vec<[f64; 2]> = {
        let conic = truth.to_conic();
        c.rim_points_px
            .iter()
            .copied()
            .filter(|p| conic.sampson_distance(p[0], p[1]) < 0.5)
            .collect()
    };
    assert!(on_rim.len() as f64 >= 0.6 * c.rim_points_px.len() as f64);
    let e = conic_fit::fit_ellipse(&on_rim).unwrap();
    assert!(truth.max_param_error_px(&e) < 0.15, "{e:?}");
}

#[test]
fn ray_directions_are_the_angles_around_the_circle() {
    for n in [1usize, 24, 173, 400] {
        let dirs: Vec<[f64; 2]> = super::ray_directions(n).collect();
        assert_eq!(dirs.len(), n);
        for (k, d) in dirs.iter().enumerate() {
            let phi = std::f64::consts::TAU * k as f64 / n as f64;
            assert!((d[0] - phi.cos()).abs() < 1e-13 && (d[1] - phi.sin()).abs() < 1e-13);
        }
    }
    // The radius along a direction, both ways.
    let (a, b, theta) = (30.0, 12.0, 0.4);
    for phi in [0.0f64, 0.4, 1.0, 2.5, 5.0] {
        let (s, c) = (phi - theta).sin_cos();
        let r = super::polar_radius(a, b, theta, phi);
        assert!((r - super::polar_radius_local(a, b, c, s)).abs() < 1e-12);
        // The point at that radius lies on the ellipse.
        let (x, y) = (r * c, r * s);
        assert!(((x / a).powi(2) + (y / b).powi(2) - 1.0).abs() < 1e-12);
    }
    assert!((super::polar_radius(a, b, theta, theta) - a).abs() < 1e-12);
}

#[test]
fn a_crescent_inside_a_canopy_ring_is_not_a_drogue() {
    // The outer arc of a crescent is a fine circle, and here even the
    // canopy's rim lies where that circle's pose puts it: only the light
    // inside the circle tells it from a disc with an occluder.
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let circle = Ellipse::new(200.0, 150.0, 40.0, 40.0, 0.0);
    let mut scene = Scene::new(circle);
    scene.bite = Some(([200.0, 168.0], 34.0));
    let img = scene.render(w, h, 2.0, 11);
    assert!(detector(&cam).detect(&img, None).is_none());
    // The same disc whole is found.
    let img = Scene::new(circle).render(w, h, 2.0, 11);
    assert!(detector(&cam).detect(&img, None).is_some());
}

#[test]
fn a_dark_disc_without_its_canopy_is_not_a_drogue() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let mut scene = Scene::new(Ellipse::new(190.0, 140.0, 36.0, 30.0, 0.3));
    scene.with_canopy = false;
    let img = scene.render(w, h, 2.0, 12);
    assert!(detector(&cam).detect(&img, None).is_none());
}

#[test]
fn a_motion_blurred_disc_is_found_and_its_rim_is_unbiased() {
    // 24 px of linear blur at 30 degrees across a 45 px disc: the rim is a
    // ramp wider than the narrow pass's first window.
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(198.3, 151.7, 45.0, 42.0, 0.3);
    let sharp = Scene::new(truth).render(w, h, 0.0, 13);
    let (s, c) = 30f64.to_radians().sin_cos();
    let img = motion_blur(&sharp, 24.0 * c, 24.0 * s, 48);
    let cand = detector(&cam).detect(&img, None).expect("detected");
    assert_near(&fit_points(&cand), &truth, 1.0, 1.5);
}

#[test]
fn a_disc_merged_with_a_wide_bar_is_found_by_its_edges() {
    // A bar as dark as the disc and wider than its radius merges with it
    // into one region whose moments are the bar's; the edge source still
    // finds the disc from its rim.
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(210.0, 120.0, 38.0, 36.0, 0.0);
    let mut scene = Scene::new(truth);
    scene.bar = Some(([200.0, 120.0], 30.0, 30.0));
    let img = scene.render(w, h, 2.0, 14);
    let cand = detector(&cam).detect(&img, None).expect("detected");
    // The detector's quick ellipse of a rim 40 % hidden: within a few
    // pixels (the fit refines it).
    let e = cand.ellipse_px;
    let centre = (e.cx - truth.cx).hypot(e.cy - truth.cy);
    assert!(centre < 2.5 && (e.a / truth.a - 1.0).abs() < 0.1, "{e:?}");
}

#[test]
fn a_blurred_disc_in_heavy_noise_keeps_its_size() {
    // 14 px of blur across a 22 px disc, then noise of 7 gray levels: along
    // the blur the rim is a ramp whose slope is below the noise of single
    // samples. Unsmoothed, the strongest rise and the step's ends follow the
    // noise, and the rim came out about 3 px too far out along the blur.
    // Found, the ellipse is within a pixel.
    let (w, h) = (320, 240);
    let cam = camera(w, h);
    let truth = Ellipse::new(161.4, 118.9, 22.0, 19.0, 0.2);
    let sharp = Scene::new(truth).render(w, h, 0.0, 21);
    let blurred = motion_blur(&sharp, 14.0, 0.0, 28);
    let mut found = 0;
    for seed in 0..4u64 {
        let img = add_noise(&blurred, 7.0, 22 + seed);
        let Some(cand) = detector(&cam).detect(&img, None) else {
            continue;
        };
        found += 1;
        let e = cand.ellipse_px;
        assert!(
            (e.a - truth.a).abs() < 1.0 && (e.b - truth.b).abs() < 1.0,
            "seed {seed}: {e:?} for {truth:?}"
        );
    }
    // The canopy's thin outer rim, blurred and in this noise, is seen on
    // about 0.45 of its points: half of the draws fall under the 0.5 asked
    // (`NoCanopy`), a miss rather than a wrong answer.
    assert!(found >= 2, "found in {found} of 4 noise draws");
}

/// `start` verified by the narrow passes (the scouts' spacing), then the
/// disc looked for inside it: the ellipse the search keeps.
fn kept_after_inner_search(
    detector: &mut Detector,
    img: &GrayImage,
    start: &Ellipse,
    cfg: &Config,
) -> Ellipse {
    let verified = detector
        .verify_settled(
            img,
            start,
            cfg.detect.rim_point_spacing_px,
            cfg.detect.max_rim_points,
            super::verify::RimUse::Scout,
        )
        .unwrap_or_else(|why| panic!("{start:?} does not verify: {why:?}"));
    detector.prefer_inner_disc(img, verified, 0).ellipse
}

/// `e` scaled about its centre by `k` (the canopy's rim: `R / r`).
fn scaled(e: &Ellipse, k: f64) -> Ellipse {
    Ellipse::new(e.cx, e.cy, k * e.a, k * e.b, e.theta)
}

#[test]
fn the_canopy_taken_for_the_disc_gives_way_to_the_disc_inside() {
    // Haze: a dull disc in a dull canopy against a bright sky, where the
    // canopy's outer edge is the strongest step on every ray from the centre
    // (as in the reference frame hard_b/frame_0015). The canopy's ellipse,
    // verified (its canopy test switched off: clutter around the drogue can
    // pass it), gives way to the disc inside, concentric at r / R of its
    // size; the true disc keeps its place (nothing inside it verifies).
    let (w, h) = (400, 300);
    let mut cfg = Config::embedded();
    cfg.detect.min_canopy_fraction = 0.0;
    let cam = camera(w, h);
    let truth = Ellipse::new(197.6, 152.3, 30.0, 26.0, -0.4);
    let mut scene = Scene::new(truth);
    scene.disc_level = 90.0;
    scene.canopy_level = 125.0;
    scene.band_level = 115.0;
    scene.sky_level = 165.0;
    let img = scene.render(w, h, 2.0, 23);
    let mut detector = crate::testing::detector(&cfg, &cam);
    let spacing = cfg.detect.rim_point_spacing_px;
    let max_points = cfg.detect.max_rim_points;
    // The scene's canopy rim (the band's outer edge) is at 2.2 disc radii.
    let canopy = scaled(&truth, 2.2);
    let outer = detector
        .verify_settled(
            &img,
            &canopy,
            spacing,
            max_points,
            super::verify::RimUse::Scout,
        )
        .expect("the canopy's outer rim verifies as a disc");
    assert!(
        (outer.ellipse.a / canopy.a - 1.0).abs() < 0.05,
        "{:?}",
        outer.ellipse
    );
    let chosen = detector.prefer_inner_disc(&img, outer, 0).ellipse;
    assert!(
        (chosen.a - truth.a).abs() < 1.0 && (chosen.b - truth.b).abs() < 1.0,
        "{chosen:?} for {truth:?}"
    );
    let kept = kept_after_inner_search(&mut detector, &img, &truth, &cfg);
    assert!((kept.a - truth.a).abs() < 1.0, "{kept:?}");
}

/// The canopy taken for the disc in haze, with the probe (nearer, so far
/// darker than the disc) over the disc's lower half, ending at its centre
/// (as the reference frame `hard_b/frame_0009` transposed): from the
/// centre the probe's outline is the strongest rise on a third of the
/// rays, and the wide pass fitted an ellipse to it and the disc's rim
/// together. The narrow passes where the disc must be (concentric, at
/// `r / R` of the canopy) find the disc, whose canopy (the rim taken for
/// the disc) the frame shows better than that rim's own predicted canopy.
#[test]
fn the_canopy_taken_for_the_disc_gives_way_to_the_disc_under_the_probe() {
    let (w, h) = (400, 300);
    let mut cfg = Config::embedded();
    cfg.detect.min_canopy_fraction = 0.0;
    let cam = camera(w, h);
    let truth = Ellipse::new(197.6, 152.3, 30.0, 28.0, -0.4);
    let mut scene = Scene::new(truth);
    scene.disc_level = 100.0;
    scene.canopy_level = 130.0;
    scene.band_level = 115.0;
    scene.sky_level = 160.0;
    let tip = [truth.cx + 2.0, truth.cy];
    scene.tip = Some((tip, 12.0, 30.0));
    scene.bar = Some((tip, 12.0, 30.0));
    for seed in [23, 24, 25, 26] {
        let img = scene.render(w, h, 2.0, seed);
        let mut detector = crate::testing::detector(&cfg, &cam);
        let chosen = kept_after_inner_search(&mut detector, &img, &scaled(&truth, 2.2), &cfg);
        assert!(
            (chosen.a - truth.a).abs() < 1.5 && (chosen.b - truth.b).abs() < 1.5,
            "noise seed {seed}: {chosen:?} for {truth:?}"
        );
    }
}

/// The probe seen end-on, its rounded end a dark circle inside a hazed
/// disc at about `r / R` of its size: a strong rim nested in the disc's,
/// which verifies on its own (its predicted canopy is the disc's rim, a
/// brightening with the lighter disc before it). The frame shows the
/// disc's canopy better than the tip's: the disc keeps its place (taking
/// the nested rim whenever it verified gave the tip on every draw here).
#[test]
fn the_probes_tip_inside_a_hazed_disc_does_not_take_its_place() {
    let (truth, mut scene) = probe_tip_in_hazed_disc();
    scene.bar = None;
    scene.tip = Some(([truth.cx + 1.0, truth.cy + 1.0], 20.0, 20.0));
    let cam = camera(400, 300);
    let cfg = Config::embedded();
    for disc_level in [95.0, 125.0] {
        scene.disc_level = disc_level;
        for seed in 2..6 {
            let img = scene.render(400, 300, 7.0, seed);
            let mut detector = crate::testing::detector(&cfg, &cam);
            let kept = kept_after_inner_search(&mut detector, &img, &truth, &cfg);
            assert!(
                (kept.a - truth.a).abs() < 1.5,
                "disc level {disc_level}, noise seed {seed}: {kept:?}"
            );
        }
    }
}

/// A step whose light side reaches saturation is a glare streak's skirt
/// (its width is not blur); a step to an unsaturated level is not.
#[test]
fn a_step_into_saturation_is_glare() {
    let ramp = |top: f32| -> Vec<f32> {
        (0..40)
            .map(|k| (30.0 + 10.0 * (k as f32 - 10.0).max(0.0)).min(top))
            .collect()
    };
    let glare = ramp(255.0);
    let e = super::rim::strongest_rise(&glare, 0.0, 0.5, 12.0).expect("a step");
    assert!(super::glare::glare_on_light_side(&glare, 0.0, 0.5, &e));
    let canopy = ramp(180.0);
    let e = super::rim::strongest_rise(&canopy, 0.0, 0.5, 12.0).expect("a step");
    assert!(!super::glare::glare_on_light_side(&canopy, 0.0, 0.5, &e));
}

/// The angle between two directions, as `rem_euclid` gives it.
#[test]
fn angle_gap_matches_rem_euclid() {
    use std::f64::consts::TAU;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..10_000 {
        let a: f64 = rng.random_range(-4.0..7.0);
        let b: f64 = rng.random_range(-4.0..7.0);
        let d = (a - b).rem_euclid(TAU);
        let expected = d.min(TAU - d);
        assert!((super::angle_gap(a, b) - expected).abs() < 1e-12, "{a} {b}");
    }
}

/// A large dark ring (light inside) whose canopy would lie far off the
/// frame: with no canopy to judge, the fill must be a disc's, and half a
/// ring's inside is not.
#[test]
fn a_ring_whose_canopy_would_be_off_the_frame_is_not_a_drogue() {
    // Dark from 0.45 to 1 of its radius: three of the fill test's five
    // radius fractions (0.5, 0.7, 0.85) are dark, a fill of 0.6.
    let (w, h) = (1280, 960);
    let cam = camera(w, h);
    let img = GrayImage::from_fn(w, h, |x, y| {
        let r = (f64::from(x) - 640.0).hypot(f64::from(y) - 480.0);
        Luma([if (150.0..330.0).contains(&r) { 40 } else { 180 }])
    });
    assert!(detector(&cam).detect(&img, None).is_none());
}

#[test]
fn a_seed_on_a_verified_rim_is_not_verified_again() {
    // The probe hides the lower part of the rim: the disc scores below
    // accept_score, so every seed of its region is tried; a second seed
    // on the same disc must stop at its first fit.
    let (cam, truth, img) = probe_scene();
    let mut detector = detector(&cam);
    let seed = |centre_px: [f64; 2], radius: f64| search::Seed {
        centre_px,
        a_px: radius,
        b_px: radius,
        theta: 0.0,
        reach: 1.8,
        from: 0.0,
        kind: 0,
    };
    let first = detector
        .verify_seed(&img, &seed([190.0, 118.0], 45.0), 0, &[])
        .expect("the disc verifies");
    assert!(
        truth.max_param_error_px(&first.ellipse) < 1.0,
        "{:?}",
        first.ellipse
    );
    let again = detector.verify_seed(&img, &seed([186.0, 115.0], 40.0), 1, &[first]);
    assert_eq!(again.err(), Some(Reject::Known));
    // Without the known candidate the same seed verifies to the same rim.
    let alone = detector
        .verify_seed(&img, &seed([186.0, 115.0], 40.0), 1, &[])
        .expect("the disc verifies");
    assert!(
        truth.max_param_error_px(&alone.ellipse) < 1.0,
        "{:?}",
        alone.ellipse
    );
}

/// A box-blurred step (8 px) from a flat dark side onto a light side that
/// brightens outward (3 % of the contrast per pixel, as a canopy shaded
/// toward the disc), the edge at 20 px: the flat levels' mid-level crossing
/// lies outward of it (analytically `g L (D/2 - L/8) / contrast`, about
/// 0.35 px here); placed for the shading, within 0.05 px of it.
#[test]
fn a_blurred_edge_on_a_shaded_canopy_is_placed_at_the_edge() {
    let (edge, blur, dark, contrast, slope) = (20.0, 8.0, 40.0, 100.0, 3.0);
    // The sharp profile, and its box blur by exact integration over the
    // blur's length: dark inside, light + slope * (s - edge) outside.
    let integral = |s: f64| {
        if s <= edge {
            dark * s
        } else {
            dark * edge + (dark + contrast) * (s - edge) + 0.5 * slope * (s - edge).powi(2)
        }
    };
    let blurred = |s: f64| (integral(s + blur / 2.0) - integral(s - blur / 2.0)) / blur;
    let profile: Vec<f32> = (0..80)
        .map(|k| blurred(f64::from(k) * 0.5) as f32)
        .collect();
    let e = super::rim::strongest_rise(&profile, 0.0, 0.5, 10.0).expect("a step");
    assert!(
        e.s - edge > 0.2,
        "the flat levels' crossing is {:.3} px from the edge",
        e.s - edge
    );
    // Every ray of the pass sees the same canopy: 12 of them.
    let edges: Vec<_> = (0..12)
        .map(|_| {
            let slope = super::rim::light_side_slope(&profile, 0.0, 0.5, &e);
            super::shading::ShadedEdge::new([1.0, 0.0], &e, [slope, f32::NAN], 0.0)
        })
        .collect();
    let points = vec![[e.s, 0.0]; 12];
    let canopy = super::shading::canopy_slope(&edges);
    let moved = super::shading::shaded_points(&points, &edges, canopy, &[false; 12]);
    for p in moved {
        assert!(
            (p[0] - edge).abs() < 0.05,
            "placed {:.3} px from the edge (flat: {:.3})",
            p[0] - edge,
            e.s - edge
        );
    }
}

/// A sharp step (a 2.5 px box blur, the edge at 20 px) under a glare
/// streak's skirt: a Gaussian light of 300 gray levels across both sides,
/// 30 px wide at half its height, its centre line two standard deviations
/// inside the edge, so that it falls outward and is convex across the step
/// (0.75 gray levels per pixel squared). Its light over the two level reads
/// is above its light at the edge by the curvature times their squared
/// distance over two: the mid-level crossing lies outward (0.046 px here).
/// Four rays of twelve see it, the other eight a flat canopy (whose median
/// slope, the canopy's, is then none); placed for the light's curvature,
/// the four lie within a quarter of that of the flat step's crossing
/// (0.002 px here) and the eight stay where they were.
#[test]
fn a_sharp_edge_under_a_curved_light_is_placed_at_the_edge() {
    let (edge, blur, dark, contrast) = (20.0, 2.5, 40.0, 100.0);
    let sigma = 30.0 / (8.0 * std::f64::consts::LN_2).sqrt();
    let centre = edge - 2.0 * sigma;
    let integral = |s: f64| {
        if s <= edge {
            dark * s
        } else {
            dark * edge + (dark + contrast) * (s - edge)
        }
    };
    let step = |s: f64| (integral(s + blur / 2.0) - integral(s - blur / 2.0)) / blur;
    let glow = |s: f64| 300.0 * (-(s - centre).powi(2) / (2.0 * sigma * sigma)).exp();
    let sampled = |f: &dyn Fn(f64) -> f64| -> Vec<f32> {
        (0..80).map(|k| f(f64::from(k) * 0.5) as f32).collect()
    };
    let flat = sampled(&step);
    let lit = sampled(&|s| step(s) + glow(s));
    let edge_of = |p: &[f32]| {
        let e = super::rim::strongest_rise(p, 0.0, 0.5, 10.0).expect("a step");
        let slopes = [
            super::rim::light_side_slope(p, 0.0, 0.5, &e),
            super::rim::dark_side_slope(p, 0.0, 0.5, &e),
        ];
        (
            e,
            super::shading::ShadedEdge::new([1.0, 0.0], &e, slopes, 0.0),
        )
    };
    let (e_flat, _) = edge_of(&flat);
    let (e_lit, _) = edge_of(&lit);
    let bias = e_lit.s - e_flat.s;
    assert!(
        bias > 0.015,
        "the curved light moves the crossing {bias:.4} px"
    );
    let rays: Vec<_> = (0..12)
        .map(|k| edge_of(if k % 3 == 0 { &lit } else { &flat }))
        .collect();
    let points: Vec<[f64; 2]> = rays.iter().map(|(e, _)| [e.s, 0.0]).collect();
    let edges: Vec<_> = rays.into_iter().map(|(_, s)| s).collect();
    let canopy = super::shading::canopy_slope(&edges);
    let moved = super::shading::shaded_points(&points, &edges, canopy, &[true; 12]);
    for (k, p) in moved.iter().enumerate() {
        if k % 3 == 0 {
            let left = p[0] - e_flat.s;
            assert!(
                left.abs() < 0.25 * bias,
                "placed {left:+.4} px from the flat step's crossing (before: {bias:+.4})"
            );
        } else {
            assert_eq!(p[0], e_flat.s, "a ray without the light stays");
        }
    }
}

/// The measurement's smoothing follows the noise relative to the step: on a
/// step of 100 gray levels it is the frame's noise-only smoothing, on a
/// faint one (a third of that, as in haze) the same noise is smoothed as if
/// it were three times larger, and nothing is smoothed for no step.
#[test]
fn a_faint_step_is_smoothed_as_much_as_stronger_noise() {
    for sigma in [1.0, 3.0, 4.0, 6.0, 9.0] {
        assert_eq!(
            super::smoothing_half_for_contrast(sigma, 100.0),
            super::smoothing_half(sigma),
            "sigma {sigma}"
        );
        assert_eq!(
            super::smoothing_half_for_contrast(sigma, 100.0 / 3.0),
            super::smoothing_half(3.0 * sigma),
            "sigma {sigma}"
        );
        assert_eq!(super::smoothing_half_for_contrast(sigma, 0.0), 0);
        assert_eq!(super::smoothing_half_for_contrast(sigma, f64::NAN), 0);
    }
    // Noise 3 on a 30-level step: the +-2 px kernel, which the frame's
    // noise alone (3 gray levels) would not get.
    assert_eq!(super::smoothing_half(3.0), 0);
    assert_eq!(super::smoothing_half_for_contrast(3.0, 30.0), 2);
}

/// The local-contrast source finds a hazed disc that no global threshold
/// separates: most of the frame is a dark patch (the frame's darkest and
/// median levels are both the patch's), and the drogue, lifted by haze,
/// sits in the light part. Its regions give a seed that verifies as the
/// disc, to within half a pixel.
#[test]
fn the_local_contrast_source_finds_a_disc_above_every_global_threshold() {
    let (w, h) = (480, 360);
    let cam = camera(w, h);
    let disc = Ellipse::new(360.0, 120.0, 24.0, 20.0, 0.4);
    let mut scene = Scene::new(disc);
    (scene.disc_level, scene.canopy_level, scene.band_level) = (110.0, 180.0, 140.0);
    scene.sky_level = 165.0;
    scene.patches = vec![
        ([0.0, 0.0, 250.0, 360.0], 20.0),
        ([250.0, 240.0, 480.0, 360.0], 20.0),
    ];
    let img = scene.render(w, h, 2.0, 11);
    let mut det = detector(&cam);
    det.cfg.local_contrast_source = true;
    det.measure_noise(&img, NOISE_ROW_STRIDE);
    // The global thresholds see no dark region at the disc.
    det.decimated.update(&img, det.cfg.decimation as usize);
    let mut blobs = Vec::new();
    det.finder.find(
        &det.decimated,
        &det.cfg.threshold_fractions,
        2,
        det.cfg.min_contrast_gray,
        &mut blobs,
    );
    assert!(
        !blobs
            .iter()
            .any(|b| (b.centre_px[0] - disc.cx).hypot(b.centre_px[1] - disc.cy) < disc.b),
        "a global threshold separated the disc: the test shows nothing"
    );
    let (mut tried, mut verified) = (Vec::new(), Vec::new());
    det.try_local_contrast(&img, det.cfg.accept_score, &mut tried, &mut verified);
    assert!(tried.iter().all(|s| s.kind >= 5), "{tried:?}");
    let best = verified
        .iter()
        .max_by(|x, y| x.score.total_cmp(&y.score))
        .expect("a verified candidate");
    let e = best.ellipse;
    assert!(
        (e.cx - disc.cx).hypot(e.cy - disc.cy) < 0.5
            && (e.a - disc.a).abs() < 0.5
            && (e.b - disc.b).abs() < 0.5,
        "{e:?}"
    );
}

/// The local-contrast source is on by default, and it finds nothing on the
/// drogue-free frames of the dark-shapes test with a saturated patch (a
/// glare) beside the shapes, where it is tried.
#[test]
fn the_local_contrast_source_is_on_by_default_and_finds_no_dark_shape() {
    assert!(Config::embedded().detect.local_contrast_source);
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let mut scene = Scene::new(Ellipse::new(0.0, 0.0, 0.0, 0.0, 0.0));
    scene.with_canopy = false;
    scene.rects = vec![[40.0, 40.0, 160.0, 80.0], [250.0, 150.0, 290.0, 190.0]];
    scene.patches = vec![([300.0, 20.0, 380.0, 100.0], 255.0)];
    let img = scene.render(w, h, 2.0, 4);
    let mut det = detector(&cam);
    det.decimated.update(&img, det.cfg.decimation as usize);
    assert!(
        det.decimated.any_at_least(super::SATURATED_LEVEL),
        "the patch saturates no block: the local source would not be tried"
    );
    assert!(det.detect(&img, None).is_none());
}

/// A drogue under a glare's glow: the disc lightened to a mid grey, its
/// canopy saturated, the sky darker than the disc.
fn glow_saturated_canopy(disc: Ellipse) -> Scene {
    let mut scene = Scene::new(disc);
    (scene.disc_level, scene.canopy_level, scene.band_level) = (185.0, 255.0, 235.0);
    scene.sky_level = 150.0;
    scene
}

/// A glare's glow that saturates the canopy around a disc lightened to a
/// mid grey (the sweep's `glare glow` levels): the sky is darker than the
/// disc, so no global threshold separates it, and every step of its rim
/// runs straight into saturated pixels, which the edge source takes for
/// the glare's skirt. Only the local-contrast source, tried because the
/// frame has a glare, finds it: within half a pixel with the source, not
/// at all without it.
#[test]
fn the_local_contrast_source_finds_a_disc_on_a_saturated_canopy() {
    let (w, h) = (480, 360);
    let cam = camera(w, h);
    let disc = Ellipse::new(240.0, 170.0, 26.0, 22.0, 0.3);
    let img = glow_saturated_canopy(disc).render(w, h, 2.0, 5);
    let mut det = detector(&cam);
    assert!(det.cfg.local_contrast_source);
    let found = det
        .detect(&img, None)
        .expect("the disc, by its local contrast");
    let e = found.ellipse_px;
    assert!(
        (e.cx - disc.cx).hypot(e.cy - disc.cy) < 0.5
            && (e.a - disc.a).abs() < 0.5
            && (e.b - disc.b).abs() < 0.5,
        "{e:?}"
    );
    let mut without = detector(&cam);
    without.cfg.local_contrast_source = false;
    assert!(
        without.detect(&img, None).is_none(),
        "found without the local source: the test shows nothing"
    );
}

/// A disc on a canopy so light that the camera clips it (400 on a scale
/// that ends at 255, its rim band below saturation): every step of the rim
/// runs into saturation, its mid level is taken from the clipped level and
/// its point lies short of the edge. Each point's distance out to
/// saturation brackets the true edge (a circle: the edge lies along the
/// ray, at the true radius): it lies between the point and that far out.
/// On the same disc below saturation no point is clipped (none carried).
#[test]
fn a_clipped_steps_reach_to_saturation_brackets_its_edge() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let disc = Ellipse::new(200.0, 150.0, 40.0, 40.0, 0.0);
    let mut scene = Scene::new(disc);
    (scene.canopy_level, scene.band_level, scene.sky_level) = (400.0, 235.0, 150.0);
    let found = detector(&cam)
        .detect(&scene.render(w, h, 1.0, 3), None)
        .expect("the disc on a clipped canopy");
    assert_eq!(found.rim_clip_px.len(), found.rim_points_px.len());
    let (mut inward, mut bracketed) = (0.0, 0);
    for (p, &clip) in found.rim_points_px.iter().zip(&found.rim_clip_px) {
        // How far out from the point the true edge is.
        let short = disc.a - (p[0] - disc.cx).hypot(p[1] - disc.cy);
        inward += short;
        if clip > 0.0 && (-0.05..=clip + 0.05).contains(&short) {
            bracketed += 1;
        }
    }
    let n = found.rim_points_px.len();
    assert!(
        inward / n as f64 > 0.1,
        "the clipped steps' points lie short of the edge: the test shows nothing ({:.3} px)",
        inward / n as f64
    );
    assert!(bracketed as f64 >= 0.95 * n as f64, "{bracketed} of {n}");
    // Below saturation: no point is clipped.
    scene.canopy_level = 200.0;
    let found = detector(&cam)
        .detect(&scene.render(w, h, 1.0, 3), None)
        .expect("the disc");
    assert!(found.rim_clip_px.is_empty(), "{:?}", found.rim_clip_px);
}

/// The local-contrast source is not tried where a candidate already shows
/// its canopy rim beyond doubt: that candidate is the drogue. On the left a
/// drogue whose canopy a patch of sky hides on one side (its share of the
/// rim below what ends the search by itself), on the right the disc on a
/// glare-saturated canopy that only the local source finds: alone, the
/// right half gives the disc; beside the drogue it is not looked for.
#[test]
fn the_local_contrast_source_is_not_tried_beside_a_drogue_its_canopy_shows() {
    let (w, h) = (960, 360);
    let cam = camera(w, h);
    // No score ends the search: only the canopy could.
    let never = 2.0;
    let drogue = Ellipse::new(200.0, 180.0, 40.0, 38.0, 0.0);
    let mut hidden = Scene::new(drogue);
    hidden.patches = vec![([250.0, 80.0, 300.0, 280.0], 136.0)];
    let left = hidden.render(w, h, 2.0, 6);
    let disc = Ellipse::new(720.0, 170.0, 26.0, 22.0, 0.3);
    let right = glow_saturated_canopy(disc).render(w, h, 2.0, 5);
    let near = |v: &Verified, e: &Ellipse| (v.ellipse.cx - e.cx).hypot(v.ellipse.cy - e.cy) < 3.0;
    let alone = detector(&cam).verify_candidates(&right, never);
    assert!(
        alone.iter().any(|v| near(v, &disc)),
        "the local source did not find the disc alone: {:?}",
        scores(&alone)
    );
    let both = GrayImage::from_fn(w, h, |x, y| {
        if x < w / 2 {
            *left.get_pixel(x, y)
        } else {
            *right.get_pixel(x, y)
        }
    });
    let mut det = detector(&cam);
    let verified = det.verify_candidates(&both, never);
    let shown = verified
        .iter()
        .find(|v| near(v, &drogue))
        .expect("the drogue verified");
    assert!(
        det.canopy_shown(shown) && !shown.canopy.is_some_and(|c| c >= search::CANOPY_CONFIRMS),
        "the drogue's canopy must be shown, not confirmed: {:?}",
        shown.canopy
    );
    assert!(
        !verified.iter().any(|v| near(v, &disc)),
        "{:?}",
        scores(&verified)
    );
}

/// A blur nearly as long as the disc's radius: 32 and 40 px across a
/// 35x32 px disc in noise of 2 gray levels, in three directions. Each
/// blurred step rises about 4 gray levels a pixel, as little as the noise
/// of a sample pair: smoothed only for the frame's noise, the rise dipped
/// below its fade level inside the ramp, the levels were taken inside it,
/// and the ellipse came out 2.6 px (32 px of blur) to 8 px (40 px) too
/// long along the blur: a wrong pose. Found now, the ellipse is within
/// half a pixel at 32 px of blur and 0.6 px at 40 px (where the noise
/// draw and the rays' spacing move the axes by that much: the minor axis
/// 0.38 px long on rays 2 px apart, 0.55 px on rays 1 px apart, this
/// draw), and a frame not found is a miss, never a wrong answer.
#[test]
fn a_blur_nearly_as_long_as_the_radius_keeps_the_disc_size() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(198.3, 151.7, 34.6, 32.0, 0.3);
    let sharp = Scene::new(truth).render(w, h, 0.0, 13);
    let mut found = 0;
    for length in [32.0, 40.0] {
        for degrees in [0.0f64, 45.0, 100.0] {
            let (s, c) = degrees.to_radians().sin_cos();
            let blurred = motion_blur(&sharp, length * c, length * s, 2 * length as usize);
            let img = add_noise(&blurred, 2.0, 5);
            let Some(cand) = detector(&cam).detect(&img, None) else {
                continue;
            };
            found += 1;
            let e = fit_points(&cand);
            let within = if length > 32.0 { 0.6 } else { 0.5 };
            assert!(
                (e.a - truth.a).abs() < within
                    && (e.b - truth.b).abs() < within
                    && (e.cx - truth.cx).hypot(e.cy - truth.cy) < within,
                "{length} px at {degrees} deg: {e:?} for {truth:?}"
            );
        }
    }
    // Every 32 px blur, and the 40 px one along the major axis.
    assert!(found >= 4, "found {found} of 6");
}

#[test]
fn the_probes_tip_inside_a_hazed_disc_is_not_the_disc() {
    // Haze lifts the disc far more than the nearer probe: its tip is the
    // darkest circle, with the disc's dark just outside its rim and the
    // canopy beyond.
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(200.3, 150.4, 32.0, 31.0, 0.2);
    let mut scene = Scene::new(truth);
    scene.disc_level = 100.0;
    scene.canopy_level = 190.0;
    scene.tip = Some(([201.0, 151.0], 20.0, 10.0));
    let img = scene.render(w, h, 2.0, 5);
    let mut detector = detector(&cam);
    let seed = |centre_px: [f64; 2], radius: f64, reach: f64, from: f64| search::Seed {
        centre_px,
        a_px: radius,
        b_px: radius,
        theta: 0.0,
        reach,
        from,
        kind: 3,
    };
    // A first pass that reaches only the tip's rim: the tip is a fine dark
    // circle, but it lies inside a larger dark shape.
    let tip = detector.verify_seed(&img, &seed([201.0, 151.0], 20.0, 1.3, 0.0), 0, &[]);
    let why = tip.as_ref().err();
    assert!(
        matches!(why, Some(Reject::Nested(rise)) if *rise > 0.5),
        "{why:?}"
    );
    // The disc, from a first pass that starts past the tip.
    let disc = detector
        .verify_seed(&img, &seed([200.0, 150.0], 32.0, 2.0, 0.75), 1, &[])
        .expect("the disc verifies");
    assert!(
        truth.max_param_error_px(&disc.ellipse) < 1.0,
        "{:?}",
        disc.ellipse
    );
    // And the whole search gives the disc, never the tip.
    let found = detector.detect(&img, None).expect("detected");
    assert!(truth.max_param_error_px(&fit_points(&found)) < 1.0);
}

#[test]
fn a_canopy_darkened_toward_the_disc_by_its_throats_shadow_is_no_nested_shape() {
    // The canopy loses half its level at the disc's edge to the shadow,
    // recovering over a quarter of the disc's radius (about what the
    // simulator's 30 % throat shadow does on its canopy's own shading):
    // measured against the rim's own, lowered, step the canopy then rises
    // beyond the ring just outside the rim (by 0.54-0.63) as much as around
    // a dark shape inside a larger one; against the full step from the
    // disc, by the shadow's depth (0.27-0.31).
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(200.3, 150.4, 45.0, 42.0, 0.3);
    for (share, width, seed) in [(0.5, 0.3, 2), (0.55, 0.25, 4)] {
        let mut scene = Scene::new(truth);
        scene.throat_shadow = Some((share, width));
        let img = scene.render(w, h, 2.0, seed);
        let found = detector(&cam)
            .detect(&img, None)
            .unwrap_or_else(|| panic!("not detected with a shadow of {share} over {width} radii"));
        assert!(truth.max_param_error_px(&fit_points(&found)) < 1.0);
    }
}

/// The probe's rounded end over the middle of a hazed disc, its shaft
/// running out across the lower rim and the hose across the upper one (as
/// `hard/frame_0000` of the reference renderer): the probe, nearer and less
/// hazed, is far darker than the disc. The disc's ellipse and the scene.
fn probe_tip_in_hazed_disc() -> (Ellipse, Scene) {
    let truth = Ellipse::new(190.6, 130.2, 44.0, 40.0, 0.3);
    let mut scene = Scene::new(truth);
    scene.disc_level = 95.0;
    scene.canopy_level = 150.0;
    scene.band_level = 120.0;
    scene.sky_level = 160.0;
    let tip = [truth.cx + 3.0, truth.cy + 14.0];
    scene.tip = Some((tip, 25.0, 20.0));
    scene.bar = Some((tip, 25.0, 20.0));
    scene.hose = Some(([truth.cx + 10.0, truth.cy], 200.0, 12.0, 60.0));
    (truth, scene)
}

/// Each of six noise draws of `scene` (400x300, noise 7) gives `truth`: the
/// detector's own ellipse, whose trimmed fit leaves out the rim points
/// beside the probe's outline, as the measurement's adaptive fit does.
fn assert_found_on_every_draw(scene: &Scene, truth: &Ellipse) {
    let cam = camera(400, 300);
    for seed in 2..8 {
        let img = scene.render(400, 300, 7.0, seed);
        let found = detector(&cam).detect(&img, None);
        let found = found.unwrap_or_else(|| panic!("noise seed {seed}: not found"));
        assert_near(&found.ellipse_px, truth, 0.5, 0.5);
    }
}

/// From a point inside the disc the probe tip's outline is the strongest
/// step, and the tip is dropped as a circle inside a larger dark shape. The
/// edge source's circle for the disc, looked for again from half its radius
/// outward, finds the disc (before, noise draw 3 was missed).
#[test]
fn a_probe_ending_inside_a_hazed_disc_leaves_the_disc_found() {
    let (truth, scene) = probe_tip_in_hazed_disc();
    assert_found_on_every_draw(&scene, &truth);
}

/// The same disc with a small dark spot on the sky: the spot verifies first
/// (a dark region), as a far disc whose canopy is too small to judge, and
/// scores well below `accept_score`. It must not end the search: the
/// circles looked for past what lies inside them still run, and the disc,
/// scoring higher, is the answer (before, the spot was: a wrong pose).
#[test]
fn a_weak_candidate_does_not_stop_the_search_for_the_disc() {
    let (truth, mut scene) = probe_tip_in_hazed_disc();
    scene.spots.push(([340.0, 60.0], 7.0, 40.0));
    assert_found_on_every_draw(&scene, &truth);
}

/// `rim_point_spacing_px` sets the density of the measuring pass only: a ray
/// on every pixel of the rim (1 px, the default) instead of every other one
/// (2 px, as a tracked frame measures) finds the same disc, verified on the
/// same 2 px rays (the detector's own ellipse is the very same), and the
/// ellipse fitted to its points is closer: at least as much as the square
/// root of the number of rays says for independent pixels' noise (0.71;
/// 0.48 on these 16 noise draws, 0.025 -> 0.012 px rms).
#[test]
fn a_ray_on_every_rim_pixel_measures_the_centre_closer() {
    let (w, h) = (320, 240);
    let cam = camera(w, h);
    let truth = Ellipse::new(158.3, 121.6, 38.0, 31.0, 0.4);
    let cfg = Config::embedded();
    let dense_cfg = cfg.detect.clone();
    assert_eq!(dense_cfg.rim_point_spacing_px, 1.0, "the default spacing");
    let mut sparse_cfg = cfg.detect.clone();
    sparse_cfg.rim_point_spacing_px = 2.0;
    let circles = crate::testing::drogue_circles(&cfg);
    let mut fitter = crate::measure::fit::Fitter::new(&cfg.fit);
    let (mut sparse, mut dense) = (0.0, 0.0);
    let draws = 16;
    for seed in 0..draws {
        let img = Scene::new(truth).render(w, h, 8.0, 300 + seed);
        let found = |detect: &DetectConfig| {
            Detector::new(detect, &cam, circles)
                .detect(&img, None)
                .expect("the disc is found")
        };
        let (sparse_found, dense_found) = (found(&sparse_cfg), found(&dense_cfg));
        assert_eq!(
            dense_found.ellipse_px, sparse_found.ellipse_px,
            "seed {seed}: the same disc, verified on the same rays"
        );
        assert!(
            dense_found.rim_points_px.len() > 3 * sparse_found.rim_points_px.len() / 2,
            "seed {seed}: {} points at 1 px, {} at 2 px",
            dense_found.rim_points_px.len(),
            sparse_found.rim_points_px.len()
        );
        let mut centre_error = |c: &RimCandidate| {
            let e = fitter
                .fit(&c.rim_points_undistorted_px, seed)
                .expect("an ellipse through the rim")
                .ellipse;
            (e.cx - truth.cx).powi(2) + (e.cy - truth.cy).powi(2)
        };
        sparse += centre_error(&sparse_found);
        dense += centre_error(&dense_found);
    }
    let ratio = (dense / sparse).sqrt();
    let rms = (sparse / draws as f64).sqrt();
    assert!(
        ratio < 0.85,
        "rms centre error dense / sparse {ratio:.2} (sparse {rms:.4} px)"
    );
}

/// A tracked frame keeps the noise measured on the frames before it and
/// measures it afresh on every `TRACKED_NOISE_EVERY`th: when the noise
/// rises from 2 to 12 gray levels (a camera's gain raised), the estimate
/// follows within that many frames, and the disc is measured on each.
#[test]
fn tracked_frames_follow_a_change_of_noise_within_a_few_frames() {
    let (w, h) = (320, 240);
    let cam = camera(w, h);
    let truth = Ellipse::new(158.3, 121.6, 38.0, 31.0, 0.4);
    let mut det = detector(&cam);
    let quiet = Scene::new(truth).render(w, h, 2.0, 41);
    assert!(det.detect(&quiet, None).is_some());
    let quiet_noise = det.noise_gray;
    let mut noisy_frames = (0..super::TRACKED_NOISE_EVERY)
        .map(|k| Scene::new(truth).render(w, h, 12.0, 50 + u64::from(k)));
    let first = noisy_frames.next().unwrap();
    assert!(det.detect(&first, Some(&truth)).is_some());
    assert_eq!(
        det.noise_gray, quiet_noise,
        "the first tracked frame keeps the estimate"
    );
    for img in noisy_frames {
        assert!(det.detect(&img, Some(&truth)).is_some());
    }
    // Measured afresh by now: near 12 (the estimate's bins are 0.6 apart).
    assert!(
        (det.noise_gray - 12.0).abs() < 1.5 && quiet_noise < 3.5,
        "noise {} after {} tracked frames, {quiet_noise} before",
        det.noise_gray,
        super::TRACKED_NOISE_EVERY
    );
}

/// A sun-glare streak added to a frame: light falling off as a Gaussian
/// (full width at half maximum `fwhm_px`) from the line through `through`
/// at `angle`, `peak` gray levels at the line, clipped at 255 as a sensor
/// saturates.
fn add_glare_streak(
    img: &GrayImage,
    through: [f64; 2],
    angle: f64,
    fwhm_px: f64,
    peak: f64,
) -> GrayImage {
    let sigma = fwhm_px / (2.0 * (2.0 * 2f64.ln()).sqrt());
    let (s, c) = angle.sin_cos();
    GrayImage::from_fn(img.width(), img.height(), |x, y| {
        let d = -(f64::from(x) - through[0]) * s + (f64::from(y) - through[1]) * c;
        let glare = peak * (-0.5 * (d / sigma).powi(2)).exp();
        Luma([(f64::from(img.get_pixel(x, y)[0]) + glare)
            .round()
            .clamp(0.0, 255.0) as u8])
    })
}

/// A glare streak 30 px wide across the middle of a 31 px disc (the
/// robustness sweep's widest): its core saturates the disc's centre and its
/// skirt lightens the rest of the disc smoothly, above the rim's mid level
/// on most of the fill test's rays. Those rays run through saturated pixels:
/// they look into the glare and count neither way, and the disc is found
/// from its two visible arcs.
#[test]
fn a_disc_under_a_wide_glare_streak_is_found() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(201.3, 148.7, 31.0, 29.5, 0.2);
    let sharp = Scene::new(truth).render(w, h, 2.0, 41);
    let img = add_glare_streak(&sharp, [truth.cx, truth.cy], 0.8, 30.0, 400.0);
    let cand = detector(&cam).detect(&img, None).expect("detected");
    assert_near(&cand.ellipse_px, &truth, 0.5, 0.5);
}

/// An overexposed canopy (saturated all round the disc) does not make its
/// own outer rim pass for the disc: the fill test leaves out its rays
/// through saturated pixels, so the rim around the canopy is not judged by
/// it, and the other tests (the canopy beyond it, the disc inside it)
/// decide. The disc is found at its own size.
#[test]
fn an_overexposed_canopy_is_not_taken_for_the_disc() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(198.2, 151.4, 30.0, 27.0, -0.3);
    let mut scene = Scene::new(truth);
    scene.canopy_level = 255.0;
    let img = scene.render(w, h, 2.0, 42);
    let cand = detector(&cam).detect(&img, None).expect("detected");
    let e = cand.ellipse_px;
    assert!(
        (e.a / truth.a - 1.0).abs() < 0.02 && (e.b / truth.b - 1.0).abs() < 0.02,
        "{e:?}"
    );
}

/// A glare streak whose core over the disc stays just below saturation
/// (it saturates over the lighter canopy only): the disc's inside under it
/// is lighter than the canopy beside the rim, which no hole in a dark shape
/// can show (a hole shows the background, at the rim's light level). Those
/// samples are a veil and count neither way. Counted as light inside (as
/// before), they failed the disc on all four of these streaks.
#[test]
fn a_veil_lighter_than_the_canopy_does_not_count_as_light_inside() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(201.3, 148.7, 31.0, 29.5, 0.2);
    let sharp = Scene::new(truth).render(w, h, 2.0, 43);
    for peak in [210.0, 215.0] {
        for off_px in [0.0, 2.0] {
            let img = add_glare_streak(&sharp, [truth.cx + off_px, truth.cy], 1.9, 30.0, peak);
            let cand = detector(&cam)
                .detect(&img, None)
                .unwrap_or_else(|| panic!("not detected under a streak of {peak} at {off_px} px"));
            assert_near(&cand.ellipse_px, &truth, 0.5, 0.5);
        }
    }
}

/// A disc tilted 75 degrees (the largest tilt `min_axis_ratio` accepts)
/// 22 degrees off the optical axis, its long axis radial, images at an axis
/// ratio of 0.249 (the simulator's frame: 70.0 x 17.4 px at (150, 237)),
/// below cos 75 = 0.259: the oblique image plane stretches it radially by
/// 1 / cos 22. Taken out, it is plausible. The same shape with its long axis
/// across the radial direction, or at the image centre, is flatter than any
/// disc within 75 degrees and is not.
#[test]
fn the_axis_ratio_is_judged_along_the_line_of_sight() {
    let cam = camera(1280, 960);
    let detector = detector(&cam);
    let (cx, cy) = (150.1, 237.4);
    let radial = (cy - 480.0f64).atan2(cx - 640.0);
    let along = Ellipse::new(cx, cy, 70.0, 17.4, radial);
    assert!(detector.plausible(&along, 1.0));
    let across = Ellipse::new(cx, cy, 70.0, 17.4, radial + std::f64::consts::FRAC_PI_2);
    assert!(!detector.plausible(&across, 1.0));
    let centred = Ellipse::new(640.0, 480.0, 70.0, 17.4, radial);
    assert!(!detector.plausible(&centred, 1.0));
    // Within 75 degrees at the centre: plausible as before.
    let round_enough = Ellipse::new(640.0, 480.0, 70.0, 18.2, radial);
    assert!(detector.plausible(&round_enough, 1.0));
}

/// A candidate whose canopy rim shows nearly all round is the drogue even
/// when part of its own rim is hidden and it scores below `accept_score`:
/// it ends the search ([`search::CANOPY_CONFIRMS`]). Two drogues side by
/// side: the larger, tried first, has a bite of canopy taken out of its
/// disc; the smaller, clear one, which verifies above `accept_score` on
/// its own, is then not verified.
#[test]
fn a_candidate_its_canopy_confirms_ends_the_search() {
    let (w, h) = (800, 300);
    let cam = camera(w, h);
    let accept = Config::embedded().detect.accept_score;
    let big = Ellipse::new(200.0, 150.0, 50.0, 48.0, 0.0);
    let mut bitten = Scene::new(big);
    bitten.bite = Some(([200.0, 190.0], 40.0));
    let left = bitten.render(w, h, 2.0, 3);
    let small = Ellipse::new(600.0, 150.0, 30.0, 29.0, 0.0);
    let right = Scene::new(small).render(w, h, 2.0, 4);
    // The clear drogue alone is a candidate that ends the search by score.
    let alone = detector(&cam).verify_candidates(&right, accept);
    assert!(
        alone.iter().any(|v| v.score >= accept),
        "{:?}",
        scores(&alone)
    );
    let both = GrayImage::from_fn(w, h, |x, y| {
        if x < w / 2 {
            *left.get_pixel(x, y)
        } else {
            *right.get_pixel(x, y)
        }
    });
    let verified = detector(&cam).verify_candidates(&both, accept);
    assert_eq!(verified.len(), 1, "{:?}", scores(&verified));
    let v = &verified[0];
    assert!(
        (v.ellipse.cx - big.cx).hypot(v.ellipse.cy - big.cy) < 5.0,
        "{:?}",
        v.ellipse
    );
    assert!(v.score < accept, "{}", v.score);
    assert!(
        v.canopy.is_some_and(|c| c >= search::CANOPY_CONFIRMS),
        "{:?}",
        v.canopy
    );
}

/// (score, canopy evidence) of each verified candidate.
fn scores(verified: &[Verified]) -> Vec<(f64, Option<f64>)> {
    verified.iter().map(|v| (v.score, v.canopy)).collect()
}

/// A frame without the drogue says why, as the candidate that came closest
/// failed: nothing dark in a clear sky is no candidate; a dark disc without
/// its canopy has none.
#[test]
fn a_frame_without_the_drogue_says_why() {
    use crate::measure::miss::MissReason;
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let why = |img: &GrayImage| match detector(&cam).detect_explained(img, None) {
        Ok(c) => panic!("detected at {:?}", c.ellipse_px),
        Err(miss) => miss,
    };
    let mut sky = Scene::new(Ellipse::new(0.0, 0.0, 0.0, 0.0, 0.0));
    sky.with_canopy = false;
    let clear = why(&sky.render(w, h, 2.0, 21));
    assert_eq!(
        (clear.reason.clone(), clear.candidates),
        (MissReason::NoCandidate, 0)
    );

    let mut bare = Scene::new(Ellipse::new(190.0, 140.0, 36.0, 30.0, 0.3));
    bare.with_canopy = false;
    let miss = why(&bare.render(w, h, 2.0, 12));
    assert!(matches!(miss.reason, MissReason::NoCanopy(_)), "{miss:?}");
    assert!(miss.candidates > 0);
}

/// The reason kept is the furthest any candidate got through the checks
/// (their order in verification), the first of equals; a candidate found
/// again in another form says nothing, and a kept one counts as tried.
#[test]
fn the_reason_is_the_candidate_that_got_furthest() {
    use super::{Misses, Reject};
    use crate::measure::miss::MissReason;
    let mut m = Misses::default();
    assert_eq!(m.reason(), MissReason::NoCandidate);
    for outcome in [
        Err(Reject::NoRim(2)),
        Err(Reject::LightInside(0.3)),
        Err(Reject::Known),
        Err(Reject::FewInliers(5)),
        Err(Reject::LightInside(0.1)),
        Ok(()),
    ] {
        m.tried(outcome);
    }
    assert_eq!(m.candidates, 6);
    assert_eq!(m.reason(), MissReason::LightInside(0.3));
    m.tried(Err(Reject::Blurred(0.6)));
    assert_eq!(m.reason(), MissReason::Blurred(0.6));
    m.tried(Err(Reject::NoCanopy(0.2)));
    assert_eq!(m.reason(), MissReason::NoCanopy(0.2));
}

/// A seed inside the canopy of a candidate that verified with its canopy
/// shown beyond doubt is that drogue's (its disc, probe or canopy) and is
/// not tried; one outside it, or beside a candidate whose canopy share is
/// within the doubt of reading 48 points (2 binomial sigmas about the
/// share needed: `2 sqrt(0.5 * 0.5 / 48)` = 0.144 at 0.5), is. The canopy
/// rim is the candidate's ellipse scaled by `R / r` (0.33 / 0.15).
#[test]
fn seeds_inside_a_drogue_its_canopy_shows_are_not_tried_again() {
    let cam = camera(1280, 960);
    let d = detector(&cam);
    let needed = Config::embedded().detect.min_canopy_fraction;
    assert_eq!(needed, 0.5, "the doubt below is worked out at 0.5");
    let doubt = 2.0 * (0.25f64 / 48.0).sqrt();
    assert!(!canopy::shown_beyond_doubt(needed + doubt - 1e-3, needed));
    assert!(canopy::shown_beyond_doubt(needed + doubt + 1e-3, needed));

    let e = Ellipse::new(600.0, 400.0, 40.0, 20.0, 0.5);
    let with_canopy = |canopy: Option<f64>| Verified {
        ellipse: e,
        points_px: Vec::new(),
        undistorted: Vec::new(),
        score: 0.6,
        rim_contrast: 100.0,
        step_widths_px: Vec::new(),
        clip_px: Vec::new(),
        canopy,
    };
    let seed_at = |along_major: f64, along_minor: f64| {
        let (s, c) = e.theta.sin_cos();
        search::Seed {
            centre_px: [
                e.cx + along_major * c - along_minor * s,
                e.cy + along_major * s + along_minor * c,
            ],
            a_px: 10.0,
            b_px: 10.0,
            theta: 0.0,
            reach: 1.8,
            from: 0.0,
            kind: 3,
        }
    };
    let ratio = 0.33 / 0.15;
    let shown = with_canopy(Some(0.7));
    for (inside, seed) in [
        (true, seed_at(0.0, 0.0)),
        (true, seed_at(0.98 * ratio * e.a, 0.0)),
        (false, seed_at(1.02 * ratio * e.a, 0.0)),
        (true, seed_at(0.0, -0.98 * ratio * e.b)),
        (false, seed_at(0.0, -1.02 * ratio * e.b)),
    ] {
        assert_eq!(
            d.within_shown_canopy(&shown, &seed),
            inside,
            "{:?}",
            seed.centre_px
        );
    }
    let centre = seed_at(0.0, 0.0);
    assert!(!d.within_shown_canopy(&with_canopy(Some(0.6)), &centre));
    assert!(!d.within_shown_canopy(&with_canopy(None), &centre));
}

/// A glare streak across a small disc whose core saturates only near the
/// disc's centre: beside the saturated samples its skirt lifts the inside
/// above the rim's mid level, falling off toward the rim. On the fill
/// test's directions that miss the saturated core, those samples are the
/// glare's skirt, not a light inside; counted as light, they failed each
/// of these discs as `LightInside` (three of 300 streaks over three discs,
/// 12-20 px wide, 240-300 gray levels at their peak; of the others, 294
/// are found either way and three missed either way).
#[test]
fn a_glare_skirt_beside_its_saturated_core_does_not_count_as_light_inside() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    for (seed, truth, angle) in [
        (50, Ellipse::new(201.3, 148.7, 27.0, 15.0, 0.2), 2.8),
        (52, Ellipse::new(200.4, 149.3, 22.0, 18.0, -0.7), 2.2),
        (52, Ellipse::new(200.4, 149.3, 22.0, 18.0, -0.7), 2.8),
    ] {
        let sharp = Scene::new(truth).render(w, h, 6.0, seed);
        let img = add_glare_streak(&sharp, [truth.cx, truth.cy - 3.0], angle, 20.0, 240.0);
        let cand = detector(&cam)
            .detect(&img, None)
            .unwrap_or_else(|| panic!("{truth:?} not detected under a streak at {angle} rad"));
        assert_near(&cand.ellipse_px, &truth, 1.0, 1.0);
    }
}

/// A tracked frame's pass counts as settled once it moved by a quarter of
/// its narrowest window: the steps a window centred that far off finds are
/// those a centred one finds. From a prediction 0.9 px off in centre and
/// size (the window here is 4 px each way, so one pass is kept), the rim
/// gives the disc as from the exact prediction.
#[test]
fn a_tracked_pass_from_a_prediction_a_pixel_off_measures_the_same_rim() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(201.3, 152.6, 40.0, 34.0, 0.3);
    let img = Scene::new(truth).render(w, h, 2.0, 11);
    let mut det = detector(&cam);
    let exact = det.verify_tracked(&img, &truth, None).expect("verified");
    let off = Ellipse::new(202.2, 151.7, 40.9, 34.9, 0.3);
    let moved = det.verify_tracked(&img, &off, None).expect("verified");
    let fitted = |v: &super::Verified| conic_fit::fit_ellipse(&v.points_px).unwrap();
    let (from_exact, from_off) = (fitted(&exact), fitted(&moved));
    assert_near(&from_exact, &truth, 0.05, 0.05);
    assert_near(&from_off, &truth, 0.05, 0.05);
    assert!(
        from_off.max_param_error_px(&from_exact) < 0.02,
        "{from_off:?} against {from_exact:?}"
    );
}

/// The rim's travel over an exposure in which `truth` moves by `blur`
/// (pixels), centred on it.
fn swept(truth: &Ellipse, blur: [f64; 2]) -> ExposureSweep {
    let at = |k: f64| Ellipse {
        cx: truth.cx + k * blur[0],
        cy: truth.cy + k * blur[1],
        ..*truth
    };
    ExposureSweep {
        start: at(-0.5),
        end: at(0.5),
    }
}

#[test]
fn the_window_a_tracked_motion_predicts_is_the_one_the_pass_widens_to() {
    // Discs drawn with linear motion blur (the blur is the motion: the
    // truth), from none to more than the disc's radius: the window the
    // motion predicts is the one the narrow pass settles on by widening,
    // and the pass that starts there measures the same rim.
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(198.3, 151.7, 45.0, 42.0, 0.3);
    let sharp = Scene::new(truth).render(w, h, 0.0, 13);
    let mut widths = Vec::new();
    for (length, angle_deg) in [
        (0.0, 0.0),
        (4.0, 10.0),
        (6.0, 70.0),
        (8.0, 10.0),
        (14.0, 70.0),
        (18.0, 10.0),
        (24.0, 30.0),
        (40.0, 120.0),
    ] {
        let (s, c) = f64::to_radians(angle_deg).sin_cos();
        let blur = [length * c, length * s];
        let img = if length > 0.0 {
            add_noise(&motion_blur(&sharp, blur[0], blur[1], 64), 2.0, 5)
        } else {
            add_noise(&sharp, 2.0, 5)
        };
        let mut det = detector(&cam);
        let found = det
            .rim_pass(&img, &truth, 1.0, 400, RimUse::Measure, 1.0)
            .expect("the pass from 1");
        let predicted = det.widen_for_motion(&truth, &swept(&truth, blur));
        assert_eq!(predicted, found.widened, "{length} px at {angle_deg} deg");
        let started = det
            .rim_pass(&img, &truth, 1.0, 400, RimUse::Measure, predicted)
            .expect("the pass from the prediction");
        assert_eq!(started.points_px, found.points_px, "{length} px");
        widths.push(predicted);
    }
    // The blurs span every window: none widened, once, and to the widest.
    assert_eq!(widths.first(), Some(&1.0));
    assert!(widths.contains(&WIDEN_STEP), "{widths:?}");
    assert_eq!(widths.last(), Some(&MAX_WIDEN));
}

/// The probe passing just outside the rim (2 px from it at the closest):
/// the canopy beyond the rim's steps there is a narrow strip, the light
/// level each step takes a little beyond it falls into the probe's dark,
/// and its crossing moves in, away from the probe. Those steps are left out
/// of the measured rim ([`super::shading::beside_dark`],
/// [`super::shading::better_without`]): with them the centre moves 0.008 px
/// away from the probe on every draw; without them, by less than 0.001 px.
#[test]
fn a_probe_just_outside_the_rim_does_not_pull_it_in() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(200.3, 150.6, 45.2, 40.1, 0.0);
    let mut scene = Scene::new(truth);
    // A bar from above the centre down, its left side 2 px right of the
    // rim's rightmost point.
    let half_width = 8.0;
    scene.bar = Some((
        [truth.cx + truth.a + 2.0 + half_width, 90.0],
        half_width,
        40.0,
    ));
    let draws = 6;
    let mut toward_probe = 0.0;
    for seed in 0..draws {
        let img = scene.render(w, h, 2.0, 40 + seed);
        let c = detector(&cam).detect(&img, None).expect("detected");
        let e = fit_points(&c);
        assert_near(&e, &truth, 0.02, 0.05);
        toward_probe += (e.cx - truth.cx) / draws as f64;
    }
    assert!(
        toward_probe.abs() < 0.003,
        "the centre moves {toward_probe:.4} px toward the probe on average"
    );
}

/// A probe over the lower rim of a disc with the light collar behind its
/// nozzle lying across that rim, starting 2 px inside it: on the rays down
/// the probe the only rise is onto the collar (the probe hides the canopy),
/// and past the collar the probe's dark comes back. Those steps are the
/// collar's, not the rim's, and are left out of the points the pose is
/// measured from (`verify::Detector::bands_within_dark`). Before, they
/// were among them, 2 px inside the rim, where the points measured are
/// not trimmed.
#[test]
fn the_steps_onto_a_probe_collar_are_not_measured() {
    let (w, h) = (400, 300);
    let cam = camera(w, h);
    let truth = Ellipse::new(200.3, 140.6, 50.0, 48.0, 0.0);
    let mut scene = Scene::new(truth);
    let tip = [truth.cx + 5.0, truth.cy];
    scene.bar = Some((tip, 20.0, 40.0));
    let collar_top = truth.cy + truth.b - 2.0;
    scene.patches = vec![(
        [tip[0] - 20.0, collar_top, tip[0] + 20.0, collar_top + 8.0],
        80.0,
    )];
    let img = scene.render(w, h, 2.0, 31);
    let cand = detector(&cam).detect(&img, None).expect("detected");
    // The rays down the probe's middle (clear of its sides, whose steps
    // are the occluder's outline's): none of their points on the collar.
    let on_collar: Vec<[f64; 2]> = cand
        .rim_points_undistorted_px
        .iter()
        .copied()
        .filter(|p| (p[0] - tip[0]).abs() < 15.0 && (p[1] - collar_top).abs() < 1.0)
        .collect();
    assert!(
        on_collar.is_empty(),
        "{} points on the collar: {on_collar:?}",
        on_collar.len()
    );
    // And the rim's own points are kept: most of the rim is measured.
    assert!(cand.rim_points_undistorted_px.len() > 100);
}
