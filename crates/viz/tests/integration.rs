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

mod reading_back {
    use super::*;
    use proptest::prelude::*;

    /// A recording of `frames` frame sets, each with a text line and three scalars, whose
    /// series are styled once (static).
    fn labelled_recording(path: &Path, frames: i64) {
        let rec = hullcut_viz::open_recording("hullcut_viz_test", &Sink::File(path.to_path_buf())).expect("file opens");
        hullcut_viz::log_series_style(
            &rec,
            "metrics/appearance/hand/colour",
            &[("red", [255, 0, 0]), ("green", [0, 255, 0]), ("blue", [0, 0, 255])],
        )
        .expect("style");
        for frame in 0..frames {
            hullcut_viz::set_frame(&rec, frame);
            hullcut_viz::log_text(&rec, "labelling/source", "geometry", frame % 2 == 1).expect("text");
            hullcut_viz::log_scalars(&rec, "metrics/appearance/hand/colour", &[60.0, 110.0, 200.0]).expect("scalars");
        }
        hullcut_viz::flush(&rec).expect("flushed");
    }

    /// Rows on the timelines per entity: one per frame set logged, none for static data.
    #[test]
    fn rows_per_entity_count_what_was_logged_on_the_timelines() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("labels.rrd");
        labelled_recording(&path, 7);
        let rows = hullcut_viz::rrd_timeline_rows(&path).expect("reads back");
        assert_eq!(rows.get("/labelling/source"), Some(&7), "{rows:?}");
        assert_eq!(rows.get("/metrics/appearance/hand/colour"), Some(&7), "{rows:?}");
        let entities = hullcut_viz::rrd_entities(&path).expect("reads back");
        assert!(entities.contains("/labelling/source"), "{entities:?}");
        assert!(hullcut_viz::rrd_timeline_rows(&dir.path().join("missing.rrd")).is_err());
    }

    /// Every file in tests/corpus (bad recordings found so far: an empty file, a single zero
    /// byte, which read back as an empty recording until the readers refused a file with no
    /// message, text, a message whose stated length of 6.5 EB rerun's decoder tried to
    /// allocate, aborting the process, until the readers stopped before a frame that runs past
    /// the file's end, and a recording cut short with two bytes overwritten whose arrow buffer
    /// arrow's slicing asserted on, a panic, until the readers caught it) is refused by both
    /// readers with an error naming it.
    #[test]
    fn the_corpus_of_bad_recordings_is_refused() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
        let mut entries: Vec<_> = std::fs::read_dir(&dir).expect("corpus").map(|e| e.expect("entry").path()).collect();
        entries.sort();
        for path in &entries {
            let name = path.file_name().and_then(|n| n.to_str()).expect("name");
            let e = hullcut_viz::rrd_timeline_rows(path).expect_err(name);
            assert!(e.to_string().contains(name), "{name}: {e}");
            assert!(hullcut_viz::rrd_entities(path).is_err(), "{name}");
        }
        assert!(entries.len() >= 5, "the corpus holds {} files", entries.len());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// A recording cut short, or with bytes overwritten, reads back as an error or as what
        /// survived, never a panic; garbage alone is an error.
        #[test]
        fn damaged_recordings_never_panic_the_readers(cut in 0.0f64..1.0, at in 0.0f64..1.0, junk in proptest::collection::vec(any::<u8>(), 1..64)) {
            let dir = tempfile::tempdir().expect("tempdir");
            let path = dir.path().join("labels.rrd");
            labelled_recording(&path, 3);
            let mut bytes = std::fs::read(&path).expect("written");
            let keep = ((bytes.len() as f64) * cut) as usize;
            bytes.truncate(keep.max(1));
            let start = ((bytes.len() as f64) * at) as usize;
            for (k, b) in junk.iter().enumerate() {
                if let Some(x) = bytes.get_mut(start + k) {
                    *x = *b;
                }
            }
            let damaged = dir.path().join("damaged.rrd");
            std::fs::write(&damaged, &bytes).expect("written");
            let _ = hullcut_viz::rrd_timeline_rows(&damaged);
            let _ = hullcut_viz::rrd_entities(&damaged);
            let garbage = dir.path().join("garbage.rrd");
            std::fs::write(&garbage, &junk).expect("written");
            prop_assert!(hullcut_viz::rrd_timeline_rows(&garbage).is_err());
        }
    }
}
