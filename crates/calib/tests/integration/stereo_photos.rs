//! OpenCV's sample stereo chessboard photos (Debian opencv-doc) calibrated as a two-camera rig,
//! compared with OpenCV's own calibrateCamera + stereoCalibrate on the same detections.

use std::path::{Path, PathBuf};

use hullcut_calib::{CalibParams, Observations, Pattern, calibrate, detect_all, discover_images};
use opencv::calib3d;
use opencv::core::{Mat, Point2f, Point3f, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;

const SAMPLES: &str = "/usr/share/doc/opencv-doc/examples/data";
/// The samples' square size is undocumented; any value scales the baseline and nothing else.
const SQUARE: f64 = 0.025;

/// Lays the photos out as `left/NN.jpg`, `right/NN.jpg`. Fails (never skips) when they are missing:
/// tools/setup.sh installs opencv-doc.
fn image_tree() -> tempfile::TempDir {
    let src = Path::new(SAMPLES);
    assert!(
        src.join("left01.jpg").exists(),
        "{SAMPLES}/left01.jpg is missing: run tools/setup.sh (installs opencv-doc)"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    for side in ["left", "right"] {
        std::fs::create_dir(dir.path().join(side)).expect("mkdir");
        for n in 1..=14 {
            let from = src.join(format!("{side}{n:02}.jpg"));
            if from.exists() {
                std::fs::copy(&from, dir.path().join(side).join(format!("{n:02}.jpg"))).expect("copy");
            }
        }
    }
    dir
}

struct OpenCvStereo {
    rms_left: f64,
    rms_right: f64,
    rms_stereo: f64,
    baseline: f64,
}

/// OpenCV's own answer from the same corners: per-camera calibrateCamera, then stereoCalibrate
/// refining everything (CALIB_USE_INTRINSIC_GUESS), which minimizes the same total reprojection
/// error as our joint refinement.
fn opencv_stereo(obs: &Observations, pattern: &Pattern) -> OpenCvStereo {
    let shared = obs.shared_views(0, 1);
    let obj: Vector<Point3f> =
        pattern.object_points().iter().map(|p| Point3f::new(p.x as f32, p.y as f32, 0.0)).collect();
    let objects: Vector<Vector<Point3f>> = shared.iter().map(|_| obj.clone()).collect();
    let corners = |c: usize| -> Vector<Vector<Point2f>> {
        shared
            .iter()
            .map(|&v| {
                obs.corners[c][v]
                    .as_ref()
                    .expect("shared")
                    .iter()
                    .map(|p| Point2f::new(p.x as f32, p.y as f32))
                    .collect()
            })
            .collect()
    };
    let (left, right) = (corners(0), corners(1));
    let (w, h) = obs.image_sizes[0];
    let size = Size::new(w as i32, h as i32);
    let criteria =
        TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 100, f64::EPSILON)
            .expect("criteria");
    let mono = |pts: &Vector<Vector<Point2f>>| {
        let (mut k, mut d) = (Mat::default(), Mat::default());
        let (mut r, mut t) = (Vector::<Mat>::new(), Vector::<Mat>::new());
        let rms = calib3d::calibrate_camera(&objects, pts, size, &mut k, &mut d, &mut r, &mut t, 0, criteria)
            .expect("calibrateCamera");
        (rms, k, d)
    };
    let (rms_left, mut k1, mut d1) = mono(&left);
    let (rms_right, mut k2, mut d2) = mono(&right);
    let (mut r, mut t, mut e, mut f) = (Mat::default(), Mat::default(), Mat::default(), Mat::default());
    let rms_stereo = calib3d::stereo_calibrate(
        &objects,
        &left,
        &right,
        &mut k1,
        &mut d1,
        &mut k2,
        &mut d2,
        size,
        &mut r,
        &mut t,
        &mut e,
        &mut f,
        calib3d::CALIB_USE_INTRINSIC_GUESS,
        criteria,
    )
    .expect("stereoCalibrate");
    let baseline = (0..3).map(|i| t.at::<f64>(i).expect("t").powi(2)).sum::<f64>().sqrt();
    OpenCvStereo { rms_left, rms_right, rms_stereo, baseline }
}

#[test]
fn matches_opencv_on_sample_stereo_photos() {
    let dir = image_tree();
    let pattern = Pattern::parse("9x6", SQUARE).expect("pattern");
    let set = discover_images(dir.path()).expect("images");
    assert_eq!(set.cameras, ["left", "right"]);
    assert_eq!(set.views.len(), 13, "13 pairs: number 10 is absent");
    let obs = detect_all(&set, &pattern, &|| ()).expect("detection");
    let cal = calibrate(&obs, &pattern, None, &CalibParams::default()).expect("calibration");
    let reference = opencv_stereo(&obs, &pattern);
    let r = &cal.report;
    let pair = &r.pairs[0];
    eprintln!(
        "ours: rms left {:.4} right {:.4} joint {:.4} pair {:.4} baseline {:.6} m ({} shared views)",
        r.cameras[0].rms_px, r.cameras[1].rms_px, r.rms_px, pair.rms_px, pair.baseline_m, pair.shared_views
    );
    eprintln!(
        "opencv: calibrateCamera rms left {:.4} right {:.4}; stereoCalibrate rms {:.4} baseline {:.6} m",
        reference.rms_left, reference.rms_right, reference.rms_stereo, reference.baseline
    );
    // Per-camera intrinsics are OpenCV's calibrateCamera on the same corners: identical RMS.
    assert!((r.cameras[0].rms_intrinsic_px - reference.rms_left).abs() < 1e-9);
    assert!((r.cameras[1].rms_intrinsic_px - reference.rms_right).abs() < 1e-9);
    // Both refinements minimise the same sum of squares over the same parameters and views, so
    // they reach the same minimum up to their stopping criteria: 1e-3 px of RMS is far below the
    // 0.1 px that would signal a different minimum, and 0.2% of the baseline is 0.1 mm here.
    assert_eq!(pair.shared_views, obs.views.len(), "every view is shared by both cameras");
    assert!(
        (pair.rms_px - reference.rms_stereo).abs() < 1e-3,
        "pair RMS {} vs stereoCalibrate {}",
        pair.rms_px,
        reference.rms_stereo
    );
    assert!(
        (pair.baseline_m - reference.baseline).abs() < 2e-3 * reference.baseline,
        "baseline {} vs stereoCalibrate {}",
        pair.baseline_m,
        reference.baseline
    );
    assert!(cal.report.refinement.converged);
    // A second camera rotated little relative to the first, as in the photos' rig.
    let rel = cal.rig.cameras[1].rotation.angle().to_degrees();
    assert!(rel < 10.0, "relative rotation {rel}°");
}

#[test]
fn missing_folder_and_unreadable_image_are_named() {
    let e = discover_images(&PathBuf::from("/nonexistent/calib")).expect_err("missing");
    assert!(e.to_string().contains("/nonexistent/calib"), "{e}");
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir(dir.path().join("cam0")).expect("mkdir");
    let e = discover_images(dir.path()).expect_err("no images");
    assert!(e.to_string().contains("holds no camera folders"), "{e}");
    let bad = dir.path().join("cam0").join("01.png");
    std::fs::write(&bad, b"not a png").expect("write");
    let set = discover_images(dir.path()).expect("one camera");
    let pattern = Pattern::parse("9x6", SQUARE).expect("pattern");
    let e = detect_all(&set, &pattern, &|| ()).expect_err("unreadable");
    assert!(e.to_string().contains("01.png"), "{e}");
}

#[test]
fn mismatched_sizes_and_missing_board_are_errors() {
    let tree = image_tree();
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir(dir.path().join("cam0")).expect("mkdir");
    // Two images of different sizes in one camera.
    std::fs::copy(tree.path().join("left/01.jpg"), dir.path().join("cam0/01.jpg")).expect("copy");
    let small = opencv::imgcodecs::imread_def(tree.path().join("left/02.jpg").to_str().expect("utf-8")).expect("read");
    let mut half = Mat::default();
    opencv::imgproc::resize_def(&small, &mut half, Size::new(320, 240)).expect("resize");
    opencv::imgcodecs::imwrite_def(dir.path().join("cam0/02.png").to_str().expect("utf-8"), &half).expect("write");
    let set = discover_images(dir.path()).expect("images");
    let pattern = Pattern::parse("9x6", SQUARE).expect("pattern");
    let e = detect_all(&set, &pattern, &|| ()).expect_err("sizes differ");
    assert!(e.to_string().contains("cam0") && e.to_string().contains("320x240"), "{e}");
    // A pattern that never appears: too few views, naming the camera.
    let set = discover_images(tree.path()).expect("images");
    let wrong = Pattern::parse("7x7", SQUARE).expect("pattern");
    let obs = detect_all(&set, &wrong, &|| ()).expect("detection runs");
    let e = calibrate(&obs, &wrong, None, &CalibParams::default()).expect_err("no board");
    assert!(e.to_string().contains("7x7 board was found in 0 image(s)"), "{e}");
}
