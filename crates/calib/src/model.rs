//! The calibration problem: the board and which camera saw it in which view.

use nalgebra::{Point2, Point3};

/// A chessboard calibration pattern, counted by inner corners as OpenCV does.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pattern {
    /// Inner corners along a row.
    pub cols: u32,
    /// Inner corners along a column.
    pub rows: u32,
    /// Side of one square, metres.
    pub square: f64,
}

impl Pattern {
    /// Parses `COLSxROWS` (e.g. `9x6`) with the square size in metres.
    pub fn parse(spec: &str, square: f64) -> Option<Self> {
        let (c, r) = spec.split_once(['x', 'X'])?;
        let (cols, rows) = (c.trim().parse().ok()?, r.trim().parse().ok()?);
        (cols >= 2 && rows >= 2 && square.is_finite() && square > 0.0).then_some(Self { cols, rows, square })
    }

    /// Number of inner corners.
    pub fn corner_count(&self) -> usize {
        (self.cols * self.rows) as usize
    }

    /// The corners in the board frame (OpenCV order: row by row, z = 0), metres.
    pub fn object_points(&self) -> Vec<Point3<f64>> {
        (0..self.rows)
            .flat_map(|j| (0..self.cols).map(move |i| Point3::new(i as f64 * self.square, j as f64 * self.square, 0.0)))
            .collect()
    }
}

/// Detected board corners: for each camera and each view, the corners in pixels (OpenCV order) or
/// `None` where the board was not found.
#[derive(Debug, Clone, Default)]
pub struct Observations {
    /// Camera names, in rig order.
    pub cameras: Vec<String>,
    /// Image size (width, height) per camera.
    pub image_sizes: Vec<(u32, u32)>,
    /// View names (the shared file name of simultaneous images).
    pub views: Vec<String>,
    /// `corners[camera][view]`.
    pub corners: Vec<Vec<Option<Vec<Point2<f64>>>>>,
    /// `has_image[camera][view]`: whether that camera has an image of that view at all.
    pub has_image: Vec<Vec<bool>>,
}

impl Observations {
    /// Empty observations for these cameras and views.
    pub fn new(cameras: Vec<String>, image_sizes: Vec<(u32, u32)>, views: Vec<String>) -> Self {
        let corners = vec![vec![None; views.len()]; cameras.len()];
        let has_image = vec![vec![true; views.len()]; cameras.len()];
        Self { cameras, image_sizes, views, corners, has_image }
    }

    /// Number of views in which camera `c` found the board.
    pub fn detected_count(&self, c: usize) -> usize {
        self.corners[c].iter().filter(|v| v.is_some()).count()
    }

    /// Views in which both cameras found the board.
    pub fn shared_views(&self, a: usize, b: usize) -> Vec<usize> {
        (0..self.views.len()).filter(|&v| self.corners[a][v].is_some() && self.corners[b][v].is_some()).collect()
    }
}
