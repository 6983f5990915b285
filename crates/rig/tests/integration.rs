//! Integration tests of hullcut-rig: projection round trips, rig.yaml I/O and its errors, and
//! hostile input (limits, alias bombs, a committed corpus of bad files, fuzzing).

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
    fn a_small_ball_in_view_projects_into_a_tight_disc() {
        let c = test_camera();
        let centre = Point3::new(0.02, -0.03, 0.12);
        let rho = 0.003 * 3f64.sqrt() / 2.0;
        let (uv, r) = c.project_ball(&centre, rho, 1e-3, c.distortion.monotonic_radius()).expect("in view");
        assert!((uv - c.project(&centre).pixel).norm() < 1e-9);
        // The same disc from the centre in the camera's frame.
        let in_camera =
            c.project_ball_in_camera(&c.world_to_camera(&centre), rho, 1e-3, c.distortion.monotonic_radius());
        assert_eq!(in_camera, Some((uv, r)));
        // How far the corners of the 3 mm cell whose half-diagonal is rho actually spread.
        let spread = (0..8)
            .map(|k| {
                let corner = Vector3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64);
                let p = centre + (corner * 2.0 - Vector3::repeat(1.0)) * 0.0015;
                (c.project(&p).pixel - uv).norm()
            })
            .fold(0.0f64, f64::max);
        assert!(spread <= r && r < 2.0 * spread, "disc radius {r} against a spread of {spread}");
        // Nearer than `near` to the camera's plane: no disc.
        assert!(c.project_ball(&c.centre(), rho, 1e-3, 1.0).is_none());
        // A coefficient that is not a number bounds nothing.
        let mut bad = c.clone();
        bad.distortion.k2 = f64::NAN;
        assert!(bad.project_ball(&centre, rho, 1e-3, 1.0).is_none());
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

        /// The distortion stretches no distance by more than its bound over the radius both points
        /// lie within, whatever the coefficients.
        #[test]
        fn distortion_stretches_no_more_than_its_bound(
            k in prop::array::uniform5(-0.5f64..0.5),
            a in prop::array::uniform2(-1.0f64..1.0),
            b in prop::array::uniform2(-1.0f64..1.0),
        ) {
            let d = Distortion::from_array([k[0], k[1], k[2] * 0.02, k[3] * 0.02, k[4]]);
            let (a, b) = (nalgebra::Vector2::from(a), nalgebra::Vector2::from(b));
            let r = a.norm().max(b.norm());
            let moved = (d.distort(a) - d.distort(b)).norm();
            prop_assert!(moved <= d.stretch_bound(r) * (a - b).norm() * (1.0 + 1e-12) + 1e-15);
        }

        /// Every point of a ball projects into the disc `project_ball` gives for it.
        #[test]
        fn a_ball_projects_into_its_disc(
            centre in prop::array::uniform3(-0.3f64..0.3),
            rho in 0.0005f64..0.05,
            dir in prop::array::uniform3(-1.0f64..1.0),
            t in 0.0f64..1.0,
        ) {
            let c = test_camera();
            let centre = Point3::from(centre);
            let dir = Vector3::from(dir);
            prop_assume!(dir.norm() > 1e-3);
            let radius = c.distortion.monotonic_radius();
            if let Some((uv, r)) = c.project_ball(&centre, rho, 1e-3, radius) {
                let p = c.project(&(centre + dir.normalize() * rho * t));
                prop_assert!((p.pixel - uv).norm() <= r * (1.0 + 1e-9), "{:?} outside {uv:?} + {r}", p.pixel);
            }
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
    pub(super) const OPENCV_STYLE: &str = "%YAML:1.0
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

/// Bad input never crashes, hangs or lies (issue 24): every case below is an error that names the
/// file and the key or line, returned before anything is sized from the bad value.
mod hostile {
    use std::path::Path;
    use std::time::{Duration, Instant};

    use hullcut_rig::colmap::read_colmap;
    use hullcut_rig::{MAX_CAMERAS, MAX_RIG_FILE_BYTES};

    use super::yaml::OPENCV_STYLE;
    use super::*;

    /// The error of reading `text` as `bad.yaml`, checked to name the file first.
    fn refused(text: &str) -> RigError {
        let e = Rig::from_yaml_str(text, "bad.yaml").expect_err("must be refused");
        assert!(e.to_string().starts_with("bad.yaml: "), "error names the file: {e}");
        e
    }

    /// The error and its sources joined the way `anyhow` prints them with `{:#}`.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut parts = vec![e.to_string()];
        let mut next = e.source();
        while let Some(source) = next {
            parts.push(source.to_string());
            next = source.source();
        }
        parts.join(": ")
    }

    const ROTATION: &str = "data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]";
    const K: &str = "data: [ 5.3e+02, 0., 3.2e+02, 0., 5.3e+02,";

    #[test]
    fn camera_count_out_of_range_is_refused_before_allocating() {
        for count in ["9223372036854775807", "1000000000", "65", "0", "-3", "1e30", "99999999999999999999999", "two"] {
            let text = OPENCV_STYLE.replace("camera_count: 1", &format!("camera_count: {count}"));
            let msg = refused(&text).to_string();
            assert!(msg.contains("`camera_count`") && msg.contains(&format!("1..={MAX_CAMERAS}")), "{count}: {msg}");
        }
    }

    #[test]
    fn camera_count_must_match_the_cameras_present() {
        let extra = format!("{OPENCV_STYLE}camera_7:\n   name: late\n");
        let msg = refused(&extra).to_string();
        assert!(msg.contains("`camera_count`") && msg.contains("camera_7"), "{msg}");
        let msg = refused(&OPENCV_STYLE.replace("camera_count: 1", "camera_count: 64")).to_string();
        assert!(msg.contains("missing key `camera_1`"), "{msg}");
    }

    /// "Billion laughs": nine levels of nine aliases, 9^9 strings once expanded. The event scan stops
    /// at the first alias (line 2), so this takes microseconds; the bound below only catches a
    /// regression to expanding it, which takes minutes and gigabytes.
    #[test]
    fn an_alias_bomb_is_refused_quickly() {
        let mut text = String::from("camera_count: 1\nl0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n");
        for level in 1..9 {
            let p = level - 1;
            text += &format!("l{level}: &l{level} [{}]\n", vec![format!("*l{p}"); 9].join(", "));
        }
        let start = Instant::now();
        let e = refused(&text);
        assert!(start.elapsed() < Duration::from_secs(5), "took {:?}", start.elapsed());
        assert!(matches!(e, RigError::Unsupported { line: 3, .. }), "{e}");
        assert!(e.to_string().contains("alias"), "{e}");
        // An alias inside a quoted string or a comment is text, not an alias.
        let quoted = OPENCV_STYLE.replace("name: left", "name: \"*left\" # *not an alias");
        assert_eq!(Rig::from_yaml_str(&quoted, "q.yaml").expect("quoted").cameras[0].name, "*left");
    }

    #[test]
    fn deep_nesting_and_huge_files_are_refused() {
        // Past 255 flow levels yaml-rust2's scanner refuses by itself; below that, the event scan.
        let deep = format!("camera_count: {}{}\n", "[".repeat(100_000), "]".repeat(100_000));
        refused(&deep);
        let nested = format!("camera_count: {}{}\n", "[".repeat(200), "]".repeat(200));
        assert!(matches!(refused(&nested), RigError::Unsupported { .. }));
        let nested: String = (0..700).map(|i| format!("{}-\n", "  ".repeat(i))).collect();
        let block = format!("camera_count:\n{nested}");
        assert!(matches!(refused(&block), RigError::Unsupported { .. }));
        let huge = format!("{OPENCV_STYLE}#{}\n", "x".repeat(MAX_RIG_FILE_BYTES as usize));
        assert!(matches!(refused(&huge), RigError::TooLarge { .. }));
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("rig.yaml");
        std::fs::write(&path, &huge).expect("write");
        let e = Rig::load(&path).expect_err("too large");
        assert!(matches!(e, RigError::TooLarge { .. }) && e.to_string().contains("rig.yaml"), "{e}");
    }

    #[test]
    fn intrinsics_outside_their_ranges_are_refused() {
        let cases = [
            (OPENCV_STYLE.replace(K, "data: [ 1e-300, 0., 3.2e+02, 0., 5.3e+02,"), "fx = 1e-300"),
            (OPENCV_STYLE.replace(K, "data: [ 5.3e+02, 0., 3.2e+02, 0., -5.3e+02,"), "fy = -530"),
            (OPENCV_STYLE.replace(K, "data: [ 5.3e+02, 0., 3.2e+02, 0., 1e7,"), "fy = 10000000"),
            (OPENCV_STYLE.replace(K, "data: [ 5.3e+02, 0., 1e300, 0., 5.3e+02,"), "cx = 1e300"),
            (OPENCV_STYLE.replace("-0.28, 0.07", "-1e300, 0.07"), "k1 = -1e300"),
            (OPENCV_STYLE.replace("image_width: 640", "image_width: 1000000"), "1..=16384"),
            (OPENCV_STYLE.replace("image_height: 480", "image_height: -480"), "1..=16384"),
            (OPENCV_STYLE.replace("data: [ 0., 0., 0. ]", "data: [ 0., 1e300, 0. ]"), "ty = 1e300"),
            (format!("{OPENCV_STYLE}   rms_reprojection_error: -1\n"), "rms_reprojection_error"),
        ];
        for (text, what) in cases {
            let msg = refused(&text).to_string();
            assert!(msg.contains("camera_0.") && msg.contains(what), "{what}: {msg}");
            assert!(msg.len() < 300, "a short message: {msg}");
        }
        let msg = refused(&OPENCV_STYLE.replace(K, "data: [ 1e-300, 0., 3.2e+02, 0., 5.3e+02,")).to_string();
        assert!(msg.contains("`camera_0.camera_matrix`") && msg.contains("[1, 1e6] px"), "{msg}");
    }

    #[test]
    fn rotations_that_are_not_rotations_are_refused() {
        for data in [
            "data: [ 1e19, 0., 0., 0., 1., 0., 0., 0., 1. ]",
            "data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1.0001 ]",
            "data: [ 0., 0., 0., 0., 0., 0., 0., 0., 0. ]",
            "data: [ 1., 0., 0., 0., 1., 0., 0., 0., .inf ]",
        ] {
            let msg = refused(&OPENCV_STYLE.replace(ROTATION, data)).to_string();
            assert!(msg.contains("camera_0.rotation_matrix"), "{data}: {msg}");
            assert!(msg.len() < 300, "a short message: {msg}");
        }
        // Rounded to six digits, a rotation still passes (and is re-orthonormalized).
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let rounded = format!("data: [ {c:.6}, {c:.6}, 0., -{c:.6}, {c:.6}, 0., 0., 0., 1. ]");
        let rig = Rig::from_yaml_str(&OPENCV_STYLE.replace(ROTATION, &rounded), "ok.yaml").expect("rounded rotation");
        let r = rig.cameras[0].rotation.matrix();
        assert!((r.transpose() * r - nalgebra::Matrix3::identity()).abs().max() < 1e-12);
    }

    #[test]
    fn validate_checks_rigs_built_in_memory() {
        assert!(default_rig().validate("default").is_ok());
        let mut rig = default_rig();
        rig.cameras[3].fx = 1e-300;
        let msg = rig.validate("mem").expect_err("tiny fx").to_string();
        assert!(msg.starts_with("mem: `camera_3.camera_matrix`") && msg.contains("fx"), "{msg}");
        let mut rig = default_rig();
        rig.cameras[1].name = rig.cameras[0].name.clone();
        assert!(rig.validate("mem").expect_err("duplicate").to_string().contains("camera_1.name"));
        let mut rig = default_rig();
        rig.cameras[0].translation.z = f64::NAN;
        assert!(rig.validate("mem").expect_err("NaN").to_string().contains("camera_0.translation_vector"));
    }

    #[test]
    fn long_values_are_shortened_in_messages() {
        let long = "x".repeat(100_000);
        let msg = refused(&OPENCV_STYLE.replace("image_width: 640", &format!("image_width: {long}"))).to_string();
        assert!(msg.contains("more chars") && msg.len() < 400, "{} chars", msg.len());
        let dup = format!("{OPENCV_STYLE}{long}: 1\n{long}: 2\n");
        let msg = refused(&dup).to_string();
        assert!(msg.len() < 400, "{} chars", msg.len());
    }

    #[test]
    fn an_error_chain_names_the_path_once() {
        let dir = tempfile::tempdir().expect("tempdir");
        let missing = dir.path().join("missing-rig.yaml");
        let bad = dir.path().join("bad-rig.yaml");
        std::fs::write(&bad, OPENCV_STYLE.replace("   image_height: 480\n", "")).expect("write");
        for path in [&missing, &bad] {
            let e = Rig::load(path).expect_err("refused");
            let text = chain(&e);
            let shown = path.display().to_string();
            assert_eq!(text.matches(&shown).count(), 1, "{text}");
        }
    }

    #[test]
    fn colmap_numbers_outside_their_ranges_are_refused() {
        let cases = [
            ("1 PINHOLE 640 480 1e-300 600 320 240\n", "1 1 0 0 0 0 0 0 1 a.png\n\n", "cameras.txt", "fx = 1e-300"),
            ("1 PINHOLE 640 480 600 600 1e300 240\n", "1 1 0 0 0 0 0 0 1 a.png\n\n", "cameras.txt", "cx = 1e300"),
            ("1 OPENCV 640 480 600 600 320 240 1e300 0 0 0\n", "1 1 0 0 0 0 0 0 1 a.png\n\n", "cameras.txt", "k1"),
            ("1 PINHOLE 640 480 600 600 320 240\n", "1 1 0 0 0 1e300 0 0 1 a.png\n\n", "images.txt", "tx = 1e300"),
        ];
        for (cameras, images, file, what) in cases {
            let dir = tempfile::tempdir().expect("tempdir");
            std::fs::write(dir.path().join("cameras.txt"), cameras).expect("cameras.txt");
            std::fs::write(dir.path().join("images.txt"), images).expect("images.txt");
            let e = read_colmap(dir.path(), 1.0).expect_err(what).to_string();
            assert!(e.contains(file) && e.contains("line 1") && e.contains(what), "{what}: {e}");
        }
    }

    /// Every file in `tests/corpus/` is a bad rig.yaml that once crashed, hung or was believed: each
    /// must be an error naming the file, with the file's path once in the error chain.
    #[test]
    fn the_regression_corpus_is_refused() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
        let mut paths: Vec<_> =
            std::fs::read_dir(&dir).expect("tests/corpus").map(|e| e.expect("entry").path()).collect();
        paths.sort();
        assert!(paths.len() >= 10, "the corpus has its files: {paths:?}");
        for path in paths {
            let name = path.file_name().expect("name").to_string_lossy().into_owned();
            let start = Instant::now();
            let e = Rig::load(&path).expect_err(&name);
            assert!(start.elapsed() < Duration::from_secs(5), "{name} took {:?}", start.elapsed());
            let text = chain(&e);
            assert!(text.contains(&name), "{name}: {text}");
            assert_eq!(text.matches(&path.display().to_string()).count(), 1, "{text}");
            assert!(text.len() < 400, "{name}: a short message: {text}");
        }
    }

    /// YAML fragments a byte mutation rarely produces on its own.
    const TOKENS: [&str; 12] =
        ["*a", "&a ", "[", "{", "- ", ": ", "1e-300", "9223372036854775807", "\n", "!!opencv-matrix ", ".nan", "'"];

    /// Applies edits `(kind, position, byte)` to `bytes`: flip a bit, insert a byte, delete a byte or
    /// insert a YAML token.
    fn mutate(mut bytes: Vec<u8>, edits: &[(u8, usize, u8)]) -> Vec<u8> {
        for &(kind, pos, byte) in edits {
            let at = pos % (bytes.len() + 1);
            match kind % 4 {
                0 if at < bytes.len() => bytes[at] ^= 1 << (byte % 8),
                1 => bytes.insert(at, byte),
                2 if at < bytes.len() => {
                    bytes.remove(at);
                }
                3 => {
                    let token = TOKENS[usize::from(byte) % TOKENS.len()].as_bytes();
                    for (k, &b) in token.iter().enumerate() {
                        bytes.insert(at + k, b);
                    }
                }
                _ => {}
            }
        }
        bytes
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Arbitrary bytes are read without a panic (the result itself is not asserted).
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
            let _ = Rig::from_yaml_str(&String::from_utf8_lossy(&bytes), "fuzz.yaml");
        }

        /// A valid rig.yaml with bytes flipped, inserted or deleted is read without a panic.
        #[test]
        fn mutated_rig_files_never_panic(
            edits in proptest::collection::vec((any::<u8>(), any::<usize>(), any::<u8>()), 1..12),
        ) {
            let valid = default_rig().to_yaml_string().into_bytes();
            let text = mutate(valid, &edits);
            let _ = Rig::from_yaml_str(&String::from_utf8_lossy(&text), "fuzz.yaml");
        }

        /// A valid COLMAP model with mutated bytes is read without a panic.
        #[test]
        fn mutated_colmap_models_never_panic(
            edits in proptest::collection::vec((any::<u8>(), any::<usize>(), any::<u8>()), 1..12),
            which in any::<bool>(),
        ) {
            let dir = tempfile::tempdir().expect("tempdir");
            hullcut_rig::colmap::write_colmap(&default_rig(), dir.path(), 1.0).expect("write");
            let file = dir.path().join(if which { "cameras.txt" } else { "images.txt" });
            let bytes = std::fs::read(&file).expect("read");
            std::fs::write(&file, mutate(bytes, &edits)).expect("write");
            let _ = read_colmap(dir.path(), 1.0);
        }
    }
}
