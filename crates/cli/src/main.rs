//! `hullcut`: six synchronized cameras → visual hull of hand and scalpel → blade pose → cuts in a
//! simulated organ. This binary wires the stages together; see `hullcut --help`.
//!
//! Exit codes: 0 success, 1 failure (the error is printed), 2 bad usage.

mod backend;
mod chart;
mod commands;
mod frames;
mod labelling;
mod logging;
mod pose_out;
mod progress;
mod report;
mod volume;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Markerless scalpel tracking from six cameras and real-time virtual cutting of soft tissue.
///
/// Every command that measures something can write a JSON report (--report FILE) and log to rerun
/// (--rrd FILE). Logs go to stderr; set RUST_LOG (e.g. RUST_LOG=debug) for more detail.
/// Exit codes: 0 success, 1 failure, 2 bad usage.
#[derive(Debug, Parser)]
#[command(name = "hullcut", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Bench(commands::bench::Args),
    Calibrate(commands::calibrate::Args),
    GpuInfo(commands::gpu_info::Args),
    ImportCalibration(commands::import::CalibrationArgs),
    ImportVideos(commands::import::VideosArgs),
    Reconstruct(commands::reconstruct::Args),
    Rig(commands::rig::Args),
    Run(commands::run::Args),
    Segment(commands::segment::Args),
    Sim(commands::sim::Args),
    Synth(commands::synth::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    let result = match cli.command {
        Command::Bench(args) => commands::bench::run(&args),
        Command::Calibrate(args) => commands::calibrate::run(&args),
        Command::GpuInfo(args) => commands::gpu_info::run(&args),
        Command::ImportCalibration(args) => commands::import::calibration(&args),
        Command::ImportVideos(args) => commands::import::videos(&args),
        Command::Reconstruct(args) => commands::reconstruct::run(&args),
        Command::Rig(args) => commands::rig::run(&args),
        Command::Run(args) => commands::run::run(&args),
        Command::Segment(args) => commands::segment::run(&args),
        Command::Sim(args) => commands::sim::run(&args),
        Command::Synth(args) => commands::synth::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
