//! `hullcut bench loop`: the whole loop as `hullcut run` runs it (the hullcut-pipeline crate's
//! threads and bounded queues, frame sets in memory, nothing logged), on several recordings, at
//! several hull leaves, tissue cells and frame sets in flight, with mask files and segmenting:
//! sustained fps and latency against the blade's error and the tissue's, so that a lab can pick
//! its operating point.
//!
//! The tissue's error is the resected piece's volume against a reference: the same organ at a
//! finer lattice ([`REFERENCE_CELL_M`]) cut by the true blade poses, so that it holds both the
//! lattice's coarseness and the pose's error. A run that does not cut the piece off has an error
//! of 100%. Beside it, the piece the true poses cut off at the configuration's own cell tells the
//! lattice's share apart: where they cut nothing off either, the lattice lost the piece, not the
//! pose.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use hullcut_dataset::Dataset;
use hullcut_hull::HullParams;
use hullcut_pipeline::measure::{Measured, reference_resection_ml, run_measured, truth_and_template};
use hullcut_pipeline::{Carver, FrameSource, LabelMethod, Labelling, Setup, tissue};
use hullcut_rig::RigPreset;
use hullcut_synth::{Appearance, Scene, SceneConfig, SceneKind, ToolKind, synthesize};

use super::bench::Table;
use crate::chart::{Scale, Series, scatter_chart};
use crate::progress::bar;
use crate::report::StageTiming;
use crate::volume::MIN_VIEWS;

/// The reference tissue's lattice spacing, metres (finer than every configuration's).
pub const REFERENCE_CELL_M: f64 = 0.004;

/// One recording: a rig, a look and a tool, in the built-in resection scene.
struct Recording {
    rig: RigPreset,
    look: &'static str,
    tool: ToolKind,
}

impl Recording {
    fn name(&self) -> String {
        format!("{} {} {}", self.rig.name(), self.look, self.tool.name())
    }
}

/// The built-in scene's rig and look; lab8 (eight 1280x720 cameras, one overhead, one strongly
/// distorted) with a dark bare hand and the pointed scalpel; a seeded random rig in a seeded
/// random look.
const RECORDINGS: [Recording; 3] = [
    Recording { rig: RigPreset::Default, look: "classic", tool: ToolKind::Standard },
    Recording { rig: RigPreset::Lab8, look: "skin-dark", tool: ToolKind::Pointed },
    Recording { rig: RigPreset::Random(7), look: "random:23", tool: ToolKind::Standard },
];

/// One configuration of the loop.
#[derive(Debug, Clone, Copy)]
struct Config {
    /// Hull leaf, metres.
    voxel: f64,
    /// Tissue lattice spacing, metres.
    cell: f64,
    /// Frame sets in flight.
    in_flight: usize,
    /// Segment the images (else the recording's mask files).
    segment: bool,
}

/// Runs the benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let frames: u64 = if quick { 12 } else { 150 };
    let recordings = if quick { &RECORDINGS[..1] } else { &RECORDINGS[..] };
    let extent = crate::volume::BENCH_SIDE_M;
    let configs: Vec<Config> = if quick {
        vec![
            Config { voxel: extent / 64.0, cell: 0.006, in_flight: 1, segment: false },
            Config { voxel: extent / 128.0, cell: 0.005, in_flight: 2, segment: false },
            Config { voxel: extent / 128.0, cell: 0.005, in_flight: 1, segment: true },
        ]
    } else {
        let mut c = Vec::new();
        for voxel in [extent / 64.0, extent / 128.0] {
            for cell in [0.006, 0.005] {
                for in_flight in [1, 2] {
                    c.push(Config { voxel, cell, in_flight, segment: false });
                }
            }
        }
        c.push(Config { voxel: extent / 128.0, cell: 0.005, in_flight: 1, segment: true });
        c.push(Config { voxel: extent / 128.0, cell: 0.005, in_flight: 2, segment: true });
        c
    };
    let tmp = tempfile::tempdir().context("creating a temporary folder for the recordings")?;
    let mut table = Table::new(&[
        "recording",
        "cameras",
        "width",
        "height",
        "masks",
        "voxel_mm",
        "cell_mm",
        "in_flight",
        "frames",
        "fps",
        "latency_p50_ms",
        "latency_p95_ms",
        "segment_ms",
        "carve_ms",
        "pose_ms",
        "cut_ms",
        "contact_ms",
        "deform_ms",
        "trusted",
        "tip_mm_mean",
        "pieces",
        "piece_ml",
        "reference_piece_ml",
        "tissue_error_pct",
        "same_cell_reference_ml",
    ]);
    let (mut speed, mut accuracy) = (Vec::<Series>::new(), Vec::<Series>::new());
    for recording in recordings {
        let name = recording.name();
        let look = Appearance::from_name(recording.look).with_context(|| format!("unknown look {}", recording.look))?;
        let mut config = SceneConfig::new(SceneKind::Resect, 1, frames);
        config.rig = recording.rig.rig();
        config.tool = recording.tool;
        config.appearance = look;
        config.stroke_depth = super::run::BUILTIN_STROKE_DEPTH;
        (config.truth_meshes, config.depth_maps) = (false, false);
        let scene = Scene::new(config)?;
        let dir = tmp.path().join(name.replace([' ', ':'], "_"));
        let pb = bar(frames, &format!("rendering {name}"));
        synthesize(&scene, &dir, &name, false, &|| pb.inc(1)).with_context(|| format!("rendering {name}"))?;
        pb.finish_and_clear();
        let ds = Arc::new(Dataset::open(&dir)?);
        let (template, truth) = truth_and_template(&ds)?;
        let reference = reference_resection_ml(&ds, &template, &truth, REFERENCE_CELL_M)?;
        // The true poses at each configuration's own cell: what the lattice alone gives.
        let mut same_cell = std::collections::BTreeMap::new();
        for config in &configs {
            let key = (config.cell * 1e6).round() as u64;
            if let std::collections::btree_map::Entry::Vacant(e) = same_cell.entry(key) {
                e.insert(reference_resection_ml(&ds, &template, &truth, config.cell)?);
            }
        }
        println!(
            "{name}: the resected piece cut by the true poses at {} mm cells: {}",
            REFERENCE_CELL_M * 1e3,
            reference.map_or_else(|| "not cut off".to_owned(), |v| format!("{v:.1} ml"))
        );
        let frame_numbers = ds.frame_numbers();
        let with_masks = hullcut_pipeline::stages::preload(&ds, &frame_numbers, true, &|| {});
        let without_masks = hullcut_pipeline::stages::preload(&ds, &frame_numbers, false, &|| {});
        let (with_masks, without_masks) = (Arc::new(with_masks), Arc::new(without_masks));
        let volume = crate::volume::of_rig(ds.rig())?;
        let (width, height) = ds.rig().cameras.first().map_or((0, 0), |c| (c.width, c.height));
        for config in &configs {
            let sets = if config.segment { &without_masks } else { &with_masks };
            let source = FrameSource::Memory(Arc::clone(&ds), Arc::clone(sets));
            let hull = HullParams { min_views: MIN_VIEWS, ..HullParams::new(volume.aabb, config.voxel) };
            let m = run_measured(loop_setup(&ds, source, &hull, config)?, &template, &truth)
                .with_context(|| format!("{name}, hull {:.2} mm, cell {} mm", config.voxel * 1e3, config.cell * 1e3))?;
            let error = reference.map(|r| m.tissue_error_pct(r));
            let (fps, tip_mm, latency) = (m.fps(), m.tip_mm_mean(), StageTiming::from_durations(&m.latencies));
            let masks = if config.segment { "segment" } else { "files" };
            let stage = |name: &str| stage_ms(&m, name);
            table.row([
                name.clone(),
                ds.rig().len().to_string(),
                width.to_string(),
                height.to_string(),
                masks.to_owned(),
                format!("{:.3}", config.voxel * 1e3),
                format!("{}", config.cell * 1e3),
                config.in_flight.to_string(),
                m.frames.to_string(),
                format!("{fps:.2}"),
                format!("{:.2}", latency.p50_ms),
                format!("{:.2}", latency.p95_ms),
                format!("{:.2}", stage("segment")),
                format!("{:.2}", stage("carve")),
                format!("{:.2}", stage("pose")),
                format!("{:.2}", stage("collide") + stage("cut_topology") + stage("cut_surface")),
                format!("{:.2}", stage("contact")),
                format!("{:.2}", stage("deform")),
                m.trusted.to_string(),
                if tip_mm.is_finite() { format!("{tip_mm:.3}") } else { String::new() },
                m.pieces.to_string(),
                format!("{:.2}", m.resected_ml.unwrap_or(0.0)),
                reference.map_or_else(String::new, |r| format!("{r:.2}")),
                error.map_or_else(String::new, |e| format!("{e:.2}")),
                same_cell
                    .get(&((config.cell * 1e6).round() as u64))
                    .copied()
                    .flatten()
                    .map_or_else(|| "not cut off".to_owned(), |r| format!("{r:.2}")),
            ]);
            println!(
                "{name}, {masks}, hull {:.2} mm, cell {} mm, {} in flight: {:.1} fps, latency {:.1} ms p50 / {:.1} p95; \
                 tip {:.2} mm ({} of {} trusted); {} piece(s), tissue error {}",
                config.voxel * 1e3,
                config.cell * 1e3,
                config.in_flight,
                fps,
                latency.p50_ms,
                latency.p95_ms,
                tip_mm,
                m.trusted,
                m.frames,
                m.pieces,
                error.map_or_else(|| "not measured".to_owned(), |e| format!("{e:.1}%"))
            );
            let label = format!("{}, {masks}", recording.rig.name());
            push(&mut speed, &label, (latency.p95_ms, fps));
            if tip_mm.is_finite() {
                push(&mut accuracy, &format!("{label}, blade tip mm"), (1e3 / fps, tip_mm));
            }
            if let Some(e) = error {
                push(&mut accuracy, &format!("{label}, tissue error %"), (1e3 / fps, e));
            }
        }
    }
    table.write(&out.join("loop.csv"))?;
    scatter_chart(
        &out.join("loop_speed.png"),
        "The whole loop on 2 cores: throughput against latency (hull leaf, tissue cell, frame sets in flight)",
        "latency from capture to cut surface, p95 (ms)",
        "frame sets per second, sustained",
        (Scale::Linear, Scale::Linear),
        &speed,
    )?;
    scatter_chart(
        &out.join("loop_accuracy.png"),
        "The whole loop: blade tip error (mm) and resected volume error (%) against time per frame set",
        "ms per frame set (1 / fps)",
        "blade tip error, mm; tissue error, %",
        (Scale::Linear, Scale::Log),
        &accuracy,
    )?;
    println!("wrote {} and {}", out.join("loop_speed.png").display(), out.join("loop_accuracy.png").display());
    Ok(())
}

fn push(series: &mut Vec<Series>, label: &str, point: (f64, f64)) {
    match series.iter_mut().find(|s| s.label == label) {
        Some(s) => s.points.push(point),
        None => series.push(Series { label: label.to_owned(), points: vec![point] }),
    }
}

/// The loop of one configuration on `source`: the organ at the configuration's cell, segmenting
/// with the tool's geometry and the learned colours when it does not read mask files (no label
/// masks drawn but those that teach the colours: nothing here logs them).
fn loop_setup(ds: &Arc<Dataset>, source: FrameSource, hull: &HullParams, config: &Config) -> anyhow::Result<Setup> {
    let organ = tissue::build("organ", config.cell, None, None)?;
    let labelling = if config.segment {
        let tool = ds.tool()?;
        Some(Labelling::new(ds, tool.as_ref(), hull.clone(), &[], LabelMethod::Both)?)
    } else {
        None
    };
    let mut setup = Setup::new(source, ds.frame_numbers(), !config.segment, hull.clone(), Carver::Cpu, organ);
    setup.labelling = labelling;
    // Nothing is logged here: no frame set's label masks are used (those that teach the colours
    // are drawn all the same), as in a run that logs nothing.
    setup.masks_every = None;
    setup.in_flight = config.in_flight;
    Ok(setup)
}

/// A stage's milliseconds per frame set: the mean of its runs for the stages that run once a
/// frame set, the sum over the run divided by the frame sets for the cut's parts (which run only
/// on frame sets that cut).
fn stage_ms(m: &Measured, name: &str) -> f64 {
    let t = &m.times;
    let mean = |d: &[Duration]| StageTiming::from_durations(d).mean_ms;
    let per_frame = |d: &[Duration]| d.iter().map(Duration::as_secs_f64).sum::<f64>() * 1e3 / m.frames.max(1) as f64;
    match name {
        "segment" => mean(&t.segment),
        "carve" => mean(&t.carve),
        "pose" => mean(&t.pose),
        "collide" => per_frame(&t.collide),
        "cut_topology" => per_frame(&t.cut_topology),
        "cut_surface" => per_frame(&t.cut_surface),
        "contact" => mean(&t.contact),
        "deform" => mean(&t.deform),
        _ => 0.0,
    }
}
