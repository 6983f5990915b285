//! The one-point TLED element kernel for eight cells at once.
//!
//! Each quantity is an array over [`LANES`] cells and every operation a loop over lanes, which LLVM
//! turns into SIMD instructions on any target (no `target-cpu=native`, no unsafe); the caller runs
//! it under `pulp`'s runtime dispatch, so on a CPU with AVX2 and FMA the same loops use them. A batch
//! with an inverted or nearly inverted cell is left to the scalar kernel, which regularizes it.
//!
//! Forces are written lane-major ([`BatchForces`]): a batch's results are plain vector stores, and
//! the node pass reads each (cell, corner) force as three scalars eight floats apart.

use nalgebra::Vector3;

use crate::tled::INVERSION_J;

/// Cells per batch.
pub const LANES: usize = 8;

type L = [f32; LANES];

/// A batch's nodal forces: `[corner][component][lane]`.
pub(crate) type BatchForces = [[L; 3]; 8];

/// A batch's corner displacements: `[component][corner][lane]`.
pub(crate) type BatchDisplacements = [[L; 8]; 3];

/// Floats in one [`BatchForces`].
pub(crate) const BATCH_FLOATS: usize = 8 * 3 * LANES;

/// Offset of cell `c`'s corner `a` force (its x component; y and z follow `LANES` apart) in the
/// flattened forces of all batches.
pub(crate) fn force_offset(c: usize, a: usize) -> usize {
    (c / LANES) * BATCH_FLOATS + a * 3 * LANES + c % LANES
}

/// Whether a batch's cells are a run along x of one lattice row with nodes numbered in grid order:
/// then corner `a` of lane `l` is node `nodes[0][a] + l`, and the corner displacements of the batch
/// load as eight contiguous runs instead of 64 scattered nodes.
pub(crate) fn is_contiguous(nodes: &[[u32; 8]]) -> bool {
    nodes.len() == LANES && (0..LANES).all(|l| (0..8).all(|a| nodes[l][a] == nodes[0][a] + l as u32))
}

/// Loads the corner displacements of a batch.
#[inline(always)]
pub(crate) fn load(nodes: &[[u32; 8]], contiguous: bool, u: &[Vector3<f32>]) -> BatchDisplacements {
    let mut ue = [[[0.0f32; LANES]; 8]; 3];
    if contiguous {
        for a in 0..8 {
            let first = nodes[0][a] as usize;
            let run = &u[first..first + LANES];
            for l in 0..LANES {
                ue[0][a][l] = run[l].x;
                ue[1][a][l] = run[l].y;
                ue[2][a][l] = run[l].z;
            }
        }
    } else {
        for l in 0..LANES {
            for a in 0..8 {
                let v = u[nodes[l][a] as usize];
                ue[0][a][l] = v.x;
                ue[1][a][l] = v.y;
                ue[2][a][l] = v.z;
            }
        }
    }
    ue
}

/// Shared, per-lattice constants of the one-point kernel.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OnePointConstants {
    pub signs: [[f32; 3]; 8],
    pub hg: [[f32; 4]; 8],
    pub inv4h: f32,
    pub lambda: f32,
    pub mu: f32,
    /// Hourglass stiffness of a full cell divided by its volume.
    pub kappa_per_volume: f32,
}

#[inline(always)]
fn splat(x: f32) -> L {
    [x; LANES]
}

macro_rules! lanes {
    (|$l:ident| $e:expr) => {{
        let mut out = [0.0f32; LANES];
        for $l in 0..LANES {
            out[$l] = $e;
        }
        out
    }};
}

/// Computes the eight nodal forces of a batch of cells with corner displacements `ue` and material
/// volumes `volume` into `out`; returns `false`, writing nothing, when some cell's det F is below
/// [`INVERSION_J`].
#[inline(always)]
pub(crate) fn forces(k: &OnePointConstants, ue: &BatchDisplacements, volume: &L, out: &mut BatchForces) -> bool {
    // F = I + (1/4h) Σ_a u_a s_aᵀ, and hourglass sums q_m = Σ_a h_am u_a.
    let mut f = [[splat(0.0); 3]; 3];
    for r in 0..3 {
        f[r][r] = splat(1.0);
    }
    let mut q = [[splat(0.0); 3]; 4];
    for a in 0..8 {
        let s = k.signs[a].map(|x| x * k.inv4h);
        let h = k.hg[a];
        for r in 0..3 {
            let ur = ue[r][a];
            for c in 0..3 {
                f[r][c] = lanes!(|l| f[r][c][l] + s[c] * ur[l]);
            }
            for m in 0..4 {
                q[m][r] = lanes!(|l| q[m][r][l] + h[m] * ur[l]);
            }
        }
    }
    // J = det F.
    let j = lanes!(|l| f[0][0][l] * (f[1][1][l] * f[2][2][l] - f[1][2][l] * f[2][1][l])
        - f[0][1][l] * (f[1][0][l] * f[2][2][l] - f[1][2][l] * f[2][0][l])
        + f[0][2][l] * (f[1][0][l] * f[2][1][l] - f[1][1][l] * f[2][0][l]));
    if j.iter().any(|&x| x.is_nan() || x < INVERSION_J) {
        return false;
    }
    // C = FᵀF (symmetric).
    let c = |a: usize, b: usize| -> L {
        lanes!(|l| f[0][a][l] * f[0][b][l] + f[1][a][l] * f[1][b][l] + f[2][a][l] * f[2][b][l])
    };
    let (c00, c01, c02, c11, c12, c22) = (c(0, 0), c(0, 1), c(0, 2), c(1, 1), c(1, 2), c(2, 2));
    // C⁻¹ = adj(C) / J².
    let inv_det = lanes!(|l| 1.0 / (j[l] * j[l]));
    let i00 = lanes!(|l| (c11[l] * c22[l] - c12[l] * c12[l]) * inv_det[l]);
    let i01 = lanes!(|l| (c02[l] * c12[l] - c01[l] * c22[l]) * inv_det[l]);
    let i02 = lanes!(|l| (c01[l] * c12[l] - c02[l] * c11[l]) * inv_det[l]);
    let i11 = lanes!(|l| (c00[l] * c22[l] - c02[l] * c02[l]) * inv_det[l]);
    let i12 = lanes!(|l| (c01[l] * c02[l] - c00[l] * c12[l]) * inv_det[l]);
    let i22 = lanes!(|l| (c00[l] * c11[l] - c01[l] * c01[l]) * inv_det[l]);
    // S = μ (I − C⁻¹) + λ J (J − 1) C⁻¹ = μ I + (λ J (J − 1) − μ) C⁻¹.
    let w = lanes!(|l| k.lambda * j[l] * (j[l] - 1.0) - k.mu);
    let s00 = lanes!(|l| k.mu + w[l] * i00[l]);
    let s11 = lanes!(|l| k.mu + w[l] * i11[l]);
    let s22 = lanes!(|l| k.mu + w[l] * i22[l]);
    let s01 = lanes!(|l| w[l] * i01[l]);
    let s02 = lanes!(|l| w[l] * i02[l]);
    let s12 = lanes!(|l| w[l] * i12[l]);
    let s = [[s00, s01, s02], [s01, s11, s12], [s02, s12, s22]];
    // P = F S, scaled by V / (4h).
    let scale = lanes!(|l| volume[l] * k.inv4h);
    let mut p = [[splat(0.0); 3]; 3];
    for r in 0..3 {
        for cc in 0..3 {
            p[r][cc] =
                lanes!(|l| (f[r][0][l] * s[0][cc][l] + f[r][1][l] * s[1][cc][l] + f[r][2][l] * s[2][cc][l]) * scale[l]);
        }
    }
    let kappa = lanes!(|l| k.kappa_per_volume * volume[l]);
    for a in 0..8 {
        let sa = k.signs[a];
        let h = k.hg[a];
        let mut fa = [splat(0.0); 3];
        for r in 0..3 {
            fa[r] = lanes!(|l| sa[0] * p[r][0][l]
                + sa[1] * p[r][1][l]
                + sa[2] * p[r][2][l]
                + kappa[l] * (h[0] * q[0][r][l] + h[1] * q[1][r][l] + h[2] * q[2][r][l] + h[3] * q[3][r][l]));
        }
        out[a] = fa;
    }
    true
}
