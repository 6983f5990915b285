//! A six-camera calibration from synthetic board views (the default rig's distorted cameras, pixel
//! noise), checked against the true rig.

use hullcut_calib::{CalibError, CalibParams, Observations, Pattern, calibrate};
use hullcut_rig::{Camera, Rig, default_rig};
use nalgebra::{Isometry3, Point2, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// Corner localisation noise per coordinate, pixels: sub-pixel chessboard detection reaches about
/// 0.1 px on sharp images (0.2–0.4 px RMS on OpenCV's blurry sample photos). At this noise, ~20
/// close-up views per camera pin the principal point to a few tenths of a pixel, which is what a
/// 0.1° rotation tolerance needs (1 px of principal point ≈ 0.1° at f = 600 px).
const NOISE_PX: f64 = 0.1;

/// A board lying face-up near the table, tilted up to `max_tilt` radians and turned about z.
/// OpenCV's board frame has z pointing away from the cameras that see its front, so face-up means
/// the board's z axis points down.
fn board_pose(rng: &mut StdRng, max_tilt: f64) -> Isometry3<f64> {
    let face_up = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.random_range(0.0..std::f64::consts::TAU));
    let axis_angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let tilt = UnitQuaternion::from_scaled_axis(
        Vector3::new(axis_angle.cos(), axis_angle.sin(), 0.0) * rng.random_range(0.0..max_tilt),
    );
    let rotation = tilt * yaw * face_up;
    let centre = Vector3::new(rng.random_range(-0.08..0.08), rng.random_range(-0.08..0.08), rng.random_range(0.0..0.2));
    // Put the board's centre (not its first corner) at `centre`.
    let half = rotation * Vector3::new(0.12, 0.075, 0.0);
    Isometry3::from_parts(Translation3::from(centre - half), rotation)
}

/// A board held close in front of one camera, as a lab does to calibrate intrinsics: 0.3 to 0.5 m
/// away, filling much of the image, tilted up to 35° and turned about its normal.
fn close_pose(cam: &Camera, rng: &mut StdRng) -> Isometry3<f64> {
    let camera_to_world = UnitQuaternion::from_rotation_matrix(&cam.rotation.inverse());
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.random_range(0.0..std::f64::consts::TAU));
    let axis_angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let tilt = UnitQuaternion::from_scaled_axis(
        Vector3::new(axis_angle.cos(), axis_angle.sin(), 0.0) * rng.random_range(0.0..0.6),
    );
    let rotation = camera_to_world * tilt * yaw;
    let offset = Vector3::new(rng.random_range(-0.05..0.05), rng.random_range(-0.04..0.04), rng.random_range(0.3..0.5));
    let centre = cam.centre().coords + camera_to_world * offset;
    Isometry3::from_parts(Translation3::from(centre - rotation * Vector3::new(0.12, 0.075, 0.0)), rotation)
}

/// Workspace views shared by several cameras plus close-up views per camera.
fn board_poses(rig: &Rig, rng: &mut StdRng, shared: usize, close: usize) -> Vec<Isometry3<f64>> {
    let mut poses: Vec<_> = (0..shared).map(|_| board_pose(rng, 0.7)).collect();
    for cam in &rig.cameras {
        poses.extend((0..close).map(|_| close_pose(cam, rng)));
    }
    poses
}

/// Projects the board into every camera that sees all of its corners from the front.
fn observe(rig: &Rig, pattern: &Pattern, boards: &[Isometry3<f64>], rng: &mut StdRng) -> Observations {
    let noise = Normal::new(0.0, NOISE_PX).expect("normal");
    let views = (0..boards.len()).map(|v| format!("{v:03}.png")).collect();
    let mut obs = Observations::new(
        rig.cameras.iter().map(|c| c.name.clone()).collect(),
        rig.cameras.iter().map(|c| (c.width, c.height)).collect(),
        views,
    );
    let object = pattern.object_points();
    for (c, cam) in rig.cameras.iter().enumerate() {
        for (v, board) in boards.iter().enumerate() {
            let front = board.rotation * -Vector3::z();
            let to_cam = (cam.centre() - board.translation.vector).coords.normalize();
            if front.dot(&to_cam) < 0.3 {
                continue;
            }
            let px: Option<Vec<Point2<f64>>> = object
                .iter()
                .map(|p| {
                    let proj = cam.project(&(board * p));
                    proj.visible.then(|| proj.pixel + nalgebra::Vector2::new(noise.sample(rng), noise.sample(rng)))
                })
                .collect();
            obs.corners[c][v] = px;
        }
    }
    obs
}

fn pattern() -> Pattern {
    Pattern::parse("9x6", 0.03).expect("pattern")
}

#[test]
fn six_cameras_recover_the_true_rig() {
    let truth = default_rig();
    let mut rng = StdRng::seed_from_u64(2026);
    let mut boards = board_poses(&truth, &mut rng, 40, 20);
    // The world board: flat on the table, first corner at the origin, rows along world x.
    let flat = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    boards.push(Isometry3::from_parts(Translation3::identity(), flat));
    let obs = observe(&truth, &pattern(), &boards, &mut rng);
    let world = obs.views.last().cloned();
    for c in 0..truth.len() {
        assert!(obs.detected_count(c) >= 10, "camera {c} sees {} boards", obs.detected_count(c));
    }
    let cal = calibrate(&obs, &pattern(), world.as_deref(), &CalibParams::default()).expect("calibration");
    assert!(cal.report.refinement.converged);
    // RMS is over 2-D point distances (OpenCV's definition): with noise sigma per coordinate it
    // approaches sigma * sqrt(2), slightly less for the degrees of freedom the fit absorbs.
    let expected = NOISE_PX * std::f64::consts::SQRT_2;
    assert!((cal.report.rms_px - expected).abs() < 0.01, "RMS {} px, expected about {expected}", cal.report.rms_px);
    for (est, tru) in cal.rig.cameras.iter().zip(&truth.cameras) {
        let focal = ((est.fx - tru.fx) / tru.fx).abs().max(((est.fy - tru.fy) / tru.fy).abs());
        let rot = (est.rotation * tru.rotation.inverse()).angle().to_degrees();
        let trans = (est.centre() - tru.centre()).norm();
        eprintln!(
            "{}: focal {:.4}%, principal point ({:+.2}, {:+.2}) px, rotation {rot:.4}°, centre {:.3} mm",
            est.name,
            100.0 * focal,
            est.cx - tru.cx,
            est.cy - tru.cy,
            1e3 * trans
        );
        assert!(focal < 0.005, "{}: focal error {:.3}%", est.name, 100.0 * focal);
        assert!(rot < 0.1, "{}: rotation error {rot}°", est.name);
        assert!(trans < 1e-3, "{}: position error {} mm", est.name, 1e3 * trans);
    }
}

#[test]
fn camera_zero_frame_without_world_board() {
    let truth = default_rig();
    let mut rng = StdRng::seed_from_u64(5);
    let boards = board_poses(&truth, &mut rng, 30, 20);
    let obs = observe(&truth, &pattern(), &boards, &mut rng);
    let cal = calibrate(&obs, &pattern(), None, &CalibParams::default()).expect("calibration");
    let c0 = &cal.rig.cameras[0];
    assert!(c0.rotation.angle() < 1e-12 && c0.translation.norm() < 1e-12, "camera 0 is the world");
    // Gauge-free comparisons with the truth: distances between camera centres (errors in camera
    // 0's own pose would otherwise leak into every other camera) and relative rotations.
    for (i, (est, tru)) in cal.rig.cameras.iter().zip(&truth.cameras).enumerate().skip(1) {
        for (e0, t0) in cal.rig.cameras.iter().zip(&truth.cameras).take(i) {
            let err = ((est.centre() - e0.centre()).norm() - (tru.centre() - t0.centre()).norm()).abs();
            assert!(err < 1e-3, "{}-{}: baseline error {} mm", e0.name, est.name, 1e3 * err);
            let rel_est = est.rotation * e0.rotation.inverse();
            let rel_tru = tru.rotation * t0.rotation.inverse();
            let deg = (rel_est * rel_tru.inverse()).angle().to_degrees();
            // Each camera's rotation is within 0.1° (the test above); a relative rotation combines
            // two such errors, so it is within 0.2°.
            assert!(deg < 0.2, "{}-{}: relative rotation error {deg}°", e0.name, est.name);
        }
    }
}

#[test]
fn disconnected_camera_and_unknown_world_board_are_named() {
    let truth = default_rig();
    let mut rng = StdRng::seed_from_u64(9);
    let boards: Vec<_> = (0..30).map(|_| board_pose(&mut rng, 0.7)).collect();
    let mut obs = observe(&truth, &pattern(), &boards, &mut rng);
    let e = calibrate(&obs, &pattern(), Some("table.png"), &CalibParams::default()).expect_err("unknown view");
    assert!(e.to_string().contains("table.png"), "{e}");
    // Camera 5 keeps only views nobody else saw: none, so drop it from every shared view.
    for v in 0..obs.views.len() {
        if (0..5).any(|c| obs.corners[c][v].is_some()) {
            obs.corners[5][v] = None;
        }
    }
    // Give it private views so its intrinsics are solvable but it shares nothing.
    let private: Vec<_> = (0..12).map(|_| board_pose(&mut rng, 0.7)).collect();
    let extra = observe(&truth, &pattern(), &private, &mut rng);
    for (v, corners) in extra.corners[5].iter().enumerate() {
        obs.views.push(format!("private{v}.png"));
        for c in 0..6 {
            obs.corners[c].push(if c == 5 { corners.clone() } else { None });
            obs.has_image[c].push(c == 5);
        }
    }
    match calibrate(&obs, &pattern(), None, &CalibParams::default()) {
        Err(CalibError::Disconnected { camera }) => assert_eq!(camera, "cam5"),
        other => panic!("expected a disconnected camera, got {other:?}"),
    }
}
