//! What every JSON report shares: schema version, provenance and stage timings.

use std::path::Path;
use std::time::Duration;

use anyhow::Context as _;
use serde::Serialize;

/// Version of the report layout (docs/reports.md).
pub const SCHEMA_VERSION: u32 = 1;

/// Where a report came from, so a run can be reproduced.
#[derive(Debug, Serialize)]
pub struct Provenance {
    /// hullcut's version.
    pub hullcut_version: &'static str,
    /// Git commit the binary was built from.
    pub git_hash: &'static str,
    /// The command line.
    pub command_line: Vec<String>,
}

impl Provenance {
    /// Provenance of this process.
    pub fn current() -> Self {
        Self {
            hullcut_version: env!("CARGO_PKG_VERSION"),
            git_hash: env!("HULLCUT_GIT_HASH"),
            command_line: std::env::args().collect(),
        }
    }
}

/// Timing statistics of one stage, milliseconds.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct StageTiming {
    /// Number of times the stage ran.
    pub count: usize,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Median, ms.
    pub p50_ms: f64,
    /// 95th percentile (nearest rank), ms.
    pub p95_ms: f64,
    /// Maximum, ms.
    pub max_ms: f64,
}

impl StageTiming {
    /// Statistics of a set of durations.
    pub fn from_durations(d: &[Duration]) -> Self {
        let mut ms: Vec<f64> = d.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        ms.sort_by(f64::total_cmp);
        let rank = |q: f64| -> f64 {
            if ms.is_empty() {
                return 0.0;
            }
            let i = ((q * ms.len() as f64).ceil() as usize).clamp(1, ms.len()) - 1;
            ms[i]
        };
        Self {
            count: ms.len(),
            mean_ms: if ms.is_empty() { 0.0 } else { ms.iter().sum::<f64>() / ms.len() as f64 },
            p50_ms: rank(0.5),
            p95_ms: rank(0.95),
            max_ms: ms.last().copied().unwrap_or(0.0),
        }
    }
}

/// Writes a report as pretty JSON.
pub fn write_json(path: &Path, value: &impl Serialize) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value).context("serializing the report")?;
    std::fs::write(path, text + "\n").with_context(|| format!("writing report {}", path.display()))
}

/// A value for a message, cut to `max` characters (with an ellipsis and the full length) so that
/// a long bad input is not echoed whole.
pub fn shorten(s: &str, max: usize) -> String {
    let n = s.chars().count();
    if n <= max {
        return s.to_owned();
    }
    let head: String = s.chars().take(max).collect();
    format!("{head}… ({n} characters)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timing_statistics() {
        let d: Vec<Duration> = (1..=20).map(Duration::from_millis).collect();
        let t = StageTiming::from_durations(&d);
        assert_eq!(t.count, 20);
        assert!((t.mean_ms - 10.5).abs() < 1e-9);
        assert_eq!((t.p50_ms, t.p95_ms, t.max_ms), (10.0, 19.0, 20.0));
        assert_eq!(StageTiming::from_durations(&[]).count, 0);
    }
}
