//! `hullcut calibrate`: multi-camera chessboard calibration to rig.yaml.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use hullcut_calib::{
    CalibParams, CalibReport, Calibration, Observations, Pattern, calibrate, detect_all, discover_images,
    read_rgb_undistorted,
};
use serde::{Deserialize, Serialize};

use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};

/// Calibrate a multi-camera rig from chessboard images.
///
/// IMAGES holds one folder per camera (the folder's name becomes the camera's name; cameras in
/// natural order, cam2 before cam10). Files with the same name in different folders are
/// simultaneous views. Each camera's intrinsics come from OpenCV's calibrateCamera; the cameras are
/// placed in one frame through a spanning tree of the pairs that share the most views, then every
/// camera and board pose is refined jointly.
///
/// Writes: OUT (rig.yaml, OpenCV FileStorage YAML); REPORT (JSON, see docs/reports.md) with
/// --report; an .rrd recording (images with detected corners, the solved rig, the boards in 3-D)
/// with --rrd.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Folder with one sub-folder of images per camera.
    #[arg(long, value_name = "DIR")]
    images: PathBuf,
    /// Inner corners of the chessboard, COLSxROWS (as OpenCV counts them, 2 to 100 each), e.g. 9x6.
    #[arg(long, value_name = "COLSxROWS", value_parser = pattern_parser)]
    pattern: String,
    /// Side of one chessboard square, metres (above 0).
    #[arg(long, value_name = "METRES", value_parser = super::positive)]
    square: f64,
    /// Where to write the rig (rig.yaml).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Write a JSON report: RMS per camera, pair and image, outliers, skipped images, timings.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Log images with detected corners, the rig and the boards to this rerun recording (.rrd).
    #[arg(long, value_name = "FILE")]
    rrd: Option<PathBuf>,
    /// An image (path, or file name present in the camera folders) of a board lying on the table:
    /// the world frame becomes that board's (origin at its first inner corner, x along its rows,
    /// z up toward the cameras). Without it, camera 0's frame is the world.
    #[arg(long, value_name = "IMAGE")]
    world_board: Option<PathBuf>,
    /// Keep the intrinsics from the single-camera calibrations; refine only poses.
    #[arg(long)]
    fix_intrinsics: bool,
}

/// Most inner corners along one side of a board that `--pattern` takes.
const MAX_CORNERS_PER_SIDE: u32 = 100;

/// `--pattern`: COLSxROWS inner corners, 2 to [`MAX_CORNERS_PER_SIDE`] each; anything else is bad
/// usage.
fn pattern_parser(s: &str) -> Result<String, String> {
    match Pattern::parse(s, 1.0) {
        Some(p) if p.cols <= MAX_CORNERS_PER_SIDE && p.rows <= MAX_CORNERS_PER_SIDE => Ok(s.trim().to_owned()),
        _ => Err(format!("expected COLSxROWS inner corners, 2 to {MAX_CORNERS_PER_SIDE} each (e.g. 9x6)")),
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct Timings {
    detect: StageTiming,
    calibrate: StageTiming,
    total: StageTiming,
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    images_dir: PathBuf,
    #[serde(flatten)]
    calibration: CalibReport,
    timings: Timings,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let Some(pattern) = Pattern::parse(&args.pattern, args.square) else {
        bail!(
            "--pattern {} / --square {}: expected COLSxROWS of at least 2x2 inner corners and a positive square size in metres",
            crate::report::shorten(&args.pattern, 40),
            args.square
        );
    };
    let set = discover_images(&args.images)?;
    let total: usize = set.paths.iter().map(|p| p.iter().flatten().count()).sum();
    tracing::info!(
        cameras = set.cameras.len(),
        images = total,
        "found calibration images in {}",
        args.images.display()
    );
    let pb = bar(total as u64, "detecting");
    let t_detect = Instant::now();
    let obs = detect_all(&set, &pattern, &|| pb.inc(1))?;
    let detect_time = t_detect.elapsed();
    pb.finish_and_clear();
    for (c, cam) in obs.cameras.iter().enumerate() {
        for (v, view) in obs.views.iter().enumerate() {
            if obs.has_image[c][v] && obs.corners[c][v].is_none() {
                tracing::warn!(
                    "{}: no {} board found; image skipped",
                    set.root.join(cam).join(view).display(),
                    args.pattern
                );
            }
        }
    }
    let world_board = args
        .world_board
        .as_ref()
        .map(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .map(str::to_owned)
                .with_context(|| format!("--world-board {}: not a file name", p.display()))
        })
        .transpose()?;
    let mut params = CalibParams::default();
    params.refine.intrinsics = !args.fix_intrinsics;
    let t_cal = Instant::now();
    let cal = calibrate(&obs, &pattern, world_board.as_deref(), &params)
        .with_context(|| format!("calibrating from {}", args.images.display()))?;
    let cal_time = t_cal.elapsed();
    cal.rig.save(&args.out)?;
    print_summary(&cal);
    println!("wrote {}", args.out.display());
    if let Some(path) = &args.rrd {
        log_rrd(path, &set.root, &obs, &cal)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &args.report {
        let per_image = if total > 0 { detect_time / total as u32 } else { Duration::ZERO };
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "calibration".to_owned(),
            provenance: Provenance::current(),
            images_dir: args.images.clone(),
            calibration: cal.report.clone(),
            timings: Timings {
                detect: StageTiming::from_durations(&vec![per_image; total]),
                calibrate: StageTiming::from_durations(&[cal_time]),
                total: StageTiming::from_durations(&[t0.elapsed()]),
            },
        };
        write_json(path, &report)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn print_summary(cal: &Calibration) {
    let r = &cal.report;
    println!(
        "calibrated {} cameras, world frame {}: RMS {:.3} px over all views ({} images skipped, {} outliers)",
        r.cameras.len(),
        r.world_frame,
        r.rms_px,
        r.skipped_images,
        r.outlier_images
    );
    println!("{:<10} {:>6} {:>10} {:>9} {:>9} {:>9} {:>9}", "camera", "views", "rms_px", "fx", "fy", "cx", "cy");
    for c in &r.cameras {
        println!(
            "{:<10} {:>3}/{:<2} {:>10.4} {:>9.2} {:>9.2} {:>9.2} {:>9.2}",
            c.name, c.views_detected, c.images, c.rms_px, c.fx, c.fy, c.cx, c.cy
        );
    }
    for p in &r.pairs {
        println!(
            "pair {}-{}: {} shared views, RMS {:.4} px, baseline {:.4} m",
            p.a, p.b, p.shared_views, p.rms_px, p.baseline_m
        );
    }
    for i in r.images.iter().filter(|i| i.outlier) {
        println!("outlier: {}/{} RMS {:.3} px", i.camera, i.image, i.rms_px.unwrap_or(f64::NAN));
    }
}

fn log_rrd(path: &Path, root: &Path, obs: &Observations, cal: &Calibration) -> anyhow::Result<()> {
    let rec = hullcut_viz::open_recording("hullcut-calibrate", &hullcut_viz::Sink::File(path.to_owned()))?;
    hullcut_viz::log_world(&rec)?;
    hullcut_viz::log_rig(&rec, &cal.rig)?;
    let pb = bar(obs.views.len() as u64, "logging");
    for (v, view) in obs.views.iter().enumerate() {
        hullcut_viz::set_frame(&rec, v as i64);
        for (c, cam) in obs.cameras.iter().enumerate() {
            if !obs.has_image[c][v] {
                continue;
            }
            // rerun's pinhole has no distortion: log undistorted images and corners so 3-D overlays line up.
            let camera = &cal.rig.cameras[c];
            let (w, h, rgb) = read_rgb_undistorted(&root.join(cam).join(view), camera)?;
            hullcut_viz::log_image_rgb(&rec, cam, w, h, &rgb)?;
            let corners: Vec<[f32; 2]> = obs.corners[c][v]
                .iter()
                .flatten()
                .filter_map(|p| camera.undistort_pixel(*p))
                .map(|p| [p.x as f32, p.y as f32])
                .collect();
            hullcut_viz::log_image_points(&rec, cam, "corners", &corners, [255, 64, 32, 255], 2.0)?;
        }
        if let Some(board) = &cal.boards[v] {
            let pts: Vec<[f32; 3]> = cal
                .report
                .pattern
                .object_points()
                .iter()
                .map(|p| board * p)
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect();
            hullcut_viz::log_points3d(&rec, "world/calibration/board", &pts, [255, 200, 0, 255], 0.002)?;
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
    fn a_pattern_is_cols_x_rows_within_bounds() {
        assert_eq!(pattern_parser("9x6").as_deref(), Ok("9x6"));
        for bad in ["9by6", "1x6", "9x", "101x6", "100000x100000", ""] {
            assert!(pattern_parser(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn timings_round_trip_through_json() {
        let t = StageTiming { count: 2, mean_ms: 3.5, p50_ms: 3.0, p95_ms: 4.0, max_ms: 4.0 };
        let timings = Timings { detect: t.clone(), calibrate: t.clone(), total: t };
        let (first, again) = crate::report::json_round_trip(&timings);
        assert_eq!(first, again);
    }
}
