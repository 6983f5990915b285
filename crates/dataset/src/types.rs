//! Plain data shared by every reader and writer of frame sets: synthetic, recorded and live.

use image::{GrayImage, RgbImage};
use nalgebra::{Matrix4, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Label values in masks (DESIGN "Conventions").
pub mod label {
    /// Nothing of interest.
    pub const BACKGROUND: u8 = 0;
    /// The hand holding the tool.
    pub const HAND: u8 = 1;
    /// The scalpel (handle and blade).
    pub const SCALPEL: u8 = 2;
    /// Not known (e.g. hidden, or refused by segmentation).
    pub const UNKNOWN: u8 = 255;
    /// Foreground labels with their names as used in paths and reports.
    pub const NAMED: [(u8, &str); 2] = [(HAND, "hand"), (SCALPEL, "scalpel")];
}

/// One camera's image of a frame set.
#[derive(Debug, Clone)]
pub struct View {
    /// Index of the camera in rig order.
    pub camera: usize,
    /// Capture time of this image, nanoseconds.
    pub timestamp_ns: i64,
    /// 8-bit colour image.
    pub image: RgbImage,
    /// Label mask (0 background, 1 hand, 2 scalpel, 255 unknown), when known.
    pub mask: Option<GrayImage>,
}

/// Simultaneous images of all cameras; a camera whose frame was dropped has `None`.
#[derive(Debug, Clone)]
pub struct FrameSet {
    /// Frame number (the dataset's six-digit numbering).
    pub frame: u64,
    /// Frame-set time: the median of its present views' timestamps, nanoseconds.
    pub timestamp_ns: i64,
    /// One entry per camera in rig order.
    pub views: Vec<Option<View>>,
}

impl FrameSet {
    /// Number of cameras that delivered an image.
    pub fn present(&self) -> usize {
        self.views.iter().filter(|v| v.is_some()).count()
    }

    /// Median of the present views' timestamps (lower median for an even count); 0 when none.
    pub fn median_timestamp(views: &[Option<View>]) -> i64 {
        let mut t: Vec<i64> = views.iter().flatten().map(|v| v.timestamp_ns).collect();
        t.sort_unstable();
        if t.is_empty() { 0 } else { t[(t.len() - 1) / 2] }
    }
}

/// `dataset.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetMeta {
    /// Format version; this crate reads and writes [`crate::FORMAT_VERSION`].
    pub format_version: u32,
    /// Human-readable name.
    pub name: String,
    /// Nominal frame rate, frames per second.
    pub fps: f64,
    /// Number of frame sets (frame numbers 0..frame_count).
    pub frame_count: u64,
    /// Camera names in rig order; each has a folder of the same name.
    pub cameras: Vec<String>,
    /// The working volume carving covers, world metres (optional; without it the volume is
    /// derived from the rig).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub workspace: Option<Workspace>,
}

/// `workspace = { min = [x, y, z], max = [x, y, z] }` in `dataset.toml`: a box in world metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

/// A triangle mesh in metres (PLY on disk): the workspace's one mesh type, from `hullcut-mesh`.
pub use hullcut_mesh::TriMesh as Mesh;

/// `tool.json`: the instrument's known geometry, all in the tool frame, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolGeometry {
    /// Closed triangle mesh of the whole instrument (written as `tool.ply` beside tool.json).
    pub mesh: Mesh,
    /// Blade tip.
    pub tip: Point3<f64>,
    /// Cutting edge as a polyline from the tip to the heel.
    pub cutting_edge: Vec<Point3<f64>>,
    /// Unit normal of the blade's mid-plane.
    pub blade_normal: Vector3<f64>,
    /// Blade thickness, metres.
    pub blade_thickness: f64,
    /// Optional outline of the blade in its mid-plane.
    pub blade_outline: Option<Vec<Point3<f64>>>,
}

/// One line of `truth/poses.jsonl`.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthPose {
    /// Frame number.
    pub frame: u64,
    /// Frame-set time, nanoseconds.
    pub timestamp_ns: i64,
    /// Tool frame to world frame.
    pub tool_to_world: Matrix4<f64>,
}
