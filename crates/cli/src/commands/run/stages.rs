//! The pipeline's stages as threads joined by bounded channels: read → hull → pose → tissue.
//!
//! Each stage owns its state (the labelling, the tracker, the simulation) and hands a [`Work`] on;
//! nothing is shared but the dataset. A stage that fails returns its error and sets the
//! pipeline's abort flag: the reader stops reading, the stages after it finish what they hold,
//! and [`Pipeline::join`] hands back the first failure (a panic as its message) with everything
//! the stages can still report. A diverged tissue simulation is not an error of the pipeline: the
//! tissue stops and the frames go on.
//!
//! The reader goes on past a camera image it cannot use (a corrupt PNG, a camera whose files stop
//! mid-recording, a mask with unknown labels): the frame set goes on without that view, or is left
//! out when no view is left; every such fault is counted and listed ([`checks::Faults`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};
use hullcut_dataset::{Dataset, FrameSet, Mesh, label};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, silhouettes};
use hullcut_pose::{PoseEstimate, Template, Tracker, TrackerParams, ViewInput};
use hullcut_sim::CutSim;

use super::tissue::{Sweeper, Tissue, TissueStep};
use crate::backend::Carver;
use crate::commands::reconstruct::checks::{self, Faults};
use crate::labelling::{Labelling, LabellingReport};
use crate::pose_out::no_tool_estimate;

/// The longest `--realtime` waits between two frame sets, seconds. A longer gap in the capture
/// times (a paused recording, a clock jump, a corrupt timestamp 31 years on), or one backwards,
/// is not waited out: it is counted ([`ReadOutcome::gaps_skipped`]) and the pacing starts again
/// from the frame set after it.
pub const MAX_REALTIME_GAP_S: f64 = 5.0;

/// The longest one sleep of the paced reader, so that Ctrl-C and a failed stage stop it soon.
const SLEEP_SLICE: Duration = Duration::from_millis(50);

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

/// What a stage hands back when it ends: what it has to report, and its error if it failed.
type StageEnd<T> = (T, anyhow::Result<()>);

/// What the reader did.
#[derive(Debug, Default)]
pub struct ReadOutcome {
    /// Frame sets read and handed on.
    pub read: u64,
    /// Camera images and frame sets left out (unreadable, unknown labels), counted and listed.
    pub faults: Faults,
    /// Capture-time gaps over [`MAX_REALTIME_GAP_S`] (or backwards) that `--realtime` did not
    /// wait out.
    pub gaps_skipped: u64,
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

/// What the stages hand back at the end.
pub struct Outcome {
    /// What the reader did (empty when it panicked).
    pub read: ReadOutcome,
    /// The tissue as it ended (`None` when its stage panicked).
    pub sim: Option<CutSim>,
    /// Why the tissue stopped early, if it diverged.
    pub failure: Option<String>,
    /// How the segmented masks were labelled.
    pub labelling: Option<LabellingReport>,
    /// The first stage that failed, and why; its message, where one panicked.
    pub error: Option<anyhow::Error>,
}

/// The running stages.
pub struct Pipeline {
    /// Finished frame sets, in order.
    pub output: Receiver<Work>,
    reader: JoinHandle<StageEnd<ReadOutcome>>,
    hull: JoinHandle<StageEnd<Option<LabellingReport>>>,
    pose: JoinHandle<StageEnd<()>>,
    tissue: JoinHandle<StageEnd<(CutSim, Option<String>)>>,
    /// Set when a stage fails (or the consumer stops): the reader stops reading.
    abort: Arc<AtomicBool>,
}

impl Pipeline {
    /// Stops the reader and waits for every stage; never blocks on a full queue (the output is
    /// let go first, so the stages after the reader finish as soon as they try to hand on). Call
    /// it after draining [`Pipeline::output`], or at once to stop early.
    pub fn join(self) -> Outcome {
        let Pipeline { output, reader, hull, pose, tissue, abort } = self;
        abort.store(true, Ordering::SeqCst);
        drop(output);
        let mut error = None;
        let read = joined("read", reader, &mut error).unwrap_or_default();
        let labelling = joined("hull", hull, &mut error).flatten();
        joined("pose", pose, &mut error);
        let (sim, failure) = match joined("tissue", tissue, &mut error) {
            Some((sim, failure)) => (Some(sim), failure),
            None => (None, None),
        };
        Outcome { read, sim, failure, labelling, error }
    }
}

/// A stage's value once its thread has ended; its error (or its panic's message) becomes
/// `error` unless an earlier stage's already has.
fn joined<T>(name: &str, handle: JoinHandle<StageEnd<T>>, error: &mut Option<anyhow::Error>) -> Option<T> {
    let (value, failed) = match handle.join() {
        Ok((value, result)) => (Some(value), result.err().map(|e| e.context(format!("the {name} stage stopped")))),
        Err(payload) => (
            None,
            Some(anyhow!(
                "the {name} stage panicked: {} (a bug in hullcut: please report it with the command line)",
                panic_message(&*payload)
            )),
        ),
    };
    if error.is_none() {
        *error = failed;
    }
    value
}

/// The message a panic was raised with (`panic!("...")` gives a `&str` or a `String`).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".to_owned())
}

/// Sets the abort flag if its stage's thread unwinds from a panic.
#[derive(Debug)]
struct AbortOnPanic(Arc<AtomicBool>);

impl Drop for AbortOnPanic {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.store(true, Ordering::SeqCst);
        }
    }
}

/// Starts a stage on a thread named `name`; a failed or panicking stage sets `abort`.
fn stage<T: Send + 'static>(
    name: &'static str,
    abort: &Arc<AtomicBool>,
    body: impl FnOnce() -> StageEnd<T> + Send + 'static,
) -> anyhow::Result<JoinHandle<StageEnd<T>>> {
    let abort = Arc::clone(abort);
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let guard = AbortOnPanic(Arc::clone(&abort));
            let end = body();
            if end.1.is_err() {
                abort.store(true, Ordering::SeqCst);
            }
            drop(guard);
            end
        })
        .with_context(|| format!("starting the {name} stage"))
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
    let abort = Arc::new(AtomicBool::new(false));
    let (read_tx, read_rx) = bounded::<Work>(queue);
    let (hull_tx, hull_rx) = bounded::<Work>(queue);
    let (pose_tx, pose_rx) = bounded::<Work>(queue);
    let (out_tx, out_rx) = bounded::<Work>(queue);

    let reader = {
        let ds = Arc::clone(&ds);
        // Only the dropping policy takes from the queue's far end; a blocked reader must see the
        // queue close when the hull stage ends.
        let oldest = (policy == Policy::DropOldest).then(|| read_rx.clone());
        let abort_flag = Arc::clone(&abort);
        stage("read", &abort, move || {
            let pace = Pace { realtime, stop: &stop, abort: &abort_flag, dropped: &dropped };
            let passes = Passes { frames: &frames, repeat, span_ns: pass_span_ns };
            let mut outcome = ReadOutcome::default();
            let result = read_stage(&ds, &passes, use_files, &pace, &read_tx, oldest.as_ref(), &mut outcome);
            (outcome, result)
        })?
    };
    let hull = {
        let ds = Arc::clone(&ds);
        stage("hull", &abort, move || {
            let mut labelling = labelling;
            let result = hull_stage(&ds, labelling.as_mut(), (carver, &hull), &read_rx, &hull_tx);
            (labelling.as_ref().map(Labelling::report), result)
        })?
    };
    let pose = {
        let ds = Arc::clone(&ds);
        let template = template.clone();
        stage("pose", &abort, move || ((), pose_stage(&ds, template, &hull_rx, &pose_tx)))?
    };
    let tissue = stage("tissue", &abort, move || (tissue_stage(tissue, template.as_ref(), &pose_rx, &out_tx), Ok(())))?;
    Ok(Pipeline { output: out_rx, reader, hull, pose, tissue, abort })
}

/// How the reader keeps time and when it stops.
#[derive(Clone, Copy)]
struct Pace<'a> {
    realtime: bool,
    stop: &'a AtomicBool,
    abort: &'a AtomicBool,
    dropped: &'a AtomicU64,
}

impl Pace<'_> {
    /// Whether reading should stop (Ctrl-C, or a stage failed).
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || self.abort.load(Ordering::Relaxed)
    }

    /// Sleeps for `wait` (at most [`MAX_REALTIME_GAP_S`]) in slices, waking early to stop.
    fn sleep(&self, wait: Duration) {
        let wait = wait.min(Duration::from_secs_f64(MAX_REALTIME_GAP_S));
        let start = Instant::now();
        while !self.stopping() {
            let Some(left) = wait.checked_sub(start.elapsed()).filter(|d| !d.is_zero()) else { break };
            std::thread::sleep(left.min(SLEEP_SLICE));
        }
    }
}

/// The frame sets the reader replays: `frames`, `repeat` times, each pass `span_ns` later.
struct Passes<'a> {
    frames: &'a [u64],
    repeat: u64,
    span_ns: i64,
}

/// Keeps frame sets to their capture times: the wall clock and the capture time of the frame
/// set pacing started from.
#[derive(Debug, Default)]
struct Pacer {
    anchor: Option<(Instant, i64)>,
    last_ns: Option<i64>,
}

impl Pacer {
    /// How long to wait before handing on a frame set captured at `ns`, and whether a gap was
    /// skipped: a gap from the last frame set over [`MAX_REALTIME_GAP_S`], backwards, or too
    /// large for the arithmetic starts the pacing again from this frame set, at once.
    fn wait(&mut self, ns: i64, now: Instant) -> (Duration, bool) {
        let max_gap_ns = (MAX_REALTIME_GAP_S * 1e9) as i64;
        let gap_ok = self.last_ns.map(|last| ns.checked_sub(last).is_some_and(|gap| (0..=max_gap_ns).contains(&gap)));
        self.last_ns = Some(ns);
        let restart = |pacer: &mut Pacer| {
            pacer.anchor = Some((now, ns));
            Duration::ZERO
        };
        match (gap_ok, self.anchor) {
            (None, _) | (_, None) => (restart(self), false),
            (Some(false), _) => (restart(self), true),
            (Some(true), Some((wall, from_ns))) => {
                let due = ns
                    .checked_sub(from_ns)
                    .and_then(|d| u64::try_from(d).ok())
                    .and_then(|d| wall.checked_add(Duration::from_nanos(d)));
                match due {
                    Some(due) => (due.saturating_duration_since(now), false),
                    None => (restart(self), true),
                }
            }
        }
    }
}

/// Reads frame sets into `outcome`; with `realtime` keeps to their timestamps (see [`Pacer`]).
fn read_stage(
    ds: &Dataset,
    passes: &Passes<'_>,
    use_files: bool,
    pace: &Pace,
    tx: &Sender<Work>,
    oldest: Option<&Receiver<Work>>,
    outcome: &mut ReadOutcome,
) -> anyhow::Result<()> {
    let mut pacer = Pacer::default();
    let replays = (0..passes.repeat).flat_map(|pass| passes.frames.iter().map(move |&frame| (pass, frame)));
    for (pass, frame) in replays {
        if pace.stopping() {
            break;
        }
        let started = Instant::now();
        let (set, faults) = checks::read_frame_set(ds, frame, use_files);
        if pass == 0 {
            for fault in &faults {
                tracing::warn!("left out: {fault}");
            }
        }
        outcome.faults.add(faults, set.is_some());
        let Some(mut set) = set else { continue };
        set.timestamp_ns = shifted(ds, &set, pass, passes.span_ns)?;
        let took = started.elapsed();
        outcome.read += 1;
        if pace.realtime {
            let (wait, skipped) = pacer.wait(set.timestamp_ns, Instant::now());
            outcome.gaps_skipped += u64::from(skipped);
            pace.sleep(wait);
        }
        let times = StageTimes { read: vec![took], ..StageTimes::default() };
        let mut work =
            Work { frame, pass, set, occ: None, grids: Vec::new(), estimate: None, tissue: None, times, started };
        loop {
            match (tx.try_send(work), oldest) {
                (Ok(()), _) => break,
                (Err(TrySendError::Disconnected(_)), _) => return Ok(()),
                (Err(TrySendError::Full(w)), Some(oldest)) => {
                    if oldest.try_recv().is_ok() {
                        pace.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    work = w;
                }
                (Err(TrySendError::Full(w)), None) => {
                    if tx.send(w).is_err() {
                        return Ok(());
                    }
                    break;
                }
            }
        }
    }
    Ok(())
}

/// The capture time of `set` in replay pass `pass` (each pass `span_ns` after the last); an
/// overflow is an error naming the frame and the camera whose time the frame set's is.
fn shifted(ds: &Dataset, set: &FrameSet, pass: u64, span_ns: i64) -> anyhow::Result<i64> {
    let shifted =
        i64::try_from(pass).ok().and_then(|p| p.checked_mul(span_ns)).and_then(|d| set.timestamp_ns.checked_add(d));
    let Some(ns) = shifted else {
        let camera = set
            .views
            .iter()
            .flatten()
            .find(|v| v.timestamp_ns == set.timestamp_ns)
            .map_or_else(|| "no camera".to_owned(), |v| checks::camera_name(ds, v.camera));
        bail!(
            "{}: frame {}, camera {camera}: capture time {} ns cannot be moved on by replay pass {pass} ({span_ns} ns \
             a pass) without overflowing",
            ds.root().join("frames.csv").display(),
            set.frame,
            set.timestamp_ns
        );
    };
    Ok(ns)
}

/// Masks (files or segmented), silhouettes, carving, surfaces. Segmenting carves the foreground's
/// hull and fits the known tool into it to label the views ([`Labelling`]): that hull, its cells
/// near the tool labelled scalpel, is the frame's (nothing is carved twice), and the labelling's
/// fit of the tool, tracked, is the frame's pose (nothing is fitted twice). Mask files were
/// checked by the reader.
fn hull_stage(
    ds: &Dataset,
    mut labelling: Option<&mut Labelling>,
    (mut carver, params): (Carver, &HullParams),
    rx: &Receiver<Work>,
    tx: &Sender<Work>,
) -> anyhow::Result<()> {
    for mut work in rx.iter() {
        let frame = work.frame;
        let mut labelled_hull = None;
        if let Some(labelling) = labelling.as_deref_mut() {
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
    Ok(())
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
/// frame sets' time (the gap saturates: a timestamp at the end of i64's range advances the
/// tissue by [`MAX_ADVANCE_S`], never overflows).
fn tissue_stage(
    mut tissue: Tissue,
    template: Option<&Template>,
    rx: &Receiver<Work>,
    tx: &Sender<Work>,
) -> (CutSim, Option<String>) {
    let mut sweeper = Sweeper::default();
    let mut last_ts: Option<i64> = None;
    let mut failure: Option<String> = None;
    for mut work in rx.iter() {
        let ts = work.set.timestamp_ns;
        let seconds = last_ts.map_or(0.0, |t| (ts.saturating_sub(t) as f64 * 1e-9).clamp(0.0, MAX_ADVANCE_S));
        last_ts = Some(ts);
        if failure.is_none() {
            let mut step = sweeper.next(work.estimate.as_ref(), template, tissue.cell);
            let hand = work.grids.iter().find(|g| g.0 == label::HAND).and_then(|g| g.2.as_ref());
            match tissue.step(&mut step, seconds, hand, &mut work.times) {
                Ok(()) => work.tissue = Some(step),
                Err(e) => failure = Some(format!("frame {}: {e:#}", work.frame)),
            }
        }
        if tx.send(work).is_err() {
            break;
        }
    }
    (tissue.sim, failure)
}

/// The longest stretch of simulated time one frame set advances the tissue (a gap in the
/// recording does not make the simulation run for seconds).
pub const MAX_ADVANCE_S: f64 = 0.2;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pacer_waits_for_the_capture_times_and_skips_a_gap_of_years() {
        let mut pacer = Pacer::default();
        let now = Instant::now();
        assert_eq!(pacer.wait(1_000_000_000, now), (Duration::ZERO, false));
        // 250 ms later in the capture, nothing of it elapsed yet: wait the 250 ms.
        assert_eq!(pacer.wait(1_250_000_000, now), (Duration::from_millis(250), false));
        // 31 years on: not waited out, counted, the pacing starts again there.
        let years = 1_250_000_000 + 31 * 365 * 86_400 * 1_000_000_000;
        assert_eq!(pacer.wait(years, now), (Duration::ZERO, true));
        assert_eq!(pacer.wait(years + 100_000_000, now), (Duration::from_millis(100), false));
        // Backwards, and across the whole range of i64: skipped, never an overflow.
        assert_eq!(pacer.wait(i64::MIN, now), (Duration::ZERO, true));
        assert_eq!(pacer.wait(i64::MAX, now), (Duration::ZERO, true));
        assert_eq!(pacer.wait(i64::MIN, now), (Duration::ZERO, true));
    }

    #[test]
    fn a_panic_reads_as_its_message() {
        // A formatted message is a String, a literal one a &str.
        let payload = std::panic::catch_unwind(|| panic!("the lattice has {} cells", 3)).expect_err("it panics");
        assert_eq!(panic_message(&*payload), "the lattice has 3 cells");
        let payload = std::panic::catch_unwind(|| panic!("plain")).expect_err("it panics");
        assert_eq!(panic_message(&*payload), "plain");
    }
}
