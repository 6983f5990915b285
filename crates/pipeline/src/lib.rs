//! The hullcut loop as a library: frame sets in, the blade's pose and the cut organ out.
//!
//! A [`Pipeline`] runs the stages on threads joined by bounded queues: reading (a dataset replayed
//! from disk or from memory, [`FrameSource`]), the hull (segmentation when the masks are not
//! files, octree carving, surfaces), the pose (the tool's blade template fitted and tracked) and
//! the tissue (the blade's swept surface cuts the organ by the virtual node algorithm; TLED moves
//! it, on the table, the hand's hull pushing it aside). At most [`Setup::in_flight`] frame sets
//! are in the stages at once, so no queue grows and a frame set's latency stays bounded: without
//! live pacing the reader waits for room, with it ([`Setup::realtime`]) the oldest frame set that
//! could not be let in is dropped and counted. Per-frame results ([`Work`]) come out of
//! [`Pipeline::output`] in order; a consumer (rerun logging in `hullcut run`, or a lab's own
//! program) takes them from there, off the stages' path.
//!
//! [`measure`] runs the loop against a synthetic recording's truth (fps and latency beside the
//! blade's and the resected piece's errors), as `hullcut bench loop` does.
//!
//! `examples/replay.rs` drives it from a few lines: open a dataset, build the organ, spawn, and
//! read the results as they come.

#![warn(missing_docs)]

pub mod backend;
pub mod budget;
pub mod deferred;
pub mod error;
pub mod labelling;
pub mod lesson;
pub mod measure;
pub mod read;
pub mod region;
pub mod stages;
pub mod tissue;

pub use backend::{Backend, Carver, GpuHandle};
pub use deferred::PendingLabels;
pub use error::Error;
pub use labelling::{LabelMethod, LabelSource, LabelTrace, Labelling, LabellingReport, Segmented, WeakWhen};
pub use read::{Faults, ViewFault};
pub use stages::{
    FrameSource, LabelGrid, MAX_ADVANCE_S, MAX_REALTIME_GAP_S, Outcome, Pipeline, ReadOutcome, Setup, StageTimes, Work,
    on_pool, preload, spawn,
};
pub use tissue::{Sweeper, Tissue, TissueStep};

/// The refused estimate of a frame set whose dataset has no tool.json.
pub fn no_tool_estimate(frame: u64, timestamp_ns: i64) -> hullcut_pose::PoseEstimate {
    hullcut_pose::PoseEstimate {
        frame,
        timestamp_ns,
        valid: false,
        held: false,
        confidence: 0.0,
        pose: None,
        fitted: None,
        reason: Some("the dataset has no tool.json: the pose needs the tool's geometry".to_owned()),
        diagnostics: hullcut_pose::Diagnostics::default(),
    }
}
