//! Live and recorded frame sources over OpenCV, frame-set synchronization, and segmentation of
//! camera images into label masks.
//!
//! Entry points:
//! - [`FrameSource`] / [`Capture`]: one OpenCV `VideoCapture` per camera ([`SourceSpec`]: device,
//!   video file or image-sequence pattern), read by one thread each into a bounded channel of
//!   [`SourceEvent`]s; timestamps from the device, a monotonic clock, a nominal rate or a replay
//!   list ([`Clock`]).
//! - [`Synchronizer`]: groups frames of N cameras into [`hullcut_dataset::FrameSet`]s by
//!   timestamp, with counted policies for late and missing frames ([`SyncStats`]);
//!   [`Capture::synchronized`] wires both into an iterator of frame sets.
//! - [`ImageUndistorter`], [`JpegEncoder`]: images undistorted (OpenCV `remap`) and encoded for
//!   logging.
//! - [`write_video`], [`export_camera_video`]: OpenCV `VideoWriter` (MJPG in `.avi`).
//! - [`import::import_videos`]: one video per camera, paired by timestamp, into a dataset.
//! - [`Segmenter`]: background model (or MOG2) + colour classes + morphological clean-up → label
//!   masks; [`iou`] and [`IouAccumulator`] score them against truth.
//!
//! Labels follow the dataset convention ([`hullcut_dataset::label`]): 0 background, 1 hand,
//! 2 scalpel, 255 unknown. No feature flags.
#![warn(missing_docs)]

mod convert;
mod error;
pub mod import;
mod jpeg;
pub mod segment;
mod source;
mod sync;
mod undistort;
mod video;

pub use error::CaptureError;
pub use jpeg::JpegEncoder;
pub use segment::{
    AppearanceModel, BackgroundModel, BackgroundSource, ColourClass, ColourClasses, ColourLut, IouAccumulator,
    LabelScore, Method, Mog2Params, SegmentParams, SegmentationReport, Segmenter, ViewTested, Window, iou,
};
pub use source::{
    Capture, CaptureParams, CaptureStats, Clock, ClockKind, FrameSource, QueuePolicy, SourceConfig, SourceEvent,
    SourceFailure, SourceSpec, SyncedFrames,
};
pub use sync::{CapturedFrame, SyncParams, SyncStats, Synchronizer};
pub use undistort::ImageUndistorter;
pub use video::{ExportedVideo, VideoCodec, export_camera_video, write_video};
