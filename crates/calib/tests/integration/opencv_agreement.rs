//! Our camera model against OpenCV's own functions, called through the opencv crate.

use hullcut_rig::{Camera, Distortion, Rig, default_rig};
use nalgebra::{Point2, Point3, Vector3};
use opencv::core::{Mat, Point2d, Point3d, TermCriteria, TermCriteria_Type, Vector, no_array};
use opencv::prelude::*;
use opencv::{calib3d, core};
use rand::{Rng, SeedableRng, rngs::StdRng};

/// The agreement the issue demands, pixels.
const TOLERANCE_PX: f64 = 1e-6;

fn k_mat(c: &Camera) -> Mat {
    Mat::from_slice_2d(&[[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]]).expect("K")
}

fn d_mat(c: &Camera) -> Mat {
    Mat::from_slice(&c.distortion.to_array()).expect("D").try_clone().expect("clone")
}

/// Cameras with strong distortion of both signs, so the test exercises every coefficient.
fn cameras() -> Vec<Camera> {
    let mut cams = default_rig().cameras;
    let mut strong = cams[0].clone();
    strong.distortion = Distortion { k1: -0.32, k2: 0.14, p1: 1.2e-3, p2: -8e-4, k3: -0.03 };
    cams.push(strong);
    let mut pincushion = cams[1].clone();
    pincushion.distortion = Distortion { k1: 0.18, k2: -0.05, p1: -5e-4, p2: 9e-4, k3: 0.01 };
    cams.push(pincushion);
    cams
}

/// Random world points in front of `c` whose normalized radius is within 90% of the distortion's
/// monotonic range (where undistortion is well defined) and that land in the image.
fn sample_points(c: &Camera, rng: &mut StdRng, n: usize) -> Vec<Point3<f64>> {
    let limit = 0.9 * c.distortion.monotonic_radius();
    let inv = c.rotation.inverse();
    let mut out = Vec::new();
    while out.len() < n {
        let (x, y, z): (f64, f64, f64) =
            (rng.random_range(-0.8..0.8), rng.random_range(-0.6..0.6), rng.random_range(0.2..2.0));
        if (x * x + y * y).sqrt() >= limit {
            continue;
        }
        let p_cam = Vector3::new(x * z, y * z, z);
        let p = Point3::from(inv * (p_cam - c.translation));
        if c.project(&p).visible {
            out.push(p);
        }
    }
    out
}

#[test]
fn projection_matches_project_points() {
    let mut rng = StdRng::seed_from_u64(7);
    for c in cameras() {
        let pts = sample_points(&c, &mut rng, 500);
        let obj: Vector<Point3d> = pts.iter().map(|p| Point3d::new(p.x, p.y, p.z)).collect();
        let rvec = Mat::from_slice(c.rotation.scaled_axis().as_slice()).expect("rvec").try_clone().expect("rvec");
        let tvec = Mat::from_slice(c.translation.as_slice()).expect("tvec").try_clone().expect("tvec");
        let mut out = Vector::<Point2d>::new();
        calib3d::project_points_def(&obj, &rvec, &tvec, &k_mat(&c), &d_mat(&c), &mut out).expect("projectPoints");
        let mut worst: f64 = 0.0;
        for (p, q) in pts.iter().zip(out.iter()) {
            let ours = c.project(p).pixel;
            worst = worst.max((ours - Point2::new(q.x, q.y)).norm());
        }
        assert!(worst < TOLERANCE_PX, "{}: worst projection difference {worst:e} px", c.name);
    }
}

#[test]
fn undistortion_matches_undistort_points_iter() {
    let mut rng = StdRng::seed_from_u64(11);
    // Plain undistortPoints stops after 5 iterations; undistortPointsIter with tight criteria runs
    // its fixed-point iteration until the reprojection error is below 1e-12 px.
    let criteria = TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 10_000, 1e-12)
        .expect("criteria");
    for c in cameras() {
        let pixels: Vec<Point2<f64>> = sample_points(&c, &mut rng, 500).iter().map(|p| c.project(p).pixel).collect();
        let src: Vector<Point2d> = pixels.iter().map(|p| Point2d::new(p.x, p.y)).collect();
        let mut dst = Vector::<Point2d>::new();
        calib3d::undistort_points_iter(&src, &mut dst, &k_mat(&c), &d_mat(&c), &no_array(), &k_mat(&c), criteria)
            .expect("undistortPointsIter");
        let mut worst: f64 = 0.0;
        for (p, q) in pixels.iter().zip(dst.iter()) {
            let ours = c.undistort_pixel(*p).expect("converges");
            worst = worst.max((ours - Point2::new(q.x, q.y)).norm());
        }
        assert!(worst < TOLERANCE_PX, "{}: worst undistortion difference {worst:e} px", c.name);
    }
}

#[test]
fn rig_yaml_loads_in_opencv_filestorage() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("rig.yaml");
    let rig = default_rig();
    rig.save(&path).expect("save");
    let fs = core::FileStorage::new_def(path.to_str().expect("utf-8 path"), core::FileStorage_Mode::READ as i32)
        .expect("FileStorage opens our rig.yaml");
    assert!(fs.is_opened().expect("is_opened"));
    assert_eq!(fs.get("camera_count").expect("node").to_i32().expect("int"), 6);
    for (i, c) in rig.cameras.iter().enumerate() {
        let node = fs.get(&format!("camera_{i}")).expect("camera node");
        assert_eq!(node.get("name").expect("name").to_string().expect("string"), c.name);
        assert_eq!(node.get("image_width").expect("w").to_i32().expect("int"), c.width as i32);
        let k = node.get("camera_matrix").expect("K").mat().expect("mat");
        assert_eq!(*k.at_2d::<f64>(0, 0).expect("fx"), c.fx);
        assert_eq!(*k.at_2d::<f64>(1, 2).expect("cy"), c.cy);
        let r = node.get("rotation_matrix").expect("R").mat().expect("mat");
        for row in 0..3 {
            for col in 0..3 {
                assert_eq!(*r.at_2d::<f64>(row as i32, col as i32).expect("r"), c.rotation[(row, col)]);
            }
        }
        let d = node.get("distortion_coefficients").expect("D").mat().expect("mat");
        assert_eq!(*d.at::<f64>(0).expect("k1"), c.distortion.k1);
    }
    // And a file OpenCV writes is read back by us.
    let out = dir.path().join("opencv.yaml");
    {
        let mut w = core::FileStorage::new_def(out.to_str().expect("utf-8"), core::FileStorage_Mode::WRITE as i32)
            .expect("write");
        let c = &rig.cameras[3];
        w.write_i32("camera_count", 1).expect("count");
        w.start_write_struct_def("camera_0", core::FileNode_MAP).expect("struct");
        w.write_str("name", &c.name).expect("name");
        w.write_i32("image_width", c.width as i32).expect("w");
        w.write_i32("image_height", c.height as i32).expect("h");
        w.write_mat("camera_matrix", &k_mat(c)).expect("K");
        w.write_mat("distortion_coefficients", &d_mat(c).reshape(1, 1).expect("row").try_clone().expect("D"))
            .expect("D");
        let r = Mat::from_slice_2d(&[
            [c.rotation[(0, 0)], c.rotation[(0, 1)], c.rotation[(0, 2)]],
            [c.rotation[(1, 0)], c.rotation[(1, 1)], c.rotation[(1, 2)]],
            [c.rotation[(2, 0)], c.rotation[(2, 1)], c.rotation[(2, 2)]],
        ])
        .expect("R");
        w.write_mat("rotation_matrix", &r).expect("R");
        w.write_mat(
            "translation_vector",
            &Mat::from_slice(c.translation.as_slice()).expect("t").try_clone().expect("t"),
        )
        .expect("t");
        w.end_write_struct().expect("end");
        w.release().expect("release");
    }
    let back = Rig::load(&out).expect("we read OpenCV's own file");
    let c = &rig.cameras[3];
    let b = &back.cameras[0];
    assert_eq!((b.fx, b.fy, b.cx, b.cy, b.distortion), (c.fx, c.fy, c.cx, c.cy, c.distortion));
    // OpenCV prints 16 significant digits; our reader re-orthonormalizes what it reads.
    assert!((b.rotation.matrix() - c.rotation.matrix()).abs().max() < 1e-14);
    assert!((b.translation - c.translation).abs().max() < 1e-15);
}
