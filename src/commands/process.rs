//! `drogue-vision process`: offline measurement of a folder of images (or an
//! MCAP log), one JSON line per frame.

use crate::camera::CameraModel;
use crate::config::Config;
use crate::frame::{Frame, FrameOrigin};
use crate::image_io::{check_frame_size, read_gray8};
use crate::log::FlightLog;
use crate::log::replay::{self, ReplayReader};
use crate::measure::Measurer;
use crate::measure::mount::Mount;
use crate::record::DetectionRecord;
use crate::source::dir::list_images;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Frame period assumed for a folder of images (their capture times are not
/// known); only the tracker's prediction uses it.
const FOLDER_FRAME_PERIOD_NS: u64 = 33_333_333;

/// Arguments of `process` (see `drogue-vision process --help`).
#[derive(Clone, Debug, clap::Args)]
#[command(
    after_help = "Exit status: 0 every frame was processed (unreadable frames are \
records with `error`); 1 the output (JSON lines or --log) could not be written; 2 bad arguments, config, camera \
file or input."
)]
pub struct ProcessArgs {
    /// A folder of images (png, jpg, pgm, bmp; lexicographic order) or an MCAP log.
    pub input: PathBuf,
    /// Camera file (ROS camera_info or OpenCV YAML); required for a folder,
    /// optional for a log (default: the log's /camera/calibration).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Radius of the drogue's dark inner circle, metres (overrides the config).
    #[arg(long)]
    pub radius: Option<f64>,
    /// Output JSON lines, one object per input frame.
    #[arg(long)]
    pub out: PathBuf,
    /// Config file laid over the embedded default.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Treat the images as unrelated views, not a sequence: no tracking and no
    /// temporal disambiguation.
    #[arg(long)]
    pub independent: bool,
    /// Also write an MCAP log of the frames and measurements (the topics of
    /// `run`'s log, for Foxglove), to exactly this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
}

/// What a `process` run did (printed on stderr at the end).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProcessSummary {
    pub frames: usize,
    pub detected: usize,
    pub unreadable: usize,
    /// Non-image files in the folder, not read.
    pub skipped: usize,
    /// Mean measurement time per readable frame, milliseconds.
    pub ms_per_frame: f64,
    /// The MCAP log written (`--log`).
    pub log_file: Option<PathBuf>,
    /// An MCAP input's records above the record bound, skipped unread
    /// (`crate::log::oversized`): frames they held are not in `frames`.
    pub oversized_records: u64,
}

/// Why `process` stopped.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// Arguments, config, camera or input unusable: nothing was processed.
    #[error("{0}")]
    Setup(String),
    /// The output (JSON lines or the MCAP log) could not be written.
    #[error("writing {path}: {message}")]
    Output { path: String, message: String },
}

fn progress_bar(len: u64) -> ProgressBar {
    let bar = if len > 0 {
        ProgressBar::new(len)
    } else {
        ProgressBar::new_spinner()
    };
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames  {per_sec}  eta {eta}")
    {
        bar.set_style(style);
    }
    bar
}

/// Frames of the input, each named for its record (file name, or sequence
/// number for a log), or the reason it could not be read.
type NamedFrames = Box<dyn Iterator<Item = (String, Result<Frame, String>)>>;

/// An opened input: its frames, camera, count of skipped non-image files,
/// frame count for the progress bar (0: unknown), and for an MCAP log the
/// count of records above the record bound it skipped.
type OpenedInput = (
    NamedFrames,
    CameraModel,
    usize,
    u64,
    Option<Arc<crate::log::oversized::Oversized>>,
);

/// Opens the input (see [`OpenedInput`]).
fn open_input(args: &ProcessArgs) -> Result<OpenedInput, ProcessError> {
    let setup = |e: String| ProcessError::Setup(e);
    let given_camera = args
        .camera
        .as_deref()
        .map(CameraModel::load)
        .transpose()
        .map_err(|e| setup(e.to_string()))?;
    if args.input.is_dir() {
        let camera =
            given_camera.ok_or_else(|| setup("a folder of images needs --camera".into()))?;
        let (images, skipped) = list_images(&args.input).map_err(|e| setup(e.to_string()))?;
        let total = images.len() as u64;
        let size = Some((camera.width, camera.height));
        let frames = images.into_iter().enumerate().map(move |(seq, path)| {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let frame = read_gray8(&path, size).map(|image| Frame {
                seq: seq as u64,
                capture_time_ns: seq as u64 * FOLDER_FRAME_PERIOD_NS,
                image,
                origin: FrameOrigin::File(path.clone()),
            });
            (name, frame)
        });
        return Ok((Box::new(frames), camera, skipped, total, None));
    }
    if args.input.is_file() {
        // An MCAP log: replay its /camera/image with its own camera unless
        // --camera overrides it.
        let input = args.input.display().to_string();
        let camera = match given_camera {
            Some(c) => c,
            None => ReplayReader::first_camera(&args.input).map_err(|e| setup(e.to_string()))?,
        };
        let reader = replay::open(&args.input).map_err(|e| setup(format!("input {input}: {e}")))?;
        let oversized = reader.oversized();
        let frames = reader.enumerate().map(|(i, item)| match item {
            Ok(frame) => (frame.seq.to_string(), Ok(frame)),
            Err(e) => (format!("#{i}"), Err(e.to_string())),
        });
        return Ok((Box::new(frames), camera, 0, 0, Some(oversized)));
    }
    Err(setup(format!(
        "input {}: neither a folder of images nor an MCAP log",
        args.input.display()
    )))
}

/// What the log's `drogue_vision::run` metadata says about the input: the
/// source in `run --source` terms (`mcap:` or `dir:`), the camera file, and
/// no MAVLink (`process` sends none).
fn provenance(args: &ProcessArgs) -> crate::log::metadata::RunProvenance {
    let input = args.input.display().to_string();
    let (source, source_details) = if args.input.is_dir() {
        (format!("dir:{input}"), vec![("folder".into(), input)])
    } else {
        (
            format!("mcap:{input}"),
            vec![("replayed_log".into(), input)],
        )
    };
    crate::log::metadata::RunProvenance {
        source,
        source_details,
        camera_file: match &args.camera {
            Some(c) => c.display().to_string(),
            None => "(the input log's /camera/calibration)".into(),
        },
        mavlink: "none (process sends no MAVLink)".into(),
        clock: "source".into(),
    }
}

/// Runs `process`. Progress on stderr when it is a terminal.
pub fn run(args: &ProcessArgs) -> Result<ProcessSummary, ProcessError> {
    let setup = |e: String| ProcessError::Setup(e);
    let mut config = Config::load(args.config.as_deref()).map_err(|e| setup(e.to_string()))?;
    if let Some(r) = args.radius {
        if !(r > 0.0 && r < config.drogue.canopy_radius_m) {
            return Err(setup(format!(
                "--radius {r}: must be > 0 and below the canopy radius {} m",
                config.drogue.canopy_radius_m
            )));
        }
        config.drogue.inner_radius_m = r;
    }
    let (frames, camera, skipped, total, oversized) = open_input(args)?;
    // The first frame decides before anything is written: a calibration of
    // another size is refused (exit 2, no output files).
    let mut frames = frames.peekable();
    match frames.peek() {
        Some((_, Ok(first))) => camera
            .check_frame_size(first.image.width(), first.image.height())
            .map_err(setup)?,
        // A folder's images are refused by their headers.
        Some((_, Err(e))) if crate::image_io::is_size_mismatch(e) => return Err(setup(e.clone())),
        _ => {}
    }
    let mount = Mount::from_config(&config.mount).map_err(setup)?;
    let camera_size = (camera.width, camera.height);
    let mut measurer = Measurer::new(camera.clone(), &config).map_err(|e| setup(e.to_string()))?;
    let mut log_config = config.log.clone();
    log_config.set_drogue(config.drogue.inner_radius_m, config.drogue.canopy_radius_m);
    let log = match &args.log {
        Some(path) => Some(
            FlightLog::start_file(&log_config, path, &camera).map_err(|e| {
                ProcessError::Output {
                    path: path.display().to_string(),
                    message: e.to_string(),
                }
            })?,
        ),
        None => None,
    };
    // The log's times are the frames' capture times (the input's own, or
    // made up for a folder): every topic on that clock, as `run --fast`.
    let clock = crate::clock::RunClock::source(0);
    if let Some(log) = &log {
        log.set_clock(clock.clone());
        log.metadata(
            crate::log::metadata::RUN_METADATA,
            crate::log::metadata::run_metadata(&config, &provenance(args)),
        );
    }

    let out_err = |e: std::io::Error| ProcessError::Output {
        path: args.out.display().to_string(),
        message: e.to_string(),
    };
    let mut out = BufWriter::new(std::fs::File::create(&args.out).map_err(out_err)?);
    let bar = progress_bar(total);
    let mut summary = ProcessSummary {
        skipped,
        ..Default::default()
    };
    let mut measure_time = std::time::Duration::ZERO;
    for (name, item) in frames {
        // Frames are sized by the calibration (a log's, or --camera).
        let item = item.and_then(|f| check_frame_size(&f.image, measurer.camera()).map(|()| f));
        let record = match item {
            Err(e) => {
                summary.unreadable += 1;
                tracing::warn!(frame = %name, "unreadable frame: {e}");
                DetectionRecord::unreadable(name, e)
            }
            Ok(frame) if camera_size != (frame.image.width(), frame.image.height()) => {
                let e = format!(
                    "{}x{} frame, the camera calibration is for {}x{}",
                    frame.image.width(),
                    frame.image.height(),
                    camera_size.0,
                    camera_size.1
                );
                summary.unreadable += 1;
                tracing::warn!(frame = %name, "frame skipped: {e}");
                DetectionRecord::unreadable(name, e)
            }
            Ok(frame) => {
                if args.independent {
                    measurer.forget_track();
                }
                clock.start_at(frame.capture_time_ns);
                clock.advance_to(frame.capture_time_ns);
                let t = Instant::now();
                let m = measurer.measure(&frame);
                measure_time += t.elapsed();
                summary.detected += usize::from(m.detection.is_some());
                let record = DetectionRecord::from_measurement(name, &m);
                if let Some(log) = &log {
                    log.frame(Arc::new(frame));
                    let json = serde_json::to_value(&record).unwrap_or_default();
                    log.measurement(Arc::new(m), json, &mount);
                }
                record
            }
        };
        summary.frames += 1;
        let line = serde_json::to_string(&record).map_err(|e| ProcessError::Output {
            path: args.out.display().to_string(),
            message: e.to_string(),
        })?;
        writeln!(out, "{line}").map_err(out_err)?;
        bar.inc(1);
    }
    out.flush().map_err(out_err)?;
    bar.finish_and_clear();
    if let (Some(log), Some(path)) = (log, &args.log) {
        let written = log.finish().map_err(|e| ProcessError::Output {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        if written.dropped_write_error > 0 {
            return Err(ProcessError::Output {
                path: path.display().to_string(),
                message: format!("{} items could not be written", written.dropped_write_error),
            });
        }
        summary.log_file = written.files.first().cloned();
    }
    summary.oversized_records = oversized.map_or(0, |o| o.records());
    let readable = summary.frames - summary.unreadable;
    if readable > 0 {
        summary.ms_per_frame = measure_time.as_secs_f64() * 1e3 / readable as f64;
    }
    Ok(summary)
}
