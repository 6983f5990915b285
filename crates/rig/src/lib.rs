//! The camera model and multi-camera rig of hullcut.
//!
//! Entry points:
//! - [`Camera`]: pinhole camera with OpenCV's distortion model and world→camera extrinsics;
//!   [`Camera::project`] (world point → pixel with a visibility flag), [`Camera::undistort`]
//!   (pixel → normalized image coordinates, iterative), [`Camera::pixel_ray`] (pixel → world ray).
//! - [`Distortion`]: the five coefficients (k1, k2, p1, p2, k3) and the radius within which the
//!   distortion map is invertible ([`Distortion::monotonic_radius`]).
//! - [`Rig`]: N cameras in one world frame; [`Rig::load`] / [`Rig::save`] read and write `rig.yaml`
//!   (OpenCV FileStorage YAML; files written by OpenCV itself are accepted);
//!   [`colmap::read_colmap`] / [`colmap::write_colmap`] read and write COLMAP's text model.
//! - [`default_rig`]: the six-camera rig of the synthetic scenes (`calibration/default-rig.yaml`);
//!   [`lab8_rig`] (eight 1280x720 cameras, one overhead, one strongly distorted) and
//!   [`random_rig`] (seeded) so that nothing is tuned to one rig; [`RigPreset`] names them.
//! - Input limits ([`MAX_CAMERAS`], [`MAX_IMAGE_SIDE`], [`MIN_FOCAL_PX`]..[`MAX_FOCAL_PX`],
//!   [`MAX_DISTORTION_COEFFICIENT`], [`MAX_WORLD_COORDINATE_M`], [`ROTATION_TOLERANCE`],
//!   [`MAX_RIG_FILE_BYTES`]): every reader refuses numbers outside them, naming the file, the key
//!   and the range; [`Rig::validate`] checks a rig built in memory. [`shorten`] and [`short_number`]
//!   keep values echoed in error messages short.
//!
//! Conventions (see DESIGN.md): SI units, OpenCV camera axes (x right, y down, z forward),
//! extrinsics world→camera `x_cam = R · x_world + t`, the centre of pixel (col i, row j) at (i, j).
//!
//! No feature flags.
#![warn(missing_docs)]

mod camera;
pub mod colmap;
mod default;
mod distortion;
mod error;
mod limits;
mod presets;
mod rig;
mod yaml;

pub use camera::{Camera, Projection, Ray};
pub use default::{DEFAULT_TARGET, DEFAULT_WORKSPACE, default_rig};
pub use distortion::{Distortion, UNDISTORT_MAX_ITERATIONS, UNDISTORT_TOLERANCE};
pub use error::RigError;
pub use limits::{
    MAX_CAMERAS, MAX_DISTORTION_COEFFICIENT, MAX_FOCAL_PX, MAX_IMAGE_SIDE, MAX_RIG_FILE_BYTES, MAX_WORLD_COORDINATE_M,
    MIN_FOCAL_PX, ROTATION_TOLERANCE, SHORT_VALUE_CHARS, check_rotation, short_number, shorten, shorten_to,
};
pub use presets::{RigPreset, lab8_rig, random_rig};
pub use rig::{Rig, WorldFrame};

/// Orders strings so that embedded numbers compare by value ("cam2" < "cam10"): the order of
/// camera folders and names everywhere in hullcut.
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    fn chunks(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[start].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for ((da, sa), (db, sb)) in ca.iter().zip(&cb) {
        let ord = if *da && *db {
            let (ta, tb) = (sa.trim_start_matches('0'), sb.trim_start_matches('0'));
            ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb))
        } else {
            sa.cmp(sb)
        };
        if ord.is_ne() {
            return ord;
        }
    }
    ca.len().cmp(&cb.len()).then_with(|| a.cmp(b))
}
