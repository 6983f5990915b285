//! Multi-camera chessboard calibration: OpenCV for detection and per-camera intrinsics, our own
//! spanning-tree initialisation and joint refinement for the extrinsics.
//!
//! Entry points:
//! - [`discover_images`]: one folder per camera; files with the same name are simultaneous views.
//! - [`detect_all`]: chessboard corners with sub-pixel refinement, in parallel.
//! - [`import::read_opencv_cameras`]: a calibration made by another tool, as per-camera OpenCV
//!   FileStorage files (YAML, XML, JSON).
//! - [`calibrate`]: intrinsics per camera (OpenCV `calibrateCamera`), extrinsics chained through a
//!   maximum spanning tree of camera pairs weighted by shared views ([`extrinsics`]), then every
//!   camera's intrinsics and pose and every board pose refined jointly ([`refine`]); the world frame
//!   is camera 0's or that of a board lying on the table.
//!
//! OpenCV 4.6 has no multi-view calibration, so the joint refinement is ours (as in OpenCV 5's
//! `calibrateMultiview` and MC-Calib). No feature flags.
#![warn(missing_docs)]

mod calibrate;
mod detect;
mod discover;
mod error;
pub mod extrinsics;
pub mod import;
mod intrinsics;
mod model;
pub mod refine;
mod report;

pub use calibrate::{CalibParams, Calibration, calibrate};
pub use detect::{Detection, detect_all, detect_corners, read_rgb, read_rgb_undistorted};
pub use discover::{ImageSet, discover_images, natural_cmp};
pub use error::CalibError;
pub use intrinsics::{IntrinsicFit, calibrate_intrinsics};
pub use model::{Observations, Pattern};
pub use report::{CalibReport, CameraReport, ImageReport, PairReport, TreeEdgeReport};
