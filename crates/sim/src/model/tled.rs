//! Total Lagrangian explicit dynamics (TLED, Miller et al. 2007) on the regular hexahedral lattice.
//!
//! Every cell of the lattice is a cube of the same side, so all cells share their shape-function
//! derivatives and hourglass vectors: per-cell storage is the node list and the material volume.
//! Forces are computed in two passes without atomics or locks: an element pass (in parallel over
//! slabs of cells, eight cells per SIMD batch) adds each cell's eight nodal forces into its slab's
//! node accumulators (module `tled_slabs`), then a node pass gathers each node's one or two slab
//! sums. Both run under `pulp`'s runtime dispatch.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use crate::lattice::{CORNERS, Lattice};
use crate::material::{first_piola, regularize};
use crate::model::tled_batch::{BatchForces, LANES, OnePointConstants};
use crate::model::tled_slabs::{SlabAccumulators, Slabs};
use crate::{Material, SimError};

/// Quadrature of the hexahedra.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Integration {
    /// One point at the centre with Flanagan–Belytschko hourglass control: cheap, and free of
    /// volumetric locking for nearly incompressible tissue.
    OnePoint,
    /// Full 2x2x2 Gauss quadrature: no hourglass modes, 8x the cost, locks as ν → 0.5.
    Gauss8,
}

/// TLED settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TledParams {
    /// Quadrature.
    pub integration: Integration,
    /// Hourglass stiffness coefficient (one-point only), applied to 4μ (see [`Tled`]); 0.05–0.1.
    pub hourglass: f32,
}

impl Default for TledParams {
    fn default() -> Self {
        Self { integration: Integration::OnePoint, hourglass: 0.075 }
    }
}

/// Determinant of F below which an element is treated as inverted (its F is regularized).
pub const INVERSION_J: f32 = 0.05;

/// Signs `(ξ_a, η_a, ζ_a)` of corner `a` in the reference cube `[-1, 1]³`.
fn corner_signs() -> [[f32; 3]; 8] {
    CORNERS.map(|o| o.map(|d| if d == 1 { 1.0 } else { -1.0 }))
}

/// The four hourglass base vectors `h_α` (ηζ, ξζ, ξη, ξηζ) at the eight corners.
fn hourglass_vectors() -> [[f32; 4]; 8] {
    corner_signs().map(|[x, y, z]| [y * z, x * z, x * y, x * y * z])
}

/// Shape-function derivatives ∂N_a/∂X of a cube of side `h` at reference point `(ξ, η, ζ)`.
fn shape_derivatives(h: f32, p: [f32; 3]) -> [[f32; 3]; 8] {
    let s = corner_signs();
    let mut d = [[0.0; 3]; 8];
    for a in 0..8 {
        let f = |k: usize| 1.0 + p[k] * s[a][k];
        // N_a = (1/8) Π (1 + ξ_k s_k); dξ/dX = 2/h.
        d[a] =
            [s[a][0] * f(1) * f(2) / (4.0 * h), s[a][1] * f(0) * f(2) / (4.0 * h), s[a][2] * f(0) * f(1) / (4.0 * h)];
    }
    d
}

/// The TLED force model for a set of cells of a lattice.
#[derive(Debug, Clone)]
pub struct Tled {
    pub(crate) params: TledParams,
    lambda: f32,
    mu: f32,
    /// Node indices of each simulated cell.
    pub(crate) cell_nodes: Vec<[u32; 8]>,
    /// Material volume of each cell, m³.
    pub(crate) volume: Vec<f32>,
    /// ∂N/∂X at the centre, shared by every cell.
    dndx: [[f32; 3]; 8],
    /// ∂N/∂X at the 8 Gauss points, shared.
    dndx_gauss: [[[f32; 3]; 8]; 8],
    /// Hourglass base vectors, shared.
    hg: [[f32; 4]; 8],
    /// Corner signs s_a, shared.
    signs: [[f32; 3]; 8],
    /// Hourglass stiffness of a full cell, N/m: κ = coeff · 4μ · V Σ|∇N|² / 8. Scaled by the shear
    /// modulus, not by λ + 2μ as in NiftySim: hourglass modes are bending modes, and a bulk-scaled
    /// stiffness locks them as ν → 0.5 (measured on the cantilever test: 0.83x beam theory at
    /// ν = 0.45 with λ + 2μ, 0.94x with 4μ; at ν = 0.3 the two differ by 14%).
    hg_kappa_full: f32,
    cell_volume_full: f32,
    /// Per batch of [`LANES`] cells: whether its corners load as contiguous runs.
    contiguous: Vec<bool>,
    /// The slabs' node accumulators, for the slab size last used.
    slabs: Slabs,
    /// The SIMD instruction sets found at run time.
    arch: pulp::Arch,
    /// Cells regularized in the last force evaluation.
    inverted: usize,
    pub(crate) node_count: usize,
}

impl Tled {
    /// TLED over the given cells of `lattice` (all cells when `cells` is `None`).
    pub fn new(
        lattice: &Lattice,
        cells: Option<&[usize]>,
        material: &Material,
        params: TledParams,
    ) -> Result<Self, SimError> {
        material.validate()?;
        if !(params.hourglass.is_finite() && params.hourglass >= 0.0) {
            return Err(SimError::Invalid {
                key: "tled.hourglass".into(),
                message: format!("must be >= 0, got {}", params.hourglass),
            });
        }
        let all: Vec<usize>;
        let cells = match cells {
            Some(c) => c,
            None => {
                all = (0..lattice.cells.len()).collect();
                &all
            }
        };
        let h = lattice.cell as f32;
        let full = h * h * h;
        let cell_nodes: Vec<[u32; 8]> = cells.iter().map(|&c| lattice.cells[c].nodes).collect();
        let volume = cells.iter().map(|&c| lattice.cells[c].fraction * full).collect();
        let dndx = shape_derivatives(h, [0.0; 3]);
        let g = 1.0 / 3.0f32.sqrt();
        let dndx_gauss = corner_signs().map(|s| shape_derivatives(h, [s[0] * g, s[1] * g, s[2] * g]));
        let sum_sq: f32 = dndx.iter().map(|d| d.iter().map(|x| x * x).sum::<f32>()).sum();
        let (lambda, mu) = (material.lambda as f32, material.mu as f32);
        let hg_kappa_full = params.hourglass * 4.0 * mu * full * sum_sq / 8.0;
        let mut tled = Self {
            params,
            lambda,
            mu,
            slabs: Slabs::default(),
            contiguous: cell_nodes.chunks(LANES).map(crate::model::tled_batch::is_contiguous).collect(),
            arch: crate::model::simd_arch(),
            cell_nodes,
            volume,
            dndx,
            dndx_gauss,
            hg: hourglass_vectors(),
            signs: corner_signs(),
            hg_kappa_full,
            cell_volume_full: full,
            inverted: 0,
            node_count: lattice.node_count(),
        };
        tled.slabs = Slabs::new(&tled.cell_nodes, tled.node_count, tled.slab_batches());
        Ok(tled)
    }

    /// Batches per slab of the element pass: a few slabs per thread, so work balances without the
    /// per-task overhead of fine chunks.
    fn slab_batches(&self) -> usize {
        let threads = rayon::current_num_threads().max(1);
        self.cell_nodes.len().div_ceil(LANES).div_ceil(4 * threads).max(8)
    }

    /// Number of simulated cells.
    pub fn cell_count(&self) -> usize {
        self.cell_nodes.len()
    }

    /// Node indices of the simulated cells.
    pub fn cell_nodes(&self) -> &[[u32; 8]] {
        &self.cell_nodes
    }

    /// Cells whose deformation gradient was regularized (inverted or nearly so) in the last call to
    /// [`Tled::internal_forces`].
    pub fn inverted_cells(&self) -> usize {
        self.inverted
    }

    /// The settings.
    pub fn params(&self) -> TledParams {
        self.params
    }

    /// Internal nodal forces `f_int(u)` for displacements `u` (one per lattice node), written into
    /// `out` (nodes outside the simulated cells get zero).
    pub fn internal_forces(&mut self, u: &[Vector3<f32>], out: &mut [Vector3<f32>]) {
        self.element_pass(u);
        let threads = rayon::current_num_threads().max(1);
        let slabs = &self.slabs;
        let node_chunk = out.len().div_ceil(4 * threads).max(256);
        out.par_chunks_mut(node_chunk).enumerate().for_each(|(k, nodes)| {
            for (i, f) in nodes.iter_mut().enumerate() {
                *f = slabs.node_force(k * node_chunk + i);
            }
        });
    }

    /// The element pass alone: every cell's nodal forces for displacements `u`, summed per slab,
    /// for [`Tled::node_force`] (which an integrator can call as it updates each node, saving a
    /// pass).
    pub fn element_pass(&mut self, u: &[Vector3<f32>]) {
        let chunk = self.slab_batches();
        if self.slabs.chunk != chunk {
            self.slabs = Slabs::new(&self.cell_nodes, self.node_count, chunk);
        }
        // Take the accumulators out so the slabs can read `self` while writing them.
        let mut slabs = std::mem::take(&mut self.slabs);
        let this = &*self;
        let arch = self.arch;
        let inverted: usize = slabs
            .split()
            .into_par_iter()
            .enumerate()
            .map(|(k, out)| arch.dispatch(SlabPass { tled: this, first: k * chunk, batches: chunk, u, out }))
            .sum();
        self.slabs = slabs;
        self.inverted = inverted;
    }

    /// Node `n`'s internal force from the last [`Tled::element_pass`] (zero outside the cells).
    #[inline]
    pub fn node_force(&self, n: usize) -> Vector3<f32> {
        self.slabs.node_force(n)
    }

    /// Batch `b`'s nodal forces into `out`; returns the number of cells whose F was regularized.
    #[inline(always)]
    fn batch_forces(&self, consts: &OnePointConstants, b: usize, u: &[Vector3<f32>], out: &mut BatchForces) -> usize {
        let cells = self.cell_nodes.len();
        let (lo, hi) = (b * LANES, ((b + 1) * LANES).min(cells));
        if self.params.integration == Integration::OnePoint && hi - lo == LANES {
            let ue = crate::model::tled_batch::load(&self.cell_nodes[lo..hi], self.contiguous[b], u);
            let mut volume = [0.0; LANES];
            volume.copy_from_slice(&self.volume[lo..hi]);
            if crate::model::tled_batch::forces(consts, ue, &volume, out) {
                return 0;
            }
        }
        // Scalar: a short last batch, a batch with a cell to regularize, or Gauss quadrature.
        *out = [[[0.0; LANES]; 8]; 3];
        let mut inverted = 0;
        for c in lo..hi {
            let mut f = [Vector3::zeros(); 8];
            inverted += usize::from(self.cell_force(c, u, &mut f));
            for a in 0..8 {
                for r in 0..3 {
                    out[r][a][c - lo] = f[a][r];
                }
            }
        }
        inverted
    }

    pub(crate) fn one_point_constants(&self) -> OnePointConstants {
        OnePointConstants {
            inv4h: self.dndx[7][0],
            lambda: self.lambda,
            mu: self.mu,
            kappa_per_volume: self.hg_kappa_full / self.cell_volume_full,
        }
    }

    /// One cell's eight nodal forces; returns whether its F had to be regularized.
    #[inline]
    fn cell_force(&self, c: usize, u: &[Vector3<f32>], out: &mut [Vector3<f32>; 8]) -> bool {
        let nodes = &self.cell_nodes[c];
        let mut ue = [Vector3::zeros(); 8];
        for a in 0..8 {
            ue[a] = u[nodes[a] as usize];
        }
        let volume = self.volume[c];
        let mut inverted = false;
        *out = [Vector3::zeros(); 8];
        match self.params.integration {
            Integration::OnePoint => {
                // On the regular lattice ∂N_a/∂X = s_a / (4h) with s_a ∈ {±1}³, so F and the nodal
                // forces need only sums and differences of corner vectors.
                let inv4h = self.dndx[7][0];
                let mut d = [Vector3::zeros(); 3];
                let mut q = [Vector3::zeros(); 4];
                for a in 0..8 {
                    let s = &self.signs[a];
                    for k in 0..3 {
                        d[k] += ue[a] * s[k];
                    }
                    for m in 0..4 {
                        q[m] += ue[a] * self.hg[a][m];
                    }
                }
                let mut f = Matrix3::from_columns(&[d[0] * inv4h, d[1] * inv4h, d[2] * inv4h]);
                f += Matrix3::identity();
                if f.determinant() < INVERSION_J {
                    f = regularize(&f, INVERSION_J.sqrt());
                    inverted = true;
                }
                let p = first_piola(&f, self.lambda, self.mu) * (volume * inv4h);
                let (c0, c1, c2) = (p.column(0).into_owned(), p.column(1).into_owned(), p.column(2).into_owned());
                // Flanagan–Belytschko hourglass control. On the undeformed cube the hourglass base
                // vectors are orthogonal to every linear field, so γ = h and rigid motions and
                // homogeneous strains produce no hourglass force.
                let kappa = self.hg_kappa_full * volume / self.cell_volume_full;
                for a in 0..8 {
                    let s = &self.signs[a];
                    let mut fa = c0 * s[0] + c1 * s[1] + c2 * s[2];
                    if kappa > 0.0 {
                        let h = &self.hg[a];
                        fa += (q[0] * h[0] + q[1] * h[1] + q[2] * h[2] + q[3] * h[3]) * kappa;
                    }
                    out[a] = fa;
                }
            }
            Integration::Gauss8 => {
                for gp in &self.dndx_gauss {
                    let mut f = Matrix3::identity();
                    for a in 0..8 {
                        f += ue[a] * Vector3::from(gp[a]).transpose();
                    }
                    if f.determinant() < INVERSION_J {
                        f = regularize(&f, INVERSION_J.sqrt());
                        inverted = true;
                    }
                    let p = first_piola(&f, self.lambda, self.mu) * (volume / 8.0);
                    for a in 0..8 {
                        out[a] += p * Vector3::from(gp[a]);
                    }
                }
            }
        }
        inverted
    }
}

/// The element pass over one slab of batches, as a `pulp` operation: dispatched to the widest SIMD
/// instruction set the CPU has, with the kernel inlined into it. Returns the number of cells whose
/// F was regularized.
struct SlabPass<'a> {
    tled: &'a Tled,
    /// First batch of the slab.
    first: usize,
    batches: usize,
    u: &'a [Vector3<f32>],
    out: SlabAccumulators<'a>,
}

impl pulp::WithSimd for SlabPass<'_> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> usize {
        let SlabPass { tled, first, batches, u, out } = self;
        let SlabAccumulators { first_node, acc: [ax, ay, az], touched } = out;
        let mut acc = [ax, ay, az];
        for a in &mut acc {
            match touched {
                Some(entries) => entries.iter().for_each(|&i| a[i as usize] = 0.0),
                None => a.fill(0.0),
            }
        }
        let consts = tled.one_point_constants();
        let cells = tled.cell_nodes.len();
        let end = (first + batches).min(cells.div_ceil(LANES));
        let mut inverted = 0;
        let mut f: BatchForces = [[[0.0; LANES]; 8]; 3];
        for b in first..end {
            inverted += tled.batch_forces(&consts, b, u, &mut f);
            let (lo, hi) = (b * LANES, ((b + 1) * LANES).min(cells));
            if hi - lo == LANES && tled.contiguous[b] {
                // Corner a of lane l is node nodes[lo][a] + l: eight consecutive accumulators.
                for a in 0..8 {
                    let n0 = tled.cell_nodes[lo][a] as usize - first_node;
                    for r in 0..3 {
                        let run = &mut acc[r][n0..n0 + LANES];
                        for l in 0..LANES {
                            run[l] += f[r][a][l];
                        }
                    }
                }
            } else {
                for c in lo..hi {
                    for a in 0..8 {
                        let n = tled.cell_nodes[c][a] as usize - first_node;
                        for r in 0..3 {
                            acc[r][n] += f[r][a][c - lo];
                        }
                    }
                }
            }
        }
        inverted
    }
}

/// A large smooth deformation of `lattice` plus node-wise noise (which the hourglass terms see),
/// for tests that compare force kernels.
#[cfg(test)]
pub(crate) fn test_deformation(lattice: &Lattice) -> Vec<Vector3<f32>> {
    lattice
        .rest
        .iter()
        .enumerate()
        .map(|(n, p)| {
            let noise = ((n * 7919) % 17) as f64 / 17.0 - 0.5;
            Vector3::new(0.2 * p.y + 1e-3 * noise, 0.1 * p.z * p.x * 10.0, -0.15 * p.x - 5e-4 * noise).cast::<f32>()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    /// Checks every cell's batched forces against the scalar kernel; returns how many batches
    /// loaded their corners as contiguous runs.
    fn check_batched_against_scalar(dims: [usize; 3], holes: bool) -> usize {
        // With holes: every 13th cell missing, so runs break and slabs cover ragged node ranges.
        let fractions: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|c| {
                if holes && c % 13 == 3 {
                    0.0
                } else if c % 7 == 2 {
                    0.4
                } else {
                    1.0
                }
            })
            .collect();
        let lattice = Lattice::from_fractions(Point3::origin(), 0.01, dims, &fractions, 0.0);
        let material = Material::default();
        let mut tled = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
        let u = test_deformation(&lattice);
        let mut gathered = vec![Vector3::zeros(); lattice.node_count()];
        tled.internal_forces(&u, &mut gathered);
        let mut expected = vec![Vector3::zeros(); lattice.node_count()];
        let mut scale = 0.0f32;
        for c in 0..tled.cell_count() {
            let mut scalar = [Vector3::zeros(); 8];
            tled.cell_force(c, &u, &mut scalar);
            for a in 0..8 {
                scale = scale.max(scalar[a].norm());
                expected[tled.cell_nodes[c][a] as usize] += scalar[a];
            }
        }
        // Each batch's forces against the scalar kernel.
        let consts = tled.one_point_constants();
        for b in 0..tled.cell_count().div_ceil(LANES) {
            let mut batch = [[[0.0; LANES]; 8]; 3];
            tled.batch_forces(&consts, b, &u, &mut batch);
            for c in b * LANES..((b + 1) * LANES).min(tled.cell_count()) {
                let mut scalar = [Vector3::zeros(); 8];
                tled.cell_force(c, &u, &mut scalar);
                for a in 0..8 {
                    let l = c - b * LANES;
                    let batched = Vector3::new(batch[0][a][l], batch[1][a][l], batch[2][a][l]);
                    let diff = (scalar[a] - batched).norm();
                    assert!(diff <= 1e-5 * scalar[a].norm().max(1e-3), "{dims:?} cell {c} corner {a}: {diff}");
                }
            }
        }
        assert!(scale > 0.0);
        // The node pass sums each node's cells.
        for (n, (g, e)) in gathered.iter().zip(&expected).enumerate() {
            assert!((g - e).norm() <= 1e-4 * scale, "{dims:?} node {n}: {g} vs {e}");
        }
        tled.contiguous.iter().filter(|&&c| c).count()
    }

    #[test]
    fn batched_kernel_matches_scalar_kernel() {
        // 5x4x3 = 60 cells: rows of five, so no batch is a contiguous run; seven batches of eight
        // and a scalar tail of four.
        assert_eq!(check_batched_against_scalar([5, 4, 3], false), 0);
        // Rows of 16 cells: two contiguous batches per row, and more than one slab (eight batches
        // per slab at most), so slabs share a node layer.
        assert_eq!(check_batched_against_scalar([16, 3, 2], false), 12);
        // Rows of 24 cells with holes: some batches are still runs, the others scatter per cell.
        let contiguous = check_batched_against_scalar([24, 4, 3], true);
        assert!(contiguous > 0 && contiguous < 33, "{contiguous} contiguous batches of 33");
    }

    #[test]
    fn slabs_share_nodes_and_cover_every_cell() {
        let lattice = Lattice::block(Point3::origin(), 0.01, [16, 3, 2]);
        let tled = Tled::new(&lattice, None, &Material::default(), TledParams::default()).expect("tled");
        let slabs = Slabs::new(&tled.cell_nodes, tled.node_count, 8);
        // 96 cells: slabs of 64 and 32 cells. The nodes both slabs' cells touch have two slots,
        // every other node one.
        let two = (0..tled.node_count).filter(|&n| slabs.slot_count(n) == 2).count();
        assert!(two > 0, "no node shared by the two slabs");
        assert!((0..tled.node_count).all(|n| (1..=2).contains(&slabs.slot_count(n))));
    }
}
