//! Per-camera intrinsics with OpenCV's calibrateCamera (Zhang's method + Levenberg–Marquardt).

use hullcut_rig::{Camera, Distortion};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use opencv::calib3d;
use opencv::core::{Mat, Point2f, Point3f, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;

use crate::CalibError;
use crate::error::Context as _;

/// One camera's intrinsic calibration.
#[derive(Debug, Clone)]
pub struct IntrinsicFit {
    /// The camera (intrinsics and distortion; identity pose).
    pub camera: Camera,
    /// Board → camera pose of each view used, in the order given.
    pub board_poses: Vec<Isometry3<f64>>,
    /// OpenCV's RMS reprojection error, pixels.
    pub rms_px: f64,
}

fn mat3(m: &Mat, what: &str) -> Result<Vector3<f64>, CalibError> {
    let ctx = || format!("reading {what}");
    Ok(Vector3::new(*m.at::<f64>(0).context(ctx)?, *m.at::<f64>(1).context(ctx)?, *m.at::<f64>(2).context(ctx)?))
}

/// Calibrates one camera from views of the board (`views[i]` are the detected corners of view i).
pub fn calibrate_intrinsics(
    name: &str,
    size: (u32, u32),
    object: &[Point3<f64>],
    views: &[&[Point2<f64>]],
) -> Result<IntrinsicFit, CalibError> {
    let ctx = || format!("calibrating camera `{name}`");
    let obj: Vector<Point3f> = object.iter().map(|p| Point3f::new(p.x as f32, p.y as f32, p.z as f32)).collect();
    let object_points: Vector<Vector<Point3f>> = views.iter().map(|_| obj.clone()).collect();
    let image_points: Vector<Vector<Point2f>> =
        views.iter().map(|v| v.iter().map(|p| Point2f::new(p.x as f32, p.y as f32)).collect()).collect();
    let mut k = Mat::default();
    let mut d = Mat::default();
    let mut rvecs = Vector::<Mat>::new();
    let mut tvecs = Vector::<Mat>::new();
    let criteria =
        TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 100, f64::EPSILON)
            .context(ctx)?;
    let image_size = Size::new(size.0 as i32, size.1 as i32);
    let rms = calib3d::calibrate_camera(
        &object_points,
        &image_points,
        image_size,
        &mut k,
        &mut d,
        &mut rvecs,
        &mut tvecs,
        0,
        criteria,
    )
    .context(ctx)?;
    let kv = |r: i32, c: i32| k.at_2d::<f64>(r, c).copied().context(ctx);
    let mut camera = Camera::new(name, size.0, size.1, kv(0, 0)?, kv(1, 1)?, kv(0, 2)?, kv(1, 2)?);
    let mut coeffs = [0.0; 5];
    for (i, c) in coeffs.iter_mut().enumerate() {
        *c = *d.at::<f64>(i as i32).context(ctx)?;
    }
    camera.distortion = Distortion::from_array(coeffs);
    camera.rms_reprojection_error = Some(rms);
    let mut board_poses = Vec::with_capacity(views.len());
    for (r, t) in rvecs.iter().zip(tvecs.iter()) {
        let r = mat3(&r, "a rotation vector")?;
        let t = mat3(&t, "a translation vector")?;
        board_poses.push(Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(r)));
    }
    Ok(IntrinsicFit { camera, board_poses, rms_px: rms })
}
