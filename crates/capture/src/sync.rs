//! Grouping frames from N cameras into frame sets by timestamp (pure logic, no OpenCV).
//!
//! Each camera delivers its frames in time order (any interleaving between cameras). A set is
//! anchored at the earliest pending frame of any camera; each camera contributes its earliest
//! pending frame if that lies within `tolerance_ns` after the anchor. A camera's view is decided
//! when its next frame is beyond the window (the camera dropped this one: `None`), when it has
//! ended, or — for a camera that has not answered yet — when waiting is given up: some camera has
//! moved past the window by more than `max_wait_ns`, or a camera's backlog exceeds `max_pending`.
//! Every outcome is counted in [`SyncStats`]:
//! - a missing view (`None` in an emitted set) counts in `missing_views` for its camera;
//! - a frame that arrives after its set was emitted is dropped and counts in `late_dropped`;
//! - a second frame of one camera inside one set's window is dropped (`surplus_dropped`);
//! - a frame not later than the camera's previous one, or arriving after the camera was ended,
//!   is dropped (`out_of_order_dropped`).

use std::collections::VecDeque;

use hullcut_dataset::{FrameSet, View};
use image::RgbImage;
use serde::{Deserialize, Serialize};

use crate::error::CaptureError;

/// A decoded frame from one camera.
#[derive(Debug, Clone)]
pub struct CapturedFrame {
    /// Camera index in rig order.
    pub camera: usize,
    /// Position in the camera's stream, from 0.
    pub sequence: u64,
    /// Capture time, nanoseconds (see [`crate::Clock`] for where it comes from).
    pub timestamp_ns: i64,
    /// The image, 8-bit RGB.
    pub image: RgbImage,
}

/// Settings of a [`Synchronizer`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SyncParams {
    /// Number of cameras (views per set).
    pub cameras: usize,
    /// Largest timestamp spread within one set, nanoseconds. Half a frame period groups frames
    /// correctly while each camera's jitter stays below a quarter period.
    pub tolerance_ns: i64,
    /// How long to wait for a camera that has not answered: once any camera delivers a frame
    /// later than the set's window end plus this, the set goes out with `None` for it. `None`
    /// waits until the camera delivers a later frame or ends (lossless replay).
    pub max_wait_ns: Option<i64>,
    /// Largest backlog of pending frames per camera; beyond it the oldest set goes out whether or
    /// not every camera has answered (bounds memory when one camera stalls).
    pub max_pending: usize,
    /// Number given to the first emitted set; later sets count up by one.
    pub first_frame: u64,
}

impl SyncParams {
    /// Live cameras at `fps`: tolerance half a period, no waiting past the window (a camera that
    /// has not answered by the time another delivers its next frame is missing), backlog 8.
    pub fn live(cameras: usize, fps: f64) -> Self {
        Self { cameras, tolerance_ns: half_period_ns(fps), max_wait_ns: Some(0), max_pending: 8, first_frame: 0 }
    }

    /// Replay of recordings at `fps`: tolerance half a period, wait for every camera, backlog 64.
    pub fn replay(cameras: usize, fps: f64) -> Self {
        Self { cameras, tolerance_ns: half_period_ns(fps), max_wait_ns: None, max_pending: 64, first_frame: 0 }
    }
}

fn half_period_ns(fps: f64) -> i64 {
    if fps.is_finite() && fps > 0.0 { (0.5e9 / fps).round() as i64 } else { 0 }
}

impl Default for SyncParams {
    /// Six live cameras at 30 frames per second.
    fn default() -> Self {
        Self::live(6, 30.0)
    }
}

/// Counters of a [`Synchronizer`], for reports. Per-camera vectors are in rig order.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SyncStats {
    /// Number of cameras.
    pub cameras: usize,
    /// The tolerance in use, nanoseconds.
    pub tolerance_ns: i64,
    /// Frames handed to the synchronizer, per camera.
    pub frames_received: Vec<u64>,
    /// Frame sets emitted.
    pub sets_emitted: u64,
    /// Sets with every camera present.
    pub complete_sets: u64,
    /// Emitted sets without this camera's view, per camera.
    pub missing_views: Vec<u64>,
    /// Frames that arrived after their set had been emitted (dropped), per camera.
    pub late_dropped: Vec<u64>,
    /// Second frames of one camera inside one set's window (dropped), per camera.
    pub surplus_dropped: Vec<u64>,
    /// Frames not later than the camera's previous frame, or arriving after the camera was ended
    /// (dropped), per camera.
    pub out_of_order_dropped: Vec<u64>,
    /// Sets emitted while some camera had not answered, because another had moved past the
    /// window by more than `max_wait_ns`.
    pub gave_up_waiting: u64,
    /// Sets emitted while some camera had not answered, because a backlog exceeded `max_pending`.
    pub backlog_forced: u64,
    /// Largest timestamp spread within an emitted set, nanoseconds.
    pub max_spread_ns: i64,
}

impl SyncStats {
    fn new(cameras: usize, tolerance_ns: i64) -> Self {
        Self {
            cameras,
            tolerance_ns,
            frames_received: vec![0; cameras],
            missing_views: vec![0; cameras],
            late_dropped: vec![0; cameras],
            surplus_dropped: vec![0; cameras],
            out_of_order_dropped: vec![0; cameras],
            ..Self::default()
        }
    }

    /// Frames dropped for any reason, per camera.
    pub fn dropped(&self) -> Vec<u64> {
        (0..self.cameras)
            .map(|c| self.late_dropped[c] + self.surplus_dropped[c] + self.out_of_order_dropped[c])
            .collect()
    }

    /// Missing views over all cameras.
    pub fn total_missing(&self) -> u64 {
        self.missing_views.iter().sum()
    }
}

/// Groups frames from N cameras into [`FrameSet`]s; see the module docs for the policy.
#[derive(Debug)]
pub struct Synchronizer {
    params: SyncParams,
    pending: Vec<VecDeque<CapturedFrame>>,
    last_ts: Vec<Option<i64>>,
    ended: Vec<bool>,
    emitted_until: Option<i64>,
    next_frame: u64,
    ready: VecDeque<FrameSet>,
    stats: SyncStats,
}

impl Synchronizer {
    /// A synchronizer for `params.cameras` cameras; refuses zero cameras and a negative tolerance
    /// or wait.
    pub fn new(params: SyncParams) -> Result<Self, CaptureError> {
        if params.cameras == 0 {
            return Err(CaptureError::Param { name: "cameras", message: "at least one camera is needed".into() });
        }
        if params.tolerance_ns < 0 {
            return Err(CaptureError::Param {
                name: "tolerance_ns",
                message: format!("{} is negative", params.tolerance_ns),
            });
        }
        if params.max_wait_ns.is_some_and(|w| w < 0) {
            return Err(CaptureError::Param { name: "max_wait_ns", message: "is negative".into() });
        }
        let n = params.cameras;
        Ok(Self {
            pending: (0..n).map(|_| VecDeque::new()).collect(),
            last_ts: vec![None; n],
            ended: vec![false; n],
            emitted_until: None,
            next_frame: params.first_frame,
            ready: VecDeque::new(),
            stats: SyncStats::new(n, params.tolerance_ns),
            params,
        })
    }

    /// The settings.
    pub fn params(&self) -> &SyncParams {
        &self.params
    }

    /// Counters so far.
    pub fn stats(&self) -> &SyncStats {
        &self.stats
    }

    /// Hands over one frame; sets that became complete are queued for [`Self::pop_ready`].
    /// A camera index outside the configured count is an error (the frame is not kept).
    pub fn push(&mut self, frame: CapturedFrame) -> Result<(), CaptureError> {
        let c = frame.camera;
        if c >= self.params.cameras {
            return Err(CaptureError::UnknownCamera { camera: c, cameras: self.params.cameras });
        }
        self.stats.frames_received[c] += 1;
        let t = frame.timestamp_ns;
        if self.ended[c] || self.last_ts[c].is_some_and(|last| t <= last) {
            self.stats.out_of_order_dropped[c] += 1;
            return Ok(());
        }
        self.last_ts[c] = Some(t);
        if self.emitted_until.is_some_and(|e| t <= e) {
            self.stats.late_dropped[c] += 1;
            return Ok(());
        }
        self.pending[c].push_back(frame);
        self.emit();
        Ok(())
    }

    /// Marks a camera as ended (end of stream or failure): it will deliver nothing more, so sets
    /// no longer wait for it.
    pub fn end_camera(&mut self, camera: usize) -> Result<(), CaptureError> {
        if camera >= self.params.cameras {
            return Err(CaptureError::UnknownCamera { camera, cameras: self.params.cameras });
        }
        self.ended[camera] = true;
        self.emit();
        Ok(())
    }

    /// Ends every camera: all pending frames go out in sets.
    pub fn finish(&mut self) {
        self.ended.iter_mut().for_each(|e| *e = true);
        self.emit();
    }

    /// The next emitted set, oldest first.
    pub fn pop_ready(&mut self) -> Option<FrameSet> {
        self.ready.pop_front()
    }

    /// Whether every camera has ended and every set has been taken.
    pub fn is_done(&self) -> bool {
        self.ended.iter().all(|&e| e) && self.ready.is_empty() && self.pending.iter().all(VecDeque::is_empty)
    }

    fn emit(&mut self) {
        while let Some(anchor) = self.pending.iter().filter_map(|q| q.front()).map(|f| f.timestamp_ns).min() {
            let window_end = anchor.saturating_add(self.params.tolerance_ns);
            let undecided = (0..self.params.cameras).any(|c| {
                self.pending[c].is_empty() && !self.ended[c] && self.last_ts[c].is_none_or(|t| t <= window_end)
            });
            if undecided {
                let newest = self.last_ts.iter().flatten().copied().max().unwrap_or(anchor);
                let waited_out = self.params.max_wait_ns.is_some_and(|w| newest > window_end.saturating_add(w));
                let backlog = self.pending.iter().any(|q| q.len() > self.params.max_pending);
                if waited_out {
                    self.stats.gave_up_waiting += 1;
                } else if backlog {
                    self.stats.backlog_forced += 1;
                } else {
                    return;
                }
            }
            let mut views = Vec::with_capacity(self.params.cameras);
            let (mut lo, mut hi) = (i64::MAX, i64::MIN);
            for c in 0..self.params.cameras {
                let take = self.pending[c].front().is_some_and(|f| f.timestamp_ns <= window_end);
                let view = if take { self.pending[c].pop_front() } else { None };
                while self.pending[c].front().is_some_and(|f| f.timestamp_ns <= window_end) {
                    self.pending[c].pop_front();
                    self.stats.surplus_dropped[c] += 1;
                }
                views.push(view.map(|f| {
                    lo = lo.min(f.timestamp_ns);
                    hi = hi.max(f.timestamp_ns);
                    View { camera: c, timestamp_ns: f.timestamp_ns, image: f.image, mask: None }
                }));
                if !take {
                    self.stats.missing_views[c] += 1;
                }
            }
            self.stats.max_spread_ns = self.stats.max_spread_ns.max(hi - lo);
            self.stats.sets_emitted += 1;
            if views.iter().all(Option::is_some) {
                self.stats.complete_sets += 1;
            }
            self.emitted_until = Some(window_end);
            let set = FrameSet { frame: self.next_frame, timestamp_ns: FrameSet::median_timestamp(&views), views };
            self.next_frame += 1;
            self.ready.push_back(set);
        }
    }
}
