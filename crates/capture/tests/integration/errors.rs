//! Failures are errors or events that name the camera and file, never panics.

use std::path::PathBuf;

use anyhow::Result;
use hullcut_capture::{
    Capture, CaptureError, CaptureParams, FrameSource, SourceConfig, SourceEvent, SourceSpec, write_video,
};
use image::RgbImage;

use crate::common::render_frame;

fn drain(capture: &Capture) -> (usize, Vec<SourceEvent>) {
    let mut frames = 0;
    let mut ends = Vec::new();
    while ends.len() < capture.cameras() {
        match capture.events().recv() {
            Ok(SourceEvent::Frame(_)) => frames += 1,
            Ok(e) => ends.push(e),
            Err(_) => break,
        }
    }
    (frames, ends)
}

#[test]
fn missing_video_file_is_an_error_naming_camera_and_file() {
    let path = PathBuf::from("/nonexistent/hullcut/cam4.avi");
    let err = FrameSource::open(SourceConfig::new(4, SourceSpec::File(path.clone()))).expect_err("missing file");
    assert!(matches!(&err, CaptureError::MissingFile { camera: 4, path: p } if *p == path), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("camera 4") && msg.contains("/nonexistent/hullcut/cam4.avi"), "{msg}");

    // Capture::open fails before starting any thread.
    let ok = SourceConfig::new(0, SourceSpec::Pattern("/nonexistent/%06d.png".into()));
    let err = Capture::open(vec![ok], &CaptureParams::default()).expect_err("missing sequence");
    assert!(err.to_string().contains("camera 0"), "{err}");
}

#[test]
fn file_that_is_not_a_video_is_refused_or_ends_empty() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let path = tmp.path().join("junk.avi");
    std::fs::write(&path, b"RIFF\0\0\0\0AVI this is not a video at all")?;
    match FrameSource::open(SourceConfig::new(2, SourceSpec::File(path.clone()))) {
        Err(e) => assert!(e.to_string().contains("camera 2") && e.to_string().contains("junk.avi"), "{e}"),
        // Some backends open anything and then deliver nothing: that is a normal, empty end.
        Ok(mut source) => assert!(source.next_frame()?.is_none()),
    }
    Ok(())
}

#[test]
fn video_that_ends_early_is_a_counted_end() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let path = tmp.path().join("short.avi");
    let frames: Vec<RgbImage> = (0..5).map(|k| render_frame(160, 120, 0, k, 1.0).0).collect();
    write_video(&path, 30.0, &frames)?;
    // The replay list expects 20 frames; the video has 5.
    let list: Vec<i64> = (0..20).map(|k| k * 1_000).collect();
    let config = SourceConfig::new(3, SourceSpec::File(path.clone())).with_timestamps(list);
    let capture = Capture::open(vec![config], &CaptureParams::default())?;
    let (n, ends) = drain(&capture);
    assert_eq!(n, 5);
    assert!(matches!(ends.as_slice(), [SourceEvent::Ended { camera: 3, frames: 5 }]), "{ends:?}");

    // A replay list shorter than the video fails that camera, after the frames it could stamp.
    let config = SourceConfig::new(1, SourceSpec::File(path)).with_timestamps(vec![0, 1, 2]);
    let capture = Capture::open(vec![config], &CaptureParams::default())?;
    let (n, ends) = drain(&capture);
    assert_eq!(n, 3);
    match ends.as_slice() {
        [SourceEvent::Failed { camera: 1, frames: 3, error }] => {
            assert!(matches!(error, CaptureError::TimestampsExhausted { camera: 1, sequence: 3, count: 3 }), "{error}");
        }
        other => panic!("{other:?}"),
    }
    Ok(())
}

#[test]
fn frame_limit_and_drop_policy_end_cleanly() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let path = tmp.path().join("clip.avi");
    let frames: Vec<RgbImage> = (0..12).map(|k| render_frame(160, 120, 0, k, 1.0).0).collect();
    write_video(&path, 30.0, &frames)?;
    let config = SourceConfig { max_frames: Some(7), ..SourceConfig::new(0, SourceSpec::File(path.clone())) };
    let capture = Capture::open(vec![config], &CaptureParams::default())?;
    let (n, ends) = drain(&capture);
    assert_eq!(n, 7);
    assert!(matches!(ends.as_slice(), [SourceEvent::Ended { camera: 0, frames: 7 }]), "{ends:?}");

    // A rendezvous channel with the drop policy: the reader never waits for the consumer, counts
    // every frame it could not hand over, and still reports its end (which is never dropped).
    let params = CaptureParams { queue_capacity: 0, policy: hullcut_capture::QueuePolicy::DropNewest };
    let capture = Capture::open(vec![SourceConfig::new(0, SourceSpec::File(path))], &params)?;
    let mut received = 0;
    let end = loop {
        match capture.events().recv()? {
            SourceEvent::Frame(_) => received += 1,
            other => break other,
        }
    };
    assert!(matches!(end, SourceEvent::Ended { camera: 0, frames: 12 }), "{end:?}");
    assert_eq!(received + capture.stats().queue_dropped[0], 12);

    // Dropping a capture with readers blocked on a full queue stops and joins them.
    let capture = Capture::open(
        vec![SourceConfig::new(0, SourceSpec::File(tmp.path().join("clip.avi")))],
        &CaptureParams { queue_capacity: 1, ..CaptureParams::default() },
    )?;
    drop(capture);
    Ok(())
}

#[test]
fn writing_video_refuses_bad_input() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let a = RgbImage::new(64, 48);
    let b = RgbImage::new(32, 24);
    let err = write_video(tmp.path().join("x.avi"), 30.0, [&a, &b]).expect_err("size change");
    assert!(err.to_string().contains("x.avi") && err.to_string().contains("frame 1"), "{err}");
    assert!(write_video(tmp.path().join("x.webm"), 30.0, [&a]).is_err(), "unknown extension");
    assert!(write_video(tmp.path().join("y.avi"), 0.0, [&a]).is_err(), "zero fps");
    assert_eq!(write_video(tmp.path().join("z.avi"), 30.0, std::iter::empty())?, 0);
    Ok(())
}
