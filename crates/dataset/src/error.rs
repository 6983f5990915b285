//! Errors of the dataset crate. Every variant names the file or folder it is about and, where there
//! is one, the key, line, frame or camera.
//!
//! Each message is said once: a variant that wraps another error either shows it in its own
//! message (and does not return it from [`std::error::Error::source`]) or is `transparent`, so a
//! chain printed the way `anyhow` prints it (`{:#}`) names the file once. Values taken from files
//! are echoed through [`hullcut_rig::shorten`].

use std::path::PathBuf;

/// What can go wrong reading, validating or writing a dataset, a PLY mesh or a `tool.json`.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A mesh file could not be read or written (the mesh crate's error names the file).
    #[error(transparent)]
    Mesh(#[from] hullcut_mesh::MeshError),
    /// A file or folder could not be read, written, listed, created or renamed (the I/O error is
    /// part of the message, not a `source`).
    #[error("{path}: {error}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// A file is larger than a file of its kind may be; nothing of it was parsed.
    #[error("{path}: more than the {limit} bytes this file may have")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        limit: u64,
    },
    /// A required file is absent.
    #[error("{path}: missing ({message})")]
    Missing {
        /// The file or folder that should exist.
        path: PathBuf,
        /// Why it is needed.
        message: String,
    },
    /// A file's text or bytes do not follow its format (TOML, JSON, PLY header, ...).
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the key or position where known.
        message: String,
    },
    /// One line of a line-oriented file (`frames.csv`, `truth/poses.jsonl`) is invalid.
    #[error("{path}:{line}: {message}")]
    Line {
        /// The file.
        path: PathBuf,
        /// Line number, counting from 1.
        line: usize,
        /// What is wrong with the line.
        message: String,
    },
    /// A key holds a value that parses but is not allowed (e.g. a zero blade normal).
    #[error("{path}: `{key}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// Files of the dataset disagree with each other (rig vs folders, rows vs images, sizes).
    #[error("{path}: {message}")]
    Inconsistent {
        /// The file or folder where the disagreement shows.
        path: PathBuf,
        /// What disagrees with what.
        message: String,
    },
    /// `rig.yaml` could not be read, validated or written (the rig crate's error names the file
    /// and the key, so it is shown as it is).
    #[error(transparent)]
    Rig(#[from] hullcut_rig::RigError),
    /// An image could not be decoded or encoded, or has the wrong pixel format.
    #[error("{path}: {message}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// The decoder's or encoder's message.
        message: String,
    },
    /// The output folder exists and replacing it was not asked for.
    #[error("{path}: already exists (pass force to replace it)")]
    Exists {
        /// The output folder.
        path: PathBuf,
    },
    /// Replacing was asked for, but the existing folder is neither empty nor a dataset.
    #[error("{path}: exists and is not a dataset (no dataset.toml) and not empty; refusing to replace it")]
    NotADataset {
        /// The output folder.
        path: PathBuf,
    },
    /// A frame number outside `0..frame_count`.
    #[error("{path}: frame {frame} is outside the dataset (dataset.toml: frame_count = {frame_count})")]
    NoSuchFrame {
        /// The dataset (or output) folder.
        path: PathBuf,
        /// The frame asked for.
        frame: u64,
        /// The dataset's frame count.
        frame_count: u64,
    },
    /// A camera index outside the rig.
    #[error("{path}: camera {camera} is outside the rig ({count} cameras)")]
    NoSuchCamera {
        /// The dataset (or output) folder.
        path: PathBuf,
        /// The camera index asked for.
        camera: usize,
        /// Number of cameras in the rig.
        count: usize,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;

impl DatasetError {
    /// An [`DatasetError::Io`] for `path`.
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |error| Self::Io { path, error }
    }
}
