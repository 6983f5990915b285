//! The calibration report: accuracy per camera, per camera pair and per image.

use serde::{Deserialize, Serialize};

use crate::Pattern;
use crate::refine::RefineSummary;

/// One camera's result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CameraReport {
    /// Camera name.
    pub name: String,
    /// Image width, pixels.
    pub image_width: u32,
    /// Image height, pixels.
    pub image_height: u32,
    /// Images of this camera.
    pub images: usize,
    /// Images in which the board was detected.
    pub views_detected: usize,
    /// RMS reprojection error of OpenCV's single-camera calibration, pixels.
    pub rms_intrinsic_px: f64,
    /// RMS reprojection error after joint refinement, pixels.
    pub rms_px: f64,
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
    /// Camera centre in the world frame, metres.
    pub centre: [f64; 3],
    /// Optical axis in the world frame (unit).
    pub viewing_direction: [f64; 3],
}

/// Two cameras that saw the board at the same time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PairReport {
    /// First camera.
    pub a: String,
    /// Second camera.
    pub b: String,
    /// Views both cameras saw.
    pub shared_views: usize,
    /// RMS reprojection error over both cameras' corners in the shared views, pixels.
    pub rms_px: f64,
    /// Distance between the two camera centres, metres.
    pub baseline_m: f64,
}

/// One image.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageReport {
    /// Camera name.
    pub camera: String,
    /// File name (the view).
    pub image: String,
    /// Whether the board was found.
    pub detected: bool,
    /// RMS reprojection error after joint refinement, pixels (detected images only).
    pub rms_px: Option<f64>,
    /// Whether its error is an outlier among all images (see [`crate::CalibParams::outlier_factor`]).
    pub outlier: bool,
}

/// A spanning-tree edge by camera names.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TreeEdgeReport {
    /// Camera nearer the root.
    pub parent: String,
    /// Camera chained through it.
    pub child: String,
    /// Views they share.
    pub shared_views: usize,
}

/// Everything a calibration measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibReport {
    /// The board.
    pub pattern: Pattern,
    /// What the world frame is (`camera_0` or `board:<image>`).
    pub world_frame: String,
    /// RMS reprojection error over every corner of every camera and view, pixels.
    pub rms_px: f64,
    /// Per camera.
    pub cameras: Vec<CameraReport>,
    /// Per pair of cameras sharing at least one view.
    pub pairs: Vec<PairReport>,
    /// Per image.
    pub images: Vec<ImageReport>,
    /// Images where the board was not found (skipped).
    pub skipped_images: usize,
    /// Images flagged as outliers.
    pub outlier_images: usize,
    /// The spanning tree the initial extrinsics were chained through.
    pub spanning_tree: Vec<TreeEdgeReport>,
    /// The joint refinement.
    pub refinement: RefineSummary,
}
