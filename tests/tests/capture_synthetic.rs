//! The capture side on synthetic recordings: the real decode path (OpenCV VideoWriter → video files
//! → six VideoCapture "cameras", one dropping frames → synchronizer) and segmentation accuracy
//! against the renderer's truth masks.

use hullcut_capture::segment::{AppearanceModel, IouAccumulator, SegmentParams, Segmenter};
use hullcut_capture::{Capture, CaptureParams, SourceConfig, SourceSpec, SyncParams, export_camera_video};
use hullcut_dataset::{Dataset, label};
use hullcut_synth::{Scene, SceneConfig, SceneKind, synthesize};
use image::GrayImage;

fn synthetic(kind: SceneKind, seed: u64, frames: u64, fps: f64, scale: f64, dir: &std::path::Path) -> Dataset {
    let mut config = SceneConfig::new(kind, seed, frames);
    config.fps = fps;
    config.truth_meshes = false;
    config.rig.cameras = config.rig.cameras.iter().map(|c| c.scaled(scale)).collect();
    let scene = Scene::new(config).expect("scene");
    let out = dir.join(kind.name());
    synthesize(&scene, &out, kind.name(), false, &|| {}).expect("synthesize");
    Dataset::open(&out).expect("open")
}

#[test]
fn videos_of_a_synthetic_recording_decode_and_resynchronize_with_the_dropping_camera_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = synthetic(SceneKind::Hard, 4, 40, 30.0, 0.5, dir.path());
    let dropped = ds.dropped().len();
    assert!(dropped > 0 && ds.dropped().iter().all(|d| d.camera == 4), "{:?}", ds.dropped());
    let mut configs = Vec::new();
    for camera in 0..6 {
        let video = export_camera_video(&ds, camera, dir.path().join(format!("cam{camera}.avi"))).expect("export");
        assert_eq!(video.frames.len() as u64 + ds.dropped().iter().filter(|d| d.camera == camera).count() as u64, 40);
        configs.push(SourceConfig::new(camera, SourceSpec::File(video.path)).with_timestamps(video.timestamps_ns));
    }
    let capture = Capture::open(configs, &CaptureParams::default()).expect("open six videos");
    let mut synced = capture.synchronized(SyncParams::replay(6, 30.0)).expect("synchronizer");
    let mut sets = Vec::new();
    for set in synced.by_ref() {
        sets.push(set);
    }
    assert!(synced.failures().is_empty(), "{:?}", synced.failures());
    assert_eq!(sets.len(), 40, "one frame set per recorded frame");
    let stats = synced.stats().clone();
    assert_eq!(stats.total_missing() as usize, dropped, "{stats:?}");
    for (k, set) in sets.iter().enumerate() {
        let frame = k as u64;
        assert_eq!(set.timestamp_ns, ds.frame_timestamp(frame).expect("timestamp"), "frame {frame}");
        for (camera, view) in set.views.iter().enumerate() {
            assert_eq!(view.is_some(), ds.timestamp(frame, camera).is_some(), "frame {frame} camera {camera}");
            if let (Some(view), 0) = (view, k % 13) {
                // MJPG is lossy: the decoded image stays close to the PNG on average.
                let original = ds.read_image(frame, camera).expect("png");
                let diff: u64 =
                    view.image.as_raw().iter().zip(original.as_raw()).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum();
                let mean = diff as f64 / original.as_raw().len() as f64;
                assert!(mean < 6.0, "frame {frame} camera {camera}: mean abs difference {mean:.2} levels");
            }
        }
    }
}

#[test]
fn segmentation_of_the_cut_scene_meets_its_iou() {
    // A whole stroke at full resolution, sampled at 10 Hz so that approach, press, cut and lift are
    // all in it. Truth masks are the renderer's first-hit labels at pixel centres.
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = synthetic(SceneKind::Cut, 2, 40, 10.0, 1.0, dir.path());
    // Without colour classes every foreground pixel is unknown: the foreground against the truth's.
    let mut segmenter = Segmenter::from_dataset(&ds, SegmentParams::default()).expect("segmenter");
    let foreground = |m: &GrayImage| {
        let mut m = m.clone();
        m.iter_mut().filter(|p| **p != label::BACKGROUND).for_each(|p| *p = label::HAND);
        m
    };
    let score = |segmenter: &mut Segmenter, merge: bool| {
        let mut acc = IouAccumulator::new();
        for frame in ds.frame_numbers() {
            let set = ds.read_frame_set(frame, true).expect("frame set");
            let masks = segmenter.segment_frame_set(&set).expect("segment");
            for (view, mask) in set.views.iter().zip(masks) {
                if let (Some(view), Some(mask)) = (view, mask) {
                    let truth = view.mask.as_ref().expect("truth mask");
                    let (mask, truth) =
                        if merge { (foreground(&mask), foreground(truth)) } else { (mask, truth.clone()) };
                    acc.add(view.camera, &mask, &truth).expect("score");
                }
            }
        }
        acc.report()
    };
    let pooled = |report: &hullcut_capture::SegmentationReport, name: &str| {
        report.labels.iter().find(|l| l.name == name).and_then(|l| l.iou_pooled).expect("label scored")
    };
    let report = score(&mut segmenter, true);
    assert!(pooled(&report, "hand") >= 0.98, "foreground: {report:?}");
    // Colours learned from three frames' truth masks (a lab's `--label-frames`) label the rest.
    let mut model = AppearanceModel::default();
    for frame in [0, 15, 30] {
        let set = ds.read_frame_set(frame, true).expect("frame set");
        for view in set.views.iter().flatten() {
            model.learn(&view.image, view.mask.as_ref().expect("truth mask"), false);
        }
    }
    segmenter.set_classes(model.classes()).expect("classes");
    let report = score(&mut segmenter, false);
    // The bars: hand ≥ 0.97, scalpel ≥ 0.90 (the blade is 0.4 mm thick and about 5 px wide
    // face-on at a metre; its boundary pixels weigh heavily in a small area).
    assert!(pooled(&report, "hand") >= 0.97, "{report:?}");
    assert!(pooled(&report, "scalpel") >= 0.90, "{report:?}");
}
