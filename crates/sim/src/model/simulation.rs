//! A scenario turned into a running simulation: lattice, boundary conditions, loads, the hybrid
//! TLED/FLSM split, time stepping, probes and reactions.

use nalgebra::{Point3, Vector3};

use crate::dynamics::{Divergence, Integrator, Prescribed};
use crate::embed::Embedding;
use crate::flsm::{Flsm, FlsmParams};
use crate::mesh::TriMesh;
use crate::operational::HybridSteps;
use crate::scenario::{BoxSpec, MAX_LATTICE_CELLS, MIN_DT, Scenario};
use crate::stability::{self, StabilityLimit};
use crate::tled::{Integration, Tled, TledParams};
use crate::{Lattice, Material, SimError};

#[cfg(feature = "gpu")]
mod on_gpu;

/// What simulates a node (the seed paper's Fig. 1 colours: TLED green, FLSM yellow, interface white).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum NodeRole {
    /// Moved by TLED only.
    Tled,
    /// Moved by FLSM.
    Flsm,
    /// A TLED node that also belongs to an FLSM cell: pulled toward its FLSM goal by β (g − x).
    Interface,
}

impl NodeRole {
    /// RGBA colour of the role in recordings: TLED green, FLSM yellow, interface white.
    pub fn color(self) -> [u8; 4] {
        match self {
            NodeRole::Tled => [40, 200, 60, 255],
            NodeRole::Flsm => [240, 210, 40, 255],
            NodeRole::Interface => [255, 255, 255, 255],
        }
    }
}

/// Most TLED steps a scenario's run may take: [`Simulation::from_scenario`] refuses a `run.duration`
/// that needs more ([`Simulation::advances_for`]), so that a tiny time step cannot make a run go on
/// for days.
pub const MAX_STEPS: u64 = 10_000_000;

/// Power-iteration budget for the stability estimate.
const STABILITY_ITERATIONS: usize = 300;
/// Stop the power iteration when the Rayleigh quotient changes by less than this.
const STABILITY_TOLERANCE: f64 = 1e-6;

/// A simulation ready to step.
#[derive(Debug)]
pub struct Simulation {
    /// The lattice.
    pub lattice: Lattice,
    /// Material.
    pub material: Material,
    /// Role of each node.
    pub roles: Vec<NodeRole>,
    /// The explicit integrator (displacements live here).
    pub integrator: Integrator,
    /// Stability estimate of the TLED part (of the whole lattice when there is no TLED part).
    pub stability: StabilityLimit,
    /// Dilatational-wave estimate `L / c` of the critical step, for comparison, seconds.
    pub dt_wave: f64,
    /// Whether the time step exceeds the computed critical step (a user-given `dt`).
    pub dt_above_critical: bool,
    /// Names of the reaction groups (faces).
    pub reaction_names: Vec<String>,
    /// Warnings raised while building (e.g. a mesh that is not closed).
    pub warnings: Vec<String>,
    tled: Tled,
    flsm: Option<FlsmPart>,
    rest: Vec<Vector3<f32>>,
    f_ext: Vec<Vector3<f32>>,
    f_applied: Vec<Vector3<f32>>,
    probes: Vec<([f64; 3], Option<Located>)>,
    surface: TriMesh,
    embedding: Embedding,
    surface_now: Vec<Point3<f32>>,
    inverted_max: usize,
    /// The GPU backend, once [`Simulation::use_gpu`] chose it.
    #[cfg(feature = "gpu")]
    gpu: Option<on_gpu::GpuPart>,
}

/// A material point located in the lattice: its cell and trilinear weights.
type Located = (usize, [f64; 8]);

#[derive(Debug)]
struct FlsmPart {
    flsm: Flsm,
    active: Vec<bool>,
    interface: Vec<u32>,
    /// FLSM's step and stiffness and the interface pull.
    steps: HybridSteps,
    x: Vec<Vector3<f32>>,
    v: Vec<Vector3<f32>>,
    goals: Vec<Vector3<f32>>,
}

fn invalid(key: &str, message: impl Into<String>) -> SimError {
    SimError::Invalid { key: key.to_owned(), message: message.into() }
}

fn axis_of(name: &str, key: &str) -> Result<usize, SimError> {
    match name {
        "x" => Ok(0),
        "y" => Ok(1),
        "z" => Ok(2),
        _ => {
            let shown: String = name.chars().take(16).collect();
            let more = if shown.len() < name.len() { "…" } else { "" };
            Err(invalid(key, format!("unknown component `{shown}{more}` (expected x, y or z)")))
        }
    }
}

/// Nodes on a lattice face (`x-` ... `z+`): rest coordinate within a tenth of a cell of the extreme.
pub(crate) fn face_nodes(lattice: &Lattice, face: &str, key: &str) -> Result<Vec<u32>, SimError> {
    let (axis, upper) = match face {
        "x-" => (0, false),
        "x+" => (0, true),
        "y-" => (1, false),
        "y+" => (1, true),
        "z-" => (2, false),
        "z+" => (2, true),
        _ => return Err(invalid(key, format!("unknown face `{face}` (expected x-, x+, y-, y+, z- or z+)"))),
    };
    let coords = lattice.rest.iter().map(|p| p[axis]);
    let extreme = if upper { coords.fold(f64::MIN, f64::max) } else { coords.fold(f64::MAX, f64::min) };
    let tol = 0.1 * lattice.cell;
    Ok((0..lattice.node_count() as u32).filter(|&n| (lattice.rest[n as usize][axis] - extreme).abs() < tol).collect())
}

pub(crate) fn box_nodes(lattice: &Lattice, b: &BoxSpec) -> Vec<u32> {
    let tol = 1e-9;
    (0..lattice.node_count() as u32)
        .filter(|&n| {
            let p = lattice.rest[n as usize];
            (0..3).all(|k| p[k] >= b.min[k] - tol && p[k] <= b.max[k] + tol)
        })
        .collect()
}

/// The lattice of a scenario's body, with any warnings, and the body's surface mesh. Grids of more
/// than [`MAX_LATTICE_CELLS`] cells are refused before they are allocated.
pub fn build_lattice(s: &Scenario) -> Result<(Lattice, Vec<String>, TriMesh), SimError> {
    let body = scenario_body(s)?;
    let params = crate::body::VoxelizeParams { max_cells: MAX_LATTICE_CELLS, ..Default::default() };
    let key = if s.body.mesh.is_some() { "body.mesh" } else { "body" };
    let vox = crate::body::voxelize(&body, s.body.cell, &params).map_err(|e| invalid(key, e.to_string()))?;
    Ok((vox.lattice, vox.warnings, body.surface()))
}

/// The body a scenario's `[body]` describes (a mesh is read here).
pub fn scenario_body(s: &Scenario) -> Result<crate::body::Body, SimError> {
    let b = &s.body;
    if !(b.cell.is_finite() && b.cell > 0.0) {
        return Err(invalid("body.cell", format!("must be a positive length in metres, got {}", b.cell)));
    }
    if !(b.scale.is_finite() && b.scale > 0.0) {
        return Err(invalid("body.scale", format!("must be a positive factor, got {}", b.scale)));
    }
    match (b.shape.as_deref(), &b.mesh) {
        (Some("box"), None) => {
            let size = b.size.ok_or_else(|| invalid("body.size", "a box needs `size = [x, y, z]`"))?;
            if size.iter().any(|&x| !(x.is_finite() && x > 0.0)) {
                return Err(invalid("body.size", format!("must be positive, got {size:?}")));
            }
            Ok(crate::body::Body::Box { size: Vector3::from(size) })
        }
        (Some("organ"), None) => Ok(crate::body::Body::Organ { scale: b.scale }),
        (None, Some(path)) => {
            crate::body::Body::load_mesh(path, b.scale).map_err(|e| invalid("body.mesh", e.to_string()))
        }
        (Some(other), None) => Err(invalid(
            "body.shape",
            format!("unknown shape `{other}` (expected \"box\" or \"organ\", or give `mesh`)"),
        )),
        (Some(_), Some(_)) => Err(invalid("body", "give either `shape` or `mesh`, not both")),
        (None, None) => Err(invalid("body", "missing `shape` or `mesh`")),
    }
}

/// Cells simulated by TLED: all for ratio 1, none for ratio 0, else those nearest the operational
/// centre (or within its radius).
fn tled_cells(lattice: &Lattice, s: &Scenario) -> Result<Vec<usize>, SimError> {
    let h = &s.hybrid;
    if !(0.0..=1.0).contains(&h.ratio) {
        return Err(invalid("hybrid.ratio", format!("must lie in [0, 1], got {}", h.ratio)));
    }
    let centre_of = |c: usize| -> Point3<f64> {
        let ijk = lattice.cells[c].ijk;
        lattice.origin + Vector3::new(ijk[0] as f64 + 0.5, ijk[1] as f64 + 0.5, ijk[2] as f64 + 0.5) * lattice.cell
    };
    let centroid = {
        let sum: Vector3<f64> = lattice.rest.iter().map(|p| p.coords).sum();
        Point3::from(sum / lattice.node_count().max(1) as f64)
    };
    let centre = h.operational.map_or(centroid, |o| Point3::from(o.center));
    let n = lattice.cells.len();
    if let Some(radius) = h.operational.and_then(|o| o.radius) {
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(invalid("hybrid.operational.radius", format!("must be >= 0, got {radius}")));
        }
        return Ok((0..n).filter(|&c| (centre_of(c) - centre).norm() <= radius).collect());
    }
    if h.ratio >= 1.0 {
        return Ok((0..n).collect());
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| (centre_of(a) - centre).norm().total_cmp(&(centre_of(b) - centre).norm()).then(a.cmp(&b)));
    let target = (h.ratio * lattice.node_count() as f64).round() as usize;
    let mut is_tled_node = vec![false; lattice.node_count()];
    let mut count = 0;
    let mut cells = Vec::new();
    for c in order {
        if count >= target {
            break;
        }
        cells.push(c);
        for &node in &lattice.cells[c].nodes {
            if !is_tled_node[node as usize] {
                is_tled_node[node as usize] = true;
                count += 1;
            }
        }
    }
    cells.sort_unstable();
    Ok(cells)
}

impl Simulation {
    /// Builds the simulation a scenario describes. The scenario is checked first
    /// ([`Scenario::validate`]); a stable step that cannot be computed (not finite and positive, or
    /// below [`MIN_DT`]) and a run of more than [`MAX_STEPS`] TLED steps are errors naming the key.
    pub fn from_scenario(s: &Scenario) -> Result<Self, SimError> {
        s.validate()?;
        let (lattice, mut warnings, surface) = build_lattice(s)?;
        let embedding = Embedding::new(&lattice, &surface.vertices).map_err(|e| invalid("body", e.to_string()))?;
        if embedding.clamped > 0 {
            warnings.push(format!(
                "{} surface vertices lie more than a cell outside the lattice and were moved up to {:.2e} m",
                embedding.clamped, embedding.max_shift
            ));
        }
        let material = Material { lambda: s.material.lambda, mu: s.material.mu, density: s.material.density };
        material.validate()?;
        let integration = match s.tled.integration.as_str() {
            "one-point" => Integration::OnePoint,
            "gauss8" => Integration::Gauss8,
            other => {
                return Err(invalid(
                    "tled.integration",
                    format!("unknown `{other}` (expected \"one-point\" or \"gauss8\")"),
                ));
            }
        };
        let params = TledParams { integration, hourglass: s.tled.hourglass };
        let n = lattice.node_count();
        let masses64 = lattice.lumped_masses(material.density);
        let mass: Vec<f32> = masses64.iter().map(|&m| m as f32).collect();

        // Boundary conditions, with contradictions detected per component.
        let mut prescribed: Vec<Option<(f32, f32, usize)>> = vec![None; 3 * n];
        for (bi, b) in s.boundary.iter().enumerate() {
            let key = format!("boundary[{bi}]");
            let mut nodes: Vec<u32> = Vec::new();
            for f in &b.faces {
                nodes.extend(face_nodes(&lattice, f, &format!("{key}.faces"))?);
            }
            if let Some(r) = &b.region {
                nodes.extend(box_nodes(&lattice, r));
            }
            if b.faces.is_empty() && b.region.is_none() {
                return Err(invalid(&key, "needs `faces` or `box`"));
            }
            if nodes.is_empty() {
                return Err(invalid(&key, "selects no lattice node"));
            }
            if !(b.ramp.is_finite() && b.ramp >= 0.0) {
                return Err(invalid(&format!("{key}.ramp"), format!("must be >= 0 seconds, got {}", b.ramp)));
            }
            let mut comps: Vec<(usize, f32)> = Vec::new();
            for c in &b.fix {
                comps.push((axis_of(c, &format!("{key}.fix"))?, 0.0));
            }
            let mut displaced = [true; 3];
            if let Some(list) = &b.components {
                if b.displace.is_none() {
                    return Err(invalid(&format!("{key}.components"), "needs `displace`"));
                }
                if list.is_empty() {
                    return Err(invalid(&format!("{key}.components"), "lists no component (omit it for all three)"));
                }
                displaced = [false; 3];
                for c in list {
                    let k = axis_of(c, &format!("{key}.components"))?;
                    if displaced[k] {
                        return Err(invalid(&format!("{key}.components"), format!("lists `{c}` twice")));
                    }
                    displaced[k] = true;
                }
            }
            if let Some(d) = b.displace {
                if d.iter().any(|x| !x.is_finite()) {
                    return Err(invalid(&format!("{key}.displace"), "must be finite"));
                }
                for (k, &v) in d.iter().enumerate().filter(|&(k, _)| displaced[k]) {
                    if comps.iter().any(|&(a, _)| a == k) {
                        return Err(invalid(
                            &key,
                            format!("component {} is both fixed and displaced", ["x", "y", "z"][k]),
                        ));
                    }
                    comps.push((k, v as f32));
                }
            }
            if comps.is_empty() {
                return Err(invalid(&key, "needs `fix` or `displace`"));
            }
            for &node in &nodes {
                for &(k, target) in &comps {
                    let slot = &mut prescribed[3 * node as usize + k];
                    match *slot {
                        Some((t, _, other)) if other != bi && (t - target).abs() > 1e-9 => {
                            return Err(invalid(
                                &key,
                                format!(
                                    "contradicts boundary[{other}]: node at {:?} has its {} component prescribed to {t} m there and {target} m here",
                                    lattice.rest[node as usize].coords.as_slice(),
                                    ["x", "y", "z"][k]
                                ),
                            ));
                        }
                        _ => *slot = Some((target, b.ramp as f32, bi)),
                    }
                }
            }
        }
        // Reaction groups: one bit each (at most `MAX_REACTIONS`, checked by `validate`).
        let mut group_of = vec![0u32; 3 * n];
        for (gi, face) in s.report.reaction.iter().enumerate() {
            for node in face_nodes(&lattice, face, "report.reaction")? {
                for k in 0..3 {
                    group_of[3 * node as usize + k] |= 1 << gi;
                }
            }
        }
        let prescribed: Vec<Prescribed> = prescribed
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                p.map(|(target, ramp, _)| Prescribed {
                    node: (i / 3) as u32,
                    axis: (i % 3) as u8,
                    target,
                    ramp,
                    groups: group_of[i],
                })
            })
            .collect();

        // Loads and gravity.
        let mut f_applied = vec![Vector3::<f32>::zeros(); n];
        let g = Vector3::from(s.run.gravity);
        for (i, m) in masses64.iter().enumerate() {
            f_applied[i] += (g * *m).cast::<f32>();
        }
        for (li, l) in s.load.iter().enumerate() {
            let nodes = box_nodes(&lattice, &l.region);
            if nodes.is_empty() {
                return Err(invalid(&format!("load[{li}].box"), "selects no lattice node"));
            }
            let share = (Vector3::from(l.force) / nodes.len() as f64).cast::<f32>();
            for node in nodes {
                f_applied[node as usize] += share;
            }
        }

        // Hybrid split.
        let cells = tled_cells(&lattice, s)?;
        let mut in_tled = vec![false; n];
        let mut in_flsm_cell = vec![false; n];
        let mut is_tled_cell = vec![false; lattice.cells.len()];
        for &c in &cells {
            is_tled_cell[c] = true;
            for &node in &lattice.cells[c].nodes {
                in_tled[node as usize] = true;
            }
        }
        for (c, cell) in lattice.cells.iter().enumerate() {
            if !is_tled_cell[c] {
                for &node in &cell.nodes {
                    in_flsm_cell[node as usize] = true;
                }
            }
        }
        let roles: Vec<NodeRole> = (0..n)
            .map(|i| match (in_tled[i], in_flsm_cell[i]) {
                (true, true) => NodeRole::Interface,
                (true, false) => NodeRole::Tled,
                _ => NodeRole::Flsm,
            })
            .collect();
        let mut tled = Tled::new(&lattice, Some(&cells), &material, params)?;

        // Stability of the TLED part (or of an all-TLED model when FLSM does everything).
        let free: Vec<[bool; 3]> = {
            let mut f = vec![[true; 3]; n];
            for p in &prescribed {
                f[p.node as usize][p.axis as usize] = false;
            }
            f
        };
        let zeros = vec![Vector3::zeros(); n];
        // The TLED part, or an all-TLED model when FLSM does everything.
        let mut all_tled = if cells.is_empty() { Some(Tled::new(&lattice, None, &material, params)?) } else { None };
        let model = match all_tled.as_mut() {
            Some(all) => all,
            None => &mut tled,
        };
        let mut stability =
            stability::estimate(model, &mass, &free, &zeros, lattice.cell, STABILITY_ITERATIONS, STABILITY_TOLERANCE);
        if !stability.dt_critical.is_finite() {
            // Every component is prescribed: nothing can vibrate, so any step is stable. Step at the
            // free body's limit anyway, so the prescribed ramps are followed finely.
            let all_free = vec![[true; 3]; n];
            stability = stability::estimate(
                model,
                &mass,
                &all_free,
                &zeros,
                lattice.cell,
                STABILITY_ITERATIONS,
                STABILITY_TOLERANCE,
            );
        }
        if !(stability.dt_critical.is_finite() && stability.dt_critical > 0.0) {
            return Err(invalid(
                "material",
                format!(
                    "the stable time step could not be computed (ω_max = {} rad/s, critical step {} s): check \
                     material.lambda, material.mu and material.density against body.cell = {} m",
                    stability.omega_max, stability.dt_critical, lattice.cell
                ),
            ));
        }
        let dt_wave = lattice.cell / material.wave_speed();
        let (dt, dt_above_critical) = match s.dt() {
            None => {
                let dt = s.run.safety * stability.dt_critical;
                if !(dt.is_finite() && dt >= MIN_DT) {
                    return Err(invalid(
                        "material",
                        format!(
                            "the stable step run.safety × {:e} s = {dt:e} s is below the smallest time step \
                             {MIN_DT:e} s: material.lambda and material.mu are too stiff, or material.density \
                             too low, for body.cell = {} m",
                            stability.dt_critical, lattice.cell
                        ),
                    ));
                }
                (dt, false)
            }
            Some(dt) => {
                let above = dt > stability.dt_critical;
                if above {
                    warnings.push(format!(
                        "run.dt = {dt:e} s exceeds the computed critical step {:e} s: the run will likely be reported unstable",
                        stability.dt_critical
                    ));
                }
                (dt, above)
            }
        };
        let speed_limit = 10.0 * material.wave_speed() as f32;
        let integrator =
            Integrator::new(mass, prescribed, s.report.reaction.len(), s.run.damping as f32, dt as f32, speed_limit);

        let flsm = if roles.iter().any(|&r| r != NodeRole::Tled) && cells.len() < lattice.cells.len() {
            let given = s.hybrid.substeps.map(|n| (n, s.flsm.alpha.unwrap_or(crate::scenario::ALPHA_DEFAULT)));
            let steps =
                crate::match_flsm(dt, lattice.cell, &material, given, s.flsm.alpha, s.hybrid.beta.map(|b| b as f32));
            let fp = FlsmParams { w: s.flsm.w, alpha: steps.alpha, region_damping: s.flsm.region_damping };
            let flsm = Flsm::new(&lattice, &masses64, fp).map_err(|e| invalid("flsm", e.to_string()))?;
            let active: Vec<bool> = roles.iter().map(|&r| r == NodeRole::Flsm).collect();
            let interface = (0..n as u32).filter(|&i| roles[i as usize] == NodeRole::Interface).collect();
            Some(FlsmPart {
                flsm,
                active,
                interface,
                steps,
                x: vec![Vector3::zeros(); n],
                v: vec![Vector3::zeros(); n],
                goals: vec![Vector3::zeros(); n],
            })
        } else {
            None
        };
        let mut integrator = integrator;
        if let Some(part) = &flsm {
            for &i in &part.interface {
                integrator.implicit_stiffness[i as usize] = part.steps.beta;
            }
            integrator.frozen.clone_from(&part.active);
        }
        let probes = s.report.probes.iter().map(|p| (*p, lattice.locate(&Point3::from(*p)))).collect();
        let rest = lattice.rest.iter().map(|p| p.coords.cast::<f32>()).collect();
        let sim = Self {
            material,
            roles,
            integrator,
            stability,
            dt_wave,
            dt_above_critical,
            reaction_names: s.report.reaction.clone(),
            warnings,
            tled,
            flsm,
            rest,
            f_ext: vec![Vector3::zeros(); n],
            f_applied,
            probes,
            surface,
            embedding,
            surface_now: Vec::new(),
            inverted_max: 0,
            #[cfg(feature = "gpu")]
            gpu: None,
            lattice,
        };
        sim.advances_for(s.run.duration)?;
        Ok(sim)
    }

    /// Calls of [`Simulation::advance`] that cover `duration` seconds of simulated time (the last
    /// may overshoot it by less than one call). An error names `run.duration` when `duration` is
    /// not a positive finite number or when the run would take more than [`MAX_STEPS`] TLED steps.
    pub fn advances_for(&self, duration: f64) -> Result<u64, SimError> {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(invalid("run.duration", format!("must be a positive number of seconds, got {duration}")));
        }
        let dt = self.dt();
        let substeps = self.steps_per_advance().max(1) as f64;
        let per_advance = dt * substeps;
        if !(per_advance.is_finite() && per_advance > 0.0) {
            return Err(invalid("run.dt", format!("the time step {dt:e} s is not a positive number of seconds")));
        }
        let advances = (duration / per_advance).ceil().max(1.0);
        let steps = advances * substeps;
        if !(steps.is_finite() && steps <= MAX_STEPS as f64) {
            return Err(invalid(
                "run.duration",
                format!(
                    "{duration} s at a time step of {dt:e} s is {steps:.3e} TLED steps, above the limit of \
                     {MAX_STEPS}: shorten run.duration, or lengthen the step (run.dt; with dt = \"auto\", a \
                     coarser body.cell or a softer or denser material)"
                ),
            ));
        }
        Ok(advances as u64)
    }

    /// Time step, seconds.
    pub fn dt(&self) -> f64 {
        f64::from(self.integrator.dt)
    }

    /// Simulated time, seconds.
    pub fn time(&self) -> f64 {
        self.integrator.time()
    }

    /// TLED steps per call of [`Simulation::advance`].
    pub fn steps_per_advance(&self) -> usize {
        self.flsm.as_ref().map_or(1, |f| f.steps.substeps)
    }

    /// The hybrid's FLSM step, FLSM stiffness and interface pull (`None`: all TLED).
    pub fn hybrid_steps(&self) -> Option<HybridSteps> {
        self.flsm.as_ref().map(|f| f.steps)
    }

    /// Cells simulated by TLED.
    pub fn tled_cells(&self) -> usize {
        self.tled.cell_count()
    }

    /// Most cells regularized (inverted) in any step so far.
    pub fn inverted_cells_max(&self) -> usize {
        self.inverted_max
    }

    /// Advances by one step (TLED only) or one FLSM step of `substeps` TLED sub-steps (hybrid).
    pub fn advance(&mut self) -> Result<(), Divergence> {
        self.advance_by(1)
    }

    /// Advances by `n` calls' worth of [`Simulation::advance`]; on the GPU (see `use_gpu`, with
    /// the `gpu` feature) as one batch, the state read back only at its end.
    pub fn advance_by(&mut self, n: u64) -> Result<(), Divergence> {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            return self.gpu_steps(n);
        }
        self.cpu_steps(n)
    }

    /// `n` calls' worth of [`Simulation::advance`] on the CPU.
    fn cpu_steps(&mut self, n: u64) -> Result<(), Divergence> {
        for _ in 0..n {
            self.advance_cpu()?;
        }
        Ok(())
    }

    fn advance_cpu(&mut self) -> Result<(), Divergence> {
        let Some(part) = self.flsm.as_mut() else {
            return self.tled_step(false);
        };
        // FLSM step over the whole lattice, moving only FLSM nodes.
        let dt_f = self.integrator.dt * part.steps.substeps as f32;
        for i in 0..self.rest.len() {
            part.x[i] = self.rest[i] + self.integrator.u[i];
        }
        part.flsm.compute_goals(&part.x, &mut part.goals);
        part.flsm.step(&mut part.x, &mut part.v, &self.f_applied, dt_f, Some(&part.active));
        // Prescribed components of FLSM nodes follow their prescription, at rest.
        let t_end = (self.integrator.time() + f64::from(dt_f)) as f32;
        for p in &self.integrator.prescribed {
            let (i, k) = (p.node as usize, p.axis as usize);
            if part.active[i] {
                part.x[i][k] = self.rest[i][k] + p.target * crate::dynamics::ramp(t_end, p.ramp);
                part.v[i][k] = 0.0;
            }
        }
        for i in 0..self.rest.len() {
            if part.active[i] {
                let u = part.x[i] - self.rest[i];
                self.integrator.u[i] = u;
                self.integrator.u_prev[i] = u - part.v[i] * self.integrator.dt;
            }
        }
        for _ in 0..part.steps.substeps {
            self.tled_step(true)?;
        }
        Ok(())
    }

    /// One TLED step; in the hybrid, FLSM nodes are held and interface nodes pulled to their goals.
    fn tled_step(&mut self, hybrid: bool) -> Result<(), Divergence> {
        self.tled.element_pass(&self.integrator.u);
        self.inverted_max = self.inverted_max.max(self.tled.inverted_cells());
        self.f_ext.copy_from_slice(&self.f_applied);
        if hybrid && let Some(part) = &self.flsm {
            // β (g − x) with x = rest + u: the constant part here, −β u implicitly. FLSM nodes are
            // frozen in the integrator during the sub-steps.
            for &i in &part.interface {
                let i = i as usize;
                self.f_ext[i] += (part.goals[i] - self.rest[i]) * part.steps.beta;
            }
        }
        let tled = &self.tled;
        self.integrator.advance_with(|i| tled.node_force(i), &self.f_ext)?;
        Ok(())
    }

    /// Displacement of each probe's material point (`None` outside the lattice), metres.
    pub fn probe_displacements(&self) -> Vec<([f64; 3], Option<[f64; 3]>)> {
        self.probes
            .iter()
            .map(|(at, loc)| {
                let d = loc.map(|(cell, w)| {
                    let nodes = self.lattice.cells[cell].nodes;
                    let mut u = Vector3::<f64>::zeros();
                    for c in 0..8 {
                        u += self.integrator.u[nodes[c] as usize].cast::<f64>() * w[c];
                    }
                    [u.x, u.y, u.z]
                });
                (*at, d)
            })
            .collect()
    }

    /// The embedded surface at the current state: vertex positions (metres) and triangles.
    pub fn surface(&mut self) -> (&[Point3<f32>], &[[u32; 3]]) {
        let x = self.positions();
        self.embedding.positions_into(&self.lattice, &x, &mut self.surface_now);
        (&self.surface_now, &self.surface.triangles)
    }

    /// Current node positions (rest + displacement), metres.
    pub fn positions(&self) -> Vec<Vector3<f32>> {
        self.rest.iter().zip(&self.integrator.u).map(|(r, u)| r + u).collect()
    }
}
