//! `hullcut segment`: label masks (hand, scalpel) from a dataset's images, scored against its truth.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hullcut_capture::segment::{IouAccumulator, Method, SegmentParams, SegmentationReport, Segmenter};
use hullcut_dataset::Dataset;
use serde::Serialize;

use crate::frames::parse_frames;
use crate::logging::CameraLogger;
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};

/// Segment a dataset's images into label masks (0 background, 1 hand, 2 scalpel) and score them.
///
/// Foreground comes from a per-pixel background model of each camera's empty-scene images
/// (CAM/background*.png), robust to shading and exposure change, or from OpenCV's MOG2 where a
/// camera has none; foreground pixels are labelled by colour class (blue glove = hand, the rest =
/// scalpel); isolated pixels are removed and small holes closed. Where the dataset has masks/, the
/// masks are scored against them (IoU per label).
///
/// Writes: OUT/masks/CAM/NNNNNN.png with --out; REPORT (JSON: method per camera, IoU, precision
/// and recall per label, timings per frame set) with --report; an .rrd (images and predicted masks
/// under world/cams/NAME every --rrd-every frames) with --rrd.
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
    #[arg(long, value_name = "N", default_value_t = 3)]
    rrd_every: u64,
}

#[derive(Debug, Serialize)]
struct Report<'a> {
    schema_version: u32,
    kind: &'static str,
    #[serde(flatten)]
    provenance: Provenance,
    dataset: String,
    frames: [u64; 2],
    frame_sets: usize,
    views: usize,
    dropped_views: usize,
    methods: Vec<Option<Method>>,
    accuracy: Option<SegmentationReport>,
    parameters: &'a str,
    timings: Timings,
}

#[derive(Debug, Serialize)]
struct Timings {
    /// Segmentation of one frame set (all cameras, in parallel).
    segment: StageTiming,
    /// Reading and decoding one frame set's PNGs.
    read: StageTiming,
    total: StageTiming,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    if args.rrd_every == 0 {
        anyhow::bail!("--rrd-every must be at least 1");
    }
    let ds = Dataset::open(&args.dataset)?;
    let range = parse_frames(args.frames.as_deref(), ds.meta().frame_count)?;
    let params = SegmentParams::default();
    let mut segmenter = Segmenter::from_dataset(&ds, params.clone())
        .with_context(|| format!("building the background models of {}", args.dataset.display()))?;
    let score = ds.has_masks();
    let rec = match &args.rrd {
        Some(path) => {
            let rec = hullcut_viz::open_recording("hullcut-segment", &hullcut_viz::Sink::File(path.clone()))?;
            hullcut_viz::log_world(&rec)?;
            let cams = CameraLogger::new(&rec, ds.rig())?;
            Some((rec, cams))
        }
        None => None,
    };
    let frames: Vec<u64> = ds.frame_numbers().into_iter().filter(|f| range.contains(f)).collect();
    let pb = bar(frames.len() as u64, "segmenting");
    let mut accuracy = IouAccumulator::new();
    let (mut read_times, mut segment_times) = (Vec::<Duration>::new(), Vec::<Duration>::new());
    let mut views = 0;
    for &frame in &frames {
        let t = Instant::now();
        let mut set = ds.read_frame_set(frame, score)?;
        read_times.push(t.elapsed());
        let t = Instant::now();
        let masks = segmenter.segment_frame_set(&set).with_context(|| format!("frame {frame}"))?;
        segment_times.push(t.elapsed());
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
            && frame % args.rrd_every == 0
        {
            hullcut_viz::set_frame(rec, frame as i64);
            hullcut_viz::set_capture_time_ns(rec, set.timestamp_ns);
            cams.log_frame_set(rec, &set)?;
            let ms = segment_times.last().map_or(0.0, |d| d.as_secs_f64() * 1e3);
            hullcut_viz::log_scalar(rec, "metrics/time/segment", ms)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    if let Some((rec, _)) = &rec {
        hullcut_viz::flush(rec)?;
    }
    let accuracy = score.then(|| accuracy.report());
    let seg = StageTiming::from_durations(&segment_times);
    println!("segmented {} frame sets ({views} images): {:.2} ms per frame set (mean)", frames.len(), seg.mean_ms);
    if let Some(acc) = &accuracy {
        for l in &acc.labels {
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
        let parameters = format!("{params:?}");
        let report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "segmentation",
            provenance: Provenance::current(),
            dataset: args.dataset.display().to_string(),
            frames: [range.start, range.end],
            frame_sets: frames.len(),
            views,
            dropped_views: ds.dropped().iter().filter(|d| range.contains(&d.frame)).count(),
            methods: (0..ds.meta().cameras.len()).map(|c| segmenter.method(c)).collect(),
            accuracy,
            parameters: &parameters,
            timings: Timings {
                segment: seg,
                read: StageTiming::from_durations(&read_times),
                total: StageTiming::from_durations(&[t0.elapsed()]),
            },
        };
        write_json(path, &report)?;
    }
    Ok(())
}
