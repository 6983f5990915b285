//! Rerun logging (and the files a run writes per frame: meshes, snapshots) on a thread of its own,
//! behind a bounded queue: the stages hand a frame set's results to it and go on.
//!
//! Without `--realtime` nothing is dropped: when the queue is full the hand-over waits (timed, and
//! reported as `log_wait`). With `--realtime` the oldest frame set waiting to be logged is dropped
//! and counted (`counters.log_dropped`): the loop keeps to the cameras, the recording thins.

use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};
use hullcut_dataset::Dataset;
use hullcut_pipeline::Work;
use hullcut_pose::{PoseError, Template};
use nalgebra::Isometry3;

use super::{snapshot, tissue_log};
use crate::logging::{CameraLogger, log_labelling, log_tool};
use crate::pose_out::log_blade;

/// Frame sets waiting to be logged at most.
pub const LOG_QUEUE: usize = 8;

/// How often the logger flushes a file recording, to find a sink that cannot write (a full disk).
const FLUSH_EVERY: Duration = Duration::from_secs(2);

/// One frame set to log.
pub struct Item {
    /// The stages' results.
    pub work: Work,
    /// Where it goes on the `frame` timeline (later replay passes follow the first).
    pub shown: u64,
    /// The true pose, where the dataset has one.
    pub truth: Option<Isometry3<f64>>,
    /// The estimate's error against it, where measured.
    pub error: Option<PoseError>,
}

/// What the logger needs, moved onto its thread.
pub struct Logger {
    pub rec: hullcut_viz::RecordingStream,
    pub sink: hullcut_viz::Sink,
    pub cams: CameraLogger,
    pub ds: Arc<Dataset>,
    pub tool: Option<hullcut_dataset::ToolGeometry>,
    pub template: Option<Template>,
    pub rrd_every: u64,
    pub export_meshes: Option<PathBuf>,
    pub snapshots: Option<snapshot::Snapshots>,
}

/// What the logger did.
#[derive(Debug, Default)]
pub struct Logged {
    /// Time spent logging each frame set it logged.
    pub times: Vec<Duration>,
    /// Of `times`, drawing the label masks the segmentation left to be drawn
    /// ([`hullcut_pipeline::Work::draw_labels`]), per frame set it drew.
    pub label_times: Vec<Duration>,
    pub meshes_exported: u64,
    pub snapshots_written: u64,
    pub surfaces: tissue_log::SurfaceLog,
}

/// The running logger and its queue of `T` (frame sets to log).
pub struct LogThread<T> {
    tx: Sender<T>,
    /// The queue's far end, to drop its oldest item under live pacing.
    oldest: Receiver<T>,
    handle: JoinHandle<(Logged, anyhow::Result<()>)>,
    drop_oldest: bool,
    /// Items dropped for a full queue.
    pub dropped: u64,
    /// Time the hand-over waited for a full queue.
    pub waited: Vec<Duration>,
}

impl LogThread<Item> {
    /// Starts `logger` on its thread; with `drop_oldest` a full queue drops its oldest item
    /// instead of waiting.
    pub fn start(logger: Logger, drop_oldest: bool) -> anyhow::Result<Self> {
        Self::spawn(move |rx| logger.run(rx), drop_oldest)
    }
}

impl<T: Send + 'static> LogThread<T> {
    /// Starts `body` on the logging thread, reading the queue until it closes.
    fn spawn(
        body: impl FnOnce(&Receiver<T>) -> (Logged, anyhow::Result<()>) + Send + 'static,
        drop_oldest: bool,
    ) -> anyhow::Result<Self> {
        let (tx, rx) = bounded::<T>(LOG_QUEUE);
        let oldest = rx.clone();
        let handle = std::thread::Builder::new()
            .name("log".into())
            .spawn(move || body(&rx))
            .context("starting the logging thread")?;
        Ok(Self { tx, oldest, handle, drop_oldest, dropped: 0, waited: Vec::new() })
    }

    /// Hands a frame set over; `false` when the logger has stopped (its error comes with
    /// [`LogThread::finish`]).
    pub fn push(&mut self, mut item: T) -> bool {
        // The queue's far end is held here too (to drop from it): a stopped logger does not
        // close it.
        if self.stopped() {
            return false;
        }
        let clock = Instant::now();
        loop {
            match self.tx.try_send(item) {
                Ok(()) => return true,
                Err(TrySendError::Disconnected(_)) => return false,
                Err(TrySendError::Full(back)) if self.drop_oldest => {
                    self.dropped += u64::from(self.oldest.try_recv().is_ok());
                    item = back;
                }
                Err(TrySendError::Full(back)) => {
                    let sent = self.tx.send(back).is_ok();
                    self.waited.push(clock.elapsed());
                    return sent;
                }
            }
        }
    }

    /// Whether the logger has stopped (it failed: its error comes with [`LogThread::finish`]).
    pub fn stopped(&self) -> bool {
        self.handle.is_finished()
    }

    /// Logs what is queued, flushes, and hands back what was logged and the first error.
    pub fn finish(self) -> (Logged, anyhow::Result<()>) {
        drop(self.tx);
        drop(self.oldest);
        match self.handle.join() {
            Ok(end) => end,
            Err(payload) => (
                Logged::default(),
                Err(anyhow::anyhow!(
                    "the logging thread panicked: {} (a bug in hullcut: please report it with the command line)",
                    hullcut_pipeline::stages::panic_message(&*payload)
                )),
            ),
        }
    }
}

impl Logger {
    fn run(mut self, rx: &Receiver<Item>) -> (Logged, anyhow::Result<()>) {
        let mut logged = Logged::default();
        let mut flushed = Instant::now();
        for item in rx.iter() {
            let clock = Instant::now();
            if let Err(e) = self.log(item, &mut logged) {
                return (logged, Err(e));
            }
            // A file sink that cannot write (a full disk) shows only when flushed: flush now and
            // then, and stop with its reason rather than log into nothing.
            if let hullcut_viz::Sink::File(path) = &self.sink
                && flushed.elapsed() >= FLUSH_EVERY
            {
                if let Err(e) = hullcut_viz::flush(&self.rec) {
                    return (
                        logged,
                        Err(anyhow::Error::new(e).context(format!("writing the recording {}", path.display()))),
                    );
                }
                flushed = Instant::now();
            }
            logged.times.push(clock.elapsed());
        }
        logged.snapshots_written = self.snapshots.as_ref().map_or(0, |s| s.written);
        // What was logged stays readable whatever stopped the run.
        let flushed = hullcut_viz::flush(&self.rec)
            .map_err(|e| anyhow::Error::new(e).context(format!("writing the recording ({})", self.sink)));
        (logged, flushed)
    }

    /// Logs one frame set: everything on the frame and capture-time timelines.
    fn log(&mut self, item: Item, logged: &mut Logged) -> anyhow::Result<()> {
        let Item { mut work, shown, truth, error } = item;
        // The label masks of a logged frame set that taught nothing are drawn here, off the loop's
        // path, before anything shows them.
        let clock = Instant::now();
        if work.draw_labels() {
            logged.label_times.push(clock.elapsed());
        }
        let rec = &self.rec;
        let every = self.rrd_every;
        hullcut_viz::set_frame(rec, i64::try_from(shown).unwrap_or(i64::MAX));
        hullcut_viz::set_capture_time_ns(rec, work.set.timestamp_ns);
        if let Some(occ) = &work.occ {
            crate::commands::reconstruct::log_hull(rec, &self.cams, &work.set, occ, &work.grids, shown, every, every)?;
        }
        if let (Some(tool), Some(iso)) = (&self.tool, &truth) {
            log_tool(rec, "truth", tool, &iso.to_homogeneous())?;
        }
        if let (Some(template), Some(iso)) = (&self.template, truth) {
            log_blade(rec, "truth", &hullcut_pose::BladePose::new(template, iso))?;
        }
        if let Some(labels) = &work.labels {
            log_labelling(rec, labels)?;
        }
        if let Some(e) = &work.estimate {
            match e.pose.as_ref().filter(|p| p.is_finite()) {
                Some(p) => log_blade(rec, "estimate", p)?,
                None => hullcut_viz::log_clear(rec, "world/tool/estimate")?,
            }
            hullcut_viz::log_scalar(rec, "metrics/pose/confidence", e.confidence)?;
            hullcut_viz::log_scalar(rec, "metrics/pose/outline_offset_px", e.diagnostics.fit_offset_px)?;
            crate::logging::log_pose_views(rec, &e.diagnostics, self.ds.rig())?;
            if let Some(err) = error {
                hullcut_viz::log_scalar(rec, "metrics/accuracy/blade_normal_deg", err.normal_deg)?;
                hullcut_viz::log_scalar(rec, "metrics/accuracy/blade_tip_mm", err.tip_mm)?;
            }
        }
        if let Some(step) = &work.tissue {
            tissue_log::log(rec, step, shown, every, &mut logged.surfaces)?;
            if let Some(dir) = &self.export_meshes {
                logged.meshes_exported += tissue_log::export(dir, shown, &step.surfaces)?;
            }
        }
        if let Some(snaps) = self.snapshots.as_mut().filter(|s| work.pass == 0 && s.wants(work.frame)) {
            let blade = work.estimate.as_ref().and_then(|e| e.pose.as_ref()).filter(|p| p.is_finite());
            let pieces = work.tissue.as_ref().map_or(&[][..], |s| &s.surfaces[..]);
            snaps.write(self.ds.rig(), &work.set, &work.grids, blade, pieces)?;
        }
        for (name, ms) in work.times.last_ms() {
            hullcut_viz::log_scalar(rec, &format!("metrics/time/{name}"), ms)?;
        }
        hullcut_viz::log_scalar(rec, "metrics/time/latency", work.latency().as_secs_f64() * 1e3)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A logger that takes `each` per item and counts them.
    fn slow(each: Duration) -> impl FnOnce(&Receiver<u32>) -> (Logged, anyhow::Result<()>) + Send + 'static {
        move |rx| {
            let mut logged = Logged::default();
            for _ in rx.iter() {
                std::thread::sleep(each);
                logged.times.push(each);
            }
            (logged, Ok(()))
        }
    }

    #[test]
    fn a_slow_logger_makes_the_loop_wait_without_pacing_and_drops_the_oldest_with_it() {
        // Without live pacing: every item logged, the hand-over waited (and said how long).
        let mut log = LogThread::spawn(slow(Duration::from_millis(5)), false).expect("started");
        for k in 0..40 {
            assert!(log.push(k));
        }
        let (dropped, waits) = (log.dropped, log.waited.len());
        let (logged, result) = log.finish();
        assert!(result.is_ok());
        assert_eq!((logged.times.len(), dropped), (40, 0));
        assert!(waits > 0, "40 items into a queue of {LOG_QUEUE} at 5 ms each: the loop must have waited");

        // With it: the loop never waits; what the logger could not take is dropped and counted.
        let mut log = LogThread::spawn(slow(Duration::from_millis(5)), true).expect("started");
        for k in 0..40 {
            assert!(log.push(k));
        }
        let (dropped, waits) = (log.dropped, log.waited.len());
        let (logged, result) = log.finish();
        assert!(result.is_ok());
        assert_eq!(waits, 0);
        assert!(dropped > 0, "nothing dropped");
        assert_eq!(logged.times.len() as u64 + dropped, 40, "every item logged or counted as dropped");
    }

    #[test]
    fn a_logger_that_stopped_refuses_the_next_item() {
        let mut log = LogThread::<u32>::spawn(|_| (Logged::default(), Err(anyhow::anyhow!("disk full"))), false)
            .expect("started");
        while !log.stopped() {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(!log.push(1));
        let (_, result) = log.finish();
        assert!(result.is_err_and(|e| e.to_string().contains("disk full")));
    }
}
