//! Errors of the rig crate. Every variant names the file and, where there is one, the key.

use std::path::PathBuf;

/// What can go wrong reading, validating or writing a rig.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
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
    /// A rotation matrix is not orthonormal with determinant +1.
    #[error("{file}: `{key}` is not a rotation (max |RᵀR − I| = {deviation:.2e}, det = {det:.6})")]
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
    /// Any other invalid value (wrong type, negative focal length, count mismatch, ...).
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
