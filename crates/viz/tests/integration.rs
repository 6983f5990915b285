//! Integration tests of hullcut-viz: recordings written to `.rrd` files in temporary directories
//! and read back with rerun's own decoder.

use std::collections::BTreeSet;
use std::path::Path;

use hullcut_rig::{Camera, Rig, WorldFrame};
use hullcut_viz::{Sink, VizError};
use nalgebra::{Point3, Vector3};

/// Two cameras 1 m from the table centre, looking at it from opposite sides.
fn two_camera_rig() -> Rig {
    let target = Point3::origin();
    let up = Vector3::z();
    let cameras = [("cam0", Point3::new(1.0, 0.0, 0.6)), ("cam1", Point3::new(-0.8, 0.5, 0.7))]
        .into_iter()
        .map(|(name, eye)| {
            Camera::new(name, 64, 48, 60.0, 61.0, 31.5, 23.5)
                .looking_at(eye, target, up)
                .expect("eye differs from target and the view is not vertical")
        })
        .collect();
    Rig::new(cameras, WorldFrame::Other("test table".to_owned()))
}

/// Every (entity path, component identifier, is static) in an `.rrd` file.
fn rrd_contents(path: &Path) -> BTreeSet<(String, String, bool)> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};

    let file = std::fs::File::open(path).expect("rrd file opens");
    let messages = DecoderApp::decode_eager(std::io::BufReader::new(file)).expect("rrd file has rerun's header");
    let mut contents = BTreeSet::new();
    for msg in messages {
        if let LogMsg::ArrowMsg(_, arrow) = msg.expect("message decodes") {
            let chunk = Chunk::from_arrow_msg(&arrow).expect("message is a chunk");
            for component in chunk.components_identifiers() {
                contents.insert((chunk.entity_path().to_string(), component.to_string(), chunk.is_static()));
            }
        }
    }
    contents
}

fn has(contents: &BTreeSet<(String, String, bool)>, entity: &str, component: &str, is_static: bool) -> bool {
    contents.contains(&(entity.to_owned(), component.to_owned(), is_static))
}

mod file_sink {
    use super::*;

    #[test]
    fn rig_and_frame_data_reach_the_rrd_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("rig.rrd");
        let rig = two_camera_rig();

        let rec = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File(path.clone())).expect("file opens");
        hullcut_viz::log_world(&rec).expect("world");
        hullcut_viz::log_rig(&rec, &rig).expect("rig");
        hullcut_viz::log_label_classes(&rec, &[(0, "background", [0, 0, 0, 0]), (1, "hand", [255, 200, 0, 255])])
            .expect("classes");

        hullcut_viz::set_frame(&rec, 7);
        hullcut_viz::set_capture_time_ns(&rec, 1_700_000_000_000_000_000);
        let rgb = vec![128_u8; 64 * 48 * 3];
        hullcut_viz::log_image_rgb(&rec, "cam0", 64, 48, &rgb).expect("rgb image");
        hullcut_viz::log_labels(&rec, "cam1", 64, 48, &[1_u8; 64 * 48]).expect("labels");
        hullcut_viz::log_image_points(&rec, "cam0", "corners", &[[1.0, 2.0], [10.5, 20.0]], [255, 0, 0, 255], 2.0)
            .expect("2-D points");
        hullcut_viz::log_points3d(&rec, "world/board", &[[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]], [0, 255, 0, 255], 0.003)
            .expect("3-D points");
        hullcut_viz::log_scalar(&rec, "metrics/time/carve", 12.5).expect("scalar");
        hullcut_viz::flush(&rec).expect("flush");
        drop(rec);

        let size = std::fs::metadata(&path).expect("rrd file exists").len();
        // The pixels alone are 9 KiB before compression; headers, schemas and the rig add more.
        assert!(size > 1_000, "rrd file is only {size} bytes");

        let contents = rrd_contents(&path);
        for cam in ["cam0", "cam1"] {
            let entity = format!("/world/cams/{cam}");
            for component in ["Transform3D:translation", "Transform3D:mat3x3", "Transform3D:relation"] {
                assert!(has(&contents, &entity, component, true), "{entity} lacks static {component}: {contents:?}");
            }
            for component in ["Pinhole:image_from_camera", "Pinhole:resolution", "Pinhole:camera_xyz"] {
                assert!(has(&contents, &entity, component, true), "{entity} lacks static {component}: {contents:?}");
            }
        }
        let expected = [
            ("/world", "ViewCoordinates:xyz", true),
            ("/", "AnnotationContext:context", true),
            ("/world/cams/cam0/image", "Image:buffer", false),
            ("/world/cams/cam1/labels", "SegmentationImage:buffer", false),
            ("/world/cams/cam0/image/corners", "Points2D:positions", false),
            ("/world/board", "Points3D:positions", false),
            ("/metrics/time/carve", "Scalars:scalars", false),
        ];
        for (entity, component, is_static) in expected {
            assert!(has(&contents, entity, component, is_static), "missing {entity} {component}: {contents:?}");
        }
    }

    #[test]
    fn a_recording_without_its_index_reads_back_whole_and_is_smaller_by_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let write = |name: &str, index: bool| {
            let path = dir.path().join(name);
            let rec = hullcut_viz::open_recording_indexed("hullcut_viz_test", &Sink::File(path.clone()), index)
                .expect("file opens");
            for frame in 0..200 {
                hullcut_viz::set_frame(&rec, frame);
                hullcut_viz::log_scalar(&rec, "metrics/time/carve", frame as f64).expect("scalar");
                hullcut_viz::flush(&rec).expect("flush");
            }
            drop(rec);
            path
        };
        let (indexed, plain) = (write("indexed.rrd", true), write("plain.rrd", false));
        for path in [&indexed, &plain] {
            assert!(has(&rrd_contents(path), "/metrics/time/carve", "Scalars:scalars", false), "{}", path.display());
        }
        // The index has an entry per chunk (one per flush here): leaving it out saves as much.
        let size = |p: &std::path::Path| std::fs::metadata(p).expect("exists").len();
        assert!(size(&plain) < size(&indexed), "{} against {}", size(&plain), size(&indexed));
    }

    #[test]
    fn jpeg_images_are_logged_as_encoded_images() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("jpeg.rrd");
        let rec = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File(path.clone())).expect("file opens");
        hullcut_viz::set_frame(&rec, 0);
        // Only the JPEG start-of-image marker: the bytes are not decoded until the viewer shows them.
        hullcut_viz::log_image_jpeg(&rec, "cam0", vec![0xFF, 0xD8, 0xFF, 0xD9]).expect("jpeg");
        drop(rec);

        let contents = rrd_contents(&path);
        assert!(has(&contents, "/world/cams/cam0/image", "EncodedImage:blob", false), "{contents:?}");
        assert!(has(&contents, "/world/cams/cam0/image", "EncodedImage:media_type", false), "{contents:?}");
    }

    #[test]
    fn image_of_the_wrong_size_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let rec = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File(dir.path().join("bad.rrd")))
            .expect("file opens");
        let err = hullcut_viz::log_image_rgb(&rec, "cam0", 4, 3, &[0_u8; 35]).expect_err("35 bytes is not 4x3x3");
        assert!(matches!(err, VizError::ImageSize { expected: 36, actual: 35, .. }), "{err}");
        assert!(err.to_string().contains("cam0"), "{err}");
    }

    #[test]
    fn file_in_a_missing_directory_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("no_such_dir").join("x.rrd");
        let err = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File(path)).expect_err("cannot create");
        assert!(matches!(err, VizError::Create { .. }), "{err}");
        assert!(err.to_string().contains("no_such_dir"), "{err}");
    }

    /// A disk that is full from the first byte: the header cannot be written, and opening says so
    /// (rerun's own sink would start a writer thread that fails later, out of sight).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_full_disk_at_open_is_an_error() {
        let err = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File("/dev/full".into()))
            .expect_err("no space left on /dev/full");
        assert!(matches!(err, VizError::Create { .. }), "{err}");
        assert!(err.to_string().contains("/dev/full") && err.to_string().contains("header"), "{err}");
    }
}

mod connect_sink {
    use super::*;

    #[test]
    fn malformed_url_is_an_error_not_a_panic() {
        let err = hullcut_viz::open_recording("hullcut_viz_test", &Sink::Connect("not a url".to_owned()))
            .expect_err("malformed URL");
        assert!(matches!(err, VizError::Open { .. }), "{err}");
        assert!(err.to_string().contains("not a url"), "{err}");
    }

    #[test]
    fn url_that_is_not_a_proxy_endpoint_is_an_error() {
        let err =
            hullcut_viz::open_recording("hullcut_viz_test", &Sink::Connect("rerun+http://127.0.0.1:9876".to_owned()))
                .expect_err("no /proxy");
        assert!(matches!(err, VizError::Open { .. }), "{err}");
    }
}
