//! The `drogue-vision` command line (ARCHITECTURE.md section 5).

use clap::{Parser, Subcommand};
use drogue_vision::commands;
use drogue_vision::config::Config;
use drogue_vision::log::LogLayer;
use std::process::ExitCode;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Registry, reload};

#[derive(Parser)]
#[command(
    name = "drogue-vision",
    version,
    about = "Drogue pose from one camera, streamed to ArduPilot/PX4 over MAVLink, logged to MCAP"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The live pipeline: frames in, pose out over MAVLink, everything logged.
    Run(commands::run::RunArgs),
    /// Offline measurement of a folder of images or an MCAP log, to JSON lines.
    Process(commands::process::ProcessArgs),
    /// Post-flight review of an MCAP log: summary, poses.csv and plots.
    Review(commands::review::ReviewArgs),
    /// Rewrite a cut-short MCAP log into a complete, indexed one.
    Recover(commands::recover::RecoverArgs),
    /// Render a simulated scenario to PNG frames, truth.jsonl, camera.yaml and mount.toml.
    Sim(commands::sim::SimArgs),
    /// Print a shell completion script to stdout.
    #[command(after_help = "bash: drogue-vision completions bash > \
/etc/bash_completion.d/drogue-vision; zsh: drogue-vision completions zsh > \
\"${fpath[1]}/_drogue-vision\"; fish: drogue-vision completions fish > \
~/.config/fish/completions/drogue-vision.fish. Exit status: 0.")]
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Print the man page (roff) to stdout, or write one page per command to --dir.
    #[command(after_help = "man <(drogue-vision man), or: drogue-vision man --dir \
/usr/local/share/man/man1 (drogue-vision.1, drogue-vision-run.1, ...). Exit status: 0 done; \
1 the pages could not be written.")]
    Man {
        /// Folder for drogue-vision.1 and one page per subcommand.
        #[arg(long)]
        dir: Option<std::path::PathBuf>,
    },
}

/// Prints the completion script for `shell`.
fn completions(shell: clap_complete::Shell) -> ExitCode {
    let mut cmd = <Cli as clap::CommandFactory>::command();
    clap_complete::generate(shell, &mut cmd, "drogue-vision", &mut std::io::stdout());
    ExitCode::SUCCESS
}

/// The man pages: the top one to stdout, or every page into `dir`.
fn man(dir: Option<&std::path::Path>) -> ExitCode {
    let cmd = <Cli as clap::CommandFactory>::command();
    let result = match dir {
        None => clap_mangen::Man::new(cmd).render(&mut std::io::stdout()),
        Some(dir) => std::fs::create_dir_all(dir).and_then(|()| clap_mangen::generate_to(cmd, dir)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: writing the man page: {e}");
            ExitCode::from(1)
        }
    }
}

/// Where `run` plugs the MCAP `/log` layer in once the log is open.
type LogSlot = reload::Handle<Option<LogLayer>, Registry>;

/// tracing to stderr (filter from `RUST_LOG`, default `info`), plus a slot
/// for the flight log's layer, so the same events reach MCAP `/log`.
fn init_tracing() -> LogSlot {
    let (slot, handle) = reload::Layer::new(None::<LogLayer>);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    tracing_subscriber::registry()
        .with(slot)
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(drogue_vision::pipeline::status::StderrWriter::new())
                .with_ansi(drogue_vision::pipeline::status::colour_allowed()),
        )
        .with(filter)
        .init();
    handle
}

/// Exit status 2: nothing could start (arguments, config, files).
fn setup_failure(e: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {e}");
    ExitCode::from(2)
}

/// Exit status of a log command: 2 for unusable input, 1 for I/O failures.
fn log_error_exit(e: drogue_vision::log::LogError) -> ExitCode {
    eprintln!("error: {e}");
    match e {
        drogue_vision::log::LogError::Format { .. } | drogue_vision::log::LogError::Config(_) => {
            ExitCode::from(2)
        }
        _ => ExitCode::from(1),
    }
}

fn run(args: commands::run::RunArgs, slot: LogSlot) -> ExitCode {
    let config = match Config::load(args.config.as_deref()) {
        Ok(c) => c,
        Err(e) => return setup_failure(e),
    };
    let plug_log = |log: &drogue_vision::log::LogHandle| {
        if let Err(e) = slot.reload(Some(log.tracing_layer())) {
            tracing::warn!("tracing events will not reach the MCAP /log topic: {e}");
        }
    };
    match commands::run::run(&args, config, plug_log) {
        Ok(s) => {
            eprintln!("{}", commands::run::report(&s));
            ExitCode::SUCCESS
        }
        Err(e @ commands::run::RunError::Setup(_)) => setup_failure(e),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}

fn main() -> ExitCode {
    let slot = init_tracing();
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => run(args, slot),
        Command::Process(args) => match commands::process::run(&args) {
            Ok(s) => {
                eprintln!(
                    "{} frames, {} detected, {} unreadable, {} other files skipped, {:.2} ms per frame",
                    s.frames, s.detected, s.unreadable, s.skipped, s.ms_per_frame
                );
                if !s.missed_by_reason.is_empty() {
                    eprintln!(
                        "not detected: {}",
                        drogue_vision::measure::miss::counts_line(&s.missed_by_reason)
                    );
                }
                if s.oversized_records > 0 {
                    eprintln!(
                        "{} MCAP records above the {} MiB record bound skipped unread \
                         (frames they held are missing)",
                        s.oversized_records,
                        drogue_vision::log::oversized::RECORD_LIMIT_BYTES >> 20
                    );
                }
                if let Some(log) = &s.log_file {
                    eprintln!("log: {}", log.display());
                }
                ExitCode::SUCCESS
            }
            Err(e @ commands::process::ProcessError::Output { .. }) => {
                eprintln!("error: {e}");
                ExitCode::from(1)
            }
            Err(e) => setup_failure(e),
        },
        Command::Review(args) => match commands::review::run(&args) {
            Ok(report) => {
                print!("{report}");
                ExitCode::SUCCESS
            }
            Err(e) => log_error_exit(e),
        },
        Command::Recover(args) => match commands::recover::run(&args) {
            Ok((out, r)) => {
                eprintln!("wrote {}: {r}", out.display());
                ExitCode::SUCCESS
            }
            Err(e) => log_error_exit(e),
        },
        Command::Completions { shell } => completions(shell),
        Command::Man { dir } => man(dir.as_deref()),
        Command::Sim(args) => match commands::sim::run(&args) {
            Ok(s) => {
                eprintln!(
                    "{} frames ({} expected detectable) written to {}",
                    s.frames,
                    s.expect_detect,
                    s.out.display()
                );
                ExitCode::SUCCESS
            }
            Err(e @ commands::sim::SimCommandError::Output { .. }) => {
                eprintln!("error: {e}");
                ExitCode::from(1)
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
    }
}
