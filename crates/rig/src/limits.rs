//! The ranges every calibration number must lie in, checked wherever a rig is read
//! ([`Rig::load`](crate::Rig::load), [`crate::colmap::read_colmap`]) or validated
//! ([`Rig::validate`](crate::Rig::validate)), and the helpers that keep echoed values in error
//! messages short.
//!
//! The ranges are wide enough for any real lens and rig and narrow enough that no later stage
//! divides by almost zero, overflows, or sizes a buffer from a nonsensical number (a focal length
//! of 1e-300 px once carved an empty hull and reported a NaN error with exit status 0).

use nalgebra::Matrix3;

use crate::Camera;

/// The most cameras a rig may have (a file claiming more is refused before anything is allocated).
pub const MAX_CAMERAS: usize = 64;

/// The longest image side a camera may have, pixels (image widths and heights lie in
/// `1..=MAX_IMAGE_SIDE`).
pub const MAX_IMAGE_SIDE: u32 = 16_384;

/// The smallest focal length (`fx`, `fy`) accepted, pixels.
pub const MIN_FOCAL_PX: f64 = 1.0;

/// The largest focal length (`fx`, `fy`) accepted, pixels (a 16384-pixel image at this focal length
/// sees less than one degree).
pub const MAX_FOCAL_PX: f64 = 1e6;

/// The largest magnitude of a distortion coefficient (k1, k2, p1, p2, k3) accepted. Real
/// five-coefficient calibrations stay below a few hundred; beyond this the polynomial overflows
/// for points inside a wide image.
pub const MAX_DISTORTION_COEFFICIENT: f64 = 1e4;

/// The farthest a camera (or, in a dataset, the tool) may be from the world origin along any axis,
/// metres: rigs are lab-sized, and a camera a light-year away only makes the working volume absurd.
/// For a camera, `|t|` bounds its centre's distance because `centre = -Rᵀ t` with `R` orthonormal.
pub const MAX_WORLD_COORDINATE_M: f64 = 1e3;

/// Largest accepted max |RᵀR − I| of a stored rotation (files rounded to about six significant
/// digits pass); its determinant must be within three times this of +1 (an orthonormal matrix within
/// this tolerance has |det − 1| ≤ 1.5 × it, so only reflections and non-rotations fail that).
pub const ROTATION_TOLERANCE: f64 = 1e-5;

/// The largest `rig.yaml` read, bytes. A rig of [`MAX_CAMERAS`] cameras written at full precision
/// is about 60 KiB.
pub const MAX_RIG_FILE_BYTES: u64 = 1 << 20;

/// How many characters of a value from a file an error message echoes (see [`shorten`]).
pub const SHORT_VALUE_CHARS: usize = 80;

/// `value` cut to [`SHORT_VALUE_CHARS`] characters, with `…(N more chars)` where it was cut: every
/// value taken from a file and echoed in an error message goes through this, so a 100,000-character
/// token does not become a 100,000-character message.
pub fn shorten(value: &str) -> String {
    shorten_to(value, SHORT_VALUE_CHARS)
}

/// `value` cut to `max_chars` characters, with `…(N more chars)` where it was cut.
pub fn shorten_to(value: &str, max_chars: usize) -> String {
    match value.char_indices().nth(max_chars) {
        None => value.to_owned(),
        Some((cut, _)) => {
            let (kept, rest) = value.split_at(cut);
            format!("{kept}…({} more chars)", rest.chars().count())
        }
    }
}

/// A number for an error message: as Rust prints it when that is short, else in scientific
/// notation (`1e-300` rather than 302 characters of zeros).
pub fn short_number(x: f64) -> String {
    let plain = format!("{x}");
    if plain.len() <= 12 { plain } else { format!("{x:e}") }
}

/// Max |RᵀR − I| and det R of a 3x3 matrix.
pub(crate) fn rotation_deviation(r: &Matrix3<f64>) -> (f64, f64) {
    ((r.transpose() * r - Matrix3::identity()).abs().max(), r.determinant())
}

/// Whether a matrix is a rotation within [`ROTATION_TOLERANCE`]: finite, orthonormal, determinant
/// +1. The error says by how much it is not (for messages that name the file and key themselves).
pub fn check_rotation(r: &Matrix3<f64>) -> Result<(), String> {
    if !r.iter().all(|v| v.is_finite()) {
        return Err("holds a non-finite number".to_owned());
    }
    let (deviation, det) = rotation_deviation(r);
    if is_rotation(deviation, det) {
        Ok(())
    } else {
        Err(format!(
            "is not a rotation (max |RᵀR − I| = {deviation:.2e}, at most {ROTATION_TOLERANCE:e}; det = {}, must be +1)",
            short_number(det)
        ))
    }
}

/// The test of [`check_rotation`] on precomputed figures (NaN fails).
pub(crate) fn is_rotation(deviation: f64, det: f64) -> bool {
    deviation <= ROTATION_TOLERANCE && (det - 1.0).abs() <= 3.0 * ROTATION_TOLERANCE
}

/// Whether `x` lies in `[lo, hi]` (NaN does not).
fn within(x: f64, lo: f64, hi: f64) -> bool {
    (lo..=hi).contains(&x)
}

/// The part of a camera a range check failed on; each is one key of a camera in `rig.yaml`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Part {
    Width,
    Height,
    Intrinsics,
    Distortion,
    Rotation,
    Translation,
    Rms,
}

impl Part {
    /// The key of this part in a camera's `rig.yaml` mapping.
    pub(crate) fn yaml_key(self) -> &'static str {
        match self {
            Self::Width => "image_width",
            Self::Height => "image_height",
            Self::Intrinsics => "camera_matrix",
            Self::Distortion => "distortion_coefficients",
            Self::Rotation => "rotation_matrix",
            Self::Translation => "translation_vector",
            Self::Rms => "rms_reprojection_error",
        }
    }
}

/// A camera number outside its range: where, and what with the allowed range.
#[derive(Debug, Clone)]
pub(crate) struct Problem {
    pub(crate) part: Part,
    pub(crate) message: String,
}

fn problem(part: Part, message: String) -> Result<(), Problem> {
    Err(Problem { part, message })
}

/// Checks every number of a camera against the ranges of this module.
pub(crate) fn check_camera(c: &Camera) -> Result<(), Problem> {
    for (part, name, side) in [(Part::Width, "width", c.width), (Part::Height, "height", c.height)] {
        if !(1..=MAX_IMAGE_SIDE).contains(&side) {
            return problem(part, format!("the image {name} {side} is outside 1..={MAX_IMAGE_SIDE} pixels"));
        }
    }
    for (name, f) in [("fx", c.fx), ("fy", c.fy)] {
        if !within(f, MIN_FOCAL_PX, MAX_FOCAL_PX) {
            return problem(
                Part::Intrinsics,
                format!("{name} = {} px is outside [{MIN_FOCAL_PX}, {MAX_FOCAL_PX:e}] px", short_number(f)),
            );
        }
    }
    for (name, p, side) in [("cx", c.cx, c.width), ("cy", c.cy, c.height)] {
        let side = f64::from(side);
        if !within(p, -side, 2.0 * side) {
            return problem(
                Part::Intrinsics,
                format!(
                    "{name} = {} px is outside [{}, {}] px (minus the image side to twice it)",
                    short_number(p),
                    -side,
                    2.0 * side
                ),
            );
        }
    }
    for (name, k) in ["k1", "k2", "p1", "p2", "k3"].into_iter().zip(c.distortion.to_array()) {
        if !within(k, -MAX_DISTORTION_COEFFICIENT, MAX_DISTORTION_COEFFICIENT) {
            return problem(
                Part::Distortion,
                format!(
                    "{name} = {} is outside [-{MAX_DISTORTION_COEFFICIENT:e}, {MAX_DISTORTION_COEFFICIENT:e}]",
                    short_number(k)
                ),
            );
        }
    }
    check_rotation(c.rotation.matrix()).or_else(|m| problem(Part::Rotation, m))?;
    for (axis, t) in ["x", "y", "z"].into_iter().zip(c.translation.iter().copied()) {
        if !within(t, -MAX_WORLD_COORDINATE_M, MAX_WORLD_COORDINATE_M) {
            return problem(
                Part::Translation,
                format!(
                    "t{axis} = {} m is outside [-{MAX_WORLD_COORDINATE_M}, {MAX_WORLD_COORDINATE_M}] m",
                    short_number(t)
                ),
            );
        }
    }
    if let Some(rms) = c.rms_reprojection_error
        && !within(rms, 0.0, f64::from(MAX_IMAGE_SIDE))
    {
        return problem(Part::Rms, format!("{} px is outside [0, {MAX_IMAGE_SIDE}] px", short_number(rms)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shorten_keeps_short_values_and_counts_the_rest() {
        assert_eq!(shorten("cam0"), "cam0");
        let long = "é".repeat(100);
        assert_eq!(shorten(&long), format!("{}…(20 more chars)", "é".repeat(80)));
        assert_eq!(shorten_to("abcdef", 6), "abcdef");
        assert_eq!(shorten_to("abcdefg", 6), "abcdef…(1 more chars)");
    }

    #[test]
    fn short_numbers_use_exponents_when_long() {
        assert_eq!(short_number(640.5), "640.5");
        assert_eq!(short_number(1e-300), "1e-300");
        assert_eq!(short_number(1e308), "1e308");
    }
}
