//! Measuring the loop against a recording's truth: every frame set counted, the blade scored on
//! the frames it was trusted, and a recording without truth refused by name.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use hullcut_dataset::Dataset;
use hullcut_hull::{HullParams, WorkingVolume};
use hullcut_pipeline::measure::{Measured, run_measured, truth_and_template};
use hullcut_pipeline::{Carver, FrameSource, Setup, StageTimes, tissue};

const CUT_SMALL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");

fn setup(ds: &Arc<Dataset>) -> Setup {
    let volume = WorkingVolume::from_rig(ds.rig(), 3, true).expect("a working volume");
    let hull = HullParams { min_views: 3, ..HullParams::new(volume.aabb, 0.004) };
    let organ = tissue::build("organ", 0.008, None, None).expect("the organ");
    Setup::new(FrameSource::Dataset(Arc::clone(ds)), ds.frame_numbers(), true, hull, Carver::Cpu, organ)
}

#[test]
fn a_measured_replay_counts_every_frame_set_and_scores_the_blade_where_it_was_trusted() {
    let ds = Arc::new(Dataset::open(CUT_SMALL).expect("the dataset opens"));
    let (template, truth) = truth_and_template(&ds).expect("cut-small has a tool and true poses");
    let m = run_measured(setup(&ds), &template, &truth).expect("the loop runs");
    assert_eq!(m.frames, 9);
    assert_eq!(m.latencies.len(), 9);
    assert!(m.latencies.iter().all(|l| *l > Duration::ZERO));
    assert_eq!(m.times.carve.len(), 9, "every frame set carved once");
    assert!(m.trusted >= 5, "{} of 9 trusted", m.trusted);
    assert_eq!(m.tip_mm.len() as u64, m.trusted);
    // Truth masks at 4 mm leaves: the fitted blade's tip within a few millimetres.
    assert!(m.tip_mm_mean() < 3.0, "tip {} mm", m.tip_mm_mean());
    assert!(m.fps() > 0.0 && m.wall_s > 0.0);
    assert!(m.pieces >= 1);
}

#[test]
fn the_tissue_error_is_the_resected_volume_off_the_reference_or_all_of_it_when_nothing_came_off() {
    let whole = Measured {
        frames: 1,
        wall_s: 1.0,
        latencies: vec![],
        times: StageTimes::default(),
        trusted: 0,
        tip_mm: vec![],
        pieces: 1,
        resected_ml: None,
    };
    assert_eq!(whole.tissue_error_pct(18.0), 100.0);
    assert!(whole.tip_mm_mean().is_nan());
    let cut = Measured { pieces: 2, resected_ml: Some(19.8), ..whole };
    assert!((cut.tissue_error_pct(18.0) - 10.0).abs() < 1e-9);
}

#[test]
fn a_recording_without_true_poses_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    copy_dir(Path::new(CUT_SMALL), dir.path(), &|p| p.file_name().is_some_and(|n| n == "truth"));
    let ds = Arc::new(Dataset::open(dir.path()).expect("the copy opens"));
    let e = truth_and_template(&ds).expect_err("no truth");
    let text = e.to_string();
    assert!(text.contains("no true poses") && text.contains(&dir.path().display().to_string()), "{text}");
}

/// Copies `from` into `to`, leaving out what `skip` names.
fn copy_dir(from: &Path, to: &Path, skip: &dyn Fn(&Path) -> bool) {
    for entry in std::fs::read_dir(from).expect("readable") {
        let path = entry.expect("an entry").path();
        if skip(&path) {
            continue;
        }
        let target = to.join(path.file_name().expect("a name"));
        if path.is_dir() {
            std::fs::create_dir_all(&target).expect("a folder");
            copy_dir(&path, &target, skip);
        } else {
            std::fs::copy(&path, &target).expect("a copy");
        }
    }
}
