//! `drogue-vision process`: offline measurement of a folder of images (or an
//! MCAP log), one JSON line per frame: the `run` sources and measurement
//! stage ([`crate::pipeline`]), in one thread, frame by frame.

use crate::camera::CameraModel;
use crate::config::Config;
use crate::image_io::check_frame_size;
use crate::log::FlightLog;
use crate::measure::Measurer;
use crate::measure::mount::Mount;
use crate::pipeline::input::choose_camera;
use crate::pipeline::provenance::{RunProvenance, run_metadata};
use crate::pipeline::stage::MeasureStage;
use crate::record::DetectionRecord;
use crate::source::dir::{DirSource, FolderTiming};
use crate::source::mcap::McapSource;
use crate::source::{Captured, FrameSource, SourceItem};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
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
    /// A folder of images (png, jpg, pgm, bmp; lexicographic order), one image, or an MCAP log.
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
    /// Input frames, one JSON line each (readable or not).
    pub frames: usize,
    /// Frames with a drogue detected.
    pub detected: usize,
    /// The readable frames without one, by the reason their records give
    /// (`not_detected.reason`).
    pub missed_by_reason: std::collections::BTreeMap<String, u64>,
    /// Frames that could not be read or decoded (their lines carry `error`).
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
    Output {
        /// The file that could not be written.
        path: String,
        /// The I/O error.
        message: String,
    },
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

/// The input's frames through the `run` sources: a folder (`dir:`, frames
/// [`FOLDER_FRAME_PERIOD_NS`] apart from 0) or a log (`mcap:`, its own times).
enum Input {
    Dir(DirSource),
    Mcap(Box<McapSource>),
}

impl Input {
    fn open(args: &ProcessArgs) -> Result<Self, ProcessError> {
        let setup = |e: crate::source::SourceError| ProcessError::Setup(e.to_string());
        if args.input.is_dir() {
            if args.camera.is_none() {
                return Err(ProcessError::Setup(
                    "a folder of images needs --camera".into(),
                ));
            }
            let timing = FolderTiming::Period(FOLDER_FRAME_PERIOD_NS);
            return Ok(Self::Dir(
                DirSource::open(&args.input, timing).map_err(setup)?,
            ));
        }
        if args.input.is_file() && crate::image_io::is_image_path(&args.input) {
            // One image: a folder of one.
            if args.camera.is_none() {
                return Err(ProcessError::Setup("an image needs --camera".into()));
            }
            let timing = FolderTiming::Period(FOLDER_FRAME_PERIOD_NS);
            return Ok(Self::Dir(DirSource::one_image(&args.input, timing)));
        }
        if args.input.is_file() {
            // An MCAP log: replay its /camera/image with its own camera
            // unless --camera overrides it.
            let input = args.input.display().to_string();
            return McapSource::open(&args.input)
                .map(|m| Self::Mcap(Box::new(m)))
                .map_err(|e| ProcessError::Setup(format!("input {input}: {e}")));
        }
        Err(ProcessError::Setup(format!(
            "input {}: neither a folder of images, an image nor an MCAP log",
            args.input.display()
        )))
    }

    fn source(&mut self) -> &mut dyn FrameSource {
        match self {
            Self::Dir(d) => d,
            Self::Mcap(m) => m.as_mut(),
        }
    }

    /// The next item, named for its record: a file's name (an unreadable
    /// file's error without its path, which the name gives), or a log
    /// frame's sequence number (`#i` for the i-th item when unreadable).
    fn next_named(&mut self, index: usize) -> Option<(String, SourceItem)> {
        let path = match self {
            Self::Dir(d) => d.peek_path().map(Path::to_path_buf),
            Self::Mcap(_) => None,
        };
        let item = self.source().next_frame()?;
        Some(match (path, item) {
            (Some(path), item) => {
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let prefix = format!("{}: ", path.display());
                let item =
                    item.map_err(|e| e.strip_prefix(&prefix).map_or(e.clone(), str::to_owned));
                (name, item)
            }
            (None, Ok(c)) => (c.frame.seq.to_string(), Ok(c)),
            (None, Err(e)) => (format!("#{index}"), Err(e)),
        })
    }
}

/// What the log's `drogue_vision::run` metadata says about the input: the
/// source in `run --source` terms (`mcap:` or `dir:`), the camera file, and
/// no MAVLink (`process` sends none).
fn provenance(args: &ProcessArgs) -> RunProvenance {
    let input = args.input.display().to_string();
    let (source, source_details) = if args.input.is_dir() {
        (format!("dir:{input}"), vec![("folder".into(), input)])
    } else if crate::image_io::is_image_path(&args.input) {
        (format!("image:{input}"), vec![("image".into(), input)])
    } else {
        (
            format!("mcap:{input}"),
            vec![("replayed_log".into(), input)],
        )
    };
    RunProvenance {
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

/// The input's first item, checked against the camera before anything is
/// written (a calibration of another size: exit 2, no output files).
fn first_item_named(
    input: &mut Input,
    camera: &CameraModel,
) -> Result<Option<(String, SourceItem)>, ProcessError> {
    input.source().expect_size(camera.width, camera.height);
    let first = input.next_named(0);
    match &first {
        Some((_, Ok(c))) => camera
            .check_frame_size(c.frame.image.width(), c.frame.image.height())
            .map_err(ProcessError::Setup)?,
        // A folder's images are refused by their headers.
        Some((_, Err(e))) if crate::image_io::is_size_mismatch(e) => {
            return Err(ProcessError::Setup(e.clone()));
        }
        _ => {}
    }
    Ok(first)
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
    let mut input = Input::open(args)?;
    let (skipped, total) = match &input {
        Input::Dir(d) => (d.other_files(), d.images() as u64),
        Input::Mcap(_) => (0, 0),
    };
    let camera =
        choose_camera(input.source(), args.camera.as_deref(), Path::new("")).map_err(setup)?;
    // The first frame decides before anything is written: a calibration of
    // another size is refused (exit 2, no output files).
    let mut first = Some(first_item_named(&mut input, &camera)?);
    let mount = Mount::from_config(&config.mount).map_err(setup)?;
    let measurer =
        Measurer::new(camera.clone(), &config.measure()).map_err(|e| setup(e.to_string()))?;
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
            run_metadata(&config, &provenance(args)),
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
    let mut stage = MeasureStage::new(measurer, mount, None, log.clone(), clock.clone());
    let mut index = 0;
    while let Some((name, item)) = first.take().flatten().or_else(|| input.next_named(index)) {
        index += 1;
        // Frames are sized by the calibration (a log's, or --camera).
        let item = item.and_then(|c| check_frame_size(&c.frame.image, &camera).map(|()| c));
        let record = match item {
            Err(e) => {
                summary.unreadable += 1;
                tracing::warn!(frame = %name, "unreadable frame: {e}");
                DetectionRecord::unreadable(name, e)
            }
            Ok(Captured { frame, truth }) => {
                if args.independent {
                    stage.measurer_mut().forget_track();
                }
                clock.start_at(frame.capture_time_ns);
                clock.advance_to(frame.capture_time_ns);
                // Shared with the log, not copied (a frame is megabytes).
                let frame = Arc::new(frame);
                if let Some(log) = &log {
                    log.frame_with_truth(Arc::clone(&frame), truth);
                }
                let t = Instant::now();
                let measured = stage.measure(&frame, name);
                measure_time += t.elapsed();
                summary.detected += usize::from(measured.measurement.detection.is_some());
                if let Some(miss) = &measured.measurement.miss {
                    *summary
                        .missed_by_reason
                        .entry(miss.reason.code().to_string())
                        .or_default() += 1;
                }
                measured.record
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
    if let Input::Mcap(m) = &input {
        summary.oversized_records = m.oversized_records();
    }
    let readable = summary.frames - summary.unreadable;
    if readable > 0 {
        summary.ms_per_frame = measure_time.as_secs_f64() * 1e3 / readable as f64;
    }
    Ok(summary)
}
