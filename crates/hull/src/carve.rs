//! Octree carving with whole-footprint tests and occlusion-aware labels.
//!
//! A cell is projected into every view; its footprint is the pixels whose centres lie in the
//! rectangle around its eight projected corners (masks are samples at pixel centres), widened by a
//! margin that bounds how far the lens' distortion bows a projected edge out of that rectangle
//! ([`Silhouette::curvature`] times the rectangle's size squared, plus `margin_px` for rounding);
//! a cell smaller than a pixel that holds no pixel centre takes the pixels whose centres bracket
//! it. With the summed-area tables of [`Silhouette`], the label counts inside that rectangle cost
//! four lookups per class:
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
//!
//! The working volume bounds carving: the octree's cube (leaf size × 2^depth, anchored at the
//! volume's lower corner, so the leaf is exactly the one asked for) is clipped to the volume's box,
//! and a cell that fewer than `min_views` views can see (its footprint inside their image) is
//! outside the volume too: a cell only one or two cameras see cannot be carved by the others, and
//! keeping it would leave a ghost volume.

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
    /// A cube of side `side` with its lower corner at `min`.
    pub fn cube(min: Point3<f64>, side: f64) -> Self {
        Aabb { min, max: min + Vector3::repeat(side) }
    }

    /// The longest side.
    pub fn extent(&self) -> f64 {
        (self.max - self.min).max()
    }

    /// Whether a point lies inside (faces included).
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (0..3).all(|a| p[a] >= self.min[a] && p[a] <= self.max[a])
    }

    /// Checks the box: finite corners and `min < max` on every axis.
    pub fn check(&self) -> Result<(), HullError> {
        let finite = self.min.iter().chain(self.max.iter()).all(|c| c.is_finite());
        if !finite || (0..3).any(|a| self.min[a] >= self.max[a]) {
            return Err(HullError::Volume(format!(
                "the working volume must have finite corners with min < max on every axis, got min {:?}, max {:?}",
                [self.min.x, self.min.y, self.min.z],
                [self.max.x, self.max.y, self.max.z]
            )));
        }
        Ok(())
    }
}

/// Settings of carving.
#[derive(Debug, Clone, PartialEq)]
pub struct HullParams {
    /// The working volume: cells outside it are never kept ([`crate::WorkingVolume`] says where it
    /// comes from).
    pub workspace: Aabb,
    /// Leaf size, metres: the octree's cube has a side of `leaf_size × 2^depth` (the smallest
    /// that holds the volume), so the leaves are exactly this size.
    pub leaf_size: f64,
    /// Views that must see a cell as pure background to carve it (k of N).
    pub carve_votes: usize,
    /// Views that must see a label in a cell's footprint for the cell to carry that label.
    pub min_support: usize,
    /// Views that must see a cell (its footprint inside their image) for it to be kept; fewer, and
    /// the cell is outside the volume. At most the views present.
    pub min_views: usize,
    /// Footprint margin for rounding, pixels (added to the distortion's bound).
    pub margin_px: f64,
    /// Octree level at which carving starts (8^level cells, in parallel).
    pub start_level: u32,
    /// A cell both labels reach goes to the one covering more of its footprints (summed over
    /// views), instead of carrying both.
    pub exclusive_labels: bool,
    /// Drop the outer shell of slivers over solid leaves: a leaf whose centre lies outside the hull
    /// (`carve_votes` views see background there) is dropped where it is the outermost layer over
    /// a solid leaf; a structure thinner than a leaf (a blade) keeps its
    /// slivers. Without it every leaf touching the hull is kept, which fattens it by half a leaf
    /// on average.
    pub trim_slivers: bool,
    /// Leaves carrying the scalpel label are carved again this many octree levels finer after
    /// carving ([`refine_label`]; 0: off, at most [`MAX_REFINE_LEVELS`]). A blade is thinner than
    /// a leaf, so at the leaf size its hull is mostly leaves that the exact hull fills in part;
    /// one level finer brings it close to the exact hull (lab8's pointed blade at 1 mm: IoU 0.72
    /// to 0.90) for the cost of the blade's few thousand leaves, while the hand keeps its leaf. The occupancy's `leaf_size` is then the finer one. [`carve_within`] does not
    /// refine.
    pub blade_levels: u32,
}

/// The most levels [`refine_label`] refines by (a leaf split into 8^3 = 512 cells).
pub const MAX_REFINE_LEVELS: u32 = 3;

/// The deepest octree carving accepts (65,536 leaves per side).
pub const MAX_DEPTH: u32 = 16;

impl HullParams {
    /// The default settings for a working volume and a leaf size: classic carving (one refuting
    /// view carves), labels supported by two views, cells seen by at least three views.
    pub fn new(workspace: Aabb, leaf_size: f64) -> Self {
        HullParams {
            workspace,
            leaf_size,
            carve_votes: 1,
            min_support: 2,
            min_views: 3,
            margin_px: 0.05,
            start_level: 3,
            exclusive_labels: true,
            trim_slivers: false,
            blade_levels: 0,
        }
    }

    /// The octree's depth (leaves per side = 2^depth) for this volume and leaf.
    pub fn depth(&self) -> Result<u32, HullError> {
        let extent = self.workspace.extent();
        let depth = (extent / self.leaf_size).log2().ceil().max(0.0);
        if depth.is_nan() || depth > f64::from(MAX_DEPTH) {
            return Err(HullError::Params(format!(
                "a {:.3} mm leaf over a {:.3} m volume needs more than 2^{MAX_DEPTH} leaves per side",
                self.leaf_size * 1e3,
                extent
            )));
        }
        Ok(depth as u32)
    }

    /// The side of the octree's cube, metres.
    pub fn cube_side(&self) -> Result<f64, HullError> {
        Ok(self.leaf_size * f64::from(1u32 << self.depth()?))
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
    /// Its centre lies inside the hull (larger uniform cells always).
    pub solid: bool,
    /// The view (by index in the views passed to the carver) that saw only background in this
    /// kept cell's footprint: with [`HullParams::carve_votes`] 2 a cell survives one refuting
    /// view, and which one it was tells the hull of every other view's silhouette apart (the cells
    /// with no refuter or with that view as refuter). The last of them when several refuted it
    /// (`carve_votes` over 2); None when no view refuted it.
    pub refuted_by: Option<u16>,
}

// `#[inline]` on these: other crates call them once per cell in their hot loops (the labeller's
// projections of the hand's cells, 665,081 calls in 20 frame sets), and without it a call into
// another crate is not inlined (docs/benchmarks.md, "Calls across crates inlined").
impl Cell {
    /// Whether the cell carries a label (`label::HAND` or `label::SCALPEL`).
    #[inline]
    pub fn has(&self, l: u8) -> bool {
        match l {
            label::HAND => self.hand,
            label::SCALPEL => self.scalpel,
            _ => false,
        }
    }

    /// Centre of the cell.
    #[inline]
    pub fn centre(&self) -> Point3<f64> {
        self.min + Vector3::repeat(self.size / 2.0)
    }

    /// The radius of a ball around [`Cell::centre`] that holds the whole cell: its half-diagonal,
    /// rounded up (√3 / 2 of its side, to six digits).
    #[inline]
    pub fn bounding_radius(&self) -> f64 {
        0.866_026 * self.size
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
    /// Cells dropped because fewer than `min_views` views see them (outside the volume), or fewer
    /// see foreground in them than keeping any part of them would need (no view refuted them).
    pub unseen_cells: u64,
    /// Leaves dropped as slivers beside solid leaves ([`HullParams::trim_slivers`]).
    pub slivers_trimmed: u64,
    /// Leaves carved again at a finer leaf ([`refine_label`]).
    pub leaves_refined: u64,
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
    /// The view cannot tell: a corner lies behind the camera or beyond the lens' valid range (the
    /// cell may still be partly in view, with anything in it).
    Unknown,
    /// The footprint lies partly off the image, with only background on the part inside it: no
    /// part of the cell that this view sees whole can be kept.
    Partial,
    /// The footprint lies wholly off the image.
    Off,
    /// Label counts inside the footprint (`inside`: the whole footprint lies in the image).
    Sees {
        /// The counts.
        counts: crate::silhouette::Counts,
        /// The footprint lies inside the image.
        inside: bool,
    },
}

/// A point projected into a view.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Projected {
    /// Its pixel (outside the image, maybe far, for a point beyond the field's radius, which is
    /// clamped to it).
    Pixel([f64; 2]),
    /// Behind the camera (or within a millimetre of its plane).
    Behind,
    /// Beyond the lens' invertible radius of a camera whose image reaches that far.
    Unknown,
}

#[inline(always)]
pub(crate) fn project(view: &Silhouette, p: &Point3<f64>) -> Projected {
    let cam = view.camera();
    let pc = cam.world_to_camera(p);
    if pc.z <= 1e-3 {
        return Projected::Behind;
    }
    let inv = 1.0 / pc.z;
    let mut xn = nalgebra::Vector2::new(pc.x * inv, pc.y * inv);
    let r2 = xn.norm_squared();
    let limit = view.field_radius().unwrap_or(view.monotonic_radius());
    if r2 >= limit * limit {
        if view.field_radius().is_none() {
            return Projected::Unknown;
        }
        xn *= limit / r2.sqrt();
    }
    let uv = cam.normalized_to_pixel(cam.distortion.distort(xn));
    Projected::Pixel([uv.x, uv.y])
}

/// The 3x3x3 lattice of a split cell's children's corners, per view (index a + 3b + 9c): the
/// parent's eight corners and the 19 new points between them. Projecting a view's points lazily,
/// on a child's first use, was tried: most views end up needed (a child that no view refutes
/// consults them all), and the bookkeeping cost more than it saved.
#[derive(Default)]
#[allow(missing_debug_implementations)] // scratch, never printed
struct Lattice {
    points: Vec<[Projected; 27]>,
}

impl Lattice {
    /// Fills the lattice of a cell at `min`, `2 half` wide, from its corners per view.
    fn fill(&mut self, views: &[&Silhouette], min: Point3<f64>, half: f64, parent: impl Fn(usize, usize) -> Projected) {
        self.points.clear();
        for (v, view) in views.iter().enumerate() {
            self.points.push(std::array::from_fn(|n| {
                let (a, b, c) = (n % 3, (n / 3) % 3, n / 9);
                if a % 2 == 0 && b % 2 == 0 && c % 2 == 0 {
                    parent(v, a / 2 + 2 * (b / 2) + 4 * (c / 2))
                } else {
                    project(view, &(min + Vector3::new(a as f64, b as f64, c as f64) * half))
                }
            }));
        }
    }
}

/// Where a cell's corners come from: projected for it (a root cell), child `k` (bits x, y, z) of
/// a split cell's [`Lattice`], or nowhere yet (a root leaf of a dense grid, projected view by view).
#[derive(Clone, Copy)]
#[allow(missing_debug_implementations)] // borrowed scratch, never printed
enum Corners<'a> {
    Own(&'a [[Projected; 8]]),
    Child(&'a Lattice, usize),
    Lazy,
}

/// Lattice index of corner `m` of child `k` (both bits x, y, z) in its parent's 3x3x3 lattice.
const CHILD_CORNER: [[u8; 8]; 8] = {
    let mut t = [[0u8; 8]; 8];
    let mut k = 0;
    while k < 8 {
        let mut m = 0;
        while m < 8 {
            let (a, b, c) = ((k & 1) + (m & 1), ((k >> 1) & 1) + ((m >> 1) & 1), ((k >> 2) & 1) + ((m >> 2) & 1));
            t[k][m] = (a + 3 * b + 9 * c) as u8;
            m += 1;
        }
        k += 1;
    }
    t
};

impl Corners<'_> {
    /// Corner `m` in view `v` (unknown for a lazy root, which projects its own).
    #[inline(always)]
    fn corner(&self, v: usize, m: usize) -> Projected {
        match *self {
            Corners::Own(c) => c[v][m],
            Corners::Child(lattice, k) => lattice.points[v][CHILD_CORNER[k][m] as usize],
            Corners::Lazy => Projected::Unknown,
        }
    }

    fn known(&self) -> bool {
        !matches!(self, Corners::Lazy)
    }
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

fn judge(view: &Silhouette, corner: impl Fn(usize) -> Projected, margin: f64) -> Verdict {
    let (ci0, cj0, ci1, cj1, inside) = match footprint_rect(view, corner, margin) {
        Footprint::Off => return Verdict::Off,
        Footprint::Unknown => return Verdict::Unknown,
        Footprint::Pixels { i0, j0, i1, j1, inside } => (i0, j0, i1, j1, inside),
    };
    if !view.may_have_foreground(ci0, cj0, ci1, cj1) {
        return if inside { Verdict::Refutes } else { Verdict::Partial };
    }
    let counts = view.counts(ci0, cj0, ci1, cj1);
    if counts.foreground() == 0 {
        if inside { Verdict::Refutes } else { Verdict::Partial }
    } else {
        Verdict::Sees { counts, inside }
    }
}

/// A cell's footprint in a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Footprint {
    /// The cell lies wholly behind the camera or off the image.
    Off,
    /// The view cannot tell (a corner behind the camera or beyond the lens' valid range).
    Unknown,
    /// The pixels whose centres the footprint covers, clipped to the image (inclusive bounds).
    Pixels {
        /// First column.
        i0: usize,
        /// First row.
        j0: usize,
        /// Last column.
        i1: usize,
        /// Last row.
        j1: usize,
        /// The footprint lies wholly inside the image.
        inside: bool,
    },
}

/// The rectangle of pixels a cell's projected corners span, grown by `margin` pixels plus the
/// lens' bowing over the rectangle (see [`judge`]).
#[inline(always)]
fn footprint_rect(view: &Silhouette, corner: impl Fn(usize) -> Projected, margin: f64) -> Footprint {
    let cam = view.camera();
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let (mut behind, mut unknown) = (0, false);
    for m in 0..8 {
        let [u, v] = match corner(m) {
            Projected::Pixel(uv) => uv,
            Projected::Behind => {
                behind += 1;
                continue;
            }
            Projected::Unknown => {
                unknown = true;
                continue;
            }
        };
        // Plain comparisons (minsd/maxsd): projections are finite, so `f64::min`'s NaN handling
        // (half of this function's time) is not needed.
        u0 = if u < u0 { u } else { u0 };
        v0 = if v < v0 { v } else { v0 };
        u1 = if u > u1 { u } else { u1 };
        v1 = if v > v1 { v } else { v1 };
    }
    if behind == 8 {
        // A box wholly behind the camera: nothing of it is in view.
        return Footprint::Off;
    }
    if behind > 0 || unknown {
        return Footprint::Unknown;
    }
    let (w, h) = (cam.width as f64, cam.height as f64);
    let extent = (u1 - u0).max(v1 - v0);
    let margin = margin + view.curvature() * extent * extent;
    let (mut i0, mut j0, mut i1, mut j1) =
        (ceil(u0 - margin), ceil(v0 - margin), floor(u1 + margin), floor(v1 + margin));
    // No pixel centre inside: the two whose centres bracket the rectangle.
    if i0 > i1 {
        std::mem::swap(&mut i0, &mut i1);
    }
    if j0 > j1 {
        std::mem::swap(&mut j0, &mut j1);
    }
    let inside = i0 >= 0.0 && j0 >= 0.0 && i1 <= w - 1.0 && j1 <= h - 1.0;
    let (ci0, cj0, ci1, cj1) = (i0.max(0.0), j0.max(0.0), i1.min(w - 1.0), j1.min(h - 1.0));
    if ci0 > ci1 || cj0 > cj1 {
        return Footprint::Off;
    }
    Footprint::Pixels { i0: ci0 as usize, j0: cj0 as usize, i1: ci1 as usize, j1: cj1 as usize, inside }
}

/// A cell's footprint in one view, as carving computes it.
pub fn footprint(view: &Silhouette, cell: &Cell, margin_px: f64) -> Footprint {
    footprint_rect(view, |k| project(view, &(cell.min + corner_offset(k) * cell.size)), margin_px)
}

/// Where a cell lies against the working volume's box.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BoxSide {
    Inside,
    Straddles,
    Outside,
}

/// The working volume's upper corner in leaves from its lower one (the octree's origin). Cells
/// are compared with it in whole leaves, as the GPU carver does, so both agree on every cell.
pub(crate) fn box_in_leaves(params: &HullParams) -> Vector3<f64> {
    (params.workspace.max - params.workspace.min) / params.leaf_size
}

/// Where the cell at leaf coordinates `lo` (whole numbers) and `n` leaves wide lies against a box
/// from the origin to `hi` (leaves); a leaf straddling the box counts as inside when its centre is.
fn box_side(hi: &Vector3<f64>, lo: [f64; 3], n: f64) -> BoxSide {
    if (0..3).any(|a| lo[a] >= hi[a]) {
        return BoxSide::Outside;
    }
    if (0..3).all(|a| lo[a] + n <= hi[a]) {
        return BoxSide::Inside;
    }
    if n <= 1.0 {
        return if (0..3).all(|a| lo[a] + 0.5 <= hi[a]) { BoxSide::Inside } else { BoxSide::Outside };
    }
    BoxSide::Straddles
}

struct Carver<'a> {
    views: Vec<&'a Silhouette>,
    params: &'a HullParams,
    leaf_level: u32,
    /// `min_views`, at most the views present.
    min_views: usize,
    /// The volume's box in leaves ([`box_in_leaves`]).
    box_hi: Vector3<f64>,
}

#[derive(Default)]
#[allow(missing_debug_implementations)] // per-thread scratch, never printed
struct Local {
    cells: Vec<Cell>,
    stats: CarveStats,
    /// One lattice for each octree level, reused from cell to cell.
    lattices: Vec<Lattice>,
    /// A root cell's own corners, reused.
    roots: Vec<[Projected; 8]>,
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
    /// Visits a root cell (a start cell, or a seed of [`carve_within`]): its corners are projected
    /// here, all views up front when it may be split, view by view otherwise.
    fn visit_root(&self, min: Point3<f64>, size: f64, level: u32, out: &mut Local) {
        if level >= self.leaf_level {
            self.visit(min, size, level, Corners::Lazy, out);
            return;
        }
        let mut own = std::mem::take(&mut out.roots);
        own.clear();
        own.extend(self.views.iter().map(|v| std::array::from_fn(|k| project(v, &(min + corner_offset(k) * size)))));
        self.visit(min, size, level, Corners::Own(&own), out);
        out.roots = own;
    }

    /// What the pixels nearest a point's projections say: whether it lies inside the hull as the
    /// pixel centres sample it (fewer than `carve_votes` views see background there), and how many
    /// views see hand and scalpel there.
    fn at_centre(&self, p: &Point3<f64>) -> (bool, usize, usize) {
        let (mut refuting, mut hand, mut scalpel) = (0, 0, 0);
        for view in &self.views {
            let Projected::Pixel([u, v]) = project(view, p) else { continue };
            let cam = view.camera();
            let (i, j) = ((u + 0.5).floor(), (v + 0.5).floor());
            if i >= 0.0 && j >= 0.0 && i < cam.width as f64 && j < cam.height as f64 {
                let (i, j) = (i as usize, j as usize);
                let c = view.counts(i, j, i, j);
                refuting += usize::from(c.foreground() == 0);
                hand += c.hand as usize;
                scalpel += c.scalpel as usize;
            }
        }
        (refuting < self.params.carve_votes, hand, scalpel)
    }

    /// Whether every view after `v` sees foreground in the cell's footprint (stopping at the first
    /// that does not).
    #[inline(never)]
    fn rest_see(&self, v: usize, corners: Corners, out: &mut Local) -> bool {
        self.views.iter().enumerate().skip(v + 1).all(|(k, view)| {
            out.stats.footprint_tests += 1;
            matches!(judge(view, |m| corners.corner(k, m), self.params.margin_px), Verdict::Sees { .. })
        })
    }

    /// Visits a cell whose corners are already projected (`corners[view]`); children reuse the
    /// parent's corners and share the 19 new lattice points between them.
    /// A root cell (`corners` None) projects its corners itself: all views up front when it may be
    /// split, view by view otherwise (a dense grid of leaves then stops at the first refuting view).
    ///
    /// A cell outside the working volume's box is dropped; a leaf straddling the box is kept only
    /// if its centre lies inside, and a larger cell straddling it is split.
    fn visit(&self, min: Point3<f64>, size: f64, level: u32, corners: Corners, out: &mut Local) {
        out.stats.cells_visited += 1;
        let leaf = self.params.leaf_size;
        let lo = [0, 1, 2].map(|a| ((min[a] - self.params.workspace.min[a]) / leaf).round());
        let side = box_side(&self.box_hi, lo, f64::from(1u32 << (self.leaf_level - level)));
        if side == BoxSide::Outside {
            return;
        }
        let (mut refutes, mut hand, mut scalpel) = (0usize, 0usize, 0usize);
        let mut uniform = side == BoxSide::Inside;
        // Views so far that saw foreground, and the last refuting one.
        let (mut sees, mut refuter) = (0usize, 0usize);
        // Views whose image holds the whole footprint, views that may see part of the cell, and
        // views that cannot tell.
        let (mut covered, mut reach, mut unknown) = (0usize, 0usize, 0usize);
        let (mut hand_share, mut scalpel_share) = (0.0f64, 0.0f64);
        let mut uniform_label = None;
        for (v, view) in self.views.iter().enumerate() {
            out.stats.footprint_tests += 1;
            let verdict = if corners.known() {
                judge(view, |m| corners.corner(v, m), self.params.margin_px)
            } else {
                let own: [Projected; 8] = std::array::from_fn(|k| project(view, &(min + corner_offset(k) * size)));
                judge(view, |m| own[m], self.params.margin_px)
            };
            match verdict {
                Verdict::Refutes => {
                    refutes += 1;
                    covered += 1;
                    reach += 1;
                    uniform = false;
                    if refutes >= self.params.carve_votes {
                        // Lone only if it is the first refutation and every view before saw
                        // foreground: then the views after it decide. A root leaf (no corners:
                        // a dense grid) is not checked, as that would double its cost.
                        if refutes == 1
                            && sees == v
                            && self.views.len() > 1
                            && corners.known()
                            && self.rest_see(v, corners, out)
                        {
                            out.lone(v, self.views.len());
                        }
                        return;
                    }
                    refuter = v;
                }
                Verdict::Unknown => {
                    uniform = false;
                    reach += 1;
                    unknown += 1;
                }
                Verdict::Partial => {
                    uniform = false;
                    reach += 1;
                }
                Verdict::Off => uniform = false,
                Verdict::Sees { counts: c, inside } => {
                    sees += 1;
                    reach += 1;
                    covered += usize::from(inside);
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
        // A part of the cell is kept only if `min_views` views see it whole with fewer than
        // `carve_votes` refuting it; a view that sees only background in the cell's footprint
        // refutes every part it sees whole. So fewer views reaching the cell, or fewer that see
        // foreground in it (or cannot tell) than `min_views - (carve_votes - 1)`, and no part of it
        // can be kept: outside the volume, or seen as foreground by too few views.
        let may_keep = sees + unknown + self.params.carve_votes - 1;
        if reach < self.min_views || may_keep < self.min_views {
            out.stats.unseen_cells += 1;
            return;
        }
        let split = !uniform || covered < self.min_views;
        if level < self.leaf_level && split && corners.known() {
            let half = size / 2.0;
            // The children's corners, in this level's reused lattice.
            if out.lattices.len() <= level as usize {
                out.lattices.resize_with(level as usize + 1, Lattice::default);
            }
            let mut lattice = std::mem::take(&mut out.lattices[level as usize]);
            lattice.fill(&self.views, min, half, |v, m| corners.corner(v, m));
            for k in 0..8 {
                self.visit(min + corner_offset(k) * half, half, level + 1, Corners::Child(&lattice, k), out);
            }
            out.lattices[level as usize] = lattice;
            return;
        }
        if covered < self.min_views {
            out.stats.unseen_cells += 1;
            return;
        }
        if refutes > 0 {
            out.stats.kept_against_refutation += 1;
        }
        // A solid leaf takes its labels from the pixels at its centre, as it took its place; a
        // larger (uniform) cell or a sliver from its footprints.
        let (solid, centre_hand, centre_scalpel) = if level < self.leaf_level {
            (true, hand, scalpel)
        } else {
            let (solid, h, s) = self.at_centre(&(min + Vector3::repeat(size / 2.0)));
            if solid { (true, h, s) } else { (false, hand, scalpel) }
        };
        let (mut has_hand, mut has_scalpel) =
            (centre_hand >= self.params.min_support, centre_scalpel >= self.params.min_support);
        if self.params.exclusive_labels && has_hand && has_scalpel {
            has_hand = match centre_hand.cmp(&centre_scalpel) {
                std::cmp::Ordering::Equal => hand_share >= scalpel_share,
                order => order.is_gt(),
            };
            has_scalpel = !has_hand;
        }
        // `refuter` is the present view's index; `gather` turns it into the rig's.
        let refuted_by = (refutes > 0).then_some(refuter as u16);
        out.cells.push(Cell { min, size, hand: has_hand, scalpel: has_scalpel, solid, refuted_by });
    }
}

/// Checks the parameters against the views; the leaf level and the carved cube's side.
pub(crate) fn check(views: &[Option<Silhouette>], params: &HullParams) -> Result<(u32, f64), HullError> {
    if !(params.leaf_size.is_finite() && params.leaf_size > 0.0) || params.carve_votes == 0 || params.min_views == 0 {
        return Err(HullError::Params(format!(
            "leaf_size must be positive and carve_votes and min_views at least 1 (got {} m, {}, {})",
            params.leaf_size, params.carve_votes, params.min_views
        )));
    }
    if views.len() > usize::from(u16::MAX) {
        // A kept cell names its refuting view in a u16 (`Cell::refuted_by`).
        return Err(HullError::Params(format!("{} views; carving takes at most {}", views.len(), u16::MAX)));
    }
    if !(params.margin_px.is_finite() && params.margin_px >= 0.0) {
        return Err(HullError::Params(format!("margin_px must be 0 or more, got {}", params.margin_px)));
    }
    let present = views.iter().flatten().count();
    if present < params.carve_votes {
        return Err(HullError::TooFewViews { present, needed: params.carve_votes });
    }
    params.workspace.check()?;
    let depth = params.depth()?;
    Ok((depth, params.leaf_size * f64::from(1u32 << depth)))
}

/// Sums the workers' cells and counters into one occupancy.
fn gather(views: &[Option<Silhouette>], carver: &Carver, locals: Vec<Local>, side: f64) -> Occupancy {
    let mut stats = CarveStats {
        views_used: carver.views.len(),
        views_missing: views.len() - carver.views.len(),
        lone_refutations: vec![0; views.len()],
        ..CarveStats::default()
    };
    // Present view n is entry rig_index[n] of `views`.
    let rig_index: Vec<usize> = views.iter().enumerate().filter(|(_, v)| v.is_some()).map(|(k, _)| k).collect();
    let mut cells = Vec::with_capacity(locals.iter().map(|l| l.cells.len()).sum());
    for local in locals {
        for (&k, n) in rig_index.iter().zip(&local.stats.lone_refutations) {
            stats.lone_refutations[k] += n;
        }
        cells.extend(local.cells.into_iter().map(|c| Cell {
            refuted_by: c.refuted_by.and_then(|v| rig_index.get(usize::from(v)).map(|&k| k as u16)),
            ..c
        }));
        stats.footprint_tests += local.stats.footprint_tests;
        stats.cells_visited += local.stats.cells_visited;
        stats.kept_against_refutation += local.stats.kept_against_refutation;
        stats.unseen_cells += local.stats.unseen_cells;
    }
    finish(cells, stats, carver.params, carver.leaf_level, side)
}

/// The occupancy from the kept cells (both carvers): slivers trimmed when asked, unlabelled cells
/// counted.
pub(crate) fn finish(
    mut cells: Vec<Cell>,
    mut stats: CarveStats,
    params: &HullParams,
    leaf_level: u32,
    side: f64,
) -> Occupancy {
    if params.trim_slivers {
        stats.slivers_trimmed = trim_slivers(&mut cells, params.workspace.min, params.leaf_size);
    }
    stats.unlabelled_cells = cells.iter().filter(|c| !c.hand && !c.scalpel).count() as u64;
    let resolution = 1usize << leaf_level;
    Occupancy { cells, leaf_size: side / resolution as f64, origin: params.workspace.min, resolution, stats }
}

/// Drops the slivers of a shell over a solid core (see [`HullParams::trim_slivers`]): a leaf that
/// is not solid is dropped when, along some axis, the two leaves on one side are solid and the
/// leaf on the other side was not kept, i.e. it is the outermost layer over a core at least two
/// leaves thick. A structure thinner than that (a blade, whose hull is a leaf or less thick) keeps
/// its slivers. Returns how many were dropped. Kept and solid leaves are
/// marked on two bit grids over the kept cells' box, in leaves.
pub(crate) fn trim_slivers(cells: &mut Vec<Cell>, origin: Point3<f64>, leaf: f64) -> u64 {
    if cells.iter().all(|c| c.solid) {
        return 0;
    }
    let index = |c: &Cell| [0, 1, 2].map(|a| ((c.min[a] - origin[a]) / leaf).round() as i64);
    let span = |c: &Cell| (c.size / leaf).round().max(1.0) as i64;
    let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for c in cells.iter() {
        let (i, n) = (index(c), span(c));
        for a in 0..3 {
            lo[a] = lo[a].min(i[a] - 1);
            hi[a] = hi[a].max(i[a] + n);
        }
    }
    let dims = [0, 1, 2].map(|a| (hi[a] - lo[a] + 1) as usize);
    let at =
        |p: [i64; 3]| ((p[2] - lo[2]) as usize * dims[1] + (p[1] - lo[1]) as usize) * dims[0] + (p[0] - lo[0]) as usize;
    let words = (dims[0] * dims[1] * dims[2]).div_ceil(64);
    let (mut kept, mut solid) = (vec![0u64; words], vec![0u64; words]);
    for c in cells.iter() {
        let (i, n) = (index(c), span(c));
        for z in i[2]..i[2] + n {
            for y in i[1]..i[1] + n {
                for x in i[0]..i[0] + n {
                    let k = at([x, y, z]);
                    kept[k / 64] |= 1 << (k % 64);
                    if c.solid {
                        solid[k / 64] |= 1 << (k % 64);
                    }
                }
            }
        }
    }
    let bit = |grid: &[u64], p: [i64; 3]| {
        let k = at(p);
        grid[k / 64] & (1 << (k % 64)) != 0
    };
    let before = cells.len();
    cells.retain(|c| {
        if c.solid {
            return true;
        }
        let i = index(c);
        let outer_layer = (0..3).any(|a| {
            [-1i64, 1].iter().any(|&d| {
                let (mut inner, mut deeper, mut outer) = (i, i, i);
                inner[a] += d;
                deeper[a] += 2 * d;
                outer[a] -= d;
                bit(&solid, inner) && bit(&solid, deeper) && !bit(&kept, outer)
            })
        });
        !outer_layer
    });
    (before - cells.len()) as u64
}

fn carver<'a>(views: &'a [Option<Silhouette>], params: &'a HullParams, leaf_level: u32) -> Carver<'a> {
    let present: Vec<&Silhouette> = views.iter().flatten().collect();
    let min_views = params.min_views.min(present.len()).max(1);
    Carver { views: present, params, leaf_level, min_views, box_hi: box_in_leaves(params) }
}

/// Carves the hull of the views' silhouettes (`None` = a missing view, left out and counted).
pub fn carve(views: &[Option<Silhouette>], params: &HullParams) -> Result<Occupancy, HullError> {
    let (leaf_level, side) = check(views, params)?;
    check_refine(params, leaf_level)?;
    let carver = carver(views, params, leaf_level);
    let start = params.start_level.min(leaf_level);
    let n = 1usize << start;
    let size = side / n as f64;
    let origin = params.workspace.min;
    // Only the roots that reach into the volume's box.
    let reach = |a: usize| ((params.workspace.max[a] - origin[a]) / size).ceil().clamp(1.0, n as f64) as usize;
    let dims = [reach(0), reach(1), reach(2)];
    let locals: Vec<Local> = (0..dims[0] * dims[1] * dims[2])
        .into_par_iter()
        .map(|k| {
            let (i, j, l) = (k % dims[0], (k / dims[0]) % dims[1], k / (dims[0] * dims[1]));
            let min = origin + Vector3::new(i as f64, j as f64, l as f64) * size;
            let mut local = Local::default();
            carver.visit_root(min, size, start, &mut local);
            local
        })
        .collect();
    let occ = gather(views, &carver, locals, side);
    refine_label(views, params, occ, label::SCALPEL, params.blade_levels)
}

/// Checks that [`HullParams::blade_levels`] fits the octree.
pub(crate) fn check_refine(params: &HullParams, leaf_level: u32) -> Result<(), HullError> {
    if params.blade_levels > MAX_REFINE_LEVELS || leaf_level + params.blade_levels > MAX_DEPTH {
        return Err(HullError::Params(format!(
            "blade_levels must be at most {MAX_REFINE_LEVELS} and leave the octree within 2^{MAX_DEPTH} leaves per side, got {} on a depth of {leaf_level}",
            params.blade_levels
        )));
    }
    Ok(())
}

/// Carves the leaves of `occ` carrying label `l` again, `levels` octree levels finer, with the
/// rules of [`carve`] ([`carve_within`] seeded by those leaves); every other cell stays as it is.
/// The result's `leaf_size` is the finer leaf (`occ.leaf_size / 2^levels`) and its counters add
/// the finer carving's. Larger uniform cells carrying the label are left whole (nothing in them
/// is mixed). `levels` 0 returns `occ` unchanged.
pub fn refine_label(
    views: &[Option<Silhouette>],
    params: &HullParams,
    occ: Occupancy,
    l: u8,
    levels: u32,
) -> Result<Occupancy, HullError> {
    refine_cells(views, params, occ, levels, |_, c| c.has(l))
}

/// Carves the leaves of `occ` that `select` picks (by index and cell) again, `levels` octree
/// levels finer, as [`refine_label`] does for a label's leaves: a hull carved at a coarse leaf
/// and refined where detail matters (near a tool, say) holds there the cells a carving at the fine
/// leaf would keep, since carving is conservative. Larger uniform cells stay whole.
pub fn refine_cells(
    views: &[Option<Silhouette>],
    params: &HullParams,
    occ: Occupancy,
    levels: u32,
    select: impl Fn(usize, &Cell) -> bool,
) -> Result<Occupancy, HullError> {
    if levels == 0 {
        return Ok(occ);
    }
    if levels > MAX_REFINE_LEVELS {
        return Err(HullError::Params(format!(
            "a leaf is refined by at most {MAX_REFINE_LEVELS} levels, got {levels}"
        )));
    }
    let leaf = occ.leaf_size;
    let fine = HullParams {
        leaf_size: leaf / f64::from(1u32 << levels),
        trim_slivers: false,
        blade_levels: 0,
        ..params.clone()
    };
    let (mut seeds, mut cells) = (Vec::new(), Vec::with_capacity(occ.cells.len()));
    for (k, c) in occ.cells.into_iter().enumerate() {
        if select(k, &c) && c.size < 1.5 * leaf { seeds.push(c) } else { cells.push(c) }
    }
    let refined = carve_within(views, &fine, &seeds)?;
    let mut stats = occ.stats;
    stats.footprint_tests += refined.stats.footprint_tests;
    stats.cells_visited += refined.stats.cells_visited;
    stats.kept_against_refutation += refined.stats.kept_against_refutation;
    stats.unseen_cells += refined.stats.unseen_cells;
    for (total, n) in stats.lone_refutations.iter_mut().zip(&refined.stats.lone_refutations) {
        *total += n;
    }
    stats.leaves_refined += seeds.len() as u64;
    cells.extend(refined.cells);
    stats.unlabelled_cells = cells.iter().filter(|c| !c.hand && !c.scalpel).count() as u64;
    Ok(Occupancy { cells, leaf_size: refined.leaf_size, origin: occ.origin, resolution: refined.resolution, stats })
}

/// Carves only inside `seeds`: cells of this octree (the same volume's lower corner and a leaf
/// size that divides theirs by a power of two), each carved down to `params.leaf_size` with the
/// rules of [`carve`]. With the kept cells of a coarser carving of the same views as seeds, this
/// gives the finer hull at a fraction of the cost, since carving is conservative (a cell the
/// coarse carving dropped holds nothing the fine one keeps); with a previous frame's cells,
/// dilated, it carves only where the hull can have moved.
pub fn carve_within(views: &[Option<Silhouette>], params: &HullParams, seeds: &[Cell]) -> Result<Occupancy, HullError> {
    let (leaf_level, side) = check(views, params)?;
    let origin = params.workspace.min;
    let mut roots = Vec::with_capacity(seeds.len());
    for s in seeds {
        let ratio = s.size / params.leaf_size;
        let up = ratio.log2().round();
        let aligned = (0..3).all(|a| {
            let q = (s.min[a] - origin[a]) / s.size;
            (q - q.round()).abs() < 1e-6
        });
        let on_octree = ratio.is_finite()
            && up >= 0.0
            && up <= f64::from(leaf_level)
            && (ratio - up.exp2()).abs() < 1e-6 * ratio
            && aligned;
        if !on_octree {
            return Err(HullError::Params(format!(
                "a seed cell of {:.4} mm at {:?} is not a cell of this octree ({:.4} mm leaves from {:?})",
                s.size * 1e3,
                [s.min.x, s.min.y, s.min.z],
                params.leaf_size * 1e3,
                [origin.x, origin.y, origin.z]
            )));
        }
        roots.push((s.min, leaf_level - up as u32));
    }
    let carver = carver(views, params, leaf_level);
    let locals: Vec<Local> = roots
        .par_chunks(64)
        .map(|chunk| {
            let mut local = Local::default();
            for &(min, level) in chunk {
                carver.visit_root(min, side / f64::from(1u32 << level), level, &mut local);
            }
            local
        })
        .collect();
    Ok(gather(views, &carver, locals, side))
}

/// Labels the cells of a hull anew from other masks of the same views, by carving's rules for
/// labels (a label needs `min_support` views with its pixels in the cell's footprint; exclusive
/// labels go to the larger share) without carving anything: every cell is kept, one that no
/// label reaches is left unlabelled. For masks whose labels changed after carving (the known
/// tool drawn into the views), this costs one footprint test per cell and view.
///
/// Also returns, per cell and view (`k * views.len() + v`), whether that view sees hand pixels
/// in the cell's footprint (what [`footprint_counts`] would count there), so that a caller need
/// not test the footprints again.
pub fn relabel(occ: &Occupancy, views: &[Option<Silhouette>], params: &HullParams) -> (Occupancy, Vec<bool>) {
    /// Cells per parallel task.
    const CHUNK: usize = 256;
    let n = views.len();
    let parts: Vec<(Vec<Cell>, Vec<bool>)> = occ
        .cells
        .par_chunks(CHUNK)
        .map_init(SharedCorners::default, |corners, chunk| {
            corners.gather(chunk, occ.origin, occ.leaf_size);
            let mut cells = Vec::with_capacity(chunk.len());
            let mut seen = vec![false; chunk.len() * n];
            let mut shares = vec![(0usize, 0usize, 0.0f64, 0.0f64); chunk.len()];
            for (v, view) in views.iter().enumerate() {
                let Some(view) = view else { continue };
                corners.project(view);
                for (k, share) in shares.iter_mut().enumerate() {
                    if let Verdict::Sees { counts, .. } = judge(view, |m| corners.corner(k, m), params.margin_px) {
                        share.0 += usize::from(counts.hand > 0);
                        share.1 += usize::from(counts.scalpel > 0);
                        share.2 += f64::from(counts.hand) / f64::from(counts.total);
                        share.3 += f64::from(counts.scalpel) / f64::from(counts.total);
                        seen[k * n + v] = counts.hand > 0;
                    }
                }
            }
            for (c, &(hand, scalpel, hand_share, scalpel_share)) in chunk.iter().zip(&shares) {
                let (mut has_hand, mut has_scalpel) = (hand >= params.min_support, scalpel >= params.min_support);
                if params.exclusive_labels && has_hand && has_scalpel {
                    has_hand = hand_share >= scalpel_share;
                    has_scalpel = !has_hand;
                }
                cells.push(Cell { hand: has_hand, scalpel: has_scalpel, ..*c });
            }
            (cells, seen)
        })
        .collect();
    let mut cells = Vec::with_capacity(occ.cells.len());
    let mut seen = Vec::with_capacity(occ.cells.len() * n);
    for (c, s) in parts {
        cells.extend(c);
        seen.extend(s);
    }
    let mut stats = occ.stats.clone();
    stats.unlabelled_cells = cells.iter().filter(|c| !c.hand && !c.scalpel).count() as u64;
    (Occupancy { cells, stats, ..*occ }, seen)
}

/// The corners of a run of cells with each lattice point projected once per view: neighbouring
/// cells of a hull share corners (a block of 4x4x4 leaves has 125 distinct corners among its
/// 512), and projecting them was most of [`relabel`]'s time.
#[derive(Default)]
#[allow(missing_debug_implementations)] // scratch, never printed
struct SharedCorners {
    /// Per cell, its eight corners' indices into `points`.
    ids: Vec<[u32; 8]>,
    /// The distinct corners.
    points: Vec<Point3<f64>>,
    /// `points` projected into the current view.
    projected: Vec<Projected>,
    /// Lattice slot -> index into `points` (`u32::MAX`: none yet), over the run's box.
    slots: Vec<u32>,
    /// Lattice coordinates of each cell's lower corner and its side in leaves.
    keys: Vec<([i64; 3], i64)>,
}

impl SharedCorners {
    /// Largest lattice box (in points) indexed densely; a run spread wider projects every
    /// corner of its own.
    const MAX_SLOTS: i64 = 1 << 15;

    /// Collects the distinct corners of `cells`, on the lattice of `leaf`-sized steps from
    /// `origin`.
    fn gather(&mut self, cells: &[Cell], origin: Point3<f64>, leaf: f64) {
        self.ids.clear();
        self.points.clear();
        self.keys.clear();
        self.keys.extend(cells.iter().map(|c| {
            let q = |a: usize| ((c.min[a] - origin[a]) / leaf).round() as i64;
            ([q(0), q(1), q(2)], (c.size / leaf).round() as i64)
        }));
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        for (k, s) in &self.keys {
            for a in 0..3 {
                lo[a] = lo[a].min(k[a]);
                hi[a] = hi[a].max(k[a].saturating_add(*s));
            }
        }
        let dims = [0, 1, 2].map(|a| hi[a].saturating_sub(lo[a]).saturating_add(1).max(0));
        let dense = !cells.is_empty()
            && dims.iter().all(|&d| d <= Self::MAX_SLOTS)
            && dims[0] * dims[1] * dims[2] <= Self::MAX_SLOTS;
        if dense {
            self.slots.clear();
            self.slots.resize((dims[0] * dims[1] * dims[2]) as usize, u32::MAX);
        }
        for (c, &(k, s)) in cells.iter().zip(&self.keys) {
            let ids = std::array::from_fn(|m| {
                let point = || c.min + corner_offset(m) * c.size;
                if !dense {
                    self.points.push(point());
                    return (self.points.len() - 1) as u32;
                }
                let d = corner_offset(m);
                let at = |a: usize| k[a].wrapping_sub(lo[a]).wrapping_add(d[a] as i64 * s);
                let index = at(2).wrapping_mul(dims[1]).wrapping_add(at(1)).wrapping_mul(dims[0]).wrapping_add(at(0));
                // Off the box only for cells of absurd coordinates: they share nothing.
                match usize::try_from(index).ok().and_then(|i| self.slots.get_mut(i)) {
                    Some(slot) if *slot != u32::MAX => *slot,
                    Some(slot) => {
                        *slot = self.points.len() as u32;
                        self.points.push(point());
                        *slot
                    }
                    None => {
                        self.points.push(point());
                        (self.points.len() - 1) as u32
                    }
                }
            });
            self.ids.push(ids);
        }
    }

    /// Projects the gathered corners into `view`.
    fn project(&mut self, view: &Silhouette) {
        self.projected.clear();
        self.projected.extend(self.points.iter().map(|p| project(view, p)));
    }

    /// Corner `m` of cell `k` in the last view projected.
    #[inline(always)]
    fn corner(&self, k: usize, m: usize) -> Projected {
        self.projected[self.ids[k][m] as usize]
    }
}

/// The label counts in a cell's footprint in one view, as carving sees them (`None` where the view
/// cannot tell or the footprint misses the image).
pub fn footprint_counts(view: &Silhouette, cell: &Cell, margin_px: f64) -> Option<crate::silhouette::Counts> {
    let corners: [Projected; 8] = std::array::from_fn(|k| project(view, &(cell.min + corner_offset(k) * cell.size)));
    match judge(view, |m| corners[m], margin_px) {
        Verdict::Sees { counts, .. } => Some(counts),
        Verdict::Refutes | Verdict::Partial => Some(crate::silhouette::Counts::default()),
        Verdict::Unknown | Verdict::Off => None,
    }
}
