//! `hullcut bench segment`: the labelling methods (colour only, geometry only, both, and both with
//! the weak foreground the other views confirm) side by side on recordings of several rigs and
//! looks, one of each seeded random: pooled IoU per label against milliseconds per frame set.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hullcut_capture::segment::{IouAccumulator, LabelScore};
use hullcut_dataset::{Dataset, FrameSet};
use hullcut_hull::HullParams;
use hullcut_rig::RigPreset;
use hullcut_synth::{Appearance, Scene, SceneConfig, SceneKind, ToolKind, synthesize};

use super::bench::Table;
use crate::backend::Carver;
use crate::chart::{Scale, Series, scatter_chart};
use crate::labelling::{LabelMethod, Labelling};
use crate::report::StageTiming;
use crate::volume::MIN_VIEWS;

/// One recording: a rig, a look and a tool.
struct Setup {
    rig: RigPreset,
    look: &'static str,
    tool: ToolKind,
}

impl Setup {
    fn name(&self) -> String {
        format!("{} {} {}", self.rig.name(), self.look, self.tool.name())
    }
}

/// The built-in rig in its classic look and in purple gloves with the pointed tool; lab8 (eight
/// 1280x720 cameras) with a bare hand; a seeded random rig in a seeded random look (seeds no test
/// uses).
const SETUPS: [Setup; 4] = [
    Setup { rig: RigPreset::Default, look: "classic", tool: ToolKind::Standard },
    Setup { rig: RigPreset::Default, look: "purple-nitrile", tool: ToolKind::Pointed },
    Setup { rig: RigPreset::Lab8, look: "skin-dark", tool: ToolKind::Pointed },
    Setup { rig: RigPreset::Random(13), look: "random:23", tool: ToolKind::Standard },
];

/// A labelling method, with or without the weak foreground the other views confirm
/// (`--confirm-weak-foreground`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Variant {
    method: LabelMethod,
    weak: bool,
}

impl Variant {
    fn name(self) -> String {
        if self.weak { format!("{}+weak", self.method.name()) } else { self.method.name().to_owned() }
    }
}

const VARIANTS: [Variant; 4] = [
    Variant { method: LabelMethod::Colour, weak: false },
    Variant { method: LabelMethod::Geometry, weak: false },
    Variant { method: LabelMethod::Both, weak: false },
    Variant { method: LabelMethod::Both, weak: true },
];

/// Frames whose truth masks teach the colour-only method; no method is scored on them.
const LABEL_FRAMES: [u64; 2] = [0, 1];

/// One row of segment.csv.
struct Row {
    setup: String,
    cameras: usize,
    width: u32,
    height: u32,
    variant: Variant,
    scored: usize,
    timing: StageTiming,
    foreground_ms: f64,
    scores: [LabelScore; 3],
    counts: [u64; 4],
}

/// Runs the segmentation benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let frames: u64 = if quick { 5 } else { 24 };
    let setups = if quick { &SETUPS[..2] } else { &SETUPS[..] };
    let tmp = tempfile::tempdir().context("creating a temporary folder for the recordings")?;
    let mut rows = Vec::new();
    for setup in setups {
        let name = setup.name();
        let look = Appearance::from_name(setup.look).with_context(|| format!("unknown look {}", setup.look))?;
        let mut config = SceneConfig::new(SceneKind::Cut, 5, frames);
        config.rig = setup.rig.rig();
        config.tool = setup.tool;
        config.appearance = look;
        config.fps = 10.0;
        (config.truth_meshes, config.depth_maps) = (false, false);
        let scene = Scene::new(config)?;
        let dir = tmp.path().join(name.replace([' ', ':'], "_"));
        synthesize(&scene, &dir, &name, false, &|| {}).with_context(|| format!("rendering {name}"))?;
        let ds = Dataset::open(&dir)?;
        let sets: Vec<FrameSet> =
            ds.frame_numbers().into_iter().map(|f| ds.read_frame_set(f, true)).collect::<Result<_, _>>()?;
        let volume = crate::volume::resolve(None, Some(&ds), ds.rig())?;
        let hull = HullParams { min_views: MIN_VIEWS, ..HullParams::new(volume.aabb, 0.4 / 128.0) };
        let tool = ds.tool()?;
        let (width, height) = ds.rig().cameras.first().map_or((0, 0), |c| (c.width, c.height));
        for variant in VARIANTS {
            let method = variant.method;
            let label_frames: &[u64] = if method == LabelMethod::Colour { &LABEL_FRAMES } else { &[] };
            let mut labelling = Labelling::new(&ds, tool.as_ref(), hull.clone(), label_frames, method)?;
            if variant.weak {
                labelling.confirm_weak_foreground(&ds)?;
            }
            let mut carver = Carver::Cpu;
            let mut acc = IouAccumulator::new();
            let (mut times, mut fg) = (Vec::new(), Vec::new());
            for set in &sets {
                let t = Instant::now();
                let labelled = labelling.label(set, &mut carver)?;
                times.push(t.elapsed());
                fg.push(Duration::from_secs_f64(labelled.foreground_ms * 1e-3));
                if LABEL_FRAMES.contains(&set.frame) {
                    continue;
                }
                for (view, mask) in set.views.iter().zip(&labelled.masks) {
                    if let (Some(view), Some(mask), Some(truth)) =
                        (view, mask, view.as_ref().and_then(|v| v.mask.as_ref()))
                    {
                        acc.add(view.camera, mask, truth)?;
                    }
                }
            }
            let report = acc.report();
            let mut labels = report.labels.into_iter();
            let (Some(hand), Some(scalpel)) = (labels.next(), labels.next()) else {
                anyhow::bail!("{name}: the accuracy report lacks a label");
            };
            labelling.settle()?;
            let c = labelling.report().counters;
            let row = Row {
                setup: name.clone(),
                cameras: ds.rig().len(),
                width,
                height,
                variant,
                scored: sets.iter().filter(|s| !LABEL_FRAMES.contains(&s.frame)).count(),
                timing: StageTiming::from_durations(&times),
                foreground_ms: StageTiming::from_durations(&fg).mean_ms,
                scores: [hand, scalpel, report.foreground],
                counts: [c.geometry, c.colour, c.untrusted, c.unknown],
            };
            println!(
                "{name}, {}: hand IoU {:.3}, scalpel {:.3}, foreground {:.3}; {:.1} ms per frame set (foreground {:.1})",
                variant.name(),
                row.scores[0].iou_pooled.unwrap_or(f64::NAN),
                row.scores[1].iou_pooled.unwrap_or(f64::NAN),
                row.scores[2].iou_pooled.unwrap_or(f64::NAN),
                row.timing.mean_ms,
                row.foreground_ms
            );
            rows.push(row);
        }
    }
    write_outputs(out, &rows)
}

fn write_outputs(out: &Path, rows: &[Row]) -> anyhow::Result<()> {
    let mut table = Table::new(&[
        "recording",
        "cameras",
        "width",
        "height",
        "method",
        "weak_foreground",
        "frame_sets_scored",
        "ms_mean",
        "ms_p50",
        "ms_p95",
        "foreground_ms_mean",
        "hand_iou",
        "scalpel_iou",
        "foreground_iou",
        "scalpel_precision",
        "scalpel_recall",
        "by_geometry",
        "by_colour",
        "untrusted_fit",
        "unknown",
    ]);
    let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for r in rows {
        let [hand, scalpel, fg] = &r.scores;
        table.row([
            r.setup.clone(),
            r.cameras.to_string(),
            r.width.to_string(),
            r.height.to_string(),
            r.variant.method.name().to_owned(),
            r.variant.weak.to_string(),
            r.scored.to_string(),
            format!("{:.3}", r.timing.mean_ms),
            format!("{:.3}", r.timing.p50_ms),
            format!("{:.3}", r.timing.p95_ms),
            format!("{:.3}", r.foreground_ms),
            f(hand.iou_pooled),
            f(scalpel.iou_pooled),
            f(fg.iou_pooled),
            f(scalpel.precision),
            f(scalpel.recall),
            r.counts[0].to_string(),
            r.counts[1].to_string(),
            r.counts[2].to_string(),
            r.counts[3].to_string(),
        ]);
    }
    table.write(&out.join("segment.csv"))?;
    for (k, label) in ["hand", "scalpel"].iter().enumerate() {
        let series: Vec<Series> = VARIANTS
            .iter()
            .map(|&v| Series {
                label: v.name(),
                points: rows
                    .iter()
                    .filter(|r| r.variant == v)
                    .filter_map(|r| Some((r.timing.mean_ms, r.scores[k].iou_pooled?)))
                    .collect(),
            })
            .collect();
        let path = out.join(format!("segment_{label}.png"));
        scatter_chart(
            &path,
            &format!("Segmentation: {label} IoU (pooled) against time, one point per recording"),
            "ms per frame set (all cameras)",
            &format!("{label} IoU"),
            (Scale::Log, Scale::Linear),
            &series,
        )?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
