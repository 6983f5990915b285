//! Errors of the simulator. Each names the scenario key, file or step it is about.

/// What can go wrong setting up or running a simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A parameter is out of range or contradicts another; `key` is its scenario path.
    #[error("`{key}`: {message}")]
    Invalid {
        /// Scenario key, e.g. `material.mu`.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The scenario file could not be read or parsed.
    #[error("{file}: {message}")]
    Scenario {
        /// The file.
        file: String,
        /// What is wrong (with the key or line where known).
        message: String,
    },
    /// The GPU backend failed (no adapter, limits, a lost device) or cannot run this model.
    #[error("GPU backend: {0}")]
    Gpu(String),
}
