//! The pipeline's stages as threads joined by bounded channels: read → hull → pose → tissue.
//!
//! At most [`Setup::in_flight`] frame sets are in the stages at once: the reader takes a credit
//! for each frame set it lets in, the tissue stage gives it back when the frame set's cut surface
//! is done. No queue can hold more than that, however slow a stage is. Without live pacing the
//! reader waits for a credit (every frame set is processed); with it, a frame set that finds no
//! credit waits in the reader's one slot until one frees, and a newer one takes its place: the
//! older is dropped and counted ([`ReadOutcome::dropped`]), never queued.
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
//! out when no view is left; every such fault is counted and listed ([`Faults`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, bounded};
use hullcut_dataset::{Dataset, FrameSet, Mesh, label};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, silhouettes};
use hullcut_pose::{PoseEstimate, Template, Tracker, TrackerParams, ViewInput};
use hullcut_sim::CutSim;

use crate::backend::Carver;
use crate::deferred::PendingLabels;
use crate::error::{Context as _, Error};
use crate::labelling::{LabelTrace, Labelling, LabellingReport};
use crate::no_tool_estimate;
use crate::read::{Faults, ViewFault, camera_name, read_frame_set};
use crate::region::{CarveRegion, RegionCounts};
use crate::tissue::{Sweeper, Tissue, TissueStep};

/// The longest `--realtime` waits between two frame sets, seconds. A longer gap in the capture
/// times (a paused recording, a clock jump, a corrupt timestamp 31 years on), or one backwards,
/// is not waited out: it is counted ([`ReadOutcome::gaps_skipped`]) and the pacing starts again
/// from the frame set after it.
pub const MAX_REALTIME_GAP_S: f64 = 5.0;

/// The longest one sleep of the paced reader, so that Ctrl-C and a failed stage stop it soon.
const SLEEP_SLICE: Duration = Duration::from_millis(50);

/// Where the reader takes frame sets from.
#[derive(Clone)]
pub enum FrameSource {
    /// Read (decoded) from the dataset as they are needed.
    Dataset(Arc<Dataset>),
    /// Decoded before the run ([`preload`]): reading is a copy, or a move where this source
    /// alone holds them and no later pass reads them again (a frame set read again after a move
    /// is decoded from the dataset).
    Memory(Arc<Dataset>, Arc<Vec<Preloaded>>),
}

impl std::fmt::Debug for FrameSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FrameSource::Dataset(ds) => write!(f, "FrameSource::Dataset({})", ds.root().display()),
            FrameSource::Memory(ds, sets) => {
                write!(f, "FrameSource::Memory({}, {} frame sets)", ds.root().display(), sets.len())
            }
        }
    }
}

/// One frame set decoded ahead: what [`read_frame_set`] gave for it.
#[derive(Debug, Clone)]
pub struct Preloaded {
    /// Its frame number.
    pub frame: u64,
    /// The frame set (`None` when no camera's image could be used).
    pub set: Option<FrameSet>,
    /// The views left out, and why.
    pub faults: Vec<ViewFault>,
}

/// Decodes `frames` of `ds` (masks too when `with_masks`) into memory, calling `progress` after
/// each; the reader then hands them on without decoding (their faults counted as when read).
pub fn preload(ds: &Dataset, frames: &[u64], with_masks: bool, progress: &dyn Fn()) -> Vec<Preloaded> {
    frames
        .iter()
        .map(|&frame| {
            let (set, faults) = read_frame_set(ds, frame, with_masks);
            progress();
            Preloaded { frame, set, faults }
        })
        .collect()
}

impl FrameSource {
    /// The dataset the frame sets come from.
    pub fn dataset(&self) -> &Arc<Dataset> {
        match self {
            FrameSource::Dataset(ds) | FrameSource::Memory(ds, _) => ds,
        }
    }

    /// Frame set `frame` and its faults; with `last` (no later pass reads it), a preloaded one
    /// that this source alone holds is moved out, not copied (six 640x480 images are 5.5 MB).
    fn read(&mut self, frame: u64, with_masks: bool, last: bool) -> (Option<FrameSet>, Vec<ViewFault>) {
        match self {
            FrameSource::Dataset(ds) => read_frame_set(ds, frame, with_masks),
            FrameSource::Memory(ds, sets) => {
                let Some(k) = sets.iter().position(|p| p.frame == frame) else {
                    return read_frame_set(ds, frame, with_masks);
                };
                match Arc::get_mut(sets).filter(|_| last) {
                    Some(owned) => {
                        let p = owned.swap_remove(k);
                        (p.set, p.faults)
                    }
                    None => (sets[k].set.clone(), sets[k].faults.clone()),
                }
            }
        }
    }
}

/// Everything the stages need.
pub struct Setup {
    /// The frame sets' source.
    pub source: FrameSource,
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
    /// When segmenting, the frame sets whose label masks the caller uses: those whose number on
    /// the frame timeline (the frame's, plus the pass times one more than the last frame's) is a
    /// multiple of this (1, the default: all; `None`: none). The others get the hull and the
    /// pose, and their masks only where they teach the colours ([`Labelling::label_with`]). The
    /// masks of these are drawn as they teach the colours, or else left to the caller to draw
    /// ([`Work::draw_labels`], off the stages' path).
    /// The same frame sets get the hull's surface meshes (with mask files too; the hand's
    /// distance grid, which pushes the tissue, every frame set).
    pub masks_every: Option<u64>,
    /// Frames of the first pass whose hull meshes the caller uses besides those `masks_every`
    /// names (snapshots).
    pub mesh_frames: Vec<u64>,
    /// Carving.
    pub hull: HullParams,
    /// Where carving runs.
    pub carver: Carver,
    /// The blade's template, when the dataset has a tool.json.
    pub template: Option<Template>,
    /// With mask files, let the pose's fit take the scalpel's silhouettes as uniformly fatter or
    /// thinner than the tool ([`TrackerParams::outline_offset`]; off in [`Setup::new`]).
    pub outline_offset: bool,
    /// The organ.
    pub tissue: Tissue,
    /// Frame sets in the stages at once (at least 1): each queue's bound, and the latency's.
    pub in_flight: usize,
    /// Pace the reader to the capture timestamps, dropping the oldest frame set that could not be
    /// let in (live capture); without it every frame set is processed, as fast as the stages go.
    pub realtime: bool,
    /// Set (by Ctrl-C) to stop reading; the frame sets in flight still go through.
    pub stop: Arc<AtomicBool>,
}

impl std::fmt::Debug for Setup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Setup")
            .field("source", &self.source)
            .field("frames", &self.frames.len())
            .field("repeat", &self.repeat)
            .field("use_files", &self.use_files)
            .field("in_flight", &self.in_flight)
            .field("realtime", &self.realtime)
            .finish_non_exhaustive()
    }
}

impl Setup {
    /// A replay of `frames` from `source` once, as fast as the stages go, with mask files
    /// (`use_files`) or without a labelling yet (set [`Setup::labelling`] to segment), the
    /// template from the dataset's tool.json when it has one (and it makes one),
    /// [`DEFAULT_IN_FLIGHT`] frame sets in flight.
    pub fn new(
        source: FrameSource,
        frames: Vec<u64>,
        use_files: bool,
        hull: HullParams,
        carver: Carver,
        tissue: Tissue,
    ) -> Self {
        let template = source.dataset().tool().ok().flatten().and_then(|t| Template::new(&t).ok());
        Setup {
            source,
            frames,
            repeat: 1,
            pass_span_ns: 0,
            use_files,
            labelling: None,
            masks_every: Some(1),
            mesh_frames: Vec::new(),
            hull,
            carver,
            template,
            outline_offset: false,
            tissue,
            in_flight: DEFAULT_IN_FLIGHT,
            realtime: false,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// Frame sets in the stages at once by default: one, the latency then the sum of the stages'
/// times. On two cores a second one raised the built-in scene's throughput by a fifth and its
/// latency by two thirds (docs/benchmarks.md, "The loop"); with more cores than stages it pays.
pub const DEFAULT_IN_FLIGHT: usize = 1;

/// What a stage hands back when it ends: what it has to report, and its error if it failed.
type StageEnd<T> = (T, Result<(), Error>);

/// What the reader did.
#[derive(Debug, Default)]
pub struct ReadOutcome {
    /// Frame sets read and handed on to the stages, or dropped by live pacing (`dropped`); one
    /// read as a stop came, before it went in, is not counted.
    pub read: u64,
    /// Camera images and frame sets left out (unreadable, unknown labels), counted and listed.
    pub faults: Faults,
    /// Capture-time gaps over [`MAX_REALTIME_GAP_S`] (or backwards) that `--realtime` did not
    /// wait out.
    pub gaps_skipped: u64,
    /// Frame sets read but dropped by live pacing: a newer one came while they waited for room.
    pub dropped: u64,
}

/// Whether the caller uses a frame set's label masks (or hull meshes), by frame and pass.
type Wanted = dyn Fn(u64, u64) -> bool;

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
    /// When segmenting: what labelled the views and the colours learned by then.
    pub labels: Option<LabelTrace>,
    /// When segmenting: the label masks of a frame set the caller logs, left to be drawn off the
    /// stages' path ([`Work::draw_labels`]; its views' masks are `None` until then).
    pub pending_labels: Option<PendingLabels>,
    /// What the tissue did.
    pub tissue: Option<TissueStep>,
    /// How long each stage took on this frame set.
    pub times: StageTimes,
    /// When the reader started on it.
    pub started: Instant,
    /// When it was captured, as this run's clock reads it: with live pacing, when its capture
    /// time came; without, when it was let in (a replay takes the next frame set when the stages
    /// have room for it, as a camera triggered by the pipeline would).
    pub captured: Instant,
    /// When it was let into the stages (a credit was free).
    pub admitted: Instant,
    /// When its cut surface was done (the tissue stage's end).
    pub finished: Option<Instant>,
}

impl Work {
    /// From its capture to its cut surface ([`Work::captured`] to [`Work::finished`]); zero
    /// before the tissue stage has finished it.
    pub fn latency(&self) -> Duration {
        self.finished.map_or(Duration::ZERO, |f| f.saturating_duration_since(self.captured))
    }

    /// How long it waited for room before the stages took it.
    pub fn admission_wait(&self) -> Duration {
        self.admitted.saturating_duration_since(self.captured)
    }

    /// Draws the label masks the segmentation left to be drawn ([`Work::pending_labels`]) into
    /// its views, the same masks it would have drawn; whether there were any. The stages hand
    /// out a frame set whose masks the caller wants (`Setup::masks_every`) with its masks drawn,
    /// or with them pending: the consumer draws them on its own thread, beside the loop.
    pub fn draw_labels(&mut self) -> bool {
        let (Some(pending), Some(occ)) = (self.pending_labels.take(), self.occ.as_ref()) else { return false };
        let masks = pending.draw(&self.set, occ);
        for (view, mask) in self.set.views.iter_mut().zip(masks) {
            if let Some(view) = view {
                view.mask = mask;
            }
        }
        true
    }
}

impl std::fmt::Debug for Work {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Work")
            .field("frame", &self.frame)
            .field("pass", &self.pass)
            .field("timestamp_ns", &self.set.timestamp_ns)
            .field("latency", &self.latency())
            .finish_non_exhaustive()
    }
}

/// Stage timings (one entry per frame set that went through the stage; the sweep's `collide`,
/// `cut_topology` and `cut_surface` one per sweep).
#[derive(Debug, Default, Clone)]
pub struct StageTimes {
    /// Reading (decoding, or copying a preloaded frame set).
    pub read: Vec<Duration>,
    /// Segmentation and labelling, its carving and the tool's fit left out.
    pub segment: Vec<Duration>,
    /// Of `segment`, the foreground test of every view (with the weak foreground's test and
    /// confirmation where they run).
    pub segment_foreground: Vec<Duration>,
    /// Of `segment`, the tool's fit's evidence: its provisional labels around the predicted pose,
    /// and around the hull's thin parts where the hull is searched.
    pub segment_evidence: Vec<Duration>,
    /// `segment` again, for the frame sets whose fitted tool was drawn into the views (an
    /// untrusted fit that may teach the colours: [`crate::labelling::Labelled::drawn`]) only.
    pub segment_drawn: Vec<Duration>,
    /// A trusted frame set's lesson, the colours learned from it on a thread of its own beside the
    /// segmentation (one entry per lesson taken: [`crate::labelling::Labelled::lesson_ms`]).
    pub learn: Vec<Duration>,
    /// Carving the hull.
    pub carve: Vec<Duration>,
    /// The labels' grids and surfaces.
    pub surface: Vec<Duration>,
    /// The blade's pose: the tracker's fit (when segmenting, the labelling's fit of the tool,
    /// the fit's evidence, i.e. the provisional labels, left to `segment`).
    pub pose: Vec<Duration>,
    /// The sweep's collision test.
    pub collide: Vec<Duration>,
    /// The virtual node algorithm's new topology.
    pub cut_topology: Vec<Duration>,
    /// The pieces' cut surfaces.
    pub cut_surface: Vec<Duration>,
    /// The hand's obstacle, the table and the pieces' contacts.
    pub contact: Vec<Duration>,
    /// The deformation's time steps, contact left out.
    pub deform: Vec<Duration>,
    /// The deformed pieces' surfaces and nodes.
    pub tissue_surface: Vec<Duration>,
}

impl StageTimes {
    fn fields(&self) -> [(&'static str, &Vec<Duration>); 15] {
        [
            ("read", &self.read),
            ("segment", &self.segment),
            ("segment_foreground", &self.segment_foreground),
            ("segment_evidence", &self.segment_evidence),
            ("segment_drawn", &self.segment_drawn),
            ("learn", &self.learn),
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
            &mut self.segment_foreground,
            &mut self.segment_evidence,
            &mut self.segment_drawn,
            &mut self.learn,
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
#[derive(Debug)]
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
    pub error: Option<Error>,
    /// Where the frame sets were carved: around the last hull, or in the whole volume.
    pub carve_region: RegionCounts,
    /// The most frame sets each queue held at once (read → hull, hull → pose, pose → tissue,
    /// tissue → output): never more than [`Setup::in_flight`].
    pub queue_max: [usize; 4],
}

/// The running stages.
#[derive(Debug)]
pub struct Pipeline {
    /// Finished frame sets, in order.
    pub output: Receiver<Work>,
    reader: JoinHandle<StageEnd<ReadOutcome>>,
    hull: JoinHandle<StageEnd<(Option<LabellingReport>, RegionCounts)>>,
    pose: JoinHandle<StageEnd<()>>,
    tissue: JoinHandle<StageEnd<(CutSim, Option<String>)>>,
    /// Set when a stage fails (or the consumer stops): the reader stops reading.
    abort: Arc<AtomicBool>,
    /// The most each queue held.
    depth: Arc<QueueDepth>,
}

/// The most frame sets each queue held at once, as the stages saw after handing one on.
#[derive(Debug, Default)]
struct QueueDepth([AtomicUsize; 4]);

impl QueueDepth {
    /// Notes queue `k`'s length after a send.
    fn note<T>(&self, k: usize, tx: &Sender<T>) {
        self.0[k].fetch_max(tx.len(), Ordering::Relaxed);
    }
}

impl Pipeline {
    /// Stops the reader and waits for every stage; never blocks on a full queue (the output is
    /// let go first, so the stages after the reader finish as soon as they try to hand on). Call
    /// it after draining [`Pipeline::output`], or at once to stop early.
    pub fn join(self) -> Outcome {
        let Pipeline { output, reader, hull, pose, tissue, abort, depth } = self;
        abort.store(true, Ordering::SeqCst);
        drop(output);
        let mut error = None;
        let read = joined("read", reader, &mut error).unwrap_or_default();
        let (labelling, carve_region) = joined("hull", hull, &mut error).unwrap_or_default();
        joined("pose", pose, &mut error);
        let (sim, failure) = match joined("tissue", tissue, &mut error) {
            Some((sim, failure)) => (Some(sim), failure),
            None => (None, None),
        };
        let queue_max = std::array::from_fn(|k| depth.0[k].load(Ordering::Relaxed));
        Outcome { read, sim, failure, labelling, error, carve_region, queue_max }
    }
}

/// A stage's value once its thread has ended; its error (or its panic's message) becomes
/// `error` unless an earlier stage's already has.
fn joined<T>(name: &str, handle: JoinHandle<StageEnd<T>>, error: &mut Option<Error>) -> Option<T> {
    let (value, failed) = match handle.join() {
        Ok((value, result)) => (
            Some(value),
            result.err().map(|e| Error::Context { context: format!("the {name} stage stopped"), cause: Box::new(e) }),
        ),
        Err(payload) => (
            None,
            Some(Error::msg(format!(
                "the {name} stage panicked: {} (a bug in hullcut: please report it with the command line)",
                panic_message(&*payload)
            ))),
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
) -> Result<JoinHandle<StageEnd<T>>, Error> {
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
pub fn spawn(setup: Setup) -> Result<Pipeline, Error> {
    let Setup {
        mut source,
        frames,
        repeat,
        pass_span_ns,
        use_files,
        labelling,
        masks_every,
        mesh_frames,
        hull,
        carver,
        template,
        outline_offset,
        tissue,
        in_flight,
        realtime,
        stop,
    } = setup;
    // A pass's frame sets follow the last pass's on the frame timeline.
    let pass_frames = frames.last().map_or(1, |&last| last.saturating_add(1));
    let masks_wanted = move |frame: u64, pass: u64| {
        masks_every.is_some_and(|n| frame.saturating_add(pass.saturating_mul(pass_frames)).is_multiple_of(n.max(1)))
    };
    let meshes_wanted =
        move |frame: u64, pass: u64| masks_wanted(frame, pass) || (pass == 0 && mesh_frames.contains(&frame));
    let in_flight = in_flight.max(1);
    let abort = Arc::new(AtomicBool::new(false));
    let depth = Arc::new(QueueDepth::default());
    let (read_tx, read_rx) = bounded::<Work>(in_flight);
    let (hull_tx, hull_rx) = bounded::<Work>(in_flight);
    let (pose_tx, pose_rx) = bounded::<Work>(in_flight);
    let (out_tx, out_rx) = bounded::<Work>(in_flight);
    // One credit per frame set let in, given back by the tissue stage.
    let (credit_tx, credit_rx) = bounded::<()>(in_flight);
    for _ in 0..in_flight {
        credit_tx.try_send(()).map_err(|_| Error::msg("the pipeline's credits could not be issued"))?;
    }
    let ds = Arc::clone(source.dataset());

    let reader = {
        let abort_flag = Arc::clone(&abort);
        let depth = Arc::clone(&depth);
        stage("read", &abort, move || {
            let pace = Pace { realtime, stop: &stop, abort: &abort_flag };
            let passes = Passes { frames: &frames, repeat, span_ns: pass_span_ns };
            let gate = Gate { credits: credit_rx, tx: read_tx, depth: &depth, handed: std::cell::Cell::new(0) };
            let mut outcome = ReadOutcome::default();
            let result = read_stage(&mut source, &passes, use_files, &pace, &gate, &mut outcome);
            // Read: handed on, or dropped by live pacing. A frame set read as a stop came, before
            // it went in, is neither: the run ended before it.
            outcome.read = gate.handed.get() + outcome.dropped;
            (outcome, result)
        })?
    };
    let hull = {
        let ds = Arc::clone(&ds);
        let depth = Arc::clone(&depth);
        stage("hull", &abort, move || {
            let mut labelling = labelling;
            // The masks of the frame sets logged are drawn by the consumer ([`Work::draw_labels`]).
            if let Some(labelling) = labelling.as_mut() {
                labelling.defer_drawing(true);
                labelling.learn_beside(true);
            }
            let mut region = CarveRegion::new(hull.workspace, hull.leaf_size);
            let result = hull_stage(
                &ds,
                (labelling.as_mut(), &masks_wanted, &meshes_wanted),
                (carver, &hull, &mut region),
                &read_rx,
                (&hull_tx, &depth),
            );
            // The colours still being learned are taken before the report.
            let result = result.and_then(|()| labelling.as_mut().map_or(Ok(()), Labelling::settle));
            ((labelling.as_ref().map(Labelling::report), region.counts), result)
        })?
    };
    let pose = {
        let template = template.clone();
        let depth = Arc::clone(&depth);
        stage("pose", &abort, move || ((), pose_stage(&ds, template, outline_offset, &hull_rx, (&pose_tx, &depth))))?
    };
    let tissue = {
        let depth = Arc::clone(&depth);
        stage("tissue", &abort, move || {
            (tissue_stage(tissue, template.as_ref(), &pose_rx, (&out_tx, &depth), &credit_tx), Ok(()))
        })?
    };
    Ok(Pipeline { output: out_rx, reader, hull, pose, tissue, abort, depth })
}

/// How the reader keeps time and when it stops.
#[derive(Clone, Copy)]
struct Pace<'a> {
    realtime: bool,
    stop: &'a AtomicBool,
    abort: &'a AtomicBool,
}

impl Pace<'_> {
    /// Whether reading should stop (Ctrl-C, or a stage failed).
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || self.abort.load(Ordering::Relaxed)
    }
}

/// The way into the stages: a credit per frame set let in.
struct Gate<'a> {
    credits: Receiver<()>,
    tx: Sender<Work>,
    depth: &'a QueueDepth,
    /// Frame sets handed on.
    handed: std::cell::Cell<u64>,
}

/// Whether the reader goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    Go,
    /// The stages have ended (or are stopping): read no more.
    End,
}

impl Gate<'_> {
    /// Lets `work` in once a credit frees (waiting in slices, to stop soon when told).
    fn admit(&self, mut work: Work, pace: &Pace) -> Flow {
        loop {
            if pace.stopping() {
                return Flow::End;
            }
            match self.credits.recv_timeout(SLEEP_SLICE) {
                Ok(()) => {
                    work.admitted = Instant::now();
                    if !pace.realtime {
                        work.captured = work.admitted;
                    }
                    return self.send(work);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Flow::End,
            }
        }
    }

    fn send(&self, work: Work) -> Flow {
        if self.tx.send(work).is_err() {
            return Flow::End;
        }
        self.handed.set(self.handed.get() + 1);
        self.depth.note(0, &self.tx);
        Flow::Go
    }

    /// Waits `wait` (at most [`MAX_REALTIME_GAP_S`]), letting `pending` in as soon as a credit
    /// frees.
    fn wait_admitting(&self, wait: Duration, pending: &mut Option<Work>, pace: &Pace) -> Flow {
        let wait = wait.min(Duration::from_secs_f64(MAX_REALTIME_GAP_S));
        let start = Instant::now();
        while !pace.stopping() {
            let Some(left) = wait.checked_sub(start.elapsed()).filter(|d| !d.is_zero()) else { break };
            let slice = left.min(SLEEP_SLICE);
            if pending.is_none() {
                std::thread::sleep(slice);
                continue;
            }
            match self.credits.recv_timeout(slice) {
                Ok(()) => {
                    if let Some(mut work) = pending.take() {
                        work.admitted = Instant::now();
                        if self.send(work) == Flow::End {
                            return Flow::End;
                        }
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Flow::End,
            }
        }
        Flow::Go
    }

    /// Lets `pending` in now if a credit is free.
    fn try_admit(&self, pending: &mut Option<Work>) -> Flow {
        if pending.is_some()
            && self.credits.try_recv().is_ok()
            && let Some(mut work) = pending.take()
        {
            work.admitted = Instant::now();
            return self.send(work);
        }
        Flow::Go
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

/// Reads frame sets into `outcome` (its `read` the caller takes from the gate afterwards) and lets
/// them into the stages ([`Gate`]); with live pacing
/// keeps to their timestamps (see [`Pacer`]) and drops the oldest that found no room.
fn read_stage(
    source: &mut FrameSource,
    passes: &Passes<'_>,
    use_files: bool,
    pace: &Pace,
    gate: &Gate<'_>,
    outcome: &mut ReadOutcome,
) -> Result<(), Error> {
    let ds = Arc::clone(source.dataset());
    let mut pacer = Pacer::default();
    let mut pending: Option<Work> = None;
    let replays = (0..passes.repeat).flat_map(|pass| passes.frames.iter().map(move |&frame| (pass, frame)));
    for (pass, frame) in replays {
        if pace.stopping() {
            break;
        }
        let started = Instant::now();
        let (set, faults) = source.read(frame, use_files, pass + 1 == passes.repeat);
        if pass == 0 {
            for fault in &faults {
                tracing::warn!("left out: {fault}");
            }
        }
        outcome.faults.add(faults, set.is_some());
        let Some(mut set) = set else { continue };
        set.timestamp_ns = shifted(&ds, &set, pass, passes.span_ns)?;
        let took = started.elapsed();
        if pace.realtime {
            let (wait, skipped) = pacer.wait(set.timestamp_ns, Instant::now());
            outcome.gaps_skipped += u64::from(skipped);
            if gate.wait_admitting(wait, &mut pending, pace) == Flow::End {
                return Ok(());
            }
        }
        let times = StageTimes { read: vec![took], ..StageTimes::default() };
        let now = Instant::now();
        let work = Work {
            frame,
            pass,
            set,
            occ: None,
            grids: Vec::new(),
            estimate: None,
            labels: None,
            pending_labels: None,
            tissue: None,
            times,
            started,
            captured: now,
            admitted: now,
            finished: None,
        };
        let flow = if pace.realtime {
            // The newest frame set takes the one slot; the one it replaces never got in.
            outcome.dropped += u64::from(pending.replace(work).is_some());
            gate.try_admit(&mut pending)
        } else {
            gate.admit(work, pace)
        };
        if flow == Flow::End {
            return Ok(());
        }
    }
    if let Some(work) = pending.take() {
        gate.admit(work, pace);
    }
    Ok(())
}

/// The capture time of `set` in replay pass `pass` (each pass `span_ns` after the last); an
/// overflow is an error naming the frame and the camera whose time the frame set's is.
fn shifted(ds: &Dataset, set: &FrameSet, pass: u64, span_ns: i64) -> Result<i64, Error> {
    let shifted =
        i64::try_from(pass).ok().and_then(|p| p.checked_mul(span_ns)).and_then(|d| set.timestamp_ns.checked_add(d));
    let Some(ns) = shifted else {
        let camera = set
            .views
            .iter()
            .flatten()
            .find(|v| v.timestamp_ns == set.timestamp_ns)
            .map_or_else(|| "no camera".to_owned(), |v| camera_name(ds, v.camera));
        crate::error::fail!(
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
    (mut labelling, masks_wanted, meshes_wanted): (Option<&mut Labelling>, &Wanted, &Wanted),
    (mut carver, params, region): (Carver, &HullParams, &mut CarveRegion),
    rx: &Receiver<Work>,
    (tx, depth): (&Sender<Work>, &QueueDepth),
) -> Result<(), Error> {
    for mut work in rx.iter() {
        // On the pool: the parallel passes inside split their work by stealing, not each handed
        // over to the pool with this thread woken when it is done ([`on_pool`]).
        let wanted = (masks_wanted(work.frame, work.pass), meshes_wanted(work.frame, work.pass));
        let labelling = labelling.as_deref_mut();
        on_pool(|| hull_frame_set(ds, &mut work, (labelling, wanted), (&mut carver, params, region)))?;
        if tx.send(work).is_err() {
            break;
        }
        depth.note(1, tx);
    }
    Ok(())
}

/// [`hull_stage`]'s work on one frame set, its label masks and meshes wanted or not (`wanted`).
fn hull_frame_set(
    ds: &Dataset,
    work: &mut Work,
    (labelling, (masks_wanted, meshes_wanted)): (Option<&mut Labelling>, (bool, bool)),
    (carver, params, region): (&mut Carver, &HullParams, &mut CarveRegion),
) -> Result<(), Error> {
    let frame = work.frame;
    let mut labelled_hull = None;
    // Around the last hull (see [`CarveRegion`]).
    let boxed = region.next_box();
    if let Some(labelling) = labelling {
        let clock = Instant::now();
        labelling.set_workspace(boxed);
        let labelled = labelling.label_with(&work.set, carver, masks_wanted)?;
        if let Some(occ) = &labelled.occupancy {
            // A clipped foreground hull stays (labelling a frame set twice would feed its
            // track twice); the next frame set is carved in the whole volume.
            region.update(&boxed, occ);
        }
        // A tool not trusted is looked for in the whole volume next ([`CarveRegion::set_tracked`]);
        // without a tool.json there is no track to lose.
        region.set_tracked(labelled.estimate.as_ref().is_none_or(|e| e.valid));
        let carve = Duration::from_secs_f64(labelled.carve_ms * 1e-3);
        // The tool's fit is the pose stage's work, done here (see [`pose_stage`]).
        let fit = labelled.stats.as_ref().map(|s| Duration::from_secs_f64(s.fit_ms * 1e-3));
        let segment = clock.elapsed().saturating_sub(carve + fit.unwrap_or_default());
        work.times.segment.push(segment);
        if labelled.drawn {
            work.times.segment_drawn.push(segment);
        }
        work.times.learn.extend(labelled.lesson_ms.map(|ms| Duration::from_secs_f64(ms * 1e-3)));
        work.times.segment_foreground.push(Duration::from_secs_f64(labelled.foreground_ms * 1e-3));
        work.times
            .segment_evidence
            .extend(labelled.stats.as_ref().map(|s| Duration::from_secs_f64(s.evidence_ms * 1e-3)));
        work.times.carve.push(carve);
        work.times.pose.extend(fit);
        work.labels = Some(labelling.trace(&labelled));
        work.pending_labels = labelled.pending;
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
            let here = HullParams { workspace: boxed, ..params.clone() };
            let mut occ = carver.carve(&views, &here).with_context(|| format!("frame {frame}"))?;
            if region.update(&boxed, &occ) {
                occ = carver.carve(&views, params).with_context(|| format!("frame {frame}"))?;
                region.counts.redone += 1;
                region.update(&region.full(), &occ);
            }
            work.times.carve.push(clock.elapsed());
            occ
        }
    };
    let clock = Instant::now();
    // The hand's grid pushes the tissue every frame set; the meshes (and the scalpel's grid,
    // which only they use) are for the frame sets the caller logs or draws.
    work.grids = label::NAMED
        .iter()
        .map(|&(l, name)| {
            let grid = (meshes_wanted || l == label::HAND).then(|| DenseGrid::from_occupancy(&occ, Some(l))).flatten();
            let mesh = grid.as_ref().filter(|_| meshes_wanted).map(DenseGrid::surface);
            (l, name, grid, mesh)
        })
        .collect();
    work.times.surface.push(clock.elapsed());
    work.occ = Some(occ);
    Ok(())
}

/// Runs `op` on a thread of rayon's pool while the calling thread waits. A stage thread is not
/// the pool's: each parallel pass it starts is handed over to the pool, and the stage thread put
/// to sleep until it is done. Run on the pool, the passes split their work with the pool's other
/// threads by work stealing instead, the thread that starts one working on it at once. On two
/// cores this took 1.2-1.5 ms off the built-in scene's segmentation of six views a frame set and
/// 2 ms off the tissue's deformation, the same results (docs/benchmarks.md, "Each stage's frame
/// set on the pool"). Nothing inside may wait for another stage: it would hold a pool thread.
pub fn on_pool<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| op())
}

/// The blade's pose from the scalpel silhouettes, tracked.
fn pose_stage(
    ds: &Dataset,
    template: Option<Template>,
    outline_offset: bool,
    rx: &Receiver<Work>,
    (tx, depth): (&Sender<Work>, &QueueDepth),
) -> Result<(), Error> {
    let params = TrackerParams { outline_offset, ..TrackerParams::default() };
    let mut tracker = template.map(|t| Tracker::new(t, params));
    for mut work in rx.iter() {
        let clock = Instant::now();
        let set = &work.set;
        // The labelling's fit was timed as this stage's by the hull stage.
        let fitted = work.estimate.is_some();
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
                    .map(|(camera, v)| {
                        let v = v.as_ref()?;
                        v.mask.as_ref().map(|mask| ViewInput { camera, mask, image: Some(&v.image) })
                    })
                    .collect();
                on_pool(|| tracker.update(work.frame, set.timestamp_ns, occ, &inputs))
            }
            _ => no_tool_estimate(work.frame, set.timestamp_ns),
        };
        if !fitted {
            work.times.pose.push(clock.elapsed());
        }
        work.estimate = Some(estimate);
        if tx.send(work).is_err() {
            break;
        }
        depth.note(2, tx);
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
    (tx, depth): (&Sender<Work>, &QueueDepth),
    credits: &Sender<()>,
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
            let times = &mut work.times;
            match on_pool(|| tissue.step(&mut step, seconds, hand, times)) {
                Ok(()) => work.tissue = Some(step),
                Err(e) => failure = Some(format!("frame {}: {e}", work.frame)),
            }
        }
        work.finished = Some(Instant::now());
        // Its cut surface is done: room for the next frame set (never blocks: a credit per frame
        // set let in).
        let _ = credits.try_send(());
        if tx.send(work).is_err() {
            break;
        }
        depth.note(3, tx);
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

    /// A preloaded frame set is copied while another pass or another holder may read it, moved
    /// out on the last pass where this source alone holds it, and decoded from the dataset if
    /// read again after that: every read gives the same frame set.
    #[test]
    fn preloaded_frame_sets_are_moved_out_only_on_their_last_read() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
        let ds = Arc::new(Dataset::open(root).expect("the dataset opens"));
        let frames = ds.frame_numbers();
        let sets = Arc::new(preload(&ds, &frames, true, &|| {}));
        let frame = frames[2];
        let (expected, _) = read_frame_set(&ds, frame, true);
        let expected = expected.expect("frame set 2 reads");
        let same = |got: &Option<FrameSet>| {
            let got = got.as_ref().expect("a frame set");
            got.frame == expected.frame
                && got.views.iter().zip(&expected.views).all(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) => a.image == b.image && a.mask == b.mask,
                    (a, b) => a.is_none() && b.is_none(),
                })
        };
        let held = |source: &FrameSource| match source {
            FrameSource::Memory(_, sets) => sets.len(),
            FrameSource::Dataset(_) => 0,
        };
        // Another holder (a second run over the same frame sets): copied, even on the last pass.
        let mut shared = FrameSource::Memory(Arc::clone(&ds), Arc::clone(&sets));
        assert!(same(&shared.read(frame, true, true).0));
        assert_eq!(held(&shared), frames.len());
        drop(shared);
        // Held alone: copied before the last pass, moved out on it, decoded again after.
        let mut alone = FrameSource::Memory(Arc::clone(&ds), sets);
        assert!(same(&alone.read(frame, true, false).0));
        assert_eq!(held(&alone), frames.len());
        assert!(same(&alone.read(frame, true, true).0));
        assert_eq!(held(&alone), frames.len() - 1);
        assert!(same(&alone.read(frame, true, true).0));
        // The others are still there, whatever order the move left them in.
        for &f in frames.iter().filter(|&&f| f != frame) {
            assert_eq!(alone.read(f, true, false).0.map(|s| s.frame), Some(f));
        }
    }

    #[test]
    fn a_stages_work_runs_on_the_pool_while_its_thread_waits() {
        use rayon::iter::{IntoParallelIterator as _, ParallelIterator as _};
        // A stage's thread is not one of the pool's; the work it hands to `on_pool` runs on one,
        // and its parallel passes stay there.
        let stage = std::thread::spawn(|| {
            let outside = rayon::current_thread_index();
            let inside = on_pool(|| {
                let sums: Vec<u64> = (0..64u64).into_par_iter().map(|k| k * k).collect();
                (rayon::current_thread_index(), sums.iter().sum::<u64>())
            });
            (outside, inside)
        });
        let (outside, (inside, sum)) = stage.join().expect("the stage's thread ends");
        assert_eq!(outside, None);
        assert!(inside.is_some(), "the work ran off the pool");
        assert_eq!(sum, (0..64u64).map(|k| k * k).sum::<u64>());
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
