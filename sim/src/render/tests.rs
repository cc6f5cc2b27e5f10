//! The fast paths checked against the straightforward ones they replace:
//! every pixel tested against every primitive (the renderer as it was before
//! spans, cached fragments, strut climbing and precomputed blur taps), and
//! the float to byte conversions against Rust's own casts.

use super::drogue::nearest_strut;
use super::sensor::{dn_to_u8, floor_dn};
use super::sky::floor_f64;
use super::tube::TubeAxis;
use super::*;
use crate::{Scenario, Simulator};

/// A scene of a built-in scenario at frame `seq` and its camera.
fn scene_at(name: &str, seq: u64) -> (SimCamera, FrameScene) {
    let mut sim = Simulator::new(Scenario::builtin(name).unwrap()).unwrap();
    for _ in 0..seq {
        sim.next_truth().unwrap();
    }
    sim.next_frame().unwrap();
    (sim.camera().clone(), sim.last_scene().unwrap().clone())
}

fn look() -> Look {
    Look {
        sky_zenith: 0.55,
        sky_horizon: 0.75,
        ground: 0.3,
        cloud_cover: 0.0,
        cloud_radiance: 0.8,
        sun_ned: V3::new(1.0, 0.0, 0.0),
        glare: 0.0,
        haze: 0.1,
        haze_radiance: 0.7,
        gain: 1.0,
        read_noise_dn: 0.0,
        shot_noise_dn: 0.0,
        vignette: 0.0,
        cloud_seed: 1,
    }
}

/// A radiance frame with a varied background, so blending shows.
fn background(r: &Renderer) -> Vec<f32> {
    (0..r.w * r.h)
        .map(|i| 0.3 + 0.4 * ((i * 7919) % 1000) as f32 / 1000.0)
        .collect()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// The drogue turned about its e1 axis by `deg` (an oblique view) with
/// `struts` struts.
fn oblique(d: &DrogueView, deg: f64, struts: u32) -> DrogueView {
    let (s, c) = deg.to_radians().sin_cos();
    DrogueView {
        normal: d.normal * c + d.e2 * s,
        e2: d.e2 * c - d.normal * s,
        struts,
        ..*d
    }
}

/// The drogue as the renderer drew it before: every box pixel with its full
/// footprint, all struts, the disc's inside through the canopy terms.
fn reference_drogue(r: &Renderer, rad: &mut [f32], d: &DrogueView, b: PixelBox) {
    let nc = d.normal.dot(&d.centre);
    if nc >= 0.0 {
        return;
    }
    let strut_dirs: Vec<(f64, f64)> = (0..d.struts)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / d.struts as f64;
            (a.cos(), a.sin())
        })
        .collect();
    let half_strut = d.strut_width * 0.5;
    let disc = r.haze(d.disc) as f32;
    for v in b.1..=b.3 {
        for u in b.0..=b.2 {
            let ray = r.ray(u, v);
            let nd = d.normal.dot(&ray);
            if nd >= -1e-12 {
                continue;
            }
            let t = nc / nd;
            let q = ray * t - d.centre;
            let (x, y) = (q.dot(&d.e1), q.dot(&d.e2));
            let rho = (x * x + y * y).sqrt();
            if rho > d.canopy_radius * 1.03 {
                continue;
            }
            let (su, sv) = r.ray_steps(u, v);
            let dx_du = (su - ray * (d.normal.dot(&su) / nd)) * t;
            let dx_dv = (sv - ray * (d.normal.dot(&sv) / nd)) * t;
            let radial = if rho > 1e-9 {
                (d.e1 * x + d.e2 * y) / rho
            } else {
                d.e1
            };
            let s = (dx_du.dot(&radial).powi(2) + dx_dv.dot(&radial).powi(2))
                .sqrt()
                .max(1e-12);
            let alpha = clamp01(0.5 - (rho - d.canopy_radius) / s);
            if alpha <= 0.0 {
                continue;
            }
            let mut val = d.canopy_radiance(rho, x);
            let mut perp_min = f64::INFINITY;
            for &(c, sn) in &strut_dirs {
                if x * c + y * sn > 0.0 {
                    perp_min = perp_min.min((-x * sn + y * c).abs());
                }
            }
            let strut_cov = clamp01(0.5 - (perp_min - half_strut) / s);
            val += (d.strut - val) * strut_cov;
            let rim_cov = clamp01(0.5 + (rho - (d.canopy_radius - d.rim_width)) / s);
            val += (d.rim - val) * rim_cov;
            let edge = (rho - d.inner_radius) / s;
            let disc_cov = if edge.abs() < 1.2 {
                let mut n = 0;
                for j in 0..4 {
                    for i in 0..4 {
                        let (du, dv) = ((i as f64 - 1.5) / 4.0, (j as f64 - 1.5) / 4.0);
                        let r2 = ray + su * du + sv * dv;
                        let t2 = nc / d.normal.dot(&r2);
                        let q2 = r2 * t2 - d.centre;
                        if q2.norm_squared() < d.inner_radius * d.inner_radius {
                            n += 1;
                        }
                    }
                }
                n as f64 / 16.0
            } else if edge < 0.0 {
                1.0
            } else {
                0.0
            };
            let val = r.haze(val) as f32;
            let val = val + (disc - val) * disc_cov as f32;
            let o = &mut rad[v * r.w + u];
            *o += (val - *o) * alpha as f32;
        }
    }
}

/// A tube as the renderer drew it before: straight into the frame, the
/// drogue tested at every covered pixel.
fn reference_tube(r: &Renderer, rad: &mut [f32], tube: &Tube, in_front_of: Option<&DrogueView>) {
    let Some(axis) = TubeAxis::new(tube) else {
        return;
    };
    let px = 1.0 / r.cam.fx;
    for (v, u0, u1) in r.tube_spans(tube) {
        for u in u0..=u1 {
            let ray = r.ray(u, v);
            let Some((t, sd, k)) = axis.probe_ray(&ray) else {
                continue;
            };
            let Some((_, s, _)) = axis.closest(&ray) else {
                continue;
            };
            let base = tube.radiance_at(s, axis.len);
            let cov = clamp01(0.5 - sd / (t * px));
            if cov <= 0.0 {
                continue;
            }
            if let Some(d) = in_front_of {
                let nd = d.normal.dot(&ray);
                if nd < 0.0 {
                    let tp = d.normal.dot(&d.centre) / nd;
                    if tp > 0.0 && tp < t && (ray * tp - d.centre).norm() < d.canopy_radius {
                        continue;
                    }
                }
            }
            let k = k.min(1.0);
            let shade = base * (0.7 + 0.45 * (1.0 - k * k).sqrt())
                + 0.25 * base * (-((k - 0.45) / 0.12).powi(2)).exp();
            let val = r.haze(shade) as f32;
            let o = &mut rad[v * r.w + u];
            *o += (val - *o) * cov as f32;
        }
    }
}

/// The motion blur as it was: every tap of every pixel bilinear with
/// clamping.
fn reference_blur(r: &Renderer, rad: &mut [f32], b: PixelBox, m: [f64; 2]) {
    let len = (m[0] * m[0] + m[1] * m[1]).sqrt();
    let pad = (len / 2.0).ceil() as usize + 2;
    let (u0, v0) = (b.0.saturating_sub(pad), b.1.saturating_sub(pad));
    let (u1, v1) = ((b.2 + pad).min(r.w - 1), (b.3 + pad).min(r.h - 1));
    let (bw, bh) = (u1 - u0 + 1, v1 - v0 + 1);
    let mut src = Vec::new();
    for v in v0..=v1 {
        src.extend_from_slice(&rad[v * r.w + u0..=v * r.w + u1]);
    }
    let taps = ((2.0 * len).ceil() as usize + 1).max(3);
    let sample = |x: f64, y: f64| -> f32 {
        let x = x.clamp(0.0, (bw - 1) as f64);
        let y = y.clamp(0.0, (bh - 1) as f64);
        let (xi, yi) = (
            (x as usize).min(bw.saturating_sub(2)),
            (y as usize).min(bh.saturating_sub(2)),
        );
        let (fx, fy) = ((x - xi as f64) as f32, (y - yi as f64) as f32);
        let p = |xx: usize, yy: usize| src[(yy.min(bh - 1)) * bw + xx.min(bw - 1)];
        let top = p(xi, yi) + (p(xi + 1, yi) - p(xi, yi)) * fx;
        let bot = p(xi, yi + 1) + (p(xi + 1, yi + 1) - p(xi, yi + 1)) * fx;
        top + (bot - top) * fy
    };
    for y in 0..bh {
        for x in 0..bw {
            let mut acc = 0.0;
            for k in 0..taps {
                let f = k as f64 / (taps - 1) as f64 - 0.5;
                acc += sample(x as f64 + m[0] * f, y as f64 + m[1] * f);
            }
            rad[(v0 + y) * r.w + u0 + x] = acc / taps as f32;
        }
    }
}

#[test]
fn drogue_matches_the_every_pixel_reference() {
    let mut cases = Vec::new();
    for (name, seq) in [("contact", 170), ("approach", 0), ("approach", 400)] {
        let (cam, scene) = scene_at(name, seq);
        cases.push((cam.clone(), scene.drogue));
        // Oblique views with an odd and a small strut count, and none.
        for (deg, struts) in [(55.0, 5), (70.0, 3), (30.0, 0)] {
            cases.push((cam.clone(), oblique(&scene.drogue, deg, struts)));
        }
        // And in its throat's shadow.
        let shaded = DrogueView {
            throat_shade: 0.3,
            throat_shade_width: 0.03,
            ..scene.drogue
        };
        cases.push((cam.clone(), shaded));
    }
    let mut renderers: Vec<(SimCamera, Renderer)> = Vec::new();
    for (cam, d) in &cases {
        if !renderers.iter().any(|(c, _)| c == cam) {
            renderers.push((cam.clone(), Renderer::new(cam, look())));
        }
        let r = &renderers.iter().find(|(c, _)| c == cam).unwrap().1;
        let b = r.drogue_bbox(d).expect("drogue in view");
        let (mut fast, mut slow) = (background(r), background(r));
        r.draw_drogue(&mut fast, d, b);
        reference_drogue(r, &mut slow, d, b);
        let changed = fast
            .iter()
            .zip(background(r))
            .filter(|(a, b)| *a != b)
            .count();
        assert!(changed > 500, "the drogue was drawn: {changed} px");
        // Radiance is 0..1 and one digital number about 0.004: the paths
        // may differ by rounding only.
        let diff = max_abs_diff(&fast, &slow);
        assert!(diff < 1e-6, "{d:?}: max difference {diff}");
    }
}

#[test]
fn the_throat_shadow_darkens_the_canopy_toward_the_disc() {
    let (_, scene) = scene_at("approach", 0);
    let plain = DrogueView {
        throat_shade: 0.0,
        ..scene.drogue
    };
    let shaded = DrogueView {
        throat_shade: 0.3,
        throat_shade_width: 0.02,
        ..scene.drogue
    };
    let r = plain.inner_radius;
    // At the disc's edge the shadow's share is lost; one e-folding width
    // out, that share over e; five widths out, under 1 %.
    for (rho, lost) in [(r, 0.3), (r + 0.02, 0.3 / std::f64::consts::E)] {
        let ratio = shaded.canopy_radiance(rho, 0.0) / plain.canopy_radiance(rho, 0.0);
        assert!((1.0 - ratio - lost).abs() < 1e-12, "{rho}: {ratio}");
    }
    let far = shaded.canopy_radiance(r + 0.1, 0.05) / plain.canopy_radiance(r + 0.1, 0.05);
    assert!(far > 0.99 && far < 1.0, "{far}");
    // Without a shadow, the canopy's own shading: 82 % of its radiance at
    // the disc, all of it at the rim.
    let (c, rim) = (plain.canopy, plain.canopy_radius);
    assert!((plain.canopy_radiance(r, 0.0) - 0.82 * c).abs() < 1e-12);
    assert!((plain.canopy_radiance(rim, 0.0) - c).abs() < 1e-12);
}

#[test]
fn tube_fragments_match_the_every_pixel_reference() {
    let (cam, scene) = scene_at("contact", 170);
    let r = Renderer::new(&cam, look());
    let d = scene.drogue;
    let b = r.drogue_bbox(&d);
    let hose = scene.hose.and_then(|t| t.clipped(0.05)).unwrap();
    let probe = scene.probe.and_then(|t| t.clipped(0.05)).unwrap();
    let (mut fast, mut slow) = (background(&r), background(&r));
    let (mut hose_layer, mut probe_layer) = (TubeLayer::default(), TubeLayer::default());
    r.rasterise_tube(&mut hose_layer, Some(hose));
    r.rasterise_tube(&mut probe_layer, Some(probe));
    r.composite_tube(&mut fast, &hose_layer, None);
    r.composite_tube(&mut fast, &probe_layer, b.map(|b| (&d, b)));
    reference_tube(&r, &mut slow, &hose, None);
    reference_tube(&r, &mut slow, &probe, Some(&d));
    assert!(hose_layer.fragments.len() > 1000 && probe_layer.fragments.len() > 10_000);
    assert!(
        fast == slow,
        "max difference {}",
        max_abs_diff(&fast, &slow)
    );
}

#[test]
fn blur_matches_the_every_tap_reference() {
    let (cam, scene) = scene_at("severe_turbulence", 300);
    let mut r = Renderer::new(&cam, look());
    let d = scene.drogue;
    let b = r.drogue_bbox(&d).unwrap();
    let mut drawn = background(&r);
    r.draw_drogue(&mut drawn, &d, b);
    // The scene's own smear, and longer ones in other directions.
    for m in [scene.blur_px, [7.3, -4.6], [-0.2, 12.9], [0.4, 0.1]] {
        let (mut fast, mut slow) = (drawn.clone(), drawn.clone());
        r.blur(&mut fast, b, m);
        reference_blur(&r, &mut slow, b, m);
        let diff = max_abs_diff(&fast, &slow);
        assert!(diff < 1e-6, "blur {m:?}: max difference {diff}");
    }
}

#[test]
fn nearest_strut_is_the_one_nearest_in_angle() {
    for n in 1..=12u32 {
        let dirs: Vec<(f64, f64)> = (0..n)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                (a.cos(), a.sin())
            })
            .collect();
        for i in 0..720 {
            let phi = i as f64 * 0.5f64.to_radians() + 0.001;
            let (x, y) = (0.2 * phi.cos(), 0.2 * phi.sin());
            // The true nearest: the smallest angle between the directions.
            let angle = |k: usize| {
                let a = (phi - k as f64 * std::f64::consts::TAU / n as f64)
                    .rem_euclid(std::f64::consts::TAU);
                a.min(std::f64::consts::TAU - a)
            };
            let best = (0..n as usize).map(angle).fold(f64::INFINITY, f64::min);
            for start in 0..n as usize {
                let k = nearest_strut(&dirs, x, y, start);
                assert!(
                    angle(k) <= best + 1e-12,
                    "n {n} phi {phi} start {start}: {k}"
                );
            }
        }
    }
}

#[test]
fn float_to_byte_matches_the_casts() {
    let check = |x: f32| {
        let cast = x.clamp(0.0, 255.0) as i32 as u8;
        assert_eq!(dn_to_u8(x), cast, "{x:e}");
        if (0.0..8_388_608.0).contains(&x) {
            assert_eq!(floor_dn(x).to_bits(), (x as i32 as f32).to_bits(), "{x:e}");
        }
    };
    // Every float from 1/64 to 300, the rest of [0, 1/64) and beyond sampled.
    let (lo, hi) = ((1.0f32 / 64.0).to_bits(), 300.0f32.to_bits());
    for bits in lo..=hi {
        check(f32::from_bits(bits));
    }
    for bits in (0..lo).step_by(4099) {
        check(f32::from_bits(bits));
    }
    for x in [
        0.0,
        -0.0,
        -1e-30,
        -0.5,
        -1.0,
        -300.0,
        1e6,
        8_388_607.5,
        8.4e6,
        1e30,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        f32::MIN_POSITIVE,
    ] {
        check(x);
    }
}

#[test]
fn floor_f64_matches_floor() {
    for i in -40_000..40_000 {
        for x in [
            i as f64 * 0.013,
            i as f64,
            i as f64 - 1e-12,
            i as f64 + 0.5,
            -(i as f64) * 7.31,
        ] {
            assert_eq!(floor_f64(x), x.floor(), "{x}");
        }
    }
}

/// A plain scene of `scene_at`'s kind: no noise, no blur, no tubes.
fn plain(name: &str) -> (SimCamera, FrameScene, Renderer) {
    let (cam, mut scene) = scene_at(name, 0);
    scene.hose = None;
    scene.probe = None;
    scene.blur_px = [0.0, 0.0];
    let mut l = look();
    l.haze = 0.0;
    let r = Renderer::new(&cam, l);
    (cam, scene, r)
}

/// A canopy-less dark disc covers the area of its exact image ellipse
/// (from the conic, not the renderer), and nothing outside it.
#[test]
fn decal_disc_covers_its_exact_ellipse() {
    let (mut cam, mut scene, _) = plain("approach");
    cam.distortion = [0.0; 5];
    let mut r = Renderer::new(&cam, {
        let mut l = look();
        l.haze = 0.0;
        l
    });
    let centre = V3::new(0.4, -0.2, 4.0);
    let normal = V3::new(0.3, 0.2, -1.0).normalize();
    let e1 = crate::geometry::perpendicular(&normal);
    let e2 = normal.cross(&e1);
    scene.without_drogue = true;
    let sky = r.render(&scene);
    scene.decals = vec![Decal {
        centre,
        normal,
        e1,
        e2,
        shape: DecalShape::Disc { radius: 0.25 },
        radiance: 0.0,
    }];
    let img = r.render(&scene);
    let e = crate::conic::conic_to_ellipse(
        &crate::conic::circle_image_conic(&cam, &centre, &normal, 0.25).unwrap(),
    )
    .unwrap();
    // Coverage from the darkening relative to the sky (radiance 0 inside).
    let mut covered = 0.0;
    for (p, s) in img.pixels().zip(sky.pixels()) {
        let (p, s) = (f64::from(p[0]), f64::from(s[0]));
        if s > 0.0 {
            covered += ((s - p) / s).clamp(0.0, 1.0);
        }
    }
    let area = std::f64::consts::PI * e.a * e.b;
    assert!(
        (covered - area).abs() < 0.01 * area,
        "covered {covered:.0} px, ellipse {area:.0} px"
    );
    // Outside the ellipse by 2 px, the sky is untouched.
    let (s, c) = e.theta.sin_cos();
    for (u, v, p) in img.enumerate_pixels() {
        let (dx, dy) = (u as f64 - e.cx, v as f64 - e.cy);
        let (x, y) = (c * dx + s * dy, -s * dx + c * dy);
        if (x / (e.a + 2.0)).powi(2) + (y / (e.b + 2.0)).powi(2) > 1.0 {
            assert_eq!(p[0], sky.get_pixel(u, v)[0], "({u}, {v})");
        }
    }
}

/// A crescent's dark part lies inside the dark disc's exact ellipse and
/// outside the covering disc's.
#[test]
fn crescent_is_the_dark_disc_minus_the_cover() {
    let (mut cam, mut scene, _) = plain("approach");
    cam.distortion = [0.0; 5];
    let mut r = Renderer::new(&cam, {
        let mut l = look();
        l.haze = 0.0;
        l
    });
    let centre = V3::new(-0.3, 0.1, 5.0);
    let normal = V3::new(-0.2, 0.1, -1.0).normalize();
    let e1 = crate::geometry::perpendicular(&normal);
    let e2 = normal.cross(&e1);
    scene.without_drogue = true;
    scene.decals = Decal::crescent(centre, normal, e1, e2, 0.3, 0.0, 0.33, 0.2, 0.75).to_vec();
    let img = r.render(&scene);
    let inside = |c: &V3, radius: f64, u: f64, v: f64| {
        let e = crate::conic::conic_to_ellipse(
            &crate::conic::circle_image_conic(&cam, c, &normal, radius).unwrap(),
        )
        .unwrap();
        let (s, co) = e.theta.sin_cos();
        let (dx, dy) = (u - e.cx, v - e.cy);
        let (x, y) = (co * dx + s * dy, -s * dx + co * dy);
        (x / e.a).powi(2) + (y / e.b).powi(2)
    };
    let mut dark = 0;
    for (u, v, p) in img.enumerate_pixels() {
        if p[0] < 20 {
            dark += 1;
            let (u, v) = (u as f64, v as f64);
            assert!(
                inside(&centre, 0.3, u, v) < 1.0,
                "dark ({u}, {v}) outside the disc"
            );
            assert!(
                inside(&(centre + e1 * 0.2), 0.33, u, v) > 1.0,
                "dark ({u}, {v}) under the cover"
            );
        }
    }
    assert!(dark > 500, "only {dark} dark pixels");
}

/// The glare streak saturates its centre line and leaves pixels a few widths
/// away as they were; a scene without the extras renders as before.
#[test]
fn glare_streak_saturates_its_line_only() {
    let (_, mut scene, mut r) = plain("approach");
    let before = r.render(&scene);
    scene.glare_streak = Some(GlareStreak {
        through_px: [600.0, 400.0],
        angle_rad: 0.5,
        width_px: 10.0,
        strength: 1.2,
    });
    let img = r.render(&scene);
    let (s, c) = 0.5f64.sin_cos();
    for (u, v, p) in img.enumerate_pixels() {
        let d = ((u as f64 - 600.0) * -s + (v as f64 - 400.0) * c).abs();
        if d < 0.5 {
            assert_eq!(p[0], 255, "({u}, {v}) on the line");
        } else if d > 25.0 {
            assert_eq!(p[0], before.get_pixel(u, v)[0], "({u}, {v}) {d:.1} px off");
        }
    }
    scene.glare_streak = None;
    assert_eq!(r.render(&scene), before);
}

/// The glare glow adds `255 gain strength exp(-d^2 / 2 sigma^2)` digital
/// numbers at a distance `d` from its centre (to a level's rounding), out to
/// four standard deviations: its strong core saturates, pixels beyond are
/// as they were; a scene without it renders as before.
#[test]
fn glare_glow_adds_its_gaussian_out_to_four_sigmas() {
    let (_, mut scene, mut r) = plain("approach");
    let before = r.render(&scene);
    let (centre, sigma, strength) = ([600.0, 400.0], 40.0, 1.5);
    scene.glare_glow = Some(GlareGlow {
        centre_px: centre,
        sigma_px: sigma,
        strength,
    });
    let img = r.render(&scene);
    for (u, v, p) in img.enumerate_pixels() {
        let d = (u as f64 - centre[0]).hypot(v as f64 - centre[1]);
        let was = f64::from(before.get_pixel(u, v)[0]);
        let added = 255.0 * strength * (-0.5 * (d / sigma).powi(2)).exp();
        if d < 1.0 {
            assert_eq!(p[0], 255, "({u}, {v}) at the centre");
        } else if d > 4.0 * sigma + 1.0 {
            assert_eq!(f64::from(p[0]), was, "({u}, {v}) {d:.1} px off");
        } else if d < 4.0 * sigma - 1.0 && was + added < 254.0 {
            let got = f64::from(p[0]) - was;
            assert!(
                (got - added).abs() <= 1.0,
                "({u}, {v}) {d:.1} px off: +{got} for +{added:.2}"
            );
        }
    }
    scene.glare_glow = None;
    assert_eq!(r.render(&scene), before);
}

/// Without the drogue the frame is the sky: the same as a drogue far out
/// of view.
#[test]
fn without_drogue_leaves_the_sky() {
    let (_, mut scene, mut r) = plain("approach");
    scene.without_drogue = true;
    let empty = r.render(&scene);
    scene.without_drogue = false;
    scene.drogue.centre = V3::new(100.0, 0.0, 5.0);
    assert_eq!(r.render(&scene), empty);
}

/// The blur a frame can ask for is bounded (issue 16: a drogue placed at
/// 1e300 m hung the renderer in its blur): a non-finite blur is none, and a
/// longer one than the image's diagonal is that long.
#[test]
fn the_blur_is_bounded() {
    assert_eq!(super::bounded_blur([f64::NAN, 1.0], 640, 480), [0.0, 0.0]);
    assert_eq!(
        super::bounded_blur([f64::INFINITY, 0.0], 640, 480),
        [0.0, 0.0]
    );
    let b = super::bounded_blur([1e300, 1e300], 640, 480);
    assert!(
        ((b[0] * b[0] + b[1] * b[1]).sqrt() - 800.0).abs() < 1e-9,
        "{b:?}"
    );
    assert_eq!(super::bounded_blur([3.0, -4.0], 640, 480), [3.0, -4.0]);
}

/// A star's arms reach its radius in the arms' directions and its waists
/// lie at `1 - depth` of it halfway between; the bounding radius holds it.
#[test]
fn star_has_its_arms_and_waists_where_its_parameters_put_them() {
    let (radius, depth, phase) = (0.5, 0.6, 0.3);
    let star = Decal {
        centre: V3::new(0.0, 0.0, 10.0),
        normal: V3::new(0.0, 0.0, -1.0),
        e1: V3::x(),
        e2: V3::y(),
        shape: DecalShape::Star {
            radius,
            arms: 5,
            depth,
            phase,
        },
        radiance: 0.1,
    };
    let at = |phi: f64, rho: f64| star.signed_distance(rho * phi.cos(), rho * phi.sin());
    let waist = phase + std::f64::consts::PI / 5.0;
    for arm in 0..5 {
        let tip = phase + f64::from(arm) * std::f64::consts::TAU / 5.0;
        assert!(at(tip, 0.99 * radius) < 0.0 && at(tip, 1.01 * radius) > 0.0);
        let w = waist + f64::from(arm) * std::f64::consts::TAU / 5.0;
        let waist_rho = radius * (1.0 - depth);
        assert!(at(w, 0.99 * waist_rho) < 0.0 && at(w, 1.01 * waist_rho) > 0.0);
    }
    assert_eq!(star.bounding_radius(), radius);
}

/// A probe seen side-on at 2 m, its axis along one image row: along that
/// row the collar's band is drawn where it lies (each pixel's axial place
/// from the pixel's own ray: depth over the ray's slope), and only there,
/// at the collar's radiance: after the haze (a linear map), the band's
/// light over the probe's is the collar's radiance over the probe's.
#[test]
fn a_probe_collar_is_drawn_where_its_band_lies() {
    let (cam, _) = scene_at("contact", 170);
    let r = Renderer::new(&cam, look());
    let (z, row) = (2.0, r.h / 2);
    let y = r.ray(r.w / 2, row).y * z;
    let (probe, collar) = (0.2, 0.45);
    let (from_tip_m, to_tip_m) = (0.05, 0.12);
    let tube = Tube {
        a: V3::new(-0.6, y, z),
        b: V3::new(0.2, y, z),
        radius_a: 0.04,
        radius_b: 0.04,
        radiance: probe,
        collar: Some(Collar {
            from_tip_m,
            to_tip_m,
            radiance: collar,
        }),
    };
    let mut rad = background(&r);
    let mut layer = TubeLayer::default();
    r.rasterise_tube(&mut layer, Some(tube));
    r.composite_tube(&mut rad, &layer, None);
    // Unhazed level of a pixel on the axis row.
    let unhazed = |u: usize| {
        let v = f64::from(rad[row * r.w + u]);
        (v - r.look.haze_radiance * r.look.haze) / (1.0 - r.look.haze)
    };
    // Pixels a pixel's width or more inside or outside the band (the
    // pixel at 2 m is about 1.5 mm), clear of the rounded end.
    let px_m = z / cam.fx;
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for u in 0..r.w {
        let back = tube.b.x - r.ray(u, row).x * z;
        if back < 2.0 * px_m || back > 0.5 {
            continue;
        }
        if back > from_tip_m + px_m && back < to_tip_m - px_m {
            inside.push(unhazed(u));
        } else if back < from_tip_m - px_m || back > to_tip_m + px_m {
            outside.push(unhazed(u));
        }
    }
    assert!(
        inside.len() > 30 && outside.len() > 200,
        "{} {}",
        inside.len(),
        outside.len()
    );
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let ratio = mean(&inside) / mean(&outside);
    assert!((ratio - collar / probe).abs() < 1e-3, "{ratio}");
    // Level along each part: one value (the axis row sees the tube's
    // middle everywhere).
    for part in [&inside, &outside] {
        let m = mean(part);
        assert!(part.iter().all(|v| (v - m).abs() < 1e-3 * m), "{part:?}");
    }
}
