//! Errors of the rig crate. Every variant names the file and, where there is one, the key.
//!
//! Each message is said once: a variant that wraps another error shows it in its own message and
//! does not also return it from [`std::error::Error::source`], so a chain printed the way `anyhow`
//! prints it (`{:#}`) names the file once.

use std::path::PathBuf;

/// What can go wrong reading, validating or writing a rig.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The file could not be read (the I/O error is part of the message, not a `source`).
    #[error("cannot read {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The file could not be written (the I/O error is part of the message, not a `source`).
    #[error("cannot write {path}: {error}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The file is larger than a calibration file of its kind may be (see
    /// [`MAX_RIG_FILE_BYTES`](crate::MAX_RIG_FILE_BYTES)); nothing of it was parsed.
    #[error("{file}: more than the {limit} bytes a file of this kind may have")]
    TooLarge {
        /// The file.
        file: String,
        /// The limit, bytes.
        limit: u64,
    },
    /// The YAML uses what rig files never need and what could exhaust memory or the stack:
    /// aliases (`*name`), nesting deeper than a rig's, or more nodes than a rig of
    /// [`MAX_CAMERAS`](crate::MAX_CAMERAS) cameras has.
    #[error("{file}: line {line}: {message}")]
    Unsupported {
        /// The file.
        file: String,
        /// Line number, counting from 1.
        line: usize,
        /// What was found and what is allowed.
        message: String,
    },
    /// The text is not YAML (after OpenCV's `%YAML:1.0` header and `!!opencv-matrix` tags are removed).
    #[error("{file}: not valid YAML: {message}")]
    Syntax {
        /// The file (or a label for in-memory text).
        file: String,
        /// The parser's message, with line and column.
        message: String,
    },
    /// A required key is absent.
    #[error("{file}: missing key `{key}`")]
    MissingKey {
        /// The file.
        file: String,
        /// Dotted path of the key, e.g. `camera_2.camera_matrix`.
        key: String,
    },
    /// A matrix has the wrong shape, or its data does not match rows x cols.
    #[error("{file}: `{key}` must be a {expected} matrix, found {found}")]
    MatrixSize {
        /// The file.
        file: String,
        /// The key.
        key: String,
        /// Expected shape, e.g. `3x3`.
        expected: String,
        /// What was found.
        found: String,
    },
    /// A rotation matrix is not orthonormal with determinant +1 (within
    /// [`ROTATION_TOLERANCE`](crate::ROTATION_TOLERANCE)).
    #[error(
        "{file}: `{key}` is not a rotation (max |RᵀR − I| = {deviation:.2e}, at most {tolerance:e}; det = {shown_det}, \
         must be +1)",
        tolerance = crate::ROTATION_TOLERANCE,
        shown_det = crate::short_number(*.det)
    )]
    NotRotation {
        /// The file.
        file: String,
        /// The key.
        key: String,
        /// Largest deviation of RᵀR from the identity.
        deviation: f64,
        /// Determinant of R.
        det: f64,
    },
    /// A value is NaN or infinite.
    #[error("{file}: `{key}` holds a non-finite number")]
    NonFinite {
        /// The file.
        file: String,
        /// The key.
        key: String,
    },
    /// `image_width` or `image_height` is zero.
    #[error("{file}: `{key}` is zero; the image size must be positive")]
    ZeroImageSize {
        /// The file.
        file: String,
        /// The key.
        key: String,
    },
    /// Any other invalid value (wrong type, a number outside its range, count mismatch, ...); the
    /// message names the allowed range.
    #[error("{file}: `{key}`: {message}")]
    Invalid {
        /// The file.
        file: String,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
}
