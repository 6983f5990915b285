//! The organ the pipeline cuts: its set-up and one frame set's step.

use std::time::{Duration, Instant};

use hullcut_hull::DenseGrid;
use hullcut_pose::{PoseEstimate, Template};
use hullcut_sim::{
    Body, CutOutcome, CutSim, CutSimParams, HybridParams, LARGE_ORGAN_SCALE, Material, NodeRole, Obstacle,
    SweptSurface, Table, TriMesh, VoxelizeParams, WindingTree, reach_back, scaled_organ_sdf, voxelize,
};
use nalgebra::{Isometry3, Point3};

use crate::backend::GpuHandle;
use crate::error::{Context as _, Error};
use crate::stages::StageTimes;

/// Young's modulus of the tissue, pascals (liver-like).
pub const YOUNG_PA: f64 = 3e3;
/// Poisson's ratio of the tissue.
pub const POISSON: f64 = 0.45;
/// Density of the tissue, kg/m³.
pub const DENSITY: f64 = 1000.0;
/// Coulomb friction between the tissue and the table (wet tissue on a drape).
pub const TABLE_FRICTION: f64 = 0.5;
/// Simulated time the tissue settles under gravity before the first frame set, seconds.
pub const SETTLE_S: f64 = 0.5;

/// A body's signed distance (negative inside), metres.
type SignedDistance = dyn Fn(&Point3<f64>) -> f64 + Sync;

/// The organ being cut.
pub struct Tissue {
    /// The simulation.
    pub sim: CutSim,
    /// Lattice spacing, metres.
    pub cell: f64,
    /// Problems worked around while voxelizing a mesh (open, inward), naming the file.
    pub warnings: Vec<String>,
}

impl std::fmt::Debug for Tissue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tissue")
            .field("nodes", &self.sim.lattice().node_count())
            .field("cells", &self.sim.cell_count())
            .field("cell", &self.cell)
            .field("warnings", &self.warnings)
            .finish_non_exhaustive()
    }
}

/// What the tissue did on one frame set.
#[derive(Debug, Default)]
pub struct TissueStep {
    /// The blade's swept surface between the last two trusted poses, when there were two.
    pub swept: Option<SweptSurface>,
    /// A trusted pose that did not sweep because the frames before it were refused for longer
    /// than [`MAX_BRIDGE_S`].
    pub sweep_skipped: bool,
    /// A trusted pose that swept across refused frame sets from the last trusted one, within
    /// [`MAX_BRIDGE_S`] of it.
    pub sweep_bridged: bool,
    /// Why a sweep between two trusted poses was not cut (a template edge or a step too large
    /// for the collision test's bounds, [`MAX_SWEEP_CELLS`]).
    pub sweep_refused: Option<String>,
    /// What cutting with `swept` did.
    pub cut: Option<CutOutcome>,
    /// The pieces' closed surfaces, deformed (world metres).
    pub surfaces: Vec<TriMesh>,
    /// The lattice nodes, deformed (real nodes, then virtual ones).
    pub nodes: Vec<Point3<f32>>,
    /// What moves each node: TLED, FLSM or both (the interface).
    pub roles: Vec<NodeRole>,
    /// Lattice cells run by TLED in this step.
    pub tled_cells: usize,
    /// Separate pieces.
    pub pieces: usize,
    /// Lattice nodes the hand's hull pushed at the end of the step.
    pub contacts: usize,
    /// Nodes on the table, and nodes put back on a contact plane with another piece, after the
    /// step's last time step.
    pub table_contacts: usize,
    /// See `table_contacts`.
    pub piece_contacts: usize,
}

/// Which poses sweep: a trusted pose that follows a trusted pose sweeps the blade's edge from the
/// one before, reaching half a lattice cell back along the gap before that when its poses were
/// trusted too (the tissue moves between frames, and consecutive sweeps must overlap, see
/// [`reach_back`]). Untrusted poses never cut; a sweep bridges refused frame sets only when the
/// trusted poses on either side are at most [`MAX_BRIDGE_S`] apart (a straight leg between them),
/// and a longer refusal starts a new stroke.
#[derive(Debug, Default)]
pub struct Sweeper {
    /// The last trusted poses, oldest first, at most [`SWEEP_LEGS`], with the capture time of the
    /// newest; cleared when a refusal lasts longer than [`MAX_BRIDGE_S`].
    previous: Vec<Isometry3<f64>>,
    last_trusted_ns: Option<i64>,
    /// Frame sets refused since the last trusted pose.
    refused: usize,
}

/// The longest stretch of capture time between two trusted poses a sweep bridges across refused
/// frame sets, seconds: three refused frame sets at 30 fps. The blade moves 1-2 cm in that time at
/// a surgeon's pace, along a nearly straight path. The built-in resection's true poses (with 0.1
/// mm and 0.3° of noise) refused at random, one frame set in twenty, one in ten or one in five,
/// kept the lobe on in 3, 6 and 6 runs of 6 when no refusal was bridged, and in none of them
/// bridged (`examples/resection_jitter.rs`).
pub const MAX_BRIDGE_S: f64 = 0.134;

/// Frame gaps a sweep spans when the poses before it were trusted.
pub const SWEEP_LEGS: usize = 2;

/// Lattice-cell-sized hash cells a swept surface may cover, summed over its triangles' bounding
/// boxes: the cut's collision test visits every one of them, so a sweep beyond this (a cutting
/// edge or a pose metres away, a step of metres) is refused and counted, never cut.
pub const MAX_SWEEP_CELLS: u64 = 1 << 22;

/// Points of the template's cutting edge a sweep takes at most (each is swept on up to a
/// thousand rows).
pub const MAX_EDGE_POINTS: usize = 4096;

impl Sweeper {
    /// The step a frame set's pose starts: its swept surface over the last [`SWEEP_LEGS`] frame
    /// gaps at most (rows at most half a `cell` apart, at most 0.05 rad of turn), or whether a sweep was skipped after a refusal, or refused for its
    /// size ([`MAX_SWEEP_CELLS`], [`MAX_EDGE_POINTS`]).
    pub fn next(&mut self, estimate: Option<&PoseEstimate>, template: Option<&Template>, cell: f64) -> TissueStep {
        let mut step = TissueStep::default();
        let trusted = estimate.filter(|e| e.valid).and_then(|e| e.pose.as_ref()).map(|p| p.tool_to_world);
        let now_ns = estimate.map(|e| e.timestamp_ns);
        match (trusted, template) {
            (Some(now), Some(template)) => {
                let mut skipped = false;
                if self.refused > 0 {
                    let gap_s = match (self.last_trusted_ns, now_ns) {
                        (Some(a), Some(b)) => b.saturating_sub(a) as f64 * 1e-9,
                        _ => f64::INFINITY,
                    };
                    if !(0.0..=MAX_BRIDGE_S).contains(&gap_s) {
                        skipped = !self.previous.is_empty();
                        self.previous.clear();
                    } else if !self.previous.is_empty() {
                        step.sweep_bridged = true;
                    }
                }
                if let Some(&before) = self.previous.last() {
                    let mut path = self.previous.clone();
                    path.push(now);
                    if let [earlier, _, _] = path.as_mut_slice() {
                        *earlier = reach_back(&template.edge, earlier, &before, cell / 2.0);
                    }
                    match sweep(template, &path, cell) {
                        Ok(swept) => step.swept = swept,
                        Err(reason) => step.sweep_refused = Some(reason),
                    }
                } else {
                    step.sweep_skipped = skipped;
                }
                if self.previous.len() == SWEEP_LEGS {
                    self.previous.remove(0);
                }
                self.previous.push(now);
                self.last_trusted_ns = now_ns;
                self.refused = 0;
            }
            _ => {
                self.refused += 1;
            }
        }
        step
    }
}

/// The blade's cutting edge swept along `path` (trusted poses, oldest first), refused when its collision test would
/// visit more than [`MAX_SWEEP_CELLS`] cells of `cell` metres (counted with checked arithmetic,
/// a number that is not finite refused) or the edge has more than [`MAX_EDGE_POINTS`] points.
fn sweep(template: &Template, path: &[Isometry3<f64>], cell: f64) -> Result<Option<SweptSurface>, String> {
    if template.edge.len() > MAX_EDGE_POINTS {
        return Err(format!(
            "the cutting edge has {} points, more than the {MAX_EDGE_POINTS} a sweep takes",
            template.edge.len()
        ));
    }
    let Some(swept) = SweptSurface::through(&template.edge, path, cell / 2.0, 0.05) else { return Ok(None) };
    let mut total: u64 = 0;
    for t in 0..swept.triangles.len() {
        let corners = swept.triangle(t);
        let mut cells: u64 = 1;
        for a in 0..3 {
            let (lo, hi) =
                corners.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[a]), hi.max(p[a])));
            let span = (hi / cell).floor() - (lo / cell).floor() + 1.0;
            if !(1.0..=MAX_SWEEP_CELLS as f64).contains(&span) {
                return Err(format!("the swept blade spans {:.3e} m along axis {a}: not a blade's step", hi - lo));
            }
            cells = cells.saturating_mul(span as u64);
        }
        total = total.saturating_add(cells);
        if total > MAX_SWEEP_CELLS {
            return Err(format!(
                "the swept blade covers more than {MAX_SWEEP_CELLS} lattice cells' worth of boxes (a step of metres?)"
            ));
        }
    }
    Ok(Some(swept))
}

/// Builds the tissue: `organ` (the built-in organ on the table), `organ-large` (the same organ
/// [`LARGE_ORGAN_SCALE`] times larger: an adult liver's size, 100k nodes at 2 mm) or a PLY/OBJ
/// mesh in world metres,
/// at lattice spacing `cell`, resting on a table at its lowest layer of nodes (contact with
/// friction, nothing held: a piece cut off falls onto the table and rests there), settled under
/// gravity; with `hybrid`, TLED runs only near the blade and FLSM elsewhere; with `gpu`, the
/// TLED steps run there.
pub fn build(name: &str, cell: f64, hybrid: Option<HybridParams>, gpu: Option<GpuHandle>) -> Result<Tissue, Error> {
    let material = Material::from_young_poisson(YOUNG_PA, POISSON, DENSITY);
    let organ_scale = match name {
        "organ" => Some(1.0),
        "organ-large" => Some(LARGE_ORGAN_SCALE),
        _ => None,
    };
    let (body, signed): (Body, Box<SignedDistance>) = if let Some(scale) = organ_scale {
        (Body::Organ { scale }, Box::new(move |p: &Point3<f64>| scaled_organ_sdf(p, scale)))
    } else {
        let mesh = TriMesh::load(name).context("--tissue")?;
        // Inside where the generalized winding number exceeds one half (robust to holes); the
        // magnitude is not a distance, so the cut faces' placement near the surface is approximate
        // to a fraction of a cell.
        let tree = WindingTree::new(&mesh);
        (
            Body::Mesh(mesh, Some(name.into())),
            Box::new(move |p: &Point3<f64>| (0.5 - tree.winding_number(p).abs()) * cell),
        )
    };
    let voxelized = voxelize(&body, cell, &VoxelizeParams::default()).context("--tissue")?;
    let lattice = voxelized.lattice;
    let floor = lattice.rest.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
    let table = Table { height: floor, friction: TABLE_FRICTION };
    let params = CutSimParams { hybrid, table: Some(table), ..CutSimParams::default() };
    let mut sim = CutSim::new(lattice, &*signed, material, |_| false, params)
        .with_context(|| format!("setting up the tissue ({name})"))?;
    #[cfg(feature = "gpu")]
    if let Some(gpu) = gpu {
        sim.use_gpu(gpu).context("--backend gpu")?;
    }
    #[cfg(not(feature = "gpu"))]
    if let Some(never) = gpu {
        match never {}
    }
    sim.advance(SETTLE_S).map_err(|d| Error::msg(format!("the tissue diverged while settling: {}", d.reason)))?;
    Ok(Tissue { sim, cell, warnings: voxelized.warnings })
}

impl Tissue {
    /// Cuts with `step.swept` (when there is one), advances by `seconds` and fills in the step's
    /// surfaces and nodes; timings go to `times`.
    pub fn step(
        &mut self,
        step: &mut TissueStep,
        seconds: f64,
        hand: Option<&DenseGrid>,
        times: &mut StageTimes,
    ) -> Result<(), Error> {
        if let Some(swept) = &step.swept {
            let outcome = self.sim.cut(swept).context("cutting")?;
            let ms = |ms: f64| Duration::from_secs_f64(ms * 1e-3);
            times.collide.push(ms(outcome.collide_ms));
            times.cut_topology.push(ms(outcome.topology_ms));
            times.cut_surface.push(ms(outcome.surface_ms));
            step.cut = Some(outcome);
        }
        // The hand's hull pushes the tissue aside (the scalpel's does not: its blade cuts, and its
        // hull, voxels thick, would shove the tissue ahead of the edge away from it).
        let clock = Instant::now();
        let obstacles = hand.and_then(|g| self.obstacle(g)).into_iter().collect();
        self.sim.set_obstacles(obstacles);
        let obstacle_set_up = clock.elapsed();
        let clock = Instant::now();
        // The operational region (hybrid model) follows the blade's sweep since the last frame.
        self.sim.set_tool(step.swept.as_ref().map_or(&[], |s| &s.vertices[..]));
        self.sim.advance(seconds).map_err(|d| {
            let node = self.sim.describe_node(d.node).unwrap_or_else(|| format!("node {}", d.node));
            Error::msg(format!("the tissue diverged at step {} (t = {:.3} s, {node}): {}", d.step, d.time, d.reason))
        })?;
        // Contact (the hand's obstacle and the table, resolved after every step) counts apart.
        let contact = Duration::from_secs_f64(self.sim.contact_seconds());
        times.deform.push(clock.elapsed().saturating_sub(contact));
        times.contact.push(obstacle_set_up + contact);
        let clock = Instant::now();
        step.surfaces = self.sim.surfaces();
        step.nodes = self.sim.node_positions();
        step.roles = self.sim.node_roles();
        step.tled_cells = self.sim.tled_cells();
        step.pieces = self.sim.pieces();
        step.contacts = self.sim.contacts();
        step.table_contacts = self.sim.table_contacts();
        step.piece_contacts = self.sim.piece_contact_nodes();
        times.tissue_surface.push(clock.elapsed());
        Ok(())
    }
}

impl Tissue {
    /// The part of a hull grid within [`CONTACT_MARGIN_M`] of the tissue's bounds, as an obstacle
    /// (the rest cannot touch it this frame, and the way out of a voxel is computed only where
    /// it can matter).
    fn obstacle(&self, grid: &DenseGrid) -> Option<Obstacle> {
        let nodes = self.sim.node_positions();
        let (mut lo, mut hi) = (Point3::from([f32::MAX; 3]), Point3::from([f32::MIN; 3]));
        for p in &nodes {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let margin = CONTACT_MARGIN_M;
        let range = |a: usize| {
            let first = ((f64::from(lo[a]) - margin - grid.origin[a]) / grid.leaf).floor().max(0.0) as usize;
            let last = ((f64::from(hi[a]) + margin - grid.origin[a]) / grid.leaf).ceil().max(0.0) as usize;
            (first.min(grid.dims[a]), last.saturating_add(1).min(grid.dims[a]))
        };
        let r = [range(0), range(1), range(2)];
        let dims = r.map(|(a, b)| b.saturating_sub(a));
        if dims.contains(&0) {
            return None;
        }
        let mut occupied = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in r[2].0..r[2].1 {
            for j in r[1].0..r[1].1 {
                for i in r[0].0..r[0].1 {
                    occupied.push(grid.occupied[i + grid.dims[0] * (j + grid.dims[1] * k)]);
                }
            }
        }
        let origin = grid.origin + nalgebra::Vector3::new(r[0].0 as f64, r[1].0 as f64, r[2].0 as f64) * grid.leaf;
        Obstacle::from_occupancy(origin, grid.leaf, dims, &occupied)
    }
}

/// How far beyond the tissue's bounds a hull is taken as an obstacle, metres.
pub const CONTACT_MARGIN_M: f64 = 0.01;

#[cfg(test)]
mod tests {
    use super::*;

    fn template() -> Template {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
        let ds = hullcut_dataset::Dataset::open(root).expect("cut-small");
        Template::new(&ds.tool().expect("tool.json").expect("a tool")).expect("a template")
    }

    fn estimate(template: &Template, valid: bool, x: f64) -> PoseEstimate {
        let mut e = crate::no_tool_estimate(0, 0);
        e.valid = valid;
        e.pose = Some(hullcut_pose::BladePose::new(template, Isometry3::translation(x, 0.0, 0.05)));
        e
    }

    /// The steps of a run of poses at 30 fps, (trusted, x) each.
    fn run(s: &mut Sweeper, t: &Template, poses: &[(bool, f64)]) -> Vec<TissueStep> {
        poses
            .iter()
            .enumerate()
            .map(|(k, &(valid, x))| {
                let mut e = estimate(t, valid, x);
                (e.frame, e.timestamp_ns) = (k as u64, k as i64 * 33_333_333);
                s.next(Some(&e), Some(t), 0.005)
            })
            .collect()
    }

    /// The x range of a sweep's vertices, relative to the template's first edge point.
    fn x_span(t: &Template, step: &TissueStep) -> (f64, f64) {
        let sweep = step.swept.as_ref().expect("a sweep");
        let xs = sweep.vertices.iter().map(|p| p.x - t.edge[0].x);
        xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)))
    }

    #[test]
    fn trusted_poses_sweep_across_a_short_refusal_and_a_long_one_starts_a_new_stroke() {
        let t = template();
        let span = t
            .edge
            .iter()
            .map(|p| p.x - t.edge[0].x)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        let near = |got: (f64, f64), from: f64, to: f64| {
            (got.0 - (from + span.0)).abs() < 1e-9 && (got.1 - (to + span.1)).abs() < 1e-9
        };
        let flags = |steps: &[TissueStep]| -> Vec<(bool, bool, bool)> {
            steps.iter().map(|s| (s.swept.is_some(), s.sweep_bridged, s.sweep_skipped)).collect()
        };
        // One refused frame set: the next trusted pose sweeps from the last trusted one, half a
        // cell (2.5 mm) back along the gap before it, and on from there.
        let mut s = Sweeper::default();
        let steps = run(&mut s, &t, &[(true, 0.0), (true, 0.01), (false, 0.02), (true, 0.03), (true, 0.04)]);
        let (no, swept, bridged) = ((false, false, false), (true, false, false), (true, true, false));
        assert_eq!(flags(&steps), [no, swept, no, bridged, swept]);
        assert!(near(x_span(&t, &steps[3]), 0.0075, 0.03), "{:?}", x_span(&t, &steps[3]));
        assert!(near(x_span(&t, &steps[4]), 0.0275, 0.04), "{:?}", x_span(&t, &steps[4]));
        // Three refused (4/30 s between the trusted poses): bridged. Four (5/30 s): the next
        // trusted pose starts a new stroke, and the one after sweeps from it alone.
        let mut s = Sweeper::default();
        let three = [(true, 0.0), (false, 0.01), (false, 0.02), (false, 0.03), (true, 0.04)];
        assert_eq!(flags(&run(&mut s, &t, &three))[4], bridged);
        let mut s = Sweeper::default();
        let four =
            [(true, 0.0), (false, 0.01), (false, 0.02), (false, 0.03), (false, 0.04), (true, 0.05), (true, 0.06)];
        let steps = run(&mut s, &t, &four);
        assert_eq!(flags(&steps)[5..], [(false, false, true), swept]);
        assert!(near(x_span(&t, &steps[6]), 0.05, 0.06), "{:?}", x_span(&t, &steps[6]));
        // Nothing trusted before: nothing to sweep from, nothing skipped.
        let mut s = Sweeper::default();
        assert_eq!(flags(&run(&mut s, &t, &[(false, 0.0), (true, 0.01)]))[1], no);
        // Without a template (no tool.json) nothing ever sweeps.
        assert!(s.next(Some(&estimate(&t, true, 0.05)), None, 0.005).swept.is_none());
    }

    #[test]
    fn a_sweep_too_large_to_test_is_refused_not_allocated() {
        // A cutting-edge point at 1e308 (tool.json refuses it; a template changed after is caught
        // here too): the sweep's boxes are not even countable.
        let mut far = template();
        far.edge[1].x = 1e308;
        let mut s = Sweeper::default();
        s.next(Some(&estimate(&far, true, 0.0)), Some(&far), 0.005);
        let step = s.next(Some(&estimate(&far, true, 0.01)), Some(&far), 0.005);
        assert!(step.swept.is_none());
        let reason = step.sweep_refused.unwrap_or_default();
        assert!(reason.contains("not a blade's step"), "{reason}");
        // A trusted step of 100 km: a thousand rows (the most a sweep has) of boxes each some
        // 20,000 cells long, over the 4 million cells a sweep may cover.
        let t = template();
        let mut s = Sweeper::default();
        s.next(Some(&estimate(&t, true, 0.0)), Some(&t), 0.005);
        let step = s.next(Some(&estimate(&t, true, 1.0e5)), Some(&t), 0.005);
        assert!(step.swept.is_none() && step.sweep_refused.is_some(), "{:?}", step.sweep_refused);
        // An edge of too many points.
        let mut long = template();
        long.edge = (0..=MAX_EDGE_POINTS).map(|k| Point3::new(k as f64 * 1e-6, 0.0, 0.0)).collect();
        let mut s = Sweeper::default();
        s.next(Some(&estimate(&long, true, 0.0)), Some(&long), 0.005);
        let step = s.next(Some(&estimate(&long, true, 0.01)), Some(&long), 0.005);
        assert!(step.sweep_refused.is_some_and(|r| r.contains("points")));
    }
}
