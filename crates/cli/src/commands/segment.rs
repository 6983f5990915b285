//! `hullcut segment`: label masks (hand, scalpel) from a dataset's images, scored against its truth.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hullcut_capture::segment::{IouAccumulator, SegmentationReport};
use hullcut_dataset::{Dataset, FrameSet};
use image::GrayImage;
use serde::{Deserialize, Serialize};

use crate::backend::Carver;
use crate::frames::parse_frames;
use crate::labelling::{LabelMethod, LabelSource, LabelTrace, Labelling, LabellingReport};
use crate::logging::CameraLogger;
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};
use crate::volume::{MIN_VIEWS, WorkspaceArg};
use crate::weak::WeakArg;

/// Segment a dataset's images into label masks (0 background, 1 hand, 2 scalpel) and score them.
///
/// Foreground comes from a per-pixel background model of each camera, robust to shading, cast
/// shadows and exposure change: from its empty-scene images (CAM/background*.png) when it has
/// them, else from the recording itself (the median of frames spread over it, the moving hand
/// rejected); isolated pixels are removed and small holes closed. The labels: with the dataset's
/// tool.json, the known tool is fitted into the hull of the foreground (carved at --voxel in the
/// working volume; at twice --voxel farther than 1.5 cm from where the tool's track predicts it,
/// at 20 fps or more) and drawn into every view, the hand's occlusion respected: its pixels are
/// the scalpel, the rest of the foreground the hand, no colour model needed. Where the tool cannot
/// be fitted, and without a tool.json, the colours learned from the recording label the foreground:
/// from the trusted frames' geometric labels, and from the masks/ of the frames named by
/// --label-frames; until a trusted frame has taught them, from up to ten frames whose fit agrees
/// with the silhouettes but is not trusted, at nearly the pose of the frame before's (only the
/// pixels that fit alone decides: the drawn tool where no hull cell lies in front of it, the hand
/// far from it; not where the hand's colours explain the tool's; such colours only guide the
/// fit, and label no frame alone). Nothing is tuned to one
/// glove: no colour is written in the code. Where the
/// dataset has masks/, the masks are scored against them (IoU per label).
///
/// Writes: OUT/masks/CAM/NNNNNN.png with --out; REPORT (JSON: foreground method per camera, the
/// frame sets labelled by geometry, by colour or left unknown, the learned colours, IoU,
/// precision and recall per label, timings per frame set) with --report; an .rrd (images and
/// predicted masks under world/cams/NAME, where the labels came from under labelling/source and
/// the learned colours under metrics/appearance/LABEL/{colour,pixels} and the share of the drawn
/// blade they call the hand's under metrics/appearance/blade_as_hand, the possible shadows given
/// back to the table under metrics/shadows/on_table, the pixels an untrusted fit that agreed
/// with the silhouettes taught the colours under metrics/appearance/taught, every --rrd-every
/// frames)
/// with --rrd.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The dataset.
    #[arg(long, value_name = "DIR")]
    dataset: PathBuf,
    /// Frames to segment: A:B (half-open) or N (the first N).
    #[arg(long, value_name = "A:B|N")]
    frames: Option<String>,
    /// Write the predicted masks under OUT/masks/.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Log images and predicted masks to this rerun recording.
    #[arg(long, value_name = "FILE")]
    rrd: Option<PathBuf>,
    /// Log every N-th frame to the .rrd.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    rrd_every: u64,
    /// Frames whose masks/ seed the learned colours (comma-separated).
    #[arg(long, value_name = "F,F,...", value_delimiter = ',')]
    label_frames: Vec<u64>,
    /// What labels the foreground: both (the tool's geometry, sharpened by the learned colours,
    /// and the colours alone where the tool cannot be fitted), geometry (the fitted tool alone),
    /// colour (the colours of --label-frames alone; tool.json ignored).
    #[arg(long, value_enum, value_name = "METHOD", default_value_t = LabelMethod::Both)]
    labels: LabelMethod,
    /// When a pixel the foreground test calls background, but that differs from it by half
    /// its tolerances, becomes foreground where the other views' hull covers it (a hand or glove of
    /// the table's colour, a grey blade over a grey table): `never`, `always`, or `track-lost`,
    /// from the frame set after the tool's track was refused in 6 of the last 30 frame sets on (the
    /// report's `labelling.weak_foreground_from` says where). It costs a second foreground test
    /// and a carving that keeps what one view alone refutes: some 30 ms a frame set on six 640x480
    /// views. It brings some recordings' lost tracks back and loses others (docs/benchmarks.md,
    /// "Weak foreground once the track is lost"), so it is not on by default.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = WeakArg::Never)]
    weak_foreground: WeakArg,
    /// The same as `--weak-foreground always`.
    #[arg(long)]
    confirm_weak_foreground: bool,
    /// With segmented masks: while searches of the hull's thin parts for a lost tool find no
    /// trusted fit, search one frame set in at most N (every frame set until two fail in a row,
    /// then every second, every fourth...). A failed search costs 100-400 ms on two cores: a
    /// steadier frame rate where the tool is lost for long (random:691 in random:701: 3.3 -> 5.6
    /// fps with 4), but fewer chances to find it again (random:769 in random:773: 48 -> 2 frame
    /// sets trusted, 126 -> 0 of the organ's edges cut). The report counts both
    /// (`labelling.counters.searches`, `searches_paused`).
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::builder::RangedU64ValueParser::<u32>::new().range(1..=64))]
    search_gap: u32,
    /// Leaf of the foreground's hull that the tool is fitted into, metres (twice it away from
    /// the tool while its track predicts it closely: see `run --help`).
    #[arg(long, value_name = "METRES", default_value_t = 0.4 / 128.0)]
    voxel: f64,
    /// The working volume, world metres (default: dataset.toml's, else the rig's).
    #[arg(long, value_name = "MINX,MINY,MINZ,MAXX,MAXY,MAXZ", allow_hyphen_values = true)]
    workspace: Option<WorkspaceArg>,
}

/// Frame sets at most that wait for learned colours (their masks held in memory).
const MAX_DEFERRED: usize = 64;

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    dataset: String,
    frames: [u64; 2],
    frame_sets: usize,
    views: usize,
    dropped_views: usize,
    labelling: LabellingReport,
    accuracy: Option<SegmentationReport>,
    parameters: hullcut_capture::segment::SegmentParams,
    timings: Timings,
}

#[derive(Debug, Serialize, Deserialize)]
struct Timings {
    /// Labelling one frame set: foreground, hull, the tool's fit and drawing (all cameras).
    segment: StageTiming,
    /// Its parts: the foreground (background model, clean-up) ...
    foreground: StageTiming,
    /// ... carving the foreground's hull ...
    carve: StageTiming,
    /// ... and the tool's fit and drawing its labels.
    geometry: StageTiming,
    /// ... which splits into the fit's evidence (thin parts, provisional labels) ...
    evidence: StageTiming,
    /// ... the tracker's fit and confidence ...
    fit: StageTiming,
    /// ... and drawing the tool and the hand's depth into the views.
    draw: StageTiming,
    /// Labelling a frame set again by the learned colours, once they were learned (frame sets
    /// the tool's fit did not label with trust; not in `segment`, and their second reading not
    /// in `read`).
    relabel: StageTiming,
    /// Reading and decoding one frame set's PNGs.
    read: StageTiming,
    total: StageTiming,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let ds = Dataset::open(&args.dataset)?;
    let range = parse_frames(args.frames.as_deref(), ds.meta().frame_count)?;
    let volume = crate::volume::resolve(args.workspace, Some(&ds), ds.rig())?;
    crate::commands::reconstruct::checks::voxel(args.voxel, volume.aabb.extent())?;
    let hull =
        hullcut_hull::HullParams { min_views: MIN_VIEWS, ..hullcut_hull::HullParams::new(volume.aabb, args.voxel) };
    let tool = ds.tool()?;
    let mut labelling = Labelling::new(&ds, tool.as_ref(), hull.clone(), &args.label_frames, args.labels)?;
    crate::weak::set_up(&mut labelling, &ds, args.weak_foreground, args.confirm_weak_foreground)?;
    labelling.set_search_gap(args.search_gap);
    let mut carver = Carver::Cpu;
    let score = ds.has_masks();
    let rec = match &args.rrd {
        Some(path) => {
            let rec = hullcut_viz::open_recording("hullcut-segment", &hullcut_viz::Sink::File(path.clone()))?;
            hullcut_viz::log_world(&rec)?;
            let cams = CameraLogger::new(&rec, ds.rig())?;
            crate::logging::log_appearance_style(&rec)?;
            Some((rec, cams))
        }
        None => None,
    };
    let frames: Vec<u64> = ds.frame_numbers().into_iter().filter(|f| range.contains(f)).collect();
    let pb = bar(frames.len() as u64, "segmenting");
    let mut accuracy = IouAccumulator::new();
    let (mut read_times, mut segment_times) = (Vec::<Duration>::new(), Vec::<Duration>::new());
    let (mut fg_times, mut carve_times, mut geometry_times) = (Vec::new(), Vec::new(), Vec::new());
    let (mut evidence_times, mut fit_times, mut draw_times) = (Vec::new(), Vec::new(), Vec::new());
    let ms = |x: f64| Duration::from_secs_f64(x * 1e-3);
    let mut views = 0;
    // Scores, writes and logs one frame set's masks.
    let mut emit =
        |set: &mut FrameSet, masks: Vec<Option<GrayImage>>, segment_ms: f64, trace: LabelTrace| -> anyhow::Result<()> {
            let frame = set.frame;
            for (view, mask) in set.views.iter_mut().zip(masks) {
                let (Some(view), Some(mask)) = (view, mask) else { continue };
                views += 1;
                if let Some(truth) = &view.mask {
                    accuracy.add(view.camera, &mask, truth)?;
                }
                if let Some(out) = &args.out {
                    let name = &ds.meta().cameras[view.camera];
                    let dir = out.join("masks").join(name);
                    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
                    let path = dir.join(hullcut_dataset::frame_file_name(frame));
                    mask.save(&path).with_context(|| format!("writing {}", path.display()))?;
                }
                view.mask = Some(mask);
            }
            if let Some((rec, cams)) = &rec
                && frame.is_multiple_of(args.rrd_every)
            {
                hullcut_viz::set_frame(rec, frame as i64);
                hullcut_viz::set_capture_time_ns(rec, set.timestamp_ns);
                cams.log_frame_set(rec, set)?;
                hullcut_viz::log_scalar(rec, "metrics/time/segment", segment_ms)?;
                crate::logging::log_labelling(rec, &trace)?;
            }
            Ok(())
        };
    // Frame sets the tool could not label with trust wait (up to MAX_DEFERRED of them) for the
    // colours that later frames teach.
    let mut deferred: Vec<(u64, Vec<Option<GrayImage>>, f64, LabelTrace)> = Vec::new();
    for &frame in &frames {
        let t = Instant::now();
        let mut set = ds.read_frame_set(frame, score)?;
        read_times.push(t.elapsed());
        let t = Instant::now();
        // On the pool, as the main job's loop segments ([`hullcut_pipeline::on_pool`]).
        let labelled = hullcut_pipeline::on_pool(|| labelling.label(&set, &mut carver))?;
        segment_times.push(t.elapsed());
        fg_times.push(ms(labelled.foreground_ms));
        carve_times.push(ms(labelled.carve_ms));
        if let Some(s) = &labelled.stats {
            geometry_times.push(ms(s.evidence_ms + s.fit_ms + s.draw_ms));
            evidence_times.push(ms(s.evidence_ms));
            fit_times.push(ms(s.fit_ms));
            draw_times.push(ms(s.draw_ms));
        }
        if let Some(e) = &labelled.estimate {
            tracing::debug!(frame, valid = e.valid, confidence = e.confidence, reason = ?e.reason, from_thin = ?labelled.stats.as_ref().map(|s| s.from_thin_parts), ms = ?labelled.stats.as_ref().map(|s| [s.evidence_ms, s.fit_ms, s.draw_ms]), carve_ms = labelled.carve_ms, "tool");
        }
        let segment_ms = t.elapsed().as_secs_f64() * 1e3;
        let trace = labelling.trace(&labelled);
        match labelled.source {
            LabelSource::Unknown | LabelSource::UntrustedGeometry
                if args.labels == LabelMethod::Both && deferred.len() < MAX_DEFERRED =>
            {
                tracing::debug!(frame, source = ?labelled.source, "the tool's fit is not trusted: the frame set waits for learned colours");
                deferred.push((frame, labelled.masks, segment_ms, trace));
            }
            _ => emit(&mut set, labelled.masks, segment_ms, trace)?,
        }
        pb.inc(1);
    }
    // The colours still being learned are taken before relabelling by them.
    labelling.settle()?;
    let mut relabel_times = Vec::new();
    for (frame, masks, segment_ms, trace) in deferred {
        let mut set = ds.read_frame_set(frame, score)?;
        let t = Instant::now();
        let (masks, trace) = match labelling.relabel_by_colour(&set, &mut carver)? {
            Some(relabelled) => (
                relabelled.masks,
                LabelTrace {
                    source: relabelled.source,
                    learned: labelling.learned(),
                    blade_as_hand: labelling.blade_as_hand(),
                    // Relabelling by colour asks no shadows: the frame set's first pass did.
                    shadow_on_table: trace.shadow_on_table,
                    weak_confirmed: trace.weak_confirmed,
                    // Relabelling by colour teaches nothing: the frame set's first pass did.
                    taught: trace.taught,
                    // Relabelling segments nothing again: the first pass's pixels.
                    segmented: trace.segmented,
                    // Nor searches the hull again, nor takes a lesson.
                    hull_search: trace.hull_search,
                    lesson_ms: trace.lesson_ms,
                },
            ),
            None => (masks, trace),
        };
        relabel_times.push(t.elapsed());
        emit(&mut set, masks, segment_ms, trace)?;
    }
    pb.finish_and_clear();
    if let Some((rec, _)) = &rec {
        hullcut_viz::flush(rec)?;
    }
    let accuracy = score.then(|| accuracy.report());
    let seg = StageTiming::from_durations(&segment_times);
    let labels = labelling.report();
    println!(
        "segmented {} frame sets ({views} images): {:.2} ms per frame set (mean; foreground {:.2} ms); labels from the \
         tool's geometry in {}, from learned colours in {}, from an untrusted fit in {}, unknown in {} ({} of \
         these two relabelled by the colours learned)",
        frames.len(),
        seg.mean_ms,
        StageTiming::from_durations(&fg_times).mean_ms,
        labels.counters.geometry,
        labels.counters.colour,
        labels.counters.untrusted,
        labels.counters.unknown,
        labels.counters.relabelled
    );
    if labels.counters.bootstrapped > 0 {
        println!(
            "  the colours were first taught by {} frame set(s) whose fit agreed with the silhouettes but was not \
             trusted (the drawn tool where no hull cell lies in front of it, the hand far from it)",
            labels.counters.bootstrapped
        );
    }
    for (what, learned) in [("learned", &labels.appearance), ("sharpening", &labels.sharpening_appearance)] {
        for c in learned {
            if let Some(rgb) = c.rgb {
                println!("  {what} {} colour ~ rgb{rgb:?} from {:.0} pixels", c.label, c.pixels);
            }
        }
    }
    if let Some(acc) = &accuracy {
        for l in acc.labels.iter().chain([&acc.foreground]) {
            println!(
                "  {:8} IoU pooled {:.4}, mean {:.4}, min {:.4} over {} views",
                l.name,
                l.iou_pooled.unwrap_or(f64::NAN),
                l.iou_mean.unwrap_or(f64::NAN),
                l.iou_min.unwrap_or(f64::NAN),
                l.views
            );
        }
    }
    if let Some(path) = &args.report {
        let parameters = labelling.params().clone();
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "segmentation".to_owned(),
            provenance: Provenance::current(),
            dataset: args.dataset.display().to_string(),
            frames: [range.start, range.end],
            frame_sets: frames.len(),
            views,
            dropped_views: ds.dropped().iter().filter(|d| range.contains(&d.frame)).count(),
            labelling: labels,
            accuracy,
            parameters,
            timings: Timings {
                segment: seg,
                foreground: StageTiming::from_durations(&fg_times),
                carve: StageTiming::from_durations(&carve_times),
                geometry: StageTiming::from_durations(&geometry_times),
                evidence: StageTiming::from_durations(&evidence_times),
                fit: StageTiming::from_durations(&fit_times),
                draw: StageTiming::from_durations(&draw_times),
                relabel: StageTiming::from_durations(&relabel_times),
                read: StageTiming::from_durations(&read_times),
                total: StageTiming::from_durations(&[t0.elapsed()]),
            },
        };
        write_json(path, &report)?;
    }
    Ok(())
}
