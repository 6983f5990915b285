//! Other tools' calibrations and a lab's videos in: the shipped recording's rig through COLMAP's
//! text model and back gives the same hull; six videos make a dataset; bad input is refused or
//! counted.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hullcut_dataset::Dataset;

fn hullcut(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hullcut")).args(args).output().expect("hullcut runs")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn shipped() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small"))
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("list") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8")
}

#[test]
fn the_rig_through_colmap_and_back_gives_the_same_hull() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (a, b, model) = (dir.path().join("a"), dir.path().join("b"), dir.path().join("colmap"));
    copy_dir(&shipped(), &a);
    copy_dir(&shipped(), &b);
    let o = hullcut(&["rig", "export", s(&a.join("rig.yaml")), "--colmap", s(&model), "--scale", "0.001"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(std::fs::read_to_string(model.join("cameras.txt")).expect("cameras.txt").contains("OPENCV"));
    let o =
        hullcut(&["import-calibration", "--colmap", s(&model), "--scale", "0.001", "--out", s(&b.join("rig.yaml"))]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("working volume"), "{}", text(&o));
    // The imported rig's world frame is the model's (not known to be a table's), so both runs get
    // the same volume given.
    let ws = "--workspace=-0.25,-0.25,0,0.25,0.25,0.3";
    for ds in [&a, &b] {
        let o = hullcut(&[
            "reconstruct",
            "--dataset",
            s(ds),
            "--out",
            s(&ds.join("out")),
            "--frames",
            "3",
            ws,
            "--accuracy-every",
            "1000",
        ]);
        assert!(o.status.success(), "{}", text(&o));
    }
    for label in ["hand", "scalpel"] {
        for frame in 0..3 {
            let file = format!("out/hull/{label}/{frame:06}.ply");
            let (x, y) = (
                hullcut_dataset::read_ply(a.join(&file)).expect("ply"),
                hullcut_dataset::read_ply(b.join(&file)).expect("ply"),
            );
            assert_eq!(x.triangles, y.triangles, "{file}: the same cells");
            let worst = x.vertices.iter().zip(&y.vertices).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
            assert!(worst < 1e-9, "{file}: vertices {worst} m apart");
        }
    }
}

#[test]
fn six_videos_make_a_dataset_and_a_short_one_is_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = Dataset::open(shipped()).expect("shipped dataset");
    let mut args: Vec<String> = Vec::new();
    for (k, cam) in ds.meta().cameras.iter().enumerate() {
        let path = dir.path().join(format!("{cam}.avi"));
        if k == 2 {
            // Camera 2's recording stopped two frames early.
            let images: Vec<image::RgbImage> = (0..7).map(|f| ds.read_image(f, k).expect("image")).collect();
            hullcut_capture::write_video(&path, ds.meta().fps, &images).expect("video");
        } else {
            hullcut_capture::export_camera_video(&ds, k, &path).expect("video");
        }
        args.push("--video".into());
        args.push(format!("{cam}={}", path.display()));
    }
    let out = dir.path().join("imported");
    let report = dir.path().join("import.json");
    let rig = shipped().join("rig.yaml");
    let mut cmd: Vec<&str> =
        vec!["import-videos", "--rig", s(&rig), "--out", s(&out), "--report", s(&report), "--offset", "cam5=0.001"];
    cmd.extend(args.iter().map(String::as_str));
    let o = hullcut(&cmd);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("camera `cam2`'s video ended early, after 7 frames"), "{}", text(&o));
    let back = Dataset::open(&out).expect("the import is a dataset");
    assert_eq!(back.meta().frame_count, 9);
    assert_eq!(back.meta().fps, ds.meta().fps, "the videos' own rate");
    assert_eq!(back.dropped().iter().filter(|d| d.camera == 2).count(), 2, "cam2 missing from the last two sets");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(json["kind"], "import_videos");
    assert_eq!(json["sync"]["missing_views"][2], 2);
    assert_eq!(json["frame_sets"], 9);
    // A 1 ms offset moves camera 5's timestamps by a millisecond (media time k/fps).
    let t5 = back.timestamp(1, 5).expect("t");
    let t0 = back.timestamp(1, 0).expect("t");
    assert_eq!(t5 - t0, 1_000_000);

    // Bad input: a camera the rig lacks, a missing camera, an unsupported COLMAP model.
    let o = hullcut(&["import-videos", "--rig", s(&rig), "--out", s(&dir.path().join("x")), "--video", "cam9=a.avi"]);
    assert!(!o.status.success() && text(&o).contains("`cam9` is not a camera of the rig"), "{}", text(&o));
    let first = args[..2].iter().map(String::as_str).collect::<Vec<_>>();
    let o = hullcut(&[&["import-videos", "--rig", s(&rig), "--out", s(&dir.path().join("x"))][..], &first].concat());
    assert!(!o.status.success() && text(&o).contains("no video for camera `cam1`"), "{}", text(&o));
    let model = dir.path().join("model");
    std::fs::create_dir_all(&model).expect("mkdir");
    std::fs::write(model.join("cameras.txt"), "1 THIN_PRISM_FISHEYE 640 480 1 2 3 4 5 6 7 8 9 10 11 12\n")
        .expect("write");
    std::fs::write(model.join("images.txt"), "1 1 0 0 0 0 0 0 1 cam0.png\n\n").expect("write");
    let o = hullcut(&["import-calibration", "--colmap", s(&model), "--out", s(&dir.path().join("r.yaml"))]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("THIN_PRISM_FISHEYE") && text(&o).contains("cameras.txt") && text(&o).contains("line 1"),
        "{}",
        text(&o)
    );
}
