//! `hullcut import-calibration` and `hullcut import-videos`: another tool's calibration and a lab's
//! videos into hullcut's formats.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use hullcut_capture::import::{ImportParams, VideoInput, import_videos};
use hullcut_rig::Rig;
use serde::{Deserialize, Serialize};

use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, write_json};

/// Write a rig.yaml from another tool's calibration.
///
/// From COLMAP (--colmap DIR): the text model's cameras.txt and images.txt, one image per camera
/// (named by its folder, `cam0/000000.png`, or its stem, `cam0.png`); camera models SIMPLE_PINHOLE,
/// PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV without rational terms; poses world →
/// camera as COLMAP stores them; the principal point moved by half a pixel (COLMAP puts the top-left
/// pixel's centre at 0.5, hullcut at 0). COLMAP's unit is whatever its reconstruction fixed:
/// --scale gives metres per unit.
///
/// From OpenCV (--opencv-dir DIR): one FileStorage file per camera (YAML, XML or JSON, named by
/// the camera), with camera_matrix/K, distortion_coefficients/D, R or rvec, T/tvec and the image
/// size (image_width and image_height, or image_size); --scale converts the translation's unit
/// (0.001 for millimetres).
///
/// The world frame is the source's; the rig's cameras are in natural order of name. The rig is
/// printed with the working volume it gives (the space at least three cameras see).
///
/// Writes: OUT (rig.yaml).
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct CalibrationArgs {
    /// A COLMAP text model (folder with cameras.txt and images.txt).
    #[arg(long, value_name = "DIR", conflicts_with = "opencv_dir", required_unless_present = "opencv_dir")]
    colmap: Option<PathBuf>,
    /// A folder of per-camera OpenCV FileStorage files.
    #[arg(long, value_name = "DIR")]
    opencv_dir: Option<PathBuf>,
    /// Metres per unit of the source's translations (above 0).
    #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = super::positive)]
    scale: f64,
    /// The rig file to write.
    #[arg(long, value_name = "rig.yaml")]
    out: PathBuf,
}

/// Runs `import-calibration`.
pub fn calibration(args: &CalibrationArgs) -> anyhow::Result<()> {
    let rig: Rig = match (&args.colmap, &args.opencv_dir) {
        (Some(dir), _) => hullcut_rig::colmap::read_colmap(dir, args.scale)?,
        (None, Some(dir)) => hullcut_calib::import::read_opencv_cameras(dir, args.scale)?,
        (None, None) => bail!("give --colmap DIR or --opencv-dir DIR"),
    };
    rig.save(&args.out)?;
    println!("wrote {} ({} cameras)", args.out.display(), rig.len());
    match crate::volume::resolve(None, None, &rig) {
        Ok(_) => {}
        Err(e) => eprintln!("warning: {e:#}"),
    }
    Ok(())
}

/// Make a dataset from one video per camera.
///
/// Each video (any container and codec OpenCV decodes: .mp4, .avi, .mkv, ...) belongs to the rig
/// camera of its --video NAME=FILE, or, with --videos-dir DIR, to the camera its file is named after
/// (cam0.mp4). Frames are stamped with their media time plus the camera's --offset (a camera that
/// started 12 ms late: --offset cam3=-0.012) plus --start-ns, and paired into frame sets within
/// half a frame period; frames that pair with nothing and sets that lack a camera (a video that
/// ends early, a dropped frame) are counted per camera and printed. The frame rate is --fps or the
/// first video's.
///
/// Writes: OUT (a dataset: dataset.toml, rig.yaml, frames.csv, CAM/NNNNNN.png); REPORT (JSON) with
/// --report. Add empty-scene images as CAM/background*.png and the scalpel as tool.json to let
/// segmentation work (README, "From your rig to hullcut run").
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct VideosArgs {
    /// The rig (rig.yaml, e.g. from `hullcut calibrate` or `hullcut import-calibration`).
    #[arg(long, value_name = "rig.yaml")]
    rig: PathBuf,
    /// A camera's video, NAME=FILE (once per camera).
    #[arg(long = "video", value_name = "NAME=FILE", value_parser = name_and_file)]
    videos: Vec<(String, PathBuf)>,
    /// A folder of videos named by camera (cam0.mp4, cam1.mp4, ...).
    #[arg(long, value_name = "DIR", conflicts_with = "videos")]
    videos_dir: Option<PathBuf>,
    /// A camera's time offset, NAME=SECONDS, added to its media time.
    #[arg(long = "offset", value_name = "NAME=SECONDS", value_parser = name_and_seconds)]
    offsets: Vec<(String, f64)>,
    /// Frame rate (default: the first video's).
    #[arg(long, value_name = "FPS", value_parser = super::positive)]
    fps: Option<f64>,
    /// Time of media time 0, nanoseconds since the epoch.
    #[arg(long, value_name = "NS", default_value_t = 0)]
    start_ns: i64,
    /// Stop after N frame sets (at least 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    max_frames: Option<u64>,
    /// The dataset folder to write (refused if it exists, unless --force).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Replace OUT if it is a dataset.
    #[arg(long)]
    force: bool,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
}

/// `NAME=VALUE`, both parts non-empty.
fn name_value(s: &str) -> Result<(&str, &str), String> {
    s.split_once('=').filter(|(k, v)| !k.is_empty() && !v.is_empty()).ok_or_else(|| "expected NAME=VALUE".to_owned())
}

/// `--video NAME=FILE`: a camera's name and its video (anything else is bad usage).
fn name_and_file(s: &str) -> Result<(String, PathBuf), String> {
    let (name, file) = name_value(s)?;
    Ok((name.to_owned(), PathBuf::from(file)))
}

/// `--offset NAME=SECONDS`: a camera's name and its time offset, a finite number of seconds.
fn name_and_seconds(s: &str) -> Result<(String, f64), String> {
    let (name, value) = name_value(s)?;
    let seconds = value.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let seconds = seconds.ok_or("expected NAME=SECONDS, SECONDS a finite number")?;
    Ok((name.to_owned(), seconds))
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    rig: String,
    videos: Vec<(String, String, f64)>,
    #[serde(flatten)]
    summary: hullcut_capture::import::ImportSummary,
}

/// Runs `import-videos`.
pub fn videos(args: &VideosArgs) -> anyhow::Result<()> {
    let rig = Rig::load(&args.rig)?;
    let mut inputs: Vec<VideoInput> = Vec::new();
    for (camera, path) in &args.videos {
        inputs.push(VideoInput { camera: camera.clone(), path: path.clone(), offset_s: 0.0 });
    }
    if let Some(dir) = &args.videos_dir {
        let entries = std::fs::read_dir(dir).with_context(|| format!("listing {}", dir.display()))?;
        for entry in entries {
            let path = entry.with_context(|| format!("listing {}", dir.display()))?.path();
            let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else { continue };
            if path.is_file() && rig.index_of(stem).is_some() {
                inputs.push(VideoInput { camera: stem.to_owned(), path: path.clone(), offset_s: 0.0 });
            }
        }
    }
    if inputs.is_empty() {
        bail!("no videos: give --video NAME=FILE per camera, or --videos-dir DIR with files named by camera");
    }
    for (camera, seconds) in &args.offsets {
        let Some(input) = inputs.iter_mut().find(|i| &i.camera == camera) else {
            bail!("--offset {camera}={seconds}: no video for camera `{camera}`");
        };
        input.offset_s = *seconds;
    }
    let name = args.out.file_name().map_or_else(|| "imported".to_owned(), |n| n.to_string_lossy().into_owned());
    let params = ImportParams {
        fps: args.fps,
        start_ns: args.start_ns,
        max_frame_sets: args.max_frames,
        name,
        force: args.force,
    };
    let pb = bar(args.max_frames.unwrap_or(0), "importing frame sets");
    let summary = import_videos(&rig, &inputs, &args.out, &params, &|n| pb.set_position(n))
        .with_context(|| format!("importing the videos into {}", args.out.display()))?;
    pb.finish_and_clear();
    println!(
        "wrote {} ({} frame sets at {} fps{})",
        summary.path.display(),
        summary.frame_sets,
        summary.fps,
        if summary.fps_from_video { ", the first video's rate" } else { "" }
    );
    let dropped = summary.sync.dropped();
    for (k, cam) in rig.cameras.iter().enumerate() {
        let missing = summary.sync.missing_views.get(k).copied().unwrap_or(0);
        let unpaired = dropped.get(k).copied().unwrap_or(0);
        if missing + unpaired > 0 {
            println!(
                "  {}: {} frames decoded, {} paired; {unpaired} frames unpaired (late {}, a second in one period {}, out of order {}), {missing} frame sets without it",
                cam.name,
                summary.decoded[k],
                summary.images[k],
                summary.sync.late_dropped[k],
                summary.sync.surplus_dropped[k],
                summary.sync.out_of_order_dropped[k]
            );
        }
    }
    for (camera, frames) in &summary.ended_early {
        eprintln!("warning: camera `{camera}`'s video ended early, after {frames} frames: later frame sets lack it");
    }
    if let Some(path) = &args.report {
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "import_videos".to_owned(),
            provenance: Provenance::current(),
            rig: args.rig.display().to_string(),
            videos: inputs.iter().map(|i| (i.camera.clone(), i.path.display().to_string(), i.offset_s)).collect(),
            summary: summary.clone(),
        };
        write_json(path, &report)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn name_value_flags_are_checked_when_parsed() {
        assert_eq!(name_and_file("cam0=a.mp4"), Ok(("cam0".to_owned(), PathBuf::from("a.mp4"))));
        assert_eq!(name_and_seconds("cam3=-0.012"), Ok(("cam3".to_owned(), -0.012)));
        for bad in ["cam0", "=a.mp4", "cam0="] {
            assert!(name_and_file(bad).is_err(), "{bad}");
        }
        for bad in ["cam3=soon", "cam3=NaN", "cam3=inf", "cam3"] {
            assert!(name_and_seconds(bad).is_err(), "{bad}");
        }
    }
}
