//! Integration tests of hullcut-rig: projection round trips, rig.yaml I/O and its errors.

use hullcut_rig::{Camera, Distortion, Rig, RigError, WorldFrame, default_rig};
use nalgebra::{Point2, Point3, Vector3};
use proptest::prelude::*;

fn test_camera() -> Camera {
    let mut c = Camera::new("cam0", 640, 480, 610.0, 605.0, 318.0, 243.0)
        .looking_at(Point3::new(0.6, 0.2, 0.5), Point3::new(0.0, 0.0, 0.1), Vector3::z())
        .expect("valid pose");
    c.distortion = Distortion { k1: -0.12, k2: 0.07, p1: 3e-4, p2: -2e-4, k3: -0.01 };
    c
}

mod projection {
    use super::*;

    #[test]
    fn centre_and_direction() {
        let c = test_camera();
        assert!((c.centre() - Point3::new(0.6, 0.2, 0.5)).norm() < 1e-12);
        let expected = (Point3::new(0.0, 0.0, 0.1) - Point3::new(0.6, 0.2, 0.5)).normalize();
        assert!((c.viewing_direction().into_inner() - expected).norm() < 1e-12);
        // The target projects onto the principal point (distortion is zero on the axis).
        let p = c.project(&Point3::new(0.0, 0.0, 0.1));
        assert!(p.visible);
        assert!((p.pixel - Point2::new(c.cx, c.cy)).norm() < 1e-9);
    }

    #[test]
    fn behind_and_outside_are_not_visible() {
        let c = test_camera();
        let behind = c.centre() + (c.centre() - Point3::new(0.0, 0.0, 0.1));
        assert!(!c.project(&behind).visible);
        let ray = c.pixel_ray(Point2::new(320.0, 240.0)).expect("ray");
        // A point far to the side of the optical axis lands outside the image.
        let side = ray.at(1.0) + c.rotation.inverse() * Vector3::new(5.0, 0.0, 0.0);
        assert!(!c.project(&side).visible);
    }

    #[test]
    fn image_bounds_use_pixel_centres() {
        let c = Camera::new("c", 4, 3, 1.0, 1.0, 0.0, 0.0);
        assert!(c.contains_pixel(Point2::new(-0.5, -0.5)));
        assert!(!c.contains_pixel(Point2::new(3.5, 0.0)));
        assert!(c.contains_pixel(Point2::new(3.49, 2.49)));
    }

    proptest! {
        /// pixel → ray → any point on the ray → pixel returns the pixel.
        #[test]
        fn unproject_then_project(u in 0.0f64..639.0, v in 0.0f64..479.0, s in 0.05f64..3.0) {
            let c = test_camera();
            let ray = c.pixel_ray(Point2::new(u, v)).expect("inside the invertible range");
            let p = c.project(&ray.at(s));
            prop_assert!(p.visible);
            prop_assert!((p.pixel - Point2::new(u, v)).norm() < 1e-7, "{:?} vs ({u}, {v})", p.pixel);
        }

        /// world point → pixel → ray: the ray passes through the point.
        #[test]
        fn project_then_unproject(x in -0.2f64..0.2, y in -0.2f64..0.2, z in 0.0f64..0.4) {
            let c = test_camera();
            let p = Point3::new(x, y, z);
            let proj = c.project(&p);
            prop_assume!(proj.visible);
            let ray = c.pixel_ray(proj.pixel).expect("ray");
            let along = (p - ray.origin).dot(&ray.direction);
            prop_assert!((ray.at(along) - p).norm() < 1e-9);
        }

        /// Undistortion inverts distortion inside the monotonic range.
        #[test]
        fn undistort_inverts(x in -0.6f64..0.6, y in -0.45f64..0.45) {
            let d = test_camera().distortion;
            let p = nalgebra::Vector2::new(x, y);
            prop_assume!(p.norm() < 0.95 * d.monotonic_radius());
            let back = d.undistort(d.distort(p)).expect("converges");
            prop_assert!((back - p).norm() < 1e-12);
        }
    }
}

mod yaml {
    use super::*;

    fn write_read(rig: &Rig) -> Rig {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("rig.yaml");
        rig.save(&path).expect("save");
        Rig::load(&path).expect("load")
    }

    #[test]
    fn round_trip_is_exact() {
        let mut rig = default_rig();
        rig.cameras[2].rms_reprojection_error = Some(0.21);
        rig.world_frame = WorldFrame::Board { image: "table.png".into() };
        let back = write_read(&rig);
        assert_eq!(back.world_frame, rig.world_frame);
        for (a, b) in rig.cameras.iter().zip(&back.cameras) {
            assert_eq!(a.name, b.name);
            assert_eq!((a.width, a.height, a.fx, a.fy, a.cx, a.cy), (b.width, b.height, b.fx, b.fy, b.cx, b.cy));
            assert_eq!(a.distortion, b.distortion);
            assert!((a.rotation.matrix() - b.rotation.matrix()).abs().max() < 1e-15);
            assert_eq!(a.translation, b.translation);
            assert_eq!(a.rms_reprojection_error, b.rms_reprojection_error);
        }
    }

    #[test]
    fn committed_default_rig_matches_the_code() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../calibration/default-rig.yaml");
        let file = Rig::load(path).expect("calibration/default-rig.yaml loads");
        assert_eq!(file, default_rig(), "regenerate with `hullcut rig default --out calibration/default-rig.yaml`");
    }

    /// A file as OpenCV's FileStorage writes it (flow and block styles, `%YAML:1.0`, tags, `1.`).
    const OPENCV_STYLE: &str = "%YAML:1.0
---
camera_count: 1
camera_0:
   name: left
   image_width: 640
   image_height: 480
   camera_matrix: !!opencv-matrix
      rows: 3
      cols: 3
      dt: d
      data: [ 5.3e+02, 0., 3.2e+02, 0., 5.3e+02,
          2.4e+02, 0., 0., 1. ]
   distortion_coefficients: !!opencv-matrix { rows: 1, cols: 5, dt: d, data: [ -0.28, 0.07, 1e-3, -2e-4, 0. ] }
   rotation_matrix: !!opencv-matrix
      rows: 3
      cols: 3
      dt: d
      data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]
   translation_vector: !!opencv-matrix
      rows: 3
      cols: 1
      dt: d
      data: [ 0., 0., 0. ]
";

    #[test]
    fn reads_opencv_filestorage_output() {
        let rig = Rig::from_yaml_str(OPENCV_STYLE, "opencv.yaml").expect("parses");
        let c = &rig.cameras[0];
        assert_eq!((c.name.as_str(), c.width, c.fx, c.cy), ("left", 640, 530.0, 240.0));
        assert_eq!(c.distortion.k1, -0.28);
        assert_eq!(rig.world_frame, WorldFrame::Other("unspecified".into()));
    }

    fn error_of(text: &str) -> String {
        let e = Rig::from_yaml_str(text, "bad.yaml").expect_err("must be refused");
        let msg = e.to_string();
        assert!(msg.starts_with("bad.yaml: "), "error names the file: {msg}");
        msg
    }

    #[test]
    fn missing_key_is_named() {
        let msg = error_of(&OPENCV_STYLE.replace("   image_height: 480\n", ""));
        assert!(msg.contains("missing key `camera_0.image_height`"), "{msg}");
        let msg = error_of("%YAML:1.0\n---\ncamera_count: 2\n");
        assert!(msg.contains("missing key `camera_0`"), "{msg}");
    }

    #[test]
    fn wrong_matrix_size_is_named() {
        let text = OPENCV_STYLE.replace("      rows: 3\n      cols: 1\n", "      rows: 2\n      cols: 1\n");
        let msg = error_of(&text);
        assert!(msg.contains("`camera_0.translation_vector` must be a 3x1 or 1x3 matrix, found 2x1"), "{msg}");
        let text = OPENCV_STYLE.replace("data: [ 0., 0., 0. ]", "data: [ 0., 0. ]");
        assert!(error_of(&text).contains("with 2 data values"));
    }

    #[test]
    fn rotation_not_orthonormal_is_named() {
        let text = OPENCV_STYLE
            .replace("data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]", "data: [ 1., 0.1, 0., 0., 1., 0., 0., 0., 1. ]");
        let msg = error_of(&text);
        assert!(msg.contains("`camera_0.rotation_matrix` is not a rotation"), "{msg}");
        // A reflection is orthonormal but not a rotation.
        let text = OPENCV_STYLE
            .replace("data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]", "data: [ -1., 0., 0., 0., 1., 0., 0., 0., 1. ]");
        assert!(matches!(Rig::from_yaml_str(&text, "x"), Err(RigError::NotRotation { .. })));
    }

    #[test]
    fn non_finite_and_zero_size_are_named() {
        let msg = error_of(&OPENCV_STYLE.replace("data: [ 0., 0., 0. ]", "data: [ 0., .nan, 0. ]"));
        assert!(msg.contains("`camera_0.translation_vector.data` holds a non-finite number"), "{msg}");
        let msg = error_of(&OPENCV_STYLE.replace("image_width: 640", "image_width: 0"));
        assert!(msg.contains("`camera_0.image_width` is zero"), "{msg}");
    }

    #[test]
    fn syntax_errors_and_missing_files_are_named() {
        assert!(error_of("camera_count: [1\n").contains("not valid YAML"));
        let e = Rig::load("/nonexistent/rig.yaml").expect_err("missing file");
        assert!(e.to_string().contains("/nonexistent/rig.yaml"));
    }
}

#[test]
fn a_scaled_camera_sees_the_same_point_at_the_scaled_pixel() {
    let cam = hullcut_rig::default_rig().cameras[2].clone();
    let half = cam.scaled(0.5);
    assert_eq!((half.width, half.height), (320, 240));
    let p = nalgebra::Point3::new(0.05, -0.03, 0.12);
    let (a, b) = (cam.project(&p).pixel, half.project(&p).pixel);
    // Pixel centres at integers: u' = (u + 0.5) / 2 - 0.5.
    assert!(((a.x + 0.5) * 0.5 - 0.5 - b.x).abs() < 1e-9 && ((a.y + 0.5) * 0.5 - 0.5 - b.y).abs() < 1e-9);
}

mod colmap {
    use hullcut_rig::colmap::{read_colmap, write_colmap};
    use hullcut_rig::{Rig, lab8_rig, random_rig};

    use super::*;

    fn assert_same(a: &Rig, b: &Rig) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.cameras.iter().zip(&b.cameras) {
            assert_eq!((&x.name, x.width, x.height), (&y.name, y.width, y.height));
            let close = |p: f64, q: f64| (p - q).abs() <= 1e-12 * p.abs().max(1.0);
            for (p, q) in [(x.fx, y.fx), (x.fy, y.fy), (x.cx, y.cx), (x.cy, y.cy)] {
                assert!(close(p, q), "{}: {p} vs {q}", x.name);
            }
            for (p, q) in x.distortion.to_array().iter().zip(y.distortion.to_array()) {
                assert!(close(*p, q), "{}: distortion {p} vs {q}", x.name);
            }
            assert!((x.rotation.matrix() - y.rotation.matrix()).abs().max() < 1e-14, "{}", x.name);
            assert!((x.translation - y.translation).abs().max() < 1e-14, "{}", x.name);
        }
    }

    #[test]
    fn rigs_round_trip_through_colmaps_text_model() {
        for rig in [default_rig(), lab8_rig(), random_rig(3)] {
            let dir = tempfile::tempdir().expect("tempdir");
            write_colmap(&rig, dir.path(), 1.0).expect("write");
            assert_same(&rig, &read_colmap(dir.path(), 1.0).expect("read"));
            // In millimetres (scale 0.001 m per unit) the translations are read back in metres.
            write_colmap(&rig, dir.path(), 0.001).expect("write");
            let text = std::fs::read_to_string(dir.path().join("images.txt")).expect("images.txt");
            assert!(text.contains(&format!("{:.17e}", rig.cameras[0].translation.x * 1000.0)));
            assert_same(&rig, &read_colmap(dir.path(), 0.001).expect("read"));
        }
    }

    /// A model as COLMAP's documentation shows it: comments, a SIMPLE_RADIAL and a PINHOLE camera,
    /// images in camera folders with their 2-D points lines (one empty).
    fn write_model(dir: &std::path::Path, cameras: &str, images: &str) {
        std::fs::write(dir.join("cameras.txt"), cameras).expect("cameras.txt");
        std::fs::write(dir.join("images.txt"), images).expect("images.txt");
    }

    #[test]
    fn a_hand_written_model_reads_with_colmaps_conventions() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_model(
            dir.path(),
            "# Camera list with one line of data per camera:\n\
             #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n\
             # Number of cameras: 2\n\
             1 SIMPLE_RADIAL 640 480 600.0 320.5 240.5 -0.1\n\
             2 PINHOLE 800 600 700.0 710.0 400.0 300.0\n",
            "# Image list with two lines of data per image:\n\
             1 1 0 0 0 0.1 0.2 0.3 2 cam10/000000.png\n\
             \n\
             2 0.7071067811865476 0 0.7071067811865476 0 1 2 3 1 cam2/000000.png\n\
             240.0 10.0 -1 300.5 20.25 7\n",
        );
        let rig = read_colmap(dir.path(), 2.0).expect("read");
        let names: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["cam2", "cam10"], "natural order");
        let (c2, c10) = (&rig.cameras[0], &rig.cameras[1]);
        // SIMPLE_RADIAL: one focal length, k1; the principal point moves by half a pixel.
        assert_eq!((c2.fx, c2.fy, c2.cx, c2.cy, c2.distortion.k1), (600.0, 600.0, 320.0, 240.0, -0.1));
        assert_eq!((c10.fx, c10.fy, c10.cx, c10.cy), (700.0, 710.0, 399.5, 299.5));
        assert!(c10.distortion.is_none());
        // Identity rotation, translation scaled to metres.
        assert!((c10.rotation.matrix() - nalgebra::Matrix3::identity()).abs().max() < 1e-15);
        assert!((c10.translation - Vector3::new(0.2, 0.4, 0.6)).norm() < 1e-15);
        // A quarter turn about y: camera z is world x... x_cam = R x_world + t.
        let p = c2.world_to_camera(&Point3::new(1.0, 0.0, 0.0));
        assert!((p - Point3::new(2.0, 4.0, 5.0)).norm() < 1e-12, "{p}");
    }

    #[test]
    fn bad_models_are_refused_naming_the_file_and_line() {
        let cases = [
            (
                "1 OPENCV_FISHEYE 640 480 600 600 320 240 0 0 0 0\n",
                "1 1 0 0 0 0 0 0 1 a.png\n\n",
                "cameras.txt",
                "line 1",
                "OPENCV_FISHEYE",
            ),
            ("# c\n1 FOV 640 480 600 600 320 240 0.1\n", "1 1 0 0 0 0 0 0 1 a.png\n\n", "cameras.txt", "line 2", "FOV"),
            ("1 FULL_OPENCV 640 480 600 600 320 240 0 0 0 0 0 0.1 0 0\n", "", "cameras.txt", "line 1", "rational"),
            ("1 PINHOLE 640 480 600 600 320\n", "", "cameras.txt", "line 1", "takes 4 parameters"),
            ("1 PINHOLE 0 480 600 600 320 240\n", "", "cameras.txt", "line 1", "image size"),
            ("1 PINHOLE 640 480 600 nan 320 240\n", "", "cameras.txt", "line 1", "not finite"),
            ("1 PINHOLE 640 480 600 600 320 240\n", "1 1 0 0 0 0 0 0 7 a.png\n\n", "images.txt", "line 1", "camera 7"),
            ("1 PINHOLE 640 480 600 600 320 240\n", "1 2 0 0 0 0 0 0 1 a.png\n\n", "images.txt", "line 1", "length 2"),
            (
                "1 PINHOLE 640 480 600 600 320 240\n",
                "1 1 0 0 0 0 0 0 1 a/1.png\n\n2 1 0 0 0 0 0 0 1 a/2.png\n\n",
                "images.txt",
                "line 3",
                "second image of camera `a`",
            ),
            ("1 PINHOLE 640 480 600 600 320 240\n", "# nothing\n", "images.txt", "", "no images"),
        ];
        for (cameras, images, file, line, what) in cases {
            let dir = tempfile::tempdir().expect("tempdir");
            write_model(dir.path(), cameras, images);
            let e = read_colmap(dir.path(), 1.0).expect_err(what).to_string();
            assert!(e.contains(file) && e.contains(line) && e.contains(what), "{what}: {e}");
        }
        let empty = tempfile::tempdir().expect("tempdir");
        let e = read_colmap(empty.path(), 1.0).expect_err("no files").to_string();
        assert!(e.contains("cameras.txt"), "{e}");
        assert!(read_colmap(empty.path(), 0.0).is_err(), "a scale of 0");
    }
}
