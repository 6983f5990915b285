//! The real decode path: a six-camera dataset written as PNGs, exported to MJPG videos with
//! OpenCV's VideoWriter, read back through `SourceSpec::File` as six cameras (one with dropped
//! frames, one whose video ends early) and synchronized into frame sets.

use std::path::Path;

use anyhow::{Context as _, Result};
use hullcut_capture::{
    Capture, CaptureParams, ClockKind, FrameSource, SourceConfig, SourceEvent, SourceSpec, SyncParams,
    export_camera_video, write_video,
};
use hullcut_dataset::{Dataset, DatasetMeta, DatasetWriter, FORMAT_VERSION, FrameSet};
use hullcut_rig::{Rig, default_rig};
use image::RgbImage;

use crate::common::{PERIOD_NS, mean_abs_diff, render_frame, uniform};

const W: u32 = 320;
const H: u32 = 240;
const CAMERAS: usize = 6;
const FRAMES: u64 = 20;
/// Frames camera 3 dropped during "capture" (absent from the dataset).
const DROPPED_CAM3: [u64; 3] = [5, 6, 13];
/// Camera 5's video holds only its first 15 frames.
const CAM5_FRAMES: usize = 15;

/// Worst mean absolute difference per channel value allowed between a decoded MJPG frame and its
/// original. Measured: 2.25 mean, 2.49 worst over the 112 views (OpenCV's MJPEG encoder, quality
/// 95; FFmpeg's MJPEG gave 2.45 / 2.62). Most of it is the sensor noise itself: σ = 2 noise is
/// what JPEG quantizes away first, and removing all of it would cost E|N(0, 2)| = 1.6 levels;
/// the 5-pixel weave and 4:2:0 chroma subsampling at the blob and bar edges add the rest. 3.0
/// leaves 20 % for another libjpeg build. A mean difference alone cannot tell a neighbouring
/// frame (mostly the same static texture), so each view must also be closer to its own original
/// than to the neighbouring frames' originals.
const MJPG_MEAN_ABS_DIFF_MAX: f64 = 3.0;

fn rig() -> Rig {
    let full = default_rig();
    Rig::new(full.cameras.iter().map(|c| c.scaled(0.5)).collect(), full.world_frame.clone())
}

/// Capture time of (frame, camera): 30 fps with ±2 ms jitter per camera.
fn timestamp(frame: u64, camera: usize) -> i64 {
    let jitter = ((uniform(frame * 31 + camera as u64) * 2.0 - 1.0) * 2e6) as i64;
    1_700_000_000_000_000_000 + frame as i64 * PERIOD_NS + jitter
}

/// Writes the dataset; returns the originals by camera and frame.
fn write_dataset(dir: &Path) -> Result<Vec<Vec<Option<RgbImage>>>> {
    let rig = rig();
    let meta = DatasetMeta {
        format_version: FORMAT_VERSION,
        name: "capture-decode".into(),
        fps: 30.0,
        frame_count: FRAMES,
        cameras: rig.cameras.iter().map(|c| c.name.clone()).collect(),
        workspace: None,
    };
    let writer = DatasetWriter::create(dir, meta, &rig, false)?;
    let mut originals = vec![vec![None; FRAMES as usize]; CAMERAS];
    for frame in 0..FRAMES {
        for camera in 0..CAMERAS {
            if camera == 3 && DROPPED_CAM3.contains(&frame) {
                continue;
            }
            let (image, _) = render_frame(W, H, camera, frame, 1.0);
            writer.write_image(frame, camera, &image, timestamp(frame, camera))?;
            originals[camera][frame as usize] = Some(image);
        }
    }
    writer.finish()?;
    Ok(originals)
}

#[test]
fn six_videos_replay_into_synchronized_frame_sets() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let ds_dir = tmp.path().join("dataset");
    let originals = write_dataset(&ds_dir)?;
    let dataset = Dataset::open(&ds_dir)?;

    let mut configs = Vec::new();
    for camera in 0..CAMERAS {
        let path = tmp.path().join(format!("cam{camera}.avi"));
        let exported = export_camera_video(&dataset, camera, &path)?;
        let expected: Vec<u64> = (0..FRAMES).filter(|f| !(camera == 3 && DROPPED_CAM3.contains(f))).collect();
        assert_eq!(exported.frames, expected, "camera {camera}: frames in the video");
        let timestamps = exported.timestamps_ns.clone();
        if camera == 5 {
            // The video ends early; its timestamp list does not (a replay list may be longer).
            let frames: Vec<&RgbImage> = originals[5].iter().flatten().take(CAM5_FRAMES).collect();
            assert_eq!(write_video(&path, 30.0, frames)?, CAM5_FRAMES as u64);
        }
        configs.push(SourceConfig::new(camera, SourceSpec::File(path)).with_timestamps(timestamps));
    }

    let capture = Capture::open(configs, &CaptureParams { queue_capacity: 4, ..CaptureParams::default() })?;
    let mut synced = capture.synchronized(SyncParams::replay(CAMERAS, dataset.meta().fps))?;
    let sets: Vec<FrameSet> = synced.by_ref().collect();
    assert!(synced.failures().is_empty(), "{:?}", synced.failures());

    let capture_stats = synced.capture_stats();
    assert_eq!(capture_stats.frames_decoded, vec![20, 20, 20, 17, 20, CAM5_FRAMES as u64]);
    assert_eq!(capture_stats.queue_dropped, vec![0; CAMERAS]);

    let stats = synced.stats().clone();
    assert_eq!(sets.len(), FRAMES as usize, "one set per dataset frame: {stats:?}");
    assert_eq!(stats.missing_views, vec![0, 0, 0, 3, 0, (FRAMES as usize - CAM5_FRAMES) as u64]);
    assert_eq!(stats.dropped(), vec![0; CAMERAS], "replay drops nothing");
    // Frames with a view missing: 5, 6, 13 (camera 3) and 15..20 (camera 5).
    assert_eq!(stats.complete_sets, FRAMES - 3 - 5);

    let mut worst: f64 = 0.0;
    let mut sum = 0.0;
    let mut n = 0;
    for set in &sets {
        let frame = set.frame;
        for camera in 0..CAMERAS {
            let original = originals[camera][frame as usize].as_ref().filter(|_| !(camera == 5 && frame >= 15));
            match (&set.views[camera], original) {
                (None, None) => {}
                (Some(view), Some(original)) => {
                    assert_eq!(view.timestamp_ns, timestamp(frame, camera), "frame {frame} camera {camera}");
                    let d = mean_abs_diff(&view.image, original);
                    for other in [frame.wrapping_sub(1), frame + 1] {
                        if let Some(Some(o)) = originals[camera].get(other as usize) {
                            let d_other = mean_abs_diff(&view.image, o);
                            assert!(d < d_other, "frame {frame} camera {camera}: {d} vs frame {other}: {d_other}");
                        }
                    }
                    worst = worst.max(d);
                    sum += d;
                    n += 1;
                }
                (v, o) => panic!("frame {frame} camera {camera}: view {} original {}", v.is_some(), o.is_some()),
            }
        }
        assert_eq!(set.timestamp_ns, FrameSet::median_timestamp(&set.views));
    }
    println!("MJPG round trip over {n} views: mean abs diff mean {:.3}, worst {worst:.3} levels", sum / n as f64);
    assert!(worst < MJPG_MEAN_ABS_DIFF_MAX, "worst mean abs diff {worst:.3}");
    Ok(())
}

#[test]
fn video_media_time_is_the_default_clock_for_files() -> Result<()> {
    // Without a replay list a file is stamped with its media time (CAP_PROP_POS_MSEC): frame k of
    // a 25 fps video at k · 40 ms. FFmpeg reports it in whole milliseconds for AVI, so ±1 ms.
    let tmp = tempfile::tempdir()?;
    let path = tmp.path().join("clip.avi");
    let frames: Vec<RgbImage> = (0..6).map(|k| render_frame(W, H, 0, k, 1.0).0).collect();
    write_video(&path, 25.0, &frames)?;
    let mut source = FrameSource::open(SourceConfig::new(0, SourceSpec::File(path)))?;
    assert_eq!(source.clock(), ClockKind::Device);
    let mut k = 0i64;
    while let Some(f) = source.next_frame()? {
        assert_eq!(f.sequence, k as u64);
        let expected = k * 40_000_000;
        assert!(
            (f.timestamp_ns - expected).abs() <= 1_000_000,
            "frame {k}: {} ns, expected {expected}",
            f.timestamp_ns
        );
        k += 1;
    }
    assert_eq!(k, 6);
    Ok(())
}

#[test]
fn image_sequence_pattern_is_a_camera() -> Result<()> {
    // PNG is lossless, so the frames come back bit-exact, in order, stamped at the nominal rate.
    let tmp = tempfile::tempdir()?;
    let frames: Vec<RgbImage> = (0..8).map(|k| render_frame(W, H, 1, k, 1.0).0).collect();
    for (k, f) in frames.iter().enumerate() {
        f.save(tmp.path().join(format!("{k:06}.png")))?;
    }
    let pattern = tmp.path().join("%06d.png").to_str().context("UTF-8 temp path")?.to_owned();
    let capture = Capture::open(vec![SourceConfig::new(1, SourceSpec::Pattern(pattern))], &CaptureParams::default())?;
    let mut got = Vec::new();
    loop {
        match capture.events().recv()? {
            SourceEvent::Frame(f) => got.push(f),
            SourceEvent::Ended { camera, frames } => {
                assert_eq!((camera, frames), (1, 8));
                break;
            }
            SourceEvent::Failed { error, .. } => return Err(error.into()),
        }
    }
    assert_eq!(got.len(), 8);
    for (k, f) in got.iter().enumerate() {
        assert_eq!(f.camera, 1);
        assert_eq!(f.sequence, k as u64);
        assert!(f.image == frames[k], "frame {k} differs");
        // Clock::Auto stamps an image sequence at a nominal 30 frames per second.
        assert_eq!(f.timestamp_ns, (k as f64 * 1e9 / 30.0).round() as i64);
    }
    Ok(())
}
