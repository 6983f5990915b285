//! Octree carving with whole-footprint tests and occlusion-aware labels.
//!
//! A cell is projected into every view; its footprint is the pixel rectangle around its eight
//! projected corners, widened by a margin (so that the curvature distortion gives projected edges,
//! and pixels that the footprint only touches, are included). With the summed-area tables of
//! [`Silhouette`], the label counts inside that rectangle cost four lookups per class:
//!
//! - a view *refutes* a cell when the footprint lies inside its image and holds only background;
//!   `carve_votes` refuting views carve it (1 is the classic hull; 2 keeps one bad silhouette from
//!   deleting real volume);
//! - a view *supports* a label when the footprint holds pixels of that label. Pixels of the other
//!   label or unknown ones never refute (the label may be hidden behind them: occlusion-aware,
//!   after Guan, Franco and Pollefeys 2008), and a label needs `min_support` supporting views;
//! - a cell that no view can refute but that is not uniform is split into eight, down to the leaf
//!   size; leaves that stay mixed are kept (the hull is conservative).
//!
//! A blade thinner than a cell survives: its pixels lie in the cell's footprint in every view that
//! sees it, so no such view refutes the cell.

use hullcut_dataset::label;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::{HullError, Silhouette};

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner, metres.
    pub min: Point3<f64>,
    /// Upper corner, metres.
    pub max: Point3<f64>,
}

impl Aabb {
    /// The default rig's workspace: x, y in ±0.2 m, z in 0..0.4 m.
    pub fn default_workspace() -> Self {
        let h = hullcut_rig::DEFAULT_WORKSPACE / 2.0;
        Aabb { min: Point3::new(-h, -h, 0.0), max: Point3::new(h, h, 2.0 * h) }
    }

    /// The longest side.
    pub fn extent(&self) -> f64 {
        (self.max - self.min).max()
    }
}

/// Settings of carving.
#[derive(Debug, Clone, PartialEq)]
pub struct HullParams {
    /// Region carved (a cube is made of its longest side, anchored at `min`).
    pub workspace: Aabb,
    /// Requested leaf size, metres; the effective one is `extent / 2^depth`, not larger.
    pub leaf_size: f64,
    /// Views that must see a cell as pure background to carve it (k of N).
    pub carve_votes: usize,
    /// Views that must see a label in a cell's footprint for the cell to carry that label.
    pub min_support: usize,
    /// Footprint margin, pixels.
    pub margin_px: f64,
    /// Octree level at which carving starts (8^level cells, in parallel).
    pub start_level: u32,
    /// A cell both labels reach goes to the one covering more of its footprints (summed over
    /// views), instead of carrying both.
    pub exclusive_labels: bool,
}

impl Default for HullParams {
    fn default() -> Self {
        HullParams {
            workspace: Aabb::default_workspace(),
            leaf_size: hullcut_rig::DEFAULT_WORKSPACE / 128.0,
            carve_votes: 1,
            min_support: 2,
            margin_px: 1.0,
            start_level: 3,
            exclusive_labels: true,
        }
    }
}

/// A kept octree cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Lower corner, metres.
    pub min: Point3<f64>,
    /// Side, metres (the leaf size, or a power-of-two multiple for a uniform cell).
    pub size: f64,
    /// Carries the hand label.
    pub hand: bool,
    /// Carries the scalpel label.
    pub scalpel: bool,
}

impl Cell {
    /// Whether the cell carries a label (`label::HAND` or `label::SCALPEL`).
    pub fn has(&self, l: u8) -> bool {
        match l {
            label::HAND => self.hand,
            label::SCALPEL => self.scalpel,
            _ => false,
        }
    }

    /// Centre of the cell.
    pub fn centre(&self) -> Point3<f64> {
        self.min + Vector3::repeat(self.size / 2.0)
    }
}

/// Counters of one carving run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CarveStats {
    /// Cell–view footprint tests (those that tell a lone refutation from a shared one included).
    pub footprint_tests: u64,
    /// Cells visited.
    pub cells_visited: u64,
    /// Views that took part.
    pub views_used: usize,
    /// Views left out (no mask).
    pub views_missing: usize,
    /// Cells kept although at least one view refuted them (the k-of-N rule at work).
    pub kept_against_refutation: u64,
    /// Kept cells with no label reaching `min_support` (occupied, label unknown).
    pub unlabelled_cells: u64,
    /// Lone refutations per view, one entry per view passed to [`carve`] (rig camera order; 0
    /// for a missing view): cells (of any octree level) that this view refuted while every other
    /// present view saw foreground in the cell's footprint, so that the view disagreed with all
    /// the others. Counted whether the cell was then carved (`carve_votes` 1) or kept (k of N).
    ///
    /// A consistent rig gives every view some: near the hull's surface, the part of the cone
    /// just outside one view's silhouette contour is refuted by that view alone. A view whose
    /// silhouette or calibration is off stands out with several times the others' count
    /// ([`CarveStats::most_disagreeing_view`]).
    ///
    /// With `carve_votes` 1, telling a lone refutation from a shared one costs footprint tests of
    /// the views after the refuting one until one of them does not see foreground (counted in
    /// `footprint_tests`; usually one, about 10% more tests at 128³, and no measurable time as the
    /// corners are already projected). Root cells that are leaves (`start_level` at the leaf
    /// level: a dense grid) are not checked: they project their corners view by view, so the
    /// check would double their cost.
    pub lone_refutations: Vec<u64>,
}

impl CarveStats {
    /// The view with the most lone refutations (the first of equals), or None when no view
    /// refuted a cell alone.
    pub fn most_disagreeing_view(&self) -> Option<usize> {
        let (k, &n) = self.lone_refutations.iter().enumerate().max_by_key(|&(k, n)| (n, std::cmp::Reverse(k)))?;
        (n > 0).then_some(k)
    }
}

/// The carved hull: kept cells with their labels.
#[derive(Debug, Clone)]
pub struct Occupancy {
    /// Kept cells (leaves, and larger uniform cells).
    pub cells: Vec<Cell>,
    /// Effective leaf size, metres.
    pub leaf_size: f64,
    /// Lower corner of the carved cube.
    pub origin: Point3<f64>,
    /// Leaves along each side of the carved cube (`2^depth`).
    pub resolution: usize,
    /// Counters.
    pub stats: CarveStats,
}

impl Occupancy {
    /// Volume of the cells carrying a label (or of every kept cell for `None`), cubic metres.
    pub fn volume(&self, l: Option<u8>) -> f64 {
        self.cells.iter().filter(|c| l.is_none_or(|l| c.has(l))).map(|c| c.size.powi(3)).sum()
    }

    /// Whether a point lies in a kept cell carrying the label (any kept cell for `None`), with a
    /// tolerance of a nanometre so that points on a face shared by two cells are never lost to
    /// rounding.
    pub fn contains(&self, p: &Point3<f64>, l: Option<u8>) -> bool {
        const EPS: f64 = 1e-9;
        self.cells.iter().any(|c| {
            l.is_none_or(|l| c.has(l)) && (0..3).all(|a| p[a] >= c.min[a] - EPS && p[a] <= c.min[a] + c.size + EPS)
        })
    }
}

/// What one view says about a cell.
#[derive(Debug, Clone, Copy)]
enum Verdict {
    /// Footprint inside the image and all background.
    Refutes,
    /// The view cannot tell (behind the camera, outside the image, beyond the lens' valid range).
    Abstains,
    /// Label counts inside the footprint.
    Sees(crate::silhouette::Counts),
}

/// A point projected into a view (pixel), or None where the view cannot tell (behind the camera,
/// beyond the lens' invertible range).
type Projected = Option<[f64; 2]>;

fn project(view: &Silhouette, p: &Point3<f64>) -> Projected {
    let cam = view.camera();
    let pc = cam.world_to_camera(p);
    if pc.z <= 1e-3 {
        return None;
    }
    let xn = nalgebra::Vector2::new(pc.x / pc.z, pc.y / pc.z);
    if xn.norm() >= view.monotonic_radius() {
        return None;
    }
    let uv = cam.normalized_to_pixel(cam.distortion.distort(xn));
    Some([uv.x, uv.y])
}

/// Offset of corner `k` (bits x, y, z) of a cell, in cell sizes.
fn corner_offset(k: usize) -> Vector3<f64> {
    Vector3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64)
}

/// `x.ceil()` for finite `x` without the libm call that `f64::ceil` becomes on baseline x86-64
/// (no SSE4.1 `roundsd`); four per footprint test took about 2% of carving. Beyond ±2^63 the cast
/// saturates, which only moves a footprint that lies off the image either way.
#[inline(always)]
fn ceil(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t < x { t + 1.0 } else { t }
}

/// `x.floor()`, likewise.
#[inline(always)]
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

fn judge(view: &Silhouette, corners: &[Projected; 8], margin: f64) -> Verdict {
    let cam = view.camera();
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for c in corners {
        let Some([u, v]) = *c else { return Verdict::Abstains };
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let (w, h) = (cam.width as f64, cam.height as f64);
    let (i0, j0, i1, j1) = (ceil(u0 - margin), ceil(v0 - margin), floor(u1 + margin), floor(v1 + margin));
    let inside = i0 >= 0.0 && j0 >= 0.0 && i1 <= w - 1.0 && j1 <= h - 1.0;
    let (ci0, cj0, ci1, cj1) = (i0.max(0.0), j0.max(0.0), i1.min(w - 1.0), j1.min(h - 1.0));
    if ci0 > ci1 || cj0 > cj1 {
        return Verdict::Abstains;
    }
    let counts = view.counts(ci0 as usize, cj0 as usize, ci1 as usize, cj1 as usize);
    if counts.foreground() == 0 {
        if inside { Verdict::Refutes } else { Verdict::Abstains }
    } else {
        Verdict::Sees(counts)
    }
}

struct Carver<'a> {
    views: Vec<&'a Silhouette>,
    params: &'a HullParams,
    leaf_level: u32,
}

#[derive(Default)]
struct Local {
    cells: Vec<Cell>,
    stats: CarveStats,
}

impl Local {
    /// Counts a lone refutation by present view `v` of `n` (the counts are allocated on the first,
    /// not for every root cell).
    fn lone(&mut self, v: usize, n: usize) {
        if self.stats.lone_refutations.len() < n {
            self.stats.lone_refutations.resize(n, 0);
        }
        self.stats.lone_refutations[v] += 1;
    }
}

impl Carver<'_> {
    /// The corners of a cell in every view.
    fn corners(&self, min: &Point3<f64>, size: f64) -> Vec<[Projected; 8]> {
        self.views.iter().map(|v| std::array::from_fn(|k| project(v, &(min + corner_offset(k) * size)))).collect()
    }

    /// Whether every view after `v` sees foreground in the cell's footprint (stopping at the first
    /// that does not).
    #[inline(never)]
    fn rest_see(&self, v: usize, corners: &[[Projected; 8]], out: &mut Local) -> bool {
        self.views.iter().zip(corners).skip(v + 1).all(|(view, c)| {
            out.stats.footprint_tests += 1;
            matches!(judge(view, c, self.params.margin_px), Verdict::Sees(_))
        })
    }

    /// Visits a cell whose corners are already projected (`corners[view]`); children reuse the
    /// parent's corners and share the 19 new lattice points between them.
    /// A root cell (`corners` None) projects its corners itself: all views up front when it may be
    /// split, view by view otherwise (a dense grid of leaves then stops at the first refuting view).
    fn visit(&self, min: Point3<f64>, size: f64, level: u32, corners: Option<&[[Projected; 8]]>, out: &mut Local) {
        let owned;
        let corners = match corners {
            None if level < self.leaf_level => {
                owned = self.corners(&min, size);
                Some(&owned[..])
            }
            other => other,
        };
        out.stats.cells_visited += 1;
        let (mut refutes, mut hand, mut scalpel, mut uniform) = (0usize, 0usize, 0usize, true);
        // Views so far that saw foreground, and the last refuting one.
        let (mut sees, mut refuter) = (0usize, 0usize);
        let (mut hand_share, mut scalpel_share) = (0.0f64, 0.0f64);
        let mut uniform_label = None;
        for (v, view) in self.views.iter().enumerate() {
            out.stats.footprint_tests += 1;
            let lazy;
            let view_corners = match corners {
                Some(c) => &c[v],
                None => {
                    lazy = std::array::from_fn(|k| project(view, &(min + corner_offset(k) * size)));
                    &lazy
                }
            };
            match judge(view, view_corners, self.params.margin_px) {
                Verdict::Refutes => {
                    refutes += 1;
                    uniform = false;
                    if refutes >= self.params.carve_votes {
                        // Lone only if it is the first refutation and every view before saw
                        // foreground: then the views after it decide. A root leaf (no corners:
                        // a dense grid) is not checked, as that would double its cost.
                        if refutes == 1
                            && sees == v
                            && self.views.len() > 1
                            && let Some(corners) = corners
                            && self.rest_see(v, corners, out)
                        {
                            out.lone(v, self.views.len());
                        }
                        return;
                    }
                    refuter = v;
                }
                Verdict::Abstains => uniform = false,
                Verdict::Sees(c) => {
                    sees += 1;
                    hand += usize::from(c.hand > 0);
                    scalpel += usize::from(c.scalpel > 0);
                    hand_share += f64::from(c.hand) / f64::from(c.total);
                    scalpel_share += f64::from(c.scalpel) / f64::from(c.total);
                    let single = if c.hand == c.total {
                        Some(label::HAND)
                    } else if c.scalpel == c.total {
                        Some(label::SCALPEL)
                    } else {
                        None
                    };
                    match (single, uniform_label) {
                        (Some(l), None) => uniform_label = Some(l),
                        (Some(l), Some(u)) if l == u => {}
                        _ => uniform = false,
                    }
                }
            }
        }
        if refutes == 1 && sees + 1 == self.views.len() && sees > 0 {
            out.lone(refuter, self.views.len());
        }
        if let (true, Some(corners)) = (level < self.leaf_level && !uniform, corners) {
            let half = size / 2.0;
            // The 3x3x3 lattice of the children's corners, per view (index a + 3b + 9c).
            let lattice: Vec<[Projected; 27]> = self
                .views
                .iter()
                .zip(corners)
                .map(|(view, parent)| {
                    std::array::from_fn(|n| {
                        let (a, b, c) = (n % 3, (n / 3) % 3, n / 9);
                        if a % 2 == 0 && b % 2 == 0 && c % 2 == 0 {
                            parent[a / 2 + 2 * (b / 2) + 4 * (c / 2)]
                        } else {
                            project(view, &(min + Vector3::new(a as f64, b as f64, c as f64) * half))
                        }
                    })
                })
                .collect();
            for k in 0..8 {
                let child: Vec<[Projected; 8]> = lattice
                    .iter()
                    .map(|l| {
                        std::array::from_fn(|m| {
                            let (a, b, c) =
                                ((k & 1) + (m & 1), ((k >> 1) & 1) + ((m >> 1) & 1), ((k >> 2) & 1) + ((m >> 2) & 1));
                            l[a + 3 * b + 9 * c]
                        })
                    })
                    .collect();
                self.visit(min + corner_offset(k) * half, half, level + 1, Some(&child), out);
            }
            return;
        }
        if refutes > 0 {
            out.stats.kept_against_refutation += 1;
        }
        let (mut has_hand, mut has_scalpel) = (hand >= self.params.min_support, scalpel >= self.params.min_support);
        if self.params.exclusive_labels && has_hand && has_scalpel {
            has_hand = hand_share >= scalpel_share;
            has_scalpel = !has_hand;
        }
        let cell = Cell { min, size, hand: has_hand, scalpel: has_scalpel };
        if !cell.hand && !cell.scalpel {
            out.stats.unlabelled_cells += 1;
        }
        out.cells.push(cell);
    }
}

/// Checks the parameters against the views; the leaf level and the carved cube's side.
pub(crate) fn check(views: &[Option<Silhouette>], params: &HullParams) -> Result<(u32, f64), HullError> {
    if params.leaf_size.is_nan() || params.leaf_size <= 0.0 || params.carve_votes == 0 {
        return Err(HullError::Params(format!(
            "leaf_size must be positive and carve_votes at least 1 (got {} m, {})",
            params.leaf_size, params.carve_votes
        )));
    }
    let present = views.iter().flatten().count();
    if present < params.carve_votes {
        return Err(HullError::TooFewViews { present, needed: params.carve_votes });
    }
    let extent = params.workspace.extent();
    if extent.is_nan() || extent <= 0.0 {
        return Err(HullError::Params("the workspace is empty".into()));
    }
    Ok(((extent / params.leaf_size).log2().ceil().max(0.0) as u32, extent))
}

/// Carves the hull of the views' silhouettes (`None` = a missing view, left out and counted).
pub fn carve(views: &[Option<Silhouette>], params: &HullParams) -> Result<Occupancy, HullError> {
    let (leaf_level, extent) = check(views, params)?;
    let present: Vec<&Silhouette> = views.iter().flatten().collect();
    let start = params.start_level.min(leaf_level);
    let carver = Carver { views: present, params, leaf_level };
    let n = 1usize << start;
    let size = extent / n as f64;
    let origin = params.workspace.min;
    let locals: Vec<Local> = (0..n * n * n)
        .into_par_iter()
        .map(|k| {
            let (i, j, l) = (k % n, (k / n) % n, k / (n * n));
            let min = origin + Vector3::new(i as f64, j as f64, l as f64) * size;
            let mut local = Local::default();
            carver.visit(min, size, start, None, &mut local);
            local
        })
        .collect();
    let mut stats = CarveStats {
        views_used: carver.views.len(),
        views_missing: views.len() - carver.views.len(),
        lone_refutations: vec![0; views.len()],
        ..CarveStats::default()
    };
    // Present view n is entry rig_index[n] of `views`.
    let rig_index: Vec<usize> = views.iter().enumerate().filter(|(_, v)| v.is_some()).map(|(k, _)| k).collect();
    let mut cells = Vec::new();
    for local in locals {
        for (&k, n) in rig_index.iter().zip(&local.stats.lone_refutations) {
            stats.lone_refutations[k] += n;
        }
        cells.extend(local.cells);
        stats.footprint_tests += local.stats.footprint_tests;
        stats.cells_visited += local.stats.cells_visited;
        stats.kept_against_refutation += local.stats.kept_against_refutation;
        stats.unlabelled_cells += local.stats.unlabelled_cells;
    }
    let resolution = 1usize << leaf_level;
    Ok(Occupancy { cells, leaf_size: extent / resolution as f64, origin, resolution, stats })
}
