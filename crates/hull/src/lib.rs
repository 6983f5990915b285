//! Visual hull of hand and scalpel from calibrated silhouettes.
//!
//! Entry points:
//! - [`Silhouette`]: a view's label mask as summed-area tables (label counts in any rectangle in
//!   four lookups); [`silhouettes`] builds them for a rig, checking sizes.
//! - [`WorkingVolume`]: the box carving covers, given (command line, dataset) or derived from the
//!   rig ([`seen_volume`]: the space at least three cameras see), with its source for reports.
//! - [`carve`] with [`HullParams`]: octree carving where each cell is tested against its whole
//!   projected footprint in every view, k-of-N carving, occlusion-aware labels, cells seen by too
//!   few views dropped; [`carve_within`] carves only inside given cells (a finer hull inside a
//!   coarser one, or the neighbourhood of the last frame's hull); both return an
//!   [`Occupancy`] (kept cells with labels, counters, among them which view disagreed with all the
//!   others: [`CarveStats::lone_refutations`]).
//! - [`shadow`]: possible cast shadows resolved by the hull (kept only where some view sees sure
//!   foreground).
//! - [`DenseGrid`]: one label's occupancy on the leaf grid and its closed surface
//!   ([`DenseGrid::surface`], surface nets).
//!
//! On the CPU, rayon runs across the top-level cells. Feature `gpu`: [`gpu::GpuCarver`], the same
//! carving on wgpu, one dispatch per octree level.
#![warn(missing_docs)]

pub mod accuracy;
mod carve;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod shadow;
mod silhouette;
mod surface;
mod volume;

pub use carve::{
    Aabb, CarveStats, Cell, Footprint, HullParams, MAX_DEPTH, MAX_REFINE_LEVELS, Occupancy, carve, carve_within,
    footprint, footprint_counts, refine_cells, refine_label, relabel,
};
pub use silhouette::{Counts, Silhouette};
pub use surface::{DenseGrid, is_watertight};
pub use volume::{SeenVolume, VolumeSource, WorkingVolume, seen_volume};

use hullcut_rig::Rig;
use image::GrayImage;
use rayon::prelude::*;

/// Why carving could not run.
#[derive(Debug, thiserror::Error)]
pub enum HullError {
    /// Bad parameters.
    #[error("visual hull: {0}")]
    Params(String),
    /// The working volume is unusable (empty, not finite, seen by too few cameras).
    #[error("working volume: {0}")]
    Volume(String),
    /// Fewer views than the carving rule needs.
    #[error("visual hull: {present} views present, the k-of-N rule needs at least {needed}")]
    TooFewViews {
        /// Views with a mask.
        present: usize,
        /// `carve_votes`.
        needed: usize,
    },
    /// A mask whose size is not its camera's.
    #[error("visual hull: camera {camera}: mask is {found_w}x{found_h}, the rig says {w}x{h}")]
    MaskSize {
        /// Camera name.
        camera: String,
        /// Rig width.
        w: u32,
        /// Rig height.
        h: u32,
        /// Mask width.
        found_w: u32,
        /// Mask height.
        found_h: u32,
    },
    /// The GPU carver failed (limits, a lost device).
    #[error("visual hull on the GPU: {0}")]
    Gpu(String),
}

/// Summed-area tables for each camera's mask (`None` for a missing view), built on the rayon pool.
pub fn silhouettes(rig: &Rig, masks: &[Option<&GrayImage>]) -> Result<Vec<Option<Silhouette>>, HullError> {
    rig.cameras
        .par_iter()
        .enumerate()
        .map(|(k, cam)| {
            let Some(mask) = masks.get(k).copied().flatten() else { return Ok(None) };
            check_mask_size(cam, mask)?;
            Ok(Some(Silhouette::new(cam, mask)))
        })
        .collect()
}

/// [`Silhouette::direct`] for each camera's mask (`None` for a missing view; masks past the
/// rig's cameras are dropped): for masks asked about few, small rectangles.
pub fn direct_silhouettes(rig: &Rig, mut masks: Vec<Option<GrayImage>>) -> Result<Vec<Option<Silhouette>>, HullError> {
    masks.resize(rig.cameras.len(), None);
    rig.cameras
        .par_iter()
        .zip(masks.into_par_iter())
        .map(|(cam, mask)| {
            let Some(mask) = mask else { return Ok(None) };
            check_mask_size(cam, &mask)?;
            Ok(Some(Silhouette::direct(cam, mask)))
        })
        .collect()
}

/// A mask must have its camera's size.
fn check_mask_size(cam: &hullcut_rig::Camera, mask: &GrayImage) -> Result<(), HullError> {
    if mask.dimensions() != (cam.width, cam.height) {
        return Err(HullError::MaskSize {
            camera: cam.name.clone(),
            w: cam.width,
            h: cam.height,
            found_w: mask.width(),
            found_h: mask.height(),
        });
    }
    Ok(())
}
