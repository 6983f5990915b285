//! What can go wrong reading or writing a mesh file.

use std::io;
use std::path::PathBuf;

/// What can go wrong reading or writing a mesh file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("cannot read mesh {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error (shown in the message, so not a `source`: said once).
        error: io::Error,
    },
    /// The file could not be written.
    #[error("cannot write mesh {path}: {error}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error (shown in the message, so not a `source`: said once).
        error: io::Error,
    },
    /// The file is larger than [`crate::MAX_FILE_BYTES`].
    #[error("mesh {path} is {bytes} bytes, more than the limit of {limit}")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
        /// The limit.
        limit: u64,
    },
    /// The extension is neither `.ply` nor `.obj`.
    #[error("mesh {path}: unsupported format (expected a .ply or .obj file)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The PLY header is malformed or lacks what a triangle mesh needs.
    #[error("mesh {path}, header line {line}: {message}")]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based header line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A value in the data could not be parsed.
    #[error("mesh {path}, {at}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where: `line N` for text, `vertex N` or `face N` for binary data.
        at: String,
        /// What is wrong.
        message: String,
    },
    /// The data ends before every declared element was read.
    #[error("mesh {path}: data ends early, at {element} {index} of {count}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The PLY element being read (`vertex`, `face`, ...).
        element: String,
        /// 0-based index of the first missing element.
        index: usize,
        /// How many the header declared.
        count: usize,
    },
    /// A face refers to a vertex that does not exist.
    #[error("mesh {path}, {at}: vertex index {index} out of range ({vertices} vertices)")]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// Where: `line N` or `face N`.
        at: String,
        /// The index as written (OBJ indices are 1-based or negative).
        index: i64,
        /// Vertices defined at that point.
        vertices: usize,
    },
    /// The file holds no vertices or no triangles.
    #[error("mesh {path} has no {what}")]
    Empty {
        /// The file.
        path: PathBuf,
        /// `vertices` or `triangles`.
        what: &'static str,
    },
}
