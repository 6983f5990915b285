//! Integration tests of hullcut-dataset: write → read round trips, dropped frames, refusal of
//! inconsistent datasets with errors that name the file, PLY and tool.json.

use std::path::{Path, PathBuf};

use hullcut_dataset::{DatasetMeta, DatasetWriter, DepthImage, FORMAT_VERSION, Mesh, ToolGeometry, TruthPose};
use hullcut_rig::{Camera, Rig, WorldFrame};
use image::{GrayImage, Luma, Rgb, RgbImage};
use nalgebra::{Matrix4, Point3, Rotation3, Translation3, Vector3};

/// Image size of the test cameras: small, so the tests write quickly.
const W: u32 = 8;
const H: u32 = 6;

fn small_rig(cameras: usize) -> Rig {
    let cams = (0..cameras)
        .map(|i| {
            let mut c = Camera::new(format!("cam{i}"), W, H, 10.0, 10.0, 3.5, 2.5);
            c.translation = Vector3::new(0.01 * i as f64, 0.0, 0.5);
            c
        })
        .collect();
    Rig::new(cams, WorldFrame::Other("test table".to_owned()))
}

fn meta(rig: &Rig, frame_count: u64) -> DatasetMeta {
    DatasetMeta {
        format_version: FORMAT_VERSION,
        name: "test".to_owned(),
        fps: 30.0,
        frame_count,
        cameras: rig.cameras.iter().map(|c| c.name.clone()).collect(),
        workspace: None,
    }
}

fn image(frame: u64, camera: usize) -> RgbImage {
    RgbImage::from_fn(W, H, |x, y| Rgb([(x * 30) as u8, (y * 40) as u8, (frame * 7 + camera as u64 * 50) as u8]))
}

fn mask(frame: u64, camera: usize) -> GrayImage {
    GrayImage::from_fn(W, H, |x, y| Luma([[0, 1, 2, 255][((x + y + frame as u32 + camera as u32) % 4) as usize]]))
}

fn depth(frame: u64, camera: usize) -> DepthImage {
    DepthImage::from_fn(W, H, |x, y| Luma([(x * 1000 + y * 7 + frame as u32 * 3 + camera as u32 + 50_000) as u16]))
}

fn timestamp(frame: u64, camera: usize) -> i64 {
    1_700_000_000_000_000_000 + frame as i64 * 33_333_333 + camera as i64 * 101 - 250
}

fn pose(frame: u64) -> TruthPose {
    let r = Rotation3::from_euler_angles(0.1 * frame as f64, -0.3, 1.234_567_89);
    let t = Translation3::new(0.01 * frame as f64, 1.0 / 3.0, -0.2);
    TruthPose {
        frame,
        timestamp_ns: timestamp(frame, 1),
        tool_to_world: nalgebra::Isometry3::from_parts(t, r.into()).to_homogeneous(),
    }
}

/// A closed tetrahedron, counter-clockwise seen from outside.
fn tetra() -> Mesh {
    Mesh {
        vertices: vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.1, 0.0, 0.0),
            Point3::new(0.0, 0.1, 0.0),
            Point3::new(0.0, 0.0, 1.0 / 7.0),
        ],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    }
}

fn tool() -> ToolGeometry {
    ToolGeometry {
        mesh: tetra(),
        tip: Point3::new(0.1, 0.0, 0.0),
        cutting_edge: vec![Point3::new(0.1, 0.0, 0.0), Point3::new(0.0, 0.0, 0.0)],
        blade_normal: Vector3::new(0.0, 0.0, 1.0),
        blade_thickness: 0.0004,
        blade_outline: Some(vec![Point3::new(0.1, 0.0, 0.0), Point3::new(0.0, 0.02, 0.0), Point3::new(0.0, 0.0, 0.0)]),
    }
}

/// Frames in the sample dataset.
const FRAMES: u64 = 4;
/// Cameras in the sample dataset.
const CAMERAS: usize = 3;

/// Writes the sample dataset at `out`: every image, mask and depth image except the views in
/// `skip`, backgrounds, the tool, poses and meshes.
fn write_sample(out: &Path, skip: &[(u64, usize)]) -> PathBuf {
    write_sample_with(out, &small_rig(CAMERAS), skip, false).expect("write the sample dataset")
}

fn write_sample_with(out: &Path, rig: &Rig, skip: &[(u64, usize)], force: bool) -> hullcut_dataset::Result<PathBuf> {
    let writer = DatasetWriter::create(out, meta(rig, FRAMES), rig, force)?;
    writer.write_tool(&tool())?;
    for camera in 0..rig.len() {
        writer.write_background(camera, 0, &image(99, camera))?;
        writer.write_background(camera, 1, &image(98, camera))?;
    }
    // Several threads at once, as the synthesizer does with rayon.
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..FRAMES)
            .map(|frame| {
                let writer = &writer;
                s.spawn(move || -> hullcut_dataset::Result<()> {
                    for camera in 0..rig.len() {
                        if skip.contains(&(frame, camera)) {
                            continue;
                        }
                        writer.write_image(frame, camera, &image(frame, camera), timestamp(frame, camera))?;
                        writer.write_mask(frame, camera, &mask(frame, camera))?;
                        writer.write_depth(frame, camera, &depth(frame, camera))?;
                    }
                    writer.write_truth_pose(&pose(frame))?;
                    writer.write_truth_mesh("scalpel", frame, &tetra())
                })
            })
            .collect();
        handles.into_iter().try_for_each(|h| h.join().expect("writer thread"))
    })?;
    writer.finish()
}

/// The error's message, for assertions on what it names.
fn message<T: std::fmt::Debug>(r: hullcut_dataset::Result<T>) -> String {
    r.expect_err("expected an error").to_string()
}

fn open_err(dir: &Path) -> String {
    message(hullcut_dataset::Dataset::open(dir))
}

/// Lists a folder's entry names, sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("read_dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

mod round_trip {
    use super::*;
    use hullcut_dataset::Dataset;

    #[test]
    fn everything_written_is_read_back_exactly() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("nested").join("ds");
        let path = write_sample(&out, &[]);
        assert_eq!(path, out);
        // Only the dataset remains in the parent: no temporary folder.
        assert_eq!(entries(&tmp.path().join("nested")), vec!["ds"]);

        let ds = Dataset::open(&out).expect("open");
        assert_eq!(ds.meta(), &meta(&small_rig(CAMERAS), FRAMES));
        assert_eq!(ds.rig().cameras.len(), CAMERAS);
        assert_eq!(ds.rig().cameras[1].name, "cam1");
        assert_eq!(ds.rig().world_frame, WorldFrame::Other("test table".to_owned()));
        assert_eq!(ds.frame_numbers(), (0..FRAMES).collect::<Vec<_>>());
        assert!(ds.dropped().is_empty());
        assert!(ds.has_masks() && ds.has_depth() && ds.has_truth());

        for frame in 0..FRAMES {
            let set = ds.read_frame_set(frame, true).expect("frame set");
            assert_eq!(set.frame, frame);
            assert_eq!(set.present(), CAMERAS);
            // Median of three timestamps: the middle camera's.
            assert_eq!(set.timestamp_ns, timestamp(frame, 1));
            assert_eq!(ds.frame_timestamp(frame), Some(timestamp(frame, 1)));
            for (camera, view) in set.views.iter().enumerate() {
                let view = view.as_ref().expect("view");
                assert_eq!(view.camera, camera);
                assert_eq!(view.timestamp_ns, timestamp(frame, camera));
                assert_eq!(ds.timestamp(frame, camera), Some(timestamp(frame, camera)));
                assert_eq!(view.image, image(frame, camera));
                assert_eq!(view.mask.as_ref(), Some(&mask(frame, camera)));
                assert_eq!(ds.read_depth(frame, camera).expect("depth"), depth(frame, camera));
                assert_eq!(ds.read_mask(frame, camera).expect("mask"), mask(frame, camera));
            }
            assert!(set.views.iter().flatten().all(|v| v.mask.is_some()));
            assert!(
                ds.read_frame_set(frame, false).expect("no masks").views.iter().flatten().all(|v| v.mask.is_none())
            );
            assert_eq!(ds.read_truth_mesh("scalpel", frame).expect("mesh"), Some(tetra()));
            assert_eq!(ds.read_truth_mesh("hand", frame).expect("no hand mesh"), None);
        }
        for camera in 0..CAMERAS {
            assert_eq!(ds.background_images(camera).expect("backgrounds"), vec![image(99, camera), image(98, camera)]);
        }
        assert_eq!(ds.tool().expect("tool"), Some(tool()));
        let poses = ds.truth_poses().expect("poses").expect("has poses");
        assert_eq!(poses, (0..FRAMES).map(pose).collect::<Vec<_>>());
    }

    #[test]
    fn files_follow_the_documented_layout() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[(1, 2)]);
        assert_eq!(
            entries(&out),
            vec![
                "cam0",
                "cam1",
                "cam2",
                "dataset.toml",
                "depth",
                "frames.csv",
                "masks",
                "rig.yaml",
                "tool.json",
                "tool.ply",
                "truth"
            ]
        );
        assert_eq!(
            entries(&out.join("cam0")),
            vec!["000000.png", "000001.png", "000002.png", "000003.png", "background00.png", "background01.png"]
        );
        assert!(out.join("depth/cam2/000003.png").is_file());
        assert!(out.join("masks/cam1/000000.png").is_file());
        assert!(out.join("truth/meshes/scalpel/000002.ply").is_file());

        let toml = std::fs::read_to_string(out.join("dataset.toml")).expect("toml");
        assert!(toml.contains("format_version = 1"), "{toml}");
        assert!(toml.contains(r#"cameras = ["cam0", "cam1", "cam2"]"#), "{toml}");

        // Sorted by frame, then rig camera order; the dropped view has no row.
        let csv = std::fs::read_to_string(out.join("frames.csv")).expect("csv");
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "frame,camera,timestamp_ns");
        assert_eq!(lines.len(), 1 + FRAMES as usize * CAMERAS - 1);
        assert_eq!(lines[1], format!("0,cam0,{}", timestamp(0, 0)));
        assert_eq!(lines[5], format!("1,cam1,{}", timestamp(1, 1)));
        assert_eq!(lines[6], format!("2,cam0,{}", timestamp(2, 0)));

        let poses = std::fs::read_to_string(out.join("truth/poses.jsonl")).expect("poses");
        let first: serde_json::Value = serde_json::from_str(poses.lines().next().expect("a line")).expect("json");
        assert_eq!(first["frame"], 0);
        assert_eq!(first["timestamp_ns"], timestamp(0, 1));
        let m = first["tool_to_world"].as_array().expect("array");
        assert_eq!(m.len(), 16);
        // Row-major: the translation is the last column.
        assert_eq!(m[7].as_f64(), Some(1.0 / 3.0));
        assert_eq!(m[15].as_f64(), Some(1.0));

        let tool_json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("tool.json")).expect("tool.json")).expect("json");
        assert_eq!(tool_json["mesh"], "tool.ply");
        assert_eq!(tool_json["blade_thickness"], 0.0004);
    }

    #[test]
    fn other_files_in_camera_folders_are_ignored() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[]);
        for name in ["notes.txt", "12.png", "0000012.png", "000001.jpg", "background.png"] {
            std::fs::write(out.join("cam0").join(name), b"not an image").expect("write");
        }
        // A folder of the user's next to the cameras, without frame images, is ignored too.
        std::fs::create_dir(out.join("docs")).expect("mkdir");
        std::fs::write(out.join("docs/readme.txt"), b"hello").expect("write");
        let ds = Dataset::open(&out).expect("open");
        assert_eq!(ds.frame_numbers().len(), FRAMES as usize);
    }
}

mod dropped {
    use super::*;
    use hullcut_dataset::{Dataset, Dropped};

    #[test]
    fn a_dropped_view_is_reported_and_read_as_none() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[(1, 2)]);
        let ds = Dataset::open(&out).expect("open");
        assert_eq!(ds.dropped(), &[Dropped { frame: 1, camera: 2 }]);
        assert_eq!(ds.timestamp(1, 2), None);
        let set = ds.read_frame_set(1, true).expect("frame set");
        assert_eq!(set.present(), 2);
        assert!(set.views[2].is_none());
        assert!(set.views[0].is_some() && set.views[1].is_some());
        // Lower median of two timestamps.
        assert_eq!(set.timestamp_ns, timestamp(1, 0));
        let err = message(ds.read_image(1, 2));
        assert!(err.contains("000001.png") && err.contains("cam2"), "{err}");
    }

    #[test]
    fn a_frame_set_without_images_is_dropped_entirely() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[(2, 0), (2, 1), (2, 2), (3, 0)]);
        let ds = Dataset::open(&out).expect("open");
        assert_eq!(ds.frame_numbers(), vec![0, 1, 3]);
        assert_eq!(
            ds.dropped(),
            &[
                Dropped { frame: 2, camera: 0 },
                Dropped { frame: 2, camera: 1 },
                Dropped { frame: 2, camera: 2 },
                Dropped { frame: 3, camera: 0 }
            ]
        );
        let set = ds.read_frame_set(2, false).expect("frame set");
        assert_eq!(set.present(), 0);
        assert_eq!(ds.frame_timestamp(2), None);
        let err = message(ds.read_frame_set(FRAMES, false));
        assert!(err.contains("frame 4") && err.contains("frame_count = 4"), "{err}");
    }
}

mod writer {
    use super::*;

    #[test]
    fn an_existing_output_is_refused_without_force() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[]);
        let rig = small_rig(CAMERAS);
        let err = message(DatasetWriter::create(&out, meta(&rig, 2), &rig, false));
        assert!(err.contains(&out.display().to_string()) && err.contains("exists"), "{err}");
        // Nothing was touched, and no temporary folder is left.
        assert_eq!(entries(tmp.path()), vec!["ds"]);
        hullcut_dataset::Dataset::open(&out).expect("the old dataset is intact");
    }

    #[test]
    fn force_replaces_an_existing_dataset() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        write_sample(&out, &[]);
        let rig = small_rig(2);
        let writer = DatasetWriter::create(&out, meta(&rig, 1), &rig, true).expect("create");
        // The old dataset stays in place until finish.
        assert!(out.join("tool.json").is_file());
        writer.write_image(0, 1, &image(0, 1), 5).expect("image");
        writer.finish().expect("finish");
        assert_eq!(entries(tmp.path()), vec!["ds"]);
        assert_eq!(entries(&out), vec!["cam0", "cam1", "dataset.toml", "frames.csv", "rig.yaml"]);
        let ds = hullcut_dataset::Dataset::open(&out).expect("open");
        assert_eq!(ds.rig().len(), 2);
        assert_eq!(ds.timestamp(0, 1), Some(5));
        assert_eq!(ds.tool().expect("no tool"), None);
        assert_eq!(ds.truth_poses().expect("no poses"), None);
    }

    #[test]
    fn force_does_not_replace_a_folder_that_is_not_a_dataset() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("home");
        std::fs::create_dir(&out).expect("mkdir");
        std::fs::write(out.join("thesis.tex"), b"precious").expect("write");
        let rig = small_rig(1);
        let err = message(DatasetWriter::create(&out, meta(&rig, 1), &rig, true));
        assert!(err.contains("home") && err.contains("not a dataset"), "{err}");
        assert!(out.join("thesis.tex").is_file());
        // An empty folder may be replaced.
        let empty = tmp.path().join("empty");
        std::fs::create_dir(&empty).expect("mkdir");
        DatasetWriter::create(&empty, meta(&rig, 1), &rig, true).expect("create").finish().expect("finish");
        assert!(empty.join("dataset.toml").is_file());
    }

    #[test]
    fn a_writer_dropped_without_finish_leaves_nothing() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        let rig = small_rig(2);
        {
            let writer = DatasetWriter::create(&out, meta(&rig, 3), &rig, false).expect("create");
            writer.write_image(0, 0, &image(0, 0), 1).expect("image");
            writer.write_mask(0, 0, &mask(0, 0)).expect("mask");
            writer.write_truth_mesh("hand", 0, &tetra()).expect("mesh");
            assert_eq!(entries(tmp.path()).len(), 1, "one temporary folder while writing");
            assert!(!out.exists());
        }
        assert!(!out.exists());
        assert!(entries(tmp.path()).is_empty(), "{:?}", entries(tmp.path()));
    }

    #[test]
    fn a_failed_write_sequence_leaves_nothing() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        let rig = small_rig(2);
        // The second camera's image has the wrong size: the whole write fails and is cleaned up.
        let result = (|| -> hullcut_dataset::Result<PathBuf> {
            let writer = DatasetWriter::create(&out, meta(&rig, 3), &rig, false)?;
            writer.write_image(0, 0, &image(0, 0), 1)?;
            writer.write_image(0, 1, &RgbImage::new(W + 1, H), 1)?;
            writer.finish()
        })();
        let err = message(result);
        assert!(
            err.contains("000000.png") && err.contains("cam1") && err.contains("9x6") && err.contains("8x6"),
            "{err}"
        );
        assert!(entries(tmp.path()).is_empty());
    }

    #[test]
    fn writes_are_checked() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        let rig = small_rig(2);
        let writer = DatasetWriter::create(&out, meta(&rig, 3), &rig, false).expect("create");
        let err = message(writer.write_image(3, 0, &image(3, 0), 0));
        assert!(err.contains("frame 3") && err.contains("frame_count = 3"), "{err}");
        let err = message(writer.write_image(0, 2, &image(0, 2), 0));
        assert!(err.contains("camera 2") && err.contains("2 cameras"), "{err}");
        writer.write_image(0, 0, &image(0, 0), 0).expect("first");
        let err = message(writer.write_image(0, 0, &image(0, 0), 0));
        assert!(err.contains("written twice") && err.contains("000000.png"), "{err}");
        let err = message(writer.write_mask(0, 0, &GrayImage::new(2, 2)));
        assert!(err.contains("masks") && err.contains("2x2"), "{err}");
        let err = message(writer.write_truth_mesh("../escape", 0, &tetra()));
        assert!(err.contains("label"), "{err}");
        let mut bad = pose(0);
        bad.tool_to_world = bad.tool_to_world.transpose();
        let err = message(writer.write_truth_pose(&bad));
        assert!(err.contains("poses.jsonl") && err.contains("bottom row"), "{err}");
        writer.write_truth_pose(&pose(0)).expect("pose");
        let err = message(writer.write_truth_pose(&pose(0)));
        assert!(err.contains("twice"), "{err}");
        // The rig and dataset.toml must name the same cameras.
        let mut m = meta(&rig, 3);
        m.cameras.reverse();
        let err = message(DatasetWriter::create(&tmp.path().join("other"), m, &rig, false));
        assert!(err.contains("rig.yaml") && err.contains("cam1"), "{err}");
    }
}

mod refused {
    use super::*;

    fn sample(tmp: &Path) -> PathBuf {
        write_sample(&tmp.join("ds"), &[])
    }

    #[test]
    fn missing_frames_csv() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::remove_file(ds.join("frames.csv")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("frames.csv") && err.contains("missing"), "{err}");
    }

    #[test]
    fn missing_dataset_toml_and_rig() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::remove_file(ds.join("rig.yaml")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("rig.yaml") && err.contains("missing"), "{err}");
        std::fs::remove_file(ds.join("dataset.toml")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("dataset.toml"), "{err}");
        let err = open_err(&tmp.path().join("nowhere"));
        assert!(err.contains("nowhere"), "{err}");
    }

    #[test]
    fn rig_with_fewer_cameras_than_folders() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = write_sample_with(&tmp.path().join("ds"), &small_rig(6), &[], false).expect("write");
        small_rig(5).save(ds.join("rig.yaml")).expect("save rig");
        let err = open_err(&ds);
        assert!(err.contains("rig.yaml") && err.contains("5 cameras") && err.contains("6 cameras"), "{err}");

        // With dataset.toml edited to match, the sixth folder is what disagrees.
        let mut m = meta(&small_rig(5), FRAMES);
        m.name = "edited".to_owned();
        std::fs::write(ds.join("dataset.toml"), toml::to_string(&m).expect("toml")).expect("write");
        let err = open_err(&ds);
        assert!(err.contains("cam5") && err.contains("not a camera") && err.contains("rig.yaml"), "{err}");
    }

    #[test]
    fn invalid_rig() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::write(ds.join("rig.yaml"), "%YAML:1.0\n---\ncamera_count: 1\n").expect("write");
        let err = open_err(&ds);
        assert!(err.contains("rig.yaml") && err.contains("camera_0"), "{err}");
    }

    #[test]
    fn wrong_image_size() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        RgbImage::new(4, 4).save(ds.join("cam1/000000.png")).expect("save");
        let err = open_err(&ds);
        assert!(
            err.contains("cam1") && err.contains("000000.png") && err.contains("4x4") && err.contains("8x6"),
            "{err}"
        );
    }

    #[test]
    fn wrong_image_size_in_a_later_frame() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        RgbImage::new(4, 4).save(ds.join("cam1/000002.png")).expect("save");
        let opened = hullcut_dataset::Dataset::open(&ds).expect("only the first frame's header is checked at open");
        let err = message(opened.read_frame_set(2, false));
        assert!(err.contains("cam1") && err.contains("000002.png") && err.contains("4x4"), "{err}");
    }

    #[test]
    fn missing_camera_folder() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::remove_dir_all(ds.join("cam2")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("cam2") && err.contains("missing"), "{err}");
    }

    #[test]
    fn missing_mask_folder() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::remove_dir_all(ds.join("masks/cam0")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("masks") && err.contains("cam0"), "{err}");
    }

    #[test]
    fn corrupt_png() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        // A truncated later frame opens (only headers of first frames are read) but fails to decode.
        let file = ds.join("cam1/000002.png");
        let bytes = std::fs::read(&file).expect("read");
        std::fs::write(&file, &bytes[..bytes.len() / 2]).expect("truncate");
        let opened = hullcut_dataset::Dataset::open(&ds).expect("open");
        let err = message(opened.read_frame_set(2, false));
        assert!(err.contains("cam1") && err.contains("000002.png"), "{err}");
        // A mask that is garbage.
        std::fs::write(ds.join("masks/cam0/000001.png"), b"garbage").expect("write");
        let err = message(opened.read_frame_set(1, true));
        assert!(err.contains("masks") && err.contains("000001.png"), "{err}");
        // A first frame cut short inside its header fails at open.
        let first = ds.join("cam0/000000.png");
        let bytes = std::fs::read(&first).expect("read");
        std::fs::write(&first, &bytes[..10]).expect("truncate");
        let err = open_err(&ds);
        assert!(err.contains("cam0") && err.contains("000000.png"), "{err}");
    }

    #[test]
    fn a_mask_of_the_wrong_pixel_format() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        RgbImage::new(W, H).save(ds.join("masks/cam2/000001.png")).expect("save");
        let opened = hullcut_dataset::Dataset::open(&ds).expect("open");
        let err = message(opened.read_mask(1, 2));
        assert!(err.contains("000001.png") && err.contains("8-bit"), "{err}");
    }

    /// Replaces frames.csv's text and returns the error of opening.
    fn with_csv(edit: impl FnOnce(String) -> String) -> String {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let csv = std::fs::read_to_string(ds.join("frames.csv")).expect("read");
        std::fs::write(ds.join("frames.csv"), edit(csv)).expect("write");
        open_err(&ds)
    }

    #[test]
    fn bad_csv_rows() {
        // 12 rows after the header: the appended row is line 14.
        let err = with_csv(|c| c + "x,cam0,5\n");
        assert!(err.contains("frames.csv:14") && err.contains("`x`"), "{err}");
        let err = with_csv(|c| c + "1,cam9,5\n");
        assert!(err.contains("frames.csv:14") && err.contains("cam9"), "{err}");
        let err = with_csv(|c| c + "1,cam0\n");
        assert!(err.contains("frames.csv:14") && err.contains("3 fields"), "{err}");
        let err = with_csv(|c| c + "1,cam0,1.5\n");
        assert!(err.contains("frames.csv:14") && err.contains("timestamp"), "{err}");
        let err = with_csv(|c| c + "4,cam0,5\n");
        assert!(err.contains("frames.csv:14") && err.contains("frame_count = 4"), "{err}");
        let err = with_csv(|c| c + "0,cam2,5\n");
        assert!(err.contains("frames.csv:14") && err.contains("twice") && err.contains("line 4"), "{err}");
        let err = with_csv(|c| c.replacen("frame,camera,timestamp_ns", "frame,cam,t", 1));
        assert!(err.contains("frames.csv:1") && err.contains("header"), "{err}");
    }

    #[test]
    fn rows_and_images_disagree() {
        // A row without its PNG.
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        std::fs::remove_file(ds.join("cam1/000003.png")).expect("rm");
        let err = open_err(&ds);
        assert!(err.contains("cam1") && err.contains("000003.png") && err.contains("frames.csv line"), "{err}");
        // A PNG without its row.
        let err = with_csv(|c| c.lines().filter(|l| !l.starts_with("2,cam0,")).map(|l| format!("{l}\n")).collect());
        assert!(err.contains("000002.png") && err.contains("no row in") && err.contains("frames.csv"), "{err}");
    }

    #[test]
    fn bad_dataset_toml() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let toml_path = ds.join("dataset.toml");
        let text = std::fs::read_to_string(&toml_path).expect("read");
        std::fs::write(&toml_path, text.replace("format_version = 1", "format_version = 2\nnew_key = 1"))
            .expect("write");
        let err = open_err(&ds);
        assert!(err.contains("dataset.toml") && err.contains("format_version") && err.contains('2'), "{err}");
        std::fs::write(&toml_path, format!("{text}colour = \"red\"\n")).expect("write");
        let err = open_err(&ds);
        assert!(err.contains("dataset.toml") && err.contains("colour"), "{err}");
        std::fs::write(&toml_path, text.replace("fps = 30.0", "fps = -1.0")).expect("write");
        let err = open_err(&ds);
        assert!(err.contains("dataset.toml") && err.contains("fps"), "{err}");
    }

    #[test]
    fn bad_truth_poses() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let path = ds.join("truth/poses.jsonl");
        let opened = hullcut_dataset::Dataset::open(&ds).expect("open");
        let line = r#"{"frame":1,"timestamp_ns":5,"tool_to_world":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0]}"#;
        std::fs::write(&path, format!("\n{line}\n")).expect("write");
        let err = message(opened.truth_poses());
        assert!(err.contains("poses.jsonl:2") && err.contains("16 numbers") && err.contains("15"), "{err}");
        std::fs::write(&path, "{\"frame\":1}\n").expect("write");
        let err = message(opened.truth_poses());
        assert!(err.contains("poses.jsonl:1") && err.contains("timestamp_ns"), "{err}");
        let ok = r#"{"frame":1,"timestamp_ns":5,"tool_to_world":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}"#;
        std::fs::write(&path, format!("{ok}\n{ok}\n")).expect("write");
        let err = message(opened.truth_poses());
        assert!(err.contains("poses.jsonl:2") && err.contains("line 1"), "{err}");
    }
}

mod tool_json {
    use super::*;
    use hullcut_dataset::{read_tool, write_tool};

    #[test]
    fn round_trip_and_normalization() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("scalpel.json");
        let mut t = tool();
        t.blade_outline = None;
        write_tool(&path, &t).expect("write");
        assert!(tmp.path().join("scalpel.ply").is_file());
        assert_eq!(read_tool(&path).expect("read"), t);

        let text = std::fs::read_to_string(&path).expect("read");
        assert!(!text.contains("blade_outline"), "{text}");
        let text = text.replace("\"blade_normal\": [\n    0.0,\n    0.0,\n    1.0\n  ]", "\"blade_normal\": [0, 3, 4]");
        std::fs::write(&path, text).expect("write");
        let read = read_tool(&path).expect("read");
        assert!((read.blade_normal - Vector3::new(0.0, 0.6, 0.8)).norm() < 1e-15, "{}", read.blade_normal);
    }

    /// tool.json as written for the sample tool, edited; the error of reading it.
    pub(super) fn error_for(edit: impl FnOnce(&mut serde_json::Value)) -> String {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("tool.json");
        write_tool(&path, &tool()).expect("write");
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
        edit(&mut v);
        std::fs::write(&path, v.to_string()).expect("write");
        message(read_tool(&path))
    }

    #[test]
    fn invalid_values_name_the_file_and_key() {
        let err = error_for(|v| v["cutting_edge"] = serde_json::json!([[0.0, 0.0, 0.0]]));
        assert!(err.contains("tool.json") && err.contains("cutting_edge") && err.contains("at least 2"), "{err}");
        let err = error_for(|v| v["blade_normal"] = serde_json::json!([0.0, 0.0, 0.0]));
        assert!(err.contains("tool.json") && err.contains("blade_normal"), "{err}");
        let err = error_for(|v| v["blade_thickness"] = serde_json::json!(0.0));
        assert!(err.contains("tool.json") && err.contains("blade_thickness"), "{err}");
        let err = error_for(|v| v["mesh"] = serde_json::json!("nowhere.ply"));
        assert!(err.contains("tool.json") && err.contains("mesh") && err.contains("nowhere.ply"), "{err}");
        let err = error_for(|v| v["blade_thicknes"] = serde_json::json!(1.0));
        assert!(err.contains("tool.json") && err.contains("blade_thicknes"), "{err}");
        let err = error_for(|v| {
            v.as_object_mut().expect("object").remove("tip");
        });
        assert!(err.contains("tool.json") && err.contains("tip"), "{err}");
    }

    #[test]
    fn an_invalid_tool_is_not_written() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let mut t = tool();
        t.blade_thickness = -1.0;
        let err = message(write_tool(tmp.path().join("tool.json"), &t));
        assert!(err.contains("blade_thickness"), "{err}");
        assert!(entries(tmp.path()).is_empty());
    }
}

mod ply {
    use super::*;
    use hullcut_dataset::{read_ply, write_ply};

    fn unit_cube() -> Mesh {
        let vertices =
            (0..8).map(|i| Point3::new(f64::from(i & 1), f64::from((i >> 1) & 1), f64::from(i >> 2))).collect();
        // Quads counter-clockwise from outside, fan-split.
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let triangles = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        Mesh { vertices, triangles }
    }

    #[test]
    fn ascii_with_quads_and_extra_properties() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("cube.ply");
        let mut text = String::from(
            "ply\r\nformat ascii 1.0\ncomment made by hand\nobj_info test\nelement vertex 8\nproperty float x\n\
             property float y\nproperty float z\nproperty uchar red\nproperty list uchar int extra\n\
             element face 6\nproperty list uchar int vertex_indices\nproperty float quality\nend_header\n",
        );
        for v in &unit_cube().vertices {
            text += &format!("{} {} {} 200 2 7 8\n", v.x, v.y, v.z);
        }
        for q in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
            text += &format!("4 {} {} {} {} 0.5\n", q[0], q[1], q[2], q[3]);
        }
        std::fs::write(&path, text).expect("write");
        let mesh = read_ply(&path).expect("read");
        assert_eq!(mesh, unit_cube());
        assert!(mesh.is_closed());
    }

    #[test]
    fn binary_little_endian_float_vertices() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("tetra.ply");
        let mesh = tetra();
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float32 x\n\
            property float32 y\nproperty float32 z\nproperty uint8 alpha\nelement face 4\n\
            property list uint8 uint32 vertex_indices\nend_header\n"
            .to_vec();
        for v in &mesh.vertices {
            for c in v.coords.iter() {
                bytes.extend_from_slice(&(*c as f32).to_le_bytes());
            }
            bytes.push(255);
        }
        for t in &mesh.triangles {
            bytes.push(3);
            for i in t {
                bytes.extend_from_slice(&i.to_le_bytes());
            }
        }
        std::fs::write(&path, bytes).expect("write");
        let read = read_ply(&path).expect("read");
        assert_eq!(read.triangles, mesh.triangles);
        for (a, b) in read.vertices.iter().zip(&mesh.vertices) {
            // f32 storage: relative rounding 2^-24.
            assert!((a - b).norm() < 1e-7, "{a} vs {b}");
        }
        assert!(read.is_closed());
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("m.ply");
        let mut mesh = unit_cube();
        mesh.vertices[3] = Point3::new(0.1 + 0.2, -1e-300, 1.0 / 3.0);
        write_ply(&path, &mesh).expect("write");
        assert_eq!(read_ply(&path).expect("read"), mesh);
    }

    #[test]
    fn is_closed_detects_holes_and_flips() {
        assert!(tetra().is_closed_oriented());
        assert!(unit_cube().is_closed_oriented());
        let mut open = tetra();
        open.triangles.pop();
        assert!(!open.is_closed_oriented());
        let mut flipped = tetra();
        flipped.triangles[0].swap(1, 2);
        assert!(!flipped.is_closed_oriented());
        assert!(!Mesh::default().is_closed_oriented());
    }

    #[test]
    fn malformed_files_name_the_file_and_place() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let path = tmp.path().join("bad.ply");
        let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
                      element face 1\nproperty list uchar uint vertex_indices\nend_header\n";
        let cases = [
            (format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n"), "face 0"),
            (format!("{header}0 0 0\n1 0 0\n0 1 0\n2 0 1\n"), "face 0"),
            (format!("{header}0 0 0\n1 zero 0\n"), "vertex 1"),
            (format!("{header}0 0 0\n1 0 0\n"), "ends early"),
            ("ply\nformat binary_big_endian 2.0\nend_header\n".to_owned(), "format"),
            ("solid stl\n".to_owned(), "not a PLY"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nend_header\n0\n".to_owned(), "`y`"),
        ];
        for (text, expected) in cases {
            std::fs::write(&path, &text).expect("write");
            let err = message(read_ply(&path));
            assert!(err.contains("bad.ply") && err.contains(expected), "{err} (expected `{expected}`)");
        }
        // A binary file cut short.
        write_ply(&path, &tetra()).expect("write");
        let bytes = std::fs::read(&path).expect("read");
        std::fs::write(&path, &bytes[..bytes.len() - 3]).expect("truncate");
        let err = message(read_ply(&path));
        assert!(err.contains("bad.ply") && err.contains("face 3"), "{err}");
    }
}

mod properties {
    use super::*;
    use hullcut_dataset::{Dataset, read_ply, write_ply};
    use proptest::prelude::*;

    fn finite() -> impl Strategy<Value = f64> {
        prop_oneof![-1e3..1e3f64, any::<f64>().prop_filter("finite", |v| v.is_finite())]
    }

    /// Any accepted timestamp, the bounds included.
    fn timestamp_ns() -> impl Strategy<Value = i64> {
        let max = hullcut_dataset::MAX_ABS_TIMESTAMP_NS;
        prop_oneof![Just(-max), Just(max), -max..=max, -1_000_000_000i64..1_000_000_000]
    }

    /// Translations a pose may have once the test adds up to 2 m: tiny, ordinary and near the bound.
    fn translation_m() -> impl Strategy<Value = f64> {
        let max = hullcut_rig::MAX_WORLD_COORDINATE_M - 2.0;
        prop_oneof![-1.0..1.0f64, -max..max, -1e-300..1e-300f64, Just(max), Just(-max)]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Timestamps (any within ±MAX_ABS_TIMESTAMP_NS, each camera's in order) and poses (any
        /// rotation, any translation within the world's bound less the 2 m the test adds) come back
        /// bit for bit, whatever order they were written in.
        #[test]
        fn poses_and_timestamps_round_trip(
            stamps in proptest::collection::vec(timestamp_ns(), 6),
            angles in proptest::collection::vec(-3.2..3.2f64, 3),
            translation in proptest::collection::vec(translation_m(), 3),
            reverse in any::<bool>(),
        ) {
            // Sorted, every camera's timestamps increase with the frame number.
            let mut stamps = stamps;
            stamps.sort_unstable();
            let tmp = tempfile::tempdir().expect("tempdir");
            let out = tmp.path().join("ds");
            let rig = small_rig(2);
            let writer = DatasetWriter::create(&out, meta(&rig, 3), &rig, false).expect("create");
            let mut order: Vec<u64> = (0..3).collect();
            if reverse {
                order.reverse();
            }
            let r = Rotation3::from_euler_angles(angles[0], angles[1], angles[2]);
            let mut m = r.to_homogeneous();
            m[(0, 3)] = translation[0];
            m[(1, 3)] = translation[1];
            m[(2, 3)] = translation[2];
            for &frame in &order {
                for camera in 0..2 {
                    writer.write_image(frame, camera, &image(frame, camera), stamps[frame as usize * 2 + camera]).expect("image");
                }
                let mut tool_to_world: Matrix4<f64> = m;
                tool_to_world[(0, 3)] += frame as f64;
                writer.write_truth_pose(&TruthPose { frame, timestamp_ns: stamps[frame as usize], tool_to_world }).expect("pose");
            }
            writer.finish().expect("finish");
            let ds = Dataset::open(&out).expect("open");
            for frame in 0..3u64 {
                for camera in 0..2 {
                    prop_assert_eq!(ds.timestamp(frame, camera), Some(stamps[frame as usize * 2 + camera]));
                }
            }
            let poses = ds.truth_poses().expect("poses").expect("some");
            prop_assert_eq!(poses.len(), 3);
            for (frame, p) in poses.iter().enumerate() {
                let mut expected: Matrix4<f64> = m;
                expected[(0, 3)] += frame as f64;
                prop_assert_eq!(p.frame, frame as u64);
                prop_assert_eq!(p.timestamp_ns, stamps[frame]);
                prop_assert_eq!(p.tool_to_world, expected);
            }
        }

        /// Any mesh with finite vertices and in-range indices survives write_ply → read_ply exactly.
        #[test]
        fn ply_round_trip(
            vertices in proptest::collection::vec(proptest::array::uniform3(finite()), 1..40),
            raw in proptest::collection::vec(proptest::array::uniform3(any::<u32>()), 0..60),
        ) {
            let n = vertices.len() as u32;
            let mesh = Mesh {
                vertices: vertices.iter().map(|v| Point3::new(v[0], v[1], v[2])).collect(),
                triangles: raw.iter().map(|t| [t[0] % n, t[1] % n, t[2] % n]).collect(),
            };
            let tmp = tempfile::tempdir().expect("tempdir");
            let path = tmp.path().join("m.ply");
            write_ply(&path, &mesh).expect("write");
            prop_assert_eq!(read_ply(&path).expect("read"), mesh);
        }
    }
}

/// Bad input never crashes, hangs or lies (issue 24): every case below is an error that names the
/// file and the key or line, returned before anything is sized from the bad value.
mod hostile {
    use std::time::{Duration, Instant};

    use super::*;
    use hullcut_dataset::{Dataset, MAX_ABS_TIMESTAMP_NS, TIMESTAMP_BACKSTEP_TOLERANCE_NS, read_tool, write_tool};
    use proptest::prelude::any;
    use proptest::test_runner::{Config, TestRunner};

    fn sample(tmp: &Path) -> PathBuf {
        write_sample(&tmp.join("ds"), &[])
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

    /// Replaces `file` of a fresh sample dataset by `edit` of its text and returns the error of
    /// opening it.
    fn open_with(file: &str, edit: impl FnOnce(String) -> String) -> String {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let text = std::fs::read_to_string(ds.join(file)).expect("read");
        std::fs::write(ds.join(file), edit(text)).expect("write");
        open_err(&ds)
    }

    /// A PNG signature and IHDR chunk claiming `width` x `height` RGB pixels, and nothing else.
    fn png_header(width: u32, height: u32) -> Vec<u8> {
        let mut bytes = vec![0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n', 0, 0, 0, 13];
        bytes.extend_from_slice(b"IHDR");
        bytes.extend_from_slice(&width.to_be_bytes());
        bytes.extend_from_slice(&height.to_be_bytes());
        bytes.extend_from_slice(&[8, 2, 0, 0, 0, 0, 0, 0, 0]);
        bytes
    }

    #[test]
    fn timestamps_beyond_the_bound_are_refused() {
        let first = format!("0,cam0,{}", timestamp(0, 0));
        for t in [i64::MAX.to_string(), i64::MIN.to_string(), (MAX_ABS_TIMESTAMP_NS + 1).to_string()] {
            let err = open_with("frames.csv", |c| c.replacen(&first, &format!("0,cam0,{t}"), 1));
            assert!(err.contains("frames.csv:2") && err.contains(&MAX_ABS_TIMESTAMP_NS.to_string()), "{t}: {err}");
        }
        let err = open_with("frames.csv", |c| c.replacen(&first, "0,cam0,99999999999999999999", 1));
        assert!(err.contains("frames.csv:2") && err.contains("not an integer"), "{err}");
        // The bound itself is accepted (frame 0 may be any time before frame 1).
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let csv = std::fs::read_to_string(ds.join("frames.csv")).expect("read");
        let low = csv.replacen(&first, &format!("0,cam0,{}", -MAX_ABS_TIMESTAMP_NS), 1);
        std::fs::write(ds.join("frames.csv"), low).expect("write");
        let opened = Dataset::open(&ds).expect("the bound is accepted");
        assert_eq!(opened.timestamp(0, 0), Some(-MAX_ABS_TIMESTAMP_NS));
    }

    #[test]
    fn timestamps_going_back_are_refused_beyond_the_tolerance() {
        // Rows are sorted by frame, then camera: frame 2 of cam1 is line 2 + 2 * 3 + 1 = 9.
        let row = format!("2,cam1,{}", timestamp(2, 1));
        let back = timestamp(1, 1) - 10 * TIMESTAMP_BACKSTEP_TOLERANCE_NS;
        let err = open_with("frames.csv", |c| c.replacen(&row, &format!("2,cam1,{back}"), 1));
        assert!(err.contains("frames.csv:9") && err.contains("cam1") && err.contains("frame 1"), "{err}");
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let csv = std::fs::read_to_string(ds.join("frames.csv")).expect("read");
        let jitter = timestamp(1, 1) - TIMESTAMP_BACKSTEP_TOLERANCE_NS / 2;
        std::fs::write(ds.join("frames.csv"), csv.replacen(&row, &format!("2,cam1,{jitter}"), 1)).expect("write");
        assert!(Dataset::open(&ds).is_ok(), "a step back within the tolerance is accepted");
    }

    #[test]
    fn the_writer_refuses_what_readers_refuse() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("ds");
        let rig = small_rig(2);
        let writer = DatasetWriter::create(&out, meta(&rig, 3), &rig, false).expect("create");
        let err = message(writer.write_image(0, 0, &image(0, 0), i64::MAX));
        assert!(err.contains("000000.png") && err.contains("timestamp"), "{err}");
        let mut skewed = pose(0);
        skewed.tool_to_world[(0, 0)] = 1e19;
        let err = message(writer.write_truth_pose(&skewed));
        assert!(err.contains("poses.jsonl") && err.contains("not a rotation"), "{err}");
        let mut late = pose(0);
        late.timestamp_ns = i64::MIN;
        assert!(message(writer.write_truth_pose(&late)).contains("timestamp"));
        // A camera's clock running backwards is refused at finish, and nothing appears.
        writer.write_image(0, 0, &image(0, 0), 1_000_000_000).expect("frame 0");
        writer.write_image(1, 0, &image(1, 0), 1).expect("frame 1");
        let err = message(writer.finish());
        assert!(err.contains("frames.csv") && err.contains("cam0"), "{err}");
        assert!(!out.exists());
        // A rig a reader would refuse is refused when the writer starts.
        let mut bad = small_rig(2);
        bad.cameras[1].fx = 1e-300;
        let err = message(DatasetWriter::create(&out, meta(&bad, 3), &bad, false));
        assert!(err.contains("rig.yaml") && err.contains("camera_1.camera_matrix") && err.contains("1e-300"), "{err}");
    }

    #[test]
    fn truth_poses_must_be_rotations_with_bounded_translations() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let opened = Dataset::open(&ds).expect("open");
        let path = ds.join("truth/poses.jsonl");
        let line = |t: &str, m: &str| format!("{{\"frame\":1,\"timestamp_ns\":{t},\"tool_to_world\":[{m}]}}\n");
        let cases = [
            line("5", "1e19,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1"),
            line("5", "2,0,0,0, 0,2,0,0, 0,0,2,0, 0,0,0,1"),
            line("5", "-1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1"),
            line("5", "1,0,0,1e300, 0,1,0,0, 0,0,1,0, 0,0,0,1"),
            line("9223372036854775807", "1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1"),
            line("5", "1e400,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1"),
        ];
        for text in cases {
            std::fs::write(&path, &text).expect("write");
            let start = Instant::now();
            let err = message(opened.truth_poses());
            assert!(start.elapsed() < Duration::from_secs(5), "{text}");
            assert!(err.contains("poses.jsonl:1") && err.len() < 400, "{text}: {err}");
        }
    }

    #[test]
    fn tool_numbers_outside_their_ranges_are_refused() {
        use serde_json::json;
        let cases: [(serde_json::Value, &str, &str); 6] = [
            (json!({"cutting_edge": [[1e308, 0.0, 0.0], [0.0, 0.0, 0.0]]}), "cutting_edge", "1e308"),
            (json!({"tip": [11.0, 0.0, 0.0]}), "tip", "±10 m"),
            // 0.1 + 0.9 rounds to exactly 1.
            (json!({"cutting_edge": [[0.1, 0.0, 0.0], [-0.9, 0.0, 0.0]]}), "cutting_edge", "span 1 m"),
            (json!({"blade_outline": [[0.0, -1e300, 0.0]]}), "blade_outline", "-1e300"),
            (json!({"blade_thickness": 1.0}), "blade_thickness", "(0, 0.5]"),
            (json!({"blade_normal": [1e308, 1e308, 0.0]}), "blade_normal", "1e308"),
        ];
        for (patch, key, what) in cases {
            let err = super::tool_json::error_for(|v| {
                for (k, value) in patch.as_object().expect("object") {
                    v[k] = value.clone();
                }
                // The numbers are checked before the mesh is read: a missing mesh is not the error.
                v["mesh"] = json!("nowhere.ply");
            });
            assert!(err.contains("tool.json") && err.contains(key) && err.contains(what), "{what}: {err}");
            assert!(err.len() < 400, "a short message: {err}");
        }
        let mut far = tool();
        far.cutting_edge[1] = Point3::new(1e308, 0.0, 0.0);
        let tmp = tempfile::tempdir().expect("tempdir");
        assert!(message(write_tool(tmp.path().join("tool.json"), &far)).contains("cutting_edge"));
    }

    #[test]
    fn oversized_png_headers_are_refused_before_decoding() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        // A later frame: open reads only first frames' headers; reading it refuses the header.
        std::fs::write(ds.join("cam1/000002.png"), png_header(100_000, 100_000)).expect("write");
        std::fs::write(ds.join("masks/cam2/000001.png"), png_header(16_385, 1)).expect("write");
        let opened = Dataset::open(&ds).expect("open");
        let start = Instant::now();
        let err = message(opened.read_frame_set(2, false));
        assert!(start.elapsed() < Duration::from_secs(5));
        assert!(err.contains("cam1") && err.contains("000002.png") && err.contains("100000x100000"), "{err}");
        assert!(err.contains("1..=16384"), "{err}");
        let err = message(opened.read_mask(1, 2));
        assert!(err.contains("000001.png") && err.contains("16385x1"), "{err}");
        // A size within the limit that is not the rig's is refused before decoding too.
        std::fs::write(ds.join("cam0/000003.png"), png_header(16_384, 16_384)).expect("write");
        let err = message(opened.read_image(3, 0));
        assert!(err.contains("16384x16384") && err.contains("8x6"), "{err}");
        // At open, the first frame's header.
        std::fs::write(ds.join("cam2/000000.png"), png_header(0, 7)).expect("write");
        let err = open_err(&ds);
        assert!(err.contains("cam2") && err.contains("000000.png") && err.contains("0x7"), "{err}");
    }

    #[test]
    fn dataset_toml_numbers_outside_their_ranges_are_refused() {
        let cases = [
            ("fps = 30.0", "fps = 1e-300", "fps"),
            ("fps = 30.0", "fps = 1e300", "fps"),
            ("fps = 30.0", "fps = nan", "fps"),
            ("frame_count = 4", "frame_count = 9223372036854775807", "frame_count"),
        ];
        for (from, to, key) in cases {
            let err = open_with("dataset.toml", |t| t.replacen(from, to, 1));
            assert!(err.contains("dataset.toml") && err.contains(key) && err.len() < 400, "{to}: {err}");
        }
        let workspace = "workspace = { min = [-1e300, 0, 0], max = [1, 1, 1] }";
        let err = open_with("dataset.toml", |t| format!("{t}{workspace}\n"));
        assert!(err.contains("dataset.toml") && err.contains("workspace") && err.contains("-1e300"), "{err}");
    }

    #[test]
    fn an_error_chain_names_the_path_once() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let rig = ds.join("rig.yaml");
        std::fs::write(&rig, "%YAML:1.0\n---\ncamera_count: 3\n").expect("write");
        let e = Dataset::open(&ds).expect_err("bad rig");
        let text = chain(&e);
        assert_eq!(text.matches(&rig.display().to_string()).count(), 1, "{text}");
        assert!(text.contains("missing key `camera_0`"), "{text}");
        // An I/O error: frames.csv is a folder.
        let ds = write_sample(&tmp.path().join("ds2"), &[]);
        let csv = ds.join("frames.csv");
        std::fs::remove_file(&csv).expect("rm");
        std::fs::create_dir(&csv).expect("mkdir");
        let text = chain(&Dataset::open(&ds).expect_err("a folder"));
        assert_eq!(text.matches(&csv.display().to_string()).count(), 1, "{text}");
    }

    #[test]
    fn long_values_are_shortened_in_messages() {
        let long = "c".repeat(100_000);
        let err = open_with("frames.csv", |c| format!("{c}1,{long},5\n"));
        assert!(err.contains("more chars") && err.len() < 600, "{} chars", err.len());
        let err = open_with("frames.csv", |c| format!("{c}{long}\n"));
        assert!(err.len() < 600, "{} chars", err.len());
        let err = open_with("dataset.toml", |t| format!("{t}{long} = 1\n"));
        assert!(err.contains("dataset.toml") && err.len() < 600, "{} chars", err.len());
        let err = super::tool_json::error_for(|v| v[long.as_str()] = serde_json::json!(1));
        assert!(err.contains("tool.json") && err.len() < 600, "{} chars", err.len());
        let err = super::tool_json::error_for(|v| v["mesh"] = serde_json::json!(long));
        assert!(err.contains("tool.json") && err.len() < 600, "{} chars", err.len());
    }

    /// Where each corpus file goes in a sample dataset, by its name's prefix, and the file the
    /// error must name.
    fn corpus_target(name: &str) -> Option<&'static str> {
        [
            ("frames_", "frames.csv"),
            ("poses_", "truth/poses.jsonl"),
            ("tool_", "tool.json"),
            ("png_", "cam0/000000.png"),
            ("dataset_", "dataset.toml"),
            ("rig_", "rig.yaml"),
        ]
        .into_iter()
        .find(|(prefix, _)| name.starts_with(prefix))
        .map(|(_, target)| target)
    }

    /// Every file in `tests/corpus/` is a bad input that once crashed, hung or was believed: put in
    /// place in a sample dataset, reading it must be an error that names the file, with the file's
    /// path once in the error chain.
    #[test]
    fn the_regression_corpus_is_refused() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
        let mut paths: Vec<PathBuf> =
            std::fs::read_dir(&dir).expect("tests/corpus").map(|e| e.expect("entry").path()).collect();
        paths.sort();
        assert!(paths.len() >= 10, "the corpus has its files: {paths:?}");
        let tmp = tempfile::tempdir().expect("tempdir");
        let pristine = sample(tmp.path());
        for (i, path) in paths.iter().enumerate() {
            let name = path.file_name().expect("name").to_string_lossy().into_owned();
            let target = corpus_target(&name).unwrap_or_else(|| panic!("{name}: no known prefix"));
            let ds = tmp.path().join(format!("case{i}"));
            copy_tree(&pristine, &ds);
            let installed = ds.join(target);
            std::fs::copy(path, &installed).expect("install");
            let start = Instant::now();
            let e = match Dataset::open(&ds) {
                Err(e) => e,
                Ok(opened) => match (opened.tool(), opened.truth_poses()) {
                    (Err(e), _) | (_, Err(e)) => e,
                    _ => panic!("{name}: accepted"),
                },
            };
            assert!(start.elapsed() < Duration::from_secs(5), "{name} took {:?}", start.elapsed());
            let text = chain(&e);
            assert_eq!(text.matches(&installed.display().to_string()).count(), 1, "{name}: {text}");
            assert!(text.len() < 600, "{name}: a short message: {text}");
        }
    }

    /// Copies a folder tree.
    fn copy_tree(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).expect("mkdir");
        for entry in std::fs::read_dir(from).expect("read_dir") {
            let entry = entry.expect("entry");
            let target = to.join(entry.file_name());
            if entry.file_type().expect("type").is_dir() {
                copy_tree(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), &target).expect("copy");
            }
        }
    }

    /// Fragments of the formats a byte mutation rarely produces on its own.
    const TOKENS: [&str; 12] =
        ["1e308", "-9223372036854775808", "9223372036854775807", ",", "\n", "[", "{", "\"", ":", "nan", "cam1", "="];

    /// Applies edits `(kind, position, byte)` to `bytes`: flip a bit, insert a byte, delete a byte or
    /// insert a token.
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

    /// The files of the sample dataset the fuzz test replaces, one per case.
    const FUZZED: [&str; 6] =
        ["frames.csv", "tool.json", "truth/poses.jsonl", "dataset.toml", "rig.yaml", "cam0/000000.png"];

    /// A valid file with bytes flipped, inserted or deleted, or arbitrary bytes, in place of one of
    /// the sample's files: opening and reading never panic (the result itself is not asserted).
    #[test]
    fn mutated_and_arbitrary_files_never_panic() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let ds = sample(tmp.path());
        let valid: Vec<Vec<u8>> = FUZZED.iter().map(|f| std::fs::read(ds.join(f)).expect("read")).collect();
        let strategy = (
            0..FUZZED.len(),
            proptest::collection::vec((any::<u8>(), any::<usize>(), any::<u8>()), 1..12),
            proptest::option::weighted(0.25, proptest::collection::vec(any::<u8>(), 0..512)),
        );
        let mut runner = TestRunner::new(Config::with_cases(64));
        let result = runner.run(&strategy, |(which, edits, raw)| {
            for (file, bytes) in FUZZED.iter().zip(&valid) {
                std::fs::write(ds.join(file), bytes).expect("restore");
            }
            let bytes = raw.unwrap_or_else(|| mutate(valid[which].clone(), &edits));
            std::fs::write(ds.join(FUZZED[which]), bytes).expect("write");
            if let Ok(opened) = Dataset::open(&ds) {
                let _ = opened.tool();
                let _ = opened.truth_poses();
                let _ = opened.read_frame_set(0, true);
            }
            let _ = read_tool(ds.join("tool.json"));
            Ok(())
        });
        result.expect("no reader panics");
    }
}
