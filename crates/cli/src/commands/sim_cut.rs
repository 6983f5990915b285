//! `hullcut sim` on a scenario with `[cut]`: a blade moved along keys cuts the body frame by frame
//! (`hullcut_sim::ScriptedCut`), with a report and a rerun recording.

use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use hullcut_sim::dynamics::Divergence;
use hullcut_sim::scripted::FrameError;
use hullcut_sim::{PieceState, Scenario, ScriptedCut, SweptSurface};
use serde::{Deserialize, Serialize};

use super::run::tissue_log::{SWEPT_CYAN, TISSUE_RED, merged};
use super::sim::Args;
use crate::backend::Backend;
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};

/// RGBA of the blade's edge.
const EDGE_WHITE: [u8; 4] = [240, 240, 240, 255];

#[derive(Debug, Serialize, Deserialize)]
struct Lattice {
    cell_m: f64,
    nodes: usize,
    cells: usize,
}

/// What cutting did over the run.
#[derive(Debug, Serialize, Deserialize)]
struct Cutting {
    /// Frames in which the blade moved and was cut in.
    cut_frames: u64,
    /// Lattice edges the blade crossed, summed over frames.
    edges_crossed: usize,
    /// Cell copies and virtual nodes at the end.
    copies: usize,
    virtual_nodes: usize,
    /// Separate pieces at the end.
    pieces: usize,
}

#[derive(Debug, Serialize, Deserialize)]
struct Timings {
    /// Per frame: the cut's collision, topology and surfaces (frames with a cut), the body's
    /// advance, and the whole frame.
    collide: StageTiming,
    cut_topology: StageTiming,
    cut_surface: StageTiming,
    advance: StageTiming,
    frame: StageTiming,
    setup: StageTiming,
}

#[derive(Debug, Serialize, Deserialize)]
struct Throughput {
    /// Frames per wall second.
    frames_per_s: f64,
    /// Simulated seconds per wall second.
    realtime_factor: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    scenario: std::path::PathBuf,
    backend: Backend,
    lattice: Lattice,
    /// `tled` (every cell), `flsm` or `frozen` outside the operational region.
    far_field: String,
    operational_radius_m: Option<f64>,
    /// Mean lattice cells stepped by TLED per frame.
    tled_cells_mean: f64,
    hybrid: Option<hullcut_sim::HybridSteps>,
    dt_s: f64,
    dt_critical_s: f64,
    frame_interval_s: f64,
    frames: u64,
    steps: u64,
    simulated_time_s: f64,
    stable: bool,
    failure: Option<Divergence>,
    kinetic_energy_j: f64,
    inverted_cells: usize,
    cutting: Cutting,
    pieces: Vec<PieceState>,
    warnings: Vec<String>,
    timings: Timings,
    throughput: Throughput,
}

/// Runs a scenario with `[cut]`.
pub fn run(args: &Args, scenario: &Scenario) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let name = args.scenario.display().to_string();
    let mut run = ScriptedCut::from_scenario(scenario).with_context(|| format!("setting up {name}"))?;
    if let Some(gpu) = args.backend.open()? {
        run.sim.use_gpu(gpu).with_context(|| format!("--backend gpu on {name} (--backend cpu runs it)"))?;
    }
    let setup = t0.elapsed();
    for w in &run.warnings {
        tracing::warn!("{name}: {w}");
    }
    let cut = scenario.cut.as_ref().context("the scenario has no [cut]")?;
    let far_field = match (cut.operational_radius, run.sim.hybrid_steps()) {
        (None, _) => "tled",
        (Some(_), Some(_)) => "flsm",
        (Some(_), None) => "frozen",
    };
    let lattice = Lattice {
        cell_m: run.sim.lattice().cell,
        nodes: run.sim.lattice().node_count(),
        cells: run.sim.lattice().cells.len(),
    };
    tracing::info!(nodes = lattice.nodes, cells = lattice.cells, dt_s = run.sim.dt(), far_field, "cutting set up");
    let rec = match &args.rrd {
        Some(path) => {
            let rec = hullcut_viz::open_recording("hullcut-sim", &hullcut_viz::Sink::File(path.clone()))?;
            hullcut_viz::log_world(&rec)?;
            Some(rec)
        }
        None => None,
    };
    let frames = run.frames_for(scenario.run.duration);
    let pb = bar(frames, "cutting");
    let (mut collide, mut topology, mut surface, mut advance, mut frame_times) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let ms = |ms: f64| Duration::from_secs_f64(ms.max(0.0) * 1e-3);
    let (mut cut_frames, mut edges_crossed, mut tled_cells, mut steps) = (0u64, 0usize, 0usize, 0u64);
    let mut failure = None;
    let t_run = Instant::now();
    // On a rayon worker, as `hullcut sim` steps (each step's parallel passes start there).
    rayon::scope(|_| -> anyhow::Result<()> {
        for k in 0..frames {
            let clock = Instant::now();
            let outcome = match run.frame() {
                Ok(outcome) => outcome,
                Err(FrameError::Diverged(d)) => {
                    failure = Some(d);
                    break;
                }
                Err(e @ FrameError::Cut(_)) => bail!("{name}: frame {k}: {e}"),
            };
            frame_times.push(clock.elapsed());
            advance.push(ms(outcome.advance_ms));
            steps += outcome.steps as u64;
            tled_cells += run.sim.tled_cells();
            if let Some(c) = &outcome.cut {
                cut_frames += 1;
                edges_crossed += c.new_edges;
                collide.push(ms(c.collide_ms));
                topology.push(ms(c.topology_ms));
                surface.push(ms(c.surface_ms));
            }
            if let Some(rec) = &rec {
                log_frame(rec, &run, k, outcome.swept.as_ref())?;
            }
            pb.set_position(k + 1);
        }
        Ok(())
    })?;
    let run_time = t_run.elapsed().as_secs_f64().max(1e-9);
    pb.finish_and_clear();
    if let Some(rec) = &rec {
        hullcut_viz::flush(rec)?;
    }
    let done = frame_times.len() as u64;
    let topo = run.sim.topology();
    let report = Report {
        schema_version: SCHEMA_VERSION,
        kind: "cut-simulation".to_owned(),
        provenance: Provenance::current(),
        scenario: args.scenario.clone(),
        backend: args.backend,
        lattice,
        far_field: far_field.to_owned(),
        operational_radius_m: cut.operational_radius,
        tled_cells_mean: tled_cells as f64 / done.max(1) as f64,
        hybrid: run.sim.hybrid_steps(),
        dt_s: run.sim.dt(),
        dt_critical_s: run.sim.dt_critical(),
        frame_interval_s: run.interval,
        frames: done,
        steps,
        simulated_time_s: run.sim.time(),
        stable: failure.is_none(),
        failure,
        kinetic_energy_j: run.sim.kinetic_energy(),
        inverted_cells: run.sim.inverted_cells(),
        cutting: Cutting {
            cut_frames,
            edges_crossed,
            copies: topo.copies.len(),
            virtual_nodes: topo.virtual_of.len(),
            pieces: run.sim.pieces(),
        },
        pieces: run.sim.piece_states(),
        warnings: run.warnings.clone(),
        timings: Timings {
            collide: StageTiming::from_durations(&collide),
            cut_topology: StageTiming::from_durations(&topology),
            cut_surface: StageTiming::from_durations(&surface),
            advance: StageTiming::from_durations(&advance),
            frame: StageTiming::from_durations(&frame_times),
            setup: StageTiming::from_durations(&[setup]),
        },
        throughput: Throughput {
            frames_per_s: done as f64 / run_time,
            realtime_factor: done as f64 * run.interval / run_time,
        },
    };
    if !(report.kinetic_energy_j.is_finite() && report.simulated_time_s.is_finite()) {
        bail!("{name}: the kinetic energy or the simulated time is not finite; no report written");
    }
    print_summary(&report);
    if let Some(path) = &args.report {
        write_json(path, &report)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &args.rrd {
        println!("wrote {}", path.display());
    }
    if let Some(f) = &report.failure {
        bail!(
            "{name}: the body became unstable at step {} (t = {:.6} s, node {}): {}; the step was {:e} s \
             ({:.2} of the critical step: look at `run.safety`, `[material]` and how fast `cut.path` moves)",
            f.step,
            f.time,
            f.node,
            f.reason,
            report.dt_s,
            report.dt_s / report.dt_critical_s
        );
    }
    Ok(())
}

fn print_summary(r: &Report) {
    let l = &r.lattice;
    println!(
        "{} nodes, {} cells, cell {} mm; far field {}{}, {:.0} TLED cells a frame on average",
        l.nodes,
        l.cells,
        l.cell_m * 1e3,
        r.far_field,
        r.operational_radius_m.map(|m| format!(" beyond {:.1} mm of the blade", m * 1e3)).unwrap_or_default(),
        r.tled_cells_mean
    );
    let c = &r.cutting;
    println!(
        "{} frames ({:.3} s simulated), {}; cut in {} frames: {} lattice edges crossed, {} copies, {} virtual nodes, {} pieces",
        r.frames,
        r.simulated_time_s,
        if r.stable { "stable" } else { "UNSTABLE" },
        c.cut_frames,
        c.edges_crossed,
        c.copies,
        c.virtual_nodes,
        c.pieces
    );
    let t = &r.timings;
    println!(
        "ms per frame: {:.2} mean ({:.2} p95): cut collide {:.2}, topology {:.2}, surface {:.2} (frames with a cut), advance {:.2}; {:.1} frames/s, {:.3}x real time",
        t.frame.mean_ms,
        t.frame.p95_ms,
        t.collide.mean_ms,
        t.cut_topology.mean_ms,
        t.cut_surface.mean_ms,
        t.advance.mean_ms,
        r.throughput.frames_per_s,
        r.throughput.realtime_factor
    );
}

/// Logs one frame: the pieces' surfaces, the surface the blade swept this frame and its edge,
/// scalars.
fn log_frame(
    rec: &hullcut_viz::RecordingStream,
    run: &ScriptedCut,
    k: u64,
    swept: Option<&SweptSurface>,
) -> anyhow::Result<()> {
    hullcut_viz::set_frame(rec, k as i64);
    hullcut_viz::set_capture_time_ns(rec, (run.sim.time() * 1e9) as i64);
    let (vertices, triangles) = merged(&run.sim.surfaces());
    hullcut_viz::log_mesh3d(rec, "world/tissue/surface", &vertices, &triangles, TISSUE_RED)?;
    let cell = run.sim.lattice().cell;
    let edge: Vec<[f32; 3]> =
        run.blade.edge_at(run.sim.time()).iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
    hullcut_viz::log_line_strips3d(rec, "world/tool/edge", &[edge], EDGE_WHITE, (cell * 0.1) as f32)?;
    match swept {
        Some(swept) => {
            let v: Vec<[f32; 3]> = swept.vertices.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
            hullcut_viz::log_mesh3d(rec, "world/tissue/cut", &v, &swept.triangles, SWEPT_CYAN)?;
        }
        None => hullcut_viz::log_clear(rec, "world/tissue/cut")?,
    }
    hullcut_viz::log_scalar(rec, "metrics/tissue/pieces", run.sim.pieces() as f64)?;
    hullcut_viz::log_scalar(rec, "metrics/tissue/tled_cells", run.sim.tled_cells() as f64)?;
    hullcut_viz::log_scalar(rec, "metrics/accuracy/kinetic_energy_j", run.sim.kinetic_energy())?;
    Ok(())
}
