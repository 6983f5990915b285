//! `hullcut sim`: a simulation-only scenario (no cameras), with a report and a rerun recording.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use hullcut_sim::dynamics::Divergence;
use hullcut_sim::{NodeRole, Scenario, Simulation};
use serde::{Deserialize, Serialize};

use crate::backend::Backend;
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};

/// Run a simulation-only scenario (TOML; see docs/scenario.md and examples/scenarios/).
///
/// The body is discretised on a hexahedral lattice and simulated by TLED (nonlinear FEM) where the
/// scenario's hybrid split says, FLSM elsewhere. The time step is computed from the highest
/// eigenfrequency of the lattice (power iteration) unless the scenario gives one. A run that
/// diverges stops, is reported as unstable with the step it failed at, and exits with status 1.
/// Every value in the scenario is checked against its documented range before anything is built
/// (docs/scenario.md), a run of more than 10 million TLED steps is refused, and a run whose figures
/// are not all finite writes no report and exits with status 1, naming the figure.
///
/// Writes: REPORT (JSON, docs/reports.md: reactions, probe displacements, kinetic energy, dt and
/// critical dt, stability, timings) with --report; an .rrd recording (lattice nodes coloured by
/// role under world/tissue/nodes, the embedded surface under world/tissue/surface, kinetic energy
/// and step time as scalars, at about 60 Hz of simulated time) with --rrd.
///
/// --backend gpu steps the scenario on wgpu (TLED with one-point integration, and the hybrid's
/// FLSM part and interface pull): the adapter is chosen as `hullcut gpu-info` shows
/// (HULLCUT_GPU_ADAPTER=software forces Mesa's lavapipe), the state is read back every report
/// interval, and a batch in which a cell inverted is redone on the CPU (counted in the report's
/// `gpu` object).
///
/// A scenario with `[cut]` moves a blade's cutting edge along keyed offsets and cuts the surface it
/// sweeps into the body every report.interval (1/60 s by default), as `hullcut run` cuts with
/// each frame set's pose; the operational region follows the blade (cut.operational_radius, with
/// cut.far_field "frozen" or "flsm") and the body may rest on a table (`[cut.table]`). Its report
/// (kind "cut-simulation") gives the pieces, the cut's edges, copies and virtual nodes, ms per
/// frame split into the cut's collision, topology and surfaces and the body's advance, and frames
/// per wall second; its recording the pieces' surfaces (world/tissue/surface), the swept surface
/// (world/tissue/cut) and the edge (world/tool/edge) every frame.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The scenario file (TOML).
    #[arg(long, value_name = "FILE.toml")]
    pub(super) scenario: PathBuf,
    /// Compute backend: `cpu` (rayon) or `gpu` (wgpu).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub(super) backend: Backend,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    pub(super) report: Option<PathBuf>,
    /// Log the simulation to this rerun recording (.rrd).
    #[arg(long, value_name = "FILE")]
    pub(super) rrd: Option<PathBuf>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Reaction {
    face: String,
    force_n: [f64; 3],
}

#[derive(Debug, Serialize, Deserialize)]
struct Probe {
    at_m: [f64; 3],
    displacement_m: Option<[f64; 3]>,
}

#[derive(Debug, Serialize, Deserialize)]
struct LatticeInfo {
    cell_m: f64,
    nodes: usize,
    cells: usize,
    tled_cells: usize,
    tled_nodes: usize,
    flsm_nodes: usize,
    interface_nodes: usize,
}

#[derive(Debug, Serialize, Deserialize)]
struct Stability {
    dt_s: f64,
    dt_critical_s: f64,
    omega_max_rad_s: f64,
    power_iterations: usize,
    l_over_c_s: f64,
    dt_critical_over_l_over_c: f64,
    dt_above_critical: bool,
}

#[derive(Debug, Serialize, Deserialize)]
struct Timings {
    /// Per call of advance (one TLED step, or one FLSM step with its TLED sub-steps).
    step: StageTiming,
    setup: StageTiming,
    total: StageTiming,
}

#[derive(Debug, Serialize, Deserialize)]
struct Throughput {
    element_steps_per_s: f64,
    node_steps_per_s: f64,
    realtime_factor: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    scenario: PathBuf,
    backend: Backend,
    /// The GPU backend's adapter and counts (batches on the GPU, batches redone on the CPU);
    /// null on the CPU backend.
    gpu: Option<hullcut_sim::GpuStats>,
    lattice: LatticeInfo,
    /// The hybrid's FLSM step (in TLED steps), FLSM stiffness and interface pull; null: all TLED.
    hybrid: Option<hullcut_sim::HybridSteps>,
    stability: Stability,
    steps: u64,
    simulated_time_s: f64,
    stable: bool,
    failure: Option<Divergence>,
    kinetic_energy_j: f64,
    inverted_cells_max: usize,
    reactions: Vec<Reaction>,
    probes: Vec<Probe>,
    warnings: Vec<String>,
    timings: Timings,
    throughput: Throughput,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let scenario = Scenario::load(&args.scenario)?;
    if scenario.cut.is_some() {
        return super::sim_cut::run(args, &scenario);
    }
    let mut sim =
        Simulation::from_scenario(&scenario).with_context(|| format!("setting up {}", args.scenario.display()))?;
    if let Some(gpu) = args.backend.open()? {
        sim.use_gpu(gpu)
            .with_context(|| format!("--backend gpu on {} (--backend cpu runs it)", args.scenario.display()))?;
    }
    let setup = t0.elapsed();
    for w in &sim.warnings {
        tracing::warn!("{}: {w}", args.scenario.display());
    }
    let roles = &sim.roles;
    let count = |r: NodeRole| roles.iter().filter(|&&x| x == r).count();
    let lattice = LatticeInfo {
        cell_m: sim.lattice.cell,
        nodes: sim.lattice.node_count(),
        cells: sim.lattice.cells.len(),
        tled_cells: sim.tled_cells(),
        tled_nodes: count(NodeRole::Tled) + count(NodeRole::Interface),
        flsm_nodes: count(NodeRole::Flsm),
        interface_nodes: count(NodeRole::Interface),
    };
    tracing::info!(
        nodes = lattice.nodes,
        cells = lattice.cells,
        tled_cells = lattice.tled_cells,
        dt_s = sim.dt(),
        dt_critical_s = sim.stability.dt_critical,
        "simulation set up"
    );
    let rec = match &args.rrd {
        Some(path) => {
            let rec = hullcut_viz::open_recording("hullcut-sim", &hullcut_viz::Sink::File(path.clone()))?;
            hullcut_viz::log_world(&rec)?;
            Some(rec)
        }
        None => None,
    };
    // At most MAX_STEPS TLED steps (checked here and when the simulation was built).
    let advances = sim.advances_for(scenario.run.duration).with_context(|| args.scenario.display().to_string())?;
    let per_advance = sim.dt() * sim.steps_per_advance() as f64;
    // Log at ~60 Hz of simulated time (or the scenario's interval); the float-to-integer cast
    // saturates, and the stride is at least one advance.
    let log_every = if scenario.report.interval > 0.0 { scenario.report.interval } else { 1.0 / 60.0 };
    let log_stride = ((log_every / per_advance).round() as u64).max(1);
    // The CPU steps one advance per call (so the report's step times are per step); the GPU runs
    // a log interval's advances per submission and is read back only then.
    let chunk = if args.backend == Backend::Gpu { log_stride } else { 1 };
    let pb = bar(advances, "simulating");
    // Grown as the steps run, never sized from the scenario's numbers up front.
    let mut step_times = Vec::new();
    let mut failure = None;
    let t_run = Instant::now();
    // The loop runs on a rayon worker: each step's parallel passes then start on the stepping
    // thread, instead of handing every pass to the pool and sleeping until it is done.
    rayon::scope(|_| -> anyhow::Result<()> {
        let mut done = 0;
        while done < advances {
            let n = chunk.min(advances - done);
            let t = Instant::now();
            let r = sim.advance_by(n);
            let per_advance = t.elapsed() / u32::try_from(n).unwrap_or(u32::MAX).max(1);
            step_times.push(per_advance);
            if let Err(d) = r {
                failure = Some(d);
                break;
            }
            if let Some(rec) = &rec
                && (done % log_stride == 0 || done + n == advances)
            {
                log_state(rec, &mut sim, done + n - 1, per_advance)?;
            }
            done += n;
            if done % 64 < n {
                pb.set_position(done);
            }
        }
        Ok(())
    })?;
    let run_time = t_run.elapsed();
    pb.finish_and_clear();
    if let Some(rec) = &rec {
        hullcut_viz::flush(rec)?;
    }
    let steps = sim.integrator.step;
    let simulated = sim.time();
    let reactions = sim
        .reaction_names
        .iter()
        .zip(&sim.integrator.reactions)
        .map(|(face, f)| Reaction { face: face.clone(), force_n: [f.x, f.y, f.z] })
        .collect::<Vec<_>>();
    let probes =
        sim.probe_displacements().into_iter().map(|(at, d)| Probe { at_m: at, displacement_m: d }).collect::<Vec<_>>();
    let secs = run_time.as_secs_f64().max(1e-9);
    let report = Report {
        schema_version: SCHEMA_VERSION,
        kind: "simulation".to_owned(),
        provenance: Provenance::current(),
        scenario: args.scenario.clone(),
        backend: args.backend,
        gpu: sim.gpu_stats().cloned(),
        stability: Stability {
            dt_s: sim.dt(),
            dt_critical_s: sim.stability.dt_critical,
            omega_max_rad_s: sim.stability.omega_max,
            power_iterations: sim.stability.iterations,
            l_over_c_s: sim.dt_wave,
            dt_critical_over_l_over_c: sim.stability.dt_critical / sim.dt_wave,
            dt_above_critical: sim.dt_above_critical,
        },
        throughput: Throughput {
            element_steps_per_s: lattice.tled_cells as f64 * steps as f64 / secs,
            node_steps_per_s: lattice.nodes as f64 * steps as f64 / secs,
            realtime_factor: simulated / secs,
        },
        lattice,
        hybrid: sim.hybrid_steps(),
        steps,
        simulated_time_s: simulated,
        stable: failure.is_none(),
        kinetic_energy_j: sim.integrator.kinetic_energy(),
        inverted_cells_max: sim.inverted_cells_max(),
        failure,
        reactions,
        probes,
        warnings: sim.warnings.clone(),
        timings: Timings {
            step: StageTiming::from_durations(&step_times),
            setup: StageTiming::from_durations(&[setup]),
            total: StageTiming::from_durations(&[t0.elapsed()]),
        },
    };
    if let Some(what) = first_non_finite(&report) {
        let diverged = report
            .failure
            .as_ref()
            .map(|f| format!(" (unstable from step {}: {}; {})", f.step, f.reason, instability_cause(&sim)))
            .unwrap_or_default();
        bail!("{}: {what} is not finite{diverged}; no report written", args.scenario.display());
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
        tracing::debug!(role = ?sim.roles[f.node], rest = ?sim.lattice.rest[f.node], "diverged node");
        bail!(
            "{}: the simulation became unstable at step {} (t = {:.6} s): {}; {}",
            args.scenario.display(),
            f.step,
            f.time,
            f.reason,
            instability_cause(&sim)
        );
    }
    Ok(())
}

/// The scenario keys that most likely made a run diverge, for its error message.
fn instability_cause(sim: &Simulation) -> String {
    if sim.dt_above_critical {
        format!(
            "`run.dt` = {:e} s is above the computed critical step {:e} s (give a smaller `run.dt` or \"auto\")",
            sim.dt(),
            sim.stability.dt_critical
        )
    } else {
        format!(
            "the step {:e} s is within the computed limit {:e} s, so look at `run.safety`, `[material]`, \
             `[[load]]` forces and `[[boundary]]` displacements",
            sim.dt(),
            sim.stability.dt_critical
        )
    }
}

/// The first figure of a report that is not a finite number (NaN or infinite), named by its report
/// field, with its value; `None` when all are finite.
fn first_non_finite(r: &Report) -> Option<String> {
    let s = &r.stability;
    let mut figures: Vec<(String, f64)> = vec![
        ("stability.dt_s".into(), s.dt_s),
        ("stability.dt_critical_s".into(), s.dt_critical_s),
        ("stability.omega_max_rad_s".into(), s.omega_max_rad_s),
        ("stability.l_over_c_s".into(), s.l_over_c_s),
        ("stability.dt_critical_over_l_over_c".into(), s.dt_critical_over_l_over_c),
        ("simulated_time_s".into(), r.simulated_time_s),
        ("kinetic_energy_j".into(), r.kinetic_energy_j),
        ("throughput.element_steps_per_s".into(), r.throughput.element_steps_per_s),
        ("throughput.node_steps_per_s".into(), r.throughput.node_steps_per_s),
        ("throughput.realtime_factor".into(), r.throughput.realtime_factor),
        ("lattice.cell_m".into(), r.lattice.cell_m),
    ];
    if let Some(h) = &r.hybrid {
        figures.push(("hybrid.alpha".into(), f64::from(h.alpha)));
        figures.push(("hybrid.beta".into(), f64::from(h.beta)));
    }
    if let Some(ms) = r.gpu.as_ref().and_then(|g| g.device_ms) {
        figures.push(("gpu.device_ms".into(), ms));
    }
    for (i, x) in r.reactions.iter().enumerate() {
        figures.extend(x.force_n.iter().map(|&f| (format!("reactions[{i}] ({}) force_n", x.face), f)));
    }
    for (i, p) in r.probes.iter().enumerate() {
        figures.extend(p.at_m.iter().map(|&v| (format!("probes[{i}].at_m"), v)));
        if let Some(d) = p.displacement_m {
            figures.extend(d.iter().map(|&v| (format!("probes[{i}].displacement_m"), v)));
        }
    }
    figures.into_iter().find(|(_, v)| !v.is_finite()).map(|(name, v)| format!("{name} = {v}"))
}

fn print_summary(r: &Report) {
    let l = &r.lattice;
    println!(
        "{} nodes, {} cells ({} TLED, {} FLSM nodes, {} interface), cell {} mm",
        l.nodes,
        l.cells,
        l.tled_cells,
        l.flsm_nodes,
        l.interface_nodes,
        l.cell_m * 1e3
    );
    if let Some(h) = &r.hybrid {
        println!(
            "hybrid: an FLSM step every {} TLED steps, FLSM alpha {:.3}, interface beta {:.1} N/m",
            h.substeps, h.alpha, h.beta
        );
    }
    let s = &r.stability;
    println!(
        "dt {:.4e} s (critical {:.4e} s = {:.3} L/c, omega_max {:.4e} rad/s)",
        s.dt_s, s.dt_critical_s, s.dt_critical_over_l_over_c, s.omega_max_rad_s
    );
    println!(
        "{} steps, {:.4} s simulated, {}, kinetic energy {:.3e} J, {:.2}x real time, {:.3e} element-steps/s",
        r.steps,
        r.simulated_time_s,
        if r.stable { "stable" } else { "UNSTABLE" },
        r.kinetic_energy_j,
        r.throughput.realtime_factor,
        r.throughput.element_steps_per_s
    );
    if let Some(g) = &r.gpu {
        println!(
            "GPU {}: {} batches ({} steps) on the GPU{}, {} batches ({} steps) redone on the CPU{}",
            g.adapter,
            g.batches,
            g.steps,
            g.device_ms.map(|ms| format!(" ({ms:.1} ms of device time)")).unwrap_or_default(),
            g.cpu_batches,
            g.cpu_steps,
            g.abandoned.as_ref().map(|e| format!("; given up: {e}")).unwrap_or_default()
        );
    }
    for x in &r.reactions {
        println!("reaction {}: [{:.6}, {:.6}, {:.6}] N", x.face, x.force_n[0], x.force_n[1], x.force_n[2]);
    }
    for p in &r.probes {
        match p.displacement_m {
            Some(d) => println!("probe {:?}: displacement [{:.6e}, {:.6e}, {:.6e}] m", p.at_m, d[0], d[1], d[2]),
            None => println!("probe {:?}: outside the body", p.at_m),
        }
    }
}

fn log_state(
    rec: &hullcut_viz::RecordingStream,
    sim: &mut Simulation,
    k: u64,
    step_time: Duration,
) -> anyhow::Result<()> {
    hullcut_viz::set_frame(rec, k as i64);
    hullcut_viz::set_capture_time_ns(rec, (sim.time() * 1e9) as i64);
    let x = sim.positions();
    for (role, name) in [(NodeRole::Tled, "tled"), (NodeRole::Flsm, "flsm"), (NodeRole::Interface, "interface")] {
        let pts: Vec<[f32; 3]> =
            x.iter().zip(&sim.roles).filter(|(_, r)| **r == role).map(|(p, _)| [p.x, p.y, p.z]).collect();
        if !pts.is_empty() {
            hullcut_viz::log_points3d(
                rec,
                &format!("world/tissue/nodes/{name}"),
                &pts,
                role.color(),
                (sim.lattice.cell * 0.1) as f32,
            )?;
        }
    }
    let (vertices, triangles) = sim.surface();
    let vertices: Vec<[f32; 3]> = vertices.iter().map(|p| [p.x, p.y, p.z]).collect();
    hullcut_viz::log_mesh3d(rec, "world/tissue/surface", &vertices, triangles, [200, 90, 80, 255])?;
    hullcut_viz::log_scalar(rec, "metrics/time/sim_step", step_time.as_secs_f64() * 1e3)?;
    hullcut_viz::log_scalar(rec, "metrics/accuracy/kinetic_energy_j", sim.integrator.kinetic_energy())?;
    Ok(())
}
