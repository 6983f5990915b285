//! Input checks of `hullcut reconstruct` and the per-camera disagreement it reports.

use anyhow::bail;
use hullcut_dataset::{Dataset, FrameSet, label};
use hullcut_hull::CarveStats;
use serde::Serialize;

/// `--voxel` lies in (0, the workspace's side].
pub(crate) fn voxel(voxel: f64, extent: f64) -> anyhow::Result<()> {
    if !(voxel > 0.0 && voxel <= extent) {
        bail!(
            "--voxel {voxel}: the leaf size must be above 0 and at most the side of the carved workspace ({extent} m)"
        );
    }
    Ok(())
}

/// Whether masks come from the dataset's files (else segmented): `--masks auto|files|segment`.
pub(crate) fn masks_from_files(ds: &Dataset, masks: &str) -> anyhow::Result<bool> {
    Ok(match masks {
        "files" if !ds.has_masks() => bail!("--masks files: {} has no masks/", ds.root().display()),
        "files" => true,
        "segment" => false,
        "auto" => ds.has_masks(),
        other => bail!("--masks {other}: expected auto, files or segment"),
    })
}

/// Every mask of the frame set holds only the labels carving knows (0, 1, 2, 255); anything else
/// (a mask saved with other values, a palette PNG's indices) is an error naming the file.
pub(crate) fn labels(ds: &Dataset, set: &FrameSet) -> anyhow::Result<()> {
    let bad = |v: &u8| ![label::BACKGROUND, label::HAND, label::SCALPEL, label::UNKNOWN].contains(v);
    for view in set.views.iter().flatten() {
        let Some(mask) = &view.mask else { continue };
        let raw = mask.as_raw();
        let Some(first) = raw.iter().position(bad) else { continue };
        let w = mask.width() as usize;
        bail!(
            "{}: label mask of camera `{}`, frame {}: pixel ({}, {}) holds {} ({} pixels outside the labels \
             0 background, 1 hand, 2 scalpel, 255 unknown)",
            ds.mask_path(set.frame, view.camera)?.display(),
            ds.rig().cameras[view.camera].name,
            set.frame,
            first % w,
            first / w,
            raw[first],
            raw.iter().filter(|v| bad(v)).count()
        );
    }
    Ok(())
}

/// Lone refutations of one camera, summed over frames.
#[derive(Debug, Serialize)]
pub(super) struct LoneRefutations {
    camera: String,
    cells: u64,
}

/// Which view disagreed with all the others, and how often (docs/reports.md).
#[derive(Debug, Serialize)]
pub(super) struct ViewDisagreement {
    lone_refutations: Vec<LoneRefutations>,
    disagreed_most: Option<String>,
    most_over_median: Option<f64>,
}

impl ViewDisagreement {
    /// Zero counts for the rig's cameras.
    pub(super) fn new(cameras: &[String]) -> Self {
        ViewDisagreement {
            lone_refutations: cameras.iter().map(|c| LoneRefutations { camera: c.clone(), cells: 0 }).collect(),
            disagreed_most: None,
            most_over_median: None,
        }
    }

    /// Adds one carving's counts (rig order).
    pub(super) fn add(&mut self, stats: &CarveStats) {
        for (l, n) in self.lone_refutations.iter_mut().zip(&stats.lone_refutations) {
            l.cells += n;
        }
    }

    /// Names the camera with the most lone refutations (the first of equals; none when no camera
    /// refuted a cell alone) and its count over the median camera's.
    pub(super) fn finish(&mut self) {
        let mut counts: Vec<u64> = self.lone_refutations.iter().map(|l| l.cells).collect();
        counts.sort_unstable();
        let median = match counts.len() {
            0 => 0.0,
            n if n % 2 == 1 => counts[n / 2] as f64,
            n => (counts[n / 2 - 1] + counts[n / 2]) as f64 / 2.0,
        };
        let most = self
            .lone_refutations
            .iter()
            .enumerate()
            .max_by_key(|&(k, l)| (l.cells, std::cmp::Reverse(k)))
            .map(|(_, l)| l)
            .filter(|l| l.cells > 0);
        self.disagreed_most = most.map(|l| l.camera.clone());
        self.most_over_median = most.filter(|_| median > 0.0).map(|l| l.cells as f64 / median);
    }

    /// One line for the terminal, when a camera disagreed at all.
    pub(super) fn summary(&self) -> Option<String> {
        let name = self.disagreed_most.as_ref()?;
        let n = self.lone_refutations.iter().find(|l| &l.camera == name).map_or(0, |l| l.cells);
        let ratio = self
            .most_over_median
            .map_or(String::from("the median camera has none"), |r| format!("{r:.1}x the median camera"));
        Some(format!(
            "  views: {name} disagreed most ({n} cells it alone refuted, {ratio}; a view with a bad mask or \
             calibration stands out at several times)"
        ))
    }
}
