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

/// A batch's nodal forces: `[component][corner][lane]`.
pub(crate) type BatchForces = [[L; 8]; 3];

/// A batch's corner displacements: `[component][corner][lane]`.
pub(crate) type BatchDisplacements = [[L; 8]; 3];

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
    // Each lane vector is built whole from its eight values, which keeps it in registers.
    if contiguous {
        for a in 0..8 {
            let first = nodes[0][a] as usize;
            let run = &u[first..first + LANES];
            ue[0][a] = lanes!(|l| run[l].x);
            ue[1][a] = lanes!(|l| run[l].y);
            ue[2][a] = lanes!(|l| run[l].z);
        }
    } else {
        for a in 0..8 {
            let v: [Vector3<f32>; LANES] = std::array::from_fn(|l| u[nodes[l][a] as usize]);
            ue[0][a] = lanes!(|l| v[l].x);
            ue[1][a] = lanes!(|l| v[l].y);
            ue[2][a] = lanes!(|l| v[l].z);
        }
    }
    ue
}

/// Shared, per-lattice constants of the one-point kernel.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OnePointConstants {
    pub inv4h: f32,
    pub lambda: f32,
    pub mu: f32,
    /// Hourglass stiffness of a full cell divided by its volume.
    pub kappa_per_volume: f32,
}

/// The subsets of axes (bit 1: x, 2: y, 4: z) whose sign products are the hourglass base vectors
/// ηζ, ξζ, ξη, ξηζ.
const HOURGLASS_SUBSETS: [usize; 4] = [6, 5, 3, 7];

/// In place: `v[S] ← Σ_a v[a] Π_{k∈S} s_k(a)`, with `s_k(a) = +1` where bit k of `a` is set, −1
/// where it is not.
#[inline(always)]
fn walsh_hadamard(v: &mut [L; 8]) {
    for bit in [1, 2, 4] {
        for a in 0..8 {
            if a & bit == 0 {
                let (lo, hi) = (v[a], v[a | bit]);
                v[a] = lanes!(|l| lo[l] + hi[l]);
                v[a | bit] = lanes!(|l| hi[l] - lo[l]);
            }
        }
    }
}

/// In place: `v[a] ← Σ_S v[S] Π_{k∈S} s_k(a)`, the synthesis that undoes [`walsh_hadamard`] up to a
/// factor of 8.
#[inline(always)]
fn walsh_hadamard_inverse(v: &mut [L; 8]) {
    for bit in [1, 2, 4] {
        for a in 0..8 {
            if a & bit == 0 {
                let (without, with) = (v[a], v[a | bit]);
                v[a] = lanes!(|l| without[l] - with[l]);
                v[a | bit] = lanes!(|l| without[l] + with[l]);
            }
        }
    }
}

/// Computes the eight nodal forces of a batch of cells with corner displacements `ue` and material
/// volumes `volume` into `out`; returns `false`, writing nothing, when some cell's det F is below
/// [`INVERSION_J`].
#[inline(always)]
pub(crate) fn forces(k: &OnePointConstants, ue: BatchDisplacements, volume: &L, out: &mut BatchForces) -> bool {
    // Corner a = x + 2y + 4z has signs s_k = ±1 per axis. The sums Σ_a u_a Π_{k∈S} s_k(a) over
    // the eight subsets S of {x, y, z} are one Walsh–Hadamard transform of the corner values:
    // S = {x}, {y}, {z} give F's columns, and {y,z}, {x,z}, {x,y}, {x,y,z} the hourglass sums
    // (their base vectors are exactly those sign products). 24 adds per component instead of 56
    // multiply-adds.
    let mut w = ue;
    for wr in &mut w {
        walsh_hadamard(wr);
    }
    // F = I + (1/4h) Σ_a u_a s_aᵀ.
    let mut f = [[splat(0.0); 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            let diag = if r == c { 1.0 } else { 0.0 };
            f[r][c] = lanes!(|l| diag + k.inv4h * w[r][1 << c][l]);
        }
    }
    // Hourglass sums q_m = Σ_a h_am u_a, m over (ηζ, ξζ, ξη, ξηζ).
    let mut q = [[splat(0.0); 3]; 4];
    for (m, &subset) in HOURGLASS_SUBSETS.iter().enumerate() {
        for r in 0..3 {
            q[m][r] = w[r][subset];
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
    // f_a = P s_a + κ Σ_m h_am q_m: the inverse transform of the coefficients per subset.
    for r in 0..3 {
        let v = &mut out[r];
        for c in 0..3 {
            v[1 << c] = p[r][c];
        }
        for (m, &subset) in HOURGLASS_SUBSETS.iter().enumerate() {
            v[subset] = lanes!(|l| kappa[l] * q[m][r][l]);
        }
        v[0] = splat(0.0);
        walsh_hadamard_inverse(v);
    }
    true
}
