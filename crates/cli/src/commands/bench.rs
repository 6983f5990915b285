//! `hullcut bench`: speed against accuracy, as CSV and PNG charts.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use hullcut_sim::{Lattice, Material, Scenario, Simulation, Tled, TledParams, stability};
use nalgebra::{Point3, Vector3};

use crate::chart::{Scale, Series, line_chart};
use crate::progress::bar;

/// Benchmark a stage: speed against accuracy, written as CSV tables and PNG charts.
///
/// Targets: `sim`, `tissue`, `hull`, `pose`, `segment`, `pipeline`, `loop`, `cut` and `backends`.
/// `tissue` measures (the built-in organ at 6 mm, the paper's size, about 3k nodes; at 2.6 mm,
/// about 30k; the large organ at 2 mm, 106k; 8 and 6 mm with --quick) the organ's left lobe cut
/// off by a scripted blade stroke (an upright edge drawn at 0.11 m/s, 60 Hz frames, as
/// examples/scenarios/organ-resect.toml), the models run in lockstep frame by frame
///   tissue.csv        per organ, model (all-TLED; the seed's hybrid, an FLSM step every 10 TLED
///                     steps and beta 200 N/m; the hybrid with FLSM matched to the material; the
///                     far field that sleeps; the hybrids with a 3 cm operational radius) and
///                     blade speed: ms per frame (mean, p95; the advance and the cut apart), TLED
///                     cells per frame, the RMS distance of the lattice nodes from the all-TLED
///                     body's within 2 cm of the blade's edge (worst frame, mean) and everywhere
///                     (worst frame), pieces at the end, and a failure if any;
///   tissue_cost.png   ms per frame against nodes per model;
///   tissue_error_near.png, tissue_error_all.png
///                     ms per frame against RMS error near the blade and everywhere;
///   tissue_speed.png  the far field's failure edge: the error of the matched hybrid and the far
///                     field that sleeps against the blade's speed (0.33 to 10 m/s) on the
///                     30k-node organ.
/// `cut` measures (the cutting stress cases: a 6 x 4 x 3 cm block of 5 mm cells on a table, stroked
/// at 30 fps: speed up to 2 m/s, tilt, lattice phase, two passes beside each other, depth, a flat
/// blade, grazing, crossing and repeated cuts, cuts a cell and half a cell apart, 24 fragments)
///   cut_stress.csv, cut_stress_cost.png, cut_stress_pieces.png
///                     per case: pieces found and expected, stable (no divergence, no inverted
///                     cell left, peak kinetic energy under the block's m g H), the failure if
///                     any, inverted cells, edges cut, copies, slivers torn, ms per frame and per
///                     cut; the charts: cost against peak energy, pieces found against expected;
///                     the command fails when a case does.
/// `pipeline` measures (the `resect` scene, the built-in scene of `hullcut run`: 150 frame sets of
/// 6 x 640x480 truth masks held in memory, the built-in organ at 6 mm, the paper's size, and 5 mm)
///   pipeline_stages.csv per configuration (hull leaf 6.25 / 3.1 mm x tissue cell 6 / 5 mm) and
///                     stage (carve, surface, pose, collide, cut_topology, cut_surface, deform for
///                     the frame gap, tissue_surface, total): mean and p95 ms, the loop run on
///                     one thread (rayon inside the stages), nothing logged;
///   pipeline.csv, pipeline.png
///                     per configuration: total per frame set, fps, blade tip and normal error,
///                     trusted poses, pieces at the end, and PNG decoding of a frame set's six
///                     images timed apart; the chart: reconstruction, cutting, deformation and total
///                     against the tissue's nodes, per hull leaf;
///   pipeline_seed_table2.csv
///                     the seed paper's Table II stage times, to read beside ours.
/// `loop` measures (the built-in resection scene, 150 frame sets, on three recordings: the default
/// rig in its classic look, lab8 with a dark bare hand and the pointed scalpel, random:7 in the
/// look random:23; the default one, 12 frame sets, with --quick) the loop as `hullcut run` runs
/// it, its threads and bounded queues, frame sets in memory, nothing logged
///   loop.csv          per recording, masks (files, segment), hull leaf (6.25, 3.1 mm), tissue
///                     cell (6, 5 mm) and frame sets in flight (1, 2): sustained fps, latency from
///                     capture to cut surface (p50, p95), ms per frame set of segmentation,
///                     carving, pose, cutting, contact, deformation measured inside the loop, the
///                     blade tip's error (trusted frames), the pieces, and the tissue's error: the
///                     resected piece's volume against the one the true poses cut at 4 mm cells
///                     (100% when it was not cut off), and the piece the true poses cut off at
///                     the configuration's own cell ("not cut off": the lattice alone loses it);
///   loop_speed.png, loop_accuracy.png
///                     fps against latency p95, one point per configuration; blade tip error
///                     and tissue error against ms per frame set.
/// `hull` measures (a rendered cut-scene frame's truth masks on three rigs: the default six
/// 640x480 cameras, lab8's eight 1280x720 cameras with the pointed scalpel, random:7)
///   hull.csv, hull_speed.png, hull_accuracy.png
///                     carving time at 2 and 1 mm leaves (4 and 2 with --quick) in the box
///                     around hand and tool (padded by 2 cm) and in the rig's own volume: the
///                     octree (conservative, and with slivers trimmed), a dense grid (every leaf
///                     tested, 2 mm), the octree on the GPU (when there is an adapter; uploads and
///                     read-back included), and Open3D's VoxelGrid.carve_silhouette on the same
///                     masks undistorted (with --open3d-python and --open3d-script); IoU per
///                     label with the exact visual hull (a quarter leaf) against time;
///   hull_robustness.csv, hull_robustness_noise.png, hull_robustness_cameras.png
///                     where carving breaks (default rig, 3.1 mm): IoU with the clean hull
///                     against salt-and-pepper noise in every view (0-5% of the pixels flipped)
///                     and against the number of cameras (the first 2-6), for carve_votes 1 and 2.
/// `segment` measures (24 frame sets of the `cut` scene at 10 fps on four recordings: the default
/// rig classic and in purple gloves with the pointed tool, lab8 with a dark bare hand and the
/// pointed tool, random:13 in the look random:23; 5 frame sets of the first two with --quick)
///   segment.csv, segment_hand.png, segment_scalpel.png
///                     per recording and labelling method (colour: the colours of two masked
///                     frames alone; geometry: the fitted tool alone; both: the default), pooled
///                     IoU per label and of the foreground against the truth (the two masked
///                     frames not scored), scalpel precision and recall, ms per frame set (all
///                     cameras; its foreground part apart), frame sets labelled by geometry, by
///                     colour, or left unknown; the charts: IoU against ms, one point per recording.
/// `pose` measures (rendered static, cut and hard scenes, 6 x 640x480 truth masks)
///   pose.csv, pose_leaf.png, pose_time.png
///                     the blade pose's error (normal, tip; trusted frames) against leaf size
///                     (6.3, 3.1, 1.6 mm) and against time per frame (silhouettes, carve, pose);
///   pose_cameras.png, pose_noise.png, pose_invalid.png
///                     its error and refusal rate against the number of cameras (the first 2-6)
///                     and against salt-and-pepper noise in every view (cut scene).
/// `sim` measures
///   scaling.csv/png   wall time per simulated second against lattice nodes, for all-TLED,
///                     all-FLSM and hybrid (ratio 0.4) models of the seed's liver material;
///   ratio.csv/png     the TLED ratio's accuracy (displacement error against an all-TLED run)
///                     against milliseconds of compute per 60 Hz frame, on the built-in organ
///                     (the seed paper's Table I setting);
///   stability.csv/png the measured stability edge (bisection) against the power-iteration
///                     estimate and L/c, for several Poisson ratios;
///   collision.csv     per 60 Hz frame of a blade stroke through the paper-size organ: the
///                     spatial hash of the lattice's cells and parry's BVH over them (what
///                     CutSim uses), each built and queried for the lattice edges the swept
///                     blade surface crosses (time, triangles, candidate pairs, edges, cells).
///   backends.csv/png  TLED whole steps (forces, update, constraints) in element-steps/s against
///                     lattice size, on the CPU (rayon) and on the GPU (wgpu, batches of 100 steps
///                     with the state read back after each, as `hullcut sim --backend gpu` runs);
///                     the GPU line is left out, with a warning, when there is no adapter.
/// `backends` measures backends.csv/png alone, as in `sim`, up to a million TLED cells (8 to 100
/// cells a side), for a machine with a GPU.
/// Timings are wall clock on this machine: run on an idle machine, and compare ratios within one run.
/// HULLCUT_BENCH_QUICK=1 (or --quick) shrinks every size so CI can smoke-run it.
///
/// Writes: DIR/*.csv and DIR/*.png as listed above.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// What to benchmark.
    target: Target,
    /// Output folder (created).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Small sizes and short runs (also HULLCUT_BENCH_QUICK=1).
    #[arg(long)]
    quick: bool,
    /// `hull`: a Python with open3d, numpy and opencv-python (a virtual environment; never a
    /// dependency of the build) to time Open3D's carving of the same masks beside ours.
    #[arg(long, value_name = "PYTHON", requires = "open3d_script")]
    open3d_python: Option<PathBuf>,
    /// `hull`: the script that runs Open3D's carving (shared/tools/vh_open3d.py).
    #[arg(long, value_name = "FILE", requires = "open3d_python")]
    open3d_script: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Target {
    /// The soft-tissue simulator.
    Sim,
    /// The organ being cut: the far-field models' cost against their error, at three sizes.
    Tissue,
    /// The visual hull.
    Hull,
    /// The blade pose.
    Pose,
    /// The whole loop of `hullcut run` on frame sets in memory, stage by stage on one thread.
    Pipeline,
    /// The whole loop as `hullcut run` runs it (threads, bounded queues): fps and latency against
    /// the blade's and the tissue's error, on several rigs, with mask files and segmenting.
    Loop,
    /// Segmentation: the labelling methods on several rigs and looks.
    Segment,
    /// Cutting where it fails: the stress cases.
    Cut,
    /// TLED steps on the CPU against the GPU, up to a million cells (a part of `sim`).
    Backends,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let quick = args.quick || std::env::var("HULLCUT_BENCH_QUICK").is_ok_and(|v| v == "1");
    match args.target {
        // On a rayon worker, so each step's parallel passes start on the stepping thread (as in
        // `hullcut sim`).
        Target::Sim => rayon::scope(|_| -> anyhow::Result<()> {
            kernels(&args.out, quick)?;
            scaling(&args.out, quick)?;
            ratio(&args.out, quick)?;
            stability_edge(&args.out, quick)?;
            collision(&args.out)?;
            backends(&args.out, if quick { &[4, 8] } else { &[8, 16, 24, 32, 40] }, quick)
        })?,
        Target::Backends => {
            rayon::scope(|_| backends(&args.out, if quick { &[4, 8] } else { &[8, 16, 32, 64, 100] }, quick))?
        }
        Target::Hull => {
            let open3d = args
                .open3d_python
                .clone()
                .zip(args.open3d_script.clone())
                .map(|(python, script)| super::bench_hull::Open3d { python, script });
            super::bench_hull::run(&args.out, quick, open3d.as_ref())?
        }
        Target::Pose => super::bench_pose::run(&args.out, quick)?,
        Target::Pipeline => super::bench_pipeline::run(&args.out, quick)?,
        Target::Loop => super::bench_loop::run(&args.out, quick)?,
        Target::Segment => super::bench_segment::run(&args.out, quick)?,
        Target::Cut => super::bench_cut::run(&args.out, quick)?,
        Target::Tissue => rayon::scope(|_| super::bench_tissue::run(&args.out, quick))?,
    }
    Ok(())
}

/// A CSV table: a header and rows of as many fields, written with the csv crate (a field that
/// holds a comma, a quote or a line break, such as a GPU's name, is quoted), so every row reads
/// back with the header's field count.
#[derive(Debug)]
pub(super) struct Table {
    header: Vec<&'static str>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// An empty table with these columns.
    pub(super) fn new(header: &[&'static str]) -> Self {
        Self { header: header.to_vec(), rows: Vec::new() }
    }

    /// Appends a row: as many fields as the header ([`Table::write`] refuses the table otherwise).
    pub(super) fn row(&mut self, fields: impl IntoIterator<Item = String>) {
        self.rows.push(fields.into_iter().collect());
    }

    /// Writes the table to `path` and says so.
    pub(super) fn write(&self, path: &Path) -> anyhow::Result<()> {
        let width = self.header.len();
        if let Some((k, row)) = self.rows.iter().enumerate().find(|(_, r)| r.len() != width) {
            bail!("{}: row {} has {} fields, the header {width}", path.display(), k + 1, row.len());
        }
        let context = || format!("writing {}", path.display());
        let mut w = csv::Writer::from_path(path).with_context(context)?;
        w.write_record(&self.header).with_context(context)?;
        for row in &self.rows {
            w.write_record(row).with_context(context)?;
        }
        w.flush().with_context(context)?;
        println!("wrote {}", path.display());
        Ok(())
    }
}

/// Wall seconds per simulated second of `sim`, over at least `min_wall` seconds of running.
fn cost(sim: &mut Simulation, min_wall: f64, max_advances: usize) -> anyhow::Result<f64> {
    sim.advance().map_err(|d| anyhow::anyhow!("unstable at step {}: {}", d.step, d.reason))?;
    let t0 = Instant::now();
    let s0 = sim.time();
    let mut n = 0;
    while n < max_advances && (n < 3 || t0.elapsed().as_secs_f64() < min_wall) {
        sim.advance().map_err(|d| anyhow::anyhow!("unstable at step {}: {}", d.step, d.reason))?;
        n += 1;
    }
    Ok(t0.elapsed().as_secs_f64() / (sim.time() - s0))
}

fn block(n: usize, ratio: f64) -> anyhow::Result<Scenario> {
    let side = n as f64 * 0.005;
    let text = format!(
        "[body]\nshape = \"box\"\nsize = [{side}, {side}, {side}]\ncell = 0.005\n[hybrid]\nratio = {ratio}\n\
         [[boundary]]\nfaces = [\"z-\"]\nfix = [\"x\", \"y\", \"z\"]\n[run]\ndamping = 20.0\ngravity = [0.0, 0.0, -9.81]\n"
    );
    Ok(Scenario::parse(&text, "bench block")?)
}

/// Kernel throughput on one and on two threads (the thread-scaling check): TLED internal forces
/// (element pass and node pass), a whole TLED step, and an FLSM step (w = 1), on a cube of
/// 5 mm cells of the liver material with a smooth deformation.
fn kernels(out: &Path, quick: bool) -> anyhow::Result<()> {
    let side = if quick { 10 } else { 30 };
    let lattice = Lattice::block(Point3::origin(), 0.005, [side; 3]);
    let material = Material::default();
    let u: Vec<Vector3<f32>> = lattice
        .rest
        .iter()
        .map(|p| Vector3::new(0.05 * p.y, 0.02 * p.z, 0.04 * p.x * p.x / (side as f64 * 0.005)).cast::<f32>())
        .collect();
    let masses = lattice.lumped_masses(material.density);
    let min_wall = if quick { 0.02 } else { 1.0 };
    // Calls per second of `op`, over at least `min_wall` seconds.
    let rate = |op: &mut dyn FnMut()| {
        op();
        let t0 = Instant::now();
        let mut calls = 0u64;
        while calls < 3 || t0.elapsed().as_secs_f64() < min_wall {
            op();
            calls += 1;
        }
        calls as f64 / t0.elapsed().as_secs_f64()
    };
    let mut table = Table::new(&["kernel", "threads", "nodes", "cells", "ms_per_call", "million_per_s"]);
    let mut single = std::collections::HashMap::new();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("a thread pool")?;
        let rows = pool.install(|| -> anyhow::Result<Vec<(&'static str, f64, f64)>> {
            let mut tled = Tled::new(&lattice, None, &material, TledParams::default())?;
            let mut forces = vec![Vector3::zeros(); lattice.node_count()];
            let forces_rate = rate(&mut || tled.internal_forces(&u, &mut forces));
            let mass32: Vec<f32> = masses.iter().map(|&m| m as f32).collect();
            let mut it = hullcut_sim::dynamics::Integrator::new(mass32, Vec::new(), 0, 0.0, 1e-5, f32::INFINITY);
            it.u.clone_from(&u);
            it.u_prev.clone_from(&u);
            let zero = vec![Vector3::zeros(); lattice.node_count()];
            let mut failed = false;
            let step_rate = rate(&mut || {
                tled.element_pass(&it.u);
                let model = &tled;
                failed |= it.advance_with(|i| model.node_force(i), &zero).is_err();
            });
            anyhow::ensure!(!failed, "the benchmark step diverged");
            let mut flsm = hullcut_sim::Flsm::new(&lattice, &masses, hullcut_sim::FlsmParams::default())?;
            let mut x: Vec<Vector3<f32>> =
                lattice.rest.iter().zip(&u).map(|(p, d)| p.coords.cast::<f32>() + d).collect();
            let mut v = zero.clone();
            let flsm_rate = rate(&mut || flsm.step(&mut x, &mut v, &zero, 5e-4, None));
            let cells = lattice.cells.len() as f64;
            let nodes = lattice.node_count() as f64;
            Ok(vec![
                ("tled_internal_forces", forces_rate, cells),
                ("tled_step", step_rate, cells),
                ("flsm_step", flsm_rate, nodes),
            ])
        })?;
        for (kernel, calls_per_s, items) in rows {
            let per_s = calls_per_s * items / 1e6;
            table.row([
                kernel.to_owned(),
                threads.to_string(),
                lattice.node_count().to_string(),
                lattice.cells.len().to_string(),
                format!("{:.4}", 1e3 / calls_per_s),
                format!("{per_s:.2}"),
            ]);
            if threads == 1 {
                single.insert(kernel, per_s);
            } else {
                let one = single.get(kernel).copied().unwrap_or(f64::NAN);
                println!("{kernel}: {one:.1} M/s on 1 thread, {per_s:.1} M/s on 2 ({:.2}x)", per_s / one);
            }
        }
    }
    table.write(&out.join("kernels.csv"))
}

fn scaling(out: &Path, quick: bool) -> anyhow::Result<()> {
    let sizes: &[usize] = if quick { &[4, 6] } else { &[8, 12, 16, 20, 25, 30] };
    let models = [("TLED", 1.0), ("FLSM", 0.0), ("hybrid 0.4", 0.4)];
    let mut table = Table::new(&["model", "nodes", "cells", "dt_s", "wall_s_per_simulated_s", "realtime_factor"]);
    let mut series: Vec<Series> =
        models.iter().map(|(m, _)| Series { label: (*m).to_owned(), points: Vec::new() }).collect();
    let pb = bar((sizes.len() * models.len()) as u64, "scaling");
    for &n in sizes {
        for (mi, (model, r)) in models.iter().enumerate() {
            let mut sim = Simulation::from_scenario(&block(n, *r)?)?;
            let c = cost(&mut sim, if quick { 0.05 } else { 0.5 }, if quick { 5 } else { 2000 })?;
            let nodes = sim.lattice.node_count();
            table.row([
                (*model).to_owned(),
                nodes.to_string(),
                sim.lattice.cells.len().to_string(),
                format!("{:.6e}", sim.dt()),
                format!("{c:.6e}"),
                format!("{:.4}", 1.0 / c),
            ]);
            series[mi].points.push((nodes as f64, c));
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    table.write(&out.join("scaling.csv"))?;
    line_chart(
        &out.join("scaling.png"),
        "Simulation cost against lattice size (liver material, 5 mm cells; below 1 = real time)",
        "lattice nodes",
        "wall seconds per simulated second",
        (Scale::Log, Scale::Log),
        &series,
    )?;
    println!("wrote {}", out.join("scaling.png").display());
    Ok(())
}

/// TLED whole steps per second on the CPU and on the GPU against lattice size.
fn backends(out: &Path, sizes: &[usize], quick: bool) -> anyhow::Result<()> {
    let gpu = match hullcut_gpu::Gpu::new(&hullcut_gpu::AdapterChoice::from_env()) {
        Ok(g) => Some(std::sync::Arc::new(g)),
        Err(e) => {
            tracing::warn!("backends.csv without the GPU line: {e}");
            None
        }
    };
    let cpu_label = format!("CPU (rayon, {} threads)", rayon::current_num_threads());
    let mut lines = vec![Series { label: cpu_label.clone(), points: Vec::new() }];
    if let Some(g) = &gpu {
        lines.push(Series { label: format!("GPU ({})", g.summary.info.name), points: Vec::new() });
    }
    let mut table = Table::new(&[
        "backend",
        "device",
        "nodes",
        "cells",
        "steps",
        "wall_s",
        "element_steps_per_s",
        "realtime_factor",
    ]);
    let pb = bar((sizes.len() * lines.len()) as u64, "backends");
    let (batch, min_wall) = if quick { (10, 0.02) } else { (100, 1.0) };
    for &n in sizes {
        for (li, line) in lines.iter_mut().enumerate() {
            let mut sim = Simulation::from_scenario(&block(n, 1.0)?)?;
            let device = match (li, &gpu) {
                (1, Some(g)) => {
                    sim.use_gpu(g.clone())?;
                    g.summary.info.name.clone()
                }
                _ => cpu_label.clone(),
            };
            let unstable =
                |d: hullcut_sim::dynamics::Divergence| anyhow::anyhow!("unstable at step {}: {}", d.step, d.reason);
            sim.advance_by(batch).map_err(unstable)?;
            let (t0, s0) = (Instant::now(), sim.integrator.step);
            while t0.elapsed().as_secs_f64() < min_wall {
                sim.advance_by(batch).map_err(unstable)?;
            }
            let wall = t0.elapsed().as_secs_f64();
            let steps = sim.integrator.step - s0;
            let cells = sim.tled_cells();
            let rate = (cells as u64 * steps) as f64 / wall;
            let realtime = steps as f64 * sim.dt() / wall;
            let backend = if li == 0 { "cpu" } else { "gpu" };
            let nodes = sim.lattice.node_count();
            table.row([
                backend.to_owned(),
                device,
                nodes.to_string(),
                cells.to_string(),
                steps.to_string(),
                format!("{wall:.4}"),
                format!("{rate:.4e}"),
                format!("{realtime:.4}"),
            ]);
            line.points.push((cells as f64, rate));
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    table.write(&out.join("backends.csv"))?;
    line_chart(
        &out.join("backends.png"),
        "TLED whole steps: CPU against GPU (liver material, 5 mm cells, clamped block under gravity)",
        "TLED cells",
        "element-steps per second",
        (Scale::Log, Scale::Log),
        &lines,
    )?;
    println!("wrote {}", out.join("backends.png").display());
    Ok(())
}

/// Collision of a blade stroke with the paper-size organ (rest positions), frame by frame.
fn collision(out: &Path) -> anyhow::Result<()> {
    let scenario = organ(0.0062, 1.0, 0.01)?;
    let sim = Simulation::from_scenario(&scenario)?;
    let lattice = &sim.lattice;
    let positions = &lattice.rest;
    // A 38 mm cutting edge (17 points) in the xz plane, its tip 30° down, stroking along x across
    // the organ in one second while pressing 1.5 cm into its top over the first half (4-5 mm
    // per 60 Hz frame): the swept surface is a vertical band through the organ.
    let (c30, s30) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let edge: Vec<Point3<f64>> =
        (0..17).map(|k| 0.038 * k as f64 / 16.0).map(|d| Point3::new(-d * c30, 0.0, d * s30)).collect();
    let (lo, hi) = lattice
        .rest
        .iter()
        .fold((Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN))), |(a, b), p| {
            (a.inf(p), b.sup(p))
        });
    let frames = 60;
    let pose = |f: usize| {
        let s = f as f64 / frames as f64;
        let x = lo.x - 0.04 + (hi.x - lo.x + 0.04) * s;
        let z = hi.z + 0.002 - 0.015 * (2.0 * s).min(1.0);
        nalgebra::Isometry3::translation(x, 0.5 * (lo.y + hi.y), z)
    };
    let mut table = Table::new(&[
        "frame",
        "nodes",
        "hash_ms",
        "cut_ms",
        "tree_ms",
        "tree_cut_ms",
        "triangles",
        "pairs_tested",
        "edges_cut",
        "cells_cut",
    ]);
    let (mut by_hash, mut by_tree) = (Vec::new(), Vec::new());
    for f in 1..=frames {
        let surface = hullcut_sim::SweptSurface::between(&edge, &pose(f - 1), &pose(f), lattice.cell / 2.0, 0.1)
            .context("a swept surface")?;
        let t0 = Instant::now();
        let hash = hullcut_sim::SpatialHash::new(lattice, positions, lattice.cell);
        let hash_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let cuts = hullcut_sim::cut_edges(lattice, positions, &hash, &surface);
        let cut_ms = t1.elapsed().as_secs_f64() * 1e3;
        // parry's BVH over the cells (what CutSim uses): the same cuts.
        let t2 = Instant::now();
        let tree = hullcut_sim::CellTree::new(lattice, positions);
        let tree_ms = t2.elapsed().as_secs_f64() * 1e3;
        let t3 = Instant::now();
        let tree_cuts = hullcut_sim::cut_edges(lattice, positions, &tree, &surface);
        let tree_cut_ms = t3.elapsed().as_secs_f64() * 1e3;
        if tree_cuts.edges != cuts.edges {
            bail!("frame {f}: the BVH and the spatial hash found different edges");
        }
        by_hash.push(hash_ms + cut_ms);
        by_tree.push(tree_ms + tree_cut_ms);
        table.row([
            f.to_string(),
            lattice.node_count().to_string(),
            format!("{hash_ms:.4}"),
            format!("{cut_ms:.4}"),
            format!("{tree_ms:.4}"),
            format!("{tree_cut_ms:.4}"),
            surface.triangles.len().to_string(),
            cuts.pairs_tested.to_string(),
            cuts.edges.len().to_string(),
            cuts.cells.len().to_string(),
        ]);
    }
    table.write(&out.join("collision.csv"))?;
    for v in [&mut by_hash, &mut by_tree] {
        v.sort_by(f64::total_cmp);
    }
    println!(
        "collision: {} nodes, swept-surface cut per frame (build + query), median / max: spatial hash {:.3} / {:.3} ms, parry BVH {:.3} / {:.3} ms (the same edges)",
        lattice.node_count(),
        by_hash[by_hash.len() / 2],
        by_hash[by_hash.len() - 1],
        by_tree[by_tree.len() / 2],
        by_tree[by_tree.len() - 1]
    );
    Ok(())
}

fn organ(cell: f64, ratio: f64, duration: f64) -> anyhow::Result<Scenario> {
    organ_with(cell, ratio, duration, "")
}

/// [`organ`] with more `[hybrid]` keys.
fn organ_with(cell: f64, ratio: f64, duration: f64, hybrid: &str) -> anyhow::Result<Scenario> {
    let text = format!(
        "[body]\nshape = \"organ\"\ncell = {cell}\n[hybrid]\nratio = {ratio}\n{hybrid}\
         [[boundary]]\nbox = {{ min = [-1.0, -1.0, -0.001], max = [1.0, 1.0, 0.004] }}\nfix = [\"x\", \"y\", \"z\"]\n\
         [[load]]\nbox = {{ min = [-0.02, -0.02, 0.03], max = [0.02, 0.02, 0.1] }}\nforce = [0.0, 0.0, -0.5]\n\
         [run]\nduration = {duration}\ndamping = 30.0\ngravity = [0.0, 0.0, -9.81]\n"
    );
    Ok(Scenario::parse(&text, "bench organ")?)
}

fn ratio(out: &Path, quick: bool) -> anyhow::Result<()> {
    let (cell, duration) = if quick { (0.01, 0.05) } else { (0.0062, 0.3) };
    // FLSM matched to the material (the default), then the seed's settings (an FLSM step every 10
    // TLED steps, β = 200 N/m): faster, and far softer than the tissue.
    const SEED: &str = "substeps = 10\nbeta = 200.0\n";
    let runs: Vec<(f64, &str, &str)> = [1.0, 0.8, 0.6, 0.4, 0.2, 0.0]
        .iter()
        .map(|&r| (r, "matched", ""))
        .chain([0.8, 0.4, 0.0].iter().map(|&r| (r, "seed", SEED)))
        .collect();
    let mut reference: Option<Vec<Vector3<f32>>> = None;
    let mut table =
        Table::new(&["ratio", "settings", "nodes", "tled_cells", "rms_error_mm", "max_error_mm", "ms_per_60hz_frame"]);
    let mut series = Vec::new();
    let mut reference_ms = f64::NAN;
    let pb = bar(runs.len() as u64, "ratio");
    for &(r, settings, hybrid) in &runs {
        let scenario = organ_with(cell, r, duration, hybrid)?;
        let mut sim = Simulation::from_scenario(&scenario)?;
        let t0 = Instant::now();
        while sim.time() < duration {
            sim.advance().map_err(|d| anyhow::anyhow!("ratio {r}: unstable at step {}: {}", d.step, d.reason))?;
        }
        let ms_per_frame = t0.elapsed().as_secs_f64() / sim.time() * 1e3 / 60.0;
        let u = sim.integrator.u.clone();
        let reference = reference.get_or_insert_with(|| u.clone());
        let errors: Vec<f64> = u.iter().zip(reference.iter()).map(|(a, b)| f64::from((a - b).norm()) * 1e3).collect();
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        let max = errors.iter().copied().fold(0.0, f64::max);
        table.row([
            r.to_string(),
            settings.to_owned(),
            sim.lattice.node_count().to_string(),
            sim.tled_cells().to_string(),
            format!("{rms:.6}"),
            format!("{max:.6}"),
            format!("{ms_per_frame:.4}"),
        ]);
        // The all-TLED run is the reference (zero error by definition): it is in the CSV and the
        // chart's title, not on the log axis.
        if r < 1.0 {
            let label = if settings == "seed" { format!("ratio {r}, seed's FLSM") } else { format!("ratio {r}") };
            series.push(Series { label, points: vec![(ms_per_frame, rms)] });
        } else {
            reference_ms = ms_per_frame;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    table.write(&out.join("ratio.csv"))?;
    line_chart(
        &out.join("ratio.png"),
        &format!("Hybrid TLED/FLSM on the built-in organ (all-TLED reference: {reference_ms:.2} ms per frame)"),
        "compute per 60 Hz frame (ms)",
        "RMS displacement error vs all-TLED (mm)",
        (Scale::Linear, Scale::Log),
        &series,
    )?;
    println!("wrote {}", out.join("ratio.png").display());
    Ok(())
}

fn stability_edge(out: &Path, quick: bool) -> anyhow::Result<()> {
    let nus = if quick { vec![0.3, 0.49] } else { vec![0.25, 0.3, 0.35, 0.4, 0.45, 0.48, 0.49] };
    let (n, steps, iters) = if quick { (3, 400, 4) } else { (6, 3000, 10) };
    let mut table = Table::new(&[
        "nu",
        "cells_per_side",
        "l_over_c_s",
        "estimate_s",
        "measured_edge_s",
        "estimate_over_l_over_c",
        "measured_over_l_over_c",
    ]);
    let mut est_s = Series { label: "estimate 2/ω_max (power iteration)".into(), points: Vec::new() };
    let mut meas_s = Series { label: "measured edge (bisection)".into(), points: Vec::new() };
    let mut lc_s = Series { label: "L/c".into(), points: Vec::new() };
    let pb = bar(nus.len() as u64, "stability");
    for &nu in &nus {
        let material = Material::from_young_poisson(30_000.0, nu, 1000.0);
        let h = 0.005;
        let lattice = Lattice::block(Point3::origin(), h, [n, n, n]);
        let mut tled = Tled::new(&lattice, None, &material, TledParams::default())?;
        let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
        let free = vec![[true; 3]; lattice.node_count()];
        let zero = vec![Vector3::zeros(); lattice.node_count()];
        let est = stability::estimate(&mut tled, &mass, &free, &zero, h, 500, 1e-8).dt_critical;
        let (mut lo, mut hi) = (0.5 * est, 2.0 * est);
        for _ in 0..iters {
            let mid = 0.5 * (lo + hi);
            if stability::free_run_stays_stable(&lattice, &material, mid, steps)? {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let edge = 0.5 * (lo + hi);
        let lc = h / material.wave_speed();
        table.row([
            nu.to_string(),
            n.to_string(),
            format!("{lc:.6e}"),
            format!("{est:.6e}"),
            format!("{edge:.6e}"),
            format!("{:.4}", est / lc),
            format!("{:.4}", edge / lc),
        ]);
        est_s.points.push((nu, est / lc));
        meas_s.points.push((nu, edge / lc));
        lc_s.points.push((nu, 1.0));
        pb.inc(1);
    }
    pb.finish_and_clear();
    table.write(&out.join("stability.csv"))?;
    line_chart(
        &out.join("stability.png"),
        "Explicit stability limit of the TLED lattice (free block)",
        "Poisson ratio ν",
        "time step / (L/c)",
        (Scale::Linear, Scale::Linear),
        &[est_s, meas_s, lc_s],
    )?;
    println!("wrote {}", out.join("stability.png").display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_quotes_what_it_must_and_reads_back_as_wide_as_its_header() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("backends.csv");
        let mut table = Table::new(&["backend", "device", "element_steps_per_s"]);
        // Device names as wgpu gives them hold commas (lavapipe's does).
        let lavapipe = "llvmpipe (LLVM 15.0.6, 256 bits)";
        let odd = "CPU \"rayon\", 2 threads\non two lines";
        table.row(["gpu".to_owned(), lavapipe.to_owned(), "1.5e6".to_owned()]);
        table.row(["cpu".to_owned(), odd.to_owned(), "2".to_owned()]);
        table.write(&path).expect("written");
        let mut reader = csv::Reader::from_path(&path).expect("reads");
        let width = reader.headers().expect("a header").len();
        let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("a row")).collect();
        assert_eq!((width, rows.len()), (3, 2));
        assert!(rows.iter().all(|r| r.len() == width), "{rows:?}");
        assert_eq!((&rows[0][1], &rows[1][1]), (lavapipe, odd));
        // A row of another width is refused, not written.
        let mut bad = Table::new(&["a", "b"]);
        bad.row(["1".to_owned()]);
        assert!(bad.write(&dir.path().join("bad.csv")).is_err());
        assert!(!dir.path().join("bad.csv").exists());
    }
}
