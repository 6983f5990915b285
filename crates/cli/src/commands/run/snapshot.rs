//! Pictures without a viewer: `hullcut run --snapshots DIR`.
//!
//! At chosen frames, two PNGs drawn by hullcut itself: NNNNNN-views.png, the six views in a grid
//! (three per row) with their label masks tinted over them (hand blue, scalpel amber) and the
//! estimated cutting edge projected through each camera's lens (orange); and NNNNNN-organ.png,
//! the organ's pieces (cut faces included) rendered through one camera over its image and
//! enlarged around the organ, the hand
//! and scalpel hulls occluding them where they are in front (the organ is virtual: everything
//! else in the picture is the camera's own image), with the cutting edge on top.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use hullcut_dataset::{FrameSet, label};
use hullcut_pose::BladePose;
use hullcut_rig::{Camera, Rig};
use hullcut_synth::{CameraRenderer, Light, Part};
use image::{Rgb, RgbImage};
use nalgebra::Point3;

use hullcut_pipeline::LabelGrid;

/// Widest tile of the views grid, pixels (larger images are shrunk by an integer factor).
const TILE_WIDTH: u32 = 320;
/// Tile columns of the views grid.
const COLUMNS: u32 = 3;
/// Tints of the label overlay and their opacity.
const HAND_TINT: [u8; 3] = [70, 130, 255];
const SCALPEL_TINT: [u8; 3] = [255, 200, 40];
const TINT_ALPHA: f32 = 0.45;
/// Colour of the estimated cutting edge.
const EDGE_COLOUR: [u8; 3] = [255, 110, 30];
/// Linear albedos of the organ's pieces, in turn.
const PIECE_ALBEDO: [[f32; 3]; 4] = [[0.45, 0.1, 0.08], [0.75, 0.45, 0.15], [0.35, 0.3, 0.6], [0.3, 0.55, 0.3]];
/// Width of the organ snapshot, pixels (the region around the organ, enlarged).
const ZOOM_WIDTH: u32 = 640;
/// Labels of the organ's pieces in the render (above the dataset's labels).
const FIRST_PIECE_LABEL: u8 = 10;

/// Which frames to draw and where.
pub struct Snapshots {
    dir: PathBuf,
    frames: BTreeSet<u64>,
    camera: usize,
    renderer: Option<CameraRenderer>,
    /// PNGs written.
    pub written: u64,
}

impl Snapshots {
    /// Snapshots into `dir` at `frames` (of those processed), the organ seen by camera `camera`
    /// (a name; the first camera when `None`).
    pub fn new(dir: &Path, frames: BTreeSet<u64>, camera: Option<&str>, rig: &Rig) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let camera = match camera {
            None => 0,
            Some(name) => match rig.cameras.iter().position(|c| c.name == name) {
                Some(i) => i,
                None => {
                    let names: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
                    bail!("--snapshot-camera {name}: no such camera (the rig has {})", names.join(", "))
                }
            },
        };
        Ok(Snapshots { dir: dir.to_owned(), frames, camera, renderer: None, written: 0 })
    }

    /// Whether `frame` is drawn.
    pub fn wants(&self, frame: u64) -> bool {
        self.frames.contains(&frame)
    }

    /// The frames drawn, in order.
    pub fn frames(&self) -> impl Iterator<Item = u64> + '_ {
        self.frames.iter().copied()
    }

    /// Draws one frame set.
    pub fn write(
        &mut self,
        rig: &Rig,
        set: &FrameSet,
        grids: &[LabelGrid],
        blade: Option<&BladePose>,
        pieces: &[hullcut_sim::TriMesh],
    ) -> anyhow::Result<()> {
        let frame = set.frame;
        let views = views_grid(rig, set, blade);
        let path = self.dir.join(format!("{frame:06}-views.png"));
        views.save(&path).with_context(|| format!("writing {}", path.display()))?;
        let camera = &rig.cameras[self.camera];
        let renderer = self.renderer.get_or_insert_with(|| CameraRenderer::new(camera, Light::default()));
        let organ = organ_view(renderer, set.views[self.camera].as_ref().map(|v| &v.image), grids, blade, pieces);
        let path = self.dir.join(format!("{frame:06}-organ.png"));
        organ.save(&path).with_context(|| format!("writing {}", path.display()))?;
        self.written += 2;
        Ok(())
    }
}

/// The six views, shrunk to tiles, masks tinted, the cutting edge drawn.
fn views_grid(rig: &Rig, set: &FrameSet, blade: Option<&BladePose>) -> RgbImage {
    let widest = rig.cameras.iter().map(|c| c.width).max().unwrap_or(1);
    let tallest = rig.cameras.iter().map(|c| c.height).max().unwrap_or(1);
    let shrink = widest.div_ceil(TILE_WIDTH).max(1);
    let (tw, th) = (widest / shrink, tallest / shrink);
    let rows = (rig.cameras.len() as u32).div_ceil(COLUMNS);
    let mut out = RgbImage::from_pixel(tw * COLUMNS, th * rows, Rgb([24, 24, 24]));
    for (k, (camera, view)) in rig.cameras.iter().zip(&set.views).enumerate() {
        let Some(view) = view else { continue };
        let mut tile = view.image.clone();
        if let Some(mask) = &view.mask {
            for (p, l) in tile.pixels_mut().zip(mask.pixels()) {
                let tint = match l.0[0] {
                    label::HAND => HAND_TINT,
                    label::SCALPEL => SCALPEL_TINT,
                    _ => continue,
                };
                for c in 0..3 {
                    p.0[c] = (f32::from(p.0[c]) * (1.0 - TINT_ALPHA) + f32::from(tint[c]) * TINT_ALPHA) as u8;
                }
            }
        }
        if let Some(blade) = blade {
            draw_edge(&mut tile, camera, &blade.edge, 2);
        }
        let tile = image::imageops::resize(&tile, tw, th, image::imageops::FilterType::Triangle);
        let (x, y) = ((k as u32 % COLUMNS) * tw, (k as u32 / COLUMNS) * th);
        image::imageops::replace(&mut out, &tile, i64::from(x), i64::from(y));
    }
    out
}

/// The organ's pieces through `renderer`'s camera over its image.
fn organ_view(
    renderer: &CameraRenderer,
    image: Option<&RgbImage>,
    grids: &[LabelGrid],
    blade: Option<&BladePose>,
    pieces: &[hullcut_sim::TriMesh],
) -> RgbImage {
    let camera = renderer.camera();
    let mut parts: Vec<Part> = pieces
        .iter()
        .enumerate()
        .map(|(k, m)| Part {
            label: FIRST_PIECE_LABEL + (k % 200) as u8,
            albedo: PIECE_ALBEDO[k % PIECE_ALBEDO.len()],
            mesh: m.clone(),
        })
        .collect();
    // The hulls occlude the organ where the hand or scalpel is in front of it.
    parts.extend(
        grids
            .iter()
            .filter_map(|(l, _, _, mesh)| mesh.as_ref().map(|m| Part { label: *l, albedo: [0.0; 3], mesh: m.clone() })),
    );
    let layers = renderer.render(&parts);
    let (w, h) = (camera.width, camera.height);
    let mut out = match image {
        Some(img) if img.dimensions() == (w, h) => img.clone(),
        _ => RgbImage::from_fn(w, h, |x, y| srgb(layers.rgb[(y * w + x) as usize])),
    };
    for (k, p) in out.pixels_mut().enumerate() {
        if layers.labels[k] >= FIRST_PIECE_LABEL {
            *p = srgb(layers.rgb[k]);
        }
    }
    if let Some(blade) = blade {
        draw_edge(&mut out, camera, &blade.edge, 1);
    }
    zoom_to(&out, camera, pieces)
}

/// The part of `img` around the organ's projection (with a margin of half its size on every
/// side), enlarged to [`ZOOM_WIDTH`] pixels across; `img` itself when nothing projects.
fn zoom_to(img: &RgbImage, camera: &Camera, pieces: &[hullcut_sim::TriMesh]) -> RgbImage {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pieces.iter().flat_map(|m| &m.vertices) {
        let q = camera.project(p);
        if q.depth > 0.0 && q.pixel.x.is_finite() && q.pixel.y.is_finite() {
            lo = [lo[0].min(q.pixel.x), lo[1].min(q.pixel.y)];
            hi = [hi[0].max(q.pixel.x), hi[1].max(q.pixel.y)];
        }
    }
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    if !(lo[0] < hi[0] && lo[1] < hi[1]) {
        return img.clone();
    }
    let margin = 0.5 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let x0 = (lo[0] - margin).clamp(0.0, w - 1.0);
    let y0 = (lo[1] - margin).clamp(0.0, h - 1.0);
    let x1 = (hi[0] + margin).clamp(x0 + 1.0, w);
    let y1 = (hi[1] + margin).clamp(y0 + 1.0, h);
    let crop = image::imageops::crop_imm(img, x0 as u32, y0 as u32, (x1 - x0) as u32, (y1 - y0) as u32).to_image();
    let height = (f64::from(ZOOM_WIDTH) * f64::from(crop.height()) / f64::from(crop.width())).round().max(1.0) as u32;
    image::imageops::resize(&crop, ZOOM_WIDTH, height, image::imageops::FilterType::CatmullRom)
}

/// Linear colour → 8-bit sRGB (gamma 2.2).
fn srgb(c: [f32; 3]) -> Rgb<u8> {
    Rgb(c.map(|v| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8))
}

/// Draws a world polyline through the camera's lens, `radius` pixels thick.
fn draw_edge(img: &mut RgbImage, camera: &Camera, edge: &[Point3<f64>], radius: i64) {
    for pair in edge.windows(2) {
        let (a, b) = (camera.project(&pair[0]), camera.project(&pair[1]));
        if !(a.depth > 0.0 && b.depth > 0.0) {
            continue;
        }
        let steps = ((b.pixel - a.pixel).norm().ceil() as usize).clamp(1, 4096);
        for s in 0..=steps {
            // Through the lens point by point: a long segment curves with the distortion.
            let t = s as f64 / steps as f64;
            let p = camera.project(&(pair[0] + (pair[1] - pair[0]) * t));
            if !p.visible {
                continue;
            }
            let (cx, cy) = (p.pixel.x.round() as i64, p.pixel.y.round() as i64);
            for dy in -radius..=radius {
                for dx in -radius..=radius {
                    let (x, y) = (cx + dx, cy + dy);
                    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
                        img.put_pixel(x as u32, y as u32, Rgb(EDGE_COLOUR));
                    }
                }
            }
        }
    }
}
