//! The camera model and multi-camera rig of hullcut.
//!
//! Entry points:
//! - [`Camera`]: pinhole camera with OpenCV's distortion model and world→camera extrinsics;
//!   [`Camera::project`] (world point → pixel with a visibility flag), [`Camera::undistort`]
//!   (pixel → normalized image coordinates, iterative), [`Camera::pixel_ray`] (pixel → world ray).
//! - [`Distortion`]: the five coefficients (k1, k2, p1, p2, k3) and the radius within which the
//!   distortion map is invertible ([`Distortion::monotonic_radius`]).
//! - [`Rig`]: N cameras in one world frame; [`Rig::load`] / [`Rig::save`] read and write `rig.yaml`
//!   (OpenCV FileStorage YAML; files written by OpenCV itself are accepted).
//! - [`default_rig`]: the six-camera rig of the synthetic scenes (`calibration/default-rig.yaml`).
//!
//! Conventions (see DESIGN.md): SI units, OpenCV camera axes (x right, y down, z forward),
//! extrinsics world→camera `x_cam = R · x_world + t`, the centre of pixel (col i, row j) at (i, j).
//!
//! No feature flags.
#![warn(missing_docs)]

mod camera;
mod default;
mod distortion;
mod error;
mod rig;
mod yaml;

pub use camera::{Camera, Projection, Ray};
pub use default::{DEFAULT_TARGET, DEFAULT_WORKSPACE, default_rig};
pub use distortion::{Distortion, UNDISTORT_MAX_ITERATIONS, UNDISTORT_TOLERANCE};
pub use error::RigError;
pub use rig::{Rig, WorldFrame};
