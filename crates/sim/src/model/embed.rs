//! Embedding a high-resolution surface in the lattice: each surface vertex follows the trilinear
//! interpolation of the eight nodes of one cell.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::lattice::{CORNERS, Lattice};

/// How far outside its cell, in cells, a vertex may lie and still be reproduced exactly by
/// extrapolated trilinear weights; beyond this the local coordinates are clamped (and the vertex
/// moves). One cell covers vertices in a dropped cell next to an active one.
const MAX_EXTRAPOLATION: f64 = 1.0;

/// Vertices per rayon task in [`Embedding::positions_into`].
const CHUNK: usize = 1024;

/// What can go wrong embedding a surface.
#[derive(Debug, thiserror::Error)]
pub enum EmbedError {
    /// The lattice has no cells to embed into.
    #[error("cannot embed a surface in a lattice without cells")]
    EmptyLattice,
    /// A vertex has a non-finite coordinate.
    #[error("surface vertex {vertex} has a non-finite coordinate")]
    NonFinite {
        /// Index of the vertex.
        vertex: usize,
    },
}

/// Each surface vertex's cell and trilinear weights in a [`Lattice`].
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    /// Index into `lattice.cells` of each vertex's cell.
    pub cell: Vec<u32>,
    /// Weights of the cell's corners ([`CORNERS`] order); they sum to 1.
    pub weights: Vec<[f32; 8]>,
    /// Vertices that lay in no active cell (in a dropped cell or just outside the grid) and were
    /// given the nearest active cell instead, with extrapolated weights.
    pub outside: usize,
    /// Of those, the ones farther than one cell from it, whose local coordinates were clamped: their
    /// embedded rest position differs from the vertex.
    pub clamped: usize,
    /// Largest distance between a vertex and its embedded rest position, metres (0 unless `clamped`).
    pub max_shift: f64,
}

impl Embedding {
    /// Embeds `vertices` (rest positions, metres) in `lattice`: the active cell containing each vertex
    /// ([`Lattice::locate`]), or else the nearest active cell (by distance to the cell's box) with
    /// local coordinates allowed up to one cell outside it and clamped beyond.
    pub fn new(lattice: &Lattice, vertices: &[Point3<f64>]) -> Result<Self, EmbedError> {
        if lattice.cells.is_empty() {
            return Err(EmbedError::EmptyLattice);
        }
        if let Some(vertex) = vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(EmbedError::NonFinite { vertex });
        }
        let found: Vec<(usize, [f64; 8], bool, f64)> = vertices
            .par_iter()
            .map(|p| match lattice.locate(p) {
                Some((cell, w)) => (cell, w, false, 0.0),
                None => {
                    let cell = nearest_cell(lattice, p);
                    let (w, shift) = weights_in(lattice, cell, p);
                    (cell, w, true, shift)
                }
            })
            .collect();
        let mut e = Self {
            cell: Vec::with_capacity(vertices.len()),
            weights: Vec::with_capacity(vertices.len()),
            outside: 0,
            clamped: 0,
            max_shift: 0.0,
        };
        for (cell, w, outside, shift) in found {
            e.cell.push(cell as u32);
            e.weights.push(w.map(|x| x as f32));
            e.outside += usize::from(outside);
            e.clamped += usize::from(shift > 0.0);
            e.max_shift = e.max_shift.max(shift);
        }
        if e.outside > 0 {
            tracing::debug!(outside = e.outside, clamped = e.clamped, max_shift = e.max_shift, "surface embedding");
        }
        Ok(e)
    }

    /// Number of embedded vertices.
    pub fn len(&self) -> usize {
        self.cell.len()
    }

    /// Whether no vertex is embedded.
    pub fn is_empty(&self) -> bool {
        self.cell.is_empty()
    }

    /// Current vertex positions from current node positions (`node_positions[n]` for node `n`, the
    /// order of `lattice.rest`), written into `out` (resized; no allocation once it has the
    /// capacity). `lattice` must be the one embedded into (same cells).
    pub fn positions_into(&self, lattice: &Lattice, node_positions: &[Vector3<f32>], out: &mut Vec<Point3<f32>>) {
        debug_assert_eq!(node_positions.len(), lattice.node_count());
        out.resize(self.len(), Point3::origin());
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
            let start = chunk * CHUNK;
            for (i, o) in out.iter_mut().enumerate() {
                let v = start + i;
                let nodes = &lattice.cells[self.cell[v] as usize].nodes;
                let w = &self.weights[v];
                let mut p = Vector3::zeros();
                for c in 0..8 {
                    p += node_positions[nodes[c] as usize] * w[c];
                }
                *o = Point3::from(p);
            }
        });
    }

    /// [`Embedding::positions_into`] into a new vector.
    pub fn positions(&self, lattice: &Lattice, node_positions: &[Vector3<f32>]) -> Vec<Point3<f32>> {
        let mut out = Vec::new();
        self.positions_into(lattice, node_positions, &mut out);
        out
    }
}

/// Trilinear weights of `p` in cell `cell`, local coordinates limited to
/// `[-MAX_EXTRAPOLATION, 1 + MAX_EXTRAPOLATION]`, and how far that limit moved `p`.
fn weights_in(lattice: &Lattice, cell: usize, p: &Point3<f64>) -> ([f64; 8], f64) {
    let ijk = lattice.cells[cell].ijk;
    let lo = lattice.origin + Vector3::new(f64::from(ijk[0]), f64::from(ijk[1]), f64::from(ijk[2])) * lattice.cell;
    let t = Vector3::from_fn(|a, _| ((p[a] - lo[a]) / lattice.cell).clamp(-MAX_EXTRAPOLATION, 1.0 + MAX_EXTRAPOLATION));
    let shift = (lo + t * lattice.cell - p).norm();
    let mut w = [0.0; 8];
    for (c, off) in CORNERS.iter().enumerate() {
        w[c] = (0..3).map(|a| if off[a] == 1 { t[a] } else { 1.0 - t[a] }).product();
    }
    // Points within the extrapolation range are reproduced up to rounding; report only real moves.
    (w, if shift > 1e-9 * lattice.cell { shift } else { 0.0 })
}

/// Squared distance from `p` to the box of the grid cell `ijk`.
fn box_distance2(lattice: &Lattice, ijk: [usize; 3], p: &Point3<f64>) -> f64 {
    (0..3)
        .map(|a| {
            let lo = lattice.origin[a] + ijk[a] as f64 * lattice.cell;
            let d = (lo - p[a]).max(p[a] - lo - lattice.cell).max(0.0);
            d * d
        })
        .sum()
}

/// Index of the active cell nearest to `p` (ties go to the lower index). Searches shells of grid
/// cells around `p`'s grid cell, stopping once no farther shell can be closer; after eight shells it
/// scans every cell. The lattice must have cells.
fn nearest_cell(lattice: &Lattice, p: &Point3<f64>) -> usize {
    let dims = lattice.dims;
    let home = [0, 1, 2].map(|a| {
        let x = ((p[a] - lattice.origin[a]) / lattice.cell).floor();
        (x.max(0.0) as usize).min(dims[a] - 1) as i64
    });
    let mut best: Option<(f64, usize)> = None;
    let consider = |d2: f64, ci: usize, best: &mut Option<(f64, usize)>| {
        if best.is_none_or(|(bd, bi)| d2 < bd || (d2 == bd && ci < bi)) {
            *best = Some((d2, ci));
        }
    };
    for r in 0..8i64 {
        // Every cell in shell r is at least (r - 1) cells away along some axis.
        if let Some((d2, _)) = best {
            let bound = (r - 1).max(0) as f64 * lattice.cell;
            if bound * bound > d2 {
                break;
            }
        }
        for k in home[2] - r..=home[2] + r {
            for j in home[1] - r..=home[1] + r {
                for i in home[0] - r..=home[0] + r {
                    let d = [i, j, k];
                    if (0..3).any(|a| d[a] < 0 || d[a] >= dims[a] as i64) {
                        continue;
                    }
                    if (0..3).all(|a| (d[a] - home[a]).abs() < r) {
                        continue;
                    }
                    let ijk = d.map(|x| x as usize);
                    if let Some(ci) = lattice.cell_index(ijk) {
                        consider(box_distance2(lattice, ijk, p), ci, &mut best);
                    }
                }
            }
        }
    }
    if let Some((_, ci)) = best {
        return ci;
    }
    let mut best = None;
    for (ci, c) in lattice.cells.iter().enumerate() {
        consider(box_distance2(lattice, c.ijk.map(|x| x as usize), p), ci, &mut best);
    }
    best.map_or(0, |(_, ci)| ci)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertices_outside_go_to_the_nearest_cell() {
        // 3 x 1 x 1 cells, the middle one dropped.
        let l = Lattice::from_fractions(Point3::origin(), 1.0, [3, 1, 1], &[1.0, 0.01, 1.0], 0.05);
        assert_eq!(l.cells.len(), 2);
        let verts = [
            Point3::new(0.5, 0.5, 0.5),
            Point3::new(1.2, 0.5, 0.5),  // dropped cell, nearer the first
            Point3::new(1.9, 0.5, 0.5),  // dropped cell, nearer the second
            Point3::new(3.3, 0.5, 0.5),  // outside the grid, within one cell
            Point3::new(0.5, 0.5, -2.5), // two and a half cells below: clamped
        ];
        let e = Embedding::new(&l, &verts).expect("embed");
        assert_eq!(e.cell, vec![0, 0, 1, 1, 0]);
        assert_eq!((e.outside, e.clamped), (4, 1));
        assert!((e.max_shift - 1.5).abs() < 1e-12, "{}", e.max_shift);
        let nodes: Vec<Vector3<f32>> = l.rest.iter().map(|p| p.coords.cast()).collect();
        let pos = e.positions(&l, &nodes);
        for (p, v) in pos.iter().zip(&verts).take(4) {
            assert!((p.coords.cast::<f64>() - v.coords).norm() < 1e-6);
        }
        assert!((pos[4].z - -1.0).abs() < 1e-6);
        // A rigid translation of the nodes moves every vertex by it.
        let moved: Vec<Vector3<f32>> = nodes.iter().map(|n| n + Vector3::new(0.1, -0.2, 0.3)).collect();
        let pos2 = e.positions(&l, &moved);
        for (a, b) in pos2.iter().zip(&pos) {
            assert!((a - b - Vector3::new(0.1, -0.2, 0.3)).norm() < 1e-5);
        }
    }

    proptest::proptest! {
        /// Trilinear interpolation reproduces affine maps, extrapolated weights included: when the nodes
        /// move by x -> A x + b, so does every embedded point (within one cell outside the lattice).
        #[test]
        fn embedded_points_follow_affine_node_motion(
            p in proptest::array::uniform3(-0.009..0.039f64),
            a in proptest::array::uniform9(-0.3..0.3f64),
            b in proptest::array::uniform3(-0.01..0.01f64),
        ) {
            let l = Lattice::block(Point3::origin(), 0.01, [3, 3, 3]);
            let p = Point3::from(p);
            let e = Embedding::new(&l, &[p]).expect("embed");
            proptest::prop_assert_eq!(e.clamped, 0);
            let m = nalgebra::Matrix3::from_row_slice(&a) + nalgebra::Matrix3::identity();
            let map = |x: &Point3<f64>| m * x.coords + Vector3::from(b);
            let nodes: Vec<Vector3<f32>> = l.rest.iter().map(|x| map(x).cast()).collect();
            let got = e.positions(&l, &nodes)[0].coords.cast::<f64>();
            // f32 node coordinates of ~0.05 m and weights up to 2 in magnitude: ~1e-8 m of rounding.
            proptest::prop_assert!((got - map(&p)).norm() < 1e-6, "{} vs {}", got, map(&p));
        }
    }

    #[test]
    fn empty_lattice_is_an_error() {
        let l = Lattice::from_fractions(Point3::origin(), 1.0, [1, 1, 1], &[0.0], 0.05);
        assert!(matches!(Embedding::new(&l, &[Point3::origin()]), Err(EmbedError::EmptyLattice)));
    }
}
