//! Node accumulators of the TLED element pass, one per slab of cells.
//!
//! The element pass runs over contiguous slabs of cell batches in parallel. Each slab adds its
//! cells' corner forces into its own accumulators, which cover the run of nodes its cells touch
//! (cells and nodes are both in grid order, so the runs of neighbouring slabs overlap only on the
//! node layer they share): a batch of eight cells along a row adds each corner's forces to eight
//! consecutive nodes, as whole vectors. A node's internal force is then the sum of its one or two
//! slab accumulators, gathered per node as before: no atomics, no locks, and the same sums in the
//! same order on every run.

use nalgebra::Vector3;

use crate::model::tled_batch::LANES;

/// The accumulators for one split of the cells into slabs.
#[derive(Debug, Clone, Default)]
pub(crate) struct Slabs {
    /// Batches of [`LANES`] cells per slab.
    pub chunk: usize,
    /// Per slab: the first node of its run.
    first_node: Vec<usize>,
    /// Per slab: where its run starts in the accumulators; one more entry for the end.
    start: Vec<usize>,
    /// Accumulated forces, one array per component.
    acc: [Vec<f32>; 3],
    /// Node → its accumulator slots (one per slab whose cells touch it), compressed rows.
    offsets: Vec<u32>,
    slots: Vec<u32>,
    /// Per slab whose cells touch under a quarter of its run (a subset of a lattice's cells: an
    /// operational region, whose cells in grid order span most of the nodes between them): the
    /// run's entries they touch, the only ones the element pass zeroes and fills.
    sparse: Vec<Option<Vec<u32>>>,
}

/// One slab's share of the accumulators: its first node and its three component runs.
pub(crate) struct SlabAccumulators<'a> {
    pub first_node: usize,
    pub acc: [&'a mut [f32]; 3],
    /// The entries of the run its cells touch, when few: only those need zeroing.
    pub touched: Option<&'a [u32]>,
}

impl Slabs {
    /// Accumulators for slabs of `chunk` batches over `cell_nodes`, on a lattice of `node_count`
    /// nodes.
    pub fn new(cell_nodes: &[[u32; 8]], node_count: usize, chunk: usize) -> Self {
        let per_slab = (chunk * LANES).max(1);
        let mut first_node = Vec::new();
        let mut start = vec![0];
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        let mut sparse = Vec::new();
        for cells in cell_nodes.chunks(per_slab) {
            let lo = cells.iter().flatten().copied().min().unwrap_or(0) as usize;
            let hi = cells.iter().flatten().copied().max().map_or(lo, |h| h as usize + 1);
            let base = start[start.len() - 1];
            let mut seen = vec![false; hi - lo];
            let mut touched = Vec::new();
            for &n in cells.iter().flatten() {
                let local = n as usize - lo;
                if !seen[local] {
                    seen[local] = true;
                    touched.push(local as u32);
                    pairs.push((n, (base + local) as u32));
                }
            }
            touched.sort_unstable();
            sparse.push((touched.len() * 4 < hi - lo).then_some(touched));
            first_node.push(lo);
            start.push(base + hi - lo);
        }
        let mut offsets = vec![0u32; node_count + 1];
        for &(n, _) in &pairs {
            offsets[n as usize + 1] += 1;
        }
        for i in 1..=node_count {
            offsets[i] += offsets[i - 1];
        }
        let mut fill = offsets.clone();
        let mut slots = vec![0u32; pairs.len()];
        for (n, slot) in pairs {
            slots[fill[n as usize] as usize] = slot;
            fill[n as usize] += 1;
        }
        let total = start[start.len() - 1];
        Self { chunk, first_node, start, acc: std::array::from_fn(|_| vec![0.0; total]), offsets, slots, sparse }
    }

    /// Each slab's accumulators, in slab order, for the element pass to fill in parallel.
    pub fn split(&mut self) -> Vec<SlabAccumulators<'_>> {
        let [x, y, z] = &mut self.acc;
        let (mut x, mut y, mut z) = (x.as_mut_slice(), y.as_mut_slice(), z.as_mut_slice());
        let mut parts = Vec::with_capacity(self.first_node.len());
        for (k, &first_node) in self.first_node.iter().enumerate() {
            let len = self.start[k + 1] - self.start[k];
            let (xs, xr) = std::mem::take(&mut x).split_at_mut(len);
            let (ys, yr) = std::mem::take(&mut y).split_at_mut(len);
            let (zs, zr) = std::mem::take(&mut z).split_at_mut(len);
            (x, y, z) = (xr, yr, zr);
            parts.push(SlabAccumulators { first_node, acc: [xs, ys, zs], touched: self.sparse[k].as_deref() });
        }
        parts
    }

    /// Number of slabs whose cells touch node `n`.
    #[cfg(test)]
    pub fn slot_count(&self, n: usize) -> usize {
        (self.offsets[n + 1] - self.offsets[n]) as usize
    }

    /// Node `n`'s force: the sum of its slabs' accumulators.
    #[inline(always)]
    pub fn node_force(&self, n: usize) -> Vector3<f32> {
        let mut f = Vector3::zeros();
        for &slot in &self.slots[self.offsets[n] as usize..self.offsets[n + 1] as usize] {
            let s = slot as usize;
            f += Vector3::new(self.acc[0][s], self.acc[1][s], self.acc[2][s]);
        }
        f
    }
}
