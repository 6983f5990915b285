//! The simulation scenario file (TOML; DESIGN.md "Simulation scenario file", extended as documented
//! in docs/scenario.md). Unknown keys are errors.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::SimError;

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
    /// Scale applied to the mesh's coordinates to get metres.
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
    /// Region half-width, cells.
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
    /// TLED steps per FLSM step; default: the FLSM step matched to the material.
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
    /// Prescribed displacement of all three components, metres (reached at the end of `ramp`).
    pub displace: Option<[f64; 3]>,
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
    /// `"auto"` or seconds.
    #[serde(default)]
    pub dt: DtSpec,
    /// Share of the computed critical step used by `dt = "auto"`.
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
    /// Parses scenario text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, SimError> {
        toml::from_str(text)
            .map_err(|e| SimError::Scenario { file: file.to_owned(), message: e.to_string().trim_end().to_owned() })
    }

    /// Reads a scenario file; relative mesh paths are resolved against its folder.
    pub fn load(path: &Path) -> Result<Self, SimError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| SimError::Scenario { file: file.clone(), message: e.to_string() })?;
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
