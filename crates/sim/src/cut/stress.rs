//! Cutting where it fails: a stress test of [`CutSim`] on a soft block resting on a table.
//!
//! Each [`Case`] strokes a straight blade edge through a 6 x 4 x 3 cm block of 5 mm cells
//! (liver-like, 3 kPa, nothing held, a table with friction under it) at 30 frames per second, as
//! `hullcut run` does: each frame the edge's sweep over the last two frame gaps is cut into the
//! body where it is now, and the body advances by the frame's time; after the last stroke it
//! settles for 0.3 s. The cases ([`cases`]) vary what breaks cutting: stroke speed up to 2 m/s,
//! the cut plane's tilt, the lattice's phase against the stroke, two passes that do not meet
//! exactly, strokes that stop short, a blade moved flat, grazing a face, crossing and repeated
//! cuts, cuts a cell apart and half a cell apart, and a block cut into 24 fragments. Each result
//! ([`run`]) says whether it stayed stable (no divergence, no inverted cell left, kinetic energy
//! bounded by the block's potential energy over its height), whether it came apart into the
//! pieces expected, and what a frame cost. A failure (a sweep or cut refused, a divergence) is
//! caught and reported as the case's `failure`, never a panic.

use std::time::Instant;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::body::box_sdf;
use crate::cutting::{CutSim, CutSimParams};
use crate::lattice::Lattice;
use crate::material::Material;
use crate::sweep::{SweptSurface, reach_back};
use crate::table::Table;

/// The block's size, metres.
pub const BLOCK: [f64; 3] = [0.06, 0.04, 0.03];
/// Its lattice spacing, metres.
pub const CELL: f64 = 0.005;
/// Frames per second of the strokes.
pub const FPS: f64 = 30.0;
/// Length of the blade's straight edge, metres (longer than the block is wide either way).
const EDGE: f64 = 0.1;
/// Simulated time the block settles after the last stroke, seconds.
const SETTLE_S: f64 = 0.3;

/// One stroke: the middle of the blade's edge moves in a straight line at constant speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stroke {
    /// Where the edge's middle starts and ends, metres.
    pub from: Point3<f64>,
    /// See `from`.
    pub to: Point3<f64>,
    /// Direction of the edge (normalized when used).
    pub edge: Vector3<f64>,
    /// Speed, m/s.
    pub speed: f64,
}

impl Stroke {
    /// A stroke of an edge along `edge` from `from` to `to` at `speed`.
    pub fn new(from: [f64; 3], to: [f64; 3], edge: [f64; 3], speed: f64) -> Self {
        Stroke { from: Point3::from(from), to: Point3::from(to), edge: Vector3::from(edge), speed }
    }

    /// The blade's poses frame by frame (the tool frame's y axis along the edge), first and last
    /// included.
    fn poses(&self) -> Vec<Isometry3<f64>> {
        let rotation = UnitQuaternion::rotation_between(&Vector3::y(), &self.edge.normalize())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI));
        let frames = ((self.to - self.from).norm() / (self.speed / FPS)).ceil().max(1.0) as usize;
        (0..=frames)
            .map(|k| {
                let p = self.from + (self.to - self.from) * (k as f64 / frames as f64);
                Isometry3::from_parts(Translation3::from(p.coords), rotation)
            })
            .collect()
    }
}

/// A stress case.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    /// Short name, unique among [`cases`].
    pub name: String,
    /// What it varies (`speed`, `tilt`, `phase`, `two_passes`, `depth`, `flat`, `graze`,
    /// `crossing`, `sliver`, `fragments`).
    pub family: &'static str,
    /// The strokes, one after another (the blade leaves the body between them).
    pub strokes: Vec<Stroke>,
    /// Pieces the block must end in.
    pub expected_pieces: usize,
}

/// What a case came to.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CaseResult {
    /// The case's name.
    pub name: String,
    /// Its family.
    pub family: String,
    /// Frames run (strokes and settling).
    pub frames: usize,
    /// Pieces at the end, and expected.
    pub pieces: usize,
    /// See `pieces`.
    pub expected_pieces: usize,
    /// Why the case stopped early (a refused cut, a divergence), if it did.
    pub failure: Option<String>,
    /// Largest kinetic energy over the run, as a share of the block's potential energy over its
    /// own height (`m g H`): a body that falls apart stays well under 1.
    pub kinetic_max_ratio: f64,
    /// Most cells inverted after any frame, and after the last.
    pub inverted_max: usize,
    /// See `inverted_max`.
    pub inverted_end: usize,
    /// Lattice edges cut, cell copies and virtual nodes at the end.
    pub edges_cut: usize,
    /// See `edges_cut`.
    pub copies: usize,
    /// See `edges_cut`.
    pub virtual_nodes: usize,
    /// Crossings merged, edges bridged and holes of one node closed by tearing slivers
    /// ([`crate::sliver`]).
    pub torn_merged: usize,
    /// See `torn_merged`.
    pub torn_bridged: usize,
    /// See `torn_merged`.
    pub torn_holes: usize,
    /// Wall time of a frame (cut and advance), mean and largest, milliseconds.
    pub frame_ms_mean: f64,
    /// See `frame_ms_mean`.
    pub frame_ms_max: f64,
    /// Wall time of the cut (collision, topology, surfaces) in frames that cut, mean, ms.
    pub cut_ms_mean: f64,
}

impl CaseResult {
    /// Stable (ran to the end, no inverted cell left, kinetic energy bounded) and in the pieces
    /// expected.
    pub fn passed(&self) -> bool {
        self.stable() && self.pieces == self.expected_pieces
    }

    /// Ran to the end, no inverted cell left, kinetic energy finite and under `m g H`.
    pub fn stable(&self) -> bool {
        self.failure.is_none() && self.inverted_end == 0 && self.kinetic_max_ratio < 1.0
    }
}

/// A vertical stroke (edge along y) down through the block at `x` with its cut plane tilted by
/// `tilt_deg` about y, from above the top to `bottom`.
fn down(x: f64, tilt_deg: f64, bottom: f64, speed: f64) -> Stroke {
    let t = tilt_deg.to_radians();
    let (top, y) = (BLOCK[2] + 0.015, BLOCK[1] / 2.0);
    let at = |z: f64| [x + (z - BLOCK[2] / 2.0) * t.tan(), y, z];
    Stroke::new(at(top), at(bottom), [0.0, 1.0, 0.0], speed)
}

/// A stroke down through the block at `y` with the edge along x.
fn across(y: f64, speed: f64) -> Stroke {
    let x = BLOCK[0] / 2.0;
    Stroke::new([x, y, BLOCK[2] + 0.015], [x, y, -0.002], [1.0, 0.0, 0.0], speed)
}

/// Every stress case.
pub fn cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let mut add = |name: String, family: &'static str, strokes: Vec<Stroke>, expected_pieces: usize| {
        cases.push(Case { name, family, strokes, expected_pieces });
    };
    let x0 = BLOCK[0] / 2.0;
    let through = -0.002;
    for speed in [0.05, 0.2, 0.5, 1.0, 2.0] {
        add(format!("speed {speed} m/s"), "speed", vec![down(x0 + 0.3 * CELL, 0.0, through, speed)], 2);
    }
    for tilt in [10.0, 20.0, 30.0, 40.0] {
        add(format!("tilt {tilt} deg"), "tilt", vec![down(x0 + 0.3 * CELL, tilt, through, 0.2)], 2);
    }
    for phase in [0.0, 0.25, 0.5, 0.75, 0.95] {
        for speed in [0.05, 2.0] {
            let stroke = down(x0 + phase * CELL, 20.0, through, speed);
            add(format!("phase {phase} cells at {speed} m/s"), "phase", vec![stroke], 2);
        }
    }
    // Two passes: the first to mid-depth, the second through from above, beside the first by a
    // fraction of a cell either way, the node plane between them or not.
    for (phase, offset) in [(0.9, 0.2), (0.1, -0.2), (0.95, 0.1), (0.85, 0.3), (0.5, 0.3), (0.0, 0.0)] {
        let x = x0 + phase * CELL;
        let strokes = vec![down(x, 0.0, 0.012, 0.1), down(x + offset * CELL, 0.0, through, 0.1)];
        add(format!("two passes at {phase} cells, {offset:+} cells apart"), "two_passes", strokes, 2);
    }
    add("stops 4 mm short".to_owned(), "depth", vec![down(x0 + 0.3 * CELL, 0.0, 0.004, 0.2)], 1);
    // Pressed down to a millimetre above the table: it cuts through what rests on it.
    add("stops 1 mm short, pressed".to_owned(), "depth", vec![down(x0 + 0.3 * CELL, 0.0, 0.001, 0.2)], 2);
    add("1 mm past the bottom".to_owned(), "depth", vec![down(x0 + 0.3 * CELL, 0.0, -0.001, 0.2)], 2);
    // The blade moved flat: the edge (along y) travels along x through the block, slicing its
    // top 1.3 cm off.
    let flat =
        |speed: f64| Stroke::new([-0.02, BLOCK[1] / 2.0, 0.017], [0.08, BLOCK[1] / 2.0, 0.017], [0.0, 1.0, 0.0], speed);
    add("flat at 0.2 m/s".to_owned(), "flat", vec![flat(0.2)], 2);
    add("flat at 2 m/s".to_owned(), "flat", vec![flat(2.0)], 2);
    // Grazing: a tenth of a millimetre inside a side face, and along the top.
    add("grazing the side face".to_owned(), "graze", vec![down(BLOCK[0] - 0.0001, 0.0, through, 0.2)], 1);
    let top = Stroke::new(
        [-0.02, BLOCK[1] / 2.0, BLOCK[2] - 0.0001],
        [0.08, BLOCK[1] / 2.0, BLOCK[2] - 0.0001],
        [0.0, 1.0, 0.0],
        0.2,
    );
    add("grazing the top".to_owned(), "graze", vec![top], 1);
    // Crossing cuts, then both again along the same lines.
    let (xc, yc) = (x0 + 0.3 * CELL, BLOCK[1] / 2.0 + 0.2 * CELL);
    add("crossing".to_owned(), "crossing", vec![down(xc, 0.0, through, 0.2), across(yc, 0.2)], 4);
    let repeated = vec![down(xc, 0.0, through, 0.2), across(yc, 0.2), down(xc, 0.0, through, 0.5), across(yc, 0.5)];
    add("crossing, repeated".to_owned(), "crossing", repeated, 4);
    // Slivers: two cuts a cell apart leave a slice; half a cell apart they are one cut (torn).
    let pair =
        |gap: f64| vec![down(x0 - 0.5 * gap * CELL, 0.0, through, 0.2), down(x0 + 0.5 * gap * CELL, 0.0, through, 0.2)];
    add("two cuts a cell apart".to_owned(), "sliver", pair(1.0), 3);
    add("two cuts 1.5 cells apart".to_owned(), "sliver", pair(1.5), 3);
    add("two cuts half a cell apart".to_owned(), "sliver", pair(0.5), 2);
    // Fragments: five cuts along x and three along y, 24 columns.
    let mut grid: Vec<Stroke> =
        [0.0105, 0.0205, 0.0315, 0.0405, 0.0515].iter().map(|&x| down(x, 0.0, through, 0.5)).collect();
    grid.extend([0.0105, 0.0195, 0.0305].iter().map(|&y| across(y, 0.5)));
    add("24 fragments".to_owned(), "fragments", grid, 24);
    cases
}

/// The block on its table.
fn block() -> Result<CutSim, String> {
    let lattice = Lattice::block(
        Point3::origin(),
        CELL,
        [BLOCK[0] / CELL, BLOCK[1] / CELL, BLOCK[2] / CELL].map(|n| n.round() as usize),
    );
    let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
    let table = Table { height: 0.0, friction: 0.5 };
    let params = CutSimParams { table: Some(table), ..CutSimParams::default() };
    CutSim::new(lattice, &box_sdf(Vector3::from(BLOCK)), material, |_| false, params).map_err(|e| e.to_string())
}

/// Runs `case` on a fresh block.
pub fn run(case: &Case) -> CaseResult {
    let mut result = CaseResult {
        name: case.name.clone(),
        family: case.family.to_owned(),
        frames: 0,
        pieces: 0,
        expected_pieces: case.expected_pieces,
        failure: None,
        kinetic_max_ratio: 0.0,
        inverted_max: 0,
        inverted_end: 0,
        edges_cut: 0,
        copies: 0,
        virtual_nodes: 0,
        torn_merged: 0,
        torn_bridged: 0,
        torn_holes: 0,
        frame_ms_mean: 0.0,
        frame_ms_max: 0.0,
        cut_ms_mean: 0.0,
    };
    let mut sim = match block() {
        Ok(sim) => sim,
        Err(e) => {
            result.failure = Some(format!("set-up: {e}"));
            return result;
        }
    };
    let weight = 1000.0 * BLOCK.iter().product::<f64>() * 9.81 * BLOCK[2];
    let edge: Vec<Point3<f64>> = (0..=20).map(|k| Point3::new(0.0, EDGE * (k as f64 / 20.0 - 0.5), 0.0)).collect();
    let (mut frame_ms, mut cut_ms) = (Vec::new(), Vec::new());
    let gap = 1.0 / FPS;
    let settle = (SETTLE_S * FPS).ceil() as usize;
    let frames = case.strokes.iter().map(|s| (Some(*s), s.poses())).chain((0..settle).map(|_| (None, Vec::new())));
    'strokes: for (stroke, poses) in frames {
        let mut path: Vec<Isometry3<f64>> = Vec::new();
        let steps = if stroke.is_some() { poses.len() } else { 1 };
        for k in 0..steps {
            let clock = Instant::now();
            if let Some(pose) = poses.get(k) {
                path.push(*pose);
                if path.len() > 3 {
                    path.remove(0);
                }
                if path.len() == 3 {
                    path[0] = reach_back(&edge, &path[0], &path[1], CELL / 2.0);
                }
                if path.len() >= 2 {
                    let Some(swept) = SweptSurface::through(&edge, &path, CELL / 2.0, 0.05) else {
                        result.failure = Some(format!("frame {}: no sweep between the poses", result.frames));
                        break 'strokes;
                    };
                    let cut = Instant::now();
                    if let Err(e) = sim.cut(&swept) {
                        result.failure = Some(format!("frame {}: cut refused: {e}", result.frames));
                        break 'strokes;
                    }
                    cut_ms.push(cut.elapsed().as_secs_f64() * 1e3);
                }
            }
            if let Err(d) = sim.advance(gap) {
                result.failure = Some(format!("frame {}: diverged at step {}: {}", result.frames, d.step, d.reason));
                break 'strokes;
            }
            frame_ms.push(clock.elapsed().as_secs_f64() * 1e3);
            result.frames += 1;
            let energy = sim.kinetic_energy() / weight;
            result.kinetic_max_ratio =
                if energy.is_finite() { result.kinetic_max_ratio.max(energy) } else { f64::INFINITY };
            result.inverted_max = result.inverted_max.max(sim.inverted_cells());
        }
    }
    let topology = sim.topology();
    result.pieces = topology.pieces;
    result.inverted_end = sim.inverted_cells();
    result.edges_cut = topology.cut.len();
    result.copies = topology.copies.len();
    result.virtual_nodes = topology.virtual_of.len();
    result.torn_merged = topology.torn.merged;
    result.torn_bridged = topology.torn.bridged;
    result.torn_holes = topology.torn.holes;
    let mean = |v: &[f64]| if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 };
    result.frame_ms_mean = mean(&frame_ms);
    result.frame_ms_max = frame_ms.iter().copied().fold(0.0, f64::max);
    result.cut_ms_mean = mean(&cut_ms);
    result
}
