//! The hybrid model in a body that is being cut: an operational region of TLED cells that follows
//! the tool, FLSM on the other cells, and interface nodes pulled toward their FLSM goals.
//!
//! # Which cells are TLED
//! A lattice cell is TLED when
//! - it is cut or partly cut, or shares a node with such a cell (the *cut band*): cut cells have
//!   copies and virtual nodes, which FLSM's grid regions cannot hold, and the band keeps FLSM
//!   regions from reaching across a cut (below);
//! - its deformed centre lies within `radius` of the tool (the swept blade surface and the edge);
//! - or it was TLED, is still within `1.5 radius` of the tool or has a node moving faster than
//!   `rest_speed`: cells return to FLSM only once the tool has left and they have come to rest.
//!
//! # FLSM regions follow the lattice's connectivity
//! FLSM runs on the lattice of the other cells alone, rebuilt whenever the roles change (after a
//! cut, as the tool moves). A region is a box of `±w` grid nodes, and two nodes of that lattice
//! in one box share a lattice cell. With the band one cell wide (`w = 1`), a node of a cut cell
//! is in no FLSM cell, so the cell two FLSM nodes share is uncut and joins them: no region spans
//! a cut, and separated pieces move apart. Wider regions (`w > 1`) widen the band to `w` cells.
//!
//! # Coupling
//! Nodes of FLSM cells only are moved by FLSM and frozen during the TLED sub-steps; nodes of both
//! kinds of cell (the interface) are moved by TLED and pulled by `β (g − x)` toward their FLSM goal,
//! taken implicitly so a stiff pull on a light node cannot destabilize the step; nodes of TLED
//! cells only are moved by TLED. One FLSM step of `substeps` TLED steps advances both.

use nalgebra::{Point3, Vector3};

use crate::SimError;
use crate::flsm::{Flsm, FlsmParams};
use crate::lattice::Lattice;
use crate::simulation::NodeRole;

/// Most TLED steps per FLSM step: the limit of `hybrid.substeps` and of the FLSM step
/// [`match_flsm`] matches to the material (a longer one would be softer than the material anyway).
pub const MAX_SUBSTEPS: usize = 1000;

/// Settings of the hybrid model in a [`crate::CutSim`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HybridParams {
    /// Cells whose deformed centre lies within this distance of the tool are TLED, metres.
    pub radius: f64,
    /// FLSM's region half-width, stiffness and damping. Its `alpha` is used as given only when
    /// `substeps` is given; otherwise it is matched to the material ([`HybridParams::resolve`]).
    pub flsm: FlsmParams,
    /// Interface pull toward the FLSM goal, N/m; `None`: `2.5 E × cell` ([`HybridParams::resolve`]).
    pub beta: Option<f32>,
    /// TLED steps per FLSM step, 1 to [`MAX_SUBSTEPS`]; `None`: matched to the material
    /// ([`HybridParams::resolve`]).
    pub substeps: Option<usize>,
    /// A TLED cell returns to FLSM only when all its nodes are slower than this, m/s.
    pub rest_speed: f32,
    /// What moves the cells outside the operational region.
    #[serde(default)]
    pub far_field: FarField,
}

/// What moves the cells outside the operational region of a [`crate::CutSim`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FarField {
    /// FLSM matched to the material (the seed paper's hybrid), stepping with TLED.
    #[default]
    Flsm,
    /// Nothing: a cell at rest and away from the tool and the cuts sleeps, its nodes held where
    /// they are (the region's nodes it shares included) until the region reaches it again. The
    /// body starts all TLED, so it settles before its cells sleep; a cell sleeps only when all its
    /// nodes are slower than `rest_speed`. Exact where the far field is at rest (the tool's push
    /// and the cuts leave it so); wrong by what the far field would have moved when the region
    /// is too small.
    Frozen,
}

impl Default for HybridParams {
    fn default() -> Self {
        Self {
            radius: 0.02,
            flsm: FlsmParams::default(),
            beta: None,
            substeps: None,
            rest_speed: 2e-3,
            far_field: FarField::Flsm,
        }
    }
}

impl HybridParams {
    /// Checks the ranges; the error names the key.
    pub fn validate(&self) -> Result<(), SimError> {
        let invalid = |key: &str, message: String| Err(SimError::Invalid { key: key.into(), message });
        self.flsm.validate()?;
        if !(self.radius.is_finite() && self.radius >= 0.0) {
            return invalid("hybrid.radius", format!("must be >= 0 m, got {}", self.radius));
        }
        if let Some(beta) = self.beta
            && !(beta.is_finite() && beta >= 0.0)
        {
            return invalid("hybrid.beta", format!("must be >= 0, got {beta}"));
        }
        if let Some(n) = self.substeps
            && !(1..=MAX_SUBSTEPS).contains(&n)
        {
            return invalid("hybrid.substeps", format!("must be 1 to {MAX_SUBSTEPS} TLED steps, got {n}"));
        }
        if !(self.rest_speed.is_finite() && self.rest_speed >= 0.0) {
            return invalid("hybrid.rest_speed", format!("must be >= 0 m/s, got {}", self.rest_speed));
        }
        Ok(())
    }
}

/// What [`HybridParams`] come to for one body: its steps and stiffnesses.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HybridSteps {
    /// TLED steps per FLSM step.
    pub substeps: usize,
    /// FLSM's goal pull per step.
    pub alpha: f32,
    /// Interface pull, N/m.
    pub beta: f32,
}

impl HybridParams {
    /// The substeps, FLSM stiffness and interface pull for a body of `material` on a lattice of
    /// spacing `cell` stepped by TLED at `dt`.
    ///
    /// FLSM has no material: it pulls a node of mass `m` back by `α (g − x)` per step, a spring of
    /// about `α m / h²` for a step `h`, where a cell of material is a spring of about `E × cell`.
    /// With `m = ρ cell³` the two match at `h = C cell √(α ρ / E)`; `C = 0.6` makes a block of FLSM
    /// (w = 1, ν = 0.45) sag under its own weight as much as the same block of TLED (measured:
    /// the test `an_flsm_body_sags_like_a_tled_one` checks it). Unless `substeps` is given, the
    /// FLSM step is the longest whole number of TLED steps within that `h` at `α = 1`, and `α` is
    /// set so that FLSM matches the material at it. Given `substeps`, `flsm.alpha` is used as is,
    /// and FLSM is softer than the material in proportion to `h²` (the seed's 60 Hz FLSM steps
    /// are hundreds of times softer than its tissue).
    ///
    /// The interface pull stands for the FLSM cells' stiffness at an interface node, about
    /// `E × cell` per cell: `β = 2.5 E cell` makes a TLED region inside an FLSM body sag as the
    /// all-TLED body does (measured on the test's block with 12 and 64 TLED cells: within 5%;
    /// 1.5 E cell sags 21–39% more, 3 E cell 9–11% less; the test checks 10%).
    pub fn resolve(&self, dt: f64, cell: f64, material: &crate::Material) -> HybridSteps {
        match_flsm(dt, cell, material, self.substeps.map(|s| (s, self.flsm.alpha)), None, self.beta)
    }
}

/// FLSM's step and stiffness and the interface pull for a body of `material` on a lattice of
/// spacing `cell` stepped by TLED at `dt` (see [`HybridParams::resolve`] for the model):
/// - `given = Some((substeps, alpha))`: both as given;
/// - else, with `alpha`: the longest FLSM step (whole TLED steps) at which that `alpha` is as stiff
///   as the material or stiffer;
/// - else the longest FLSM step within the match at `α = 1`, and `α` set to match the material at
///   it.
///
/// A matched FLSM step is at most [`MAX_SUBSTEPS`] TLED steps (with `α` matched to that step when
/// `alpha` is not given). `beta`, when not given, is `2.5 E cell`.
pub fn match_flsm(
    dt: f64,
    cell: f64,
    material: &crate::Material,
    given: Option<(usize, f32)>,
    alpha: Option<f32>,
    beta: Option<f32>,
) -> HybridSteps {
    let young = material.young_modulus();
    let beta = beta.unwrap_or((BETA_MATCH * young * cell) as f32);
    // The FLSM step at which goal stiffness α matches the material.
    let h_match = |alpha: f64| FLSM_MATCH * cell * (alpha * material.density / young).sqrt();
    match (given, alpha) {
        (Some((substeps, alpha)), _) => HybridSteps { substeps, alpha, beta },
        (None, Some(alpha)) => HybridSteps { substeps: whole_steps(h_match(f64::from(alpha)) / dt), alpha, beta },
        (None, None) => {
            let substeps = whole_steps(h_match(1.0) / dt);
            let alpha = ((substeps as f64 * dt / h_match(1.0)).powi(2)).min(1.0) as f32;
            HybridSteps { substeps, alpha, beta }
        }
    }
}

/// The whole number of TLED steps within `ratio` of them, 1 to [`MAX_SUBSTEPS`] (1 for NaN).
fn whole_steps(ratio: f64) -> usize {
    ratio.floor().max(1.0).min(MAX_SUBSTEPS as f64) as usize
}

/// The constant `C` of [`HybridParams::resolve`].
const FLSM_MATCH: f64 = 0.6;
/// The interface pull of [`HybridParams::resolve`], in `E × cell`.
const BETA_MATCH: f64 = 2.5;

/// Lattice cells whose deformed centre (mean of its real corners, `rest + u`) lies within
/// `radius` of a point of `tool`.
pub(crate) fn near_tool(lattice: &Lattice, u: &[Vector3<f32>], tool: &[Point3<f64>], radius: f64) -> Vec<bool> {
    let mut near = vec![false; lattice.cells.len()];
    let Some(first) = tool.first() else {
        return near;
    };
    let (mut lo, mut hi) = (*first, *first);
    for p in tool {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let r2 = radius * radius;
    for (c, cell) in lattice.cells.iter().enumerate() {
        let centre = cell
            .nodes
            .iter()
            .fold(Vector3::zeros(), |s, &n| s + lattice.rest[n as usize].coords + u[n as usize].cast::<f64>())
            / 8.0;
        let outside = (0..3).any(|a| centre[a] < lo[a] - radius || centre[a] > hi[a] + radius);
        if !outside {
            near[c] = tool.iter().any(|p| (p.coords - centre).norm_squared() <= r2);
        }
    }
    near
}

/// FLSM over the lattice cells outside the operational region.
#[derive(Debug)]
pub(crate) struct FlsmPart {
    flsm: Flsm,
    /// The body's node of each particle.
    pub node: Vec<u32>,
    /// Particles FLSM moves: nodes of FLSM cells only, not held.
    active: Vec<bool>,
    /// Interface particles: nodes of both FLSM and TLED cells.
    pub interface: Vec<u32>,
    x: Vec<Vector3<f32>>,
    /// The displacement the last step gave each active particle.
    written: Vec<Vector3<f32>>,
    /// Velocity of each particle; kept for active ones (the integrator freezes them).
    pub v: Vec<Vector3<f32>>,
    goals: Vec<Vector3<f32>>,
    /// Goals of the step before, for the goals' velocity (`None` before two steps).
    goals_before: Option<Vec<Vector3<f32>>>,
    /// The last step's length, seconds.
    h: f32,
    f_ext: Vec<Vector3<f32>>,
}

impl FlsmPart {
    /// FLSM over the cells of `lattice` marked in `flsm_cells` (whole, uncut cells over lattice
    /// nodes), with the body's node masses and gravity; `None` when there are no such cells.
    /// `tled_node` marks the nodes of TLED cells, `held` the nodes held in place, `u_now` and
    /// `velocity` give each node's displacement and velocity now.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        lattice: &Lattice,
        flsm_cells: &[bool],
        mass: &[f32],
        gravity: Vector3<f32>,
        tled_node: &[bool],
        held: &[bool],
        u_now: impl Fn(usize) -> Vector3<f32>,
        velocity: impl Fn(usize) -> Vector3<f32>,
        params: FlsmParams,
    ) -> Result<Option<Self>, SimError> {
        if !flsm_cells.contains(&true) {
            return Ok(None);
        }
        let [nx, ny, nz] = lattice.dims;
        let mut fractions = vec![0.0f32; nx * ny * nz];
        for (cell, _) in lattice.cells.iter().zip(flsm_cells).filter(|(_, f)| **f) {
            let [i, j, k] = cell.ijk.map(|a| a as usize);
            fractions[i + nx * (j + ny * k)] = cell.fraction;
        }
        let sub = Lattice::from_fractions(lattice.origin, lattice.cell, lattice.dims, &fractions, 0.0);
        let node: Vec<u32> = sub
            .node_ijk
            .iter()
            .map(|ijk| {
                lattice.node_at(ijk.map(|a| a as usize)).ok_or_else(|| SimError::Invalid {
                    key: "hybrid".into(),
                    message: format!("FLSM node at grid index {ijk:?} is not a lattice node"),
                })
            })
            .collect::<Result<_, _>>()?;
        let masses: Vec<f64> = node.iter().map(|&n| f64::from(mass[n as usize])).collect();
        let flsm = Flsm::new(&sub, &masses, params)?;
        let active: Vec<bool> = node.iter().map(|&n| !tled_node[n as usize] && !held[n as usize]).collect();
        let interface = (0..node.len() as u32).filter(|&p| tled_node[node[p as usize] as usize]).collect();
        let n = node.len();
        Ok(Some(Self {
            flsm,
            active,
            interface,
            x: vec![Vector3::zeros(); n],
            written: node.iter().map(|&n| u_now(n as usize)).collect(),
            v: node.iter().map(|&n| velocity(n as usize)).collect(),
            goals: vec![Vector3::zeros(); n],
            goals_before: None,
            h: 0.0,
            f_ext: node.iter().map(|&n| gravity * mass[n as usize]).collect(),
            node,
        }))
    }

    /// Whether particle `p` is moved by FLSM.
    pub fn is_active(&self, p: usize) -> bool {
        self.active[p]
    }

    /// One FLSM step of `dt` seconds from the body's displacements `u` (rest positions `rest`):
    /// moves the active particles' displacements and leaves their goals for the interface pull.
    /// An active particle whose displacement changed since the last step (contact moved it)
    /// starts this one at rest. The other particles take their velocity from the integrator's
    /// `u` and `u_prev` over its step `dt_tled`: region damping compares each velocity with its
    /// regions' mean, and a stale one would drag the active particles.
    /// `damping` is the body's mass-proportional damping (1/s), applied to the FLSM velocities
    /// as the integrator applies it to the TLED ones.
    pub fn step(
        &mut self,
        rest: &[Point3<f32>],
        motion: (&mut [Vector3<f32>], &[Vector3<f32>], f32),
        dt: f32,
        damping: f32,
    ) {
        let (u, u_prev, dt_tled) = motion;
        for (p, &n) in self.node.iter().enumerate() {
            let n = n as usize;
            if !self.active[p] {
                self.v[p] = (u[n] - u_prev[n]) / dt_tled;
            } else if u[n] != self.written[p] {
                self.v[p] = Vector3::zeros();
            }
            self.x[p] = rest[n].coords + u[n];
        }
        self.flsm.step(&mut self.x, &mut self.v, &self.f_ext, dt, Some(&self.active));
        if self.h > 0.0 {
            let before = self.goals_before.get_or_insert_with(Vec::new);
            before.clone_from(&self.goals);
        }
        self.h = dt;
        let keep = (1.0 - 0.5 * damping * dt) / (1.0 + 0.5 * damping * dt);
        for (v, _) in self.v.iter_mut().zip(&self.active).filter(|(_, a)| **a) {
            *v *= keep.max(0.0);
        }
        self.goals.copy_from_slice(self.flsm.goals());
        for (p, &n) in self.node.iter().enumerate() {
            if self.active[p] {
                u[n as usize] = self.x[p] - rest[n as usize].coords;
                self.written[p] = u[n as usize];
            }
        }
    }

    /// The FLSM goal of particle `p` from the last step, world metres.
    pub fn goal(&self, p: usize) -> Vector3<f32> {
        self.goals[p]
    }

    /// How fast the goal of particle `p` moved over the last step, m/s (zero before two steps).
    pub fn goal_velocity(&self, p: usize) -> Vector3<f32> {
        match &self.goals_before {
            Some(before) => (self.goals[p] - before[p]) / self.h,
            None => Vector3::zeros(),
        }
    }
}

/// Roles of the nodes of a cut lattice with `node_count` nodes: `tled_node` marks nodes of TLED
/// cells; `part` (the FLSM part) the nodes of FLSM cells.
pub(crate) fn node_roles(node_count: usize, tled_node: &[bool], part: Option<&FlsmPart>) -> Vec<NodeRole> {
    let mut in_flsm = vec![false; node_count];
    if let Some(part) = part {
        for &n in &part.node {
            in_flsm[n as usize] = true;
        }
    }
    (0..node_count)
        .map(|n| match (tled_node.get(n).copied().unwrap_or(true), in_flsm[n]) {
            (true, true) => NodeRole::Interface,
            (false, true) => NodeRole::Flsm,
            _ => NodeRole::Tled,
        })
        .collect()
}
