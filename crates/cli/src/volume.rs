//! The working volume of `reconstruct`, `run` and `segment`: `--workspace` on the command line, else
//! `workspace` in dataset.toml, else derived from the rig (shared/DESIGN.md, "Working volume").

use anyhow::Context as _;
use hullcut_dataset::Dataset;
use hullcut_hull::{VolumeSource, WorkingVolume};
use hullcut_rig::Rig;

/// Views that must see a cell for carving to keep it, and that must see a point for the volume
/// derived from the rig to hold it.
pub(crate) const MIN_VIEWS: usize = 3;

/// `--workspace MINX,MINY,MINZ,MAXX,MAXY,MAXZ` in metres, parsed by clap (bad input is bad usage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WorkspaceArg {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl std::str::FromStr for WorkspaceArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let values: Vec<f64> = s
            .split(',')
            .map(|v| {
                v.trim().parse::<f64>().map_err(|_| format!("`{}` is not a number", crate::report::shorten(v, 40)))
            })
            .collect::<Result<_, _>>()?;
        let [x0, y0, z0, x1, y1, z1] = values[..] else {
            return Err(format!("expected six numbers MINX,MINY,MINZ,MAXX,MAXY,MAXZ, got {}", values.len()));
        };
        let (min, max) = ([x0, y0, z0], [x1, y1, z1]);
        if !values.iter().all(|v| v.is_finite()) || (0..3).any(|a| min[a] >= max[a]) {
            return Err("the corners must be finite with MIN < MAX on every axis (metres)".to_owned());
        }
        Ok(Self { min, max })
    }
}

/// The working volume: the flag's, the dataset's or the rig's, said on standard output.
pub(crate) fn resolve(flag: Option<WorkspaceArg>, ds: Option<&Dataset>, rig: &Rig) -> anyhow::Result<WorkingVolume> {
    let volume = match (flag, ds.and_then(|d| d.meta().workspace.map(|w| (d, w)))) {
        (Some(w), _) => {
            WorkingVolume::given(w.min, w.max, VolumeSource::CommandLine, rig, MIN_VIEWS).context("--workspace")?
        }
        (None, Some((ds, w))) => WorkingVolume::given(w.min, w.max, VolumeSource::Dataset, rig, MIN_VIEWS)
            .with_context(|| format!("{}: workspace", ds.root().join("dataset.toml").display()))?,
        (None, None) => WorkingVolume::from_rig(rig, MIN_VIEWS, rig.world_frame.is_table())
            .context("deriving the working volume from the rig (give one with --workspace)")?,
    };
    println!("{}", volume.describe());
    Ok(volume)
}

/// The volume a rig's cameras see (at least [`MIN_VIEWS`] of them), for benches on rendered scenes.
pub(crate) fn of_rig(rig: &Rig) -> anyhow::Result<WorkingVolume> {
    WorkingVolume::from_rig(rig, MIN_VIEWS, rig.world_frame.is_table())
        .context("deriving the working volume from the rig")
}

/// The hull's settings for a rig's own volume and a leaf size (as `reconstruct` and `run` carve).
pub(crate) fn hull_params(rig: &Rig, leaf: f64) -> anyhow::Result<hullcut_hull::HullParams> {
    Ok(hullcut_hull::HullParams { min_views: MIN_VIEWS, ..hullcut_hull::HullParams::new(of_rig(rig)?.aabb, leaf) })
}

/// Leaf sizes of the benches are given as a side of 0.4 m (the default rig's old workspace) over
/// 2^n: 64 → 6.25 mm, 128 → 3.125 mm, 256 → 1.5625 mm.
pub(crate) const BENCH_SIDE_M: f64 = 0.4;

/// Logs the volume as a labelled box at `world/workspace` (static).
pub(crate) fn log(rec: &hullcut_viz::RecordingStream, volume: &WorkingVolume) -> anyhow::Result<()> {
    let f = |p: &nalgebra::Point3<f64>| [p.x as f32, p.y as f32, p.z as f32];
    hullcut_viz::log_box3d(
        rec,
        "world/workspace",
        f(&volume.aabb.min),
        f(&volume.aabb.max),
        &volume.source.describe(),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workspace_flag_parses_six_finite_ordered_numbers() {
        let w: WorkspaceArg = "-0.1,-0.2,0,0.1,0.2,0.3".parse().expect("valid");
        assert_eq!(w.min, [-0.1, -0.2, 0.0]);
        assert_eq!(w.max, [0.1, 0.2, 0.3]);
        for bad in ["", "1,2,3", "0,0,0,1,1,x", "0,0,0,1,1,NaN", "0,0,0,1,1,inf", "0,0,1,1,1,1", "0,0,0,1,1,1,1"] {
            assert!(bad.parse::<WorkspaceArg>().is_err(), "{bad:?} accepted");
        }
    }
}
