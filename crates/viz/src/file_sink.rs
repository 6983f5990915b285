//! An `.rrd` file sink that notices a failed write.
//!
//! rerun's own file sink writes on a thread of its own and, when a write fails (a full disk, a
//! file-size limit), logs the error, stops, and drops every later message silently; the caller
//! learns only that "the file-writer thread shut down prematurely", and the file ends inside a
//! message. This sink encodes and writes each message as it comes, and on the first failed write
//! cuts the file back to the end of the last whole message (so every message in it decodes), keeps
//! the I/O error, counts what it drops from then on, and reports all of it from `flush_blocking`.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use rerun::external::re_log_encoding::{CrateVersion, EncodeError, Encoder, EncodingOptions};
use rerun::log::LogMsg;
use rerun::sink::{LogSink, SinkFlushError};

use crate::VizError;

/// What the sink has written and what went wrong.
struct State {
    path: PathBuf,
    file: Arc<File>,
    /// `None` once a write failed (or the stream was finished).
    encoder: Option<Encoder<Arc<File>>>,
    /// Bytes up to the end of the last message written whole.
    kept: u64,
    /// Messages dropped after the failure.
    dropped: u64,
    /// The first failed write.
    error: Option<String>,
}

impl State {
    /// Stops writing after `error`: the encoder is released without finishing (which would write
    /// again) and the partial message is cut off.
    fn fail(&mut self, error: String) {
        if let Some(encoder) = self.encoder.take() {
            // The encoder's footer would be a second write into the same failure: released unfinished.
            let _ = encoder.into_inner();
        }
        if let Err(e) = self.file.set_len(self.kept) {
            tracing::warn!(path = %self.path.display(), "cannot cut the recording back to its last whole message: {e}");
        }
        self.error.get_or_insert(error);
    }
}

impl Drop for State {
    fn drop(&mut self) {
        let Some(encoder) = self.encoder.as_mut() else { return };
        match encoder.finish() {
            Ok(()) => {}
            Err(e) => self.fail(format!("finishing the recording: {e}")),
        }
    }
}

/// A [`LogSink`] writing an `.rrd` file synchronously, reporting write failures (see the module
/// docs).
pub(crate) struct CheckedFileSink(Mutex<State>);

impl CheckedFileSink {
    /// Creates (or truncates) `path` and writes the stream header; without `footer`, the file
    /// ends without rerun's chunk index (see [`crate::open_recording_indexed`]).
    pub(crate) fn create(path: &Path, footer: bool) -> Result<Self, VizError> {
        let open = |message: String| VizError::Create { path: path.display().to_string(), message };
        let file = Arc::new(File::create(path).map_err(|e| open(e.to_string()))?);
        let mut encoder =
            Encoder::new_eager(CrateVersion::LOCAL, EncodingOptions::PROTOBUF_COMPRESSED, Arc::clone(&file))
                .map_err(|e| open(format!("writing the header: {e}")))?;
        if !footer {
            encoder.do_not_emit_footer();
        }
        let kept = file.metadata().map_err(|e| open(e.to_string()))?.len();
        Ok(Self(Mutex::new(State {
            path: path.to_owned(),
            file,
            encoder: Some(encoder),
            kept,
            dropped: 0,
            error: None,
        })))
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // A panic while holding the lock leaves the counts as they were: still worth reporting.
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl LogSink for CheckedFileSink {
    fn send(&self, msg: LogMsg) {
        let mut state = self.state();
        let Some(encoder) = state.encoder.as_mut() else {
            state.dropped += 1;
            return;
        };
        match encoder.append(&msg) {
            Ok(bytes) => state.kept += bytes,
            Err(EncodeError::Write(e)) => {
                state.dropped += 1;
                state.fail(e.to_string());
            }
            // Not a write: the message could not be encoded; the file is as it was.
            Err(e) => {
                state.dropped += 1;
                tracing::warn!(path = %state.path.display(), "a message could not be encoded for the recording: {e}");
            }
        }
    }

    fn flush_blocking(&self, _timeout: Duration) -> Result<(), SinkFlushError> {
        let state = self.state();
        match &state.error {
            None => Ok(()),
            Some(error) => Err(SinkFlushError::failed(format!(
                "{}: {error}; the file keeps its first {} bytes (every message in them reads back), {} messages \
                 after them were dropped",
                state.path.display(),
                state.kept,
                state.dropped
            ))),
        }
    }
}
