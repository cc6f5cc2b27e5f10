//! `drogue-vision sim`: render a scenario to PNG frames, `truth.jsonl`,
//! `camera.yaml` (ROS camera_info) and `mount.toml`, the scenario's camera
//! mount as a config fragment (`[mount]`), so that `process --camera
//! OUT/camera.yaml --config OUT/mount.toml OUT` measures in the same body
//! frame as the truth's `position_body`.

use drogue_sim::{Scenario, Simulator};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};

/// Arguments of `sim` (see `drogue-vision sim --help`).
#[derive(Clone, Debug, clap::Args)]
#[command(
    after_help = "Builtin scenarios: approach, station_keeping, severe_turbulence, low_sun, \
contact. Writes the frames (PNG), truth.jsonl, camera.yaml and mount.toml (the scenario's \
camera mount, a config fragment for `process --config`). Exit status: 0 done; 1 the output could not be written; 2 bad scenario or arguments."
)]
pub struct SimArgs {
    /// Builtin scenario name or a scenario TOML file.
    #[arg(long, default_value = "approach")]
    pub scenario: String,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Render only the first N frames (default: the whole scenario).
    #[arg(long)]
    pub frames: Option<u64>,
}

/// What a `sim` run wrote.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimSummary {
    /// Frames rendered and written.
    pub frames: u64,
    /// Frames whose truth says the drogue should be detected.
    pub expect_detect: u64,
    /// The output folder.
    pub out: PathBuf,
}

/// Why `sim` stopped.
#[derive(Debug, thiserror::Error)]
pub enum SimCommandError {
    /// Scenario unusable: nothing was written.
    #[error("{0}")]
    Setup(String),
    /// The output could not be written.
    #[error("writing {path}: {message}")]
    Output {
        /// The file or folder that could not be written.
        path: String,
        /// The I/O error.
        message: String,
    },
}

fn output_err(path: &Path, e: impl std::fmt::Display) -> SimCommandError {
    SimCommandError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The scenario's camera mount as a config fragment `--config` takes, and
/// its exposure time when its frames are motion-blurred (from which a
/// tracked frame's blur is predicted, as `run` does with `sim:`).
fn mount_fragment(sim: &Simulator) -> Result<String, SimCommandError> {
    #[derive(serde::Serialize)]
    struct Exposure {
        exposure_ms: f64,
    }
    #[derive(serde::Serialize)]
    struct Fragment {
        #[serde(skip_serializing_if = "Option::is_none")]
        camera: Option<Exposure>,
        mount: crate::measure::mount::MountConfig,
    }
    let exposure = crate::source::sim::scenario_exposure(sim.scenario());
    let body = toml::to_string(&Fragment {
        camera: exposure.map(|e| Exposure {
            exposure_ms: e.as_secs_f64() * 1e3,
        }),
        mount: crate::source::sim::mount_config(sim.mount()),
    })
    .map_err(|e| SimCommandError::Setup(format!("the scenario's mount: {e}")))?;
    Ok(format!(
        "# The camera mount of this simulated scenario (drogue-vision sim), and its\n\
         # exposure time when its frames are motion-blurred.\n\
         # Use it with the frames: process --camera camera.yaml --config mount.toml .\n{body}"
    ))
}

/// Renders the scenario into `args.out`.
pub fn run(args: &SimArgs) -> Result<SimSummary, SimCommandError> {
    let scenario =
        Scenario::resolve(&args.scenario).map_err(|e| SimCommandError::Setup(e.to_string()))?;
    let mut sim = Simulator::new(scenario).map_err(|e| SimCommandError::Setup(e.to_string()))?;
    let total = args
        .frames
        .map_or(sim.frame_count(), |n| n.min(sim.frame_count()));
    std::fs::create_dir_all(&args.out).map_err(|e| output_err(&args.out, e))?;
    let camera_path = args.out.join("camera.yaml");
    std::fs::write(&camera_path, sim.camera_yaml()).map_err(|e| output_err(&camera_path, e))?;
    let mount_path = args.out.join("mount.toml");
    std::fs::write(&mount_path, mount_fragment(&sim)?).map_err(|e| output_err(&mount_path, e))?;
    let truth_path = args.out.join("truth.jsonl");
    let file = std::fs::File::create(&truth_path).map_err(|e| output_err(&truth_path, e))?;
    let mut truth_out = BufWriter::new(file);
    let bar = if std::io::stderr().is_terminal() {
        let b = ProgressBar::new(total);
        if let Ok(style) =
            ProgressStyle::with_template("{bar:40} {pos}/{len} frames {per_sec} eta {eta}")
        {
            b.set_style(style);
        }
        b
    } else {
        ProgressBar::hidden()
    };
    let mut summary = SimSummary {
        out: args.out.clone(),
        ..SimSummary::default()
    };
    for (img, truth) in sim.by_ref().take(total as usize) {
        let png = args.out.join(&truth.frame);
        img.save_with_format(&png, image::ImageFormat::Png)
            .map_err(|e| output_err(&png, e))?;
        let line = serde_json::to_string(&truth).map_err(|e| output_err(&truth_path, e))?;
        writeln!(truth_out, "{line}").map_err(|e| output_err(&truth_path, e))?;
        summary.frames += 1;
        summary.expect_detect += u64::from(truth.expect == "detect");
        bar.inc(1);
    }
    truth_out.flush().map_err(|e| output_err(&truth_path, e))?;
    bar.finish_and_clear();
    Ok(summary)
}
