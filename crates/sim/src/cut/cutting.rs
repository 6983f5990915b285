//! A body that a blade cuts while it deforms: TLED on the virtual node algorithm's cut lattice,
//! explicit time stepping under gravity, and the closed surfaces of its pieces.
//!
//! [`CutSim::cut`] finds the lattice edges a swept blade surface crosses in the deformed body
//! (parry's bounding volume hierarchy over the cells, segment–triangle tests), adds them to the cuts so far and, when any is new,
//! rebuilds the topology ([`CutTopology::rebuild`]), the TLED model over the copies and the lumped
//! masses, and carries the motion over: a node of the new topology takes the displacement of the
//! node that held the same corner of the same material before, so nothing jumps when a cut lands
//! and pieces cut off earlier keep where they are. Cutting only ever divides a copy's material, and
//! every copy keeps its parent's cube, so the stable time step computed for the whole body stays
//! valid (mass and stiffness of a copy both scale with its material).
//!
//! Obstacles ([`CutSim::set_obstacles`], the reconstructed hand) push the tissue aside: nodes
//! found inside one after a time step are moved out and stopped. A table
//! ([`CutSimParams::table`]) holds the body up with friction, so a piece cut free falls onto it
//! and rests there.
//!
//! Every cell is TLED unless [`CutSimParams::hybrid`] is set: then the operational region follows
//! the tool ([`CutSim::set_tool`]) and FLSM moves the rest, with regions rebuilt from the cut
//! lattice's connectivity (see [`crate::operational`]).

use std::collections::BTreeSet;
use std::time::Instant;

use nalgebra::{Point3, Vector3};

use crate::collide::{CellTree, EdgeCut, cut_edges, padded};
use crate::cut_surface::{BodySamples, PieceSurface, piece_surfaces};
use crate::dynamics::{Divergence, Integrator, Prescribed};
use crate::flsm::FlsmParams;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::obstacle::Obstacle;
use crate::operational::{FarField, FlsmPart, HybridParams, HybridSteps, near_tool, node_roles};
use crate::piece_contact::{self, PieceContacts};
use crate::simulation::NodeRole;
use crate::stability;
use crate::sweep::SweptSurface;
use crate::table::Table;
use crate::tled::{Tled, TledParams};
use crate::vna::CutTopology;
use crate::vna::cut_band;
use crate::{Material, SimError};

#[cfg(feature = "gpu")]
mod on_gpu;

/// Settings of a [`CutSim`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CutSimParams {
    /// TLED quadrature and hourglass control.
    pub tled: TledParams,
    /// Mass-proportional damping, 1/s.
    pub damping: f32,
    /// Gravity, m/s².
    pub gravity: [f64; 3],
    /// Time step as a fraction of the computed critical step.
    pub dt_safety: f64,
    /// Copies holding less than this share of a full cell are dropped (they carry too little
    /// material to matter).
    pub min_fraction: f32,
    /// Surface samples per lattice cell along each axis.
    pub samples_per_cell: usize,
    /// The hybrid model (TLED near the tool, FLSM elsewhere); `None`: TLED everywhere.
    pub hybrid: Option<HybridParams>,
    /// The table the body rests on (contact with friction after every step); `None`: no table.
    pub table: Option<Table>,
}

impl Default for CutSimParams {
    fn default() -> Self {
        Self {
            tled: TledParams::default(),
            damping: 40.0,
            gravity: [0.0, 0.0, -9.81],
            dt_safety: 0.8,
            min_fraction: 1e-3,
            samples_per_cell: 2,
            hybrid: None,
            table: None,
        }
    }
}

/// What one call of [`CutSim::cut`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CutOutcome {
    /// Lattice edges the swept surface crossed.
    pub crossed: usize,
    /// Of those, edges not cut before.
    pub new_edges: usize,
    /// Separate pieces of the body after the cut.
    pub pieces: usize,
    /// Cell copies after the cut.
    pub copies: usize,
    /// Virtual nodes after the cut.
    pub virtual_nodes: usize,
    /// Collision (hash and tests), milliseconds.
    pub collide_ms: f64,
    /// Topology, TLED, masses and state transfer, milliseconds (0 when nothing new was cut).
    pub topology_ms: f64,
    /// Piece surfaces, milliseconds (0 when nothing new was cut).
    pub surface_ms: f64,
}

/// Where a piece of the body is and how it moves (see [`CutSim::piece_states`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PieceState {
    /// Material volume, cubic metres.
    pub volume_m3: f64,
    /// Nodes (real and virtual) of its cell copies.
    pub nodes: usize,
    /// Mean position of its nodes, world metres.
    pub centroid_m: [f64; 3],
    /// Its lowest node's height above the table's top (world z when there is no table), metres.
    pub lowest_above_table_m: f64,
    /// Mean and largest node speed, m/s.
    pub mean_speed_m_s: f64,
    /// See `mean_speed_m_s`.
    pub max_speed_m_s: f64,
    /// Nodes held in place.
    pub held_nodes: usize,
    /// Nodes resting on the table (within a micrometre of its top).
    pub on_table: usize,
}

/// A deformable body that can be cut.
#[derive(Debug)]
pub struct CutSim {
    lattice: Lattice,
    material: Material,
    params: CutSimParams,
    samples: BodySamples,
    fixed: Vec<bool>,
    topology: CutTopology,
    tled: Tled,
    integrator: Integrator,
    f_int: Vec<Vector3<f32>>,
    f_ext: Vec<Vector3<f32>>,
    surfaces: Vec<PieceSurface>,
    dt_critical: f64,
    dropped: usize,
    /// Rest positions of the cut lattice's nodes (virtual nodes at their real node's).
    rest: Vec<Point3<f32>>,
    /// Whether each node is held in place.
    held: Vec<bool>,
    obstacles: Vec<Obstacle>,
    contacts: usize,
    /// Nodes on the table after the last step.
    table_contacts: usize,
    /// Time the last advance spent resolving contacts on the CPU, seconds.
    contact_s: f64,
    /// For each node of the cut lattice, the piece whose material it carries (`u32::MAX` for
    /// virtual nodes, nodes without mass and held ones): the nodes kept out of other pieces.
    piece_of_node: Vec<u32>,
    /// The contact planes between pieces found at the start of the last advance.
    piece_contacts: PieceContacts,
    /// Nodes put back on a contact plane after the last step.
    piece_contact_nodes: usize,
    /// The cut lattice: one cell per kept copy, over lattice and virtual nodes.
    cut_lattice: Lattice,
    /// Gravity on each node, newtons.
    f_gravity: Vec<Vector3<f32>>,
    /// Lattice cells run by TLED.
    cell_tled: Vec<bool>,
    /// Cells that stay TLED because a cut passes through them or next to them.
    band: Vec<bool>,
    /// Nodes of TLED cells.
    node_tled: Vec<bool>,
    /// Where the tool is, world metres (deformed configuration).
    tool: Vec<Point3<f64>>,
    /// FLSM over the cells outside the operational region (hybrid only, when there are any).
    flsm: Option<FlsmPart>,
    /// Operational-region changes so far.
    region_changes: usize,
    /// Substeps and stiffnesses of the hybrid model.
    steps: Option<HybridSteps>,
    /// Interface anchors of the current FLSM step: node, goal − rest, β × velocity.
    anchors: Vec<(usize, Vector3<f32>, Vector3<f32>)>,
    /// Sliver copies torn off after they diverged ([`CellCopy::key`](crate::vna::CellCopy::key)):
    /// left out of the cut lattice from then on.
    torn: BTreeSet<(u32, u8)>,
    /// The state at the start of the current advance, to take it again after a tear.
    rewind: Rewind,
    /// The GPU backend, once [`CutSim::use_gpu`] chose it.
    #[cfg(feature = "gpu")]
    gpu: Option<crate::gpu::GpuRun>,
}

impl CutSim {
    /// A body on `lattice` whose shape is the negative set of `signed` (a signed distance, metres),
    /// with the lattice nodes for which `fixed` holds held in place.
    pub fn new(
        lattice: Lattice,
        signed: &(dyn Fn(&Point3<f64>) -> f64 + Sync),
        material: Material,
        fixed: impl Fn(&Point3<f64>) -> bool,
        params: CutSimParams,
    ) -> Result<Self, SimError> {
        material.validate()?;
        let invalid = |key: &str, message: String| SimError::Invalid { key: key.to_owned(), message };
        if !(params.dt_safety > 0.0 && params.dt_safety < 1.0) {
            return Err(invalid("dt_safety", format!("must lie in (0, 1), got {}", params.dt_safety)));
        }
        if !(params.damping.is_finite() && params.damping >= 0.0) {
            return Err(invalid("damping", format!("must be >= 0, got {}", params.damping)));
        }
        if lattice.cells.is_empty() {
            return Err(invalid("body", "the lattice has no cells".to_owned()));
        }
        if let Some(hybrid) = &params.hybrid {
            hybrid.validate()?;
        }
        if let Some(table) = &params.table {
            table.validate()?;
        }
        let fixed: Vec<bool> = lattice.rest.iter().map(fixed).collect();
        let samples = BodySamples::new(&lattice, params.samples_per_cell, signed);
        let topology = CutTopology::rebuild(&lattice, []);
        let (cut, dropped) = topology.to_lattice(&lattice, params.min_fraction, &BTreeSet::new());
        let mut tled = Tled::new(&cut, None, &material, params.tled)?;
        let mass: Vec<f32> = cut.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
        let free: Vec<[bool; 3]> = (0..cut.node_count()).map(|n| [!fixed[n]; 3]).collect();
        let zeros = vec![Vector3::zeros(); cut.node_count()];
        let limit = stability::estimate(&mut tled, &mass, &free, &zeros, lattice.cell, 300, 1e-6);
        let dt_critical = limit.dt_critical.min(lone_cell_dt(&lattice, &material, params.tled)?);
        let dt = (params.dt_safety * dt_critical) as f32;
        let steps = params
            .hybrid
            .filter(|h| h.far_field == FarField::Flsm)
            .map(|h| h.resolve(f64::from(dt), lattice.cell, &material));
        let integrator = Integrator::new(mass, Vec::new(), 0, params.damping, dt, speed_limit(&material));
        let mut sim = CutSim {
            lattice,
            material,
            params,
            samples,
            fixed,
            topology,
            tled,
            integrator,
            f_int: Vec::new(),
            f_ext: Vec::new(),
            surfaces: Vec::new(),
            dt_critical,
            dropped,
            rest: Vec::new(),
            held: Vec::new(),
            obstacles: Vec::new(),
            contacts: 0,
            table_contacts: 0,
            contact_s: 0.0,
            piece_of_node: Vec::new(),
            piece_contacts: PieceContacts::default(),
            piece_contact_nodes: 0,
            cut_lattice: Lattice::block(Point3::origin(), 1.0, [0, 0, 0]),
            f_gravity: Vec::new(),
            cell_tled: Vec::new(),
            band: Vec::new(),
            node_tled: Vec::new(),
            tool: Vec::new(),
            flsm: None,
            region_changes: 0,
            steps,
            anchors: Vec::new(),
            torn: BTreeSet::new(),
            rewind: Rewind::default(),
            #[cfg(feature = "gpu")]
            gpu: None,
        };
        sim.install(
            cut,
            vec![Vector3::zeros(); sim.lattice.node_count()],
            vec![Vector3::zeros(); sim.lattice.node_count()],
        )?;
        sim.surfaces = piece_surfaces(&sim.lattice, &sim.topology, &sim.samples);
        Ok(sim)
    }

    /// Sets up TLED, masses, constraints and forces for a cut lattice, with its displacements now
    /// and one step ago, and the operational region over it.
    fn install(&mut self, cut: Lattice, u: Vec<Vector3<f32>>, u_prev: Vec<Vector3<f32>>) -> Result<(), SimError> {
        // Selective mass scaling: a node of the cut lattice that carries mass weighs at least
        // MASS_FLOOR of a full cell's node. A sliver copy's mass and stiffness scale together, so
        // it is stable in the linear range, but crossing cuts leave slivers that deform far into
        // the nonlinear one: in the built-in scene with the hybrid model, a virtual node of 6% of
        // a node's mass reached 55 m/s at frame 120 without the floor. Nodes of dropped copies
        // only keep no mass (the integrator leaves them where they are).
        let floor = (MASS_FLOOR * self.material.density * self.lattice.cell.powi(3) / 8.0) as f32;
        let mass: Vec<f32> = cut
            .lumped_masses(self.material.density)
            .iter()
            .map(|&m| if m > 0.0 { (m as f32).max(floor) } else { 0.0 })
            .collect();
        let base = self.lattice.node_count();
        let held = |n: usize| {
            let real = if n < base { n } else { self.topology.virtual_of[n - base] as usize };
            self.fixed[real]
        };
        let prescribed: Vec<Prescribed> = (0..cut.node_count())
            .filter(|&n| held(n))
            .flat_map(|n| {
                (0..3).map(move |axis| Prescribed { node: n as u32, axis, target: 0.0, ramp: 0.0, groups: 0 })
            })
            .collect();
        let g = Vector3::from(self.params.gravity).cast::<f32>();
        self.f_gravity = mass.iter().map(|&m| g * m).collect();
        self.f_ext.clone_from(&self.f_gravity);
        self.f_int = vec![Vector3::zeros(); cut.node_count()];
        self.rest = cut.rest.iter().map(|p| p.cast::<f32>()).collect();
        self.held = (0..cut.node_count()).map(held).collect();
        self.piece_of_node = vec![u32::MAX; cut.node_count()];
        for (copy, &piece) in self.topology.copies.iter().zip(&self.topology.piece_of) {
            for corner in (0..8).filter(|c| copy.material & (1 << c) != 0) {
                let n = copy.nodes[corner] as usize;
                if n < base && mass[n] > 0.0 && !self.held[n] {
                    self.piece_of_node[n] = piece;
                }
            }
        }
        let step = self.integrator.step;
        let mut integrator =
            Integrator::new(mass, prescribed, 0, self.params.damping, self.integrator.dt, self.integrator.speed_limit);
        integrator.step = step;
        integrator.u = u;
        integrator.u_prev = u_prev;
        self.integrator = integrator;
        self.cut_lattice = cut;
        #[cfg(feature = "gpu")]
        if let Some(run) = &mut self.gpu {
            // The stepper takes the cut lattice over at the next advance.
            run.stale = true;
        }
        // Whatever FLSM moved is in u and u_prev now (see `flush_flsm`); the region is rebuilt.
        self.flsm = None;
        let width = self.params.hybrid.map_or(0, |h| h.flsm.w);
        self.band = cut_band(&self.lattice, &self.topology, width);
        let wanted = match self.params.hybrid {
            Some(_) => self.wanted_region(),
            None => vec![true; self.lattice.cells.len()],
        };
        self.set_region(wanted)
    }

    /// The cells the operational region should hold now (hybrid only): the cut band, the cells
    /// near the tool, and TLED cells still near it or still moving.
    fn wanted_region(&self) -> Vec<bool> {
        let Some(h) = self.params.hybrid else {
            return vec![true; self.lattice.cells.len()];
        };
        if h.far_field == FarField::Frozen && self.cell_tled.is_empty() {
            // All TLED to begin with: the body settles before its cells sleep.
            return vec![true; self.lattice.cells.len()];
        }
        let u = &self.integrator.u;
        let near = near_tool(&self.lattice, u, &self.tool, h.radius);
        let near_leave = near_tool(&self.lattice, u, &self.tool, 1.5 * h.radius);
        let dt = self.integrator.dt;
        // With a frozen far field a node also counts as moving while its forces are out of
        // balance (at the start of a settle it has no speed yet, only gravity): above the
        // acceleration that would take it to `rest_speed` in REST_TIME_S.
        // Held nodes and the table's push (a node on it is pushed up as hard as it presses down)
        // are left out of the balance.
        let out_of_balance = |n: usize| {
            let it = &self.integrator;
            if h.far_field != FarField::Frozen || it.mass[n] <= 0.0 || it.frozen[n] || self.held[n] {
                return false;
            }
            let mut residual = self.f_ext[n] - self.tled.node_force(n);
            let on_table = self.params.table.is_some_and(|t| f64::from(self.rest[n].z + u[n].z) <= t.height + 1e-6);
            if on_table {
                residual.z = residual.z.max(0.0);
            }
            residual.norm() > it.mass[n] * h.rest_speed / REST_TIME_S
        };
        let moving = |c: usize| {
            self.lattice.cells[c].nodes.iter().any(|&n| {
                let n = n as usize;
                (u[n] - self.integrator.u_prev[n]).norm() > h.rest_speed * dt || out_of_balance(n)
            })
        };
        // A cell the obstacles (the hand) reach into is awake: a sleeping or FLSM node is not
        // pushed out of them, and the hand would pass through a far field that sleeps. Each
        // lattice node is looked up once.
        let pressed: Vec<bool> = if self.obstacles.is_empty() {
            Vec::new()
        } else {
            (0..self.lattice.node_count())
                .map(|n| {
                    let p = self.rest[n] + u[n];
                    self.obstacles.iter().any(|o| o.push_at(&p).is_some())
                })
                .collect()
        };
        let touched =
            |c: usize| !pressed.is_empty() && self.lattice.cells[c].nodes.iter().any(|&n| pressed[n as usize]);
        (0..self.lattice.cells.len())
            .map(|c| {
                self.band[c]
                    || near[c]
                    || touched(c)
                    || (self.cell_tled.get(c).copied().unwrap_or(false) && (near_leave[c] || moving(c)))
            })
            .collect()
    }

    /// Makes `wanted` the operational region: TLED over the copies of its cells, FLSM over the
    /// other cells, interface pulls and frozen nodes set; velocities carry over.
    fn set_region(&mut self, wanted: Vec<bool>) -> Result<(), SimError> {
        self.flush_flsm();
        let cells: Vec<usize> = self
            .cut_lattice
            .cells
            .iter()
            .enumerate()
            .filter(|(_, cell)| {
                let parent = self.lattice.cell_index(cell.ijk.map(|a| a as usize));
                parent.is_none_or(|p| wanted[p])
            })
            .map(|(k, _)| k)
            .collect();
        self.tled = Tled::new(&self.cut_lattice, Some(&cells), &self.material, self.params.tled)?;
        let n = self.cut_lattice.node_count();
        self.node_tled = vec![false; n];
        for &k in &cells {
            for &node in &self.cut_lattice.cells[k].nodes {
                self.node_tled[node as usize] = true;
            }
        }
        let dt = self.integrator.dt;
        let (u, u_prev) = (&self.integrator.u, &self.integrator.u_prev);
        self.flsm = match (self.params.hybrid, self.steps) {
            (Some(h), Some(steps)) => {
                let flsm_cells: Vec<bool> = wanted.iter().map(|w| !w).collect();
                FlsmPart::new(
                    &self.lattice,
                    &flsm_cells,
                    &self.integrator.mass,
                    Vector3::from(self.params.gravity).cast::<f32>(),
                    &self.node_tled,
                    &self.held,
                    |node| u[node],
                    |node| (u[node] - u_prev[node]) / dt,
                    FlsmParams { alpha: steps.alpha, ..h.flsm },
                )?
            }
            _ => None,
        };
        self.anchors.clear();
        self.integrator.frozen = vec![false; n];
        self.integrator.implicit_stiffness = vec![0.0; n];
        self.f_ext.clone_from(&self.f_gravity);
        if let (Some(part), Some(steps)) = (&self.flsm, self.steps) {
            for (p, &node) in part.node.iter().enumerate() {
                self.integrator.frozen[node as usize] = part.is_active(p);
            }
            for &p in &part.interface {
                self.integrator.implicit_stiffness[part.node[p as usize] as usize] = steps.beta;
            }
        }
        if self.params.hybrid.is_some_and(|h| h.far_field == FarField::Frozen) {
            // Sleeping cells hold their nodes, the region's nodes they share included.
            let mut awake = vec![false; self.cut_lattice.cells.len()];
            for &k in &cells {
                awake[k] = true;
            }
            for (cell, _) in self.cut_lattice.cells.iter().zip(&awake).filter(|(_, a)| !**a) {
                for &node in &cell.nodes {
                    self.integrator.frozen[node as usize] = true;
                }
            }
            // Steps and contacts then cost what the awake nodes cost.
            let it = &self.integrator;
            let active =
                (0..n).filter(|&i| (!it.frozen[i] && it.mass[i] > 0.0) || self.held[i]).map(|i| i as u32).collect();
            self.integrator.set_active(Some(active));
        }
        if !self.cell_tled.is_empty() && self.cell_tled != wanted {
            self.region_changes += 1;
        }
        self.cell_tled = wanted;
        Ok(())
    }

    /// Writes the velocities FLSM keeps for its nodes back into the integrator's previous
    /// displacements (frozen nodes lose theirs there), so that the integrator state alone
    /// describes the motion.
    fn flush_flsm(&mut self) {
        let Some(part) = &self.flsm else {
            return;
        };
        let dt = self.integrator.dt;
        for (p, &node) in part.node.iter().enumerate() {
            if part.is_active(p) {
                let n = node as usize;
                self.integrator.u_prev[n] = self.integrator.u[n] - part.v[p] * dt;
            }
        }
    }

    /// Where the tool is now (world metres, deformed configuration), e.g. the swept blade surface
    /// and the edge: with the hybrid model, cells near it become TLED at the next
    /// [`Self::advance`]. An empty slice: no tool (cells return to FLSM once at rest).
    pub fn set_tool(&mut self, points: &[Point3<f64>]) {
        self.tool.clear();
        self.tool.extend_from_slice(points);
    }

    /// The role of every node of the cut lattice (lattice nodes first, then virtual ones): TLED,
    /// FLSM or interface.
    pub fn node_roles(&self) -> Vec<NodeRole> {
        node_roles(self.integrator.u.len(), &self.node_tled, self.flsm.as_ref())
    }

    /// Lattice cells run by TLED now.
    pub fn tled_cells(&self) -> usize {
        self.cell_tled.iter().filter(|&&t| t).count()
    }

    /// TLED steps per FLSM step (1 without the hybrid).
    pub fn substeps(&self) -> usize {
        self.steps.map_or(1, |s| s.substeps)
    }

    /// The hybrid model's substeps and stiffnesses, when it runs.
    pub fn hybrid_steps(&self) -> Option<HybridSteps> {
        self.steps
    }

    /// How many times the operational region has changed.
    pub fn region_changes(&self) -> usize {
        self.region_changes
    }

    /// Cuts the body with a swept blade surface (world metres, in the deformed configuration).
    ///
    /// Where the edge plunges to within [`crate::table::TABLE_REACH_M`] of the table, it cuts
    /// through to it ([`Table::pressed_through`]).
    pub fn cut(&mut self, surface: &SweptSurface) -> Result<CutOutcome, SimError> {
        let start = Instant::now();
        let pressed = self.params.table.and_then(|t| t.pressed_through(surface));
        let surface = pressed.as_ref().unwrap_or(surface);
        let positions: Vec<Point3<f64>> =
            self.lattice.rest.iter().zip(&self.integrator.u).map(|(p, u)| p + u.cast::<f64>()).collect();
        // Only the cells near the swept surface can be cut: the tree holds those.
        let (mut lo, mut hi) =
            (Point3::from(Vector3::repeat(f64::INFINITY)), Point3::from(Vector3::repeat(f64::NEG_INFINITY)));
        for v in &surface.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        let (lo, hi) = padded(&lo, &hi);
        let tree = CellTree::within(&self.lattice, &positions, &lo, &hi);
        let cuts = cut_edges(&self.lattice, &positions, &tree, surface);
        let new_edges =
            cuts.edges.iter().filter(|e| !self.topology.cut.contains_key(&(e.a.min(e.b), e.a.max(e.b)))).count();
        let mut outcome = CutOutcome {
            crossed: cuts.edges.len(),
            new_edges,
            pieces: self.topology.pieces,
            copies: self.topology.copies.len(),
            virtual_nodes: self.topology.virtual_of.len(),
            collide_ms: start.elapsed().as_secs_f64() * 1e3,
            ..CutOutcome::default()
        };
        if new_edges == 0 {
            return Ok(outcome);
        }
        let start = Instant::now();
        let old_edges = self.topology.cut.iter().map(|(&(a, b), &t)| EdgeCut { a, b, t, triangle: u32::MAX });
        let edges: Vec<EdgeCut> = old_edges.chain(cuts.edges).collect();
        let topology = CutTopology::rebuild(&self.lattice, edges);
        self.flush_flsm();
        let (u, u_prev) = self.carry_over(&topology);
        let old = std::mem::replace(&mut self.topology, topology);
        let (cut, dropped) = self.topology.to_lattice(&self.lattice, self.params.min_fraction, &self.torn);
        if let Err(e) = self.install(cut, u, u_prev) {
            self.topology = old;
            return Err(e);
        }
        self.dropped = dropped;
        outcome.topology_ms = start.elapsed().as_secs_f64() * 1e3;
        let start = Instant::now();
        self.surfaces = piece_surfaces(&self.lattice, &self.topology, &self.samples);
        outcome.surface_ms = start.elapsed().as_secs_f64() * 1e3;
        outcome.pieces = self.topology.pieces;
        outcome.copies = self.topology.copies.len();
        outcome.virtual_nodes = self.topology.virtual_of.len();
        Ok(outcome)
    }

    /// Displacements (now and one step ago) for the nodes of `next`: each corner of each new copy
    /// takes the value of the same corner of the old copy whose material contains the new copy's.
    fn carry_over(&self, next: &CutTopology) -> (Vec<Vector3<f32>>, Vec<Vector3<f32>>) {
        let base = self.lattice.node_count();
        let n = next.node_count(&self.lattice);
        let (old_u, old_prev) = (&self.integrator.u, &self.integrator.u_prev);
        let mut u = vec![Vector3::zeros(); n];
        let mut u_prev = vec![Vector3::zeros(); n];
        u[..base].copy_from_slice(&old_u[..base]);
        u_prev[..base].copy_from_slice(&old_prev[..base]);
        for c in 0..self.lattice.cells.len() {
            for k in next.copies_of(c) {
                let copy = &next.copies[k];
                let from = self
                    .topology
                    .copies_of(c)
                    .map(|o| &self.topology.copies[o])
                    .find(|o| o.material & copy.material == copy.material);
                for corner in 0..8 {
                    let node = copy.nodes[corner] as usize;
                    if node < base {
                        continue;
                    }
                    let source = from.map_or(next.virtual_of[node - base] as usize, |o| o.nodes[corner] as usize);
                    u[node] = old_u[source];
                    u_prev[node] = old_prev[source];
                }
            }
        }
        (u, u_prev)
    }

    /// Advances by `seconds` of simulated time (whole steps, at least one); the TLED steps taken.
    ///
    /// With the hybrid model the operational region is updated first (see
    /// [`crate::operational`]), and time advances in FLSM steps of `substeps` TLED steps.
    ///
    /// A sliver that diverges is torn off: when the node that diverged belongs to copies holding
    /// less than [`TEAR_ON_DIVERGENCE`] of a cell, those copies leave the cut lattice (counted by
    /// [`Self::torn_copies`]) and the advance starts again from where it began, up to
    /// [`MAX_TEARS_PER_ADVANCE`] times. Re-cutting cut cells (a blade stroked again through its
    /// own groove) leaves copies of a few percent of a cell: in the built-in scene's third replay
    /// a virtual node of a copy holding 8.8% of its cell reached 700 m/s, floored mass and all.
    /// Tissue tears such shreds. Any other divergence is returned as it is.
    pub fn advance(&mut self, seconds: f64) -> Result<usize, Divergence> {
        // The state to start again from, in buffers kept across advances (no allocation a frame).
        let mut start = std::mem::take(&mut self.rewind);
        start.u.clone_from(&self.integrator.u);
        start.u_prev.clone_from(&self.integrator.u_prev);
        start.step = self.integrator.step;
        let mut tears = 0;
        let result = loop {
            match self.advance_once(seconds) {
                Err(d) if tears < MAX_TEARS_PER_ADVANCE && self.tear_sliver_at(d.node, &start) => tears += 1,
                result => break result,
            }
        };
        self.rewind = start;
        result
    }

    /// Tears off the sliver copies (under [`TEAR_ON_DIVERGENCE`] of a cell) that hold `node` and
    /// puts the state back to `start`; false when `node` is in no sliver, or the cut lattice could
    /// not be set up without them.
    fn tear_sliver_at(&mut self, node: usize, start: &Rewind) -> bool {
        let share = |c: &crate::vna::CellCopy| f64::from(self.lattice.cells[c.parent as usize].fraction) * c.share;
        let slivers: Vec<((u32, u8), f64)> = self
            .topology
            .copies
            .iter()
            .filter(|c| c.nodes.contains(&(node as u32)) && !self.torn.contains(&c.key()))
            .filter(|c| share(c) < TEAR_ON_DIVERGENCE)
            .map(|c| (c.key(), share(c)))
            .collect();
        if slivers.is_empty() {
            return false;
        }
        self.torn.extend(slivers.iter().map(|(key, _)| *key));
        let (cut, dropped) = self.topology.to_lattice(&self.lattice, self.params.min_fraction, &self.torn);
        self.integrator.step = start.step;
        if self.install(cut, start.u.clone(), start.u_prev.clone()).is_err() {
            for (key, _) in &slivers {
                self.torn.remove(key);
            }
            return false;
        }
        self.dropped = dropped;
        let largest = slivers.iter().map(|(_, s)| *s).fold(0.0, f64::max);
        tracing::info!(node, copies = slivers.len(), largest_share = largest, "a diverged sliver torn off");
        true
    }

    /// Copies torn off after they diverged (see [`Self::advance`]), so far.
    pub fn torn_copies(&self) -> usize {
        self.torn.len()
    }

    /// One try of [`Self::advance`].
    fn advance_once(&mut self, seconds: f64) -> Result<usize, Divergence> {
        let substeps = self.substeps();
        if self.params.hybrid.is_some() {
            let wanted = self.wanted_region();
            if wanted != self.cell_tled {
                self.set_region(wanted).map_err(|e| Divergence {
                    step: self.integrator.step,
                    time: self.integrator.time(),
                    node: 0,
                    reason: format!("the operational region could not be rebuilt: {e}"),
                })?;
            }
        }
        let outer = (seconds / (f64::from(self.integrator.dt) * substeps as f64)).ceil().max(1.0) as usize;
        self.contacts = 0;
        self.contact_s = 0.0;
        // The pieces' contact planes are found anew every PIECE_REFRESH_S of simulated time.
        let step_s = f64::from(self.integrator.dt) * substeps as f64;
        let refresh = ((PIECE_REFRESH_S / step_s).round() as usize).max(1);
        #[allow(unused_mut)]
        let mut done = 0;
        #[cfg(feature = "gpu")]
        while done < outer {
            // On the GPU, in batches of `refresh` steps: its steps do not see the pieces' planes,
            // which are enforced after each batch (and the state sent back when they moved a
            // node), in batches of PIECE_CONTACT_GPU_STEPS while there are planes.
            self.find_piece_contacts();
            let batch =
                if self.piece_contacts.planes.is_empty() { refresh } else { PIECE_CONTACT_GPU_STEPS }.min(outer - done);
            if !self.gpu_steps(batch)? {
                break;
            }
            let clock = Instant::now();
            self.enforce_piece_contacts_after_batch();
            self.contact_s += clock.elapsed().as_secs_f64();
            done += batch;
        }
        for outer_step in done..outer {
            if (outer_step - done) % refresh == 0 {
                self.find_piece_contacts();
            }
            if let (Some(part), Some(steps)) = (&mut self.flsm, self.steps) {
                let dt = self.integrator.dt;
                part.step(
                    &self.rest,
                    (&mut self.integrator.u, &self.integrator.u_prev, dt),
                    dt * substeps as f32,
                    self.params.damping,
                );
                // The interface pull's anchor: the goal, moving on through the sub-steps as it moved
                // over the last FLSM step. A fixed goal lags the body's motion by up to one FLSM
                // step and drags the interface like a damper of about β × h per node (a cut-off
                // piece then sinks at millimetres per second instead of falling); the node's own
                // velocity would feed back into its pull and destabilize it.
                self.anchors.clear();
                for &p in &part.interface {
                    let (n, p) = (part.node[p as usize] as usize, p as usize);
                    let goal = part.goal(p) - self.rest[n].coords;
                    self.anchors.push((n, goal, part.goal_velocity(p) * steps.beta));
                }
            }
            for k in 0..substeps {
                // β (anchor − x) with x = rest + u: the constant part here, −β u implicitly, both at
                // the end of the sub-step (the integrator takes the pull on the new displacement).
                let beta = self.steps.map_or(0.0, |s| s.beta);
                let tau = (k + 1) as f32 * self.integrator.dt;
                for &(n, goal, beta_v) in &self.anchors {
                    self.f_ext[n] = self.f_gravity[n] + goal * beta + beta_v * tau;
                }
                self.tled.element_pass(&self.integrator.u);
                let tled = &self.tled;
                self.integrator.advance_with(|i| tled.node_force(i), &self.f_ext)?;
                let clock = Instant::now();
                if !self.obstacles.is_empty() {
                    self.contacts = self.resolve_contacts();
                }
                if let Some(table) = &self.params.table {
                    let (rest, held) = (&self.rest, &self.held);
                    self.table_contacts = self.integrator.with_active(|active, u, u_prev| match active {
                        Some(nodes) => table.resolve_nodes(rest, u, u_prev, held, nodes.iter().map(|&n| n as usize)),
                        None => table.resolve(rest, u, u_prev, held),
                    });
                }
                self.enforce_piece_contacts();
                self.contact_s += clock.elapsed().as_secs_f64();
            }
        }
        Ok(outer * substeps)
    }

    /// Finds the contact planes between pieces for this advance (see [`crate::piece_contact`]),
    /// timed with the other contacts.
    fn find_piece_contacts(&mut self) {
        self.piece_contact_nodes = 0;
        if self.topology.pieces < 2 {
            self.piece_contacts = PieceContacts::default();
            return;
        }
        let clock = Instant::now();
        let reach = (PIECE_REACH * self.lattice.cell) as f32;
        let u = &self.integrator.u;
        self.piece_contacts = piece_contact::detect(&self.surfaces, &self.rest, u, &self.piece_of_node, reach);
        self.contact_s += clock.elapsed().as_secs_f64();
    }

    /// After a batch of GPU steps: nodes behind their planes put back (up to half a cell), and
    /// the GPU told to take the state over again when any moved.
    #[cfg(feature = "gpu")]
    fn enforce_piece_contacts_after_batch(&mut self) {
        if self.piece_contacts.planes.is_empty() {
            return;
        }
        let max_move = (PIECE_BATCH_MOVE * self.lattice.cell) as f32;
        let i = &mut self.integrator;
        let planes = &self.piece_contacts.planes;
        self.piece_contact_nodes =
            piece_contact::enforce(planes, &self.rest, &mut i.u, &mut i.u_prev, PIECE_FRICTION, max_move);
        if self.piece_contact_nodes > 0
            && let Some(run) = &mut self.gpu
        {
            run.in_sync = false;
        }
    }

    /// Puts nodes of one piece that went behind their contact plane with another back on it.
    fn enforce_piece_contacts(&mut self) {
        if self.piece_contacts.planes.is_empty() {
            return;
        }
        let max_move = (MAX_PUSH_PER_STEP * self.lattice.cell) as f32;
        let i = &mut self.integrator;
        self.piece_contact_nodes = piece_contact::enforce(
            &self.piece_contacts.planes,
            &self.rest,
            &mut i.u,
            &mut i.u_prev,
            PIECE_FRICTION,
            max_move,
        );
    }

    /// Obstacles the tissue cannot enter from now on (replacing the previous ones): nodes found
    /// inside one after a time step are moved out and stopped (see [`Obstacle`]).
    pub fn set_obstacles(&mut self, obstacles: Vec<Obstacle>) {
        self.obstacles = obstacles;
    }

    /// Nodes in contact with an obstacle after the last time step of the last [`Self::advance`].
    pub fn contacts(&self) -> usize {
        self.contacts
    }

    /// Nodes on the table after the last time step of the last [`Self::advance`].
    pub fn table_contacts(&self) -> usize {
        self.table_contacts
    }

    /// The contact planes between pieces found at the start of the last [`Self::advance`].
    pub fn piece_contacts(&self) -> &PieceContacts {
        &self.piece_contacts
    }

    /// Nodes put back on a contact plane with another piece after the last time step.
    pub fn piece_contact_nodes(&self) -> usize {
        self.piece_contact_nodes
    }

    /// Moves the free nodes inside an obstacle toward its outside and stops them; returns how
    /// many. A node moves at most [`MAX_PUSH_PER_STEP`] cells per step: an obstacle that appears
    /// around nodes (a hull is reconstructed anew every frame) pushes them out over several steps
    /// instead of tearing their cells in one.
    fn resolve_contacts(&mut self) -> usize {
        let (rest, held, obstacles) = (&self.rest, &self.held, &self.obstacles);
        let max_push = (MAX_PUSH_PER_STEP * self.lattice.cell) as f32;
        // Sequential: a voxel lookup per node is cheaper than spreading a few thousand of them
        // over threads every step. Only the nodes a step moves (all but a frozen far field's).
        self.integrator.with_active(|active, u, u_prev| {
            let count = u.len();
            let mut push = |n: usize| -> usize {
                if held[n] {
                    return 0;
                }
                match obstacles.iter().find_map(|o| o.push_at(&(rest[n] + u[n]))) {
                    Some(push) => {
                        u[n] += push * (max_push / push.norm().max(max_push));
                        u_prev[n] = u[n];
                        1
                    }
                    None => 0,
                }
            };
            match active {
                Some(nodes) => nodes.iter().map(|&n| push(n as usize)).sum(),
                None => (0..count).map(push).sum(),
            }
        })
    }

    /// Each piece's volume, place and motion now, piece by piece: whether a piece cut free rests
    /// on the table (`lowest_above_table_m` about 0, `on_table` > 0, speeds about 0).
    pub fn piece_states(&self) -> Vec<PieceState> {
        let pieces = self.topology.pieces;
        let mut piece_of_node = vec![u32::MAX; self.integrator.u.len()];
        for (copy, &p) in self.topology.copies.iter().zip(&self.topology.piece_of) {
            for &n in &copy.nodes {
                piece_of_node[n as usize] = p;
            }
        }
        let dt = f64::from(self.integrator.dt);
        let mut flsm_v: Vec<Option<Vector3<f32>>> = vec![None; piece_of_node.len()];
        if let Some(part) = &self.flsm {
            for (k, &n) in part.node.iter().enumerate() {
                if part.is_active(k) {
                    flsm_v[n as usize] = Some(part.v[k]);
                }
            }
        }
        let top = self.params.table.map_or(0.0, |t| t.height);
        let volumes = self.topology.piece_volumes(&self.lattice);
        let mut states: Vec<PieceState> = volumes
            .iter()
            .map(|&volume_m3| PieceState {
                volume_m3,
                nodes: 0,
                centroid_m: [0.0; 3],
                lowest_above_table_m: f64::INFINITY,
                mean_speed_m_s: 0.0,
                max_speed_m_s: 0.0,
                held_nodes: 0,
                on_table: 0,
            })
            .collect();
        for (n, &p) in piece_of_node.iter().enumerate() {
            let Some(state) = states.get_mut(p as usize) else { continue };
            let x = (self.rest[n] + self.integrator.u[n]).cast::<f64>();
            let v = flsm_v[n].unwrap_or_else(|| (self.integrator.u[n] - self.integrator.u_prev[n]) / dt as f32);
            let speed = f64::from(v.norm());
            state.nodes += 1;
            for a in 0..3 {
                state.centroid_m[a] += x[a];
            }
            state.lowest_above_table_m = state.lowest_above_table_m.min(x.z - top);
            state.mean_speed_m_s += speed;
            state.max_speed_m_s = state.max_speed_m_s.max(speed);
            state.held_nodes += usize::from(self.held[n]);
            state.on_table += usize::from(self.params.table.is_some() && x.z - top < 1e-6);
        }
        for state in states.iter_mut().take(pieces) {
            let count = state.nodes.max(1) as f64;
            state.centroid_m = state.centroid_m.map(|c| c / count);
            state.mean_speed_m_s /= count;
        }
        states
    }

    /// Time the last [`Self::advance`] spent resolving contacts (obstacles and table) on the CPU,
    /// seconds; on the GPU they are part of its steps and this is 0.
    pub fn contact_seconds(&self) -> f64 {
        self.contact_s
    }

    /// The table the body rests on, if any.
    pub fn table(&self) -> Option<&Table> {
        self.params.table.as_ref()
    }

    /// The pieces' closed surfaces, deformed (world metres), piece by piece.
    pub fn surfaces(&self) -> Vec<TriMesh> {
        self.surfaces
            .iter()
            .map(|s| {
                let vertices = s.deformed(&self.integrator.u).iter().map(|p| p.cast::<f64>()).collect();
                TriMesh::new(vertices, s.rest.triangles.clone())
            })
            .collect()
    }

    /// The pieces' surfaces at rest, with their bindings.
    pub fn piece_surfaces(&self) -> &[PieceSurface] {
        &self.surfaces
    }

    /// Where node `n` of the cut lattice is, at rest and now, whether it is a virtual node, the
    /// material of the cell copies that hold it and whether an obstacle reaches it, for messages
    /// about a node that diverged; `None` for a node the cut lattice does not have.
    pub fn describe_node(&self, n: usize) -> Option<String> {
        let u = self.integrator.u.get(n)?;
        let rest = self.topology.rest(&self.lattice, n as u32);
        let now = rest + u.cast::<f64>();
        let shares: Vec<String> = self
            .topology
            .copies
            .iter()
            .filter(|c| c.nodes.contains(&(n as u32)))
            .map(|c| format!("{:.2}", f64::from(self.lattice.cells[c.parent as usize].fraction) * c.share))
            .collect();
        let kind = if n >= self.lattice.node_count() { "virtual node" } else { "node" };
        let mm = |p: Point3<f64>| format!("({:.1}, {:.1}, {:.1}) mm", p.x * 1e3, p.y * 1e3, p.z * 1e3);
        let inside = self.obstacles.iter().any(|o| o.push_at(&now.cast::<f32>()).is_some());
        Some(format!(
            "{kind} {n} at rest {}, now {}, in {} cell copies holding [{}] of a cell{}",
            mm(rest),
            mm(now),
            shares.len(),
            shares.join(", "),
            if inside { ", inside an obstacle" } else { "" }
        ))
    }

    /// Deformed position of every node of the cut lattice (lattice nodes first, then virtual ones).
    pub fn node_positions(&self) -> Vec<Point3<f32>> {
        (0..self.integrator.u.len())
            .map(|n| self.topology.rest(&self.lattice, n as u32).cast::<f32>() + self.integrator.u[n])
            .collect()
    }

    /// Displacements of every node of the cut lattice.
    pub fn displacements(&self) -> &[Vector3<f32>] {
        &self.integrator.u
    }

    /// The uncut lattice.
    pub fn lattice(&self) -> &Lattice {
        &self.lattice
    }

    /// The cuts so far.
    pub fn topology(&self) -> &CutTopology {
        &self.topology
    }

    /// Separate pieces of the body.
    pub fn pieces(&self) -> usize {
        self.topology.pieces
    }

    /// Whether each lattice node is held.
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }

    /// Time step, seconds.
    pub fn dt(&self) -> f64 {
        f64::from(self.integrator.dt)
    }

    /// Computed critical time step of the uncut body, seconds.
    pub fn dt_critical(&self) -> f64 {
        self.dt_critical
    }

    /// Simulated time, seconds.
    pub fn time(&self) -> f64 {
        self.integrator.time()
    }

    /// Kinetic energy, joules (FLSM nodes with the velocities FLSM keeps for them).
    pub fn kinetic_energy(&self) -> f64 {
        let mut energy = self.integrator.kinetic_energy();
        if let Some(part) = &self.flsm {
            for (p, &n) in part.node.iter().enumerate() {
                if part.is_active(p) {
                    energy += 0.5 * f64::from(self.integrator.mass[n as usize]) * f64::from(part.v[p].norm_squared());
                }
            }
        }
        energy
    }

    /// Copies dropped for holding too little material.
    pub fn dropped_copies(&self) -> usize {
        self.dropped
    }

    /// Elements currently inverted (J below the regularization threshold).
    pub fn inverted_cells(&self) -> usize {
        self.tled.inverted_cells()
    }

    /// Cells of the cut lattice (copies kept).
    pub fn cell_count(&self) -> usize {
        self.cut_lattice.cells.len()
    }
}

/// How far from another piece's surface a node gets a contact plane for the frame, in lattice
/// cells (more than a frame's motion).
pub const PIECE_REACH: f64 = 1.0;
/// How often the pieces' contact planes are found anew, seconds of simulated time (a frame at
/// 30 fps; between two searches the planes stay where they were found).
pub const PIECE_REFRESH_S: f64 = 1.0 / 30.0;
/// GPU steps between two enforcements of the pieces' contact planes while pieces touch. The GPU's
/// steps do not see the planes: a node goes on into the other piece for the whole batch and is
/// put back after it. Over a frame's 46 steps (the built-in organ at 5 mm) that put-back pumped
/// energy into a resected lobe leaning on the organ: it never came to rest (130 mm/s mean, nodes
/// at 1 m/s, 1.5 s after the cut; on the CPU, which enforces the planes every step, 0.02 mm/s).
/// 4 steps still left 6.6 mm/s, 2 brought it to rest (0.02 mm/s, as on the CPU). Each batch is
/// a submission and a read-back, so this costs round trips only while pieces touch.
#[cfg(feature = "gpu")]
const PIECE_CONTACT_GPU_STEPS: usize = 2;
/// How far the pieces' planes move a node after a batch of GPU steps, in lattice cells.
#[cfg(feature = "gpu")]
const PIECE_BATCH_MOVE: f64 = 0.5;

/// Where an advance started: displacements now and a step before, and the step count.
#[derive(Debug, Clone, Default)]
struct Rewind {
    u: Vec<Vector3<f32>>,
    u_prev: Vec<Vector3<f32>>,
    step: u64,
}

/// Share of a cell below which a copy whose node diverged is torn off (see [`CutSim::advance`]).
pub const TEAR_ON_DIVERGENCE: f64 = 0.25;

/// Slivers torn off in one [`CutSim::advance`] before a divergence is given up on.
pub const MAX_TEARS_PER_ADVANCE: usize = 4;

/// With a frozen far field, a node whose forces would take it from rest to the hybrid's
/// `rest_speed` within this time is not at rest, seconds.
const REST_TIME_S: f32 = 0.1;

/// Coulomb friction between pieces (tissue on tissue).
pub const PIECE_FRICTION: f32 = 0.5;

/// How far contact moves a node in one time step, in lattice cells.
pub const MAX_PUSH_PER_STEP: f64 = 0.05;

/// Least mass of a node of the cut lattice, as a share of a full cell's node mass (`ρ cell³ / 8`).
pub const MASS_FLOOR: f64 = 0.25;

/// The critical step of one free cell of the lattice's spacing (lumped masses, nothing held).
///
/// A body's highest eigenfrequency is at most the highest of its elements taken alone (Irons'
/// bound), and a cut approaches that bound: a copy joined to the rest by few nodes vibrates almost
/// on its own. A copy's mass and stiffness both scale with its material, so one full free cell
/// bounds every copy a cut can make; the uncut body's own estimate is lower than this bound by up
/// to the factor the safety margin leaves, which is why cut bodies need it.
fn lone_cell_dt(lattice: &Lattice, material: &Material, tled: TledParams) -> Result<f64, SimError> {
    let cell = Lattice::block(Point3::origin(), lattice.cell, [1, 1, 1]);
    let mut model = Tled::new(&cell, None, material, tled)?;
    let mass: Vec<f32> = cell.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
    let free = vec![[true; 3]; cell.node_count()];
    let zeros = vec![Vector3::zeros(); cell.node_count()];
    Ok(stability::estimate(&mut model, &mass, &free, &zeros, lattice.cell, 300, 1e-6).dt_critical)
}

fn speed_limit(material: &Material) -> f32 {
    (10.0 * material.wave_speed()) as f32
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;

    use super::*;
    use crate::body::box_sdf;

    /// The surface a blade edge along y sweeps going down through x = `x` from z0 to z1.
    pub(super) fn vertical_stroke(x: f64, z0: f64, z1: f64) -> SweptSurface {
        let edge: Vec<Point3<f64>> = (0..7).map(|k| Point3::new(0.0, -0.01 + 0.01 * k as f64, 0.0)).collect();
        SweptSurface::between(
            &edge,
            &Isometry3::translation(x, 0.0, z0),
            &Isometry3::translation(x, 0.0, z1),
            0.005,
            0.1,
        )
        .expect("surface")
    }

    /// A 1 x 1 cm "finger" of 2.5 mm voxels over the centre of a 4 x 4 x 3 cm block, its tip 6 mm
    /// below the block's top; and its voxel size.
    pub(super) fn finger() -> (Obstacle, f64) {
        let h = 0.0025;
        let dims = [24, 24, 24];
        let origin = Point3::new(-0.01, -0.01, 0.0);
        let occupied: Vec<bool> = (0..dims[0] * dims[1] * dims[2])
            .map(|g| {
                let (i, j, k) = (g % 24, (g / 24) % 24, g / 576);
                let p = origin + Vector3::new(i as f64, j as f64, k as f64) * h;
                (p.x - 0.02).abs() < 0.005 && (p.y - 0.02).abs() < 0.005 && p.z > 0.024 && k < 23
            })
            .collect();
        (Obstacle::from_occupancy(origin, h, dims, &occupied).expect("finger"), h)
    }

    #[test]
    fn a_finger_pressed_into_the_top_pushes_the_tissue_down_instead_of_passing_through() {
        // A 4 x 4 x 3 cm block on the table (bottom held), and a 1 x 1 cm "finger" of 2.5 mm
        // voxels whose tip reaches 6 mm below the block's top at its centre.
        let size = Vector3::new(0.04, 0.04, 0.03);
        let lattice = Lattice::block(Point3::origin(), 0.005, [8, 8, 6]);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let mut sim =
            CutSim::new(lattice, &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim");
        sim.advance(0.3).expect("stable");
        let top_before = sim.node_positions().iter().map(|p| p.z).fold(f32::MIN, f32::max);
        let (finger, h) = finger();
        sim.set_obstacles(vec![finger.clone()]);
        sim.advance(0.3).expect("stable with contact");
        assert!(sim.contacts() > 0, "the finger touches the tissue");
        let nodes = sim.node_positions();
        // At rest against the finger a node may sit just inside its boundary voxel (the push per
        // step is capped, and the tissue presses back), never deeper.
        let deepest = nodes.iter().filter_map(|p| finger.push_at(p)).map(|d| d.norm()).fold(0.0f32, f32::max);
        assert!(deepest <= 1.01 * h as f32, "a node {deepest} m inside the finger");
        // The node under the finger's centre is pushed down by the intrusion (the finger's
        // lowest voxel ends 5.3 mm below the sagged top) less at most a voxel (2.5 mm).
        let centre = nodes
            .iter()
            .filter(|p| (p.x - 0.02).abs() < 1e-3 && (p.y - 0.02).abs() < 1e-3)
            .map(|p| p.z)
            .fold(f32::MIN, f32::max);
        assert!(centre < top_before - 0.0028, "pressed: {centre} vs {top_before}");
        // Far from the finger the top stays where it was (within the sag's settling).
        let corner = nodes.iter().filter(|p| p.x < 1e-3 && p.y < 1e-3).map(|p| p.z).fold(f32::MIN, f32::max);
        assert!(corner > top_before - 0.003, "{corner} vs {top_before}");
        // Taken away, the tissue springs back.
        sim.set_obstacles(Vec::new());
        sim.advance(0.5).expect("stable");
        let back = sim
            .node_positions()
            .iter()
            .filter(|p| (p.x - 0.02).abs() < 2e-3 && (p.y - 0.02).abs() < 2e-3)
            .map(|p| p.z)
            .fold(f32::MIN, f32::max);
        assert!(back > top_before - 0.0015, "recovered to {back} of {top_before}");
    }

    #[test]
    fn a_bar_cut_through_drops_its_free_end_and_keeps_every_piece_closed() {
        // A 6 x 3 x 3 cm bar of 1 cm cells held at x = 0, under gravity; stiff enough (50 kPa) that
        // it sags only millimetres before the cut.
        let size = Vector3::new(0.06, 0.03, 0.03);
        let lattice = Lattice::block(Point3::origin(), 0.01, [6, 3, 3]);
        let material = Material::from_young_poisson(5.0e4, 0.45, 1000.0);
        let params = CutSimParams { samples_per_cell: 4, ..CutSimParams::default() };
        let mut sim = CutSim::new(lattice, &box_sdf(size), material, |p| p.x < 1e-9, params).expect("sim");
        assert!(sim.dt() < sim.dt_critical());
        let uncut_volume = sim.piece_surfaces()[0].rest.volume();
        sim.advance(0.2).expect("stable");
        let sag_before: f64 = {
            let s = sim.surfaces();
            s[0].vertices.iter().map(|p| p.z).fold(f64::MAX, f64::min)
        };
        // Half the height first: a slit, still one piece.
        let first = sim.cut(&vertical_stroke(0.037, 0.05, 0.015)).expect("cut");
        assert!(first.new_edges > 0);
        assert_eq!(first.pieces, 1);
        sim.advance(0.05).expect("stable");
        // Through the rest: two pieces.
        let second = sim.cut(&vertical_stroke(0.037, 0.02, -0.01)).expect("cut");
        assert_eq!(second.pieces, 2);
        let surfaces = sim.surfaces();
        assert_eq!(surfaces.len(), 2);
        for s in &surfaces {
            assert!(s.is_closed());
            assert_eq!(s.orientation_conflicts(), 0);
        }
        let rest_volume: f64 = sim.piece_surfaces().iter().map(|s| s.rest.volume()).sum();
        assert!((rest_volume - uncut_volume).abs() < 0.01 * uncut_volume, "{rest_volume} vs {uncut_volume}");
        // No jump when the cut lands: the surfaces just after it are where they were just before.
        let lowest = |s: &TriMesh| s.vertices.iter().map(|p| p.z).fold(f64::MAX, f64::min);
        let right = |m: &TriMesh| m.bounds().map_or(f64::MIN, |b| b.1.x);
        let free = surfaces.iter().max_by(|a, b| right(a).total_cmp(&right(b))).expect("pieces");
        assert!(lowest(free) > sag_before - 0.005, "no jump: {} vs {sag_before}", lowest(free));
        // The free end falls away; the held part stays.
        let before = lowest(free);
        sim.advance(0.1).expect("stable");
        let surfaces = sim.surfaces();
        let free_after = surfaces.iter().map(lowest).fold(f64::MAX, f64::min);
        let fall = before - free_after;
        // Free fall over 0.1 s is 49 mm; damping at 40/s slows it.
        assert!(fall > 0.01, "the cut-off end fell {fall} m");
        assert!(sim.kinetic_energy().is_finite());
        // A repeated stroke through the same cut changes nothing.
        let again = sim.cut(&vertical_stroke(0.037, 0.05, -0.01)).expect("cut");
        assert_eq!(again.pieces, 2);
    }

    /// Hybrid settings with an operational region of `radius` metres.
    fn hybrid(radius: f64) -> CutSimParams {
        CutSimParams { hybrid: Some(HybridParams { radius, ..HybridParams::default() }), ..CutSimParams::default() }
    }

    /// Centres of the TLED cells, rest metres.
    fn tled_centres(sim: &CutSim) -> Vec<Point3<f64>> {
        let cell = sim.lattice().cell;
        (0..sim.lattice().cells.len())
            .filter(|&c| sim.cell_tled[c])
            .map(|c| sim.lattice().rest[sim.lattice().cells[c].nodes[0] as usize] + Vector3::repeat(cell / 2.0))
            .collect()
    }

    #[test]
    fn the_operational_region_follows_the_tool_and_gives_cells_at_rest_back_to_flsm() {
        // A 6 x 2 x 2 cm block of 5 mm cells on the table; the tool (a few points) at one end,
        // then at the other.
        let size = Vector3::new(0.06, 0.02, 0.02);
        let lattice = Lattice::block(Point3::origin(), 0.005, [12, 4, 4]);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let mut sim = CutSim::new(lattice, &box_sdf(size), material, |p| p.z < 1e-9, hybrid(0.008)).expect("sim");
        // No tool, nothing cut: all FLSM.
        assert_eq!(sim.tled_cells(), 0);
        assert!(sim.node_roles().iter().all(|&r| r == NodeRole::Flsm));
        sim.advance(0.2).expect("stable");
        let tool_at = |x: f64| -> Vec<Point3<f64>> { (0..5).map(|k| Point3::new(x, 0.005 * k as f64, 0.02)).collect() };
        sim.set_tool(&tool_at(0.005));
        sim.advance(0.05).expect("stable");
        let centres = tled_centres(&sim);
        assert!(!centres.is_empty(), "cells near the tool are TLED");
        assert!(centres.iter().all(|c| c.x < 0.005 + 0.008 + 0.0025 + 1e-9), "only near the tool: {centres:?}");
        let roles = sim.node_roles();
        for role in [NodeRole::Tled, NodeRole::Flsm, NodeRole::Interface] {
            assert!(roles.contains(&role), "{role:?} among the roles");
        }
        // The tool moves to the other end: the cells there become TLED at once; the first ones
        // return to FLSM once the tool has left and they have come to rest.
        sim.set_tool(&tool_at(0.055));
        sim.advance(0.05).expect("stable");
        assert!(tled_centres(&sim).iter().any(|c| c.x > 0.045), "TLED at the new place");
        sim.set_tool(&[]);
        sim.advance(1.0).expect("stable");
        sim.advance(0.05).expect("stable");
        assert_eq!(sim.tled_cells(), 0, "all back to FLSM at rest");
        assert!(sim.region_changes() >= 3);
        // At rest: below the energy of the whole block (24 g) at the rest speed.
        let rest_speed = f64::from(HybridParams::default().rest_speed);
        assert!(sim.kinetic_energy() < 0.5 * 0.024 * rest_speed * rest_speed, "at rest: {}", sim.kinetic_energy());
    }

    #[test]
    fn a_hybrid_body_sags_like_the_all_tled_one_where_the_tool_is() {
        // The same block under gravity, bottom held, with the tool over its middle: the TLED cells
        // under the tool sag as in the all-TLED model. FLSM is not the material (its stiffness
        // follows its step), but matched to the material (see `HybridParams::resolve`), with the
        // interface pull matched too, the sag agrees within 10%.
        let size = Vector3::new(0.06, 0.02, 0.02);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let top_middle = |sim: &CutSim| -> f32 {
            let nodes = sim.node_positions();
            let i = nodes
                .iter()
                .position(|p| (p.x - 0.03).abs() < 1e-4 && (p.y - 0.01).abs() < 1e-4 && (p.z - 0.02).abs() < 0.004)
                .expect("node");
            0.02 - nodes[i].z
        };
        let block = || Lattice::block(Point3::origin(), 0.005, [12, 4, 4]);
        let mut all =
            CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim");
        all.advance(1.0).expect("stable");
        let mut hyb = CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, hybrid(0.012)).expect("sim");
        hyb.set_tool(&[Point3::new(0.03, 0.01, 0.025)]);
        hyb.advance(1.0).expect("stable");
        assert!(hyb.tled_cells() > 0 && hyb.tled_cells() < hyb.lattice().cells.len());
        let (a, h) = (top_middle(&all), top_middle(&hyb));
        assert!(a > 1e-4, "it sags: {a}");
        assert!((h - a).abs() < 0.1 * a, "hybrid {h} m vs TLED {a} m");
        // All FLSM (no tool): the block sags as the TLED block does, within 10%.
        let mut flsm = CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, hybrid(0.012)).expect("sim");
        flsm.advance(1.0).expect("stable");
        assert_eq!(flsm.tled_cells(), 0);
        let f = top_middle(&flsm);
        assert!((f - a).abs() < 0.1 * a, "FLSM {f} m vs TLED {a} m");
        // An operational region that holds every cell is the all-TLED model, step for step.
        let mut whole = CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, hybrid(1.0)).expect("sim");
        whole.set_tool(&[Point3::new(0.03, 0.01, 0.025)]);
        let mut again =
            CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim");
        let steps = whole.advance(0.1).expect("stable");
        again.advance(steps as f64 * again.dt() * 0.999).expect("stable");
        assert_eq!(whole.displacements(), again.displacements());
    }

    #[test]
    fn a_frozen_far_field_settles_with_the_body_then_sleeps_and_wakes_where_the_tool_goes() {
        // The block under gravity, bottom held, tool over its middle: it starts all TLED, so it
        // sags as the all-TLED block does; once at rest the cells away from the tool sleep (their
        // nodes held), and the sag under the tool stays the all-TLED one.
        let size = Vector3::new(0.06, 0.02, 0.02);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let block = || Lattice::block(Point3::origin(), 0.005, [12, 4, 4]);
        let frozen = || CutSimParams {
            hybrid: Some(HybridParams { radius: 0.012, far_field: FarField::Frozen, ..HybridParams::default() }),
            ..CutSimParams::default()
        };
        let mut all =
            CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim");
        all.advance(1.5).expect("stable");
        let mut sim = CutSim::new(block(), &box_sdf(size), material, |p| p.z < 1e-9, frozen()).expect("sim");
        assert_eq!(sim.tled_cells(), sim.lattice().cells.len(), "all TLED before it settles");
        assert!(sim.hybrid_steps().is_none(), "no FLSM");
        let tool = |x: f64| vec![Point3::new(x, 0.01, 0.025)];
        sim.set_tool(&tool(0.03));
        // Frame by frame (the region is chosen once an advance).
        for _ in 0..45 {
            sim.advance(1.0 / 30.0).expect("stable");
        }
        let cells = sim.lattice().cells.len();
        assert!(sim.tled_cells() > 0 && sim.tled_cells() < cells / 2, "{} of {cells} awake", sim.tled_cells());
        let (a, f) = (all.displacements(), sim.displacements());
        let sag = a.iter().map(|d| d.z).fold(0.0f32, f32::min);
        let worst = a.iter().zip(f).map(|(a, f)| (a - f).norm()).fold(0.0f32, f32::max);
        eprintln!("{} of {cells} cells awake; sag {sag} m, largest difference {worst} m", sim.tled_cells());
        assert!(sag < -1e-4 && worst < 0.02 * -sag, "sag {sag} m, largest difference {worst} m");
        // Held: a sleeping node does not move over a further step.
        let before = sim.displacements().to_vec();
        sim.advance(0.05).expect("stable");
        let far = (0..sim.lattice().node_count()).filter(|&n| sim.lattice().rest[n].x < 0.005);
        assert!(far.clone().count() > 0 && far.clone().all(|n| sim.displacements()[n] == before[n]));
        // The tool moves to the end: its cells wake.
        sim.set_tool(&tool(0.0025));
        sim.advance(0.05).expect("stable");
        assert!(tled_centres(&sim).iter().any(|c| c.x < 0.005), "awake where the tool is");
    }

    #[test]
    fn a_node_is_described_by_where_it_is_and_what_holds_it() {
        // A 2 x 2 x 3 cm block of 1 cm cells: its corner node is in one whole cell, an inner node
        // in eight; the finger reaches its top corner at (2, 2, 3) cm.
        let size = Vector3::new(0.02, 0.02, 0.03);
        let lattice = Lattice::block(Point3::origin(), 0.01, [2, 2, 3]);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let mut sim =
            CutSim::new(lattice, &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim");
        let corner = sim.describe_node(0).expect("node 0");
        assert_eq!(
            corner,
            "node 0 at rest (0.0, 0.0, 0.0) mm, now (0.0, 0.0, 0.0) mm, in 1 cell copies holding [1.00] of a cell"
        );
        let centre = (0..sim.lattice().node_count())
            .find(|&n| (sim.lattice().rest[n] - Point3::new(0.01, 0.01, 0.01)).norm() < 1e-9)
            .expect("centre");
        assert!(sim.describe_node(centre).expect("centre").contains("in 8 cell copies"));
        assert!(sim.describe_node(sim.lattice().node_count()).is_none());
        let top = (0..sim.lattice().node_count())
            .find(|&n| (sim.lattice().rest[n] - Point3::new(0.02, 0.02, 0.03)).norm() < 1e-9)
            .expect("top");
        let (finger, _) = finger();
        sim.set_obstacles(vec![finger]);
        assert!(sim.describe_node(top).expect("top").ends_with(", inside an obstacle"));
    }

    #[test]
    fn a_finger_pressed_into_a_sleeping_far_field_wakes_it_and_pushes_the_tissue_down() {
        // The finger test's block with a far field that sleeps and the tool at a far corner: once
        // settled the middle of the block sleeps; the finger pressed into it there wakes its
        // cells and pushes them as in the all-TLED test, instead of passing through them.
        let size = Vector3::new(0.04, 0.04, 0.03);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let params = CutSimParams {
            hybrid: Some(HybridParams { radius: 0.008, far_field: FarField::Frozen, ..HybridParams::default() }),
            ..CutSimParams::default()
        };
        let lattice = Lattice::block(Point3::origin(), 0.005, [8, 8, 6]);
        let mut sim = CutSim::new(lattice, &box_sdf(size), material, |p| p.z < 1e-9, params).expect("sim");
        sim.set_tool(&[Point3::new(0.0, 0.0, 0.03)]);
        for _ in 0..30 {
            sim.advance(1.0 / 30.0).expect("stable");
        }
        let centre_cell = |sim: &CutSim| {
            tled_centres(sim).iter().any(|c| (c.x - 0.0225).abs() < 0.004 && (c.y - 0.0225).abs() < 0.004)
        };
        assert!(!centre_cell(&sim), "the middle sleeps before the finger comes");
        let top_before = sim.node_positions().iter().map(|p| p.z).fold(f32::MIN, f32::max);
        let (finger, h) = finger();
        sim.set_obstacles(vec![finger.clone()]);
        for _ in 0..9 {
            sim.advance(1.0 / 30.0).expect("stable with contact");
        }
        assert!(centre_cell(&sim), "the finger woke the cells it reaches");
        let nodes = sim.node_positions();
        let deepest = nodes.iter().filter_map(|p| finger.push_at(p)).map(|d| d.norm()).fold(0.0f32, f32::max);
        assert!(deepest <= 1.01 * h as f32, "a node {deepest} m inside the finger");
        let centre = nodes
            .iter()
            .filter(|p| (p.x - 0.02).abs() < 1e-3 && (p.y - 0.02).abs() < 1e-3)
            .map(|p| p.z)
            .fold(f32::MIN, f32::max);
        assert!(centre < top_before - 0.0028, "pressed: {centre} vs {top_before}");
    }

    #[test]
    fn a_hybrid_bar_cut_through_drops_its_free_end_moved_by_flsm() {
        // As the all-TLED bar test, with an operational region of 1 cm around the cut: the free
        // end beyond it is FLSM, its regions rebuilt from the cut lattice, so it falls away.
        let size = Vector3::new(0.06, 0.03, 0.03);
        let lattice = Lattice::block(Point3::origin(), 0.01, [6, 3, 3]);
        let material = Material::from_young_poisson(5.0e4, 0.45, 1000.0);
        let params = CutSimParams { samples_per_cell: 4, ..hybrid(0.01) };
        let mut sim = CutSim::new(lattice, &box_sdf(size), material, |p| p.x < 1e-9, params).expect("sim");
        sim.advance(0.2).expect("stable");
        let stroke = vertical_stroke(0.037, 0.05, -0.01);
        sim.set_tool(&stroke.vertices);
        let cut = sim.cut(&stroke).expect("cut");
        assert_eq!(cut.pieces, 2);
        // Cut cells and their neighbours are TLED; the far end is not.
        let roles = sim.node_roles();
        let far: Vec<usize> = (0..sim.lattice().node_count()).filter(|&n| sim.lattice().rest[n].x > 0.055).collect();
        assert!(far.iter().all(|&n| roles[n] == NodeRole::Flsm), "the free end is FLSM");
        let lowest_far = |sim: &CutSim| far.iter().map(|&n| sim.node_positions()[n].z).fold(f32::MAX, f32::min);
        let before = lowest_far(&sim);
        sim.set_tool(&[]);
        sim.advance(0.1).expect("stable");
        let fall = before - lowest_far(&sim);
        assert!(fall > 0.01, "the cut-off end fell {fall} m");
        for s in sim.surfaces() {
            assert!(s.is_closed());
        }
    }
    #[test]
    fn a_free_hybrid_body_falls_as_the_tled_one_does() {
        // Nothing held: TLED, FLSM and the hybrid must all fall as a damped point mass does
        // (x = (g/c) (t − (1 − e^{−ct})/c), 18.5 mm in 0.1 s at c = 40/s). The interface pull
        // must not drag: with a goal fixed over the FLSM step, the hybrid fell 6.5 mm.
        let size = Vector3::new(0.06, 0.03, 0.03);
        let material = Material::from_young_poisson(5.0e4, 0.45, 1000.0);
        let (g, c, t) = (9.81, 40.0, 0.1);
        let expected = (g / c) * (t - (1.0 - f64::exp(-c * t)) / c);
        for (params, tool) in [(CutSimParams::default(), false), (hybrid(0.01), false), (hybrid(0.01), true)] {
            let lattice = Lattice::block(Point3::origin(), 0.01, [6, 3, 3]);
            let mut sim = CutSim::new(lattice, &box_sdf(size), material, |_| false, params).expect("sim");
            if tool {
                sim.set_tool(&[Point3::new(0.03, 0.015, 0.03)]);
            }
            let steps = sim.advance(t).expect("stable");
            let elapsed = steps as f64 * sim.dt();
            let expected = expected + (g / c) * (elapsed - t);
            let fell = -f64::from(sim.node_positions().iter().map(|p| p.z).fold(f32::MAX, f32::min));
            let kind = (sim.tled_cells(), sim.lattice().cells.len());
            assert!(
                (fell - expected).abs() < 0.05 * expected,
                "{kind:?} TLED cells: fell {fell} m, expected {expected}"
            );
        }
    }

    /// An L-shaped body of 5 mm cells on a table at z = 0: a 3 x 2 x 3 cm column held at its
    /// foot and a 3 x 2 x 1.5 cm arm reaching out from its top, 1.5 cm above the table.
    pub(super) fn l_shape(table: Option<Table>) -> CutSim {
        let h = 0.005;
        let dims = [12, 4, 6];
        let inside = |x: f64, z: f64| x < 0.03 || z > 0.015;
        let fractions: Vec<f32> = (0..dims[0] * dims[1] * dims[2])
            .map(|g| {
                let (i, k) = (g % dims[0], g / (dims[0] * dims[1]));
                if inside((i as f64 + 0.5) * h, (k as f64 + 0.5) * h) { 1.0 } else { 0.0 }
            })
            .collect();
        let lattice = Lattice::from_fractions(Point3::origin(), h, dims, &fractions, 0.5);
        let column = box_sdf(Vector3::new(0.03, 0.02, 0.03));
        let arm = box_sdf(Vector3::new(0.06, 0.02, 0.015));
        let signed = move |p: &Point3<f64>| column(p).min(arm(&(p - Vector3::new(0.0, 0.0, 0.015))));
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let params = CutSimParams { table, ..CutSimParams::default() };
        CutSim::new(lattice, &signed, material, |p| p.z < 1e-9, params).expect("sim")
    }

    #[test]
    fn a_piece_cut_off_above_the_table_falls_onto_it_and_rests_there() {
        let table = Table { height: 0.0, friction: 0.5 };
        let mut landed = Vec::new();
        for with_table in [true, false] {
            let mut sim = l_shape(with_table.then_some(table));
            sim.advance(0.2).expect("stable");
            let outcome = sim.cut(&vertical_stroke(0.0455, 0.05, -0.02)).expect("cut");
            assert_eq!(outcome.pieces, 2);
            let tip = sim.topology().copies_of(sim.lattice().cells.len() - 1).start;
            let at_cut = sim.node_positions()[sim.topology().copies[tip].nodes[0] as usize].z;
            assert!(!with_table || at_cut > 0.003, "the arm's far end hangs above the table when cut off: {at_cut} m");
            sim.advance(0.6).expect("stable");
            let topology = sim.topology();
            let free = topology.piece_of[topology.copies_of(sim.lattice().cells.len() - 1).start];
            let nodes: Vec<u32> = topology
                .copies
                .iter()
                .zip(&topology.piece_of)
                .filter(|(_, p)| **p == free)
                .flat_map(|(c, _)| c.nodes)
                .collect();
            let before = sim.node_positions();
            sim.advance(0.05).expect("stable");
            let after = sim.node_positions();
            let lowest = nodes.iter().map(|&n| after[n as usize].z).fold(f32::INFINITY, f32::min);
            let speed =
                nodes.iter().map(|&n| (after[n as usize] - before[n as usize]).norm()).fold(0.0f32, f32::max) / 0.05;
            let drift = nodes
                .iter()
                .map(|&n| (after[n as usize].x - sim.topology().rest(sim.lattice(), n).x as f32).abs())
                .fold(0.0f32, f32::max);
            landed.push((lowest, speed, drift, sim.table_contacts()));
        }
        let (lowest, speed, drift, contacts) = landed[0];
        // On the table: its lowest node within 0.2 mm of the top, still (under 5 mm/s), where it
        // fell (within a centimetre of where it was cut off), resting on nodes in contact.
        assert!(lowest.abs() < 2e-4, "lowest node at {lowest} m");
        assert!(speed < 5e-3, "still moving at {speed} m/s");
        assert!(drift < 0.01, "slid {drift} m");
        assert!(contacts > 0);
        // Without the table it falls through where the table would be.
        assert!(landed[1].0 < -0.1, "without a table the piece is at {} m", landed[1].0);
    }

    #[test]
    fn a_slab_cut_off_the_top_rests_on_the_rest_of_the_block_instead_of_sinking_through_it() {
        // A 4 x 3 x 3 cm block of 5 mm cells on the table, nothing held, its top 1.2 cm sliced off
        // by a blade edge (along y) moved flat through it at z = 1.8 cm.
        let lattice = Lattice::block(Point3::origin(), 0.005, [8, 6, 6]);
        let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
        let table = Table { height: 0.0, friction: 0.5 };
        let params = CutSimParams { table: Some(table), ..CutSimParams::default() };
        let size = Vector3::new(0.04, 0.03, 0.03);
        let mut sim = CutSim::new(lattice, &box_sdf(size), material, |_| false, params).expect("sim");
        sim.advance(0.2).expect("stable");
        let edge: Vec<Point3<f64>> = (0..7).map(|k| Point3::new(0.0, -0.01 + 0.01 * k as f64, 0.0)).collect();
        let slice = SweptSurface::between(
            &edge,
            &Isometry3::translation(-0.01, 0.0, 0.018),
            &Isometry3::translation(0.05, 0.0, 0.018),
            0.0025,
            0.1,
        )
        .expect("surface");
        assert_eq!(sim.cut(&slice).expect("cut").pieces, 2);
        // Frame by frame, as `hullcut run` advances it: the contacts are found once a frame.
        for _ in 0..15 {
            sim.advance(1.0 / 30.0).expect("stable");
        }
        let states = sim.piece_states();
        let top = states.iter().max_by(|a, b| a.centroid_m[2].total_cmp(&b.centroid_m[2])).expect("two pieces");
        // It rests where the cut left it (its lowest nodes, virtual ones at the node plane 3 mm
        // under the cut, 12.7 mm up: the block below sags under it), not on the table (0 without
        // the pieces' contact: it sinks through), and it is still.
        assert!(
            top.lowest_above_table_m > 0.009,
            "the slab's lowest node {} m above the table",
            top.lowest_above_table_m
        );
        assert!(top.max_speed_m_s < 0.01, "{top:?}");
        assert!(sim.piece_contacts().skipped_surfaces == 0 && !sim.piece_contacts().planes.is_empty());
    }
}
