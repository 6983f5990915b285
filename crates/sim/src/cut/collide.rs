//! Which lattice edges a swept blade surface cuts: spatial hashing of the lattice's cells at their
//! current (deformed) positions (Teschner et al. 2003) against the surface's triangles, then an
//! exact segment–triangle test of the candidate cells' edges.
//!
//! The candidates come from either index, [`CellTree`] (parry's bounding volume hierarchy over the
//! cells' boxes, the one [`crate::CutSim`] uses) or [`SpatialHash`]; both return a superset of the
//! cells whose boxes overlap a query box, so the cuts are the same (`hullcut bench sim` times
//! both).
//!
//! This is the geometric query the virtual node algorithm builds on: a lattice edge crossed by the
//! blade separates its two nodes, and a cell with crossed edges is (partly) cut. The parameter of
//! each crossing along its edge is kept, so the cut can be placed in the material (rest) frame.

use nalgebra::{Point3, Vector3};
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::math::Vector as PVector;
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy};

use crate::lattice::Lattice;
use crate::sweep::SweptSurface;

/// Teschner et al.'s three large primes for hashing grid coordinates.
const PRIMES: [i64; 3] = [73_856_093, 19_349_663, 83_492_791];
/// Barycentric and segment-parameter tolerance: a segment through the shared edge of two triangles
/// hits at least one, and a node lying on the surface is found from both its edges.
const BARY_EPS: f64 = 1e-12;

/// Slack around a swept surface's boxes before they are tested against the cells' boxes, as a
/// fraction of the box's size and distance from the origin: a node lying on the surface to within
/// rounding, which [`segment_triangle`] and the crossing test take as on it, must find the cells on
/// both sides of it. Without it a blade swept exactly in a plane of nodes skipped the cells beyond
/// the plane wherever a node's position rounded a hair past it (1e-17 m), so that the edges from
/// such a node to that side were never cut: the built-in resection's true poses left its lobe
/// joined by the nodes on the table.
pub const BOX_SLACK: f64 = 1e-9;

pub use crate::model::lattice::CELL_EDGES;

/// A hash table of the lattice's cells by the grid cells their current bounding boxes overlap.
#[derive(Debug, Clone)]
pub struct SpatialHash {
    size: f64,
    buckets: Vec<Vec<u32>>,
}

fn grid(p: &Point3<f64>, size: f64) -> [i64; 3] {
    [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64]
}

impl SpatialHash {
    /// Hashes every cell of `lattice` with its nodes at `positions` (one per lattice node) into a
    /// table of grid cells of side `size` (the lattice's cell side is a good choice).
    pub fn new(lattice: &Lattice, positions: &[Point3<f64>], size: f64) -> Self {
        let n = (2 * lattice.cells.len()).next_power_of_two().max(64);
        let mut hash = SpatialHash { size, buckets: vec![Vec::new(); n] };
        for (c, cell) in lattice.cells.iter().enumerate() {
            let (lo, hi) = bounds(cell.nodes.iter().map(|&i| positions[i as usize]));
            hash.each_bucket(&lo, &hi, |b| b.push(c as u32));
        }
        hash
    }

    fn bucket(&self, g: [i64; 3]) -> usize {
        let h = (g[0].wrapping_mul(PRIMES[0])) ^ (g[1].wrapping_mul(PRIMES[1])) ^ (g[2].wrapping_mul(PRIMES[2]));
        (h as u64 as usize) & (self.buckets.len() - 1)
    }

    fn each_bucket(&mut self, lo: &Point3<f64>, hi: &Point3<f64>, mut f: impl FnMut(&mut Vec<u32>)) {
        let (a, b) = (grid(lo, self.size), grid(hi, self.size));
        for i in a[0]..=b[0] {
            for j in a[1]..=b[1] {
                for k in a[2]..=b[2] {
                    let idx = self.bucket([i, j, k]);
                    f(&mut self.buckets[idx]);
                }
            }
        }
    }

    /// Cells whose buckets overlap the box (a superset of the cells overlapping it; sorted, no
    /// repeats), appended to `out` after clearing it.
    pub fn candidates(&self, lo: &Point3<f64>, hi: &Point3<f64>, out: &mut Vec<u32>) {
        out.clear();
        let (a, b) = (grid(lo, self.size), grid(hi, self.size));
        for i in a[0]..=b[0] {
            for j in a[1]..=b[1] {
                for k in a[2]..=b[2] {
                    out.extend_from_slice(&self.buckets[self.bucket([i, j, k])]);
                }
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}

/// An index of the lattice's cells by their current bounding boxes: what a swept surface's
/// triangles are tested against.
pub trait CellIndex {
    /// Cells whose boxes may overlap the box `lo`..`hi` (a superset of those that do; sorted, no
    /// repeats), appended to `out` after clearing it.
    fn candidates(&self, lo: &Point3<f64>, hi: &Point3<f64>, out: &mut Vec<u32>);
}

impl CellIndex for SpatialHash {
    fn candidates(&self, lo: &Point3<f64>, hi: &Point3<f64>, out: &mut Vec<u32>) {
        SpatialHash::candidates(self, lo, hi, out);
    }
}

/// parry's bounding volume hierarchy (binned SAH build) over the lattice's cells at their current
/// positions (all of them, or those near a box: [`CellTree::within`]).
#[derive(Clone)]
pub struct CellTree {
    /// None when no cell is in it.
    bvh: Option<Bvh>,
    /// The lattice cell of each of the tree's leaves (the tree numbers its leaves densely).
    cells: Vec<u32>,
}

impl std::fmt::Debug for CellTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CellTree").field("cells", &self.cells.len()).finish()
    }
}

fn to_parry(p: &Point3<f64>) -> PVector {
    PVector::new(p.x, p.y, p.z)
}

impl CellTree {
    /// The hierarchy over every cell of `lattice` with its nodes at `positions` (one per lattice
    /// node).
    pub fn new(lattice: &Lattice, positions: &[Point3<f64>]) -> Self {
        let all = Point3::from(Vector3::repeat(f64::INFINITY));
        Self::within(lattice, positions, &-all, &all)
    }

    /// The hierarchy over the cells whose boxes overlap the box `lo`..`hi` (the rest can never be
    /// a candidate of a query inside that box): for a cut, the swept surface's box, so that a
    /// large organ's tree holds the few thousand cells near the blade, not all of them.
    pub fn within(lattice: &Lattice, positions: &[Point3<f64>], lo: &Point3<f64>, hi: &Point3<f64>) -> Self {
        let mut cells = Vec::new();
        let mut boxes = Vec::new();
        for (k, cell) in lattice.cells.iter().enumerate() {
            let (a, b) = bounds(cell.nodes.iter().map(|&i| positions[i as usize]));
            if (0..3).all(|i| a[i] <= hi[i] && b[i] >= lo[i]) {
                boxes.push((cells.len(), Aabb::new(to_parry(&a), to_parry(&b))));
                cells.push(k as u32);
            }
        }
        let bvh = (!boxes.is_empty()).then(|| Bvh::from_iter(BvhBuildStrategy::Binned, boxes));
        CellTree { bvh, cells }
    }

    /// How many cells the tree holds.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether the tree holds no cell.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }
}

impl CellIndex for CellTree {
    fn candidates(&self, lo: &Point3<f64>, hi: &Point3<f64>, out: &mut Vec<u32>) {
        out.clear();
        let Some(bvh) = &self.bvh else { return };
        let query = Aabb::new(to_parry(lo), to_parry(hi));
        out.extend(bvh.intersect_aabb(&query).map(|leaf| self.cells[leaf as usize]));
        out.sort_unstable();
        out.dedup();
    }
}

/// The box `lo`..`hi` grown by [`BOX_SLACK`]: what a swept surface's box (or one of its
/// triangles') is tested against the cells with.
pub fn padded(lo: &Point3<f64>, hi: &Point3<f64>) -> (Point3<f64>, Point3<f64>) {
    let size = (hi - lo).norm() + lo.coords.amax().max(hi.coords.amax());
    let pad = Vector3::repeat(BOX_SLACK * size);
    (lo - pad, hi + pad)
}

fn bounds(points: impl Iterator<Item = Point3<f64>>) -> (Point3<f64>, Point3<f64>) {
    let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
    let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
    for p in points {
        lo = lo.inf(&p);
        hi = hi.sup(&p);
    }
    (lo, hi)
}

/// A lattice edge crossed by the swept surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeCut {
    /// The edge's nodes, `a < b`.
    pub a: u32,
    /// See `a`.
    pub b: u32,
    /// Where it is crossed, from `a` (0) to `b` (1).
    pub t: f64,
    /// The swept triangle that crosses it.
    pub triangle: u32,
}

/// What a swept surface does to a lattice.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cuts {
    /// Crossed edges, sorted by `(a, b)`, each once (its first crossing from `a`).
    pub edges: Vec<EdgeCut>,
    /// Cells with at least one crossed edge, sorted.
    pub cells: Vec<u32>,
    /// Cell–triangle candidate pairs tested (the hash's work).
    pub pairs_tested: usize,
}

/// Where segment `p + t (q - p)` crosses triangle `tri`, as `t` in [0, 1] (Möller–Trumbore), or
/// `None` (no crossing, or a segment in the triangle's plane).
pub fn segment_triangle(p: &Point3<f64>, q: &Point3<f64>, tri: &[Point3<f64>; 3]) -> Option<f64> {
    let d = q - p;
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    let scale = d.norm() * e1.norm() * e2.norm();
    if det.abs() <= 1e-12 * scale {
        return None;
    }
    let s = p - tri[0];
    let u = s.dot(&h) / det;
    if !(-BARY_EPS..=1.0 + BARY_EPS).contains(&u) {
        return None;
    }
    let qv = s.cross(&e1);
    let v = d.dot(&qv) / det;
    if v < -BARY_EPS || u + v > 1.0 + BARY_EPS {
        return None;
    }
    let t = e2.dot(&qv) / det;
    (-BARY_EPS..=1.0 + BARY_EPS).contains(&t).then_some(t.clamp(0.0, 1.0))
}

/// Whether a crossing at `s` separates the edge's ends. A node lying on the surface (a crossing at
/// an end, within [`BARY_EPS`]) counts as lying on the side the triangle's normal points to, so
/// that of the edges meeting at it only those reaching the other side are cut (a cut exactly
/// through a row of nodes cuts one layer of edges, not two).
fn separates(a: &Point3<f64>, b: &Point3<f64>, s: f64, tri: &[Point3<f64>; 3]) -> bool {
    let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0]));
    let tol = BARY_EPS * (b - a).norm() * n.norm();
    if s <= BARY_EPS {
        n.dot(&(b - a)) < -tol
    } else if s >= 1.0 - BARY_EPS {
        n.dot(&(a - b)) < -tol
    } else {
        true
    }
}

/// The lattice edges and cells `surface` cuts, with the lattice's nodes at `positions` (and `hash`
/// built over them).
pub fn cut_edges(lattice: &Lattice, positions: &[Point3<f64>], hash: &impl CellIndex, surface: &SweptSurface) -> Cuts {
    let mut found: Vec<EdgeCut> = Vec::new();
    let mut candidates = Vec::new();
    let mut pairs_tested = 0;
    // The cells whose boxes met a triangle's: every cell with a crossed edge is among them (the
    // crossing lies in the triangle's box and in the box of each cell holding the edge).
    let mut near = Vec::new();
    for t in 0..surface.triangles.len() {
        let tri = surface.triangle(t);
        let (lo, hi) = bounds(tri.iter().copied());
        let (lo, hi) = padded(&lo, &hi);
        hash.candidates(&lo, &hi, &mut candidates);
        for &c in &candidates {
            let cell = &lattice.cells[c as usize];
            let (clo, chi) = bounds(cell.nodes.iter().map(|&i| positions[i as usize]));
            if (0..3).any(|a| chi[a] < lo[a] || clo[a] > hi[a]) {
                continue;
            }
            pairs_tested += 1;
            near.push(c);
            for [i, j] in CELL_EDGES {
                let (a, b) = (cell.nodes[i].min(cell.nodes[j]), cell.nodes[i].max(cell.nodes[j]));
                let (pa, pb) = (&positions[a as usize], &positions[b as usize]);
                if let Some(s) = segment_triangle(pa, pb, &tri).filter(|&s| separates(pa, pb, s, &tri)) {
                    found.push(EdgeCut { a, b, t: s, triangle: t as u32 });
                }
            }
        }
    }
    found.sort_by(|x, y| (x.a, x.b).cmp(&(y.a, y.b)).then(x.t.total_cmp(&y.t)));
    found.dedup_by(|x, y| (x.a, x.b) == (y.a, y.b));
    near.sort_unstable();
    near.dedup();
    let mut cells = Vec::new();
    for c in near {
        let cell = &lattice.cells[c as usize];
        let crossed = CELL_EDGES.iter().any(|&[i, j]| {
            let key = (cell.nodes[i].min(cell.nodes[j]), cell.nodes[i].max(cell.nodes[j]));
            found.binary_search_by(|e| (e.a, e.b).cmp(&key)).is_ok()
        });
        if crossed {
            cells.push(c);
        }
    }
    Cuts { edges: found, cells, pairs_tested }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

    use super::*;

    /// A 6 x 6 x 6 block of 1 cm cells from the origin.
    fn block() -> Lattice {
        Lattice::block(Point3::origin(), 0.01, [6, 6, 6])
    }

    /// A blade edge along x (tool frame), 8 cm long from x = -1 cm.
    fn edge() -> Vec<Point3<f64>> {
        (0..9).map(|k| Point3::new(-0.01 + 0.01 * k as f64, 0.0, 0.0)).collect()
    }

    fn cut(lattice: &Lattice, positions: &[Point3<f64>], from: Isometry3<f64>, to: Isometry3<f64>) -> Cuts {
        let hash = SpatialHash::new(lattice, positions, lattice.cell);
        let s = SweptSurface::between(&edge(), &from, &to, 0.005, 0.1).expect("surface");
        cut_edges(lattice, positions, &hash, &s)
    }

    #[test]
    fn a_tree_of_the_cells_near_the_surface_finds_what_the_whole_lattices_tree_finds() {
        // A tilted stroke through part of a larger block: the tree over the cells in the swept
        // surface's box holds fewer cells and gives the same cuts as the hash and the whole tree.
        let l = Lattice::block(Point3::origin(), 0.01, [24, 16, 6]);
        let tilt = UnitQuaternion::from_euler_angles(0.3, 0.2, 0.5);
        let (from, to) = (
            Isometry3::from_parts(Translation3::new(0.01, 0.02, 0.08), tilt),
            Isometry3::from_parts(Translation3::new(0.03, 0.04, 0.0), tilt),
        );
        let s = SweptSurface::between(&edge(), &from, &to, 0.005, 0.1).expect("surface");
        let (mut lo, mut hi) = (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
        for v in &s.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        let whole = cut_edges(&l, &l.rest, &CellTree::new(&l, &l.rest), &s);
        let near_tree = CellTree::within(&l, &l.rest, &lo, &hi);
        assert!(near_tree.len() < l.cells.len() / 2, "{} of {} cells", near_tree.len(), l.cells.len());
        let near = cut_edges(&l, &l.rest, &near_tree, &s);
        let hashed = cut_edges(&l, &l.rest, &SpatialHash::new(&l, &l.rest, l.cell), &s);
        assert!(!whole.edges.is_empty());
        assert_eq!((&near.edges, &near.cells), (&whole.edges, &whole.cells));
        assert_eq!((&hashed.edges, &hashed.cells), (&whole.edges, &whole.cells));
        // A surface away from every cell: an empty tree, no candidates, no cuts.
        let far = Point3::new(5.0, 5.0, 5.0);
        let empty = CellTree::within(&l, &l.rest, &far, &(far + Vector3::repeat(0.1)));
        assert!(empty.is_empty());
        assert!(cut_edges(&l, &l.rest, &empty, &s).edges.is_empty());
    }

    #[test]
    fn a_straight_stroke_down_through_a_block_cuts_one_layer_of_edges() {
        let l = block();
        // The edge at y = 2.5 cm, from above the block to below it.
        let c = cut(&l, &l.rest, Isometry3::translation(0.0, 0.025, 0.08), Isometry3::translation(0.0, 0.025, -0.01));
        // Every y-edge between j = 2 and j = 3: 7 x 7 of them, crossed half-way; the cells with
        // j = 2 are cut, 36 of them.
        assert_eq!(c.edges.len(), 49);
        for e in &c.edges {
            let (pa, pb) = (l.rest[e.a as usize], l.rest[e.b as usize]);
            assert!((pa.y - 0.02).abs() < 1e-12 && (pb.y - 0.03).abs() < 1e-12, "{pa} {pb}");
            assert!((e.t - 0.5).abs() < 1e-9);
        }
        assert_eq!(c.cells.len(), 36);
        assert!(c.cells.iter().all(|&k| l.cells[k as usize].ijk[1] == 2));
    }

    #[test]
    fn a_fast_sideways_stroke_does_not_tunnel() {
        let l = block();
        // The blade edge upright (along z), crossing the whole block in x in one frame.
        let upright = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2);
        let from = Isometry3::from_parts(Translation3::new(-0.02, 0.035, -0.005), upright);
        let to = Isometry3::from_parts(Translation3::new(0.09, 0.035, -0.005), upright);
        let c = cut(&l, &l.rest, from, to);
        assert_eq!(c.edges.len(), 49, "the plane y = 3.5 cm crosses every y-edge between j = 3 and 4");
        assert_eq!(c.cells.len(), 36);
    }

    #[test]
    fn a_partial_stroke_cuts_only_where_the_edge_went_and_a_deformed_lattice_is_cut_where_it_is() {
        let l = block();
        // The edge's end at x = 7 cm: shorten the stroke so the edge reaches only z = 3.5 cm.
        let c = cut(&l, &l.rest, Isometry3::translation(0.0, 0.025, 0.08), Isometry3::translation(0.0, 0.025, 0.035));
        // y-edges at z = 4, 5, 6 cm (k = 4..6), 7 along x each.
        assert_eq!(c.edges.len(), 21);
        assert!(c.edges.iter().all(|e| l.rest[e.a as usize].z > 0.035));
        // Cells with j = 2 and k >= 3 have a crossed edge (k = 3 through its top face).
        assert_eq!(c.cells.len(), 6 * 3);

        // Moving the whole lattice and the stroke together changes nothing.
        let shift = Vector3::new(0.3, -0.2, 0.1);
        let moved: Vec<Point3<f64>> = l.rest.iter().map(|p| p + shift).collect();
        let t = |z: f64| Isometry3::translation(shift.x, 0.025 + shift.y, z + shift.z);
        let c2 = cut(&l, &moved, t(0.08), t(0.035));
        assert_eq!(
            c2.edges.iter().map(|e| (e.a, e.b)).collect::<Vec<_>>(),
            c.edges.iter().map(|e| (e.a, e.b)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_stroke_through_a_row_of_nodes_cuts_the_edges_that_end_there() {
        let l = block();
        // The plane y = 2 cm passes through nodes: y-edges ending there are crossed at t = 0 or 1.
        let c = cut(&l, &l.rest, Isometry3::translation(0.0, 0.02, 0.08), Isometry3::translation(0.0, 0.02, -0.01));
        assert!(!c.edges.is_empty());
        for e in &c.edges {
            assert!(e.t < 1e-9 || e.t > 1.0 - 1e-9, "{e:?}");
        }
        // The nodes on the plane count as lying on the side its normal points to: one layer of
        // y-edges is cut, 49, at one end.
        assert_eq!(c.edges.len(), 49);
    }

    #[test]
    fn a_stroke_along_a_plane_of_nodes_cuts_one_layer_whichever_way_they_round() {
        // The nodes of the plane y = 2 cm a few units in the last place to either side of it, as
        // rest positions plus f32 displacements round: each node is still on the surface, and
        // one of its two y-edges is cut, whichever way it rounded (the cells beyond the plane
        // are tested too), through the spatial hash and the cell tree alike.
        let l = block();
        for ulps in [-3i32, -1, 1, 3] {
            let moved: Vec<Point3<f64>> = l
                .rest
                .iter()
                .map(|p| {
                    let mut y = p.y;
                    if (y - 0.02).abs() < 1e-12 {
                        for _ in 0..ulps.unsigned_abs() {
                            y = if ulps > 0 { y.next_up() } else { y.next_down() };
                        }
                    }
                    Point3::new(p.x, y, p.z)
                })
                .collect();
            let (from, to) = (Isometry3::translation(0.0, 0.02, 0.08), Isometry3::translation(0.0, 0.02, -0.01));
            let s = SweptSurface::between(&edge(), &from, &to, 0.005, 0.1).expect("surface");
            for (index, c) in
                [("hash", cut(&l, &moved, from, to)), ("tree", cut_edges(&l, &moved, &CellTree::new(&l, &moved), &s))]
            {
                assert_eq!(c.edges.len(), 49, "{ulps} ulps, {index}");
                let mut nodes: Vec<u32> = c
                    .edges
                    .iter()
                    .map(|e| if (l.rest[e.a as usize].y - 0.02).abs() < 1e-12 { e.a } else { e.b })
                    .collect();
                nodes.sort_unstable();
                nodes.dedup();
                assert_eq!(nodes.len(), 49, "every node of the plane cut once: {ulps} ulps, {index}");
            }
        }
    }

    #[test]
    fn the_cell_tree_and_the_hash_find_the_same_cuts_on_a_deformed_lattice() {
        let l = block();
        // A twisted, sheared lattice, and a tilted stroke through it.
        let moved: Vec<Point3<f64>> = l
            .rest
            .iter()
            .map(|p| Point3::new(p.x + 0.3 * p.z, p.y + 0.2 * (40.0 * p.x).sin() * 0.01, p.z + 0.1 * p.y))
            .collect();
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.4);
        let from = Isometry3::from_parts(Translation3::new(0.0, 0.02, 0.09), tilt);
        let to = Isometry3::from_parts(Translation3::new(0.01, 0.035, -0.02), tilt);
        let s = SweptSurface::between(&edge(), &from, &to, 0.004, 0.1).expect("surface");
        let by_hash = cut_edges(&l, &moved, &SpatialHash::new(&l, &moved, l.cell), &s);
        let by_tree = cut_edges(&l, &moved, &CellTree::new(&l, &moved), &s);
        assert!(by_hash.edges.len() > 40, "{} edges", by_hash.edges.len());
        assert_eq!(by_tree.edges, by_hash.edges);
        assert_eq!(by_tree.cells, by_hash.cells);
    }

    #[test]
    fn segments_and_triangles() {
        let tri = [Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0)];
        let t = segment_triangle(&Point3::new(0.2, 0.2, -1.0), &Point3::new(0.2, 0.2, 1.0), &tri);
        assert!((t.expect("hit") - 0.5).abs() < 1e-15);
        assert!(segment_triangle(&Point3::new(0.8, 0.8, -1.0), &Point3::new(0.8, 0.8, 1.0), &tri).is_none());
        assert!(segment_triangle(&Point3::new(0.2, 0.2, 0.5), &Point3::new(0.2, 0.2, 1.0), &tri).is_none());
        // In the plane: not a crossing.
        assert!(segment_triangle(&Point3::new(-1.0, 0.2, 0.0), &Point3::new(1.0, 0.2, 0.0), &tri).is_none());
    }
}
