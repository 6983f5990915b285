//! Per-view summed-area tables of a label mask, so that the label counts inside any pixel
//! rectangle cost four lookups, whatever its size.

use hullcut_dataset::label;
use hullcut_rig::Camera;
use image::GrayImage;

/// The largest undistorted radius of the image's border pixels (sampled every 8 pixels and at the
/// corners), widened by 1%, if every one undistorts within `monotonic` and the widened radius stays
/// below it.
fn field_radius(camera: &Camera, monotonic: f64) -> Option<f64> {
    let (w, h) = (f64::from(camera.width) - 1.0, f64::from(camera.height) - 1.0);
    let mut border = Vec::new();
    let steps = |len: f64| ((len / 8.0).ceil() as usize).max(1);
    for k in 0..=steps(w) {
        let x = w * k as f64 / steps(w) as f64;
        border.push((x, 0.0));
        border.push((x, h));
    }
    for k in 0..=steps(h) {
        let y = h * k as f64 / steps(h) as f64;
        border.push((0.0, y));
        border.push((w, y));
    }
    let mut r = 0.0f64;
    for (u, v) in border {
        r = r.max(camera.undistort(nalgebra::Point2::new(u, v))?.norm());
    }
    let r = r * 1.01;
    (r < monotonic).then_some(r)
}

/// Pixel counts of each class inside a rectangle of a mask.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Pixels in the rectangle.
    pub total: u32,
    /// Hand pixels.
    pub hand: u32,
    /// Scalpel pixels.
    pub scalpel: u32,
    /// Unknown pixels (label 255, or any label this crate does not know).
    pub unknown: u32,
}

impl Counts {
    /// Pixels that are not background.
    pub fn foreground(&self) -> u32 {
        self.hand + self.scalpel + self.unknown
    }

    /// Pixels of a foreground label (`label::HAND` or `label::SCALPEL`).
    pub fn of(&self, l: u8) -> u32 {
        match l {
            label::HAND => self.hand,
            label::SCALPEL => self.scalpel,
            _ => self.unknown,
        }
    }
}

/// One camera's mask as a summed-area table, `(w + 1) × (h + 1)` entries of (hand, scalpel,
/// unknown) counts, interleaved so that a rectangle query touches four cache lines, not twelve.
#[derive(Debug, Clone)]
pub struct Silhouette {
    camera: Camera,
    /// The lens' invertible radius, computed once (it is a root search).
    monotonic_radius: f64,
    /// The undistorted radius the image's border reaches, when it lies within the invertible
    /// radius: nothing farther from the axis is in view.
    field_radius: Option<f64>,
    stride: usize,
    table: Vec<[u32; 3]>,
}

impl Silhouette {
    /// Builds the tables of a mask taken by `camera` (sizes must agree; the caller checks).
    pub fn new(camera: &Camera, mask: &GrayImage) -> Self {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let stride = w + 1;
        let mut table = vec![[0u32; 3]; stride * (h + 1)];
        let raw = mask.as_raw();
        for j in 0..h {
            let mut row = [0u32; 3];
            for i in 0..w {
                match raw[j * w + i] {
                    label::BACKGROUND => {}
                    label::HAND => row[0] += 1,
                    label::SCALPEL => row[1] += 1,
                    _ => row[2] += 1,
                }
                let above = table[j * stride + i + 1];
                table[(j + 1) * stride + i + 1] = [above[0] + row[0], above[1] + row[1], above[2] + row[2]];
            }
        }
        let monotonic_radius = camera.distortion.monotonic_radius();
        let field_radius = field_radius(camera, monotonic_radius);
        Silhouette { camera: camera.clone(), monotonic_radius, field_radius, stride, table }
    }

    /// The undistorted normalized radius beyond which nothing is in view, when the whole image
    /// lies within the lens' invertible radius (a point farther out then projects, clamped to this
    /// radius, outside the image); `None` when the image reaches beyond it.
    pub fn field_radius(&self) -> Option<f64> {
        self.field_radius
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Normalized radius within which the camera's distortion can be inverted.
    pub fn monotonic_radius(&self) -> f64 {
        self.monotonic_radius
    }

    /// The summed-area table (`(w + 1) × (h + 1)` entries of hand, scalpel, unknown counts, row
    /// by row) and its row stride.
    #[cfg(feature = "gpu")]
    pub(crate) fn table(&self) -> (&[[u32; 3]], usize) {
        (&self.table, self.stride)
    }

    /// Counts inside the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside the image).
    pub fn counts(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> Counts {
        let s = self.stride;
        let (a, b, c, d) = (
            self.table[(j1 + 1) * s + i1 + 1],
            self.table[j0 * s + i0],
            self.table[j0 * s + i1 + 1],
            self.table[(j1 + 1) * s + i0],
        );
        let sum = |k: usize| a[k] + b[k] - c[k] - d[k];
        Counts { total: ((i1 - i0 + 1) * (j1 - j0 + 1)) as u32, hand: sum(0), scalpel: sum(1), unknown: sum(2) }
    }
}
