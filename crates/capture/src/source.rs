//! Frame sources over OpenCV's `VideoCapture`: live devices, video files and image sequences, one
//! reader thread per camera feeding a bounded channel.
//!
//! [`FrameSource`] reads one camera synchronously ([`FrameSource::next_frame`]); [`Capture`] runs
//! one thread per source and delivers [`SourceEvent`]s on one bounded channel. End of stream and
//! read errors are events ([`SourceEvent::Ended`], [`SourceEvent::Failed`]), never panics. When the
//! channel is full the [`QueuePolicy`] decides: block the reader (replay: lossless) or drop the
//! new frame and count it (live cameras must not stall their drivers).

use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio;
use serde::{Deserialize, Serialize};

use crate::convert::mat_to_rgb;
use crate::error::{CaptureError, Context as _};
use crate::sync::{CapturedFrame, SyncParams, SyncStats, Synchronizer};

/// Where a camera's frames come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// A live device by OpenCV index (`/dev/video<N>` with V4L2).
    Device(i32),
    /// A video file (any container and codec the installed OpenCV backends decode).
    File(PathBuf),
    /// An image sequence as a printf-style pattern, e.g. `dir/%06d.png` (OpenCV's `CAP_IMAGES`).
    Pattern(String),
}

impl fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SourceSpec::Device(i) => write!(f, "device {i}"),
            SourceSpec::File(p) => write!(f, "video file {}", p.display()),
            SourceSpec::Pattern(p) => write!(f, "image sequence {p}"),
        }
    }
}

/// How a source stamps its frames (nanoseconds).
#[derive(Debug, Clone, PartialEq)]
pub enum Clock {
    /// Chosen by source kind. Devices: the driver's timestamp (`CAP_PROP_POS_MSEC`, V4L2 buffer
    /// time) when the first frame reports a positive one, else [`Clock::Monotonic`]. Files: media
    /// time (`CAP_PROP_POS_MSEC`). Image sequences (no time of their own): [`Clock::Nominal`] at
    /// 30 frames per second (pass [`Clock::Nominal`] or [`Clock::List`] for the real rate).
    Auto,
    /// `CAP_PROP_POS_MSEC` as the backend reports it after each grab.
    Device,
    /// The host's monotonic clock when `grab` returned, relative to an origin shared by all
    /// sources of one [`Capture`].
    Monotonic,
    /// `sequence / fps`: frame k at k/fps seconds.
    Nominal {
        /// Frames per second.
        fps: f64,
    },
    /// Replay of a recording: frame k gets the k-th timestamp (e.g. from the dataset's
    /// `frames.csv`). A stream longer than the list fails with
    /// [`CaptureError::TimestampsExhausted`].
    List(Vec<i64>),
}

/// The clock a source actually uses once opened (what [`Clock::Auto`] resolved to).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClockKind {
    /// `CAP_PROP_POS_MSEC`.
    Device,
    /// Host monotonic clock at grab.
    Monotonic,
    /// Sequence number over a nominal rate.
    Nominal,
    /// Supplied list (replay).
    List,
}

/// One camera's source: what to open and how to stamp it.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceConfig {
    /// Camera index in rig order; frames and events carry it.
    pub camera: usize,
    /// What to open.
    pub spec: SourceSpec,
    /// How to stamp frames.
    pub clock: Clock,
    /// Stop after this many frames (an [`SourceEvent::Ended`] follows); `None` reads to the end.
    pub max_frames: Option<u64>,
    /// Added to every timestamp, nanoseconds: a camera's known delay against the others (videos
    /// started at different moments), or a recording's start time.
    pub offset_ns: i64,
}

impl SourceConfig {
    /// A source with [`Clock::Auto`] and no frame limit.
    pub fn new(camera: usize, spec: SourceSpec) -> Self {
        Self { camera, spec, clock: Clock::Auto, max_frames: None, offset_ns: 0 }
    }

    /// Replays with the given per-frame timestamps (nanoseconds, in stream order).
    pub fn with_timestamps(mut self, timestamps_ns: Vec<i64>) -> Self {
        self.clock = Clock::List(timestamps_ns);
        self
    }

    /// Uses the given clock.
    pub fn with_clock(mut self, clock: Clock) -> Self {
        self.clock = clock;
        self
    }

    /// Adds `offset_ns` to every timestamp.
    pub fn with_offset(mut self, offset_ns: i64) -> Self {
        self.offset_ns = offset_ns;
        self
    }

    /// The frame rate the source's container states (`CAP_PROP_FPS`), when it states a positive
    /// one; opens and closes the source.
    pub fn stated_fps(&self) -> Result<Option<f64>, CaptureError> {
        let source = FrameSource::open(self.clone())?;
        let fps = source.cap.get(videoio::CAP_PROP_FPS).unwrap_or(0.0);
        Ok((fps.is_finite() && fps > 0.0).then_some(fps))
    }
}

/// A decoded frame source for one camera, read synchronously.
pub struct FrameSource {
    config: SourceConfig,
    cap: videoio::VideoCapture,
    kind: ClockKind,
    nominal_fps: f64,
    origin: Instant,
    sequence: u64,
    mat: Mat,
    resolved: bool,
}

impl fmt::Debug for FrameSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FrameSource")
            .field("camera", &self.config.camera)
            .field("spec", &self.config.spec)
            .field("clock", &self.kind)
            .field("sequence", &self.sequence)
            .finish_non_exhaustive()
    }
}

/// Frames per second assumed for image sequences whose backend reports no rate.
const DEFAULT_SEQUENCE_FPS: f64 = 30.0;

impl FrameSource {
    /// Opens the source. A missing video file is [`CaptureError::MissingFile`]; anything OpenCV
    /// cannot open is [`CaptureError::Open`], naming the camera and the source.
    pub fn open(config: SourceConfig) -> Result<Self, CaptureError> {
        let camera = config.camera;
        let desc = config.spec.to_string();
        let ctx = || format!("opening {desc} for camera {camera}");
        let cap = match &config.spec {
            SourceSpec::Device(index) => videoio::VideoCapture::new(*index, videoio::CAP_ANY).context(ctx)?,
            SourceSpec::File(path) => {
                if !path.is_file() {
                    return Err(CaptureError::MissingFile { camera, path: path.clone() });
                }
                let Some(name) = path.to_str() else {
                    return Err(CaptureError::Open { camera, source_desc: format!("{desc} (path is not UTF-8)") });
                };
                // FFmpeg first: it decodes every container Debian's build knows and reports media
                // time; CAP_ANY would also try GStreamer, which is slower and noisier.
                let cap = videoio::VideoCapture::from_file(name, videoio::CAP_FFMPEG).context(ctx)?;
                if cap.is_opened().context(ctx)? {
                    cap
                } else {
                    videoio::VideoCapture::from_file(name, videoio::CAP_ANY).context(ctx)?
                }
            }
            SourceSpec::Pattern(pattern) => {
                videoio::VideoCapture::from_file(pattern, videoio::CAP_IMAGES).context(ctx)?
            }
        };
        if !cap.is_opened().context(ctx)? {
            return Err(CaptureError::Open { camera, source_desc: desc });
        }
        let (kind, nominal_fps, resolved) = match (&config.clock, &config.spec) {
            (Clock::Device, _) => (ClockKind::Device, 0.0, true),
            (Clock::Monotonic, _) => (ClockKind::Monotonic, 0.0, true),
            (Clock::Nominal { fps }, _) => {
                if !(fps.is_finite() && *fps > 0.0) {
                    return Err(CaptureError::Param {
                        name: "fps",
                        message: format!("camera {camera}: {fps} is not positive"),
                    });
                }
                (ClockKind::Nominal, *fps, true)
            }
            (Clock::List(_), _) => (ClockKind::List, 0.0, true),
            (Clock::Auto, SourceSpec::File(_)) => (ClockKind::Device, 0.0, true),
            // OpenCV's image-sequence backend reports 1 frame per second as a placeholder.
            (Clock::Auto, SourceSpec::Pattern(_)) => (ClockKind::Nominal, DEFAULT_SEQUENCE_FPS, true),
            // Decided at the first frame: does the driver report a time?
            (Clock::Auto, SourceSpec::Device(_)) => (ClockKind::Monotonic, 0.0, false),
        };
        Ok(Self { config, cap, kind, nominal_fps, origin: Instant::now(), sequence: 0, mat: Mat::default(), resolved })
    }

    /// Camera index (rig order).
    pub fn camera(&self) -> usize {
        self.config.camera
    }

    /// What was opened.
    pub fn spec(&self) -> &SourceSpec {
        &self.config.spec
    }

    /// The clock in use (for [`Clock::Auto`] on a device, known after the first frame).
    pub fn clock(&self) -> ClockKind {
        self.kind
    }

    /// Frames delivered so far.
    pub fn frames_read(&self) -> u64 {
        self.sequence
    }

    /// Sets the origin of [`Clock::Monotonic`] timestamps (shared by all sources of a capture so
    /// their times compare).
    pub fn set_origin(&mut self, origin: Instant) {
        self.origin = origin;
    }

    /// Reads the next frame: `Ok(None)` at the end of a file or sequence (or after
    /// [`SourceConfig::max_frames`]); a device that stops delivering is an error.
    pub fn next_frame(&mut self) -> Result<Option<CapturedFrame>, CaptureError> {
        let camera = self.config.camera;
        let sequence = self.sequence;
        if self.config.max_frames.is_some_and(|m| sequence >= m) {
            return Ok(None);
        }
        let ctx = || format!("reading frame {sequence} of camera {camera}");
        let grabbed = self.cap.grab().context(ctx)?;
        let grab_time = self.origin.elapsed();
        if !grabbed {
            return match self.config.spec {
                SourceSpec::Device(_) => Err(CaptureError::DeviceStopped {
                    camera,
                    source_desc: self.config.spec.to_string(),
                    frames: sequence,
                }),
                _ => Ok(None),
            };
        }
        let device_ms = match self.kind {
            ClockKind::Device => Some(self.cap.get(videoio::CAP_PROP_POS_MSEC).context(ctx)?),
            _ if !self.resolved => Some(self.cap.get(videoio::CAP_PROP_POS_MSEC).context(ctx)?),
            _ => None,
        };
        if !self.resolved {
            self.resolved = true;
            if device_ms.is_some_and(|ms| ms.is_finite() && ms > 0.0) {
                self.kind = ClockKind::Device;
            }
            tracing::debug!(camera, clock = ?self.kind, "clock chosen for {}", self.config.spec);
        }
        let timestamp_ns = match self.kind {
            ClockKind::Device => (device_ms.unwrap_or(0.0) * 1e6).round() as i64,
            ClockKind::Monotonic => i64::try_from(grab_time.as_nanos()).unwrap_or(i64::MAX),
            ClockKind::Nominal => (sequence as f64 * 1e9 / self.nominal_fps).round() as i64,
            ClockKind::List => {
                let Clock::List(list) = &self.config.clock else {
                    return Err(CaptureError::TimestampsExhausted { camera, sequence, count: 0 });
                };
                let Some(&t) = usize::try_from(sequence).ok().and_then(|i| list.get(i)) else {
                    return Err(CaptureError::TimestampsExhausted { camera, sequence, count: list.len() });
                };
                t
            }
        };
        let Some(timestamp_ns) = timestamp_ns.checked_add(self.config.offset_ns) else {
            return Err(CaptureError::Param {
                name: "offset_ns",
                message: format!("camera {camera}, frame {sequence}: the timestamp plus the offset overflows"),
            });
        };
        if !self.cap.retrieve_def(&mut self.mat).context(ctx)? || self.mat.empty() {
            return match self.config.spec {
                SourceSpec::Device(_) => Err(CaptureError::DeviceStopped {
                    camera,
                    source_desc: self.config.spec.to_string(),
                    frames: sequence,
                }),
                _ => Ok(None),
            };
        }
        let image = mat_to_rgb(&self.mat, camera, sequence)?;
        self.sequence += 1;
        Ok(Some(CapturedFrame { camera, sequence, timestamp_ns, image }))
    }
}

/// What a source thread reports.
#[derive(Debug)]
pub enum SourceEvent {
    /// A decoded frame.
    Frame(CapturedFrame),
    /// The stream ended normally (end of file or sequence, frame limit, or [`Capture`] stopped);
    /// `frames` is how many frames it delivered (a video that ends early says so here).
    Ended {
        /// Camera index.
        camera: usize,
        /// Frames delivered.
        frames: u64,
    },
    /// Reading failed; the source delivers nothing more.
    Failed {
        /// Camera index.
        camera: usize,
        /// Frames delivered before the failure.
        frames: u64,
        /// What went wrong.
        error: CaptureError,
    },
}

/// What a source thread does when the channel is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QueuePolicy {
    /// Wait until the consumer takes a frame (replay: nothing is lost, the reader slows down).
    #[default]
    Block,
    /// Drop the new frame and count it (live cameras: the driver never waits on a slow stage).
    DropNewest,
}

/// Settings of a [`Capture`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CaptureParams {
    /// Capacity of the event channel shared by all sources (frames; 0 is a rendezvous channel).
    pub queue_capacity: usize,
    /// What a source does when the channel is full.
    pub policy: QueuePolicy,
}

impl Default for CaptureParams {
    fn default() -> Self {
        Self { queue_capacity: 16, policy: QueuePolicy::Block }
    }
}

/// Per-camera counters of a running or finished [`Capture`].
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaptureStats {
    /// Frames each camera's thread decoded.
    pub frames_decoded: Vec<u64>,
    /// Frames each camera dropped because the channel was full ([`QueuePolicy::DropNewest`]).
    pub queue_dropped: Vec<u64>,
}

#[derive(Debug)]
struct Counters {
    decoded: Vec<AtomicU64>,
    dropped: Vec<AtomicU64>,
}

/// Running sources, one reader thread per camera, delivering [`SourceEvent`]s on one channel.
///
/// Dropping it stops the threads (they see the closed channel or the stop flag) and joins them.
#[derive(Debug)]
pub struct Capture {
    events: Receiver<SourceEvent>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    threads: Vec<JoinHandle<()>>,
    cameras: usize,
}

impl Capture {
    /// Opens every source (failing on the first that cannot be opened, before any thread starts)
    /// and starts them.
    pub fn open(configs: Vec<SourceConfig>, params: &CaptureParams) -> Result<Self, CaptureError> {
        let sources = configs.into_iter().map(FrameSource::open).collect::<Result<Vec<_>, _>>()?;
        Self::start(sources, params)
    }

    /// Starts one reader thread per source. Monotonic clocks share one origin (now). The number
    /// of cameras is one more than the largest camera index.
    pub fn start(mut sources: Vec<FrameSource>, params: &CaptureParams) -> Result<Self, CaptureError> {
        let cameras = sources.iter().map(|s| s.camera() + 1).max().unwrap_or(0);
        let mut seen = vec![false; cameras];
        for s in &sources {
            if std::mem::replace(&mut seen[s.camera()], true) {
                return Err(CaptureError::Param {
                    name: "sources",
                    message: format!("camera {} has more than one source", s.camera()),
                });
            }
        }
        let (tx, rx) = crossbeam_channel::bounded(params.queue_capacity);
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters {
            decoded: (0..cameras).map(|_| AtomicU64::new(0)).collect(),
            dropped: (0..cameras).map(|_| AtomicU64::new(0)).collect(),
        });
        let origin = Instant::now();
        let mut capture =
            Self { events: rx, stop: stop.clone(), counters: counters.clone(), threads: Vec::new(), cameras };
        for mut source in sources.drain(..) {
            source.set_origin(origin);
            let camera = source.camera();
            let (tx, stop, counters, policy) = (tx.clone(), stop.clone(), counters.clone(), params.policy);
            let handle = std::thread::Builder::new()
                .name(format!("capture-cam{camera}"))
                .spawn(move || read_loop(source, &tx, &stop, &counters, policy))
                .map_err(|e| CaptureError::Param {
                    name: "threads",
                    message: format!("cannot start camera {camera}'s reader: {e}"),
                })?;
            capture.threads.push(handle);
        }
        Ok(capture)
    }

    /// The event channel.
    pub fn events(&self) -> &Receiver<SourceEvent> {
        &self.events
    }

    /// Number of cameras (largest camera index + 1).
    pub fn cameras(&self) -> usize {
        self.cameras
    }

    /// Counters so far.
    pub fn stats(&self) -> CaptureStats {
        CaptureStats {
            frames_decoded: self.counters.decoded.iter().map(|a| a.load(Ordering::Relaxed)).collect(),
            queue_dropped: self.counters.dropped.iter().map(|a| a.load(Ordering::Relaxed)).collect(),
        }
    }

    /// Groups the frames into frame sets with a [`Synchronizer`]; see [`SyncedFrames`].
    pub fn synchronized(self, params: SyncParams) -> Result<SyncedFrames, CaptureError> {
        let sync = Synchronizer::new(SyncParams { cameras: params.cameras.max(self.cameras), ..params })?;
        let live = self.cameras;
        Ok(SyncedFrames { capture: self, sync, live, failures: Vec::new() })
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Closing the channel wakes readers blocked on a full queue.
        drop(std::mem::replace(&mut self.events, crossbeam_channel::never()));
        for handle in self.threads.drain(..) {
            if handle.join().is_err() {
                tracing::error!("a capture reader thread panicked");
            }
        }
    }
}

fn read_loop(
    mut source: FrameSource,
    tx: &Sender<SourceEvent>,
    stop: &AtomicBool,
    counters: &Counters,
    policy: QueuePolicy,
) {
    let camera = source.camera();
    loop {
        if stop.load(Ordering::Relaxed) {
            // Best effort: the consumer may be gone.
            let _ = tx.try_send(SourceEvent::Ended { camera, frames: source.frames_read() });
            return;
        }
        let event = match source.next_frame() {
            Ok(Some(frame)) => {
                counters.decoded[camera].fetch_add(1, Ordering::Relaxed);
                SourceEvent::Frame(frame)
            }
            Ok(None) => {
                let _ = tx.send(SourceEvent::Ended { camera, frames: source.frames_read() });
                return;
            }
            Err(error) => {
                let _ = tx.send(SourceEvent::Failed { camera, frames: source.frames_read(), error });
                return;
            }
        };
        let sent = match policy {
            QueuePolicy::Block => tx.send(event).is_ok(),
            QueuePolicy::DropNewest => match tx.try_send(event) {
                Ok(()) => true,
                Err(TrySendError::Full(_)) => {
                    counters.dropped[camera].fetch_add(1, Ordering::Relaxed);
                    true
                }
                Err(TrySendError::Disconnected(_)) => false,
            },
        };
        if !sent {
            return;
        }
    }
}

/// A source that failed, as [`SyncedFrames`] records it.
#[derive(Debug)]
pub struct SourceFailure {
    /// Camera index.
    pub camera: usize,
    /// Frames it delivered before failing.
    pub frames: u64,
    /// What went wrong.
    pub error: CaptureError,
}

/// Frame sets from a running [`Capture`], in time order, until every source has ended.
///
/// A source that fails is recorded ([`SyncedFrames::failures`]) and treated as ended: the other
/// cameras go on and its views are `None`.
#[derive(Debug)]
pub struct SyncedFrames {
    capture: Capture,
    sync: Synchronizer,
    live: usize,
    failures: Vec<SourceFailure>,
}

impl SyncedFrames {
    /// Synchronization counters so far.
    pub fn stats(&self) -> &SyncStats {
        self.sync.stats()
    }

    /// Capture counters so far.
    pub fn capture_stats(&self) -> CaptureStats {
        self.capture.stats()
    }

    /// Sources that failed so far.
    pub fn failures(&self) -> &[SourceFailure] {
        &self.failures
    }

    fn end(&mut self, camera: usize) {
        self.live = self.live.saturating_sub(1);
        if let Err(e) = self.sync.end_camera(camera) {
            tracing::warn!("{e}");
        }
    }
}

impl Iterator for SyncedFrames {
    type Item = hullcut_dataset::FrameSet;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(set) = self.sync.pop_ready() {
                return Some(set);
            }
            if self.live == 0 {
                self.sync.finish();
                return self.sync.pop_ready();
            }
            match self.capture.events.recv() {
                Ok(SourceEvent::Frame(frame)) => {
                    if let Err(e) = self.sync.push(frame) {
                        tracing::warn!("{e}");
                    }
                }
                Ok(SourceEvent::Ended { camera, frames }) => {
                    tracing::debug!(camera, frames, "source ended");
                    self.end(camera);
                }
                Ok(SourceEvent::Failed { camera, frames, error }) => {
                    tracing::warn!(camera, frames, "source failed: {error}");
                    self.failures.push(SourceFailure { camera, frames, error });
                    self.end(camera);
                }
                Err(_) => self.live = 0,
            }
        }
    }
}
