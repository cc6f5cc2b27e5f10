//! Post-flight review of a log: a terminal summary, `poses.csv` and PNG plots.
//! Streams the log once; memory stays bounded whatever its size (histograms,
//! per-range sums, and a plot series thinned by halving when it grows).

mod plots;
mod records;
mod report;
mod stats;

use super::reader::{counted_message_reader, is_cut_short};
use super::{LogError, topics};
use foxglove::Decode;
use foxglove::messages::Log;
use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use records::{CpuTotalLite, DetectionLite, LinkLite, StatsLite, TruthLite};
pub use report::{ResourceReview, ReviewReport};
pub use stats::{Histogram, RangeBin};

/// Heartbeat gap that counts as the autopilot link lost, ns.
const LINK_LOST_NS: u64 = 3_000_000_000;
/// Plot points kept; above this the series is thinned by half.
const MAX_PLOT_POINTS: usize = 50_000;
/// `/log` messages at warning level or above quoted in the summary.
const QUOTED_PROBLEMS: usize = 10;
/// Truth records waiting for their detection (normally one).
const MAX_PENDING_TRUTH: usize = 256;

/// One frame for the plots (NaN where there is no value).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlotPoint {
    pub t_s: f64,
    pub detected: bool,
    pub position_camera: [f64; 3],
    pub truth_camera: [f64; 3],
    /// Body FRD: what the autopilot receives.
    pub position_body: [f64; 3],
    pub truth_body: [f64; 3],
    pub range_m: f64,
    pub position_error_m: f64,
    pub normal_error_deg: f64,
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let na = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn csv_opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x}")).unwrap_or_default()
}

fn csv_xyz(v: Option<[f64; 3]>) -> String {
    match v {
        Some([x, y, z]) => format!("{x},{y},{z}"),
        None => ",,".into(),
    }
}

const CSV_HEADER: &str = "time_s,capture_time_ns,seq,detected,\
position_camera_x_m,position_camera_y_m,position_camera_z_m,\
normal_camera_x,normal_camera_y,normal_camera_z,\
position_body_x_m,position_body_y_m,position_body_z_m,\
processing_ms,\
truth_position_camera_x_m,truth_position_camera_y_m,truth_position_camera_z_m,\
truth_normal_camera_x,truth_normal_camera_y,truth_normal_camera_z,\
truth_range_m,position_error_m,normal_error_deg,not_detected";

/// Reviews `log`, writing `poses.csv`, the plots and the metadata into
/// `out_dir`. Everything is written to a temporary folder beside `out_dir`
/// and moved into place at the end, so a failure leaves no half-written
/// folder. An existing `out_dir` is replaced only when it is empty or an
/// earlier review (it holds `poses.csv`).
pub fn review(log: &Path, out_dir: &Path) -> Result<ReviewReport, LogError> {
    // Before any folder is made: a bad input leaves nothing behind.
    super::check_mcap_input(log)?;
    if out_dir.exists() {
        let earlier_review = out_dir.join("poses.csv").is_file();
        let empty = std::fs::read_dir(out_dir).is_ok_and(|mut d| d.next().is_none());
        if !(earlier_review || empty) {
            return Err(LogError::Config(format!(
                "{} exists and is not an earlier review: choose another --out",
                out_dir.display()
            )));
        }
    }
    let parent = out_dir
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| LogError::io(parent, e))?;
    let tmp = tempfile::Builder::new()
        .prefix(".review-")
        .tempdir_in(parent)
        .map_err(|e| LogError::io(parent, e))?;
    let mut r = review_into(log, tmp.path())?;
    // Move into place: the old review aside, the new one in, the old one gone.
    let old = if out_dir.exists() {
        let aside = tempfile::Builder::new()
            .prefix(".review-old-")
            .tempdir_in(parent)
            .map_err(|e| LogError::io(parent, e))?;
        let aside_path = aside.path().join("old");
        std::fs::rename(out_dir, &aside_path).map_err(|e| LogError::io(out_dir, e))?;
        Some(aside)
    } else {
        None
    };
    let tmp_path = tmp.keep();
    if let Err(e) = std::fs::rename(&tmp_path, out_dir) {
        let _ = std::fs::remove_dir_all(&tmp_path);
        if let Some(old) = &old {
            let _ = std::fs::rename(old.path().join("old"), out_dir);
        }
        return Err(LogError::io(out_dir, e));
    }
    drop(old);
    for f in &mut r.files_written {
        if let Ok(rest) = f.strip_prefix(&tmp_path) {
            *f = out_dir.join(rest);
        }
    }
    Ok(r)
}

/// The review, written into the folder `out_dir` (which exists).
fn review_into(log: &Path, out_dir: &Path) -> Result<ReviewReport, LogError> {
    let metadata = super::metadata::read_metadata(log)?;
    let csv_path = out_dir.join("poses.csv");
    let csv_file = File::create(&csv_path).map_err(|e| LogError::io(&csv_path, e))?;
    let mut csv = BufWriter::new(csv_file);
    let csv_err = |e: std::io::Error| LogError::io(&csv_path, e);
    writeln!(csv, "{CSV_HEADER}").map_err(csv_err)?;

    let mut r = ReviewReport {
        log: log.to_path_buf(),
        metadata,
        by_range: stats::range_bins(),
        ..Default::default()
    };
    // `run --fast` stamps its messages on the source's clock, which stands
    // still while a frame is processed: capture → send is no latency there.
    let source_clock = r.metadata.iter().any(|(name, values)| {
        name == super::metadata::RUN_METADATA
            && values.get("clock").map(String::as_str) == Some("source")
    });
    r.source_clock = source_clock;
    r.full_frame_every = full_frame_every(&r.metadata);
    let every = u32::try_from(r.full_frame_every).unwrap_or(1).max(1);
    let mut last_frame_seq: Option<u32> = None;
    let mut last_heartbeat: Option<u64> = None;
    let mut last_sent_capture: Option<u64> = None;
    let mut pending_truth: VecDeque<(u64, TruthLite)> = VecDeque::new();
    let mut stride = 1usize;
    let mut since_kept = 0usize;
    let mut first_frame_ns: Option<u64> = None;
    let mut first_stats: Option<(u64, CpuTotalLite)> = None;

    let (messages, oversized) = counted_message_reader(log)?;
    for message in messages {
        let m = match message {
            Ok(m) => m,
            Err(e) => {
                if r.first_ns.is_none() && matches!(e, mcap::McapError::BadMagic) {
                    return Err(LogError::format(log, e));
                }
                if is_cut_short(&e) {
                    r.cut = Some(super::error_chain(&e));
                } else {
                    r.damaged = Some(super::error_chain(&e));
                }
                break;
            }
        };
        let t = m.log_time;
        r.first_ns = Some(r.first_ns.map_or(t, |f| f.min(t)));
        r.last_ns = Some(r.last_ns.map_or(t, |l| l.max(t)));
        match m.channel.topic.as_str() {
            topics::IMAGE => {
                r.frames += 1;
                first_frame_ns.get_or_insert(t);
                r.first_frame_ns = first_frame_ns;
                r.last_frame_ns = Some(t);
                if let Some(prev) = last_frame_seq
                    && m.sequence > prev
                {
                    // Full frames kept between the two, but not logged.
                    r.frames_lost += u64::from((m.sequence - 1) / every - prev / every);
                }
                last_frame_seq = Some(m.sequence);
            }
            topics::SIM_TRUTH => {
                if let Ok(truth) = serde_json::from_slice::<TruthLite>(&m.data) {
                    pending_truth.push_back((t, truth));
                    if pending_truth.len() > MAX_PENDING_TRUTH {
                        pending_truth.pop_front();
                    }
                }
            }
            topics::DETECTION => {
                let Ok(d) = serde_json::from_slice::<DetectionLite>(&m.data) else {
                    r.problems
                        .push(format!("unreadable /drogue/detection at {t} ns"));
                    continue;
                };
                r.measurements += 1;
                if d.detected {
                    r.detected += 1;
                } else {
                    let reason = d.not_detected.as_ref().map_or("unknown", |n| n.code());
                    *r.missed_by_reason.entry(reason.to_string()).or_default() += 1;
                }
                let processing = d.times_us.as_ref().map(|x| x.total_us / 1000.0);
                if let Some(p) = processing {
                    r.processing_ms.add(p);
                }
                // The truth of this frame has the same log time.
                while pending_truth.front().is_some_and(|(tt, _)| *tt < t) {
                    pending_truth.pop_front();
                }
                let truth = match pending_truth.front() {
                    Some((tt, truth)) if *tt == t => Some(*truth),
                    _ => None,
                };
                let mut pos_err = None;
                let mut normal_err = None;
                if let Some(truth) = truth {
                    r.truth_frames += 1;
                    if let (Some(p), Some(n)) = (d.position_camera, d.normal_camera) {
                        let pe = distance(p, truth.position_camera);
                        let ne = angle_deg(n, truth.normal_camera);
                        pos_err = Some(pe);
                        normal_err = Some(ne);
                        stats::add_to_bins(&mut r.by_range, truth.range_m, Some((pe, ne)));
                    } else {
                        stats::add_to_bins(&mut r.by_range, truth.range_m, None);
                    }
                }
                let time_s = t.saturating_sub(first_frame_ns.unwrap_or(t)) as f64 * 1e-9;
                writeln!(
                    csv,
                    "{time_s:.6},{t},{},{},{},{},{},{},{},{},{},{},{},{}",
                    m.sequence,
                    u8::from(d.detected),
                    csv_xyz(d.position_camera),
                    csv_xyz(d.normal_camera),
                    csv_xyz(d.position_body),
                    csv_opt(processing),
                    csv_xyz(truth.map(|x| x.position_camera)),
                    csv_xyz(truth.map(|x| x.normal_camera)),
                    csv_opt(truth.map(|x| x.range_m)),
                    csv_opt(pos_err),
                    csv_opt(normal_err),
                    d.not_detected.as_ref().map_or("", |n| n.code()),
                )
                .map_err(csv_err)?;

                since_kept += 1;
                if since_kept >= stride {
                    since_kept = 0;
                    r.series.push(PlotPoint {
                        t_s: time_s,
                        detected: d.detected,
                        position_camera: d.position_camera.unwrap_or([f64::NAN; 3]),
                        truth_camera: truth.map_or([f64::NAN; 3], |x| x.position_camera),
                        position_body: d.position_body.unwrap_or([f64::NAN; 3]),
                        truth_body: truth.and_then(|x| x.position_body).unwrap_or([f64::NAN; 3]),
                        range_m: truth.map_or(f64::NAN, |x| x.range_m),
                        position_error_m: pos_err.unwrap_or(f64::NAN),
                        normal_error_deg: normal_err.unwrap_or(f64::NAN),
                    });
                    if r.series.len() >= MAX_PLOT_POINTS {
                        let mut i = 0;
                        r.series.retain(|_| {
                            i += 1;
                            i % 2 == 1
                        });
                        stride *= 2;
                    }
                }
            }
            topics::MAVLINK_OUT | topics::MAVLINK_IN => {
                let Ok(l) = serde_json::from_slice::<LinkLite>(&m.data) else {
                    continue;
                };
                let incoming = m.channel.topic == topics::MAVLINK_IN;
                // Capture → send latency: the first pose message sent for a frame.
                if !incoming
                    && !source_clock
                    && let (Some(sent), Some(captured)) = (l.time_ns, l.capture_time_ns)
                    && last_sent_capture != Some(captured)
                {
                    last_sent_capture = Some(captured);
                    r.latency_ms
                        .add(sent.saturating_sub(captured) as f64 * 1e-6);
                }
                if incoming && l.name == "HEARTBEAT" {
                    r.heartbeats_in += 1;
                    if let Some(prev) = last_heartbeat {
                        let gap = t.saturating_sub(prev);
                        if gap > LINK_LOST_NS {
                            r.link_losses += 1;
                        }
                        r.longest_heartbeat_gap_s =
                            r.longest_heartbeat_gap_s.max(gap as f64 * 1e-9);
                    }
                    last_heartbeat = Some(t);
                }
                let counts = if incoming {
                    &mut r.mavlink_in
                } else {
                    &mut r.mavlink_out
                };
                *counts.entry(l.name).or_insert(0) += 1;
            }
            topics::STATS => {
                let Ok(st) = serde_json::from_slice::<StatsLite>(&m.data) else {
                    r.problems
                        .push(format!("unreadable /drogue/stats at {t} ns"));
                    continue;
                };
                let res = r.resources.get_or_insert_with(Default::default);
                res.samples += 1;
                let (t0, first) = *first_stats.get_or_insert((st.time_ns, st.cpu_s_total));
                let wall_s = st.time_ns.saturating_sub(t0) as f64 * 1e-9;
                if wall_s > 0.0 {
                    let source = st.cpu_s_total.source - first.source;
                    let process = st.cpu_s_total.process - first.process;
                    let writer = st.cpu_s_total.log_writer - first.log_writer;
                    res.pipeline_cpu_pct = 100.0 * (process - source - writer) / wall_s;
                    res.source_cpu_pct = 100.0 * source / wall_s;
                    res.log_writer_cpu_pct = 100.0 * writer / wall_s;
                }
                res.pipeline_cpu_max_pct = res.pipeline_cpu_max_pct.max(st.cpu_pct.pipeline);
                res.peak_rss_bytes = res.peak_rss_bytes.max(st.rss_bytes.unwrap_or(0));
                res.max_log_queue = res.max_log_queue.max(st.queues.log);
                res.last_log_queue = st.queues.log;
                res.max_link_event_queue = res.max_link_event_queue.max(st.queues.link_events);
            }
            topics::LOG => {
                let Ok(l) = Log::decode(m.data.as_ref()) else {
                    continue;
                };
                if let Some(n) = stats::dropped_in_report(&l.message) {
                    r.log_dropped = r.log_dropped.max(n);
                }
                use foxglove::messages::log::Level;
                let level = l.level;
                if level >= Level::Warning as i32 {
                    if level >= Level::Error as i32 {
                        r.errors += 1;
                    } else {
                        r.warnings += 1;
                    }
                    if r.problems.len() < QUOTED_PROBLEMS {
                        r.problems.push(format!("{}: {}", l.name, l.message));
                    }
                }
            }
            _ => {}
        }
    }
    r.oversized_records = oversized.records();
    r.oversized_bytes = oversized.bytes();
    csv.flush().map_err(csv_err)?;
    r.files_written.push(csv_path);
    if !r.metadata.is_empty() {
        let path = out_dir.join("metadata.txt");
        let mut text = String::new();
        for (name, values) in &r.metadata {
            text.push_str(&format!("[{name}]\n"));
            for (k, v) in values {
                text.push_str(&format!("--- {k}\n{v}\n"));
            }
        }
        std::fs::write(&path, text).map_err(|e| LogError::io(&path, e))?;
        r.files_written.push(path);
    }
    match plots::draw_all(&r, out_dir) {
        Ok(files) => r.files_written.extend(files),
        Err(e) => r.plot_error = Some(e),
    }
    Ok(r)
}

/// `[log] full_frame_every` of a crop-mode log, from its run metadata's
/// config (1 for every other log, also without metadata).
fn full_frame_every(metadata: &[(String, BTreeMap<String, String>)]) -> u64 {
    let config = metadata
        .iter()
        .find(|(name, _)| name == super::metadata::RUN_METADATA)
        .and_then(|(_, values)| values.get("config_toml"))
        .and_then(|text| toml::from_str::<toml::Table>(text).ok());
    let log = config.as_ref().and_then(|c| c.get("log"));
    let crop = log
        .and_then(|l| l.get("image_encoding"))
        .and_then(|v| v.as_str())
        == Some("crop");
    let every = log
        .and_then(|l| l.get("full_frame_every"))
        .and_then(toml::Value::as_integer)
        .and_then(|n| u64::try_from(n).ok())
        .filter(|&n| n >= 1);
    match (crop, every) {
        (true, Some(n)) => n,
        _ => 1,
    }
}
