//! `--weak-foreground`: when the weak foreground test runs, shared by the commands that segment.

use hullcut_dataset::Dataset;
use hullcut_pipeline::{Labelling, WeakWhen};

/// When a pixel the foreground test calls background, but that differs from it by half its
/// tolerances, becomes foreground where the other views' hull covers it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum WeakArg {
    /// From the frame set after the tool's track was refused in 6 of the last 30 frame sets on,
    /// for the rest of the recording (never without tool.json).
    TrackLost,
    /// On every frame set.
    Always,
    /// Never.
    Never,
}

/// Sets up `labelling`'s weak foreground test as `when` asks (`always` where `confirm`, the
/// older flag, is given).
pub(crate) fn set_up(labelling: &mut Labelling, ds: &Dataset, when: WeakArg, confirm: bool) -> anyhow::Result<()> {
    let when = match (confirm, when) {
        (true, _) | (false, WeakArg::Always) => WeakWhen::Always,
        (false, WeakArg::TrackLost) => WeakWhen::TrackLost,
        (false, WeakArg::Never) => return Ok(()),
    };
    labelling.confirm_weak_foreground_when(ds, when)?;
    Ok(())
}
