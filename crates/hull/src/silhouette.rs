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

/// What a camera's lens allows a silhouette: these depend on the image size, the intrinsics and
/// the distortion alone, and finding the field's radius undistorts 300-500 border points (0.1-0.5
/// ms), for every silhouette built: two or three per view and frame set. So they are found once
/// per lens and kept (the last [`LensBounds::KEPT`] lenses seen, for the whole process).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LensBounds {
    monotonic_radius: f64,
    field_radius: Option<f64>,
    curvature: f64,
}

impl LensBounds {
    /// Lenses kept.
    const KEPT: usize = 64;

    fn of(camera: &Camera) -> LensBounds {
        type Key = [u64; 11];
        static SEEN: std::sync::Mutex<Vec<(Key, LensBounds)>> = std::sync::Mutex::new(Vec::new());
        let d = &camera.distortion;
        let key: Key = [
            u64::from(camera.width),
            u64::from(camera.height),
            camera.fx.to_bits(),
            camera.fy.to_bits(),
            camera.cx.to_bits(),
            camera.cy.to_bits(),
            d.k1.to_bits(),
            d.k2.to_bits(),
            d.k3.to_bits(),
            d.p1.to_bits(),
            d.p2.to_bits(),
        ];
        // A poisoned lock (a panic elsewhere while it was held) only loses the memory.
        if let Some((_, bounds)) = SEEN.lock().ok().and_then(|seen| seen.iter().find(|(k, _)| *k == key).copied()) {
            return bounds;
        }
        let bounds = LensBounds::find(camera);
        if let Ok(mut seen) = SEEN.lock() {
            if seen.len() >= Self::KEPT {
                seen.remove(0);
            }
            seen.push((key, bounds));
        }
        bounds
    }

    fn find(camera: &Camera) -> LensBounds {
        let monotonic_radius = camera.distortion.monotonic_radius();
        let field_radius = field_radius(camera, monotonic_radius);
        let curvature = curvature(camera, field_radius.unwrap_or(monotonic_radius.min(2.0)));
        LensBounds { monotonic_radius, field_radius, curvature }
    }
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
    /// Summed-area tables over `window`, the box of the mask's foreground (nothing outside it
    /// but background, so a rectangle's counts are those of its part inside the window): `table`
    /// has `(window width + 1) × (window height + 1)` entries of (hand, scalpel, unknown) counts,
    /// interleaved so that a rectangle query touches four cache lines, not twelve; `blocks` counts
    /// the foreground pixels per block of `BLOCK`² pixels of the window, as a summed-area table
    /// over blocks (`block_stride` columns): small enough to stay in cache, so that a footprint
    /// over background (most of them) is settled without touching `table`.
    Summed { window: Window, stride: usize, table: Vec<[u32; 3]>, blocks: Vec<u32>, block_stride: usize },
    /// The mask's labels, counted pixel by pixel over each rectangle asked for.
    Direct { width: usize, labels: Vec<u8> },
}

/// Side of the blocks of [`Silhouette`]'s coarse table, pixels.
const BLOCK: usize = 8;

/// The pixel box `[x0, x0 + w) × [y0, y0 + h)` a summed-area table covers (empty: `w` or `h` 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Window {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

impl Window {
    /// The box of the pixels of `raw` (rows of `w`) that are not background.
    fn of_foreground(raw: &[u8], w: usize) -> Window {
        let (mut lo, mut hi, mut rows) = (usize::MAX, 0, None::<(usize, usize)>);
        for (j, row) in raw.chunks_exact(w.max(1)).enumerate() {
            let Some(first) = row.iter().position(|&p| p != label::BACKGROUND) else { continue };
            let last = row.iter().rposition(|&p| p != label::BACKGROUND).unwrap_or(first);
            lo = lo.min(first);
            hi = hi.max(last);
            rows = Some((rows.map_or(j, |r| r.0), j));
        }
        match rows {
            Some((j0, j1)) => Window { x0: lo, y0: j0, w: hi + 1 - lo, h: j1 + 1 - j0 },
            None => Window { x0: 0, y0: 0, w: 0, h: 0 },
        }
    }

    /// The part of the inclusive rectangle `[i0, i1] × [j0, j1]` inside the window, in window
    /// coordinates (inclusive); `None` when they do not meet.
    #[inline]
    fn clip(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> Option<(usize, usize, usize, usize)> {
        let (a0, b0) = (i0.max(self.x0), j0.max(self.y0));
        let (a1, b1) = (i1.min((self.x0 + self.w).checked_sub(1)?), j1.min((self.y0 + self.h).checked_sub(1)?));
        (a0 <= a1 && b0 <= b1).then(|| (a0 - self.x0, b0 - self.y0, a1 - self.x0, b1 - self.y0))
    }
}

impl Silhouette {
    /// Builds the tables of a mask taken by `camera` (sizes must agree; the caller checks).
    pub fn new(camera: &Camera, mask: &GrayImage) -> Self {
        let w = mask.width() as usize;
        let raw = mask.as_raw();
        // Only the foreground's box is tabled: a hand and a tool fill a fraction of the image.
        let window = Window::of_foreground(raw, w);
        let stride = window.w + 1;
        let mut table = vec![[0u32; 3]; stride * (window.h + 1)];
        for j in 0..window.h {
            let mut row = [0u32; 3];
            let start = (window.y0 + j) * w + window.x0;
            for (i, &p) in raw[start..start + window.w].iter().enumerate() {
                match p {
                    label::BACKGROUND => {}
                    label::HAND => row[0] += 1,
                    label::SCALPEL => row[1] += 1,
                    _ => row[2] += 1,
                }
                let above = table[j * stride + i + 1];
                table[(j + 1) * stride + i + 1] = [above[0] + row[0], above[1] + row[1], above[2] + row[2]];
            }
        }
        let (bw, bh) = (window.w.div_ceil(BLOCK), window.h.div_ceil(BLOCK));
        let block_stride = bw + 1;
        let mut blocks = vec![0u32; block_stride * (bh + 1)];
        for bj in 0..bh {
            let mut row = 0u32;
            for bi in 0..bw {
                let (i0, j0) = (bi * BLOCK, bj * BLOCK);
                let (i1, j1) = ((i0 + BLOCK).min(window.w) - 1, (j0 + BLOCK).min(window.h) - 1);
                let at = |i: usize, j: usize| table[j * stride + i];
                let (a, b, c, d) = (at(i1 + 1, j1 + 1), at(i0, j0), at(i1 + 1, j0), at(i0, j1 + 1));
                let fg: u32 = (0..3).map(|k| a[k] + b[k] - c[k] - d[k]).sum();
                row += fg;
                blocks[(bj + 1) * block_stride + bi + 1] = blocks[bj * block_stride + bi + 1] + row;
            }
        }
        Self::with_store(camera, Store::Summed { window, stride, table, blocks, block_stride })
    }

    /// A silhouette that counts labels by visiting the mask's pixels in each rectangle asked
    /// for, without building tables (sizes must agree; the caller checks): for a mask that is
    /// asked about few, small rectangles (the cells near the tool, the few cells a shadow test
    /// leaves open), where building the table over the foreground's box (up to 3.7 MB for a
    /// 640x480 view) would cost more than all the queries. Counts and verdicts are those of
    /// [`Silhouette::new`].
    pub fn direct(camera: &Camera, mask: GrayImage) -> Self {
        let width = mask.width() as usize;
        Self::with_store(camera, Store::Direct { width, labels: mask.into_raw() })
    }

    fn with_store(camera: &Camera, store: Store) -> Self {
        let LensBounds { monotonic_radius, field_radius, curvature } = LensBounds::of(camera);
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

    /// Appends the image's whole summed-area table (`(w + 1) × (h + 1)` entries of hand,
    /// scalpel, unknown counts, row by row, flattened) to `out` and returns its row stride;
    /// `None` for a [`Silhouette::direct`] one. Built from the foreground's window: outside it
    /// every count is the window's nearest edge entry (nothing but background there).
    #[cfg(feature = "gpu")]
    pub(crate) fn extend_whole_table(&self, out: &mut Vec<u32>) -> Option<usize> {
        let Store::Summed { window, stride, table, .. } = &self.store else { return None };
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        out.reserve(3 * (w + 1) * (h + 1));
        for j in 0..=h {
            let b = j.saturating_sub(window.y0).min(window.h);
            for i in 0..=w {
                let a = i.saturating_sub(window.x0).min(window.w);
                out.extend_from_slice(&table[b * stride + a]);
            }
        }
        Some(w + 1)
    }

    /// Whether the blocks covering the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside
    /// the image) hold any foreground: `false` means the rectangle holds none (always `true` for
    /// a [`Silhouette::direct`] one: its counts tell).
    // Inlined always, as `counts`: called per cell and view in carving (a million times in 20 frame
    // sets), where the compiler left them calls (carving 11.3 -> 10.9 ms a frame set).
    #[inline(always)]
    pub fn may_have_foreground(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> bool {
        let Store::Summed { window, blocks: b, block_stride: s, .. } = &self.store else { return true };
        let Some((i0, j0, i1, j1)) = window.clip(i0, j0, i1, j1) else { return false };
        let (b0, c0, b1, c1) = (i0 / BLOCK, j0 / BLOCK, i1 / BLOCK + 1, j1 / BLOCK + 1);
        b[c1 * s + b1] + b[c0 * s + b0] != b[c0 * s + b1] + b[c1 * s + b0]
    }

    /// Counts inside the pixel rectangle `[i0, i1] × [j0, j1]` (inclusive, inside the image).
    #[inline(always)]
    pub fn counts(&self, i0: usize, j0: usize, i1: usize, j1: usize) -> Counts {
        let total = ((i1 - i0 + 1) * (j1 - j0 + 1)) as u32;
        match &self.store {
            Store::Summed { window, stride: s, table, .. } => {
                let Some((i0, j0, i1, j1)) = window.clip(i0, j0, i1, j1) else {
                    return Counts { total, ..Counts::default() };
                };
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w`×`h` mask with a few labelled pixels at the given places (hand, scalpel, unknown in
    /// turn), and the camera it belongs to.
    fn mask_with(w: u32, h: u32, at: &[(u32, u32)]) -> (Camera, GrayImage) {
        let mut m = GrayImage::new(w, h);
        for (n, &(i, j)) in at.iter().enumerate() {
            m.put_pixel(i, j, image::Luma([[label::HAND, label::SCALPEL, label::UNKNOWN][n % 3]]));
        }
        (Camera::new("c", w, h, 50.0, 50.0, f64::from(w) / 2.0, f64::from(h) / 2.0), m)
    }

    /// The tables cover the foreground's box only; every rectangle of the image, inside it,
    /// across its edges or away from it, counts what the mask holds there, and the blocks never
    /// rule out a rectangle that holds foreground.
    #[test]
    fn a_lens_seen_before_gives_the_bounds_found_for_it_and_another_lens_its_own() {
        let mut barrel = Camera::new("a", 640, 480, 500.0, 500.0, 319.5, 239.5);
        barrel.distortion = hullcut_rig::Distortion { k1: -0.3, k2: 0.08, ..hullcut_rig::Distortion::NONE };
        let mut wider = barrel.clone();
        wider.width = 1280;
        let plain = Camera::new("b", 640, 480, 500.0, 500.0, 319.5, 239.5);
        for camera in [&barrel, &wider, &plain, &barrel, &plain] {
            assert_eq!(LensBounds::of(camera), LensBounds::find(camera), "{}x{}", camera.width, camera.height);
        }
        assert_ne!(LensBounds::of(&barrel), LensBounds::of(&plain));
        assert_ne!(LensBounds::of(&barrel).field_radius, LensBounds::of(&wider).field_radius);
        // More lenses than are kept: each still gets its own.
        for k in 0..(LensBounds::KEPT + 5) {
            let mut c = barrel.clone();
            c.fx = 400.0 + k as f64;
            assert_eq!(LensBounds::of(&c), LensBounds::find(&c), "lens {k}");
        }
        assert_eq!(LensBounds::of(&barrel), LensBounds::find(&barrel));
    }

    #[test]
    fn tables_over_the_foregrounds_box_count_as_the_whole_image() {
        let cases: [&[(u32, u32)]; 4] =
            [&[(7, 5), (9, 5), (8, 11), (20, 14), (13, 9)], &[(0, 0), (30, 20)], &[(30, 3)], &[]];
        for at in cases {
            let (camera, mask) = mask_with(31, 21, at);
            let tabled = Silhouette::new(&camera, &mask);
            let direct = Silhouette::direct(&camera, mask.clone());
            for j0 in 0..21 {
                for i0 in (0..31).step_by(3) {
                    for (di, dj) in [(0, 0), (2, 1), (5, 7), (30, 20)] {
                        let (i1, j1) = ((i0 + di).min(30), (j0 + dj).min(20));
                        let counts = tabled.counts(i0, j0, i1, j1);
                        assert_eq!(counts, direct.counts(i0, j0, i1, j1), "{at:?}: [{i0}, {i1}] x [{j0}, {j1}]");
                        if counts.foreground() > 0 {
                            assert!(tabled.may_have_foreground(i0, j0, i1, j1), "{at:?}: [{i0}, {i1}] x [{j0}, {j1}]");
                        }
                    }
                }
            }
            // The window is the labelled pixels' box exactly (empty without any).
            let Store::Summed { window, .. } = &tabled.store else { panic!("a tabled silhouette") };
            let expected = match (at.iter().map(|p| p.0).min(), at.iter().map(|p| p.1).min()) {
                (Some(x0), Some(y0)) => {
                    let (x1, y1) =
                        (at.iter().map(|p| p.0).max().unwrap_or(x0), at.iter().map(|p| p.1).max().unwrap_or(y0));
                    Window { x0: x0 as usize, y0: y0 as usize, w: (x1 - x0 + 1) as usize, h: (y1 - y0 + 1) as usize }
                }
                _ => Window { x0: 0, y0: 0, w: 0, h: 0 },
            };
            assert_eq!(*window, expected, "{at:?}");
        }
    }

    /// The whole-image table handed to the GPU equals one built over the whole image.
    #[cfg(feature = "gpu")]
    #[test]
    fn the_whole_table_rebuilt_from_the_window_is_the_whole_images() {
        let (camera, mask) = mask_with(31, 21, &[(7, 5), (9, 5), (8, 11), (20, 14), (13, 9)]);
        let mut out = Vec::new();
        let stride = Silhouette::new(&camera, &mask).extend_whole_table(&mut out);
        assert_eq!(stride, Some(32));
        let direct = Silhouette::direct(&camera, mask);
        for j in 0..=21usize {
            for i in 0..=31usize {
                let c = if i == 0 || j == 0 { Counts::default() } else { direct.counts(0, 0, i - 1, j - 1) };
                let k = 3 * (j * 32 + i);
                assert_eq!(out[k..k + 3], [c.hand, c.scalpel, c.unknown], "entry ({i}, {j})");
            }
        }
    }
}
