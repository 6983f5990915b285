//! `hullcut synth`: a synthetic recording (any rig, tool and look) with exact ground truth.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use hullcut_dataset::Dataset;
use hullcut_synth::{Appearance, SceneConfig, SceneKind, ToolKind, synthesize};
use serde::{Deserialize, Serialize};

use crate::logging::{CameraLogger, log_tool};
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, write_json};

/// Render a synthetic recording of a gloved hand cutting with a scalpel, with ground truth.
///
/// Scenes: `cut` (cut strokes at up to ~0.2 m/s, every camera delivers every frame), `static`
/// (the tool held still in the organ, for averaged accuracy), `hard` (fast strokes peaking at
/// 0.5 m/s, the blade edge-on to two cameras, the index finger over the blade, motion blur, ±15 %
/// exposure drift, camera 4 dropping about 10 % of its frames), `resect` (two strokes along one
/// line down to the table across the built-in organ's left lobe, which cut its tip off in
/// `hullcut run`, then strokes as in `cut`: `hullcut run`'s built-in scene). Deterministic for a
/// seed.
///
/// Writes the dataset OUT (DESIGN "Dataset format", datasets/README.md): dataset.toml, rig.yaml,
/// frames.csv (per-camera timestamps with jitter), CAM/NNNNNN.png, CAM/backgroundNN.png
/// (empty-scene images), masks/CAM/NNNNNN.png (0 background, 1 hand, 2 scalpel),
/// depth/CAM/NNNNNN.png (16-bit, mm; not with --no-depth), tool.json + tool.ply, truth/poses.jsonl and
/// truth/meshes/LABEL/NNNNNN.ply (CAM is a camera name, LABEL hand or scalpel; not with
/// --no-truth-meshes). The dataset is written to a temporary folder and renamed into
/// place when complete. Also REPORT (JSON) with --report and an .rrd (undistorted images and masks
/// under world/cams/NAME every --rrd-every frames, the true tool under world/tool/truth) with --rrd.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Output dataset folder (refused if it exists, unless --force).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of frame sets (at least 1).
    #[arg(long, value_name = "N", default_value_t = 120, value_parser = clap::value_parser!(u64).range(1..))]
    frames: u64,
    /// Seed for the trajectory, timing jitter, drops and noise.
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// The scene (see above; `resect` is `hullcut run`'s built-in scene).
    #[arg(long, value_name = "NAME", default_value = "cut", value_parser = scene_parser())]
    scene: SceneKind,
    /// Frame rate, frames per second (above 0).
    #[arg(long, value_name = "FPS", default_value_t = 30.0, value_parser = super::positive)]
    fps: f64,
    /// The rig: default, lab8, random:SEED, or a rig.yaml file.
    #[arg(long, value_name = "NAME|rig.yaml", default_value = "default")]
    rig: String,
    /// The scalpel (written to tool.json).
    #[arg(long, value_name = "NAME", default_value = "standard", value_parser = tool_parser())]
    tool: ToolKind,
    /// The look: classic, purple-nitrile, latex, skin-light, skin-medium, skin-dark, random:SEED.
    #[arg(long, value_name = "NAME", default_value = "classic", value_parser = parse_appearance)]
    appearance: Appearance,
    /// Empty-scene images per camera (CAM/backgroundNN.png) for the background model.
    #[arg(long, value_name = "N", default_value_t = 5)]
    background_frames: usize,
    /// Compress PNGs as hard as possible (several times slower; for datasets that are shipped).
    #[arg(long)]
    compact: bool,
    /// Replace OUT if it exists.
    #[arg(long)]
    force: bool,
    /// Do not write per-frame truth meshes (truth/meshes/).
    #[arg(long)]
    no_truth_meshes: bool,
    /// Do not write the views' depth maps (depth/; only `hullcut bench hull` scores against
    /// them): a tenth less disk.
    #[arg(long)]
    no_depth: bool,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Log the dataset, read back from OUT, to this rerun recording.
    #[arg(long, value_name = "FILE")]
    rrd: Option<PathBuf>,
    /// Log images and masks every N-th frame to the .rrd (poses every frame).
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    rrd_every: u64,
}

/// The report (docs/reports.md, `kind: "synth"`).
#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    scene: String,
    rig: String,
    tool: String,
    appearance: String,
    seed: u64,
    fps: f64,
    frames: u64,
    cameras: usize,
    out: String,
    views: usize,
    dropped_views: usize,
    mean_scalpel_pixels_per_view: f64,
    mean_hand_pixels_per_view: f64,
    peak_tip_speed_m_s: f64,
    skipped_triangles: usize,
    seconds: f64,
    frame_sets_per_s: f64,
}

/// `--scene`: a name of [`SceneKind::ALL`], which clap lists in `--help` and when refusing another.
fn scene_parser() -> impl TypedValueParser<Value = SceneKind> {
    PossibleValuesParser::new(SceneKind::ALL.map(|(_, name)| name))
        .try_map(|name| SceneKind::from_name(&name).ok_or_else(|| format!("unknown scene {name}")))
}

/// `--tool`: a name of [`ToolKind::ALL`], listed as `--scene`'s are.
fn tool_parser() -> impl TypedValueParser<Value = ToolKind> {
    PossibleValuesParser::new(ToolKind::ALL.map(|(_, name)| name))
        .try_map(|name| ToolKind::from_name(&name).ok_or_else(|| format!("unknown tool {name}")))
}

fn parse_appearance(s: &str) -> Result<Appearance, String> {
    Appearance::from_name(s).ok_or_else(|| format!("unknown look (known: {})", Appearance::NAMES))
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let kind = args.scene;
    let mut config = SceneConfig::new(kind, args.seed, args.frames);
    config.fps = args.fps;
    config.tool = args.tool;
    config.appearance = args.appearance.clone();
    config.truth_meshes = !args.no_truth_meshes;
    config.depth_maps = !args.no_depth;
    config.background_frames = args.background_frames;
    if args.compact {
        config.compression = hullcut_dataset::PngCompression::Best;
    }
    config.rig = crate::commands::rig::load_rig(&args.rig).context("--rig")?;
    if kind == SceneKind::Hard && config.rig.len() <= 4 {
        config.dropping_camera = Some((config.rig.len() - 1, 0.1));
    }
    let t0 = Instant::now();
    let scene = hullcut_synth::Scene::new(config).context("preparing the scene")?;
    tracing::info!(seconds = t0.elapsed().as_secs_f64(), "cameras prepared");
    let pb = bar(args.frames, "rendering");
    let name =
        format!("{}-{}-{}-seed{}", kind.name(), args.appearance.name.replace(':', ""), args.tool.name(), args.seed);
    let summary = synthesize(&scene, &args.out, &name, args.force, &|| pb.inc(1))
        .with_context(|| format!("writing {}", args.out.display()))?;
    pb.finish_and_clear();
    println!(
        "wrote {} ({} frame sets, {} images, {} dropped) in {:.1} s",
        summary.path.display(),
        summary.frames,
        summary.views,
        summary.dropped_views,
        summary.seconds
    );
    if let Some(path) = &args.report {
        let duration = args.frames as f64 / args.fps;
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "synth".to_owned(),
            provenance: Provenance::current(),
            scene: kind.name().to_owned(),
            rig: args.rig.clone(),
            tool: args.tool.name().to_owned(),
            appearance: args.appearance.name.clone(),
            seed: args.seed,
            fps: args.fps,
            frames: args.frames,
            cameras: scene.config().rig.len(),
            out: summary.path.display().to_string(),
            views: summary.views,
            dropped_views: summary.dropped_views,
            mean_scalpel_pixels_per_view: summary.mean_scalpel_pixels,
            mean_hand_pixels_per_view: summary.mean_hand_pixels,
            peak_tip_speed_m_s: scene.trajectory().peak_tip_speed(duration),
            skipped_triangles: summary.skipped_triangles,
            seconds: summary.seconds,
            frame_sets_per_s: summary.frames as f64 / summary.seconds.max(1e-9),
        };
        write_json(path, &report)?;
    }
    if let Some(path) = &args.rrd {
        log_dataset(&summary.path, path, args.rrd_every)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Reads a dataset back (through the same reader a lab's recording goes through) and logs it.
fn log_dataset(dataset: &std::path::Path, rrd: &std::path::Path, every: u64) -> anyhow::Result<()> {
    let ds = Dataset::open(dataset)?;
    let rec = hullcut_viz::open_recording("hullcut-synth", &hullcut_viz::Sink::File(rrd.to_path_buf()))?;
    hullcut_viz::log_world(&rec)?;
    let cams = CameraLogger::new(&rec, ds.rig())?;
    let tool = ds.tool()?;
    let poses = ds.truth_poses()?.unwrap_or_default();
    let frames = ds.frame_numbers();
    let pb = bar(frames.len() as u64, "logging");
    for &frame in &frames {
        hullcut_viz::set_frame(&rec, frame as i64);
        if frame % every == 0 {
            let set = ds.read_frame_set(frame, true)?;
            hullcut_viz::set_capture_time_ns(&rec, set.timestamp_ns);
            cams.log_frame_set(&rec, &set)?;
        }
        if let (Some(tool), Some(pose)) = (&tool, poses.iter().find(|p| p.frame == frame)) {
            hullcut_viz::set_capture_time_ns(&rec, pose.timestamp_ns);
            log_tool(&rec, "truth", tool, &pose.tool_to_world)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    hullcut_viz::flush(&rec)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_round_trips_through_json() {
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "synth".to_owned(),
            provenance: Provenance::current(),
            scene: "resect".to_owned(),
            rig: "random:7".to_owned(),
            tool: "pointed".to_owned(),
            appearance: "purple-nitrile".to_owned(),
            seed: 7,
            fps: 30.0,
            frames: 4,
            cameras: 6,
            out: "/tmp/a \"quoted\", odd path".to_owned(),
            views: 22,
            dropped_views: 2,
            mean_scalpel_pixels_per_view: 812.5,
            mean_hand_pixels_per_view: 20_480.25,
            peak_tip_speed_m_s: 0.5,
            skipped_triangles: 0,
            seconds: 1.75,
            frame_sets_per_s: 2.5,
        };
        let (first, again) = crate::report::json_round_trip(&report);
        assert_eq!(first, again);
        let value: serde_json::Value = serde_json::from_str(&first).expect("JSON");
        // The provenance is flattened into the report's top level, as docs/reports.md lists it.
        assert_eq!(value["git_hash"], crate::report::GIT_HASH);
        assert_eq!(value["scene"], "resect");
    }
}
