//! Where each frame set is carved: around the last frame set's hull, not the whole working
//! volume. Hands and tools move a few centimetres between frame sets, and carving the rig's whole
//! volume costs 1.6-2x carving a box around them (docs/benchmarks.md, "Visual hull").
//!
//! The box is the last hull's bounds padded by [`PAD_M`], snapped outward to the full volume's
//! leaf grid (so its leaves are the full carving's leaves) and clipped to the volume. A hull that
//! reaches a face of the box inside the volume may go on past it: that frame set is carved again
//! in the whole volume. Every [`FULL_EVERY`]-th frame set, and whenever the last hull was empty,
//! the whole volume is carved, so that something entering the view away from the hand is found
//! within a fraction of a second. While segmenting, a frame set after one whose tool was not
//! trusted is carved in the whole volume too ([`CarveRegion::set_tracked`]): the box (and the
//! segmentation near the last hull that follows it) held on to a hull that had lost the blade,
//! and the tool's searches found it only in the frame sets carved whole (random:1709 in
//! random:1777: 40 of 150 frame sets trusted; 114 carved whole after every refusal).

use hullcut_capture::segment::Window;
use hullcut_hull::{Aabb, Occupancy};
use hullcut_rig::Camera;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Margin around the last hull, metres: a hand at 1 m/s moves 3.3 cm in a 30 fps frame.
pub const PAD_M: f64 = 0.05;

/// The whole volume is carved at least every this many frame sets.
pub const FULL_EVERY: u64 = 15;

/// Counts of where frame sets were carved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RegionCounts {
    /// Carved in a box around the last hull.
    pub boxed: u64,
    /// Carved in the whole volume (first frame set, every [`FULL_EVERY`]-th, after an empty hull
    /// or a tool not trusted).
    pub full: u64,
    /// Of those, carved whole because the frame set before's tool was not trusted (segmenting).
    #[serde(default)]
    pub untracked: u64,
    /// Hulls that reached the box's side inside the volume.
    pub clipped: u64,
    /// Of those, frame sets carved again in the whole volume (with mask files; a segmented
    /// frame set keeps its hull, and the next one is carved in the whole volume).
    pub redone: u64,
}

/// Chooses the box each frame set is carved in.
#[derive(Debug, Clone)]
pub struct CarveRegion {
    full: Aabb,
    leaf: f64,
    last: Option<Aabb>,
    since_full: u64,
    /// Whether the last frame set's tool was trusted (always, unless told otherwise).
    tracked: bool,
    /// What it chose so far.
    pub counts: RegionCounts,
}

impl CarveRegion {
    /// Boxes within the working volume `full`, on its grid of `leaf` metres.
    pub fn new(full: Aabb, leaf: f64) -> Self {
        CarveRegion { full, leaf, last: None, since_full: 0, tracked: true, counts: RegionCounts::default() }
    }

    /// The box to carve the next frame set in.
    pub fn next_box(&mut self) -> Aabb {
        let due = self.since_full + 1 >= FULL_EVERY;
        match self.last {
            Some(last) if self.tracked && !due => {
                self.since_full += 1;
                self.counts.boxed += 1;
                self.around(&last)
            }
            last => {
                // Boxed but for the tool not trusted.
                self.counts.untracked += u64::from(last.is_some() && !due);
                self.since_full = 0;
                self.counts.full += 1;
                self.full
            }
        }
    }

    /// Whether the frame set just carved had its tool trusted: until one has again, the next
    /// frame sets are carved in the whole volume.
    pub fn set_tracked(&mut self, tracked: bool) {
        self.tracked = tracked;
    }

    /// The whole working volume.
    pub fn full(&self) -> Aabb {
        self.full
    }

    /// Takes the hull carved in `region`; `true` when it reaches a side of `region` that lies
    /// inside the working volume (it may go on past it: carve the frame set again in the whole
    /// volume and hand that hull to this again).
    pub fn update(&mut self, region: &Aabb, occ: &Occupancy) -> bool {
        let Some(bounds) = bounds(occ) else {
            self.last = None;
            return false;
        };
        let eps = 1e-9 + 1e-6 * self.leaf;
        let clipped = (0..3).any(|a| {
            (bounds.min[a] <= region.min[a] + eps && region.min[a] > self.full.min[a] + eps)
                || (bounds.max[a] >= region.max[a] - eps && region.max[a] < self.full.max[a] - eps)
        });
        if clipped {
            self.counts.clipped += 1;
            self.last = None;
            return true;
        }
        self.last = Some(bounds);
        false
    }

    /// `last` padded by [`PAD_M`], snapped outward to the volume's leaf grid, clipped to it.
    fn around(&self, last: &Aabb) -> Aabb {
        let (o, leaf) = (self.full.min, self.leaf);
        let snap_down = |v: f64, a: usize| o[a] + ((v - o[a]) / leaf).floor() * leaf;
        let snap_up = |v: f64, a: usize| o[a] + ((v - o[a]) / leaf).ceil() * leaf;
        let min = Point3::from(Vector3::from_fn(|a, _| snap_down(last.min[a] - PAD_M, a).max(self.full.min[a])));
        let max = Point3::from(Vector3::from_fn(|a, _| snap_up(last.max[a] + PAD_M, a).min(self.full.max[a])));
        if (0..3).any(|a| max[a] <= min[a]) {
            return self.full;
        }
        Aabb { min, max }
    }
}

/// The bounds of a hull's kept cells (`None` when it has none).
fn bounds(occ: &Occupancy) -> Option<Aabb> {
    let mut cells = occ.cells.iter();
    let first = cells.next()?;
    let (mut lo, mut hi) = (first.min, first.min + Vector3::repeat(first.size));
    for c in cells {
        lo = lo.inf(&c.min);
        hi = hi.sup(&(c.min + Vector3::repeat(c.size)));
    }
    Some(Aabb { min: lo, max: hi })
}

/// Points per edge where a box is projected into a view ([`window`]).
const EDGE_SAMPLES: usize = 32;

/// Pixels of slack around the sampled edges' rectangle in [`window`]: between two samples 1/32
/// of an edge apart a lens bows the edge's image by far less.
const SAMPLE_SLACK_PX: f64 = 2.0;

/// The rectangle of `camera`'s pixels where the box `b` can be seen, grown by `pad` pixels and
/// clipped to the image (empty where the box lies off it): the box's projection lies within the
/// rectangle around the projections of its twelve edges (the pinhole image of a box is the convex
/// polygon its edges bound, and a lens within its invertible radius maps that region's boundary
/// onto the boundary of its image), each edge followed through the lens at 32
/// points. `None` where a point of an edge lies within a millimetre of the camera's plane or
/// behind it, or beyond the lens' invertible radius: then the whole image.
pub fn window(camera: &Camera, b: &Aabb, pad: f64) -> Option<Window> {
    let radius = camera.distortion.monotonic_radius();
    let corner = |k: usize| {
        Point3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        )
    };
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    // The edges: corner pairs that differ in one axis.
    for k in 0..8 {
        for axis in [1, 2, 4].into_iter().filter(|a| k & a == 0) {
            let (from, to) = (corner(k), corner(k | axis));
            for n in 0..=EDGE_SAMPLES {
                let p = from + (to - from) * (n as f64 / EDGE_SAMPLES as f64);
                let pc = camera.world_to_camera(&p);
                // NaN fails too: then the whole image.
                if pc.z.is_nan() || pc.z <= 1e-3 {
                    return None;
                }
                let xn = nalgebra::Vector2::new(pc.x / pc.z, pc.y / pc.z);
                let r = xn.norm();
                if r.is_nan() || r >= radius {
                    return None;
                }
                let uv = camera.normalized_to_pixel(camera.distortion.distort(xn));
                lo = [lo[0].min(uv.x), lo[1].min(uv.y)];
                hi = [hi[0].max(uv.x), hi[1].max(uv.y)];
            }
        }
    }
    let grow = pad.max(0.0) + SAMPLE_SLACK_PX;
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    let clamp = |v: f64, n: f64| v.clamp(0.0, n) as u32;
    if !(lo[0].is_finite() && lo[1].is_finite() && hi[0].is_finite() && hi[1].is_finite()) {
        return None;
    }
    let window = Window {
        x0: clamp((lo[0] - grow).floor(), w),
        y0: clamp((lo[1] - grow).floor(), h),
        x1: clamp((hi[0] + grow).ceil() + 1.0, w),
        y1: clamp((hi[1] + grow).ceil() + 1.0, h),
    };
    Some(window.clipped(camera.width, camera.height))
}

/// Side of the blocks a hull is summed up in for [`stretches`], metres: a hand's hull is some
/// tens of them, and a block's ball is wider than a cell's by less than the motion allowed for.
pub const BLOCK_M: f64 = 0.025;

/// The centres of the blocks of side `size` (a grid from the world's origin) that `occ`'s
/// cells touch (every point of a cell lies in one of them), but those whose 26 neighbours all
/// are: for balls of a radius `R` at least the side around the centres, the neighbours' balls
/// cover such a block's ball (a point at `t ≤ R` from its centre in direction `d` is within `R`
/// of the neighbour along `d`'s largest axis, since `t² − 2t·s·|d|∞ + s² ≤ R²` holds at `t = 0`
/// and at `t = R`, as `s ≤ 2R/√3`, and so between), so [`stretches`] need not project it.
pub fn blocks(occ: &Occupancy, size: f64) -> Vec<Point3<f64>> {
    let Some(bounds) = bounds(occ) else { return Vec::new() };
    // A grid one block wider than the hull all round (so every block's neighbours are on it),
    // its origin on the world's grid: in it coordinates are at least 0, where truncation is the
    // floor (the library's rounding calls would cost more than the rest).
    let origin = bounds.min.map(|v| ((v / size).floor() - 1.0) * size);
    let extent = (bounds.max - origin).map(|v| (v / size).floor() + 2.0);
    // A hull beyond any working volume (or not finite): no blocks, the whole windows segmented.
    let cells = extent.x * extent.y * extent.z;
    if cells.is_nan() || cells > f64::from(1 << 24) || !origin.iter().all(|v| v.is_finite()) {
        return Vec::new();
    }
    let (nx, ny, nz) = (extent.x as usize, extent.y as usize, extent.z as usize);
    let at = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    let mut touched = vec![false; nx * ny * nz];
    for c in &occ.cells {
        let lo = (c.min - origin).map(|v| ((v / size) as usize).max(1));
        let hi = (c.min + Vector3::repeat(c.size) - origin).map(|v| (v / size) as usize);
        for z in lo.z..=hi.z.min(nz - 2) {
            for y in lo.y..=hi.y.min(ny - 2) {
                for x in lo.x..=hi.x.min(nx - 2) {
                    touched[at(x, y, z)] = true;
                }
            }
        }
    }
    let inner = |x: usize, y: usize, z: usize| {
        (z - 1..=z + 1).all(|zz| (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| touched[at(xx, yy, zz)])))
    };
    let mut centres = Vec::new();
    for z in 1..nz - 1 {
        for y in 1..ny - 1 {
            for x in 1..nx - 1 {
                if touched[at(x, y, z)] && !inner(x, y, z) {
                    let k = Vector3::new(x as f64, y as f64, z as f64);
                    centres.push(origin + (k + Vector3::repeat(0.5)) * size);
                }
            }
        }
    }
    centres
}

/// Rows whose stretches [`stretches`] takes together: each group's stretch holds every row's.
const GROUP_ROWS: usize = 4;

/// Per image row of `camera`, the columns `a..b` within `window` where a ball of radius `reach`
/// around one of `centres` can be seen, grown by `pad` pixels (rows outside the window, or that
/// no ball reaches, have none: `a == b`): for each ball, the disc [`Camera::project_ball`]
/// bounds its projection with, through any lens, and each row's stretch from the first to the
/// last of its discs' pixels, taken over four rows at a time (a disc's widest row in
/// the group). `None` where a ball comes within a millimetre of the camera's plane or beyond the
/// lens' invertible radius (then test the whole window), or where there are no centres.
pub fn stretches(
    camera: &Camera,
    centres: &[Point3<f64>],
    reach: f64,
    pad: f64,
    window: Window,
) -> Option<Vec<(u32, u32)>> {
    if centres.is_empty() {
        return None;
    }
    let radius = camera.distortion.monotonic_radius();
    let h = camera.height as usize;
    let mut groups = vec![(u32::MAX, 0u32); h.div_ceil(GROUP_ROWS)];
    let (x0, x1) = (f64::from(window.x0), f64::from(window.x1));
    let (y0, y1) = (f64::from(window.y0), f64::from(window.y1) - 1.0);
    for c in centres {
        let (uv, r) = camera.project_ball(c, reach, 1e-3, radius)?;
        let r = r + pad.max(0.0);
        let (ya, yb) = ((uv.y - r).ceil().max(y0), (uv.y + r).floor().min(y1));
        if ya.partial_cmp(&yb).is_none_or(|o| o.is_gt()) {
            continue;
        }
        let (ya, yb) = (ya as usize, yb as usize);
        for g in ya / GROUP_ROWS..=yb / GROUP_ROWS {
            // The group's row nearest the disc's centre row: the disc is widest there.
            let (first, last) = ((g * GROUP_ROWS).max(ya), (g * GROUP_ROWS + GROUP_ROWS - 1).min(yb));
            let dy = if uv.y < first as f64 {
                first as f64 - uv.y
            } else if uv.y > last as f64 {
                uv.y - last as f64
            } else {
                0.0
            };
            let half = (r * r - dy * dy).max(0.0).sqrt();
            // Truncation rounds down at or above 0, and `x + 2` rounded down is past `x` rounded
            // up (the library's rounding calls cost more than the rest).
            let (a, b) = ((uv.x - half).max(x0), (uv.x + half + 2.0).min(x1));
            if a < b {
                let group = &mut groups[g];
                *group = (group.0.min(a as u32), group.1.max(b as u32));
            }
        }
    }
    let inside = |y: usize| (window.y0 as usize..window.y1 as usize).contains(&y);
    Some(
        (0..h)
            .map(|y| match groups[y / GROUP_ROWS] {
                (a, b) if a < b && inside(y) => (a, b),
                _ => (0, 0),
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use hullcut_hull::{Cell, HullParams, carve, silhouettes};

    use super::*;

    fn occupancy(cells: &[(Point3<f64>, f64)]) -> Occupancy {
        Occupancy {
            cells: cells
                .iter()
                .map(|&(min, size)| Cell { min, size, hand: true, scalpel: false, solid: true, refuted_by: None })
                .collect(),
            leaf_size: 0.01,
            origin: Point3::origin(),
            resolution: 64,
            stats: Default::default(),
        }
    }

    #[test]
    fn boxes_follow_the_hull_on_the_leaf_grid_and_a_clipped_hull_asks_for_the_whole_volume() {
        let full = Aabb { min: Point3::new(-0.3, -0.3, 0.0), max: Point3::new(0.3, 0.3, 0.4) };
        let mut region = CarveRegion::new(full, 0.01);
        // The first frame set: the whole volume.
        assert_eq!(region.next_box(), full);
        let hand = occupancy(&[(Point3::new(0.0, 0.0, 0.1), 0.01), (Point3::new(0.02, 0.0, 0.12), 0.01)]);
        assert!(!region.update(&full, &hand));
        // Then a box 5 cm around it, on the grid.
        let b = region.next_box();
        let expect_min = Point3::new(-0.05, -0.05, 0.05);
        let expect_max = Point3::new(0.08, 0.06, 0.18);
        assert!((b.min - expect_min).norm() < 1e-9 && (b.max - expect_max).norm() < 1e-9, "{b:?}");
        for a in 0..3 {
            let k = (b.min[a] - full.min[a]) / 0.01;
            assert!((k - k.round()).abs() < 1e-6, "off the leaf grid: {b:?}");
        }
        // A hull reaching the box's side inside the volume: carve again.
        let moved = occupancy(&[(Point3::new(0.07, 0.0, 0.1), 0.01)]);
        assert!(region.update(&b, &moved));
        assert_eq!(region.counts.clipped, 1);
        // Until a hull is taken in the whole volume, the next box is the whole volume.
        assert_eq!(region.next_box(), full);
        // A hull on the volume's own side (the table) is not clipped.
        let low = occupancy(&[(Point3::new(0.0, 0.0, 0.0), 0.01)]);
        assert!(!region.update(&full, &low));
        let b = region.next_box();
        assert_eq!(b.min.z, 0.0);
        assert!(!region.update(&b, &low));
        // The whole volume every FULL_EVERY frame sets, and after an empty hull.
        let mut fulls = 0;
        for _ in 0..FULL_EVERY {
            let b = region.next_box();
            fulls += usize::from(b == full);
            region.update(&b, &low);
        }
        assert_eq!(fulls, 1);
        region.update(&full, &occupancy(&[]));
        assert_eq!(region.next_box(), full);
    }

    /// A tool not trusted: the next frame sets are carved whole, counted apart, until one is
    /// trusted again; then boxes again.
    #[test]
    fn a_tool_not_trusted_is_looked_for_in_the_whole_volume() {
        let full = Aabb { min: Point3::new(-0.3, -0.3, 0.0), max: Point3::new(0.3, 0.3, 0.4) };
        let mut region = CarveRegion::new(full, 0.01);
        let hand = occupancy(&[(Point3::new(0.0, 0.0, 0.1), 0.01)]);
        let b = region.next_box();
        region.update(&b, &hand);
        assert_ne!(region.next_box(), full, "tracked: a box");
        region.update(&b, &hand);
        region.set_tracked(false);
        for _ in 0..3 {
            let b = region.next_box();
            assert_eq!(b, full);
            region.update(&b, &hand);
        }
        assert_eq!(region.counts.untracked, 3);
        region.set_tracked(true);
        assert_ne!(region.next_box(), full, "trusted again: a box");
        assert_eq!(region.counts.untracked, 3);
        assert_eq!(region.counts.full, 4);
    }

    /// The default rig, lab8 and a seeded random rig (lab8's and the random rig's lenses distort).
    fn three_rigs(seed: u64) -> [hullcut_rig::Rig; 3] {
        [
            hullcut_rig::RigPreset::Default.rig(),
            hullcut_rig::RigPreset::Lab8.rig(),
            hullcut_rig::RigPreset::Random(seed).rig(),
        ]
    }

    /// A reproducible stream of numbers in [0, 1) (xorshift).
    fn numbers(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn every_point_of_a_box_projects_into_its_window_through_any_lens() {
        // Three rigs' lenses (lab8's and the random rig's distort), boxes small and large,
        // near and off the image.
        let rigs = three_rigs(5);
        let mut next = numbers(0x2545_f491_4f6c_dd1d);
        let (mut tested, mut inside_image) = (0, 0);
        for rig in &rigs {
            for _ in 0..60 {
                let centre = Point3::new(next() * 0.6 - 0.3, next() * 0.6 - 0.3, next() * 0.3);
                let half = Vector3::new(next(), next(), next()) * 0.15 + Vector3::repeat(0.005);
                let b = Aabb { min: centre - half, max: centre + half };
                for camera in &rig.cameras {
                    let Some(win) = window(camera, &b, 0.0) else { continue };
                    tested += 1;
                    for _ in 0..400 {
                        let p = b.min + (b.max - b.min).component_mul(&Vector3::new(next(), next(), next()));
                        let pr = camera.project(&p);
                        if !pr.visible {
                            continue;
                        }
                        inside_image += 1;
                        // The pixel whose centre is nearest.
                        let (x, y) = (pr.pixel.x.round(), pr.pixel.y.round());
                        assert!(
                            x >= f64::from(win.x0)
                                && x < f64::from(win.x1)
                                && y >= f64::from(win.y0)
                                && y < f64::from(win.y1),
                            "{p:?} at ({x:.2}, {y:.2}) outside {win:?} of {b:?}"
                        );
                    }
                }
            }
        }
        assert!(tested > 300 && inside_image > 50_000, "{tested} windows, {inside_image} points seen");
        // A box behind a camera, or one beyond the lens' invertible radius: the whole image.
        let camera = &rigs[0].cameras[0];
        let behind = camera.centre() - camera.viewing_direction().into_inner();
        let b = Aabb { min: behind - Vector3::repeat(0.01), max: behind + Vector3::repeat(0.01) };
        assert_eq!(window(camera, &b, 3.0), None);
        // A box that is not finite: the whole image, never a window that loses the hand.
        let nan = Aabb { min: Point3::new(f64::NAN, 0.0, 0.0), max: Point3::new(0.1, 0.1, 0.1) };
        let huge = Aabb { min: Point3::new(-f64::MAX, 0.0, 0.0), max: Point3::new(f64::MAX, 0.1, 0.1) };
        assert_eq!((window(camera, &nan, 3.0), window(camera, &huge, 3.0)), (None, None));
        // A box well inside the view: a window much smaller than the image, grown by the pad.
        let ahead = camera.centre() + camera.viewing_direction().into_inner() * 0.5;
        let b = Aabb { min: ahead - Vector3::repeat(0.01), max: ahead + Vector3::repeat(0.01) };
        let (small, padded) = (window(camera, &b, 0.0).expect("seen"), window(camera, &b, 10.0).expect("seen"));
        assert!(small.area() * 20 < u64::from(camera.width) * u64::from(camera.height), "{small:?}");
        assert_eq!(
            (padded.x0 + 10, padded.y0 + 10, padded.x1 - 10, padded.y1 - 10),
            (small.x0, small.y0, small.x1, small.y1)
        );
    }

    #[test]
    fn every_point_near_a_cell_projects_into_the_stretches_of_its_blocks() {
        let rigs = three_rigs(9);
        let mut next = numbers(0x9e37_79b9_7f4a_7c15);
        let (mut seen, mut stretched) = (0, 0);
        for rig in &rigs {
            for _ in 0..8 {
                // A cluster of cells of a leaf's to an octree cell's size.
                let centre = Point3::new(next() * 0.3 - 0.15, next() * 0.3 - 0.15, 0.02 + next() * 0.2);
                let cells: Vec<(Point3<f64>, f64)> = (0..40)
                    .map(|_| {
                        let size = [0.003125, 0.00625, 0.025, 0.05][(next() * 4.0) as usize % 4];
                        (centre + Vector3::new(next(), next(), next()) * 0.06, size)
                    })
                    .collect();
                let occ = occupancy(&cells);
                let centres = blocks(&occ, BLOCK_M);
                assert!(!centres.is_empty() && centres.len() < 40 * 27, "{} blocks", centres.len());
                // Balls of the blocks' half-diagonal grown by 3 cm: every point within 3 cm of a
                // cell projects into the stretches (blocks inside others' are not projected: the
                // rays through their points leave the blocks through one that is).
                let reach = 0.5 * BLOCK_M * 3f64.sqrt() + 0.03;
                for camera in &rig.cameras {
                    let window = Window::whole(camera.width, camera.height);
                    let Some(rows) = stretches(camera, &centres, reach, 2.0, window) else { continue };
                    stretched += 1;
                    assert_eq!(rows.len(), camera.height as usize);
                    for &(min, size) in &cells {
                        for _ in 0..30 {
                            let d = Vector3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                            let inside = min + Vector3::new(next(), next(), next()) * size;
                            let p = inside + d.normalize() * 0.03 * next().sqrt();
                            let pr = camera.project(&p);
                            if !pr.visible {
                                continue;
                            }
                            seen += 1;
                            let (x, y) = (pr.pixel.x.round(), pr.pixel.y.round());
                            let (a, bb) = rows[y as usize];
                            assert!(x >= f64::from(a) && x < f64::from(bb), "{p:?} at ({x}, {y}) outside {a}..{bb}");
                        }
                    }
                    // Rows far from every ball have none.
                    assert!(rows.iter().any(|&(a, b)| a == b), "some row has no stretch");
                }
            }
        }
        assert!(stretched > 60 && seen > 20_000, "{stretched} views, {seen} points seen");
        // A solid cube of 5x5x5 blocks (one cell each): the 27 inside are not kept.
        let cube: Vec<(Point3<f64>, f64)> = (0..125)
            .map(|k| {
                let corner = Point3::new((k % 5) as f64, (k / 5 % 5) as f64, (k / 25) as f64) + Vector3::repeat(0.1);
                (corner * BLOCK_M, BLOCK_M * 0.8)
            })
            .collect();
        assert_eq!(blocks(&occupancy(&cube), BLOCK_M).len(), 125 - 27);
        // No centres, or a ball behind the camera: the whole window.
        let camera = &rigs[0].cameras[0];
        let window = Window::whole(camera.width, camera.height);
        assert_eq!(stretches(camera, &[], 0.05, 2.0, window), None);
        let behind = camera.centre() - camera.viewing_direction().into_inner();
        assert_eq!(stretches(camera, &[behind], 0.05, 2.0, window), None);
        // Stretches stay within a smaller window.
        let small = Window { x0: 100, y0: 50, x1: 300, y1: 200 };
        let ahead = camera.centre() + camera.viewing_direction().into_inner() * 0.5;
        let rows = stretches(camera, &[ahead], 0.2, 2.0, small).expect("seen");
        for (y, &(a, b)) in rows.iter().enumerate() {
            if a < b {
                assert!((50..200).contains(&y) && a >= 100 && b <= 300, "row {y}: {a}..{b}");
            }
        }
    }

    #[test]
    fn carving_in_the_box_keeps_the_whole_volumes_leaves_there() {
        // The default rig's masks of a 4 cm ball.
        let rig = hullcut_rig::RigPreset::Default.rig();
        let ball = Point3::new(0.02, -0.01, 0.12);
        let masks: Vec<image::GrayImage> = rig
            .cameras
            .iter()
            .map(|c| {
                image::GrayImage::from_fn(c.width, c.height, |x, y| {
                    let ray = c.pixel_ray(nalgebra::Point2::new(f64::from(x), f64::from(y)));
                    let hit = ray.is_some_and(|r| {
                        let t = (ball - r.origin).dot(&r.direction);
                        (r.origin + r.direction.into_inner() * t - ball).norm() < 0.04
                    });
                    image::Luma([u8::from(hit)])
                })
            })
            .collect();
        let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Some).collect();
        let views = silhouettes(&rig, &refs).expect("silhouettes");
        let full = Aabb { min: Point3::new(-0.4, -0.4, 0.0), max: Point3::new(0.4, 0.4, 0.4) };
        let params = HullParams::new(full, 0.005);
        let whole = carve(&views, &params).expect("carves");
        let mut region = CarveRegion::new(full, 0.005);
        region.update(&full, &whole);
        let b = region.next_box();
        assert!(b != full);
        let boxed = carve(&views, &HullParams { workspace: b, ..params.clone() }).expect("carves");
        assert!(!region.update(&b, &boxed));
        let volume = |o: &Occupancy| o.volume(None);
        assert!(volume(&whole) > 0.0);
        assert!((volume(&boxed) - volume(&whole)).abs() < 1e-12, "{} against {}", volume(&boxed), volume(&whole));
        // The same leaves, one by one: every leaf centre of one hull lies in the other.
        for (a, b) in [(&boxed, &whole), (&whole, &boxed)] {
            for c in &a.cells {
                let centre = c.min + Vector3::repeat(c.size / 2.0);
                assert!(b.contains(&centre, None), "{centre:?}");
            }
        }
    }
}
