//! `hullcut bench tissue`: what the far field costs and what it gets wrong. The built-in organ
//! (the paper's size, about 30k nodes, and the large organ past 100k) cut by a scripted blade,
//! all-TLED beside the seed's hybrid settings, the hybrid with FLSM matched to the material, and
//! a far field that sleeps, run in lockstep frame by frame, so every model is compared with the
//! all-TLED body in the same state of the same cut; then the far field's failure edge: the same
//! stroke ever faster.

use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use hullcut_sim::{LARGE_ORGAN_SCALE, Scenario, ScriptedCut};
use nalgebra::Point3;

use super::bench::Table;
use crate::chart::{Scale, Series, line_chart, scatter_chart};
use crate::progress::bar;

/// Nodes within this distance of the blade's cutting edge are "near the tool", metres (the
/// issue's 2 cm).
const NEAR_M: f32 = 0.02;
/// The operational radius of the hybrid models, metres.
const RADIUS_M: f64 = 0.03;
/// Simulated time the organ settles before the blade moves, seconds.
const SETTLE_S: f64 = 0.3;
/// Simulated time after the stroke, seconds.
const AFTER_S: f64 = 0.3;
/// The stroke's length on the built-in organ (scaled with the organ), metres.
const STROKE_M: f64 = 0.11;

/// A model of the tissue's far field, as the bench names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Model {
    /// Every cell TLED: the reference.
    Tled,
    /// The seed paper's hybrid: an FLSM step every 10 TLED steps, β = 200 N/m.
    Seed,
    /// The hybrid with FLSM matched to the material (`--far-field flsm`).
    Matched,
    /// Cells at rest away from the blade sleep (`--far-field frozen`, the default far field).
    Frozen,
}

impl Model {
    const ALL: [Model; 4] = [Model::Tled, Model::Seed, Model::Matched, Model::Frozen];

    fn name(self) -> &'static str {
        match self {
            Model::Tled => "all-TLED",
            Model::Seed => "seed hybrid (FLSM every 10 steps, beta 200)",
            Model::Matched => "matched hybrid (FLSM)",
            Model::Frozen => "far field that sleeps",
        }
    }

    fn key(self) -> &'static str {
        match self {
            Model::Tled => "tled",
            Model::Seed => "seed",
            Model::Matched => "matched",
            Model::Frozen => "frozen",
        }
    }

    /// The scenario's lines for this model: `[hybrid]` and the `[cut]` keys.
    fn lines(self) -> (&'static str, String) {
        let radius = format!("operational_radius = {RADIUS_M}\n");
        match self {
            Model::Tled => ("", String::new()),
            Model::Seed => ("[hybrid]\nsubsteps = 10\nbeta = 200.0\n", radius + "far_field = \"flsm\"\n"),
            Model::Matched => ("", radius + "far_field = \"flsm\"\n"),
            Model::Frozen => ("", radius + "far_field = \"frozen\"\n"),
        }
    }
}

/// One organ size.
#[derive(Debug, Clone, Copy)]
struct Size {
    label: &'static str,
    scale: f64,
    cell: f64,
}

/// The scenario: the organ at `size` on a table, its left lobe's tip cut off by an upright
/// straight edge drawn along y at `speed` m/s after the organ settled (as
/// examples/scenarios/organ-resect.toml, scaled with the organ).
fn scenario(size: Size, model: Model, speed: f64) -> anyhow::Result<Scenario> {
    let s = size.scale;
    let stroke_s = STROKE_M * s / speed;
    let (hybrid, cut) = model.lines();
    let text = format!(
        "[body]\nshape = \"organ\"\nscale = {s}\ncell = {cell}\n\n\
         [material]\nlambda = 9310.3\nmu = 1034.5\ndensity = 1000.0\n\n\
         [run]\nduration = {duration}\ndamping = 40.0\ngravity = [0.0, 0.0, -9.81]\n\n\
         [report]\ninterval = {interval}\n\n{hybrid}\n\
         [cut]\nedge = [[{x}, {y0}, -0.002], [{x}, {y0}, {top}]]\n\
         path = [{{ time = {SETTLE_S}, offset = [0.0, 0.0, 0.0] }}, {{ time = {t1}, offset = [0.0, {stroke}, 0.0] }}]\n\
         {cut}\n[cut.table]\nfriction = 0.5\n",
        cell = size.cell,
        duration = SETTLE_S + stroke_s + AFTER_S,
        interval = 1.0 / 60.0,
        x = 0.055 * s,
        y0 = -0.05 * s,
        top = 0.045 * s,
        t1 = SETTLE_S + stroke_s,
        stroke = STROKE_M * s,
    );
    Scenario::parse(&text, &format!("bench tissue ({}, {})", size.label, model.key())).map_err(Into::into)
}

/// What one model did over a run, against the all-TLED body.
#[derive(Debug, Default, Clone)]
struct Outcome {
    nodes: usize,
    frames: u64,
    ms: Vec<f64>,
    advance_ms: Vec<f64>,
    cut_ms: Vec<f64>,
    tled_cells: f64,
    rms_near_worst: f64,
    rms_all_worst: f64,
    rms_near_sum: f64,
    pieces: usize,
    failure: Option<String>,
}

impl Outcome {
    fn mean(v: &[f64]) -> f64 {
        v.iter().sum::<f64>() / v.len().max(1) as f64
    }
}

/// Runs every model of `models` on `size` at `speed` in lockstep with all-TLED.
fn lockstep(size: Size, speed: f64, models: &[Model]) -> anyhow::Result<Vec<(Model, Outcome)>> {
    let mut runs: Vec<(Model, ScriptedCut, Outcome)> = Vec::new();
    for &m in Model::ALL.iter().filter(|m| **m == Model::Tled || models.contains(m)) {
        let run = ScriptedCut::from_scenario(&scenario(size, m, speed)?)
            .with_context(|| format!("setting up {} on the {} organ", m.name(), size.label))?;
        let nodes = run.sim.lattice().node_count();
        runs.push((m, run, Outcome { nodes, ..Outcome::default() }));
    }
    let frames = runs[0].1.frames_for(SETTLE_S + STROKE_M * size.scale / speed + AFTER_S);
    let pb = bar(frames, &format!("{} organ at {:.1} m/s", size.label, speed));
    for _ in 0..frames {
        for (m, run, out) in runs.iter_mut() {
            if out.failure.is_some() {
                continue;
            }
            let clock = Instant::now();
            match run.frame() {
                Ok(frame) => {
                    out.ms.push(clock.elapsed().as_secs_f64() * 1e3);
                    out.advance_ms.push(frame.advance_ms);
                    if let Some(c) = frame.cut {
                        out.cut_ms.push(c.collide_ms + c.topology_ms + c.surface_ms);
                    }
                    out.frames += 1;
                    out.tled_cells += run.sim.tled_cells() as f64;
                    out.pieces = run.sim.pieces();
                }
                Err(e) => out.failure = Some(format!("{}: {e}", m.name())),
            }
        }
        // Errors against the all-TLED body, near the edge where it is now and everywhere; none
        // once the reference itself has stopped.
        let (reference, rest) = runs.split_first_mut().context("no reference")?;
        if reference.2.failure.is_some() {
            break;
        }
        let time = reference.1.sim.time();
        let edge = reference.1.blade.edge_at(time);
        let a = reference.1.sim.node_positions();
        let nodes = reference.1.sim.lattice().node_count();
        let near: Vec<bool> = a[..nodes].iter().map(|p| distance_to_polyline(p, &edge) < NEAR_M).collect();
        for (_, run, out) in rest.iter_mut().filter(|(_, _, o)| o.failure.is_none()) {
            let b = run.sim.node_positions();
            let (mut sum_near, mut n_near, mut sum_all) = (0.0f64, 0usize, 0.0f64);
            for n in 0..nodes {
                let d2 = f64::from((a[n] - b[n]).norm_squared());
                sum_all += d2;
                if near[n] {
                    sum_near += d2;
                    n_near += 1;
                }
            }
            let rms_all = (sum_all / nodes as f64).sqrt() * 1e3;
            let rms_near = if n_near > 0 { (sum_near / n_near as f64).sqrt() * 1e3 } else { 0.0 };
            out.rms_all_worst = out.rms_all_worst.max(rms_all);
            out.rms_near_worst = out.rms_near_worst.max(rms_near);
            out.rms_near_sum += rms_near;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    Ok(runs.into_iter().map(|(m, _, o)| (m, o)).collect())
}

/// Distance from `p` to the polyline through `points`, metres.
fn distance_to_polyline(p: &Point3<f32>, points: &[Point3<f64>]) -> f32 {
    let p = p.cast::<f64>();
    points
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let ab = b - a;
            let t = if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
            (p - (a + ab * t)).norm()
        })
        .fold(f64::INFINITY, f64::min) as f32
}

/// Runs the benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let sizes: Vec<Size> = if quick {
        vec![Size { label: "8 mm", scale: 1.0, cell: 0.008 }, Size { label: "paper-size", scale: 1.0, cell: 0.006 }]
    } else {
        vec![
            Size { label: "paper-size", scale: 1.0, cell: 0.006 },
            Size { label: "30k", scale: 1.0, cell: 0.0026 },
            Size { label: "large", scale: LARGE_ORGAN_SCALE, cell: 0.002 },
        ]
    };
    let mut table = Table::new(&[
        "organ",
        "cell_mm",
        "nodes",
        "model",
        "blade_m_s",
        "frames",
        "ms_per_frame_mean",
        "ms_per_frame_p95",
        "advance_ms_mean",
        "cut_ms_mean_per_cut",
        "tled_cells_mean",
        "rms_near_mm_worst",
        "rms_near_mm_mean",
        "rms_all_mm_worst",
        "pieces",
        "failure",
    ]);
    let mut results: Vec<(Size, f64, Model, Outcome)> = Vec::new();
    let mut record = |size: Size, speed: f64, outcomes: Vec<(Model, Outcome)>, table: &mut Table| {
        for (m, o) in outcomes {
            let mut sorted = o.ms.clone();
            sorted.sort_by(f64::total_cmp);
            let p95 = sorted.get(((sorted.len() as f64 * 0.95).ceil() as usize).saturating_sub(1)).copied();
            let frames = o.frames.max(1) as f64;
            table.row([
                size.label.to_owned(),
                format!("{:.1}", size.cell * 1e3),
                o.nodes.to_string(),
                m.key().to_owned(),
                format!("{speed}"),
                o.frames.to_string(),
                format!("{:.2}", Outcome::mean(&o.ms)),
                format!("{:.2}", p95.unwrap_or(0.0)),
                format!("{:.2}", Outcome::mean(&o.advance_ms)),
                format!("{:.2}", Outcome::mean(&o.cut_ms)),
                format!("{:.0}", o.tled_cells / frames),
                format!("{:.4}", o.rms_near_worst),
                format!("{:.4}", o.rms_near_sum / frames),
                format!("{:.4}", o.rms_all_worst),
                o.pieces.to_string(),
                o.failure.clone().unwrap_or_default(),
            ]);
            println!(
                "{:<10} {:>7} nodes {:<44} {:>5.2} m/s: {:>8.2} ms/frame (advance {:>7.2}, cut {:>7.2}), RMS {:.3} mm near the blade, {:.3} everywhere (worst frame), {} pieces{}",
                size.label,
                o.nodes,
                m.name(),
                speed,
                Outcome::mean(&o.ms),
                Outcome::mean(&o.advance_ms),
                Outcome::mean(&o.cut_ms),
                o.rms_near_worst,
                o.rms_all_worst,
                o.pieces,
                o.failure.as_deref().map(|f| format!(", FAILED: {f}")).unwrap_or_default()
            );
            results.push((size, speed, m, o));
        }
    };
    // The stroke at a surgeon's pace on every size, every model.
    for &size in &sizes {
        let outcomes = lockstep(size, 0.11, &Model::ALL)?;
        record(size, 0.11, outcomes, &mut table);
    }
    // The failure edge: the same stroke ever faster on the paper-size organ.
    let edge_size = sizes[sizes.len().min(2) - 1];
    let speeds: &[f64] = if quick { &[1.0] } else { &[0.33, 1.0, 3.0, 10.0] };
    for &speed in speeds {
        let outcomes = lockstep(edge_size, speed, &[Model::Matched, Model::Frozen])?;
        record(edge_size, speed, outcomes, &mut table);
    }
    table.write(&out.join("tissue.csv"))?;
    let at_pace = |m: Model| results.iter().filter(move |(_, v, model, _)| *v == 0.11 && *model == m);
    let series = |point: &dyn Fn(&Outcome) -> (f64, f64), models: &[Model]| -> Vec<Series> {
        models
            .iter()
            .map(|&m| Series { label: m.name().to_owned(), points: at_pace(m).map(|(_, _, _, o)| point(o)).collect() })
            .collect()
    };
    line_chart(
        &out.join("tissue_cost.png"),
        "The organ cut by a blade stroke: cost of a 60 Hz frame against organ size",
        "lattice nodes",
        "ms per frame (cut + deformation), mean",
        (Scale::Log, Scale::Log),
        &series(&|o| (o.nodes as f64, Outcome::mean(&o.ms)), &Model::ALL),
    )?;
    let hybrids = [Model::Seed, Model::Matched, Model::Frozen];
    scatter_chart(
        &out.join("tissue_error_near.png"),
        "Cost against error near the blade (RMS within 2 cm of its edge, worst frame, vs all-TLED)",
        "ms per frame, mean (one point per organ size)",
        "RMS error near the blade, mm",
        (Scale::Log, Scale::Log),
        &series(&|o| (Outcome::mean(&o.ms), o.rms_near_worst.max(1e-4)), &hybrids),
    )?;
    scatter_chart(
        &out.join("tissue_error_all.png"),
        "Cost against error everywhere (RMS over all nodes, worst frame, vs all-TLED)",
        "ms per frame, mean (one point per organ size)",
        "RMS error everywhere, mm",
        (Scale::Log, Scale::Log),
        &series(&|o| (Outcome::mean(&o.ms), o.rms_all_worst.max(1e-4)), &hybrids),
    )?;
    let edge_series: Vec<Series> = [Model::Matched, Model::Frozen]
        .iter()
        .flat_map(|&m| {
            let points = |f: fn(&Outcome) -> f64| -> Vec<(f64, f64)> {
                results
                    .iter()
                    .filter(|(s, _, model, o)| s.label == edge_size.label && *model == m && o.failure.is_none())
                    .map(|(_, v, _, o)| (*v, f(o).max(1e-4)))
                    .collect()
            };
            [
                Series { label: format!("{}: near the blade", m.name()), points: points(|o| o.rms_near_worst) },
                Series { label: format!("{}: everywhere", m.name()), points: points(|o| o.rms_all_worst) },
            ]
        })
        .collect();
    line_chart(
        &out.join("tissue_speed.png"),
        &format!("Where the far field fails: error against the blade's speed ({} organ)", edge_size.label),
        "blade speed, m/s",
        "RMS error vs all-TLED (worst frame), mm",
        (Scale::Log, Scale::Log),
        &edge_series,
    )?;
    if let Some((s, v, m, o)) = results.iter().find(|(_, _, _, o)| o.failure.is_some()) {
        println!(
            "note: {} on the {} organ at {v} m/s stopped: {}",
            m.name(),
            s.label,
            o.failure.as_deref().unwrap_or_default()
        );
    }
    Ok(())
}
