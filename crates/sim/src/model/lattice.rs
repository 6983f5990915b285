//! The regular hexahedral lattice a body is discretised on.
//!
//! Cells are axis-aligned cubes of side `cell`; node (i, j, k) rests at `origin + cell * (i, j, k)`.
//! Only cells holding material are kept. Corner `c` (0..8) of a cell is the node at offset
//! `(c & 1, (c >> 1) & 1, (c >> 2) & 1)` from the cell's lowest corner.

use nalgebra::{Point3, Vector3};

/// Offsets of a cell's eight corners, in the corner order every module uses.
pub const CORNERS: [[usize; 3]; 8] =
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]];

/// The twelve edges of a cell as pairs of corners (see [`CORNERS`]): four along x, y, z.
pub const CELL_EDGES: [[usize; 2]; 12] =
    [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]];

/// One hexahedral cell of the lattice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Grid index of the cell's lowest corner.
    pub ijk: [u32; 3],
    /// Node indices of its eight corners (see [`CORNERS`]).
    pub nodes: [u32; 8],
    /// Share of the cell's volume filled with material, in (0, 1].
    pub fraction: f32,
}

/// A lattice of cells and the nodes they use.
#[derive(Debug, Clone)]
pub struct Lattice {
    /// Rest position of grid node (0, 0, 0), metres.
    pub origin: Point3<f64>,
    /// Cell side, metres.
    pub cell: f64,
    /// Number of cells along x, y, z of the bounding grid.
    pub dims: [usize; 3],
    /// Cells holding material, in grid order (x fastest).
    pub cells: Vec<Cell>,
    /// Grid index of each node.
    pub node_ijk: Vec<[u32; 3]>,
    /// Rest position of each node, metres.
    pub rest: Vec<Point3<f64>>,
    /// For each grid node (x fastest, `(dims + 1)` per axis), its node index or `u32::MAX`.
    grid_to_node: Vec<u32>,
}

impl Lattice {
    /// Builds a lattice from per-cell material fractions over a grid: `fraction[idx]` with
    /// `idx = i + dims[0] * (j + dims[1] * k)`. Cells with a fraction below `min_fraction` are
    /// dropped (they hold too little material to matter and would only shrink the stable time step).
    pub fn from_fractions(
        origin: Point3<f64>,
        cell: f64,
        dims: [usize; 3],
        fraction: &[f32],
        min_fraction: f32,
    ) -> Self {
        let [nx, ny, _] = dims;
        let gx = nx + 1;
        let gy = ny + 1;
        let grid_nodes = (nx + 1) * (ny + 1) * (dims[2] + 1);
        let kept = |i: usize, j: usize, k: usize| {
            let f = fraction[i + nx * (j + ny * k)];
            f >= min_fraction && f > 0.0
        };
        // Nodes are numbered in grid order (x fastest), so the nodes of a run of cells along x are
        // runs of consecutive indices: TLED loads such cells' corners as contiguous slices.
        let mut grid_to_node = vec![u32::MAX; grid_nodes];
        for k in 0..dims[2] {
            for j in 0..ny {
                for i in 0..nx {
                    if kept(i, j, k) {
                        for off in &CORNERS {
                            grid_to_node[(i + off[0]) + gx * ((j + off[1]) + gy * (k + off[2]))] = 0;
                        }
                    }
                }
            }
        }
        let mut node_ijk = Vec::new();
        for (g, slot) in grid_to_node.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = node_ijk.len() as u32;
                node_ijk.push([(g % gx) as u32, ((g / gx) % gy) as u32, (g / (gx * gy)) as u32]);
            }
        }
        let mut cells = Vec::new();
        for k in 0..dims[2] {
            for j in 0..ny {
                for i in 0..nx {
                    if !kept(i, j, k) {
                        continue;
                    }
                    let nodes = CORNERS.map(|off| grid_to_node[(i + off[0]) + gx * ((j + off[1]) + gy * (k + off[2]))]);
                    cells.push(Cell {
                        ijk: [i as u32, j as u32, k as u32],
                        nodes,
                        fraction: fraction[i + nx * (j + ny * k)].min(1.0),
                    });
                }
            }
        }
        let rest = node_ijk
            .iter()
            .map(|ijk| origin + Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) * cell)
            .collect();
        Self { origin, cell, dims, cells, node_ijk, rest, grid_to_node }
    }

    /// A full box of `n` cells per axis spanning `[min, min + n * cell]`.
    pub fn block(min: Point3<f64>, cell: f64, n: [usize; 3]) -> Self {
        Self::from_fractions(min, cell, n, &vec![1.0; n[0] * n[1] * n[2]], 0.0)
    }

    /// This lattice's grid with other cells over its nodes and extra nodes appended (each a copy
    /// of an existing node: same rest position and grid index). Cut lattices are made this way:
    /// cell copies over real and virtual nodes. [`Lattice::node_at`] still finds the original
    /// nodes only.
    pub fn with_cells(&self, cells: Vec<Cell>, copies_of: &[u32]) -> Lattice {
        let mut out = self.clone();
        out.cells = cells;
        for &n in copies_of {
            out.rest.push(self.rest[n as usize]);
            out.node_ijk.push(self.node_ijk[n as usize]);
        }
        out
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.rest.len()
    }

    /// The node at grid index `ijk`, if it belongs to an active cell.
    pub fn node_at(&self, ijk: [usize; 3]) -> Option<u32> {
        if ijk.iter().zip(&self.dims).any(|(&a, &d)| a > d) {
            return None;
        }
        let g = ijk[0] + (self.dims[0] + 1) * (ijk[1] + (self.dims[1] + 1) * ijk[2]);
        self.grid_to_node.get(g).copied().filter(|&n| n != u32::MAX)
    }

    /// Lumped node masses, kilograms: each cell gives an eighth of its material mass to each corner.
    pub fn lumped_masses(&self, density: f64) -> Vec<f64> {
        let v = self.cell.powi(3);
        let mut m = vec![0.0; self.node_count()];
        for c in &self.cells {
            let share = density * v * f64::from(c.fraction) / 8.0;
            for &n in &c.nodes {
                m[n as usize] += share;
            }
        }
        m
    }

    /// Total material volume, cubic metres.
    pub fn volume(&self) -> f64 {
        let v = self.cell.powi(3);
        self.cells.iter().map(|c| f64::from(c.fraction) * v).sum()
    }

    /// For every node, the (cell, corner) pairs that touch it, as a compressed list:
    /// `offsets[n]..offsets[n + 1]` indexes `entries`. Used to gather element forces without atomics.
    pub fn node_to_cells(&self) -> (Vec<u32>, Vec<(u32, u8)>) {
        let mut count = vec![0u32; self.node_count() + 1];
        for c in &self.cells {
            for &n in &c.nodes {
                count[n as usize + 1] += 1;
            }
        }
        for i in 1..count.len() {
            count[i] += count[i - 1];
        }
        let mut fill = count.clone();
        let mut entries = vec![(0u32, 0u8); count[self.node_count()] as usize];
        for (ci, c) in self.cells.iter().enumerate() {
            for (corner, &n) in c.nodes.iter().enumerate() {
                let slot = &mut fill[n as usize];
                entries[*slot as usize] = (ci as u32, corner as u8);
                *slot += 1;
            }
        }
        (count, entries)
    }

    /// The cell containing point `p` (rest frame) and its trilinear weights for the 8 corners, if
    /// `p` lies in an active cell (points on shared faces go to the lower cell on each axis, clamped).
    pub fn locate(&self, p: &Point3<f64>) -> Option<(usize, [f64; 8])> {
        let rel = (p - self.origin) / self.cell;
        let mut ijk = [0usize; 3];
        let mut t = [0.0; 3];
        for a in 0..3 {
            let x = rel[a];
            if !(x >= -1e-9 && x <= self.dims[a] as f64 + 1e-9) {
                return None;
            }
            let i = (x.floor().max(0.0) as usize).min(self.dims[a] - 1);
            ijk[a] = i;
            t[a] = (x - i as f64).clamp(0.0, 1.0);
        }
        let cell = self.cell_index(ijk)?;
        let mut w = [0.0; 8];
        for (c, off) in CORNERS.iter().enumerate() {
            w[c] = (0..3).map(|a| if off[a] == 1 { t[a] } else { 1.0 - t[a] }).product();
        }
        Some((cell, w))
    }

    /// Index into `cells` of the active cell at grid index `ijk`.
    pub fn cell_index(&self, ijk: [usize; 3]) -> Option<usize> {
        let key = [ijk[0] as u32, ijk[1] as u32, ijk[2] as u32];
        // Cells are sorted in grid order (x fastest): binary search on (k, j, i).
        self.cells.binary_search_by(|c| (c.ijk[2], c.ijk[1], c.ijk[0]).cmp(&(key[2], key[1], key[0]))).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_shares_nodes() {
        let l = Lattice::block(Point3::origin(), 0.01, [2, 3, 4]);
        assert_eq!(l.cells.len(), 24);
        assert_eq!(l.node_count(), 3 * 4 * 5);
        assert!((l.volume() - 24e-6).abs() < 1e-15);
        let (off, entries) = l.node_to_cells();
        assert_eq!(entries.len(), 24 * 8);
        // An interior node touches 8 cells, a corner node 1.
        let interior = l.node_at([1, 1, 1]).expect("node") as usize;
        assert_eq!(off[interior + 1] - off[interior], 8);
        let corner = l.node_at([0, 0, 0]).expect("node") as usize;
        assert_eq!(off[corner + 1] - off[corner], 1);
        let (cell, w) = l.locate(&Point3::new(0.015, 0.005, 0.035)).expect("inside");
        assert_eq!(l.cells[cell].ijk, [1, 0, 3]);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
