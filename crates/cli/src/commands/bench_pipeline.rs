//! `hullcut bench pipeline`: the whole loop of `hullcut run` (hull, pose, cut, deformation) on
//! frame sets already in memory, stage by stage, at the paper's organ size and finer, beside the
//! seed paper's Table II; decoding the images is timed on its own.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hullcut_dataset::label;
use hullcut_hull::{DenseGrid, carve, silhouettes};
use hullcut_pose::{Template, Tracker, TrackerParams, ViewInput, isometry_from_matrix, pose_error};
use hullcut_sim::HybridParams;
use hullcut_synth::{Scene, SceneConfig, SceneKind};
use image::GrayImage;

use super::bench::Table;
use crate::chart::{Scale, Series, line_chart};
use crate::progress::bar;
use crate::report::StageTiming;
use hullcut_pipeline::tissue::{self, Sweeper};
use hullcut_pipeline::{MAX_ADVANCE_S, StageTimes};

/// Operational radius of the hybrid configurations, metres: cells within 2 cm of the blade's
/// sweep run TLED (about four cells on each side at 5 mm).
const HYBRID_RADIUS_M: f64 = 0.02;

/// The seed paper's Table II (GeForce 9800, 2,250-2,886 nodes), milliseconds per frame:
/// reconstruction, collision, cutting, deformation.
const SEED_TABLE_II: [(&str, &str); 4] =
    [("reconstruction", "20"), ("collision", "11-13"), ("cutting", "6-7"), ("deformation", "15")];

/// One configuration of the loop.
struct Config {
    /// Hull leaf, metres.
    voxel: f64,
    /// Tissue lattice spacing, metres.
    cell: f64,
    /// The hybrid model's operational radius, metres (`None`: TLED everywhere).
    hybrid: Option<f64>,
}

impl Config {
    /// `tled` or `hybrid`, as the CSV files name the tissue model.
    fn model(&self) -> &'static str {
        if self.hybrid.is_some() { "hybrid" } else { "tled" }
    }
}

/// Runs the benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    // The resection's second pass ends near frame 120; quick runs stop during the first.
    let count: u64 = if quick { 12 } else { 150 };
    let scene = Scene::new(SceneConfig::new(SceneKind::Resect, 1, count))?;
    let cameras = scene.config().rig.len();
    let pb = bar(count, "rendering the resection scene");
    let mut masks: Vec<Vec<Option<GrayImage>>> = Vec::new();
    let mut decode = Vec::new();
    for f in 0..count {
        let views: Vec<_> = (0..cameras).map(|c| scene.render_view(f, c)).collect();
        // Decoding a frame set's six PNG images, as `hullcut run` reads them from a dataset.
        if f < 10 {
            let encoded: Vec<Vec<u8>> = views
                .iter()
                .flatten()
                .map(|v| {
                    let mut png = Vec::new();
                    v.image.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).map(|()| png)
                })
                .collect::<Result<_, _>>()
                .context("encoding a PNG")?;
            let clock = Instant::now();
            for png in &encoded {
                image::load_from_memory(png).context("decoding a PNG")?;
            }
            decode.push(clock.elapsed());
        }
        masks.push(views.into_iter().map(|v| v.map(|v| v.mask)).collect());
        pb.inc(1);
    }
    pb.finish_and_clear();
    let decode = StageTiming::from_durations(&decode);
    let extent = crate::volume::BENCH_SIDE_M;
    let configs = [
        Config { voxel: extent / 64.0, cell: 0.006, hybrid: None },
        Config { voxel: extent / 128.0, cell: 0.006, hybrid: None },
        Config { voxel: extent / 64.0, cell: 0.005, hybrid: None },
        Config { voxel: extent / 128.0, cell: 0.005, hybrid: None },
        Config { voxel: extent / 64.0, cell: 0.006, hybrid: Some(HYBRID_RADIUS_M) },
        Config { voxel: extent / 64.0, cell: 0.005, hybrid: Some(HYBRID_RADIUS_M) },
    ];
    let template = Template::new(&scene.scalpel().geometry)?;
    let stages =
        ["carve", "surface", "pose", "collide", "cut_topology", "cut_surface", "contact", "deform", "tissue_surface"];
    let mut stage_table =
        Table::new(&["voxel_mm", "cell_mm", "model", "nodes", "frames", "stage", "mean_ms", "p95_ms"]);
    let mut summary = Table::new(&[
        "voxel_mm",
        "cell_mm",
        "model",
        "nodes",
        "frames",
        "total_mean_ms",
        "total_p95_ms",
        "fps",
        "decode_mean_ms",
        "tip_mm_mean",
        "normal_deg_mean",
        "trusted",
        "pieces",
        "tled_cells_mean",
    ]);
    let mut series: Vec<Series> = Vec::new();
    for config in &configs {
        let hull = crate::volume::hull_params(&scene.config().rig, config.voxel)?;
        let hybrid = config.hybrid.map(|radius| HybridParams { radius, ..HybridParams::default() });
        let mut sim = tissue::build("organ", config.cell, hybrid, None)?;
        let mut tled_cells = Vec::new();
        let nodes = sim.sim.lattice().node_count();
        let mut tracker = Tracker::new(template.clone(), TrackerParams::default());
        let mut sweeper = Sweeper::default();
        let mut times = StageTimes::default();
        let mut totals = Vec::new();
        let (mut tips, mut normals, mut trusted) = (Vec::new(), Vec::new(), 0);
        let mut last_ts = None;
        let pb = bar(
            count,
            &format!("voxel {:.2} mm, cell {} mm, {}", config.voxel * 1e3, config.cell * 1e3, config.model()),
        );
        for (f, frame_masks) in masks.iter().enumerate() {
            let f = f as u64;
            let started = Instant::now();
            let refs: Vec<Option<&GrayImage>> = frame_masks.iter().map(Option::as_ref).collect();
            let clock = Instant::now();
            let occ = carve(&silhouettes(&scene.config().rig, &refs)?, &hull)?;
            times.carve.push(clock.elapsed());
            let clock = Instant::now();
            let mut hand = None;
            for &(l, _) in &label::NAMED {
                if let Some(grid) = DenseGrid::from_occupancy(&occ, Some(l)) {
                    std::hint::black_box(grid.surface());
                    if l == label::HAND {
                        hand = Some(grid);
                    }
                }
            }
            times.surface.push(clock.elapsed());
            let clock = Instant::now();
            let inputs: Vec<Option<ViewInput>> = scene
                .config()
                .rig
                .cameras
                .iter()
                .zip(&refs)
                .map(|(camera, mask)| mask.map(|mask| ViewInput { camera, mask, image: None }))
                .collect();
            let ts = scene.frame_timestamp(f);
            let estimate = tracker.update(f, ts, &occ, &inputs);
            times.pose.push(clock.elapsed());
            if let (true, Some(p)) = (estimate.valid, &estimate.pose) {
                trusted += 1;
                let truth = isometry_from_matrix(&scene.truth_pose(f).tool_to_world).context("a true pose")?;
                let e = pose_error(p, &template, &truth);
                tips.push(e.tip_mm);
                normals.push(e.normal_deg);
            }
            let seconds = last_ts.map_or(0.0, |t: i64| (ts.saturating_sub(t) as f64 * 1e-9).clamp(0.0, MAX_ADVANCE_S));
            last_ts = Some(ts);
            let mut step = sweeper.next(Some(&estimate), Some(&template), config.cell);
            sim.step(&mut step, seconds, hand.as_ref(), &mut times).with_context(|| format!("frame {f}"))?;
            tled_cells.push(step.tled_cells as f64);
            totals.push(started.elapsed());
            pb.inc(1);
        }
        pb.finish_and_clear();
        let mean = |v: &[f64]| if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
        let total = StageTiming::from_durations(&totals);
        let row = |name: &str, d: &[Duration]| {
            let t = StageTiming::from_durations(d);
            [
                format!("{:.3}", config.voxel * 1e3),
                (config.cell * 1e3).to_string(),
                config.model().to_owned(),
                nodes.to_string(),
                count.to_string(),
                name.to_owned(),
                format!("{:.3}", t.mean_ms),
                format!("{:.3}", t.p95_ms),
            ]
        };
        let fields = [
            &times.carve,
            &times.surface,
            &times.pose,
            &times.collide,
            &times.cut_topology,
            &times.cut_surface,
            &times.contact,
            &times.deform,
            &times.tissue_surface,
        ];
        for (name, d) in stages.iter().zip(fields) {
            stage_table.row(row(name, d));
        }
        stage_table.row(row("total", &totals));
        let fps = 1e3 / total.mean_ms;
        summary.row([
            format!("{:.3}", config.voxel * 1e3),
            (config.cell * 1e3).to_string(),
            config.model().to_owned(),
            nodes.to_string(),
            count.to_string(),
            format!("{:.3}", total.mean_ms),
            format!("{:.3}", total.p95_ms),
            format!("{fps:.2}"),
            format!("{:.3}", decode.mean_ms),
            format!("{:.3}", mean(&tips)),
            format!("{:.3}", mean(&normals)),
            trusted.to_string(),
            sim.sim.pieces().to_string(),
            format!("{:.1}", mean(&tled_cells)),
        ]);
        println!(
            "voxel {:.2} mm, cell {} mm, {} ({nodes} nodes, {:.0} TLED cells mean): deformation {:.1} ms; {:.1} ms per frame set (p95 {:.1}), {fps:.1} fps; tip {:.2} mm; {} piece(s)",
            config.voxel * 1e3,
            config.cell * 1e3,
            config.model(),
            mean(&tled_cells),
            StageTiming::from_durations(&times.deform).mean_ms,
            total.mean_ms,
            total.p95_ms,
            mean(&tips),
            sim.sim.pieces()
        );
        // The chart: time per stage against the tissue's size, one line per stage and hull leaf.
        let leaf = format!("{:.2} mm hull", config.voxel * 1e3);
        let charted = [
            (
                "reconstruction",
                [&times.carve, &times.surface].map(|d| StageTiming::from_durations(d).mean_ms).iter().sum(),
            ),
            (
                "cutting",
                [&times.cut_topology, &times.cut_surface].map(|d| StageTiming::from_durations(d).mean_ms).iter().sum(),
            ),
            ("deformation", StageTiming::from_durations(&times.deform).mean_ms),
            ("total", total.mean_ms),
        ];
        let coarse = config.voxel > extent / 100.0;
        if config.hybrid.is_some() {
            // The hybrid model changes the deformation only: one line for it.
            let label = "deformation, hybrid".to_owned();
            let point = (nodes as f64, StageTiming::from_durations(&times.deform).mean_ms);
            match series.iter_mut().find(|s| s.label == label) {
                Some(s) => s.points.push(point),
                None => series.push(Series { label, points: vec![point] }),
            }
            continue;
        }
        for (stage, ms) in charted {
            // Cutting and deformation do not depend on the hull: one line each, from the coarse hull.
            let per_leaf = matches!(stage, "reconstruction" | "total");
            if !per_leaf && !coarse {
                continue;
            }
            let label = if per_leaf { format!("{stage}, {leaf}") } else { stage.to_owned() };
            let point = (nodes as f64, ms);
            match series.iter_mut().find(|s| s.label == label) {
                Some(s) => s.points.push(point),
                None => series.push(Series { label, points: vec![point] }),
            }
        }
    }
    let mut seed = Table::new(&["stage", "seed_ms"]);
    for (stage, ms) in SEED_TABLE_II {
        seed.row([stage.to_owned(), ms.to_owned()]);
    }
    stage_table.write(&out.join("pipeline_stages.csv"))?;
    summary.write(&out.join("pipeline.csv"))?;
    seed.write(&out.join("pipeline_seed_table2.csv"))?;
    println!("decoding six PNG images per frame set: {:.1} ms mean (timed apart from the loop)", decode.mean_ms);
    line_chart(
        &out.join("pipeline.png"),
        "Whole loop, frame sets in memory: ms per frame set by stage",
        "tissue lattice nodes (6 mm and 5 mm cells)",
        "ms per frame set, mean (2 cores)",
        (Scale::Linear, Scale::Linear),
        &series,
    )?;
    println!("wrote {}", out.join("pipeline.png").display());
    Ok(())
}
