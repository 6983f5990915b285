//! rerun logging of hullcut's domain types, at the entity paths of DESIGN.md's "rerun entity tree".
//! This is the only library crate that knows rerun; stages pass their results here (or the binary
//! does), together with a [`RecordingStream`] it opened.
//!
//! Entry points:
//! - [`open_recording`] opens a recording on a [`Sink`] (an `.rrd` file, a spawned viewer, or a
//!   viewer at a `rerun+http://…/proxy` URL); [`flush`] waits until the sink has the data.
//! - [`log_world`] (z-up view coordinates of `world`) and [`log_rig`] (each camera's world→camera
//!   transform and pinhole at `world/cams/<name>`), both static, once per recording.
//! - [`set_frame`] and [`set_capture_time_ns`] set the `frame` and `capture_time` timelines.
//! - Per frame: [`log_image_rgb`] / [`log_image_jpeg`] (`world/cams/<name>/image`),
//!   [`log_labels`] with [`log_label_classes`] (`world/cams/<name>/labels`), [`log_image_points`]
//!   (2-D overlays), [`log_points3d`] (world points), [`log_scalar`] (`metrics/…`).
//!
//! Pixel coordinates follow hullcut's convention (pixel centres at integers) in every API; the
//! half-pixel shift to rerun's convention happens here ([`RERUN_PIXEL_OFFSET`]).
//!
//! No feature flags.
#![warn(missing_docs)]

mod error;
mod file_sink;
mod log;
mod read;
mod recording;
mod undistort;

pub use error::VizError;
pub use log::{
    RERUN_PIXEL_OFFSET, WORLD, camera_entity_path, image_entity_path, log_box3d, log_camera, log_clear, log_image_jpeg,
    log_image_points, log_image_rgb, log_label_classes, log_labels, log_line_strips3d, log_mesh3d, log_points3d,
    log_points3d_colored, log_rig, log_scalar, log_scalars, log_series_style, log_text, log_world,
};
pub use read::{rrd_entities, rrd_timeline_rows};
pub use recording::{
    CAPTURE_TIME_TIMELINE, FLUSH_TIMEOUT, FRAME_TIMELINE, Sink, flush, open_recording, open_recording_indexed,
    set_capture_time_ns, set_frame,
};
pub use undistort::UndistortMap;
// Re-exported so that callers need not depend on rerun themselves.
pub use rerun::{EntityPath, RecordingStream};
