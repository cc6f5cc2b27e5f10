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
