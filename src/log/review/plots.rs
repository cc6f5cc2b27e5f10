//! The review's PNG plots (plotters, bitmap backend). Text is drawn with the
//! DejaVu Sans font built into the binary (plotters' `ab_glyph` feature), so
//! plots draw on a machine without fonts and the build needs no fontconfig
//! or freetype.
//!
//! Conventions, the same in every plot: the estimate is drawn first as blue
//! dots, the simulator's truth over it as a thick orange line (visible where
//! the two agree); every axis names its quantity, frame and unit.

use super::{PlotPoint, ReviewReport};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const SIZE: (u32, u32) = (1400, 1000);
/// The bundled font (its licence: assets/fonts/DejaVuSans-LICENSE.txt).
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";
const TRUTH: RGBColor = RGBColor(230, 120, 0);
const ESTIMATE: RGBColor = RGBColor(30, 80, 200);
const FOUND: RGBColor = RGBColor(40, 160, 60);
const LOST: RGBColor = RGBColor(210, 40, 40);

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Registers the bundled font once; its error (a corrupt font) is kept.
fn font() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
                .map_err(|_| "the bundled font does not load".to_string())
        })
        .clone()
}

/// (min, max) of the finite values, widened so a constant series still has a
/// visible range.
fn bounds(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return None;
    }
    let pad = ((hi - lo) * 0.05).max(1e-3);
    Some((lo - pad, hi + pad))
}

/// Draws every plot the data allows; returns the files written.
pub(crate) fn draw_all(r: &ReviewReport, dir: &Path) -> Result<Vec<PathBuf>, String> {
    font()?;
    let mut files = Vec::new();
    let s = &r.series;
    if !s.is_empty() {
        files.push(position(
            s,
            dir.join("position_body.png"),
            "drogue centre, body FRD (what the autopilot receives)",
            ["x forward, m", "y right, m", "z down, m"],
            |p| (p.position_body, p.truth_body),
        )?);
        files.push(position(
            s,
            dir.join("position_camera.png"),
            "drogue centre, camera frame",
            ["x right, m", "y down, m", "z forward (range), m"],
            |p| (p.position_camera, p.truth_camera),
        )?);
        files.push(detections(s, dir)?);
    }
    if s.iter().any(|p| p.position_error_m.is_finite()) {
        files.push(errors_over_time(s, dir)?);
        files.push(error_vs_range(s, dir)?);
    }
    let latency = if r.latency_ms.count() > 0 {
        Some((&r.latency_ms, "capture to pose sent, ms"))
    } else if r.processing_ms.count() > 0 {
        Some((&r.processing_ms, "measurement time per frame, ms"))
    } else {
        None
    };
    if let Some((h, label)) = latency {
        files.push(latency_histogram(h, label, dir)?);
    }
    Ok(files)
}

/// Time span of the series, s.
fn time_span(series: &[PlotPoint]) -> (f64, f64) {
    bounds(series.iter().map(|p| p.t_s)).unwrap_or((0.0, 1.0))
}

/// Three panels (x, y, z) over time: estimate dots, truth line over them.
fn position(
    series: &[PlotPoint],
    path: PathBuf,
    title: &str,
    axes: [&str; 3],
    pick: impl Fn(&PlotPoint) -> ([f64; 3], [f64; 3]),
) -> Result<PathBuf, String> {
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, (FAMILY, 26)).map_err(err)?;
    let (t0, t1) = time_span(series);
    for (axis, area) in root.split_evenly((3, 1)).iter().enumerate() {
        let values = series.iter().flat_map(|p| {
            let (e, t) = pick(p);
            [e[axis], t[axis]]
        });
        let (lo, hi) = bounds(values).unwrap_or((-1.0, 1.0));
        let mut chart = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("time since the first frame, s")
            .y_desc(axes[axis])
            .axis_desc_style((FAMILY, 18))
            .label_style((FAMILY, 15))
            .draw()
            .map_err(err)?;
        chart
            .draw_series(series.iter().filter_map(|p| {
                let v = pick(p).0[axis];
                v.is_finite()
                    .then(|| Circle::new((p.t_s, v), 2, ESTIMATE.filled()))
            }))
            .map_err(err)?
            .label("estimate")
            .legend(|(x, y)| Circle::new((x + 10, y), 4, ESTIMATE.filled()));
        let truth: Vec<(f64, f64)> = series
            .iter()
            .filter_map(|p| {
                let v = pick(p).1[axis];
                v.is_finite().then_some((p.t_s, v))
            })
            .collect();
        if !truth.is_empty() {
            chart
                .draw_series(LineSeries::new(truth, TRUTH.stroke_width(3)))
                .map_err(err)?
                .label("truth (simulator)")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], TRUTH.stroke_width(3))
                });
        }
        chart
            .configure_series_labels()
            .label_font((FAMILY, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// Found / lost as coloured bands over time, one band per run of frames.
fn detections(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("detections.png");
    let root = BitMapBackend::new(&path, (SIZE.0, 320)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (t0, t1) = time_span(series);
    let found = series.iter().filter(|p| p.detected).count();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "detection timeline: found in {found} of {} frames (green found, red lost)",
                series.len()
            ),
            (FAMILY, 22),
        )
        .margin(10)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(t0..t1, 0.0f64..1.0f64)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("time since the first frame, s")
        .y_desc("")
        .disable_y_mesh()
        .disable_y_axis()
        .axis_desc_style((FAMILY, 18))
        .label_style((FAMILY, 15))
        .draw()
        .map_err(err)?;
    // Runs of equal state; each band reaches the next frame's time.
    let mut bands: Vec<(f64, f64, bool)> = Vec::new();
    for (i, p) in series.iter().enumerate() {
        let end = series.get(i + 1).map_or(p.t_s, |n| n.t_s);
        match bands.last_mut() {
            Some(b) if b.2 == p.detected => b.1 = end,
            _ => bands.push((p.t_s, end, p.detected)),
        }
    }
    chart
        .draw_series(bands.iter().map(|&(a, b, found)| {
            let c = if found { FOUND } else { LOST };
            // A lone frame still shows.
            let b = b.max(a + (t1 - t0) * 0.001);
            Rectangle::new([(a, 0.15), (b, 0.85)], c.filled())
        }))
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// An error panel: its axis label and the value it plots.
type Panel = (&'static str, fn(&PlotPoint) -> f64);

const ERROR_PANELS: [Panel; 2] = [
    ("position error, m", |p| p.position_error_m),
    ("normal (orientation) error, deg", |p| p.normal_error_deg),
];

/// Position and normal errors against truth over time.
fn errors_over_time(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("error_vs_time.png");
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled("errors against the simulator's truth", (FAMILY, 26))
        .map_err(err)?;
    let (t0, t1) = time_span(series);
    let panels = ERROR_PANELS;
    for ((label, value), area) in panels.iter().zip(root.split_evenly((2, 1)).iter()) {
        let (_, top) = bounds(series.iter().map(value)).unwrap_or((0.0, 1.0));
        let mut chart = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(t0..t1, 0.0..top.max(1e-3))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("time since the first frame, s")
            .y_desc(*label)
            .axis_desc_style((FAMILY, 18))
            .label_style((FAMILY, 15))
            .draw()
            .map_err(err)?;
        chart
            .draw_series(series.iter().filter_map(|p| {
                let v = value(p);
                v.is_finite()
                    .then(|| Circle::new((p.t_s, v), 2, ESTIMATE.filled()))
            }))
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// Position and normal errors against the true range.
fn error_vs_range(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("error_vs_range.png");
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled("errors against the true range (simulator)", (FAMILY, 26))
        .map_err(err)?;
    let (r0, r1) = bounds(
        series
            .iter()
            .filter(|p| p.position_error_m.is_finite())
            .map(|p| p.range_m),
    )
    .unwrap_or((0.0, 1.0));
    let panels = ERROR_PANELS;
    for ((label, value), area) in panels.iter().zip(root.split_evenly((2, 1)).iter()) {
        let pts: Vec<(f64, f64)> = series
            .iter()
            .filter(|p| value(p).is_finite() && p.range_m.is_finite())
            .map(|p| (p.range_m, value(p)))
            .collect();
        let (_, top) = bounds(pts.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
        let mut chart = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(r0..r1, 0.0..top.max(1e-3))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("true range (camera to drogue centre), m")
            .y_desc(*label)
            .axis_desc_style((FAMILY, 18))
            .label_style((FAMILY, 15))
            .draw()
            .map_err(err)?;
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 2, ESTIMATE.filled())))
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// Histogram of latencies (or measurement times).
fn latency_histogram(h: &super::Histogram, label: &str, dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("latency.png");
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    // About 100 bars over the observed span.
    let width_ms = ((h.max() / 100.0).max(0.01) * 100.0).ceil() / 100.0;
    let bars = h.coarse(width_ms);
    let top = bars.iter().map(|b| b.1).max().unwrap_or(1) as f64 * 1.1;
    let right = bars.last().map_or(1.0, |b| b.0 + width_ms) * 1.02;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("latency: {label}"), (FAMILY, 24))
        .margin(10)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..right, 0.0..top)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(label)
        .y_desc("frames")
        .axis_desc_style((FAMILY, 18))
        .label_style((FAMILY, 15))
        .draw()
        .map_err(err)?;
    chart
        .draw_series(bars.iter().map(|&(x, n)| {
            Rectangle::new(
                [(x, 0.0), (x + width_ms, n as f64)],
                ESTIMATE.mix(0.7).filled(),
            )
        }))
        .map_err(err)?;
    for (q, c) in [(0.5, FOUND), (0.95, MAGENTA), (0.99, LOST)] {
        let x = h.quantile(q);
        chart
            .draw_series(LineSeries::new([(x, 0.0), (x, top)], c.stroke_width(2)))
            .map_err(err)?
            .label(format!("p{:.0} {x:.2} ms", q * 100.0))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    chart
        .configure_series_labels()
        .label_font((FAMILY, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(path.clone())
}
