//! The simulation scenario file (TOML; DESIGN.md "Simulation scenario file", extended as documented
//! in docs/scenario.md). Unknown keys are errors.
//!
//! Every value is checked where it is read ([`Scenario::parse`] runs [`Scenario::validate`]): numbers
//! must be finite and inside the ranges the constants of this module document, and lists and the
//! lattice the body makes are bounded, so that no file makes the simulator allocate or loop without
//! limit. Errors name the file, the key and the allowed range.

use std::io::Read as _;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::SimError;

/// Largest scenario file read, bytes.
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;
/// Smallest lattice spacing `body.cell`, metres.
pub const MIN_CELL_M: f64 = 1e-5;
/// Largest lattice spacing `body.cell`, metres.
pub const MAX_CELL_M: f64 = 10.0;
/// Largest box edge `body.size`, metres.
pub const MAX_SIZE_M: f64 = 1e3;
/// Largest mesh scale `body.scale`.
pub const MAX_SCALE: f64 = 1e6;
/// Most lattice cells a body may make (the grid of `body.size` or the organ at `body.cell`; a mesh's
/// grid is checked when it is voxelized). Also the voxelizer's limit in [`crate::Simulation`].
pub const MAX_LATTICE_CELLS: usize = 20_000_000;
/// Largest magnitude of a position or displacement component (probes, boxes, the operational centre
/// and radius, prescribed displacements), metres.
pub const MAX_POSITION_M: f64 = 1e6;
/// Largest hourglass coefficient `tled.hourglass` (typical values are 0.05 to 0.15).
pub const MAX_HOURGLASS: f64 = 1.0;
/// Largest interface pull `hybrid.beta`, N/m.
pub const MAX_BETA: f64 = 1e12;
/// Longest simulated time `run.duration` (and `report.interval`, `[[boundary]] ramp`), seconds.
pub const MAX_DURATION_S: f64 = 1e4;
/// Smallest time step, seconds: `run.dt` when given, and the step `dt = "auto"` computes.
pub const MIN_DT: f64 = 1e-9;
/// Largest time step `run.dt`, seconds.
pub const MAX_DT: f64 = 1.0;
/// Smallest share of the critical step `run.safety` (largest: 1).
pub const MIN_SAFETY: f64 = 0.01;
/// Largest mass-proportional damping `run.damping`, 1/s.
pub const MAX_DAMPING: f64 = 1e6;
/// Largest magnitude of a gravity component `run.gravity`, m/s² (a thousand g).
pub const MAX_GRAVITY: f64 = 1e4;
/// Largest magnitude of a load's force component, newtons.
pub const MAX_FORCE_N: f64 = 1e9;
/// Most `[[boundary]]` entries.
pub const MAX_BOUNDARIES: usize = 256;
/// Most `[[load]]` entries.
pub const MAX_LOADS: usize = 256;
/// Most faces in `report.reaction` (one bit each in a node's reaction groups).
pub const MAX_REACTIONS: usize = 32;
/// Most points in `report.probes`.
pub const MAX_PROBES: usize = 1000;
/// Most points of the blade's cutting edge `cut.edge`.
pub const MAX_EDGE_POINTS: usize = 64;
/// Most keys of the blade's path `cut.path`.
pub const MAX_PATH_KEYS: usize = 1000;
/// Largest Coulomb friction `cut.table.friction`.
pub const MAX_FRICTION: f64 = 10.0;

/// A whole scenario.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// The body and its lattice.
    pub body: BodySpec,
    /// Material.
    #[serde(default)]
    pub material: MaterialSpec,
    /// TLED settings.
    #[serde(default)]
    pub tled: TledSpec,
    /// FLSM settings.
    #[serde(default)]
    pub flsm: FlsmSpec,
    /// Hybrid split.
    #[serde(default)]
    pub hybrid: HybridSpec,
    /// Boundary conditions.
    #[serde(default)]
    pub boundary: Vec<BoundarySpec>,
    /// Time integration.
    #[serde(default)]
    pub run: RunSpec,
    /// Point or distributed loads.
    #[serde(default)]
    pub load: Vec<LoadSpec>,
    /// What to report.
    #[serde(default)]
    pub report: ReportSpec,
    /// A blade that moves through the body and cuts it (the run is then a [`crate::CutSim`]).
    pub cut: Option<CutSpec>,
}

/// `[cut]`: a blade's cutting edge moved along a path; every `report.interval` the surface it
/// swept since the last is cut into the body, as `hullcut run` cuts with each frame set's pose.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CutSpec {
    /// The cutting edge at offset zero, world metres, 2 to [`MAX_EDGE_POINTS`] points.
    pub edge: Vec<[f64; 3]>,
    /// Where the edge is: its offset from `edge` at simulated times, linear between keys, held
    /// before the first and after the last; times increasing. 1 to [`MAX_PATH_KEYS`] keys.
    pub path: Vec<PathKey>,
    /// Cells within this distance of the blade's sweep (and the cut cells) run TLED, the others
    /// `far_field`; absent: every cell TLED.
    pub operational_radius: Option<f64>,
    /// With `operational_radius`: `"frozen"` (cells at rest sleep; the default) or `"flsm"` (FLSM,
    /// matched to the material unless `hybrid.substeps` says otherwise).
    pub far_field: Option<String>,
    /// The table the body rests on, at its lowest layer of nodes; absent: no table.
    pub table: Option<TableSpec>,
}

/// A key of `cut.path`: `{ time = s, offset = [x, y, z] }`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathKey {
    /// Simulated time, seconds.
    pub time: f64,
    /// The edge's offset from `cut.edge`, metres.
    pub offset: [f64; 3],
}

/// `[cut.table]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableSpec {
    /// Coulomb friction between the body and the table, 0 to [`MAX_FRICTION`].
    #[serde(default = "friction_default")]
    pub friction: f64,
}

fn friction_default() -> f64 {
    0.5
}

/// `[body]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// `"box"` (with `size`) or `"organ"` (the built-in liver-like organ); absent with `mesh`.
    pub shape: Option<String>,
    /// Box size, metres; the box spans `[0, size]`.
    pub size: Option<[f64; 3]>,
    /// A closed triangle mesh (PLY or OBJ), relative to the scenario file.
    pub mesh: Option<PathBuf>,
    /// Scale applied to the mesh's coordinates to get metres; for the organ, its size factor
    /// ([`crate::body::LARGE_ORGAN_SCALE`] for an adult liver's size).
    #[serde(default = "one")]
    pub scale: f64,
    /// Lattice spacing, metres.
    pub cell: f64,
}

fn one() -> f64 {
    1.0
}

/// `[material]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// λ, Pa.
    pub lambda: f64,
    /// μ, Pa.
    pub mu: f64,
    /// ρ, kg/m³.
    pub density: f64,
}

impl Default for MaterialSpec {
    fn default() -> Self {
        let m = crate::Material::default();
        Self { lambda: m.lambda, mu: m.mu, density: m.density }
    }
}

/// `[tled]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TledSpec {
    /// `"one-point"` or `"gauss8"`.
    #[serde(default = "one_point")]
    pub integration: String,
    /// Hourglass coefficient.
    #[serde(default = "hourglass")]
    pub hourglass: f32,
}

fn one_point() -> String {
    "one-point".to_owned()
}
fn hourglass() -> f32 {
    0.075
}

impl Default for TledSpec {
    fn default() -> Self {
        Self { integration: one_point(), hourglass: hourglass() }
    }
}

/// `[flsm]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlsmSpec {
    /// Region half-width, cells, 1 to [`crate::flsm::MAX_W`].
    #[serde(default = "w_default")]
    pub w: usize,
    /// Goal stiffness; default: matched to the material with the FLSM step (see
    /// [`crate::match_flsm`]), or 0.8 when `hybrid.substeps` is given.
    pub alpha: Option<f32>,
    /// Per-region damping.
    #[serde(default = "region_damping_default")]
    pub region_damping: f32,
}

fn w_default() -> usize {
    1
}
/// `flsm.alpha` when `hybrid.substeps` is given and `flsm.alpha` is not.
pub const ALPHA_DEFAULT: f32 = 0.8;
fn region_damping_default() -> f32 {
    0.1
}

impl Default for FlsmSpec {
    fn default() -> Self {
        Self { w: w_default(), alpha: None, region_damping: region_damping_default() }
    }
}

/// `[hybrid]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridSpec {
    /// Share of nodes simulated by TLED (nearest the operational centre); 1 = all TLED.
    #[serde(default = "one")]
    pub ratio: f64,
    /// Operational region; default centre: the body's centroid, radius from `ratio`.
    pub operational: Option<OperationalSpec>,
    /// Interface pull, N/m; default `2.5 E cell` (see [`crate::match_flsm`]).
    pub beta: Option<f64>,
    /// TLED steps per FLSM step, 1 to [`crate::MAX_SUBSTEPS`]; default: the FLSM step matched to
    /// the material.
    pub substeps: Option<usize>,
}

impl Default for HybridSpec {
    fn default() -> Self {
        Self { ratio: 1.0, operational: None, beta: None, substeps: None }
    }
}

/// `operational = { center = [..], radius = r }`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OperationalSpec {
    /// Centre, metres.
    pub center: [f64; 3],
    /// Radius, metres; when given, cells whose centre lies within it are TLED (overrides `ratio`).
    pub radius: Option<f64>,
}

/// An axis-aligned box `{ min = [..], max = [..] }`, metres.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

/// `[[boundary]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundarySpec {
    /// Lattice faces: `x-`, `x+`, `y-`, `y+`, `z-`, `z+` (nodes on the lattice's extreme planes).
    #[serde(default)]
    pub faces: Vec<String>,
    /// Or the nodes whose rest position lies in this box.
    #[serde(rename = "box")]
    pub region: Option<BoxSpec>,
    /// Components held at their rest value.
    #[serde(default)]
    pub fix: Vec<String>,
    /// Prescribed displacement, metres (reached at the end of `ramp`): of all three components, or
    /// of those in `components`.
    pub displace: Option<[f64; 3]>,
    /// With `displace`: the components it prescribes (`"x"`, `"y"`, `"z"`); the others stay free.
    /// All three when absent.
    pub components: Option<Vec<String>>,
    /// Ramp duration, seconds.
    #[serde(default)]
    pub ramp: f64,
}

/// `[run]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// Simulated time, seconds.
    #[serde(default = "duration_default")]
    pub duration: f64,
    /// `"auto"` or seconds, [`MIN_DT`] to [`MAX_DT`].
    #[serde(default)]
    pub dt: DtSpec,
    /// Share of the computed critical step used by `dt = "auto"`, [`MIN_SAFETY`] to 1.
    #[serde(default = "safety_default")]
    pub safety: f64,
    /// Mass-proportional damping, 1/s.
    #[serde(default = "damping_default")]
    pub damping: f64,
    /// Gravity, m/s².
    #[serde(default)]
    pub gravity: [f64; 3],
}

fn duration_default() -> f64 {
    1.0
}
fn safety_default() -> f64 {
    0.8
}
fn damping_default() -> f64 {
    50.0
}

impl Default for RunSpec {
    fn default() -> Self {
        Self {
            duration: duration_default(),
            dt: DtSpec::default(),
            safety: safety_default(),
            damping: damping_default(),
            gravity: [0.0; 3],
        }
    }
}

/// `dt = "auto"` or a number of seconds.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Default)]
#[serde(untagged)]
pub enum DtSpec {
    /// Safety × computed critical step.
    #[default]
    #[serde(skip)]
    Auto,
    /// Given, seconds.
    Seconds(f64),
    /// The string form (must be "auto").
    #[serde(skip_serializing)]
    Text(AutoWord),
}

/// The word `auto`.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum AutoWord {
    /// `"auto"`.
    Auto,
}

/// `[[load]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// Nodes in this box share the force.
    #[serde(rename = "box")]
    pub region: BoxSpec,
    /// Total force, newtons.
    pub force: [f64; 3],
}

/// `[report]`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReportSpec {
    /// Faces whose constraint reaction is reported.
    #[serde(default)]
    pub reaction: Vec<String>,
    /// Material points (rest positions) whose displacement is reported.
    #[serde(default)]
    pub probes: Vec<[f64; 3]>,
    /// Report and log every this many seconds of simulated time (0: only at the end).
    #[serde(default)]
    pub interval: f64,
}

impl Scenario {
    /// Parses scenario text and checks every value ([`Scenario::validate`]); `file` names it in
    /// errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, SimError> {
        let s: Self = toml::from_str(text)
            .map_err(|e| SimError::Scenario { file: file.to_owned(), message: e.to_string().trim_end().to_owned() })?;
        s.validate().map_err(|e| SimError::Scenario { file: file.to_owned(), message: e.to_string() })?;
        Ok(s)
    }

    /// Reads a scenario file (at most [`MAX_SCENARIO_BYTES`]); relative mesh paths are resolved
    /// against its folder.
    pub fn load(path: &Path) -> Result<Self, SimError> {
        let file = path.display().to_string();
        let read_error = |e: std::io::Error| SimError::Scenario { file: file.clone(), message: e.to_string() };
        let mut text = String::new();
        std::fs::File::open(path)
            .map_err(read_error)?
            .take(MAX_SCENARIO_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(read_error)?;
        if text.len() as u64 > MAX_SCENARIO_BYTES {
            return Err(SimError::Scenario {
                file,
                message: format!("larger than {MAX_SCENARIO_BYTES} bytes: not a scenario file"),
            });
        }
        let mut s = Self::parse(&text, &file)?;
        if let (Some(mesh), Some(dir)) = (&s.body.mesh, path.parent())
            && mesh.is_relative()
        {
            s.body.mesh = Some(dir.join(mesh));
        }
        Ok(s)
    }

    /// The time step setting.
    pub fn dt(&self) -> Option<f64> {
        match self.run.dt {
            DtSpec::Seconds(s) => Some(s),
            DtSpec::Auto | DtSpec::Text(_) => None,
        }
    }

    /// Checks every value against its documented range (the constants of this module,
    /// [`crate::Material::validate`], [`crate::flsm::MAX_W`]): numbers finite, lists and the body's
    /// lattice bounded. The error names the key and the allowed range. [`Scenario::parse`] and
    /// [`crate::Simulation::from_scenario`] run it; what needs the lattice (faces that select no
    /// node, contradicting constraints) is checked when the simulation is built.
    pub fn validate(&self) -> Result<(), SimError> {
        self.validate_body()?;
        let m = &self.material;
        crate::Material { lambda: m.lambda, mu: m.mu, density: m.density }.validate()?;
        let t = &self.tled;
        if !matches!(t.integration.as_str(), "one-point" | "gauss8") {
            return Err(invalid(
                "tled.integration",
                format!("unknown `{}` (expected \"one-point\" or \"gauss8\")", t.integration),
            ));
        }
        in_range("tled.hourglass", f64::from(t.hourglass), 0.0, MAX_HOURGLASS, "")?;
        let f = &self.flsm;
        if !(1..=crate::flsm::MAX_W).contains(&f.w) {
            return Err(invalid("flsm.w", format!("must be 1 to {} cells, got {}", crate::flsm::MAX_W, f.w)));
        }
        if let Some(alpha) = f.alpha
            && !(alpha.is_finite() && alpha > 0.0 && alpha <= 1.0)
        {
            return Err(invalid("flsm.alpha", format!("must lie in (0, 1], got {alpha}")));
        }
        in_range("flsm.region_damping", f64::from(f.region_damping), 0.0, 1.0, "")?;
        self.validate_hybrid()?;
        self.validate_constraints()?;
        self.validate_run()?;
        self.validate_report()?;
        self.validate_cut()
    }

    fn validate_body(&self) -> Result<(), SimError> {
        let b = &self.body;
        in_range("body.cell", b.cell, MIN_CELL_M, MAX_CELL_M, " m")?;
        if let Some(size) = b.size {
            for x in size {
                positive("body.size", x, MAX_SIZE_M, " m")?;
            }
        }
        positive("body.scale", b.scale, MAX_SCALE, "")?;
        // The grid the voxelizer will make for a box or the organ (a mesh's is checked when it is
        // read), estimated before anything is allocated.
        let extent = match (b.shape.as_deref(), b.size, &b.mesh) {
            (Some("box"), Some(size), None) => Some(size),
            (Some("organ"), _, None) => {
                let (lo, hi) = crate::Body::Organ { scale: b.scale }.bounds();
                Some([hi.x - lo.x, hi.y - lo.y, hi.z - lo.z])
            }
            _ => None,
        };
        if let Some(extent) = extent {
            let cells: f64 = extent.iter().map(|e| (e / b.cell).ceil().max(1.0)).product();
            if !(cells.is_finite() && cells <= MAX_LATTICE_CELLS as f64) {
                return Err(invalid(
                    "body.cell",
                    format!(
                        "a lattice of {} m cells over {extent:?} m has about {cells:.3e} cells, above the limit of \
                         {MAX_LATTICE_CELLS} (give a larger cell or a smaller body)",
                        b.cell
                    ),
                ));
            }
        }
        Ok(())
    }

    fn validate_hybrid(&self) -> Result<(), SimError> {
        let h = &self.hybrid;
        in_range("hybrid.ratio", h.ratio, 0.0, 1.0, "")?;
        if let Some(o) = &h.operational {
            position("hybrid.operational.center", &o.center)?;
            if let Some(radius) = o.radius {
                in_range("hybrid.operational.radius", radius, 0.0, MAX_POSITION_M, " m")?;
            }
        }
        if let Some(beta) = h.beta {
            in_range("hybrid.beta", beta, 0.0, MAX_BETA, " N/m")?;
        }
        if let Some(n) = h.substeps
            && !(1..=crate::MAX_SUBSTEPS).contains(&n)
        {
            return Err(invalid(
                "hybrid.substeps",
                format!("must be 1 to {} TLED steps, got {n}", crate::MAX_SUBSTEPS),
            ));
        }
        Ok(())
    }

    fn validate_constraints(&self) -> Result<(), SimError> {
        count("boundary", self.boundary.len(), MAX_BOUNDARIES)?;
        for (i, b) in self.boundary.iter().enumerate() {
            count(&format!("boundary[{i}].faces"), b.faces.len(), 6)?;
            count(&format!("boundary[{i}].fix"), b.fix.len(), 3)?;
            if let Some(c) = &b.components {
                count(&format!("boundary[{i}].components"), c.len(), 3)?;
            }
            if let Some(r) = &b.region {
                region(&format!("boundary[{i}].box"), r)?;
            }
            if let Some(d) = &b.displace {
                position(&format!("boundary[{i}].displace"), d)?;
            }
            in_range(&format!("boundary[{i}].ramp"), b.ramp, 0.0, MAX_DURATION_S, " s")?;
        }
        count("load", self.load.len(), MAX_LOADS)?;
        for (i, l) in self.load.iter().enumerate() {
            region(&format!("load[{i}].box"), &l.region)?;
            bounded3(&format!("load[{i}].force"), &l.force, MAX_FORCE_N, " N")?;
        }
        Ok(())
    }

    fn validate_run(&self) -> Result<(), SimError> {
        let r = &self.run;
        positive("run.duration", r.duration, MAX_DURATION_S, " s")?;
        if let Some(dt) = self.dt() {
            in_range("run.dt", dt, MIN_DT, MAX_DT, " s")?;
        }
        in_range("run.safety", r.safety, MIN_SAFETY, 1.0, "")?;
        in_range("run.damping", r.damping, 0.0, MAX_DAMPING, " 1/s")?;
        bounded3("run.gravity", &r.gravity, MAX_GRAVITY, " m/s²")
    }

    fn validate_report(&self) -> Result<(), SimError> {
        let r = &self.report;
        count("report.reaction", r.reaction.len(), MAX_REACTIONS)?;
        count("report.probes", r.probes.len(), MAX_PROBES)?;
        for (i, p) in r.probes.iter().enumerate() {
            position(&format!("report.probes[{i}]"), p)?;
        }
        in_range("report.interval", r.interval, 0.0, MAX_DURATION_S, " s")
    }

    /// `[cut]`: the edge and the path bounded and finite, times increasing, and nothing the cutting
    /// simulation does not do (it holds nodes fixed, moves nothing by prescription, pushes with no
    /// load, and steps at `run.safety` times the critical step).
    fn validate_cut(&self) -> Result<(), SimError> {
        let Some(c) = &self.cut else { return Ok(()) };
        if !(2..=MAX_EDGE_POINTS).contains(&c.edge.len()) {
            return Err(invalid("cut.edge", format!("2 to {MAX_EDGE_POINTS} points, got {}", c.edge.len())));
        }
        for (i, p) in c.edge.iter().enumerate() {
            position(&format!("cut.edge[{i}]"), p)?;
        }
        if c.path.is_empty() {
            return Err(invalid("cut.path", "at least one key `{ time = s, offset = [x, y, z] }`".to_owned()));
        }
        count("cut.path", c.path.len(), MAX_PATH_KEYS)?;
        for (i, k) in c.path.iter().enumerate() {
            in_range(&format!("cut.path[{i}].time"), k.time, 0.0, MAX_DURATION_S, " s")?;
            position(&format!("cut.path[{i}].offset"), &k.offset)?;
            if i > 0 && k.time <= c.path[i - 1].time {
                return Err(invalid(
                    &format!("cut.path[{i}].time"),
                    format!("keys must come in increasing time: {} s after {} s", num(k.time), num(c.path[i - 1].time)),
                ));
            }
        }
        if let Some(r) = c.operational_radius {
            in_range("cut.operational_radius", r, 0.0, MAX_POSITION_M, " m")?;
        }
        if let Some(far) = &c.far_field {
            if !matches!(far.as_str(), "flsm" | "frozen") {
                return Err(invalid("cut.far_field", format!("unknown `{far}` (expected \"frozen\" or \"flsm\")")));
            }
            if c.operational_radius.is_none() {
                return Err(invalid(
                    "cut.far_field",
                    "needs `cut.operational_radius` (the region that stays TLED)".to_owned(),
                ));
            }
        }
        if let Some(t) = &c.table {
            in_range("cut.table.friction", t.friction, 0.0, MAX_FRICTION, "")?;
        }
        let unsupported = |key: &str, why: &str| Err(invalid(key, format!("not supported with [cut]: {why}")));
        if self.dt().is_some() {
            return unsupported(
                "run.dt",
                "the cutting simulation steps at `run.safety` times the critical step, recomputed as it is cut",
            );
        }
        if self.run.safety >= 1.0 {
            return unsupported("run.safety", "it must be below 1 (a cut makes new, lighter cells)");
        }
        for (i, b) in self.boundary.iter().enumerate() {
            if b.displace.is_some() || b.components.is_some() || b.fix.len() != 3 {
                return unsupported(
                    &format!("boundary[{i}]"),
                    "a boundary may only hold its nodes (`fix = [\"x\", \"y\", \"z\"]`)",
                );
            }
        }
        if !self.load.is_empty() {
            return unsupported("load", "loads are not applied to a body being cut");
        }
        if !self.report.reaction.is_empty() || !self.report.probes.is_empty() {
            return unsupported("report", "reactions and probes are not reported for a body being cut");
        }
        if self.hybrid.ratio != 1.0 || self.hybrid.operational.is_some() {
            return unsupported("hybrid", "the operational region follows the blade: give `cut.operational_radius`");
        }
        Ok(())
    }
}

fn invalid(key: &str, message: String) -> SimError {
    SimError::Invalid { key: key.to_owned(), message }
}

/// A number as the messages write it: plain for everyday magnitudes, else in exponent form.
fn num(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) { format!("{x}") } else { format!("{x:e}") }
}

/// `value` is finite and in `[min, max]`.
fn in_range(key: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<(), SimError> {
    if value.is_finite() && (min..=max).contains(&value) {
        return Ok(());
    }
    Err(invalid(key, format!("must be a finite number in [{}, {}]{unit}, got {}", num(min), num(max), num(value))))
}

/// `value` is finite and in `(0, max]`.
fn positive(key: &str, value: f64, max: f64, unit: &str) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 && value <= max {
        return Ok(());
    }
    Err(invalid(key, format!("must be a finite number in (0, {}]{unit}, got {}", num(max), num(value))))
}

/// Every component finite and at most `max` in magnitude.
fn bounded3(key: &str, v: &[f64; 3], max: f64, unit: &str) -> Result<(), SimError> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= max) {
        return Ok(());
    }
    Err(invalid(key, format!("must be three finite numbers within ±{}{unit}, got {v:?}", num(max))))
}

/// A point or displacement: components finite and within [`MAX_POSITION_M`].
fn position(key: &str, p: &[f64; 3]) -> Result<(), SimError> {
    bounded3(key, p, MAX_POSITION_M, " m")
}

/// A box: both corners are positions (`key.min`, `key.max`).
fn region(key: &str, b: &BoxSpec) -> Result<(), SimError> {
    position(&format!("{key}.min"), &b.min)?;
    position(&format!("{key}.max"), &b.max)
}

/// A list of at most `max` entries.
fn count(key: &str, n: usize, max: usize) -> Result<(), SimError> {
    if n <= max {
        return Ok(());
    }
    Err(invalid(key, format!("at most {max} entries, got {n}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = "[body]\nshape = \"box\"\nsize = [0.05, 0.05, 0.05]\ncell = 0.005\n";

    #[test]
    fn parses_design_example_and_defaults() {
        let s = Scenario::parse(MINIMAL, "s.toml").expect("parses");
        assert_eq!(s.material.mu, 20_000.0);
        assert_eq!(s.dt(), None);
        let s = Scenario::parse(&format!("{MINIMAL}[run]\ndt = \"auto\"\n"), "s.toml").expect("auto");
        assert_eq!(s.dt(), None);
        let s = Scenario::parse(&format!("{MINIMAL}[run]\ndt = 1e-4\n"), "s.toml").expect("number");
        assert_eq!(s.dt(), Some(1e-4));
    }

    #[test]
    fn unknown_keys_are_errors_naming_the_key() {
        let e = Scenario::parse(
            &format!("{MINIMAL}[material]\nlambda = 1.0\nmu = 1.0\ndensity = 1.0\nyoung = 3.0\n"),
            "s.toml",
        )
        .expect_err("unknown key");
        let msg = e.to_string();
        assert!(msg.starts_with("s.toml: ") && msg.contains("young"), "{msg}");
        let e = Scenario::parse(&format!("{MINIMAL}[run]\ndt = \"fast\"\n"), "s.toml").expect_err("bad dt");
        assert!(e.to_string().contains("dt"), "{e}");
    }
}
