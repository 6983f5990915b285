//! Calibrations from other tools: per-camera files written by OpenCV's own FileStorage (YAML, XML,
//! JSON, with the key names different tools use) read back into the rig they came from.

use std::path::Path;

use hullcut_calib::import::read_opencv_cameras;
use hullcut_rig::{Camera, Rig, lab8_rig};
use opencv::core::{FileStorage, FileStorageTrait, Mat};
use opencv::prelude::*;

fn mat(rows: i32, values: &[f64]) -> Mat {
    let m = Mat::from_slice(values).expect("mat");
    m.reshape(1, rows).expect("reshape").try_clone().expect("clone")
}

/// Writes one camera with OpenCV, in one of three styles of key names, `unit` metres per unit.
fn write_camera(path: &Path, c: &Camera, style: usize, unit: f64) {
    let mut fs = FileStorage::new(path, opencv::core::FileStorage_WRITE, "").expect("open for writing");
    let k = c.k_matrix();
    let k: Vec<f64> = (0..9).map(|i| k[(i / 3, i % 3)]).collect();
    let d = c.distortion.to_array();
    let r = c.rotation.matrix();
    let r: Vec<f64> = (0..9).map(|i| r[(i / 3, i % 3)]).collect();
    let t: Vec<f64> = c.translation.iter().map(|v| v / unit).collect();
    match style {
        // OpenCV's calibration sample: image_width/height, camera_matrix, distortion_coefficients, R, T.
        0 => {
            fs.write_i32("image_width", c.width as i32).expect("w");
            fs.write_i32("image_height", c.height as i32).expect("h");
            fs.write_mat("camera_matrix", &mat(3, &k)).expect("K");
            fs.write_mat("distortion_coefficients", &mat(1, &d)).expect("D");
            fs.write_mat("R", &mat(3, &r)).expect("R");
            fs.write_mat("T", &mat(3, &t)).expect("T");
        }
        // Short names, a Rodrigues vector and eight distortion coefficients (rational ones zero).
        1 => {
            fs.write_i32("width", c.width as i32).expect("w");
            fs.write_i32("height", c.height as i32).expect("h");
            fs.write_mat("K", &mat(3, &k)).expect("K");
            let mut d8 = d.to_vec();
            d8.extend([0.0; 3]);
            fs.write_mat("D", &mat(1, &d8)).expect("D");
            let rvec = c.rotation.scaled_axis();
            fs.write_mat("rvec", &mat(3, &[rvec.x, rvec.y, rvec.z])).expect("rvec");
            fs.write_mat("tvec", &mat(3, &t)).expect("tvec");
        }
        // stereoCalibrate-style names with image_size.
        _ => {
            fs.write_mat("image_size", &mat(1, &[f64::from(c.width), f64::from(c.height)])).expect("size");
            fs.write_mat("cameraMatrix", &mat(3, &k)).expect("K");
            fs.write_mat("distCoeffs", &mat(1, &d[..4])).expect("D");
            fs.write_mat("rotation_matrix", &mat(3, &r)).expect("R");
            fs.write_mat("translation_vector", &mat(3, &t)).expect("T");
        }
    }
    fs.release().expect("close");
}

fn assert_close(a: &Camera, b: &Camera, four_coefficients: bool) {
    assert_eq!((&a.name, a.width, a.height), (&b.name, b.width, b.height));
    for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
        assert!((x - y).abs() < 1e-9 * x.abs().max(1.0), "{}: {x} vs {y}", a.name);
    }
    let (da, db) = (a.distortion.to_array(), b.distortion.to_array());
    for k in 0..if four_coefficients { 4 } else { 5 } {
        assert!((da[k] - db[k]).abs() < 1e-12, "{}: {da:?} vs {db:?}", a.name);
    }
    assert!((a.rotation.matrix() - b.rotation.matrix()).abs().max() < 1e-9, "{}", a.name);
    assert!((a.translation - b.translation).abs().max() < 1e-9, "{}", a.name);
}

#[test]
fn per_camera_files_written_by_opencv_read_back_as_the_rig() {
    let rig = lab8_rig();
    for (ext, style, unit) in [("yml", 0, 1.0), ("xml", 1, 0.001), ("json", 2, 1.0)] {
        let dir = tempfile::tempdir().expect("tempdir");
        // Written in reverse, named so that natural order matters (cam2 before cam10).
        let renamed: Vec<Camera> = rig
            .cameras
            .iter()
            .enumerate()
            .map(|(i, c)| Camera { name: format!("cam{}", [10, 2, 3, 4, 5, 6, 7, 8][i]), ..c.clone() })
            .collect();
        for c in renamed.iter().rev() {
            write_camera(&dir.path().join(format!("{}.{ext}", c.name)), c, style, unit);
        }
        let back: Rig = read_opencv_cameras(dir.path(), unit).expect("read");
        let mut expected = renamed.clone();
        expected.sort_by(|a, b| hullcut_rig::natural_cmp(&a.name, &b.name));
        assert_eq!(back.len(), 8);
        for (a, b) in expected.iter().zip(&back.cameras) {
            assert_close(a, b, style == 2);
        }
    }
}

#[test]
fn bad_calibration_files_are_refused_naming_file_and_key() {
    let rig = lab8_rig();
    let c = &rig.cameras[0];
    let dir = tempfile::tempdir().expect("tempdir");
    assert!(read_opencv_cameras(dir.path(), 1.0).expect_err("empty").to_string().contains("no calibration files"));
    let path = dir.path().join("cam0.yml");
    type Write = Box<dyn Fn(&mut FileStorage)>;
    let cases: [(&str, Write); 5] = [
        (
            "no intrinsic matrix",
            Box::new(|fs| {
                fs.write_i32("width", 640).expect("w");
                fs.write_i32("height", 480).expect("h");
            }),
        ),
        (
            "rational",
            Box::new(|fs| {
                fs.write_i32("width", 640).expect("w");
                fs.write_i32("height", 480).expect("h");
                fs.write_mat("K", &mat(3, &[600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0])).expect("K");
                fs.write_mat("D", &mat(1, &[0.1, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0])).expect("D");
            }),
        ),
        (
            "not a rotation",
            Box::new(|fs| {
                fs.write_i32("width", 640).expect("w");
                fs.write_i32("height", 480).expect("h");
                fs.write_mat("K", &mat(3, &[600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0])).expect("K");
                fs.write_mat("R", &mat(3, &[1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0])).expect("R");
                fs.write_mat("T", &mat(3, &[0.0, 0.0, 1.0])).expect("T");
            }),
        ),
        (
            "no translation",
            Box::new(|fs| {
                fs.write_i32("width", 640).expect("w");
                fs.write_i32("height", 480).expect("h");
                fs.write_mat("K", &mat(3, &[600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0])).expect("K");
                fs.write_mat("rvec", &mat(3, &[0.0, 0.0, 0.0])).expect("rvec");
            }),
        ),
        (
            "image size",
            Box::new(|fs| {
                fs.write_i32("width", 0).expect("w");
                fs.write_i32("height", 480).expect("h");
            }),
        ),
    ];
    for (what, write) in &cases {
        let mut fs = FileStorage::new(&path, opencv::core::FileStorage_WRITE, "").expect("open");
        write(&mut fs);
        fs.release().expect("close");
        let e = read_opencv_cameras(dir.path(), 1.0).expect_err(what).to_string();
        assert!(e.contains("cam0.yml") && e.contains(what), "{what}: {e}");
    }
    std::fs::write(&path, "not: [a FileStorage file").expect("write");
    let e = read_opencv_cameras(dir.path(), 1.0).expect_err("garbage").to_string();
    assert!(e.contains("cam0.yml"), "{e}");
    write_camera(&path, c, 0, 1.0);
    write_camera(&dir.path().join("cam0.xml"), c, 0, 1.0);
    let e = read_opencv_cameras(dir.path(), 1.0).expect_err("twice").to_string();
    assert!(e.contains("two files for camera `cam0`"), "{e}");
}

/// OpenCV FileStorage files with bytes flipped, inserted or removed, or a number replaced by a
/// hostile one: the import refuses them (naming the file) or reads a valid rig, never panics.
mod generated {
    use proptest::prelude::*;

    use super::*;

    const HOSTILE: [&str; 10] =
        ["nan", "-inf", "1e308", "-1e308", "1e-300", "0", "-1", "9223372036854775807", "4294967296", "1e19"];

    fn valid_file() -> Vec<u8> {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("cam0.yml");
        write_camera(&path, &lab8_rig().cameras[0], 0, 1.0);
        std::fs::read(&path).expect("read")
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn mutated_opencv_files_never_panic(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..4), 1..5),
            hostile in 0usize..HOSTILE.len(),
        ) {
            let mut bytes = valid_file();
            for (at, byte, kind) in edits {
                if bytes.is_empty() {
                    break;
                }
                let i = at.index(bytes.len());
                match kind {
                    0 => bytes[i] = byte,
                    1 => bytes.insert(i, byte),
                    2 => {
                        bytes.remove(i);
                    }
                    _ => {
                        // Replace the number that starts at or after i, if any.
                        if let Some(start) = bytes[i..].iter().position(u8::is_ascii_digit).map(|p| p + i) {
                            let end = bytes[start..]
                                .iter()
                                .position(|b| !(b.is_ascii_digit() || b"+-.e".contains(b)))
                                .map_or(bytes.len(), |p| p + start);
                            bytes.splice(start..end, HOSTILE[hostile].bytes());
                        }
                    }
                }
            }
            let dir = tempfile::tempdir().expect("tempdir");
            std::fs::write(dir.path().join("cam0.yml"), &bytes).expect("write");
            match read_opencv_cameras(dir.path(), 1.0) {
                Ok(rig) => prop_assert!(rig.validate("mutated").is_ok()),
                Err(e) => prop_assert!(e.to_string().contains("cam0.yml") || e.to_string().contains(dir.path().to_str().expect("utf-8")), "{e}"),
            }
        }
    }
}
