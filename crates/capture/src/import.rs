//! A lab's videos in: one video file per camera (any container OpenCV decodes) made into a dataset
//! in hullcut's format, frame sets paired by the videos' timestamps.
//!
//! Each video's frames are stamped with its media time (`CAP_PROP_POS_MSEC`) plus the camera's
//! offset (a camera started late by 12 ms has offset −0.012 s against the others) plus the
//! recording's start time; the [`Synchronizer`](crate::Synchronizer) pairs them into frame sets within half a frame
//! period, waiting for every camera (a lossless replay). What it could not pair is counted per
//! camera: frames no set took (late, a second frame in one period, out of order) and sets that lack
//! a camera (its video ended early, or it dropped a frame). Frame sets are numbered from 0 and
//! written with their images' own timestamps in `frames.csv`.

use std::path::{Path, PathBuf};

use hullcut_dataset::{DatasetMeta, DatasetWriter, FORMAT_VERSION, MAX_FRAME_COUNT};
use hullcut_rig::Rig;
use serde::{Deserialize, Serialize};

use crate::error::CaptureError;
use crate::source::{Capture, CaptureParams, Clock, SourceConfig, SourceSpec};
use crate::sync::{SyncParams, SyncStats};

/// One camera's video.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoInput {
    /// The rig camera it shows (by name).
    pub camera: String,
    /// The video file.
    pub path: PathBuf,
    /// Added to its media time, seconds.
    pub offset_s: f64,
}

/// Settings of [`import_videos`].
#[derive(Debug, Clone, PartialEq)]
pub struct ImportParams {
    /// Frame rate of the recording; `None` takes the first video's stated rate.
    pub fps: Option<f64>,
    /// Time of media time 0, nanoseconds since the epoch (the recording's start).
    pub start_ns: i64,
    /// Stop after this many frame sets.
    pub max_frame_sets: Option<u64>,
    /// The dataset's name.
    pub name: String,
    /// Replace an existing dataset at the output.
    pub force: bool,
}

/// What [`import_videos`] wrote and could not pair.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImportSummary {
    /// The dataset.
    pub path: PathBuf,
    /// Frame sets written.
    pub frame_sets: u64,
    /// The frame rate used.
    pub fps: f64,
    /// Whether it came from the first video's container (else given).
    pub fps_from_video: bool,
    /// Images written, per camera (rig order).
    pub images: Vec<u64>,
    /// Frames decoded, per camera.
    pub decoded: Vec<u64>,
    /// The synchronizer's counters: missing views per camera, frames it dropped and why.
    pub sync: SyncStats,
    /// Cameras whose video ended before the others' (name, frames it had).
    pub ended_early: Vec<(String, u64)>,
}

/// Reads the videos (one per rig camera, any order) into a dataset at `out`; `progress` is called
/// once per frame set written. See the module docs.
pub fn import_videos(
    rig: &Rig,
    inputs: &[VideoInput],
    out: &Path,
    params: &ImportParams,
    progress: &dyn Fn(u64),
) -> Result<ImportSummary, CaptureError> {
    let param = |name: &'static str, message: String| CaptureError::Param { name, message };
    // One video per rig camera, in rig order.
    let mut ordered: Vec<Option<&VideoInput>> = vec![None; rig.len()];
    for input in inputs {
        let Some(k) = rig.index_of(&input.camera) else {
            let names: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
            return Err(param(
                "videos",
                format!("`{}` is not a camera of the rig ({})", input.camera, names.join(", ")),
            ));
        };
        if ordered[k].is_some() {
            return Err(param("videos", format!("two videos for camera `{}`", input.camera)));
        }
        if !(input.offset_s.is_finite() && input.offset_s.abs() < 3600.0) {
            return Err(param(
                "offset",
                format!("camera `{}`: {} s is not an offset under an hour", input.camera, input.offset_s),
            ));
        }
        ordered[k] = Some(input);
    }
    if let Some(k) = ordered.iter().position(Option::is_none) {
        return Err(param("videos", format!("no video for camera `{}`", rig.cameras[k].name)));
    }
    let configs: Vec<SourceConfig> = ordered
        .iter()
        .flatten()
        .enumerate()
        .map(|(k, v)| {
            let offset = params.start_ns.saturating_add((v.offset_s * 1e9).round() as i64);
            SourceConfig::new(k, SourceSpec::File(v.path.clone())).with_clock(Clock::Device).with_offset(offset)
        })
        .collect();
    let (fps, fps_from_video) = match params.fps {
        Some(fps) => (fps, false),
        None => (
            configs[0].stated_fps()?.ok_or_else(|| {
                param(
                    "fps",
                    format!(
                        "{} states no frame rate: give one",
                        ordered[0].map_or(Path::new(""), |v| &v.path).display()
                    ),
                )
            })?,
            true,
        ),
    };
    if !(fps.is_finite() && fps > 0.0 && fps <= 10_000.0) {
        return Err(param("fps", format!("{fps} is not a frame rate in (0, 10000]")));
    }
    let meta = DatasetMeta {
        format_version: FORMAT_VERSION,
        name: params.name.clone(),
        fps,
        frame_count: MAX_FRAME_COUNT,
        cameras: rig.cameras.iter().map(|c| c.name.clone()).collect(),
        workspace: None,
    };
    let mut writer = DatasetWriter::create(out, meta, rig, params.force)?;
    let capture = Capture::open(configs, &CaptureParams::default())?;
    let mut synced = capture.synchronized(SyncParams::replay(rig.len(), fps))?;
    let mut frame_sets = 0u64;
    let mut images = vec![0u64; rig.len()];
    let limit = params.max_frame_sets.unwrap_or(MAX_FRAME_COUNT).min(MAX_FRAME_COUNT);
    for set in synced.by_ref() {
        if frame_sets >= limit {
            break;
        }
        for view in set.views.iter().flatten() {
            writer.write_image(frame_sets, view.camera, &view.image, view.timestamp_ns)?;
            images[view.camera] += 1;
        }
        frame_sets += 1;
        progress(frame_sets);
    }
    if let Some(f) = synced.failures().first() {
        return Err(param(
            "videos",
            format!("camera `{}` failed after {} frames: {}", rig.cameras[f.camera].name, f.frames, f.error),
        ));
    }
    if frame_sets == 0 {
        return Err(param("videos", "no frame set could be paired from the videos".to_owned()));
    }
    writer.set_frame_count(frame_sets)?;
    let decoded = synced.capture_stats().frames_decoded;
    let longest = decoded.iter().copied().max().unwrap_or(0);
    let ended_early = rig
        .cameras
        .iter()
        .zip(&decoded)
        .filter(|&(_, &n)| n + 1 < longest)
        .map(|(c, &n)| (c.name.clone(), n))
        .collect();
    let sync = synced.stats().clone();
    drop(synced);
    let path = writer.finish()?;
    Ok(ImportSummary { path, frame_sets, fps, fps_from_video, images, decoded, sync, ended_early })
}
