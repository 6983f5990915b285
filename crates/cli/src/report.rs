//! What every JSON report shares: schema version, provenance and stage timings.

use std::path::Path;
use std::time::Duration;

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

/// Version of the report layout (docs/reports.md).
pub const SCHEMA_VERSION: u32 = 1;

/// Git commit the binary was built from (build.rs), as reports and `--version` give it.
pub const GIT_HASH: &str = env!("HULLCUT_GIT_HASH");

/// `hullcut --version`: the package version and the git commit reports carry.
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (", env!("HULLCUT_GIT_HASH"), ")");

/// Where a report came from, so a run can be reproduced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// hullcut's version.
    pub hullcut_version: String,
    /// Git commit the binary was built from ([`GIT_HASH`]).
    pub git_hash: String,
    /// The command line.
    pub command_line: Vec<String>,
}

impl Provenance {
    /// Provenance of this process.
    pub fn current() -> Self {
        Self {
            hullcut_version: env!("CARGO_PKG_VERSION").to_owned(),
            git_hash: GIT_HASH.to_owned(),
            command_line: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
        }
    }
}

/// Timing statistics of one stage, milliseconds.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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

/// Writes a report as pretty JSON, after checking that it reads back as the same report (every
/// report type is `Deserialize`; a field that would not survive the trip is a bug, refused here
/// rather than written). The file is written beside its place and renamed over it, so a failed
/// write (a full disk) never leaves half a report.
pub fn write_json<T: Serialize + serde::de::DeserializeOwned>(path: &Path, value: &T) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value).context("serializing the report")?;
    let back: T = serde_json::from_str(&text).context("the report does not read back")?;
    let again = serde_json::to_string_pretty(&back).context("serializing the report read back")?;
    if again != text {
        anyhow::bail!("the report for {} does not read back as written", path.display());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let write = || -> std::io::Result<()> {
        let mut file = tempfile::NamedTempFile::new_in(dir)?;
        std::io::Write::write_all(&mut file, (text + "\n").as_bytes())?;
        file.persist(path).map_err(|e| e.error)?;
        Ok(())
    };
    write().with_context(|| format!("writing report {}", path.display()))
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

/// Serializes `value` to JSON, reads it back as `T` and serializes that again (tests): the two
/// texts are equal when every field survives the round trip.
#[cfg(test)]
pub(crate) fn json_round_trip<T: Serialize + serde::de::DeserializeOwned>(value: &T) -> (String, String) {
    let text = serde_json::to_string_pretty(value).expect("serializes");
    let back: T = serde_json::from_str(&text).unwrap_or_else(|e| panic!("reads back: {e}\n{text}"));
    (text, serde_json::to_string_pretty(&back).expect("serializes again"))
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

    #[test]
    fn provenance_and_timings_round_trip() {
        let p = Provenance::current();
        assert_eq!(p.git_hash, GIT_HASH);
        let (version, hash) = (env!("CARGO_PKG_VERSION"), GIT_HASH);
        assert_eq!(VERSION, format!("{version} ({hash})"));
        let text = serde_json::to_string(&p).expect("serializes");
        assert_eq!(serde_json::from_str::<Provenance>(&text).expect("reads back"), p);
        // Milliseconds that JSON writes and reads exactly (sums of powers of two).
        let t = StageTiming { count: 3, mean_ms: 14.5, p50_ms: 2.25, p95_ms: 40.0, max_ms: 40.0 };
        let text = serde_json::to_string(&t).expect("serializes");
        assert_eq!(serde_json::from_str::<StageTiming>(&text).expect("reads back"), t);
        let (first, again) = json_round_trip(&t);
        assert_eq!(first, again);
    }
}
