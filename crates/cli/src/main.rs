//! `hullcut`: six synchronized cameras → visual hull of hand and scalpel → blade pose → cuts in a
//! simulated organ. This binary wires the stages together; see `hullcut --help`.
//!
//! Exit codes: 0 success, 1 failure (the error is printed), 2 bad usage.

mod chart;
mod commands;
mod frames;
mod logging;
mod pose_out;
mod progress;
mod report;
mod volume;
mod weak;

use hullcut_pipeline::{backend, labelling};

use std::fmt::Write as _;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Longest line of an error message printed, in characters: a longer one (a value given whole on
/// the command line, a file's content quoted) is cut, saying how much was left out.
const MAX_LINE_CHARS: usize = 300;
/// Most lines of an error message printed.
const MAX_LINES: usize = 60;

/// Markerless scalpel tracking from six cameras and real-time virtual cutting of soft tissue.
///
/// Every command that measures something can write a JSON report (--report FILE) and log to rerun
/// (--rrd FILE). Logs go to stderr; set RUST_LOG (e.g. RUST_LOG=debug) for more detail.
/// Exit codes: 0 success, 1 failure, 2 bad usage.
#[derive(Debug, Parser)]
#[command(name = "hullcut", version = report::VERSION, about, long_about)]
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
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e),
    };
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
            eprintln!("error: {}", error_message(&e));
            ExitCode::FAILURE
        }
    }
}

/// What clap found (bad usage: exit 2; --help and --version: exit 0), printed as clap prints it,
/// unless an error's line is too long (a value given whole): then cut, uncoloured.
fn usage_error(e: &clap::Error) -> ExitCode {
    let text = e.render().to_string();
    let fits = text.lines().count() <= MAX_LINES && text.lines().all(|l| l.chars().count() <= MAX_LINE_CHARS);
    // Help asked for, or shown for a command given without its subcommand, is printed whole.
    let help = !e.use_stderr() || e.kind() == clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand;
    if help || fits {
        e.exit();
    }
    eprint!("{}", cap_lines(&text));
    ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2))
}

/// The error and its causes, each said once (a cause whose text an earlier message already holds
/// is left out), joined by ": " as anyhow's `{:#}` joins them, long lines cut.
fn error_message(e: &anyhow::Error) -> String {
    let mut said: Vec<String> = Vec::new();
    for cause in e.chain() {
        let text = cause.to_string();
        let text = text.trim();
        if text.is_empty() || said.iter().any(|s| s.contains(text)) {
            continue;
        }
        said.push(text.to_owned());
    }
    cap_lines(&said.join(": "))
}

/// `text` with every line cut to [`MAX_LINE_CHARS`] characters and at most [`MAX_LINES`] lines,
/// each cut saying how much it left out.
fn cap_lines(text: &str) -> String {
    let mut out = String::new();
    let lines = text.split_inclusive('\n').count();
    for line in text.split_inclusive('\n').take(MAX_LINES) {
        let (body, end) = line.strip_suffix('\n').map_or((line, ""), |body| (body, "\n"));
        let n = body.chars().count();
        if n > MAX_LINE_CHARS {
            out.extend(body.chars().take(MAX_LINE_CHARS));
            let _ = write!(out, "…({} more chars)", n - MAX_LINE_CHARS);
        } else {
            out.push_str(body);
        }
        out.push_str(end);
    }
    if lines > MAX_LINES {
        let _ = writeln!(out, "…({} more lines)", lines - MAX_LINES);
    }
    out
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory as _;

    use super::*;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn each_cause_is_said_once() {
        let e = anyhow::anyhow!("No such file or directory (os error 2)")
            .context("reading rig.yaml: No such file or directory (os error 2)")
            .context("--rig");
        assert_eq!(error_message(&e), "--rig: reading rig.yaml: No such file or directory (os error 2)");
        let e = anyhow::anyhow!("not a number").context("--offset cam0=x");
        assert_eq!(error_message(&e), "--offset cam0=x: not a number");
    }

    #[test]
    fn long_values_are_cut() {
        let value = "7".repeat(100_000);
        let e = anyhow::anyhow!("bad value {value}").context("--frames");
        let message = error_message(&e);
        // "--frames: bad value " is 20 characters.
        let left_out = 20 + value.len() - MAX_LINE_CHARS;
        assert!(message.ends_with(&format!("…({left_out} more chars)")), "{message}");
        assert!(message.chars().count() < MAX_LINE_CHARS + 30, "{message}");
        let many = "line\n".repeat(1000);
        let capped = cap_lines(&many);
        assert_eq!(capped.lines().count(), MAX_LINES + 1, "{capped}");
        assert!(capped.ends_with(&format!("…({} more lines)\n", 1000 - MAX_LINES)), "{capped}");
        assert_eq!(cap_lines("short\nlines\n"), "short\nlines\n");
    }

    #[test]
    fn bad_values_are_bad_usage() {
        let e = Cli::try_parse_from(["hullcut", "synth", "--out", "x", "--scene", "bogus"]).expect_err("bogus scene");
        assert_eq!(e.exit_code(), 2);
        let text = e.render().to_string();
        assert!(text.contains("cut, static, hard, resect"), "{text}");
        let e = Cli::try_parse_from(["hullcut", "synth", "--out", "x", "--frames", "0"]).expect_err("no frames");
        assert_eq!(e.exit_code(), 2);
        let e = Cli::try_parse_from(["hullcut", "synth", "--out", "x", "--fps", "NaN"]).expect_err("NaN fps");
        assert_eq!(e.exit_code(), 2);
        let e = Cli::try_parse_from(["hullcut", "--version"]).expect_err("version is shown, not parsed");
        assert_eq!((e.exit_code(), e.use_stderr()), (0, false));
        assert!(e.render().to_string().contains(report::GIT_HASH));
    }
}
