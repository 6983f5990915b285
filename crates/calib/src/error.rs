//! Errors of calibration. Each names the folder, file or camera it is about.

use std::path::PathBuf;

/// What can go wrong calibrating a rig.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The image folder does not exist or cannot be listed.
    #[error("cannot read image folder {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The image folder has no camera sub-folders with images.
    #[error("{path} holds no camera folders with images (expected one folder per camera, e.g. {path}/cam0/*.png)")]
    NoCameras {
        /// The folder.
        path: PathBuf,
    },
    /// An image could not be read or decoded.
    #[error("cannot read image {path}")]
    Image {
        /// The image.
        path: PathBuf,
    },
    /// Images of one camera differ in size.
    #[error("{path} is {found_w}x{found_h} but camera `{camera}`'s other images are {w}x{h}")]
    ImageSize {
        /// The odd image.
        path: PathBuf,
        /// The camera.
        camera: String,
        /// Size of the camera's first image.
        w: u32,
        /// Size of the camera's first image.
        h: u32,
        /// Size of this image.
        found_w: u32,
        /// Size of this image.
        found_h: u32,
    },
    /// Too few views of the board in one camera to calibrate it.
    #[error("camera `{camera}`: the {cols}x{rows} board was found in {found} image(s), at least {needed} are needed")]
    TooFewViews {
        /// The camera.
        camera: String,
        /// Views with a detected board.
        found: usize,
        /// Views needed.
        needed: usize,
        /// Pattern columns.
        cols: u32,
        /// Pattern rows.
        rows: u32,
    },
    /// A camera shares no simultaneous board view with the cameras already placed.
    #[error(
        "camera `{camera}` shares no simultaneous board view with the other cameras; add images with the same file name in both folders"
    )]
    Disconnected {
        /// The camera.
        camera: String,
    },
    /// The world-board image was not found or the board was not detected in it.
    #[error("world board {image}: {reason}")]
    WorldBoard {
        /// The image named by `--world-board`.
        image: String,
        /// What is wrong.
        reason: String,
    },
    /// OpenCV reported an error.
    #[error("OpenCV failed while {context}: {source}")]
    OpenCv {
        /// What was being done.
        context: String,
        /// OpenCV's error.
        source: opencv::Error,
    },
}

pub(crate) trait Context<T> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, CalibError>;
}

impl<T> Context<T> for Result<T, opencv::Error> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, CalibError> {
        self.map_err(|source| CalibError::OpenCv { context: what(), source })
    }
}
