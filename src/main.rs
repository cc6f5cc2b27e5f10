//! The `drogue-vision` command line (ARCHITECTURE.md section 5).

use clap::{Parser, Subcommand};
use drogue_vision::commands;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "drogue-vision",
    version,
    about = "Drogue pose from one camera, streamed to ArduPilot/PX4 over MAVLink"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Offline measurement of a folder of images or an MCAP log, to JSON lines.
    Process(commands::process::ProcessArgs),
    /// Post-flight review of an MCAP log: summary, poses.csv and plots.
    Review(commands::review::ReviewArgs),
    /// Rewrite a cut-short MCAP log into a complete, indexed one.
    Recover(commands::recover::RecoverArgs),
    /// Render a simulated scenario to PNG frames, truth.jsonl and camera.yaml.
    Sim(commands::sim::SimArgs),
}

fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
}

/// Exit 2 when the input is unusable, 1 when the output could not be written.
fn log_error_exit(e: drogue_vision::log::LogError) -> ExitCode {
    eprintln!("error: {e}");
    match e {
        drogue_vision::log::LogError::Format { .. } | drogue_vision::log::LogError::Config(_) => {
            ExitCode::from(2)
        }
        _ => ExitCode::from(1),
    }
}

fn main() -> ExitCode {
    init_tracing();
    let cli = Cli::parse();
    match cli.command {
        Command::Process(args) => match commands::process::run(&args) {
            Ok(s) => {
                eprintln!(
                    "{} frames, {} detected, {} unreadable, {} other files skipped, {:.2} ms per frame",
                    s.frames, s.detected, s.unreadable, s.skipped, s.ms_per_frame
                );
                ExitCode::SUCCESS
            }
            Err(e @ commands::process::ProcessError::Output { .. }) => {
                eprintln!("error: {e}");
                ExitCode::from(1)
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
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
                eprintln!(
                    "wrote {}: {} messages{}",
                    out.display(),
                    r.messages,
                    r.cut
                        .map(|c| format!(" (the input was cut short: {c})"))
                        .unwrap_or_else(|| " (the input was complete)".into())
                );
                ExitCode::SUCCESS
            }
            Err(e) => log_error_exit(e),
        },
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
