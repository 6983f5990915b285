//! Fast lattice shape matching (FLSM; Rivers & James 2007, "FastLSM"), as used by the hybrid model
//! of Shao, Zhou and Wu (equations 6–9).
//!
//! The particles are the lattice nodes. The region of node `r` is every node whose grid index lies
//! within `±w` of `r`'s on each axis. Per step, each region fits the rotation `R_r` that best maps
//! its rest shape onto its current shape (polar decomposition of
//! `A_r = Σ m̃_i (x_i − c_r)(x0_i − c0_r)ᵀ`), every particle gets the goal
//! `g_i = mean over the regions r containing i of R_r (x0_i − c0_r) + c_r`, and
//! `v ← v + α (g − x) / h + h f_ext / m`, `x ← x + h v`.
//!
//! # Fast summation
//! All region sums (`M̃_r`, `Σ m̃ x`, `Σ m̃ x x0ᵀ`) and per-particle sums over the regions containing
//! it (`Σ_r R_r`, `Σ_r (c_r − R_r c0_r)`) are separable box sums over the dense `(dims + 1)³` node
//! grid, computed with a sliding window along x, then y, then z. Their cost per particle does not
//! depend on `w`. Missing grid nodes contribute zeros.
//!
//! # Particle weights
//! As in Rivers & James, a particle enters each region containing it with the weight
//! `m̃_i = m_i / N_i`, where `N_i` is the number of regions containing it. Inside the body `N_i` is
//! constant, so this only changes the fit near the surface, and it makes the goal pull (and the
//! region damping) conserve the linear momentum of free nodes exactly: a deformed body cannot
//! push itself along. With a converged rotation the goal pull also conserves angular momentum.
//!
//! # Rotations
//! `R_r` maximises `tr(Rᵀ A_r)`. As in Müller et al. 2016 ("A Robust Method to Extract the
//! Rotational Part of Deformations") it is found by turning the region's rotation of the previous
//! call (the warm start) along the gradient of that trace, but with a safeguarded Newton step
//! (shifted where the Hessian is not safely definite, halved until the trace does not fall): their
//! fixed step converges only linearly and can wander for inverted `A`. From a warm start two
//! iterations are typical. The result is always a proper rotation, including for flat, collapsed
//! and inverted regions (`det A_r <= 0`); a region whose `A_r` vanishes keeps its previous rotation.
//!
//! # Stiffness
//! FLSM has no material: a node `α (g − x)` away from its goal is pulled back within a step, which
//! acts like a spring of about `α m / dt²` per node. Its stiffness therefore follows the step, not
//! the tissue: at 60 Hz a 5 mm cell of tissue (`m` ≈ 0.13 g) gets ~0.4 N/m, while the seed's
//! material (E ≈ 50 kPa) gives about E × cell ≈ 250 N/m; at 50 µs (a few TLED steps) FLSM gets
//! ~4e4 N/m, far stiffer than the tissue. The
//! hybrid model has to choose the FLSM step with this in mind. Any `dt` is stable (see the tests).
//!
//! Sums and rotations are computed in `f64` (the state is `f32`), around the rest centroid, so that
//! `Σ m̃ x x0ᵀ − M̃ c c0ᵀ` does not lose the region's deformation to cancellation. Results do not
//! depend on the number of threads.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::{Lattice, SimError};

/// Channels of the widest box sum: `m̃ x` (3) and `m̃ x x0ᵀ` (9); `R` (9) and `c − R c0` (3).
const CHANNELS: usize = 12;
/// Grid points with no node.
const NONE: u32 = u32::MAX;
/// Most polar-decomposition iterations per region and call. From a warm start 1–3 are used.
const POLAR_MAX_ITER: u32 = 12;
/// Polar decomposition stops when the rotation update is below this angle, radians.
const POLAR_TOL: f64 = 1e-10;
/// ... or when a full Newton step was below this angle: it is taken without a check, and what is
/// left is of its square, ~1e-6 rad (5e-9 m of goal in a 5 mm region), removed by the next call
/// from this warm start. Between FLSM steps regions turn by less than this, so one iteration per
/// region and step is the rule (1e-5 took two: 2x the cost).
const POLAR_NEWTON_TOL: f64 = 1e-3;
/// Halvings of a polar-decomposition step that would lower `tr(Rᵀ A)` before giving up.
const POLAR_BACKTRACK: usize = 8;
/// Smallest curvature allowed in a Newton step of the polar decomposition (`|A| = 1`, where a
/// rotation has curvature 2/√3 ≈ 1.15 and a flat region at least 1/√2).
const POLAR_MIN_CURVATURE: f64 = 0.05;
/// `A_r` below this share of its rest size (`M̃_r · cell²`) counts as vanished.
const COLLAPSED: f64 = 1e-12;
/// Smallest parallel work item, grid points or nodes.
const MIN_LEN: usize = 512;

/// Largest region half-width accepted (`flsm.w`), cells. The cost per step does not depend on it,
/// but the region sums index the grid by `t ± w`, which must not overflow.
pub const MAX_W: usize = 1000;

/// Parameters of FLSM, the scenario's `[flsm]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlsmParams {
    /// Region half-width in cells (`flsm.w`), 1 to [`MAX_W`]. Larger regions are stiffer and propagate
    /// deformation further per step; the cost per step does not depend on it.
    pub w: usize,
    /// Stiffness of the goal pull (`flsm.alpha`, the seed's "∂"), in (0, 1]: the share of the
    /// distance to the goal made up per step.
    pub alpha: f32,
    /// Per-region damping (`flsm.region_damping`), in [0, 1]: the share of each particle's velocity
    /// relative to the mean velocity of its regions removed per step.
    pub region_damping: f32,
}

impl Default for FlsmParams {
    fn default() -> Self {
        Self { w: 1, alpha: 0.8, region_damping: 0.1 }
    }
}

impl FlsmParams {
    /// Checks the ranges; the error names the scenario key.
    pub fn validate(&self) -> Result<(), SimError> {
        let invalid = |key: &str, message: String| Err(SimError::Invalid { key: key.into(), message });
        if !(1..=MAX_W).contains(&self.w) {
            return invalid("flsm.w", format!("must be 1 to {MAX_W} cells, got {}", self.w));
        }
        if !(self.alpha > 0.0 && self.alpha <= 1.0) {
            return invalid("flsm.alpha", format!("must be in (0, 1], got {}", self.alpha));
        }
        if !(0.0..=1.0).contains(&self.region_damping) {
            return invalid("flsm.region_damping", format!("must be in [0, 1], got {}", self.region_damping));
        }
        Ok(())
    }
}

/// FLSM state for one lattice: rest-state region sums, the rotation of every region (the warm start
/// of the next polar decomposition) and scratch buffers, so that stepping allocates nothing.
#[derive(Debug, Clone)]
pub struct Flsm {
    params: FlsmParams,
    /// Grid nodes per axis, `dims + 1`.
    grid: [usize; 3],
    /// For each grid point in grid order (x fastest, then y, then z), its node or [`NONE`].
    grid_node: Vec<u32>,
    /// For each node, its index in the output order of [`box_sum`] (x fastest, then z, then y).
    node_sum: Vec<u32>,
    /// Reference point subtracted from rest and current positions before summing.
    origin: Vector3<f64>,
    /// Rest positions relative to `origin`.
    x0: Vec<Vector3<f64>>,
    /// Weight of each node in each region containing it, `m / N`.
    weight: Vec<f64>,
    /// `1 / m`.
    inv_mass: Vec<f32>,
    /// `1 / N`, `N` the number of regions containing the node.
    inv_count: Vec<f64>,
    /// `M̃_r` of the region centred at each node.
    region_mass: Vec<f64>,
    /// `c0_r` of the region centred at each node, relative to `origin`.
    region_c0: Vec<Vector3<f64>>,
    /// `M̃_r · cell² · COLLAPSED`: `A_r` below this norm is taken as vanished.
    region_floor: Vec<f64>,
    /// Rotation of the region centred at each grid point (identity where there is no node).
    rotation: Vec<UnitQuaternion<f64>>,
    /// Box-sum input and scratch, `grid points × CHANNELS`.
    buf_a: Vec<f64>,
    /// Box-sum output, `grid points × CHANNELS`.
    buf_b: Vec<f64>,
    /// Goals of the last [`Flsm::step`].
    goals: Vec<Vector3<f32>>,
    /// Polar-decomposition iterations summed over regions in the last goal computation.
    polar_iterations: u64,
}

impl Flsm {
    /// Sets FLSM up on `lattice` with node masses `masses` (kilograms, e.g.
    /// [`Lattice::lumped_masses`]).
    ///
    /// Fails when the parameters are out of range (the error names the key), when `masses` does
    /// not match the nodes or holds a mass that is not positive and finite, or when two nodes share
    /// a grid index (the dense-grid box sums need at most one node per grid point).
    pub fn new(lattice: &Lattice, masses: &[f64], params: FlsmParams) -> Result<Self, SimError> {
        params.validate()?;
        let n_nodes = lattice.node_count();
        let invalid = |message: String| Err(SimError::Invalid { key: "flsm".into(), message });
        if n_nodes == 0 {
            return invalid("the lattice has no nodes".into());
        }
        if masses.len() != n_nodes {
            return invalid(format!("{} node masses for {} nodes", masses.len(), n_nodes));
        }
        if let Some((i, m)) = masses.iter().enumerate().find(|(_, m)| !(m.is_finite() && **m > 0.0)) {
            return invalid(format!("node {i} has mass {m} kg; FLSM needs positive, finite masses"));
        }
        if n_nodes >= NONE as usize {
            return invalid(format!("{n_nodes} nodes is too many"));
        }
        let grid = [lattice.dims[0] + 1, lattice.dims[1] + 1, lattice.dims[2] + 1];
        let [gx, gy, gz] = grid;
        let points = gx * gy * gz;
        let mut grid_node = vec![NONE; points];
        let mut node_sum = Vec::with_capacity(n_nodes);
        for (n, ijk) in lattice.node_ijk.iter().enumerate() {
            let [i, j, k] = ijk.map(|a| a as usize);
            if i >= gx || j >= gy || k >= gz {
                return invalid(format!("node {n} has grid index {ijk:?} outside the grid {grid:?}"));
            }
            let g = i + gx * (j + gy * k);
            if grid_node[g] != NONE {
                return invalid(format!("nodes {} and {n} share grid index {ijk:?}", grid_node[g]));
            }
            grid_node[g] = n as u32;
            node_sum.push((i + gx * (k + gz * j)) as u32);
        }

        let centroid = lattice.rest.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n_nodes as f64;
        let x0: Vec<Vector3<f64>> = lattice.rest.iter().map(|p| p.coords - centroid).collect();
        let mut buf_a = vec![0.0; points * CHANNELS];
        let mut buf_b = vec![0.0; points * CHANNELS];

        // Regions containing each node: the nodes within ±w of it (the neighbourhood is symmetric).
        for (a, &n) in buf_a.iter_mut().zip(&grid_node) {
            *a = if n == NONE { 0.0 } else { 1.0 };
        }
        box_sum::<1>(grid, params.w, &mut buf_a, &mut buf_b);
        let count: Vec<f64> = node_sum.iter().map(|&s| buf_b[s as usize].round()).collect();
        let weight: Vec<f64> = masses.iter().zip(&count).map(|(m, c)| m / c).collect();

        // Rest-state region sums: M̃_r and Σ m̃ x0.
        for (a, &n) in buf_a.chunks_exact_mut(4).zip(&grid_node) {
            if n == NONE {
                a.fill(0.0);
            } else {
                let n = n as usize;
                let wx = weight[n] * x0[n];
                a.copy_from_slice(&[weight[n], wx.x, wx.y, wx.z]);
            }
        }
        box_sum::<4>(grid, params.w, &mut buf_a, &mut buf_b);
        let region_mass: Vec<f64> = node_sum.iter().map(|&s| buf_b[4 * s as usize]).collect();
        let region_c0 = node_sum
            .iter()
            .zip(&region_mass)
            .map(|(&s, m)| {
                let s = &buf_b[4 * s as usize..][..4];
                Vector3::new(s[1], s[2], s[3]) / *m
            })
            .collect();
        let floor = COLLAPSED * lattice.cell * lattice.cell;
        let region_floor = region_mass.iter().map(|m| m * floor).collect();

        tracing::debug!(nodes = n_nodes, grid = ?grid, w = params.w, "FLSM set up");
        Ok(Self {
            params,
            grid,
            grid_node,
            node_sum,
            origin: centroid,
            x0,
            weight,
            inv_mass: masses.iter().map(|m| (1.0 / m) as f32).collect(),
            inv_count: count.iter().map(|c| 1.0 / c).collect(),
            region_mass,
            region_c0,
            region_floor,
            rotation: vec![UnitQuaternion::identity(); points],
            buf_a,
            buf_b,
            goals: vec![Vector3::zeros(); n_nodes],
            polar_iterations: 0,
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> FlsmParams {
        self.params
    }

    /// Number of particles (lattice nodes).
    pub fn node_count(&self) -> usize {
        self.x0.len()
    }

    /// Number of regions containing `node` (`N_i`; its goal is the mean over them).
    pub fn regions_containing(&self, node: usize) -> usize {
        (1.0 / self.inv_count[node]).round() as usize
    }

    /// The goals of the last [`Flsm::step`], computed from the positions it started from: what
    /// the hybrid model pulls its interface nodes towards. Zeros before the first step.
    pub fn goals(&self) -> &[Vector3<f32>] {
        &self.goals
    }

    /// Polar-decomposition iterations, summed over all regions, in the last goal computation.
    pub fn polar_iterations(&self) -> u64 {
        self.polar_iterations
    }

    /// Forgets the region rotations (the warm starts), e.g. after positions were reset.
    pub fn reset_rotations(&mut self) {
        self.rotation.fill(UnitQuaternion::identity());
    }

    /// Goals of all nodes for positions `x` (equations 6–8), written to `goals`. Updates the
    /// region rotations (the warm start of the next call).
    ///
    /// # Panics
    /// If `x` or `goals` do not have one entry per node.
    pub fn compute_goals(&mut self, x: &[Vector3<f32>], goals: &mut [Vector3<f32>]) {
        let n = self.node_count();
        assert_eq!(x.len(), n, "FLSM: positions for {} nodes, expected {n}", x.len());
        assert_eq!(goals.len(), n, "FLSM: goal buffer for {} nodes, expected {n}", goals.len());
        self.region_frames(x);
        let Self { x0, node_sum, inv_count, origin, buf_b, .. } = self;
        let (x0, node_sum, inv_count, origin, buf_b) = (&*x0, &*node_sum, &*inv_count, *origin, &*buf_b);
        goals.par_iter_mut().enumerate().with_min_len(MIN_LEN).for_each(|(n, g)| {
            let s = &buf_b[node_sum[n] as usize * CHANNELS..][..CHANNELS];
            let rotations = Matrix3::from_column_slice(&s[..9]);
            let shift = Vector3::new(s[9], s[10], s[11]);
            *g = ((rotations * x0[n] + shift) * inv_count[n] + origin).cast::<f32>();
        });
    }

    /// One FLSM step of `dt` seconds (equations 6–9) for the nodes where `active` is true (all
    /// when `None`): goals from `x`, `v ← v + α (g − x) / dt + dt f_ext / m`, region damping,
    /// `x ← x + dt v`. Inactive nodes keep their `x` and `v` but take part in all region sums.
    ///
    /// # Panics
    /// If a slice does not have one entry per node, or `dt` is not positive and finite.
    pub fn step(
        &mut self,
        x: &mut [Vector3<f32>],
        v: &mut [Vector3<f32>],
        f_ext: &[Vector3<f32>],
        dt: f32,
        active: Option<&[bool]>,
    ) {
        let n = self.node_count();
        assert_eq!(v.len(), n, "FLSM: velocities for {} nodes, expected {n}", v.len());
        assert_eq!(f_ext.len(), n, "FLSM: forces for {} nodes, expected {n}", f_ext.len());
        if let Some(a) = active {
            assert_eq!(a.len(), n, "FLSM: active flags for {} nodes, expected {n}", a.len());
        }
        assert!(dt > 0.0 && dt.is_finite(), "FLSM: time step must be positive and finite, got {dt}");
        let mut goals = std::mem::take(&mut self.goals);
        self.compute_goals(x, &mut goals);
        self.goals = goals;

        let is_active = |i: usize| active.is_none_or(|a| a[i]);
        let pull = self.params.alpha / dt;
        let (goals, inv_mass) = (&self.goals, &self.inv_mass);
        let x_now: &[Vector3<f32>] = x;
        v.par_iter_mut().enumerate().with_min_len(MIN_LEN).for_each(|(i, vi)| {
            if is_active(i) {
                *vi += (goals[i] - x_now[i]) * pull + f_ext[i] * (dt * inv_mass[i]);
            }
        });
        if self.params.region_damping > 0.0 {
            self.damp(v, active);
        }
        x.par_iter_mut().zip(v.par_iter()).enumerate().with_min_len(MIN_LEN).for_each(|(i, (xi, vi))| {
            if is_active(i) {
                *xi += vi * dt;
            }
        });
    }

    /// What the GPU's FLSM passes need ([`crate::gpu`]), in f32: positions relative to the rest
    /// centroid (the sums are then small numbers, as on the CPU).
    #[cfg(feature = "gpu")]
    pub(crate) fn gpu_layout(&self) -> FlsmLayout {
        let mut node_grid = vec![0u32; self.node_count()];
        for (g, &n) in self.grid_node.iter().enumerate() {
            if n != NONE {
                node_grid[n as usize] = g as u32;
            }
        }
        FlsmLayout {
            grid: self.grid.map(|g| g as u32),
            w: self.params.w as u32,
            alpha: self.params.alpha,
            region_damping: self.params.region_damping,
            grid_node: self.grid_node.clone(),
            nodes: (0..self.node_count())
                .map(|n| {
                    let x0 = self.x0[n];
                    [
                        x0.x as f32,
                        x0.y as f32,
                        x0.z as f32,
                        self.weight[n] as f32,
                        f32::from_bits(node_grid[n]),
                        self.inv_count[n] as f32,
                        self.inv_mass[n],
                        0.0,
                    ]
                })
                .collect(),
            regions: (0..self.node_count())
                .map(|n| {
                    let c0 = self.region_c0[n];
                    [
                        c0.x as f32,
                        c0.y as f32,
                        c0.z as f32,
                        self.region_mass[n] as f32,
                        self.region_floor[n] as f32,
                        0.0,
                        0.0,
                        0.0,
                    ]
                })
                .collect(),
        }
    }

    /// Region frames for positions `x`: afterwards `buf_b` holds, at each node's box-sum index,
    /// `Σ_r R_r` (9, column-major) and `Σ_r (c_r − R_r c0_r)` (3) over the regions containing it.
    fn region_frames(&mut self, x: &[Vector3<f32>]) {
        let Self {
            params,
            grid,
            grid_node,
            node_sum,
            origin,
            x0,
            weight,
            region_mass,
            region_c0,
            region_floor,
            rotation,
            buf_a,
            buf_b,
            polar_iterations,
            ..
        } = self;
        let (grid, w, origin) = (*grid, params.w, *origin);
        let points = grid_node.len();
        let (grid_node, node_sum, x0, weight) = (&*grid_node, &*node_sum, &*x0, &*weight);

        // Per particle: m̃ x and m̃ x x0ᵀ (column-major), relative to the rest centroid.
        buf_a[..points * CHANNELS].par_chunks_mut(CHANNELS).zip(grid_node.par_iter()).with_min_len(MIN_LEN).for_each(
            |(a, &n)| {
                if n == NONE {
                    a.fill(0.0);
                    return;
                }
                let n = n as usize;
                let wx = (x[n].cast::<f64>() - origin) * weight[n];
                a[..3].copy_from_slice(wx.as_slice());
                a[3..].copy_from_slice((wx * x0[n].transpose()).as_slice());
            },
        );
        box_sum::<CHANNELS>(grid, w, buf_a, buf_b);

        // Per region: c_r, A_r, R_r; then R_r and c_r − R_r c0_r per region centre.
        let buf_b_read: &[f64] = buf_b;
        *polar_iterations = buf_a[..points * CHANNELS]
            .par_chunks_mut(CHANNELS)
            .zip(rotation.par_iter_mut())
            .zip(grid_node.par_iter())
            .with_min_len(MIN_LEN)
            .map(|((a, q), &n)| {
                if n == NONE {
                    a.fill(0.0);
                    return 0;
                }
                let n = n as usize;
                let s = &buf_b_read[node_sum[n] as usize * CHANNELS..][..CHANNELS];
                let sum_x = Vector3::new(s[0], s[1], s[2]);
                let c = sum_x / region_mass[n];
                let c0 = region_c0[n];
                let moment = Matrix3::from_column_slice(&s[3..]) - sum_x * c0.transpose();
                let iterations = extract_rotation(&moment, region_floor[n], q);
                let r = q.to_rotation_matrix().into_inner();
                a[..9].copy_from_slice(r.as_slice());
                a[9..].copy_from_slice((c - r * c0).as_slice());
                u64::from(iterations)
            })
            .sum();
        box_sum::<CHANNELS>(grid, w, buf_a, buf_b);
    }

    /// Region damping: `v ← v + k (v̄ − v)` for active nodes, `v̄` the mean over the regions
    /// containing the node of their (m̃-weighted) mean velocity.
    fn damp(&mut self, v: &mut [Vector3<f32>], active: Option<&[bool]>) {
        let Self { params, grid, grid_node, node_sum, weight, inv_count, region_mass, buf_a, buf_b, .. } = self;
        let (grid, w, k) = (*grid, params.w, f64::from(params.region_damping));
        let points = grid_node.len();
        let (grid_node, node_sum, weight, inv_count, region_mass) =
            (&*grid_node, &*node_sum, &*weight, &*inv_count, &*region_mass);
        let velocities: &[Vector3<f32>] = v;
        buf_a[..points * 3].par_chunks_mut(3).zip(grid_node.par_iter()).with_min_len(MIN_LEN).for_each(|(a, &n)| {
            if n == NONE {
                a.fill(0.0);
            } else {
                let n = n as usize;
                a.copy_from_slice((velocities[n].cast::<f64>() * weight[n]).as_slice());
            }
        });
        box_sum::<3>(grid, w, buf_a, buf_b);
        let buf_b_read: &[f64] = buf_b;
        buf_a[..points * 3].par_chunks_mut(3).zip(grid_node.par_iter()).with_min_len(MIN_LEN).for_each(|(a, &n)| {
            if n == NONE {
                a.fill(0.0);
            } else {
                let n = n as usize;
                let s = &buf_b_read[node_sum[n] as usize * 3..][..3];
                for (a, s) in a.iter_mut().zip(s) {
                    *a = s / region_mass[n];
                }
            }
        });
        box_sum::<3>(grid, w, buf_a, buf_b);
        let buf_b_read: &[f64] = buf_b;
        v.par_iter_mut().enumerate().with_min_len(MIN_LEN).for_each(|(n, vn)| {
            if active.is_none_or(|a| a[n]) {
                let s = &buf_b_read[node_sum[n] as usize * 3..][..3];
                let mean = Vector3::new(s[0], s[1], s[2]) * inv_count[n];
                let vd = vn.cast::<f64>();
                *vn = (vd + (mean - vd) * k).cast::<f32>();
            }
        });
    }
}

/// FLSM's constants laid out for the GPU ([`Flsm::gpu_layout`]).
#[cfg(feature = "gpu")]
#[derive(Debug, Clone)]
pub(crate) struct FlsmLayout {
    /// Grid points per axis.
    pub grid: [u32; 3],
    /// Region half-width.
    pub w: u32,
    /// Goal stiffness.
    pub alpha: f32,
    /// Region damping.
    pub region_damping: f32,
    /// Node at each grid point (x fastest), `u32::MAX` for none.
    pub grid_node: Vec<u32>,
    /// Per node: rest position relative to the rest centroid (3), weight `m / N`, grid point (bits of a
    /// u32), `1 / N`, `1 / m`, and a slot for the active flag.
    pub nodes: Vec<[f32; 8]>,
    /// Per region (node): rest centroid relative to the body's (3), mass, the floor below which its
    /// moment counts as vanished, padding.
    pub regions: Vec<[f32; 8]>,
}

/// Box sum of half-width `w` (clipped at the grid's edges) of `C` channels per grid point.
///
/// `a[..points * C]` holds the input in grid order (x fastest, then y, then z) and is clobbered;
/// the result is written to `b[..points * C]` in the order x fastest, then z, then y (so that the
/// last pass can hand each thread whole output planes).
fn box_sum<const C: usize>(grid: [usize; 3], w: usize, a: &mut [f64], b: &mut [f64]) {
    let [gx, gy, gz] = grid;
    let row = gx * C;
    let slab = row * gy;
    let len = slab * gz;
    let (a, b) = (&mut a[..len], &mut b[..len]);
    // Along x, a → b: each element is one grid point's `c` channels; one z-slab per task.
    a.par_chunks(slab).zip(b.par_chunks_mut(slab)).for_each(|(src, dst)| {
        for (src, dst) in src.chunks_exact(row).zip(dst.chunks_exact_mut(row)) {
            slide_points::<C>(src.as_chunks::<C>().0, dst.as_chunks_mut::<C>().0, w);
        }
    });
    // Along y, b → a: each element is an x-row; one z-slab per task.
    b.par_chunks(slab).zip(a.par_chunks_mut(slab)).for_each(|(src, dst)| slide(src, row, row, dst, gy, w));
    // Along z, a → b: each element is an x-row; one output y-plane (rows ordered by z) per task.
    let a: &[f64] = a;
    b.par_chunks_mut(row * gz).enumerate().for_each(|(j, dst)| slide(&a[j * row..], row, slab, dst, gz, w));
}

/// Sliding-window sum along a row of grid points: `dst[t]` is the sum of the `src[t − w ..= t + w]`
/// that exist. (The same sums as [`slide`], with the channels of a point held in registers.)
fn slide_points<const C: usize>(src: &[[f64; C]], dst: &mut [[f64; C]], w: usize) {
    let mut acc = [0.0; C];
    for s in src.iter().take(w + 1) {
        for c in 0..C {
            acc[c] += s[c];
        }
    }
    for (t, d) in dst.iter_mut().enumerate() {
        if t > 0 {
            if let Some(s) = src.get(t + w) {
                for c in 0..C {
                    acc[c] += s[c];
                }
            }
            if t > w {
                let s = &src[t - w - 1];
                for c in 0..C {
                    acc[c] -= s[c];
                }
            }
        }
        *d = acc;
    }
}

/// Sliding-window sum over `n` elements of `len` values: element `t` of `dst` (contiguous) is the
/// sum of source elements `t − w ..= t + w` that exist; source element `s` starts at `s * stride`.
fn slide(src: &[f64], len: usize, stride: usize, dst: &mut [f64], n: usize, w: usize) {
    let element = |s: usize| &src[s * stride..s * stride + len];
    let first = &mut dst[..len];
    first.copy_from_slice(element(0));
    for s in 1..=w.min(n - 1) {
        add(first, element(s));
    }
    for t in 1..n {
        let (done, rest) = dst.split_at_mut(t * len);
        let previous = &done[(t - 1) * len..];
        let current = &mut rest[..len];
        // One pass per element: the window's sum moves on by the element entering it and the one
        // leaving it, (previous + entering) − leaving.
        match (t + w < n, t > w) {
            (true, true) => {
                let (entering, leaving) = (element(t + w), element(t - w - 1));
                for (((c, p), e), l) in current.iter_mut().zip(previous).zip(entering).zip(leaving) {
                    *c = (p + e) - l;
                }
            }
            (true, false) => {
                for ((c, p), e) in current.iter_mut().zip(previous).zip(element(t + w)) {
                    *c = p + e;
                }
            }
            (false, true) => {
                for ((c, p), l) in current.iter_mut().zip(previous).zip(element(t - w - 1)) {
                    *c = p - l;
                }
            }
            (false, false) => current.copy_from_slice(previous),
        }
    }
}

fn add(dst: &mut [f64], src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d += s;
    }
}

/// Rotational part of `a`, iterated from `q` and written back to it; returns the iterations used.
///
/// Maximises `f(R) = tr(Rᵀ A)` over rotations: the polar rotation where `det A > 0`, the nearest
/// rotation (with the smallest singular direction flipped) where `A` is inverted, and one of the
/// maximisers where `A` is flat. As in Müller et al. 2016 each iteration turns `R` by `δ` in its own
/// frame along the gradient `g` of `f` (the axial vector of `Q − Qᵀ`, `Q = RᵀA`, which for `A`
/// near a rotation is their `Σ r_i × a_i`); the step is Newton's, `δ = H⁻¹ g` with
/// `H = tr(Q) I − sym(Q)` the negated Hessian, shifted to be positive definite where it is not, and
/// halved until `f` does not decrease. So every iteration is an ascent step (their fixed step
/// `g / |tr Q|` is not, for inverted `A`), convergence is quadratic near a well-defined rotation, and
/// the result is a rotation whatever `A` is. `A` below `floor` in norm (or not finite) leaves `q`
/// as it is.
fn extract_rotation(a: &Matrix3<f64>, floor: f64, q: &mut UnitQuaternion<f64>) -> u32 {
    let norm = a.norm();
    if !(norm.is_finite() && norm > floor) {
        return 0;
    }
    let a = a * (1.0 / norm);
    // q ⊗ (1, δ/2), renormalised: a turn by 2 atan(|δ|/2), which is |δ| to third order.
    let turn = |q: &UnitQuaternion<f64>, delta: Vector3<f64>| {
        let half = delta * 0.5;
        UnitQuaternion::new_normalize(q.into_inner() * Quaternion::new(1.0, half.x, half.y, half.z))
    };
    let mut qm = q.to_rotation_matrix().matrix().transpose() * a;
    for iteration in 1..=POLAR_MAX_ITER {
        let grad = Vector3::new(qm[(2, 1)] - qm[(1, 2)], qm[(0, 2)] - qm[(2, 0)], qm[(1, 0)] - qm[(0, 1)]);
        let f = qm.trace();
        let hessian = Matrix3::identity() * f - (qm + qm.transpose()) * 0.5;
        let (delta, newton) = ascent_step(&hessian, &grad);
        let size = delta.norm();
        if size < POLAR_TOL || (newton && size < POLAR_NEWTON_TOL) {
            // Converged: a step this small cannot lower f beyond rounding.
            *q = turn(q, delta);
            return iteration;
        }
        let mut step = delta;
        let mut improved = false;
        for _ in 0..POLAR_BACKTRACK {
            let candidate = turn(q, step);
            let cq = candidate.to_rotation_matrix().matrix().transpose() * a;
            // f is at most √3 (|A| = 1): allow its rounding, so converged steps are not refused.
            if cq.trace() >= f - 1e-15 {
                *q = candidate;
                qm = cq;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            return iteration;
        }
    }
    POLAR_MAX_ITER
}

/// Newton's ascent step `H⁻¹ g` where `H` is safely positive definite (Cholesky pivots of at least
/// [`POLAR_MIN_CURVATURE`]); otherwise `(H + μ I)⁻¹ g` with `μ` from Gershgorin's bound, so that the
/// shifted matrix has no eigenvalue below [`POLAR_MIN_CURVATURE`]. Either way `gᵀδ > 0`. The
/// flag tells whether the step is Newton's.
fn ascent_step(h: &Matrix3<f64>, g: &Vector3<f64>) -> (Vector3<f64>, bool) {
    if let Some(step) = cholesky_solve(h, g, POLAR_MIN_CURVATURE) {
        return (step, true);
    }
    let gershgorin = (0..3)
        .map(|i| h[(i, i)] - (0..3).filter(|&j| j != i).map(|j| h[(i, j)].abs()).sum::<f64>())
        .fold(f64::INFINITY, f64::min);
    let shifted = h + Matrix3::identity() * (POLAR_MIN_CURVATURE - gershgorin).max(0.0);
    let step = cholesky_solve(&shifted, g, 0.0).unwrap_or_else(|| g / POLAR_MIN_CURVATURE.max(h.trace().abs()));
    (step, false)
}

/// Solves `h x = g` for symmetric `h` (lower triangle read) by `L D Lᵀ` (Cholesky without its
/// square roots), if every pivot `D_k` is positive and at least `min_pivot`.
fn cholesky_solve(h: &Matrix3<f64>, g: &Vector3<f64>, min_pivot: f64) -> Option<Vector3<f64>> {
    let pivot_ok = |d: f64| d > 0.0 && d >= min_pivot;
    let d0 = h[(0, 0)];
    if !pivot_ok(d0) {
        return None;
    }
    let inv0 = 1.0 / d0;
    let (l10, l20) = (h[(1, 0)] * inv0, h[(2, 0)] * inv0);
    let d1 = h[(1, 1)] - l10 * h[(1, 0)];
    if !pivot_ok(d1) {
        return None;
    }
    let inv1 = 1.0 / d1;
    let l21 = (h[(2, 1)] - l20 * h[(1, 0)]) * inv1;
    let d2 = h[(2, 2)] - l20 * h[(2, 0)] - l21 * l21 * d1;
    if !pivot_ok(d2) {
        return None;
    }
    let z0 = g.x;
    let z1 = g.y - l10 * z0;
    let z2 = g.z - l20 * z0 - l21 * z1;
    let x2 = z2 / d2;
    let x1 = z1 * inv1 - l21 * x2;
    let x0 = z0 * inv0 - l10 * x1 - l20 * x2;
    Some(Vector3::new(x0, x1, x2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Rotation3};

    /// Deterministic pseudo-random numbers in [-1, 1).
    fn noise(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    /// An L-shaped block with holes: cells missing at a corner and scattered inside.
    fn irregular_lattice() -> Lattice {
        let dims = [6, 5, 4];
        let mut fraction = vec![1.0f32; 6 * 5 * 4];
        for k in 0..4 {
            for j in 0..5 {
                for i in 0..6 {
                    let idx = i + 6 * (j + 5 * k);
                    let l_notch = i >= 3 && j >= 2;
                    let hole = (i * 7 + j * 3 + k * 5) % 11 == 0;
                    if l_notch || hole {
                        fraction[idx] = 0.0;
                    }
                    if (i + j + k) % 4 == 1 {
                        fraction[idx] *= 0.5;
                    }
                }
            }
        }
        Lattice::from_fractions(Point3::new(0.01, -0.02, 0.03), 0.005, dims, &fraction, 0.0)
    }

    /// Region sums and goals by brute force over each region's neighbourhood.
    fn brute_force(lattice: &Lattice, masses: &[f64], w: usize, x: &[Vector3<f32>]) -> Vec<Vector3<f64>> {
        let n = lattice.node_count();
        let neighbours = |i: usize| {
            let c = lattice.node_ijk[i];
            (0..n).filter(move |&j| {
                (0..3).all(|a| (i64::from(lattice.node_ijk[j][a]) - i64::from(c[a])).abs() <= w as i64)
            })
        };
        let count: Vec<f64> = (0..n).map(|i| neighbours(i).count() as f64).collect();
        let wm: Vec<f64> = (0..n).map(|i| masses[i] / count[i]).collect();
        let x0: Vec<Vector3<f64>> = lattice.rest.iter().map(|p| p.coords).collect();
        let xd: Vec<Vector3<f64>> = x.iter().map(|p| p.cast::<f64>()).collect();
        let mut frames = Vec::with_capacity(n);
        for r in 0..n {
            let m: f64 = neighbours(r).map(|i| wm[i]).sum();
            let c0 = neighbours(r).map(|i| x0[i] * wm[i]).sum::<Vector3<f64>>() / m;
            let c = neighbours(r).map(|i| xd[i] * wm[i]).sum::<Vector3<f64>>() / m;
            let a: Matrix3<f64> = neighbours(r).map(|i| (xd[i] - c) * (x0[i] - c0).transpose() * wm[i]).sum();
            let svd = a.svd(true, true);
            let (Some(u), Some(vt)) = (svd.u, svd.v_t) else { panic!("svd") };
            let rot = u * vt;
            assert!(rot.determinant() > 0.0, "test deformation must not invert a region");
            frames.push((rot, c, c0));
        }
        (0..n)
            .map(|i| {
                neighbours(i).map(|r| frames[r].0 * (x0[i] - frames[r].2) + frames[r].1).sum::<Vector3<f64>>()
                    / count[i]
            })
            .collect()
    }

    #[test]
    fn fast_sums_match_brute_force_on_irregular_lattice() {
        let lattice = irregular_lattice();
        let masses = lattice.lumped_masses(1000.0);
        let mut rnd = noise(7);
        // Smooth rotation plus stretch plus noise of 20 % of a cell: no region inverts.
        let rot = Rotation3::from_scaled_axis(Vector3::new(0.3, -0.2, 0.5));
        let x: Vec<Vector3<f32>> = lattice
            .rest
            .iter()
            .map(|p| {
                let d = Vector3::new(rnd(), rnd(), rnd()) * 0.001;
                (rot * Vector3::new(p.x * 1.1, p.y * 0.95, p.z) + d).cast::<f32>()
            })
            .collect();
        for w in 1..=3 {
            let mut flsm = Flsm::new(&lattice, &masses, FlsmParams { w, ..FlsmParams::default() }).expect("flsm");
            // N_i by brute force.
            for i in 0..lattice.node_count() {
                let c = lattice.node_ijk[i];
                let expect = lattice
                    .node_ijk
                    .iter()
                    .filter(|d| (0..3).all(|a| (i64::from(d[a]) - i64::from(c[a])).abs() <= w as i64))
                    .count();
                assert_eq!(flsm.regions_containing(i), expect);
            }
            let mut goals = vec![Vector3::zeros(); x.len()];
            flsm.compute_goals(&x, &mut goals);
            let expect = brute_force(&lattice, &masses, w, &x);
            // f32 output of positions of order 0.05 m: rounding ~4e-9 m; the rest is summation order.
            let worst = goals.iter().zip(&expect).map(|(g, e)| (g.cast::<f64>() - e).norm()).fold(0.0, f64::max);
            assert!(worst < 2e-8, "w = {w}: fast goals differ from brute force by {worst} m");
        }
    }

    #[test]
    fn box_sum_matches_direct_sum() {
        let grid = [5, 4, 3];
        let c = 2;
        let points = 60;
        let mut rnd = noise(3);
        let input: Vec<f64> = (0..points * c).map(|_| rnd()).collect();
        for w in 1..=4 {
            let mut a = input.clone();
            let mut b = vec![0.0; points * c];
            box_sum::<2>(grid, w, &mut a, &mut b);
            for k in 0..3usize {
                for j in 0..4usize {
                    for i in 0..5usize {
                        for ch in 0..c {
                            let mut s = 0.0;
                            for kk in 0..3usize {
                                for jj in 0..4usize {
                                    for ii in 0..5usize {
                                        if i.abs_diff(ii) <= w && j.abs_diff(jj) <= w && k.abs_diff(kk) <= w {
                                            s += input[(ii + 5 * (jj + 4 * kk)) * c + ch];
                                        }
                                    }
                                }
                            }
                            let got = b[(i + 5 * (k + 3 * j)) * c + ch];
                            assert!((got - s).abs() < 1e-12, "w {w} at {i},{j},{k}: {got} vs {s}");
                        }
                    }
                }
            }
        }
    }

    fn assert_rotation(q: &UnitQuaternion<f64>) {
        let r = q.to_rotation_matrix().into_inner();
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn polar_recovers_rotation_of_stretched_matrices() {
        let mut rnd = noise(11);
        for _ in 0..200 {
            let truth = Rotation3::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()) * 3.0);
            let basis = Rotation3::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()) * 3.0);
            let stretch =
                Matrix3::from_diagonal(&Vector3::new(1.0 + rnd() * 0.5, 1.0 + rnd() * 0.5, 1.0 + rnd() * 0.5));
            let a = truth.matrix() * basis.matrix() * stretch * basis.matrix().transpose();
            let mut q = UnitQuaternion::identity();
            // From a cold start a turn of up to π takes a few Müller steps, then Newton converges.
            let mut iterations = 0;
            for _ in 0..4 {
                iterations += extract_rotation(&a, 0.0, &mut q);
            }
            assert_rotation(&q);
            let err = (q.to_rotation_matrix().matrix() - truth.matrix()).norm();
            assert!(err < 1e-9, "rotation error {err} after {iterations} iterations");
            // Warm: already converged.
            assert!(extract_rotation(&a, 0.0, &mut q) <= 2);
        }
    }

    #[test]
    fn polar_is_robust_to_degenerate_and_inverted_matrices() {
        let mut rnd = noise(5);
        let f = |q: &UnitQuaternion<f64>, a: &Matrix3<f64>| (q.to_rotation_matrix().matrix().transpose() * a).trace();
        let cases = [
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)),
            Matrix3::from_diagonal(&Vector3::new(-1.0, -2.0, -0.5)),
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)),
            Matrix3::from_diagonal(&Vector3::new(1.0, 0.0, 0.0)),
            Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 3.0, 6.0, 9.0),
            Matrix3::zeros(),
            Matrix3::from_element(f64::NAN),
            Matrix3::from_element(f64::INFINITY),
        ];
        for a in cases {
            let start = UnitQuaternion::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()));
            let mut q = start;
            extract_rotation(&a, 1e-30, &mut q);
            assert_rotation(&q);
            if !(a.norm() > 0.0 && a.norm().is_finite()) {
                assert_eq!(q, start, "vanished or non-finite A keeps the previous rotation");
            }
        }
        // Arbitrary matrices (a third inverted reflections of rotations, a third of rank 2): every
        // call returns a rotation and never lowers tr(RᵀA); the optimum is σ1 + σ2 ± σ3.
        for case in 0..3000 {
            let mut a = Matrix3::from_fn(|_, _| rnd());
            if case % 3 == 0 {
                a = Rotation3::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()) * 3.0).matrix()
                    * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
            } else if case % 3 == 1 {
                let c = a.column(0) * rnd();
                a.set_column(2, &c);
            }
            let sv = a.svd(false, false).singular_values;
            let optimum = sv[0] + sv[1] + a.determinant().signum() * sv[2];
            let mut q = UnitQuaternion::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()) * 3.0);
            for _ in 0..4 {
                let before = f(&q, &a);
                extract_rotation(&a, 0.0, &mut q);
                assert_rotation(&q);
                assert!(f(&q, &a) >= before - 1e-12, "case {case}: tr(RᵀA) fell");
            }
            // Where the optimum is well defined (the two smallest singular values of an inverted A
            // apart, or a rank of at least 2), it is reached.
            let gap = if a.determinant() < 0.0 { sv[1] - sv[2] } else { sv[1] };
            if gap > 0.05 * sv[0] {
                assert!(f(&q, &a) > optimum - 1e-9 * sv[0], "case {case}: {} of {optimum}", f(&q, &a));
            }
        }
    }

    #[test]
    fn invalid_masses_and_lattices_are_rejected() {
        let lattice = Lattice::block(Point3::origin(), 0.01, [2, 2, 2]);
        let mut masses = lattice.lumped_masses(1000.0);
        assert!(Flsm::new(&lattice, &masses[1..], FlsmParams::default()).is_err());
        masses[3] = 0.0;
        let err = Flsm::new(&lattice, &masses, FlsmParams::default()).expect_err("zero mass");
        assert!(err.to_string().contains("node 3"), "{err}");
    }
}
