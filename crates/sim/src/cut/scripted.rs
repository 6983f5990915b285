//! A cut scripted by a scenario's `[cut]`: a blade's cutting edge moved along a path of keys
//! through a body, cut into it frame by frame as `hullcut run` cuts with each frame set's pose.
//!
//! [`ScriptedCut::from_scenario`] builds the [`CutSim`] the scenario describes (its body, material,
//! held nodes, gravity, damping, table and the hybrid's far field) and [`ScriptedCut::frame`]
//! advances it by one frame: the surface the edge swept since the last frame (reaching half a
//! lattice cell back into the frame before, so consecutive sweeps overlap, see [`reach_back`]) is
//! cut, the operational region follows it, and the body advances by the frame's time.

use std::collections::HashSet;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::body::{Body, box_sdf, scaled_organ_sdf};
use crate::cutting::{CutOutcome, CutSim, CutSimParams};
use crate::dynamics::Divergence;
use crate::flsm::FlsmParams;
use crate::mesh::WindingTree;
use crate::operational::{FarField, HybridParams};
use crate::scenario::{CutSpec, MAX_LATTICE_CELLS, Scenario};
use crate::simulation::{MAX_STEPS, box_nodes, face_nodes, scenario_body};
use crate::sweep::{SweptSurface, reach_back};
use crate::table::Table;
use crate::tled::{Integration, TledParams};
use crate::{Material, SimError};

/// Where a blade's cutting edge is over time: its points at offset zero and the offset at keyed
/// times, linear between keys, held before the first and after the last.
#[derive(Debug, Clone, PartialEq)]
pub struct BladePath {
    /// The edge at offset zero, world metres.
    pub edge: Vec<Point3<f64>>,
    /// `(time, offset)` keys, times increasing.
    pub keys: Vec<(f64, Vector3<f64>)>,
}

impl BladePath {
    /// The path `[cut]` describes.
    pub fn from_spec(spec: &CutSpec) -> Self {
        Self {
            edge: spec.edge.iter().map(|p| Point3::from(*p)).collect(),
            keys: spec.path.iter().map(|k| (k.time, Vector3::from(k.offset))).collect(),
        }
    }

    /// The edge's offset at time `t`.
    pub fn offset_at(&self, t: f64) -> Vector3<f64> {
        let Some(&(first_t, first)) = self.keys.first() else { return Vector3::zeros() };
        if t <= first_t {
            return first;
        }
        for pair in self.keys.windows(2) {
            let ((t0, a), (t1, b)) = (pair[0], pair[1]);
            if t <= t1 {
                return a.lerp(&b, (t - t0) / (t1 - t0));
            }
        }
        self.keys.last().map_or(first, |k| k.1)
    }

    /// The edge's points at time `t`.
    pub fn edge_at(&self, t: f64) -> Vec<Point3<f64>> {
        let offset = self.offset_at(t);
        self.edge.iter().map(|p| p + offset).collect()
    }

    /// The surface the edge sweeps from time `from` to `to` (through the keys between), rows no
    /// farther apart than `max_chord`, reaching `back` metres of travel into the `before` to `from`
    /// leg first; `None` when the edge does not move from `from` to `to`.
    pub fn sweep(&self, before: f64, from: f64, to: f64, back: f64, max_chord: f64) -> Option<SweptSurface> {
        let pose = |t: f64| {
            let o = self.offset_at(t);
            Isometry3::translation(o.x, o.y, o.z)
        };
        let between: Vec<Isometry3<f64>> =
            self.keys.iter().filter(|&&(t, _)| t > from && t < to).map(|&(t, _)| pose(t)).collect();
        if between.is_empty() && pose(from) == pose(to) {
            return None;
        }
        let mut poses = vec![reach_back(&self.edge, &pose(before), &pose(from), back)];
        for p in std::iter::once(pose(from)).chain(between).chain([pose(to)]) {
            // A leg the edge does not move along adds no row.
            if poses.last().is_none_or(|q| q.translation.vector != p.translation.vector) {
                poses.push(p);
            }
        }
        SweptSurface::through(&self.edge, &poses, max_chord, 0.05)
    }
}

/// A body's signed distance (negative inside), metres.
type SignedDistance = dyn Fn(&Point3<f64>) -> f64 + Sync;

/// A rest position's exact bits, to find a held node by it.
fn bits(p: &Point3<f64>) -> [u64; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

/// What one frame of a [`ScriptedCut`] did.
#[derive(Debug, Clone, Default)]
pub struct FrameOutcome {
    /// The surface the blade swept this frame, when it moved.
    pub swept: Option<SweptSurface>,
    /// The cut, when the blade moved this frame.
    pub cut: Option<CutOutcome>,
    /// Wall time advancing the body (contacts included), milliseconds.
    pub advance_ms: f64,
    /// TLED steps taken.
    pub steps: usize,
}

/// A body cut by a blade that moves along a [`BladePath`], frame by frame.
pub struct ScriptedCut {
    /// The body being cut.
    pub sim: CutSim,
    /// Where the blade's edge goes.
    pub blade: BladePath,
    /// Simulated time between frames (cuts), seconds.
    pub interval: f64,
    /// Frames done.
    pub frame: u64,
    /// Warnings from building the body (a mesh with holes).
    pub warnings: Vec<String>,
}

impl std::fmt::Debug for ScriptedCut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScriptedCut")
            .field("nodes", &self.sim.lattice().node_count())
            .field("blade", &self.blade)
            .field("interval", &self.interval)
            .field("frame", &self.frame)
            .finish_non_exhaustive()
    }
}

/// The frame interval when the scenario gives `report.interval = 0`, seconds (60 Hz).
pub const DEFAULT_INTERVAL_S: f64 = 1.0 / 60.0;

impl ScriptedCut {
    /// The body, blade and settings a scenario with `[cut]` describes (checked first, as
    /// [`Scenario::validate`] does; an error names the key). A run of more than [`MAX_STEPS`]
    /// steps (every frame takes at least one) is refused naming `run.duration` or
    /// `report.interval`.
    pub fn from_scenario(s: &Scenario) -> Result<Self, SimError> {
        s.validate()?;
        let invalid = |key: &str, message: String| SimError::Invalid { key: key.to_owned(), message };
        let spec = s.cut.as_ref().ok_or_else(|| invalid("cut", "the scenario has no [cut] table".to_owned()))?;
        let body = scenario_body(s)?;
        let cell = s.body.cell;
        let params = crate::body::VoxelizeParams { max_cells: MAX_LATTICE_CELLS, ..Default::default() };
        let key = if s.body.mesh.is_some() { "body.mesh" } else { "body" };
        let voxelized = crate::body::voxelize(&body, cell, &params).map_err(|e| invalid(key, e.to_string()))?;
        let lattice = voxelized.lattice;
        let signed: Box<SignedDistance> = match &body {
            Body::Box { size } => Box::new(box_sdf(*size)),
            Body::Organ { scale } => {
                let scale = *scale;
                Box::new(move |p: &Point3<f64>| scaled_organ_sdf(p, scale))
            }
            Body::Mesh(mesh, _) => {
                // Inside where the winding number exceeds one half (robust to holes); not a
                // distance, so the cut faces' placement near the surface is approximate.
                let tree = WindingTree::new(mesh);
                Box::new(move |p: &Point3<f64>| (0.5 - tree.winding_number(p).abs()) * cell)
            }
        };
        // Held nodes, by their rest positions (CutSim asks per rest position).
        let mut held: HashSet<[u64; 3]> = HashSet::new();
        for (i, b) in s.boundary.iter().enumerate() {
            let key = format!("boundary[{i}]");
            let mut nodes = Vec::new();
            for f in &b.faces {
                nodes.extend(face_nodes(&lattice, f, &format!("{key}.faces"))?);
            }
            if let Some(r) = &b.region {
                nodes.extend(box_nodes(&lattice, r));
            }
            if b.faces.is_empty() && b.region.is_none() {
                return Err(invalid(&key, "needs `faces` or `box`".to_owned()));
            }
            if nodes.is_empty() {
                return Err(invalid(&key, "selects no lattice node".to_owned()));
            }
            let mut axes = b.fix.clone();
            axes.sort();
            axes.dedup();
            if axes != ["x", "y", "z"] {
                return Err(invalid(
                    &format!("{key}.fix"),
                    format!("must hold x, y and z with [cut], got {:?}", b.fix),
                ));
            }
            held.extend(nodes.iter().map(|&n| bits(&lattice.rest[n as usize])));
        }
        let material = Material { lambda: s.material.lambda, mu: s.material.mu, density: s.material.density };
        let integration = match s.tled.integration.as_str() {
            "gauss8" => Integration::Gauss8,
            _ => Integration::OnePoint,
        };
        let far_field = if spec.far_field.as_deref() == Some("flsm") { FarField::Flsm } else { FarField::Frozen };
        let hybrid = spec.operational_radius.map(|radius| HybridParams {
            radius,
            flsm: FlsmParams {
                w: s.flsm.w,
                alpha: s.flsm.alpha.unwrap_or(crate::scenario::ALPHA_DEFAULT),
                region_damping: s.flsm.region_damping,
            },
            beta: s.hybrid.beta.map(|b| b as f32),
            substeps: s.hybrid.substeps,
            far_field,
            ..HybridParams::default()
        });
        let floor = lattice.rest.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let table = spec.table.map(|t| Table { height: floor, friction: t.friction });
        let params = CutSimParams {
            tled: TledParams { integration, hourglass: s.tled.hourglass },
            damping: s.run.damping as f32,
            gravity: s.run.gravity,
            dt_safety: s.run.safety,
            hybrid,
            table,
            ..CutSimParams::default()
        };
        let fixed = |p: &Point3<f64>| held.contains(&bits(p));
        let sim = CutSim::new(lattice, &*signed, material, fixed, params)?;
        let interval = if s.report.interval > 0.0 { s.report.interval } else { DEFAULT_INTERVAL_S };
        // Every frame takes at least one step: the run is bounded as a scenario's run is.
        let frames = (s.run.duration / interval).round().max(1.0);
        let steps = frames * (interval / sim.dt()).ceil().max(1.0);
        if !(steps.is_finite() && steps <= MAX_STEPS as f64) {
            return Err(invalid(
                if interval < sim.dt() { "report.interval" } else { "run.duration" },
                format!(
                    "{} s in frames of {interval:e} s at a step of {:e} s is {steps:.3e} steps, above the limit of \
                     {MAX_STEPS}: shorten run.duration, or make report.interval no shorter than the step",
                    s.run.duration,
                    sim.dt()
                ),
            ));
        }
        Ok(Self { sim, blade: BladePath::from_spec(spec), interval, frame: 0, warnings: voxelized.warnings })
    }

    /// Frames in `duration` seconds (at least one).
    pub fn frames_for(&self, duration: f64) -> u64 {
        ((duration / self.interval).round() as u64).max(1)
    }

    /// One frame: cuts the surface the blade swept over it, moves the operational region to the
    /// blade, and advances the body by the interval. A cut that fails is an error; a body that
    /// diverges is a [`Divergence`] with the step.
    pub fn frame(&mut self) -> Result<FrameOutcome, FrameError> {
        let (t0, t1) = (self.frame as f64 * self.interval, (self.frame + 1) as f64 * self.interval);
        let cell = self.sim.lattice().cell;
        let swept = self.blade.sweep(t0 - self.interval, t0, t1, cell / 2.0, cell / 2.0);
        let mut outcome = FrameOutcome::default();
        if let Some(swept) = &swept {
            outcome.cut = Some(self.sim.cut(swept).map_err(FrameError::Cut)?);
        }
        self.sim.set_tool(swept.as_ref().map_or(&[], |s| &s.vertices[..]));
        outcome.swept = swept;
        let clock = Instant::now();
        // To the frame's end (whole steps: the body keeps within a step of the blade's clock).
        let seconds = (t1 - self.sim.time()).max(0.0);
        outcome.steps = self.sim.advance(seconds).map_err(|mut d| {
            if let Some(node) = self.sim.describe_node(d.node) {
                d.reason = format!("{}; {node}", d.reason);
            }
            FrameError::Diverged(d)
        })?;
        outcome.advance_ms = clock.elapsed().as_secs_f64() * 1e3;
        self.frame += 1;
        Ok(outcome)
    }
}

/// Why a frame of a [`ScriptedCut`] failed.
#[derive(Debug)]
pub enum FrameError {
    /// The cut could not be made.
    Cut(SimError),
    /// The body diverged (the step, time and node are in it).
    Diverged(Divergence),
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cut(e) => write!(f, "cutting: {e}"),
            Self::Diverged(d) => {
                write!(f, "the body diverged at step {} (t = {:.4} s, node {}): {}", d.step, d.time, d.node, d.reason)
            }
        }
    }
}

impl std::error::Error for FrameError {}

#[cfg(test)]
mod tests {
    use super::*;

    fn path() -> BladePath {
        BladePath {
            edge: vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.01)],
            keys: vec![
                (0.1, Vector3::zeros()),
                (0.3, Vector3::new(0.0, 0.02, 0.0)),
                (0.4, Vector3::new(0.0, 0.02, -0.01)),
            ],
        }
    }

    #[test]
    fn the_path_holds_before_and_after_its_keys_and_is_linear_between() {
        let p = path();
        assert_eq!(p.offset_at(0.0), Vector3::zeros());
        assert!((p.offset_at(0.2) - Vector3::new(0.0, 0.01, 0.0)).norm() < 1e-12);
        assert!((p.offset_at(0.35) - Vector3::new(0.0, 0.02, -0.005)).norm() < 1e-12);
        assert_eq!(p.offset_at(5.0), Vector3::new(0.0, 0.02, -0.01));
        assert_eq!(p.edge_at(5.0)[1], Point3::new(0.0, 0.02, 0.0));
    }

    #[test]
    fn a_sweep_follows_the_keys_inside_the_frame_and_none_is_made_at_rest() {
        let p = path();
        assert!(p.sweep(0.0, 0.0, 0.1, 0.001, 0.001).is_none(), "at rest before the first key");
        assert!(p.sweep(0.5, 0.6, 0.7, 0.001, 0.001).is_none(), "at rest after the last");
        // Over the corner at 0.3 s: the sweep's rows pass through the key's edge.
        let s = p.sweep(0.2, 0.25, 0.35, 0.0, 0.001).expect("moved");
        let corner = p.edge_at(0.3);
        assert!(s.vertices.iter().any(|v| (v - corner[0]).norm() < 1e-12), "through the key");
        let (first, last) = (s.vertices[0], s.vertices[s.vertices.len() - 2]);
        assert!((first - p.edge_at(0.25)[0]).norm() < 1e-12);
        assert!((last - p.edge_at(0.35)[0]).norm() < 1e-12);
        // Reaching back: the sweep starts half a millimetre behind where the frame starts.
        let s = p.sweep(0.15, 0.2, 0.25, 0.0005, 0.001).expect("moved");
        assert!((s.vertices[0].y - (0.01 - 0.0005)).abs() < 1e-12, "{}", s.vertices[0]);
    }
}
