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

/// Twice the largest sag of a distorted chord per pixel² (see [`Silhouette::curvature`]): a segment
/// of normalized length ℓ sags from its chord by at most max|D''| ℓ² / 8, with the second derivative
/// of the distortion D bounded over radii up to `r` by 6|k1| r + 20|k2| r³ + 42|k3| r⁵ and
/// 6 (|p1| + |p2|) for the tangential terms; in pixels ℓ = e / f.
fn curvature(camera: &Camera, r: f64) -> f64 {
    let d = &camera.distortion;
    let second = 6.0 * d.k1.abs() * r
        + 20.0 * d.k2.abs() * r.powi(3)
        + 42.0 * d.k3.abs() * r.powi(5)
        + 6.0 * (d.p1.abs() + d.p2.abs());
    2.0 * second / 8.0 / camera.fx.min(camera.fy)
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

/// One camera's mask, ready for label counts over pixel rectangles: as a summed-area table
/// ([`Silhouette::new`]) or as the mask itself ([`Silhouette::direct`]).
#[derive(Debug, Clone)]
pub struct Silhouette {
    camera: Camera,
    /// The lens' invertible radius, computed once (it is a root search).
    monotonic_radius: f64,
    /// The undistorted radius the image's border reaches, when it lies within the invertible
    /// radius: nothing farther from the axis is in view.
    field_radius: Option<f64>,
    /// Bound on how far distortion bows a projected straight edge, per pixel² of its length.
    curvature: f64,
    store: Store,
}

/// How a [`Silhouette`] counts the labels in a rectangle.
#[derive(Debug, Clone)]
enum Store {
    /// `(w + 1) × (h + 1)` entries of (hand, scalpel, unknown) counts, interleaved so that a
    /// rectangle query touches four cache lines, not twelve; `blocks` counts the foreground
    /// pixels per block of `BLOCK`² pixels, as a summed-area table over blocks
    /// (`(w / BLOCK + 2)` columns): small enough to stay in cache, so that a footprint over
    /// background (most of them) is settled without touching `table`.
    Summed { stride: usize, table: Vec<[u32; 3]>, blocks: Vec<u32>, block_stride: usize },
    /// The mask's labels, counted pixel by pixel over each rectangle asked for.
    Direct { width: usize, labels: Vec<u8> },
}

/// Side of the blocks of [`Silhouette`]'s coarse table, pixels.
const BLOCK: usize = 8;

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
        let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        let block_stride = bw + 1;
        let mut blocks = vec![0u32; block_stride * (bh + 1)];
        for bj in 0..bh {
            let mut row = 0u32;
            for bi in 0..bw {
                let (i0, j0) = (bi * BLOCK, bj * BLOCK);
                let (i1, j1) = ((i0 + BLOCK).min(w) - 1, (j0 + BLOCK).min(h) - 1);
                let at = |i: usize, j: usize| table[j * stride + i];
                let (a, b, c, d) = (at(i1 + 1, j1 + 1), at(i0, j0), at(i1 + 1, j0), at(i0, j1 + 1));
                let fg: u32 = (0..3).map(|k| a[k] + b[k] - c[k] - d[k]).sum();
                row += fg;
                blocks[(bj + 1) * block_stride + bi + 1] = blocks[bj * block_stride + bi + 1] + row;
            }
        }
        Self::with_store(camera, Store::Summed { stride, table, blocks, block_stride })
    }

    /// A silhouette that counts labels by visiting the mask's pixels in each rectangle asked
    /// for, without building tables (sizes must agree; the caller checks): for a mask that is
    /// asked about few, small rectangles (the cells near the tool, the few cells a shadow test
    /// leaves open), where building the 3.7 MB table of a 640x480 view would cost more than all
    /// the queries. Counts and verdicts are those of [`Silhouette::new`].
    pub fn direct(camera: &Camera, mask: GrayImage) -> Self {
        let width = mask.width() as usize;
        Self::with_store(camera, Store::Direct { width, labels: mask.into_raw() })
    }

    fn with_store(camera: &Camera, store: Store) -> Self {
        let monotonic_radius = camera.distortion.monotonic_radius();
        let field_radius = field_radius(camera, monotonic_radius);
        let curvature = curvature(camera, field_radius.unwrap_or(monotonic_radius.min(2.0)));
        Silhouette { camera: camera.clone(), monotonic_radius, field_radius, curvature, store }
    }

    /// A bound on how far, in pixels, the lens' distortion bows the image of a straight edge out of
    /// its chord, per pixel² of the chord's length: a footprint of `e` pixels needs a margin of
    /// `curvature · e²` to hold the cell's whole image. 0 without distortion.
    pub fn curvature(&self) -> f64 {
        self.curvature
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
    /// by row) and its row stride; `None` for a [`Silhouette::direct`] one.
    #[cfg(feature = "gpu")]
    pub(crate) fn table(&self) -> Option<(&[[u32; 3]], usize)> {
        match &self.store {
            Store::Summed { table, stride, .. } => Some((table, *stride)),
            Store::Direct { .. } => None,
        }
    }

    /// Whether the blocks covering the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside
    /// the image) hold any foreground: `false` means the rectangle holds none (always `true` for
    /// a [`Silhouette::direct`] one: its counts tell).
    #[inline]
    pub fn may_have_foreground(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> bool {
        let Store::Summed { blocks: b, block_stride: s, .. } = &self.store else { return true };
        let (b0, c0, b1, c1) = (i0 / BLOCK, j0 / BLOCK, i1 / BLOCK + 1, j1 / BLOCK + 1);
        b[c1 * s + b1] + b[c0 * s + b0] != b[c0 * s + b1] + b[c1 * s + b0]
    }

    /// Counts inside the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside the image).
    pub fn counts(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> Counts {
        let total = ((i1 - i0 + 1) * (j1 - j0 + 1)) as u32;
        match &self.store {
            Store::Summed { stride: s, table, .. } => {
                let (a, b, c, d) = (
                    table[(j1 + 1) * s + i1 + 1],
                    table[j0 * s + i0],
                    table[j0 * s + i1 + 1],
                    table[(j1 + 1) * s + i0],
                );
                let sum = |k: usize| a[k] + b[k] - c[k] - d[k];
                Counts { total, hand: sum(0), scalpel: sum(1), unknown: sum(2) }
            }
            Store::Direct { width, labels } => {
                let mut counts = Counts { total, ..Counts::default() };
                for row in labels.chunks_exact(*width).skip(j0).take(j1 + 1 - j0) {
                    for &p in &row[i0..=i1] {
                        match p {
                            label::BACKGROUND => {}
                            label::HAND => counts.hand += 1,
                            label::SCALPEL => counts.scalpel += 1,
                            _ => counts.unknown += 1,
                        }
                    }
                }
                counts
            }
        }
    }
}
