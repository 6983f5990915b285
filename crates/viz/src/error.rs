//! Errors of the viz crate. Every variant names the sink, entity or camera it concerns.

/// What can go wrong opening a recording or logging into it.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// The application id is empty.
    #[error("rerun application id must not be empty")]
    ApplicationId,
    /// The recording stream could not be created (file not creatable, viewer not spawnable,
    /// malformed or non-`/proxy` URL).
    #[error("cannot open rerun recording ({sink}): {error}")]
    Open {
        /// The sink, in words (e.g. `file out.rrd`, `connect rerun+http://127.0.0.1:9876/proxy`).
        sink: String,
        /// rerun's error (in the message, so not a `source`: said once).
        error: rerun::RecordingStreamError,
    },
    /// Data could not be logged to an entity.
    #[error("cannot log to rerun entity {entity}: {error}")]
    Log {
        /// The entity path.
        entity: String,
        /// rerun's error (in the message, so not a `source`: said once).
        error: rerun::RecordingStreamError,
    },
    /// An image buffer does not hold `width × height × channels` bytes.
    #[error("camera {camera}: {what} of {width}x{height} needs {expected} bytes, got {actual}")]
    ImageSize {
        /// The camera the image belongs to.
        camera: String,
        /// Which kind of image (`RGB image`, `label image`).
        what: &'static str,
        /// Image width, pixels.
        width: u32,
        /// Image height, pixels.
        height: u32,
        /// Bytes the size implies.
        expected: u64,
        /// Bytes given.
        actual: u64,
    },
    /// An `.rrd` file could not be created or its header written.
    #[error("cannot create rerun recording {path}: {message}")]
    Create {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// An `.rrd` file could not be read back.
    #[error("cannot read rerun recording {path}: {message}")]
    Read {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// Flushing the recording to its sink failed or timed out.
    #[error("cannot write rerun recording: {error}")]
    Flush {
        /// rerun's error, or the file's write error and what was kept (in the message, so not a
        /// `source`: said once).
        error: rerun::sink::SinkFlushError,
    },
}
