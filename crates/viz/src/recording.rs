//! Opening a recording on a sink, flushing it, and setting the timelines.

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use rerun::{ApplicationId, RecordingStream, RecordingStreamBuilder};

use crate::VizError;
use crate::file_sink::CheckedFileSink;

/// Name of the sequence timeline: the index of a synchronised multi-camera frame.
pub const FRAME_TIMELINE: &str = "frame";

/// Name of the timestamp timeline: when a frame was captured (or simulated).
pub const CAPTURE_TIME_TIMELINE: &str = "capture_time";

/// How long [`flush`] waits for the sink before giving up. Long enough for a viewer on another
/// machine to take a few hundred megabytes; a file sink finishes far sooner.
pub const FLUSH_TIMEOUT: Duration = Duration::from_secs(60);

/// Where a recording goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sink {
    /// Write an `.rrd` file (created or truncated when the recording opens). A failed write (a full
    /// disk) cuts the file after the last whole message and is reported by [`flush`].
    File(PathBuf),
    /// Start a Rerun Viewer (the `rerun` executable must be on `PATH`) and stream to it; a viewer
    /// already listening on the default port is reused.
    Spawn,
    /// Stream over gRPC to a running viewer or server, at a URL such as
    /// `rerun+http://127.0.0.1:9876/proxy` (rerun's URL form; it must end in `/proxy`).
    Connect(String),
}

impl fmt::Display for Sink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File(path) => write!(f, "file {}", path.display()),
            Self::Spawn => f.write_str("spawned viewer"),
            Self::Connect(url) => write!(f, "connect {url}"),
        }
    }
}

/// Opens a recording named `application_id` on `sink`.
///
/// rerun replaces dots and characters it does not allow in the name with `-`; an empty name is an
/// error.
///
/// The recording is always enabled: hullcut opens one only when the user asked for it, so the
/// `RERUN` environment variable (which can switch rerun's default off) is not consulted.
/// Nothing is logged yet; call [`log_world`](crate::log_world) and [`log_rig`](crate::log_rig)
/// next.
pub fn open_recording(application_id: &str, sink: &Sink) -> Result<RecordingStream, VizError> {
    open_recording_indexed(application_id, sink, true)
}

/// As [`open_recording`]; a file written without `index` has no footer (rerun's index of every
/// chunk, written when the file is closed and kept in memory until then: some 10 KB for each
/// frame set of `hullcut run`, 200 MB over ten minutes). The viewer reads such a file all the
/// same, from the start; long runs should leave the index out to keep their memory flat.
pub fn open_recording_indexed(application_id: &str, sink: &Sink, index: bool) -> Result<RecordingStream, VizError> {
    let id = ApplicationId::try_new(application_id).map_err(|_| VizError::ApplicationId)?;
    let builder = RecordingStreamBuilder::new(id).enabled(true);
    let open = |error| VizError::Open { sink: sink.to_string(), error };
    match sink {
        Sink::File(path) => {
            let file_sink = CheckedFileSink::create(path, index)?;
            let rec = builder.buffered().map_err(open)?;
            rec.set_sink(Box::new(file_sink));
            Ok(rec)
        }
        Sink::Spawn => builder.spawn().map_err(open),
        Sink::Connect(url) => builder.connect_grpc_opts(url.clone()).map_err(open),
    }
}

/// Sends everything logged so far to the sink and waits (at most [`FLUSH_TIMEOUT`]) until it is
/// there. Dropping the last handle to a recording flushes too, but cannot report an error.
///
/// For a file, an error names the write that failed (a full disk, a file-size limit), how many
/// bytes of the recording were kept (the file is cut after the last whole message, so it reads
/// back) and how many messages were dropped since.
pub fn flush(rec: &RecordingStream) -> Result<(), VizError> {
    rec.flush_with_timeout(FLUSH_TIMEOUT).map_err(|error| VizError::Flush { error })
}

/// Sets the `frame` timeline (a sequence) for everything this thread logs next.
///
/// rerun keeps the current time per thread: set it on the thread that logs.
pub fn set_frame(rec: &RecordingStream, frame: i64) {
    rec.set_time_sequence(FRAME_TIMELINE, frame);
}

/// Sets the `capture_time` timeline (nanoseconds since the Unix epoch) for everything this thread
/// logs next.
///
/// rerun keeps the current time per thread: set it on the thread that logs.
pub fn set_capture_time_ns(rec: &RecordingStream, ns: i64) {
    rec.set_timestamp_nanos_since_epoch(CAPTURE_TIME_TIMELINE, ns);
}
