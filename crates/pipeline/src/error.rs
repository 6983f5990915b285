//! The pipeline's error: what failed, with the context it failed in (the frame, the file, the
//! flag), outermost first.

/// A failure of the pipeline or of one of its stages' set-up.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A failure described in full by its message.
    #[error("{0}")]
    Message(String),
    /// A failure of a library the pipeline calls, in the context it was called in.
    #[error("{context}: {cause}")]
    Context {
        /// Where it happened (a frame, a file, a flag).
        context: String,
        /// What went wrong there (its message is part of this error's).
        cause: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}

impl Error {
    /// An error of `message` alone.
    pub fn msg(message: impl Into<String>) -> Self {
        Error::Message(message.into())
    }
}

/// Adds context to a failed result, as the stages report it ("frame 12: ...").
pub trait Context<T> {
    /// The error, if any, said to have happened in `context`.
    fn context(self, context: impl Into<String>) -> Result<T, Error>;
    /// As [`Context::context`], the context made only on failure.
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T, Error>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> Context<T> for Result<T, E> {
    fn context(self, context: impl Into<String>) -> Result<T, Error> {
        self.map_err(|e| Error::Context { context: context.into(), cause: Box::new(e) })
    }

    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T, Error> {
        self.map_err(|e| Error::Context { context: context().into(), cause: Box::new(e) })
    }
}

/// Returns early with an [`Error::Message`] made by `format!`.
macro_rules! fail {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Message(format!($($arg)*)))
    };
}
pub(crate) use fail;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_reads_outermost_first_and_keeps_the_cause() {
        let parsed: Result<u8, _> = "300".parse::<u8>();
        let e = parsed.context("frame 12").expect_err("300 is not a u8");
        assert_eq!(e.to_string(), "frame 12: number too large to fit in target type");
        let nested: Result<(), Error> = Err(e).with_context(|| "the hull stage");
        assert_eq!(
            nested.expect_err("failed").to_string(),
            "the hull stage: frame 12: number too large to fit in target type"
        );
    }
}
