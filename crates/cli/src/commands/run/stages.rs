//! The pipeline's stages as threads joined by bounded channels: read → hull → pose → tissue.
//!
//! Each stage owns its state (the labelling, the tracker, the simulation) and hands a [`Work`] on;
//! nothing is shared but the dataset. A stage that fails stops, drops its channel, and the stages
//! after it finish what they hold; [`Pipeline::join`] reports the first failure. A diverged tissue
//! simulation is not an error of the pipeline: the tissue stops and the frames go on.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};
use hullcut_dataset::{Dataset, FrameSet, Mesh, label};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, silhouettes};
use hullcut_pose::{PoseEstimate, Template, Tracker, TrackerParams, ViewInput};
use hullcut_sim::CutSim;

use super::tissue::{Sweeper, Tissue, TissueStep};
use crate::backend::Carver;
use crate::commands::reconstruct::checks;
use crate::labelling::{Labelling, LabellingReport};
use crate::pose_out::no_tool_estimate;

/// What a full queue does to the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Policy {
    /// Wait: every frame set is processed.
    Block,
    /// Drop the oldest queued frame set and count it (live pacing).
    DropOldest,
}

/// Everything the stages need.
pub struct Setup {
    /// The frame sets' source.
    pub ds: Arc<Dataset>,
    /// Frame numbers to process, in order.
    pub frames: Vec<u64>,
    /// Times to replay them, each pass's capture times following the last pass's by
    /// `pass_span_ns`.
    pub repeat: u64,
    /// Capture time from one pass's first frame set to the next pass's, nanoseconds.
    pub pass_span_ns: i64,
    /// Masks from files (else segmented from the images).
    pub use_files: bool,
    /// Segmentation and labelling, when the masks are not files.
    pub labelling: Option<Labelling>,
    /// Carving.
    pub hull: HullParams,
    /// Where carving runs.
    pub carver: Carver,
    /// The blade's template, when the dataset has a tool.json.
    pub template: Option<Template>,
    /// The organ.
    pub tissue: Tissue,
    /// Frame sets per queue.
    pub queue: usize,
    /// Full-queue policy of the reader.
    pub policy: Policy,
    /// Frame sets the reader dropped.
    pub dropped: Arc<AtomicU64>,
    /// Pace the reader to the capture timestamps.
    pub realtime: bool,
    /// Set (by Ctrl-C) to stop reading; the frame sets in flight still go through.
    pub stop: Arc<AtomicBool>,
}

/// A hull label's grid and surface.
pub type LabelGrid = (u8, &'static str, Option<DenseGrid>, Option<Mesh>);

/// One frame set on its way through the stages.
pub struct Work {
    /// Frame number in the dataset.
    pub frame: u64,
    /// Which replay of the frames it belongs to (0 without `--repeat`).
    pub pass: u64,
    /// The images and masks (segmented ones when segmenting).
    pub set: FrameSet,
    /// The carved hull.
    pub occ: Option<Occupancy>,
    /// Per label: grid and closed surface.
    pub grids: Vec<LabelGrid>,
    /// The blade's pose.
    pub estimate: Option<PoseEstimate>,
    /// What the tissue did.
    pub tissue: Option<TissueStep>,
    /// How long each stage took on this frame set.
    pub times: StageTimes,
    /// When the reader started on it.
    pub started: Instant,
}

/// Stage timings (one entry per frame set that went through the stage).
#[derive(Debug, Default, Clone)]
pub struct StageTimes {
    pub read: Vec<Duration>,
    pub segment: Vec<Duration>,
    pub carve: Vec<Duration>,
    pub surface: Vec<Duration>,
    pub pose: Vec<Duration>,
    pub collide: Vec<Duration>,
    pub cut_topology: Vec<Duration>,
    pub cut_surface: Vec<Duration>,
    pub contact: Vec<Duration>,
    pub deform: Vec<Duration>,
    pub tissue_surface: Vec<Duration>,
}

impl StageTimes {
    fn fields(&self) -> [(&'static str, &Vec<Duration>); 11] {
        [
            ("read", &self.read),
            ("segment", &self.segment),
            ("carve", &self.carve),
            ("surface", &self.surface),
            ("pose", &self.pose),
            ("collide", &self.collide),
            ("cut_topology", &self.cut_topology),
            ("cut_surface", &self.cut_surface),
            ("contact", &self.contact),
            ("deform", &self.deform),
            ("tissue_surface", &self.tissue_surface),
        ]
    }

    /// Appends another frame set's timings.
    pub fn extend(&mut self, other: &StageTimes) {
        let targets = [
            &mut self.read,
            &mut self.segment,
            &mut self.carve,
            &mut self.surface,
            &mut self.pose,
            &mut self.collide,
            &mut self.cut_topology,
            &mut self.cut_surface,
            &mut self.contact,
            &mut self.deform,
            &mut self.tissue_surface,
        ];
        for (target, (_, source)) in targets.into_iter().zip(other.fields()) {
            target.extend_from_slice(source);
        }
    }

    /// The latest timing of every stage that ran, milliseconds.
    pub fn last_ms(&self) -> Vec<(&'static str, f64)> {
        self.fields().into_iter().filter_map(|(name, d)| d.last().map(|d| (name, d.as_secs_f64() * 1e3))).collect()
    }
}

/// What the tissue stage hands back at the end.
pub struct Outcome {
    /// Frame sets the reader read.
    pub read: u64,
    /// The tissue as it ended.
    pub sim: CutSim,
    /// Why the tissue stopped early, if it diverged.
    pub failure: Option<String>,
    /// How the segmented masks were labelled.
    pub labelling: Option<LabellingReport>,
}

/// The running stages.
pub struct Pipeline {
    /// Finished frame sets, in order.
    pub output: Receiver<Work>,
    reader: JoinHandle<anyhow::Result<u64>>,
    hull: JoinHandle<anyhow::Result<Option<LabellingReport>>>,
    pose: JoinHandle<anyhow::Result<()>>,
    tissue: JoinHandle<anyhow::Result<(CutSim, Option<String>)>>,
}

impl Pipeline {
    /// Waits for every stage; the first stage that failed gives the error.
    pub fn join(self) -> anyhow::Result<Outcome> {
        let join =
            |name: &'static str| move |e: Box<dyn std::any::Any + Send>| anyhow!("the {name} stage panicked: {e:?}");
        let read = self.reader.join().map_err(join("read"))?;
        let hull = self.hull.join().map_err(join("hull"))?;
        let pose = self.pose.join().map_err(join("pose"))?;
        let tissue = self.tissue.join().map_err(join("tissue"))?;
        let read = read?;
        let labelling = hull?;
        pose?;
        let (sim, failure) = tissue?;
        Ok(Outcome { read, sim, failure, labelling })
    }
}

/// Starts the stages.
pub fn spawn(setup: Setup) -> anyhow::Result<Pipeline> {
    let Setup {
        ds,
        frames,
        repeat,
        pass_span_ns,
        use_files,
        labelling,
        hull,
        carver,
        template,
        tissue,
        queue,
        policy,
        dropped,
        realtime,
        stop,
    } = setup;
    let (read_tx, read_rx) = bounded::<Work>(queue);
    let (hull_tx, hull_rx) = bounded::<Work>(queue);
    let (pose_tx, pose_rx) = bounded::<Work>(queue);
    let (out_tx, out_rx) = bounded::<Work>(queue);

    let reader = {
        let ds = Arc::clone(&ds);
        let oldest = read_rx.clone();
        std::thread::Builder::new().name("read".into()).spawn(move || {
            let pace = Pace { realtime, policy, stop: &stop, dropped: &dropped };
            let passes = Passes { frames: &frames, repeat, span_ns: pass_span_ns };
            read_stage(&ds, &passes, use_files, &pace, &read_tx, &oldest)
        })?
    };
    let hull = {
        let ds = Arc::clone(&ds);
        std::thread::Builder::new()
            .name("hull".into())
            .spawn(move || hull_stage(&ds, use_files, labelling, (carver, &hull), &read_rx, &hull_tx))?
    };
    let pose = {
        let ds = Arc::clone(&ds);
        let template = template.clone();
        std::thread::Builder::new().name("pose".into()).spawn(move || pose_stage(&ds, template, &hull_rx, &pose_tx))?
    };
    let tissue = std::thread::Builder::new()
        .name("tissue".into())
        .spawn(move || tissue_stage(tissue, template.as_ref(), &pose_rx, &out_tx))?;
    Ok(Pipeline { output: out_rx, reader, hull, pose, tissue })
}

/// How the reader keeps time and when it stops.
#[derive(Clone, Copy)]
struct Pace<'a> {
    realtime: bool,
    policy: Policy,
    stop: &'a AtomicBool,
    dropped: &'a AtomicU64,
}

/// The frame sets the reader replays: `frames`, `repeat` times, each pass `span_ns` later.
struct Passes<'a> {
    frames: &'a [u64],
    repeat: u64,
    span_ns: i64,
}

/// Reads frame sets; with `realtime` keeps to their timestamps.
fn read_stage(
    ds: &Dataset,
    passes: &Passes<'_>,
    use_files: bool,
    pace: &Pace,
    tx: &Sender<Work>,
    oldest: &Receiver<Work>,
) -> anyhow::Result<u64> {
    let Pace { realtime, policy, stop, dropped } = *pace;
    let mut read = 0;
    let start = Instant::now();
    let mut first_ts = None;
    let replays = (0..passes.repeat).flat_map(|pass| passes.frames.iter().map(move |&frame| (pass, frame)));
    for (pass, frame) in replays {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let started = Instant::now();
        let mut set = ds.read_frame_set(frame, use_files)?;
        set.timestamp_ns += pass as i64 * passes.span_ns;
        let took = started.elapsed();
        read += 1;
        if realtime {
            let first = *first_ts.get_or_insert(set.timestamp_ns);
            let due = Duration::from_nanos(u64::try_from(set.timestamp_ns - first).unwrap_or(0));
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let times = StageTimes { read: vec![took], ..StageTimes::default() };
        let mut work =
            Work { frame, pass, set, occ: None, grids: Vec::new(), estimate: None, tissue: None, times, started };
        loop {
            match (policy, tx.try_send(work)) {
                (_, Ok(())) => break,
                (_, Err(TrySendError::Disconnected(_))) => return Ok(read),
                (Policy::Block, Err(TrySendError::Full(w))) => {
                    if tx.send(w).is_err() {
                        return Ok(read);
                    }
                    break;
                }
                (Policy::DropOldest, Err(TrySendError::Full(w))) => {
                    if oldest.try_recv().is_ok() {
                        dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    work = w;
                }
            }
        }
    }
    Ok(read)
}

/// Masks (files or segmented), silhouettes, carving, surfaces. Segmenting carves the foreground's
/// hull and fits the known tool into it to label the views ([`Labelling`]): that hull, its cells
/// near the tool labelled scalpel, is the frame's (nothing is carved twice), and the labelling's
/// fit of the tool, tracked, is the frame's pose (nothing is fitted twice).
fn hull_stage(
    ds: &Dataset,
    use_files: bool,
    mut labelling: Option<Labelling>,
    (mut carver, params): (Carver, &HullParams),
    rx: &Receiver<Work>,
    tx: &Sender<Work>,
) -> anyhow::Result<Option<LabellingReport>> {
    for mut work in rx.iter() {
        let frame = work.frame;
        if use_files {
            checks::labels(ds, &work.set)?;
        }
        let mut labelled_hull = None;
        if let Some(labelling) = &mut labelling {
            let clock = Instant::now();
            let labelled = labelling.label(&work.set, &mut carver)?;
            let carve = Duration::from_secs_f64(labelled.carve_ms * 1e-3);
            work.times.segment.push(clock.elapsed().saturating_sub(carve));
            work.times.carve.push(carve);
            for (view, mask) in work.set.views.iter_mut().zip(labelled.masks) {
                if let Some(view) = view {
                    view.mask = mask;
                }
            }
            labelled_hull = labelled.occupancy;
            // The tool's track is the labelling's: the pose stage takes its estimate.
            work.estimate = labelled.estimate;
        }
        let occ = match labelled_hull {
            Some(occ) => occ,
            None => {
                let clock = Instant::now();
                let masks: Vec<Option<&image::GrayImage>> =
                    work.set.views.iter().map(|v| v.as_ref().and_then(|v| v.mask.as_ref())).collect();
                let views = silhouettes(ds.rig(), &masks).with_context(|| format!("frame {frame}"))?;
                let occ = carver.carve(&views, params).with_context(|| format!("frame {frame}"))?;
                work.times.carve.push(clock.elapsed());
                occ
            }
        };
        let clock = Instant::now();
        work.grids = label::NAMED
            .iter()
            .map(|&(l, name)| {
                let grid = DenseGrid::from_occupancy(&occ, Some(l));
                let mesh = grid.as_ref().map(DenseGrid::surface);
                (l, name, grid, mesh)
            })
            .collect();
        work.times.surface.push(clock.elapsed());
        work.occ = Some(occ);
        if tx.send(work).is_err() {
            break;
        }
    }
    Ok(labelling.as_ref().map(Labelling::report))
}

/// The blade's pose from the scalpel silhouettes, tracked.
fn pose_stage(ds: &Dataset, template: Option<Template>, rx: &Receiver<Work>, tx: &Sender<Work>) -> anyhow::Result<()> {
    let mut tracker = template.map(|t| Tracker::new(t, TrackerParams::default()));
    for mut work in rx.iter() {
        let clock = Instant::now();
        let set = &work.set;
        let estimate = match (&mut tracker, &work.occ) {
            // Segmented with the tool's geometry: its fit into the foreground's hull, tracked, is
            // the pose (fitting again to the masks drawn from it adds nothing but time).
            _ if work.estimate.is_some() => {
                work.estimate.take().unwrap_or_else(|| no_tool_estimate(work.frame, set.timestamp_ns))
            }
            (Some(tracker), Some(occ)) => {
                let inputs: Vec<Option<ViewInput>> = ds
                    .rig()
                    .cameras
                    .iter()
                    .zip(&set.views)
                    .map(|(camera, v)| v.as_ref().and_then(|v| v.mask.as_ref()).map(|mask| ViewInput { camera, mask }))
                    .collect();
                tracker.update(work.frame, set.timestamp_ns, occ, &inputs)
            }
            _ => no_tool_estimate(work.frame, set.timestamp_ns),
        };
        work.times.pose.push(clock.elapsed());
        work.estimate = Some(estimate);
        if tx.send(work).is_err() {
            break;
        }
    }
    Ok(())
}

/// Cuts the tissue with the blade swept between consecutive trusted poses and moves it on by the
/// frame sets' time.
fn tissue_stage(
    mut tissue: Tissue,
    template: Option<&Template>,
    rx: &Receiver<Work>,
    tx: &Sender<Work>,
) -> anyhow::Result<(CutSim, Option<String>)> {
    let mut sweeper = Sweeper::default();
    let mut last_ts: Option<i64> = None;
    let mut failure: Option<String> = None;
    for mut work in rx.iter() {
        let ts = work.set.timestamp_ns;
        let seconds = last_ts.map_or(0.0, |t| ((ts - t) as f64 * 1e-9).clamp(0.0, MAX_ADVANCE_S));
        last_ts = Some(ts);
        if failure.is_none() {
            let mut step = sweeper.next(work.estimate.as_ref(), template, tissue.cell);
            let hand = work.grids.iter().find(|g| g.0 == label::HAND).and_then(|g| g.2.as_ref());
            match tissue.step(&mut step, seconds, hand, &mut work.times) {
                Ok(()) => work.tissue = Some(step),
                Err(e) => failure = Some(format!("frame {}: {e}", work.frame)),
            }
        }
        if tx.send(work).is_err() {
            break;
        }
    }
    Ok((tissue.sim, failure))
}

/// The longest stretch of simulated time one frame set advances the tissue (a gap in the
/// recording does not make the simulation run for seconds).
pub const MAX_ADVANCE_S: f64 = 0.2;
