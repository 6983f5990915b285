//! The synchronizer's policy on jittered, dropped, delayed and reordered frames (pure logic).

use hullcut_capture::{CapturedFrame, SyncParams, SyncStats, Synchronizer};
use hullcut_dataset::FrameSet;
use image::RgbImage;

use crate::common::{PERIOD_NS, uniform};

/// A 1×1 frame whose pixel records its true frame number and camera.
fn frame(camera: usize, truth: u64, timestamp_ns: i64) -> CapturedFrame {
    let px = [(truth % 256) as u8, (truth / 256) as u8, camera as u8];
    CapturedFrame { camera, sequence: truth, timestamp_ns, image: RgbImage::from_raw(1, 1, px.to_vec()).expect("1x1") }
}

fn truth_of(set: &FrameSet, camera: usize) -> Option<u64> {
    set.views[camera].as_ref().map(|v| {
        let p = v.image.get_pixel(0, 0).0;
        assert_eq!(usize::from(p[2]), camera, "view in the wrong camera slot");
        u64::from(p[0]) + 256 * u64::from(p[1])
    })
}

/// One generated capture: per camera, (true frame, timestamp, arrival time) in stream order.
struct Recording {
    frames: Vec<Vec<(u64, i64, i64)>>,
    dropped: Vec<Vec<bool>>,
}

/// `n` frames from `cameras` cameras at 30 fps: timestamp jitter uniform in ±`jitter_ns`, each
/// frame dropped with probability `drop_p` (never all cameras of one frame), arrival = timestamp +
/// latency uniform in 0..`latency_ns`, plus `stall_ns` for camera 2's frames 40..50.
fn record(cameras: usize, n: u64, jitter_ns: i64, drop_p: f64, latency_ns: i64, stall_ns: i64, seed: u64) -> Recording {
    let mut frames = vec![Vec::new(); cameras];
    let mut dropped = vec![vec![false; n as usize]; cameras];
    for k in 0..n {
        let keep: Vec<bool> = (0..cameras).map(|c| uniform(seed ^ (k * 977 + c as u64 * 7 + 1)) >= drop_p).collect();
        let keep = if keep.iter().any(|&b| b) { keep } else { vec![true; cameras] };
        for c in 0..cameras {
            if !keep[c] {
                dropped[c][k as usize] = true;
                continue;
            }
            let key = seed ^ (k << 20) ^ (c as u64) << 8;
            let jitter = ((uniform(key ^ 0x11) * 2.0 - 1.0) * jitter_ns as f64) as i64;
            let t = 1_000_000_000 + k as i64 * PERIOD_NS + jitter;
            let stall = if c == 2 && (40..50).contains(&k) { stall_ns } else { 0 };
            let arrival = t + (uniform(key ^ 0x22) * latency_ns as f64) as i64 + stall;
            frames[c].push((k, t, arrival));
        }
    }
    Recording { frames, dropped }
}

/// Feeds the frames in arrival order (each camera's own order kept, as one reader thread per
/// camera guarantees) and collects the sets, finishing at the end.
fn run(rec: &Recording, params: SyncParams) -> (Vec<FrameSet>, SyncStats) {
    let mut events: Vec<(i64, usize, u64, i64)> = Vec::new();
    for (c, fs) in rec.frames.iter().enumerate() {
        let mut last_arrival = i64::MIN;
        for &(k, t, a) in fs {
            last_arrival = last_arrival.max(a);
            events.push((last_arrival, c, k, t));
        }
    }
    events.sort_by_key(|&(a, c, k, _)| (a, k, c));
    let mut sync = Synchronizer::new(params).expect("valid params");
    let mut sets = Vec::new();
    for (_, c, k, t) in events {
        sync.push(frame(c, k, t)).expect("camera in range");
        while let Some(s) = sync.pop_ready() {
            sets.push(s);
        }
    }
    sync.finish();
    while let Some(s) = sync.pop_ready() {
        sets.push(s);
    }
    assert!(sync.is_done());
    (sets, sync.stats().clone())
}

/// Invariants of any run: sets numbered consecutively and ordered in time, views of one set
/// from one true frame, every received frame either in a set or counted as dropped, and
/// `missing_views` equal to the `None`s.
fn check_invariants(sets: &[FrameSet], stats: &SyncStats, cameras: usize) {
    assert_eq!(stats.sets_emitted, sets.len() as u64);
    for (i, s) in sets.iter().enumerate() {
        assert_eq!(s.frame, i as u64, "sets are numbered consecutively");
        let truths: Vec<u64> = (0..cameras).filter_map(|c| truth_of(s, c)).collect();
        assert!(!truths.is_empty(), "a set has at least one view");
        assert!(truths.iter().all(|&t| t == truths[0]), "set {i} mixes true frames {truths:?}");
        if i > 0 {
            assert!(s.timestamp_ns > sets[i - 1].timestamp_ns, "sets are in time order");
        }
    }
    for c in 0..cameras {
        let present = sets.iter().filter(|s| s.views[c].is_some()).count() as u64;
        let missing = sets.len() as u64 - present;
        assert_eq!(stats.missing_views[c], missing, "camera {c}: missing views");
        assert_eq!(stats.frames_received[c], present + stats.dropped()[c], "camera {c}: every frame accounted for");
    }
    assert_eq!(stats.complete_sets, sets.iter().filter(|s| s.present() == cameras).count() as u64);
}

#[test]
fn replay_with_jitter_and_drops_groups_every_frame_correctly() {
    // Jitter ±4 ms stays below a quarter period (8.3 ms), the documented bound for tolerance =
    // half a period; replay waits for every camera, so nothing may be late and every drop is
    // exactly one missing view.
    let cameras = 6;
    for seed in 1..=5u64 {
        let rec = record(cameras, 300, 4_000_000, 0.05, 30_000_000, 200_000_000, seed);
        let (sets, stats) = run(&rec, SyncParams::replay(cameras, 30.0));
        check_invariants(&sets, &stats, cameras);
        assert_eq!(sets.len(), 300, "one set per true frame");
        for (k, s) in sets.iter().enumerate() {
            for c in 0..cameras {
                assert_eq!(s.views[c].is_none(), rec.dropped[c][k], "seed {seed}, frame {k}, camera {c}");
            }
        }
        assert_eq!(stats.dropped().iter().sum::<u64>(), 0, "{stats:?}");
        for c in 0..cameras {
            assert_eq!(stats.missing_views[c], rec.dropped[c].iter().filter(|&&d| d).count() as u64);
        }
        assert!(stats.max_spread_ns <= 8_000_000, "spread {} ns", stats.max_spread_ns);
    }
}

#[test]
fn live_policy_drops_a_stalled_camera_frames_as_late_and_counts_them() {
    // Live: a camera that has not answered when another delivers a frame past the window is
    // missing. Camera 2 stalls 150 ms (4.5 periods) on frames 40..50 and then delivers its backlog,
    // so frames 40..49 and the few queued behind them arrive after their sets went out: each is a
    // missing view and a late drop. Latency spread 5 ms is well inside a period, so no other
    // camera may lose anything.
    let cameras = 6;
    let rec = record(cameras, 200, 2_000_000, 0.0, 5_000_000, 150_000_000, 9);
    let (sets, stats) = run(&rec, SyncParams::live(cameras, 30.0));
    check_invariants(&sets, &stats, cameras);
    assert_eq!(sets.len(), 200);
    let missing: Vec<usize> = (0..200).filter(|&k| sets[k].views[2].is_none()).collect();
    let (first, last) = (missing[0], missing[missing.len() - 1]);
    assert_eq!(first, 40);
    // The backlog drains within 4.5 periods of frame 49.
    assert!((49..=54).contains(&last), "{missing:?}");
    assert_eq!(missing.len(), last - first + 1, "one contiguous gap: {missing:?}");
    for s in &sets {
        for c in [0, 1, 3, 4, 5] {
            assert!(s.views[c].is_some(), "frame {} camera {c}", s.frame);
        }
    }
    assert_eq!(stats.late_dropped[2], missing.len() as u64);
    assert_eq!(stats.late_dropped.iter().sum::<u64>(), missing.len() as u64);
    assert!(stats.gave_up_waiting >= missing.len() as u64, "{stats:?}");
    assert_eq!(stats.complete_sets, 200 - missing.len() as u64);
}

#[test]
fn random_interleavings_keep_the_invariants() {
    // Any mix of drops, latency and stalls must keep the bookkeeping exact under both policies;
    // jitter stays within the documented bound, so no set may mix true frames either.
    for seed in 0..40u64 {
        let cameras = 1 + (seed % 6) as usize;
        let jitter = (uniform(seed ^ 1) * 8e6) as i64;
        let latency = (uniform(seed ^ 2) * 80e6) as i64;
        let rec =
            record(cameras, 120, jitter, uniform(seed ^ 3) * 0.3, latency, (uniform(seed ^ 4) * 3e8) as i64, seed);
        for params in [SyncParams::live(cameras, 30.0), SyncParams::replay(cameras, 30.0)] {
            let (sets, stats) = run(&rec, params);
            check_invariants(&sets, &stats, cameras);
        }
    }
}

#[test]
fn camera_that_ends_early_leaves_none_and_finish_flushes() {
    let mut sync = Synchronizer::new(SyncParams::replay(3, 30.0)).expect("params");
    for k in 0..10u64 {
        for c in 0..3 {
            if c == 1 && k >= 4 {
                continue;
            }
            sync.push(frame(c, k, k as i64 * PERIOD_NS)).expect("push");
        }
    }
    // Camera 1 has neither ended nor moved on: replay waits for it after frame 3.
    let mut sets = Vec::new();
    while let Some(s) = sync.pop_ready() {
        sets.push(s);
    }
    assert_eq!(sets.len(), 4, "sets 0..4 are complete, set 4 waits for camera 1");
    sync.end_camera(1).expect("camera 1 exists");
    while let Some(s) = sync.pop_ready() {
        sets.push(s);
    }
    // With camera 1 ended, every set is decided: the others' frames are all there.
    assert_eq!(sets.len(), 10);
    sync.finish();
    assert!(sync.pop_ready().is_none() && sync.is_done());
    assert!(sets[4..].iter().all(|s| s.views[1].is_none() && s.present() == 2));
    let st = sync.stats();
    assert_eq!(st.missing_views, vec![0, 6, 0]);
    assert_eq!(st.complete_sets, 4);
}

#[test]
fn silent_camera_is_bounded_by_the_backlog() {
    // Replay waits for a silent camera, but never holds more than max_pending frames of another.
    let params = SyncParams { max_pending: 4, ..SyncParams::replay(2, 30.0) };
    let mut sync = Synchronizer::new(params).expect("params");
    for k in 0..20u64 {
        sync.push(frame(0, k, k as i64 * PERIOD_NS)).expect("push");
    }
    let mut n = 0;
    while sync.pop_ready().is_some() {
        n += 1;
    }
    // Pushes 4..20 each make a fifth pending frame, which forces out the oldest set.
    assert_eq!(n, 16);
    assert_eq!(sync.stats().backlog_forced, 16);
    assert_eq!(sync.stats().missing_views[1], 16);
}

#[test]
fn out_of_order_surplus_late_and_unknown_frames_are_counted_not_kept() {
    let mut sync = Synchronizer::new(SyncParams::replay(2, 30.0)).expect("params");
    // Camera 1 delivers two frames inside set 0's window before camera 0 answers.
    sync.push(frame(1, 0, 1_000_000)).expect("push");
    sync.push(frame(1, 0, 2_000_000)).expect("push");
    sync.push(frame(0, 0, 0)).expect("push");
    assert!(sync.pop_ready().is_some_and(|s| s.present() == 2));
    sync.push(frame(0, 1, PERIOD_NS)).expect("push");
    sync.push(frame(0, 2, PERIOD_NS / 2)).expect("push"); // older than its predecessor
    sync.push(frame(1, 0, 3_000_000)).expect("push"); // set 0 is gone
    assert!(sync.push(frame(5, 0, 0)).is_err(), "camera 5 does not exist");
    sync.push(frame(1, 1, PERIOD_NS + 1)).expect("push");
    sync.finish();
    let mut n = 1;
    while sync.pop_ready().is_some() {
        n += 1;
    }
    let st = sync.stats();
    assert_eq!(n, 2);
    assert_eq!(st.complete_sets, 2);
    assert_eq!(st.surplus_dropped, vec![0, 1]);
    assert_eq!(st.out_of_order_dropped, vec![1, 0]);
    assert_eq!(st.late_dropped, vec![0, 1]);
    assert_eq!(st.frames_received, vec![3, 4]);
    let json = serde_json::to_value(st).expect("stats serialize");
    assert_eq!(json["complete_sets"], 2);
    assert_eq!(json["late_dropped"][1], 1);
}

#[test]
fn invalid_parameters_are_refused() {
    assert!(Synchronizer::new(SyncParams { cameras: 0, ..SyncParams::default() }).is_err());
    assert!(Synchronizer::new(SyncParams { tolerance_ns: -1, ..SyncParams::default() }).is_err());
}
