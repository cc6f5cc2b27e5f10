//! The review's PNG plots (plotters, bitmap backend).

use super::{PlotPoint, ReviewReport};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

const SIZE: (u32, u32) = (1400, 900);

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
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
    let mut files = Vec::new();
    if !r.series.is_empty() {
        files.push(position(&r.series, dir)?);
        files.push(detections(&r.series, dir)?);
    }
    if r.series.iter().any(|p| p.position_error_m.is_finite()) {
        files.push(error_vs_range(&r.series, dir)?);
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

/// Position x, y, z (camera frame) over time, estimate dots and truth line.
fn position(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("position.png");
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (t0, t1) = bounds(series.iter().map(|p| p.t_s)).unwrap_or((0.0, 1.0));
    let names = ["x (right) m", "y (down) m", "z (forward) m"];
    for (axis, area) in root.split_evenly((3, 1)).iter().enumerate() {
        let values = series
            .iter()
            .flat_map(|p| [p.position_camera[axis], p.truth_camera[axis]]);
        let (lo, hi) = bounds(values).unwrap_or((-1.0, 1.0));
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("drogue centre, camera frame: {}", names[axis]),
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("time s")
            .y_desc(names[axis])
            .draw()
            .map_err(err)?;
        let truth: Vec<(f64, f64)> = series
            .iter()
            .filter(|p| p.truth_camera[axis].is_finite())
            .map(|p| (p.t_s, p.truth_camera[axis]))
            .collect();
        if !truth.is_empty() {
            chart
                .draw_series(LineSeries::new(truth, BLACK.stroke_width(1)))
                .map_err(err)?
                .label("truth")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        chart
            .draw_series(
                series
                    .iter()
                    .filter(|p| p.position_camera[axis].is_finite())
                    .map(|p| Circle::new((p.t_s, p.position_camera[axis]), 2, BLUE.filled())),
            )
            .map_err(err)?
            .label("estimate")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// Detected (1) or not (0) over time.
fn detections(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("detections.png");
    let root = BitMapBackend::new(&path, (SIZE.0, 300)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (t0, t1) = bounds(series.iter().map(|p| p.t_s)).unwrap_or((0.0, 1.0));
    let mut chart = ChartBuilder::on(&root)
        .caption("detection timeline", ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, -0.2f64..1.2f64)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("time s")
        .y_desc("detected")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(series.iter().map(|p| {
            let (y, c) = if p.detected { (1.0, GREEN) } else { (0.0, RED) };
            Circle::new((p.t_s, y), 2, c.filled())
        }))
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(path.clone())
}

/// Position error against the true range.
fn error_vs_range(series: &[PlotPoint], dir: &Path) -> Result<PathBuf, String> {
    let path = dir.join("error_vs_range.png");
    let root = BitMapBackend::new(&path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let pts: Vec<(f64, f64)> = series
        .iter()
        .filter(|p| p.position_error_m.is_finite() && p.range_m.is_finite())
        .map(|p| (p.range_m, p.position_error_m))
        .collect();
    let (r0, r1) = bounds(pts.iter().map(|p| p.0)).unwrap_or((0.0, 1.0));
    let (_, e1) = bounds(pts.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
    let mut chart = ChartBuilder::on(&root)
        .caption("position error against range (truth)", ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(r0..r1, 0.0..e1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("true range m")
        .y_desc("position error m")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(pts.iter().map(|&p| Circle::new(p, 2, BLUE.filled())))
        .map_err(err)?;
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
        .caption(format!("latency: {label}"), ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..right, 0.0..top)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(label)
        .y_desc("frames")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(bars.iter().map(|&(x, n)| {
            Rectangle::new([(x, 0.0), (x + width_ms, n as f64)], BLUE.mix(0.7).filled())
        }))
        .map_err(err)?;
    for (q, c) in [(0.5, GREEN), (0.95, MAGENTA), (0.99, RED)] {
        let x = h.quantile(q);
        chart
            .draw_series(LineSeries::new([(x, 0.0), (x, top)], c.stroke_width(2)))
            .map_err(err)?
            .label(format!("p{:.0} {x:.2} ms", q * 100.0))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(path.clone())
}
