//! `--frames A:B|N`: which frame numbers of a dataset a command works on (DESIGN "Command line").

use std::ops::Range;

use anyhow::bail;

/// Parses `A:B` (half-open, frame numbers) or `N` (the first N, `0:N`), clamped to `count`.
/// None means every frame.
pub fn parse_frames(spec: Option<&str>, count: u64) -> anyhow::Result<Range<u64>> {
    let Some(spec) = spec else { return Ok(0..count) };
    let number = |s: &str| -> anyhow::Result<u64> {
        s.trim().parse::<u64>().map_err(|_| anyhow::anyhow!("--frames {spec}: {s:?} is not a frame number"))
    };
    let range = match spec.split_once(':') {
        Some((a, b)) => number(a)?..number(b)?,
        None => 0..number(spec)?,
    };
    if range.start >= range.end {
        bail!("--frames {spec}: the range is empty (A:B is half-open, A < B)");
    }
    if range.start >= count {
        bail!("--frames {spec}: the dataset has {count} frames (0..{count})");
    }
    Ok(range.start..range.end.min(count))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_half_open_and_clamped() {
        assert_eq!(parse_frames(None, 10).ok(), Some(0..10));
        assert_eq!(parse_frames(Some("4"), 10).ok(), Some(0..4));
        assert_eq!(parse_frames(Some("3:7"), 10).ok(), Some(3..7));
        assert_eq!(parse_frames(Some("3:70"), 10).ok(), Some(3..10));
        for bad in ["7:3", "x", "12:14", "0", "1:1"] {
            assert!(parse_frames(Some(bad), 10).is_err(), "{bad}");
        }
    }
}
