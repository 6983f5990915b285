//! Writes a whole synthetic recording as a dataset (DESIGN "Dataset format"), frames in parallel.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use hullcut_dataset::{DatasetMeta, DatasetWriter, FORMAT_VERSION};
use rayon::prelude::*;

use crate::{Scene, SynthError};

/// What a synthesis wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSummary {
    /// Where the dataset is.
    pub path: PathBuf,
    /// Frame sets.
    pub frames: u64,
    /// Camera images written.
    pub views: usize,
    /// Camera images dropped by the scene's drop policy.
    pub dropped_views: usize,
    /// Mean number of scalpel pixels per written view (how large the tool appears).
    pub mean_scalpel_pixels: f64,
    /// Mean number of hand pixels per written view.
    pub mean_hand_pixels: f64,
    /// Triangles skipped because they came too close to a camera (should be 0).
    pub skipped_triangles: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Renders every frame set of `scene` and writes the dataset to `out` (refused if it exists,
/// unless `force`). The dataset appears at `out` only once complete. `progress` is called once per
/// finished frame set, from worker threads.
pub fn synthesize(
    scene: &Scene,
    out: &Path,
    name: &str,
    force: bool,
    progress: &(dyn Fn() + Sync),
) -> Result<SynthSummary, SynthError> {
    let start = Instant::now();
    let config = scene.config();
    let rig = &config.rig;
    let meta = DatasetMeta {
        format_version: FORMAT_VERSION,
        name: name.to_owned(),
        fps: config.fps,
        frame_count: config.frames,
        cameras: rig.cameras.iter().map(|c| c.name.clone()).collect(),
        workspace: None,
    };
    let writer = DatasetWriter::create(out, meta, rig, force)?.with_compression(config.compression);
    writer.write_tool(&scene.scalpel().geometry)?;
    for camera in 0..rig.len() {
        for index in 0..config.background_frames {
            if let Some(image) = scene.render_background(camera, index) {
                writer.write_background(camera, index, &image)?;
            }
        }
    }
    let views = AtomicUsize::new(0);
    let dropped = AtomicUsize::new(0);
    let skipped = AtomicUsize::new(0);
    let scalpel_px = AtomicUsize::new(0);
    let hand_px = AtomicUsize::new(0);
    (0..config.frames).into_par_iter().try_for_each(|frame| -> Result<(), SynthError> {
        for camera in 0..rig.len() {
            let Some(view) = scene.render_view(frame, camera) else {
                dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            };
            writer.write_image(frame, camera, &view.image, view.timestamp_ns)?;
            writer.write_mask(frame, camera, &view.mask)?;
            if config.depth_maps {
                writer.write_depth(frame, camera, &view.depth)?;
            }
            views.fetch_add(1, Ordering::Relaxed);
            skipped.fetch_add(view.skipped_triangles, Ordering::Relaxed);
            let count = |l: u8| view.mask.as_raw().iter().filter(|&&v| v == l).count();
            scalpel_px.fetch_add(count(hullcut_dataset::label::SCALPEL), Ordering::Relaxed);
            hand_px.fetch_add(count(hullcut_dataset::label::HAND), Ordering::Relaxed);
        }
        writer.write_truth_pose(&scene.truth_pose(frame))?;
        if config.truth_meshes {
            for (label, mesh) in scene.truth_meshes(frame) {
                writer.write_truth_mesh(label, frame, &mesh)?;
            }
        }
        progress();
        Ok(())
    })?;
    let path = writer.finish()?;
    let views = views.into_inner();
    let per_view = |n: usize| if views == 0 { 0.0 } else { n as f64 / views as f64 };
    Ok(SynthSummary {
        path,
        frames: config.frames,
        views,
        dropped_views: dropped.into_inner(),
        mean_scalpel_pixels: per_view(scalpel_px.into_inner()),
        mean_hand_pixels: per_view(hand_px.into_inner()),
        skipped_triangles: skipped.into_inner(),
        seconds: start.elapsed().as_secs_f64(),
    })
}
