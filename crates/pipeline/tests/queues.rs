//! The pipeline's queues: bounded by the frame sets in flight whatever is slow, drops counted
//! under live pacing, every frame set processed without it.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use hullcut_dataset::Dataset;
use hullcut_hull::{HullParams, WorkingVolume};
use hullcut_pipeline::{Carver, FrameSource, Outcome, Setup, Work, spawn, tissue};

const CUT_SMALL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");

/// A replay of `root` at 8 mm leaves and a 8 mm organ (small and quick), `in_flight` at once.
fn setup(root: &Path, in_flight: usize, realtime: bool, repeat: u64) -> Setup {
    let ds = Arc::new(Dataset::open(root).expect("the dataset opens"));
    let volume = WorkingVolume::from_rig(ds.rig(), 3, true).expect("a working volume");
    let hull = HullParams { min_views: 3, ..HullParams::new(volume.aabb, 0.008) };
    let organ = tissue::build("organ", 0.008, None, None).expect("the organ");
    let frames = ds.frame_numbers();
    let span = (frames.len() as f64 * 1e9 / ds.meta().fps).round() as i64;
    let mut setup = Setup::new(FrameSource::Dataset(ds), frames, true, hull, Carver::Cpu, organ);
    setup.in_flight = in_flight;
    setup.realtime = realtime;
    setup.repeat = repeat;
    setup.pass_span_ns = span;
    setup
}

/// Runs to the end, the consumer taking `consume` per result.
fn run(setup: Setup, consume: Duration) -> (Vec<Work>, Outcome) {
    let pipeline = spawn(setup).expect("the stages start");
    let mut results = Vec::new();
    for work in pipeline.output.iter() {
        std::thread::sleep(consume);
        results.push(work);
    }
    (results, pipeline.join())
}

#[test]
fn without_pacing_every_frame_set_goes_through_in_order_and_no_queue_outgrows_the_frame_sets_in_flight() {
    for in_flight in [1, 3] {
        // A consumer far slower than the stages (a slow logger): the stages wait, nothing piles up.
        // 200 ms a frame set: at 60 ms, on two cores shared with two other runs, the stages were
        // the slower and the output queue never filled (2026-11-28).
        let (results, outcome) = run(setup(Path::new(CUT_SMALL), in_flight, false, 1), Duration::from_millis(200));
        assert!(outcome.error.is_none(), "{:?}", outcome.error);
        assert_eq!(outcome.read.read, 9);
        assert_eq!(outcome.read.dropped, 0);
        let frames: Vec<u64> = results.iter().map(|w| w.frame).collect();
        assert_eq!(frames, (0..9).collect::<Vec<_>>());
        assert!(outcome.queue_max.iter().all(|&q| q <= in_flight), "in flight {in_flight}: {:?}", outcome.queue_max);
        // The output queue filled up behind the slow consumer, to its bound and no further.
        assert_eq!(outcome.queue_max[3], in_flight, "{:?}", outcome.queue_max);
        for w in &results {
            let finished = w.finished.expect("its cut surface was done");
            assert!(finished >= w.admitted && w.admitted >= w.captured);
            assert!(w.latency() > Duration::ZERO && w.tissue.is_some());
        }
    }
}

#[test]
fn live_pacing_faster_than_the_stages_drops_the_oldest_counts_it_and_keeps_the_queues_bounded() {
    // cut-small captured at 1000 fps (a millisecond between frame sets, far less than a frame
    // set takes here): replayed four times, paced.
    let dir = tempfile::tempdir().expect("tempdir");
    copy_dir(Path::new(CUT_SMALL), dir.path());
    let csv = std::fs::read_to_string(dir.path().join("frames.csv")).expect("frames.csv");
    let mut fast = String::from("frame,camera,timestamp_ns\n");
    for line in csv.lines().skip(1) {
        let mut cols = line.split(',');
        let (frame, camera) = (cols.next().expect("frame"), cols.next().expect("camera"));
        let f: i64 = frame.parse().expect("a frame number");
        fast.push_str(&format!("{frame},{camera},{}\n", 1_000_000_000 + f * 1_000_000));
    }
    std::fs::write(dir.path().join("frames.csv"), fast).expect("written");
    let toml = std::fs::read_to_string(dir.path().join("dataset.toml")).expect("dataset.toml");
    std::fs::write(dir.path().join("dataset.toml"), toml.replace("fps = 4.0", "fps = 1000.0")).expect("written");

    let in_flight = 1;
    let (results, outcome) = run(setup(dir.path(), in_flight, true, 4), Duration::ZERO);
    assert!(outcome.error.is_none(), "{:?}", outcome.error);
    assert_eq!(outcome.read.read, 36);
    let processed = results.len() as u64;
    assert!(outcome.read.dropped > 0, "nothing dropped at 1000 fps");
    assert_eq!(processed + outcome.read.dropped, 36, "every frame set read is processed or counted as dropped");
    assert!(processed >= 2, "the first and the newest get through: {processed}");
    assert!(outcome.queue_max.iter().all(|&q| q <= in_flight), "{:?}", outcome.queue_max);
    // The last frame set read is never the one dropped: it is the newest.
    assert_eq!(results.last().map(|w| (w.pass, w.frame)), Some((3, 8)));
}

fn copy_dir(from: &Path, to: &Path) {
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            std::fs::create_dir_all(&target).expect("mkdir");
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

/// The hull's meshes (and the scalpel's grid, which only they use) are made for the frame sets
/// the caller logs (`masks_every`, on the frame timeline across passes) and draws (`mesh_frames`,
/// the first pass); the hand's grid, which pushes the tissue, for every frame set.
#[test]
fn the_hull_meshes_are_made_only_for_the_frame_sets_the_caller_uses() {
    let mut setup = setup(Path::new(CUT_SMALL), 1, false, 2);
    setup.masks_every = Some(4);
    setup.mesh_frames = vec![5];
    let (results, outcome) = run(setup, Duration::ZERO);
    assert!(outcome.error.is_none(), "{:?}", outcome.error);
    assert_eq!(results.len(), 18);
    for w in &results {
        // Nine frames a pass: pass 1's frame f is 9 + f on the timeline.
        let wanted = (w.frame + 9 * w.pass).is_multiple_of(4) || (w.pass == 0 && w.frame == 5);
        for (l, name, grid, mesh) in &w.grids {
            let (pass, frame) = (w.pass, w.frame);
            assert_eq!(mesh.is_some(), wanted, "{name} mesh, pass {pass} frame {frame}");
            let hand = *l == hullcut_dataset::label::HAND;
            assert_eq!(grid.is_some(), wanted || hand, "{name} grid, pass {pass} frame {frame}");
        }
    }
}
