//! Errors of capture, synchronization, video writing and segmentation. Each names the camera,
//! file or frame it is about.

use std::path::PathBuf;

/// What can go wrong capturing, synchronizing, writing video or segmenting.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// A video file named as a source does not exist.
    #[error("camera {camera}: video file {path} does not exist")]
    MissingFile {
        /// Camera index (rig order).
        camera: usize,
        /// The file.
        path: PathBuf,
    },
    /// OpenCV could not open a source (device, file or image-sequence pattern).
    #[error("camera {camera}: OpenCV cannot open {source_desc}")]
    Open {
        /// Camera index (rig order).
        camera: usize,
        /// The source, in words (`device 0`, `file x.avi`, `image sequence dir/%06d.png`).
        source_desc: String,
    },
    /// A decoded frame has a pixel format this crate does not convert.
    #[error("camera {camera}, frame {sequence}: unsupported pixel format (OpenCV type {typ}, {channels} channels)")]
    PixelFormat {
        /// Camera index.
        camera: usize,
        /// Position of the frame in the camera's stream, from 0.
        sequence: u64,
        /// OpenCV's type code of the Mat.
        typ: i32,
        /// Channel count of the Mat.
        channels: i32,
    },
    /// A replay source has more frames than timestamps were supplied for it.
    #[error("camera {camera}: frame {sequence} has no timestamp (only {count} were supplied for replay)")]
    TimestampsExhausted {
        /// Camera index.
        camera: usize,
        /// Position of the frame in the camera's stream.
        sequence: u64,
        /// Number of timestamps supplied.
        count: usize,
    },
    /// A live device stopped delivering frames.
    #[error("camera {camera}: {source_desc} stopped delivering frames after {frames} frame(s)")]
    DeviceStopped {
        /// Camera index.
        camera: usize,
        /// The source, in words.
        source_desc: String,
        /// Frames delivered before it stopped.
        frames: u64,
    },
    /// A camera's reader thread could not be started.
    #[error("camera {camera}: cannot start the reader thread: {source}")]
    Thread {
        /// Camera index.
        camera: usize,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A camera index outside the configured cameras (synchronizer, segmenter or dataset rig).
    #[error("camera {camera} is outside the {cameras} configured camera(s)")]
    UnknownCamera {
        /// The camera index given.
        camera: usize,
        /// Number of cameras configured.
        cameras: usize,
    },
    /// A parameter is out of its allowed range.
    #[error("invalid parameter `{name}`: {message}")]
    Param {
        /// The parameter.
        name: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// Images that must share a size do not.
    #[error("camera {camera}: {what} is {found_w}x{found_h}, expected {w}x{h}")]
    ImageSize {
        /// Camera index.
        camera: usize,
        /// Which image (e.g. `frame 12`, `background 3`).
        what: String,
        /// Expected width.
        w: u32,
        /// Expected height.
        h: u32,
        /// Width found.
        found_w: u32,
        /// Height found.
        found_h: u32,
    },
    /// A video file could not be written.
    #[error("cannot write video {path}: {message}")]
    VideoWrite {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Colour classes could not be learnt from the given images and masks.
    #[error("cannot learn colour class `{label}`: {message}")]
    ColourClass {
        /// The label's name.
        label: String,
        /// What is missing or wrong.
        message: String,
    },
    /// An image to encode is not what it says it is (its buffer's size), or the encoder refused it.
    #[error("{0}")]
    Encode(String),
    /// The dataset crate reported an error (it names the file).
    #[error(transparent)]
    Dataset(#[from] hullcut_dataset::DatasetError),
    /// OpenCV reported an error.
    #[error("OpenCV failed while {context}: {source}")]
    OpenCv {
        /// What was being done (names the camera or file).
        context: String,
        /// OpenCV's error.
        source: opencv::Error,
    },
}

pub(crate) trait Context<T> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, CaptureError>;
}

impl<T> Context<T> for Result<T, opencv::Error> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, CaptureError> {
        self.map_err(|source| CaptureError::OpenCv { context: what(), source })
    }
}
