//! Label masks drawn later: the main job's loop needs a fitted frame set's hull and pose, not its
//! label masks, and those of the frame sets it only logs are drawn on the logging thread
//! ([`Labelling::defer_drawing`](crate::Labelling::defer_drawing)). Drawing the fitted tool into
//! six views and labelling them was half of such a frame set's segmentation (about 3 ms of 6 on
//! the built-in scene's recording; docs/benchmarks.md, "Logged labels drawn beside the loop").

use std::sync::Arc;

use hullcut_capture::segment::ColourLut;
use hullcut_dataset::FrameSet;
use hullcut_hull::Occupancy;
use hullcut_pose::{ToolDrawer, ToolRegion, ViewInput};
use hullcut_rig::Rig;
use image::GrayImage;
use nalgebra::Isometry3;

use crate::labelling::{images_of, sharpen_views, to_background};

/// A fitted frame set's label masks, not yet drawn: what its labelling saw, kept to draw them as
/// the labelling would have ([`PendingLabels::draw`]).
pub struct PendingLabels {
    pub(crate) drawer: ToolDrawer,
    pub(crate) rig: Arc<Rig>,
    /// The fitted tool.
    pub(crate) pose: Isometry3<f64>,
    /// Per view, the foreground the fit saw (with its hints).
    pub(crate) masks: Vec<Option<GrayImage>>,
    /// Per view, the possible shadows given back to the table (background unless the tool is
    /// drawn there).
    pub(crate) given_back: Vec<Vec<usize>>,
    /// The colours that sharpen a trusted fit's labels near the drawn tool, as they were then.
    pub(crate) sharpen: Option<Arc<ColourLut>>,
}

impl std::fmt::Debug for PendingLabels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PendingLabels")
            .field("views", &self.masks.iter().flatten().count())
            .field("sharpen", &self.sharpen.is_some())
            .finish_non_exhaustive()
    }
}

impl PendingLabels {
    /// The label masks of `set` (per view, rig order; `None` for a missing view), the same as
    /// its labelling would have drawn: `occupancy` is the hull it handed out with the frame set
    /// ([`crate::labelling::Labelled::occupancy`]).
    pub fn draw(self, set: &FrameSet, occupancy: &Occupancy) -> Vec<Option<GrayImage>> {
        let sharpen_with = self.sharpen.clone();
        let (mut masks, tool_regions) = self.draw_plain(occupancy);
        if let Some(lut) = &sharpen_with {
            sharpen_views(lut, &images_of(set), &mut masks, &tool_regions);
        }
        masks.resize(set.views.len(), None);
        masks
    }

    /// The label masks (per camera, rig order) before any colour sharpened them, and where the
    /// tool is drawn in each view.
    pub(crate) fn draw_plain(self, occupancy: &Occupancy) -> (Vec<Option<GrayImage>>, Vec<Option<ToolRegion>>) {
        let views: Vec<Option<ViewInput>> = self
            .rig
            .cameras
            .iter()
            .zip(&self.masks)
            .map(|(camera, m)| m.as_ref().map(|mask| ViewInput { camera, mask, image: None }))
            .collect();
        let drawn = self.drawer.draw(&views, occupancy, &self.pose, false);
        let mut masks = drawn.masks;
        to_background(&mut masks, &self.given_back, true);
        (masks, drawn.tool_regions)
    }
}
