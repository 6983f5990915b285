//! Errors of the dataset crate. Every variant names the file or folder it is about and, where there
//! is one, the key, line, frame or camera.

use std::path::PathBuf;

/// What can go wrong reading, validating or writing a dataset, a PLY mesh or a `tool.json`.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or folder could not be read, written, listed, created or renamed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
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
    /// `rig.yaml` could not be read or written.
    #[error("{path}: invalid rig: {source}")]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// The rig crate's error (it names the key).
        source: hullcut_rig::RigError,
    },
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
    #[error("{path}: frame {frame} is outside the dataset (frame_count = {frame_count})")]
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
        move |source| Self::Io { path, source }
    }
}
