//! File names of the dataset layout and the checks reader and writer share.

use std::path::Path;

use nalgebra::Matrix4;
use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};
use crate::types::{DatasetMeta, TruthPose};
use crate::{FORMAT_VERSION, MAX_FRAME_COUNT};
use hullcut_rig::MAX_CAMERAS;

/// `dataset.toml`.
pub(crate) const DATASET_TOML: &str = "dataset.toml";
/// `rig.yaml`.
pub(crate) const RIG_YAML: &str = "rig.yaml";
/// `frames.csv`.
pub(crate) const FRAMES_CSV: &str = "frames.csv";
/// Header line of `frames.csv`.
pub(crate) const FRAMES_CSV_HEADER: &str = "frame,camera,timestamp_ns";
/// `tool.json`.
pub(crate) const TOOL_JSON: &str = "tool.json";
/// Folder of label masks.
pub(crate) const MASKS: &str = "masks";
/// Folder of depth images.
pub(crate) const DEPTH: &str = "depth";
/// Folder of ground truth.
pub(crate) const TRUTH: &str = "truth";
/// Truth poses, relative to the dataset root.
pub(crate) const POSES_JSONL: &str = "truth/poses.jsonl";
/// Truth meshes, relative to the dataset root.
pub(crate) const MESHES: &str = "truth/meshes";
/// Names a camera may not have, because the dataset uses them for other folders.
const RESERVED: [&str; 3] = [MASKS, DEPTH, TRUTH];

/// The file name of a frame's image, mask or depth image: six digits and `.png` (`000012.png`).
pub fn frame_file_name(frame: u64) -> String {
    format!("{frame:06}.png")
}

/// The frame number of a file named like `^[0-9]{6}\.png$`; `None` for any other name
/// (`background00.png`, `12.png`, `0000012.png`).
pub fn parse_frame_file_name(name: &str) -> Option<u64> {
    let digits = name.strip_suffix(".png")?;
    if digits.len() == 6 && digits.bytes().all(|b| b.is_ascii_digit()) { digits.parse().ok() } else { None }
}

/// Whether `name` may be used as one path component (a camera or label name): non-empty, not
/// hidden, no separators or control characters.
pub(crate) fn check_component(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("the name is empty".to_owned());
    }
    if name.starts_with('.') {
        return Err(format!("`{name}` starts with a dot"));
    }
    if name.chars().any(|c| c == '/' || c == '\\' || c == ':' || c.is_control()) {
        return Err(format!("`{name}` contains a path separator or control character"));
    }
    Ok(())
}

/// Checks `dataset.toml`'s values; `path` names the file in errors.
pub(crate) fn validate_meta(path: &Path, meta: &DatasetMeta) -> Result<()> {
    let invalid =
        |key: &str, message: String| DatasetError::Invalid { path: path.to_owned(), key: key.to_owned(), message };
    if meta.format_version != FORMAT_VERSION {
        return Err(invalid(
            "format_version",
            format!("this reader knows version {FORMAT_VERSION}, the file has {}", meta.format_version),
        ));
    }
    if !(meta.fps.is_finite() && meta.fps > 0.0) {
        return Err(invalid("fps", format!("must be positive, found {}", meta.fps)));
    }
    if meta.frame_count > MAX_FRAME_COUNT {
        return Err(invalid(
            "frame_count",
            format!("{} exceeds {MAX_FRAME_COUNT} (frame numbers have six digits)", meta.frame_count),
        ));
    }
    if meta.cameras.is_empty() {
        return Err(invalid("cameras", "no cameras".to_owned()));
    }
    if meta.cameras.len() > MAX_CAMERAS {
        return Err(invalid(
            "cameras",
            format!("{} cameras, more than the {MAX_CAMERAS} a dataset may have", meta.cameras.len()),
        ));
    }
    if let Some(w) = &meta.workspace {
        let finite = w.min.iter().chain(&w.max).all(|c| c.is_finite());
        if !finite || (0..3).any(|a| w.min[a] >= w.max[a]) {
            return Err(invalid(
                "workspace",
                format!("needs finite corners with min < max on every axis, found min {:?}, max {:?}", w.min, w.max),
            ));
        }
    }
    for (i, name) in meta.cameras.iter().enumerate() {
        check_component(name).map_err(|m| invalid("cameras", format!("camera {i}: {m}")))?;
        if RESERVED.contains(&name.as_str()) {
            return Err(invalid("cameras", format!("camera {i}: `{name}` is reserved for the dataset's own folder")));
        }
        if meta.cameras[..i].contains(name) {
            return Err(invalid("cameras", format!("camera `{name}` is listed twice")));
        }
    }
    Ok(())
}

/// Checks that the rig's camera names are `dataset.toml`'s camera list, in order.
pub(crate) fn check_rig_cameras(rig_path: &Path, meta: &DatasetMeta, rig: &hullcut_rig::Rig) -> Result<()> {
    let names: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
    if names != meta.cameras {
        return Err(DatasetError::Inconsistent {
            path: rig_path.to_owned(),
            message: format!(
                "the rig's cameras {names:?} ({} cameras) differ from {DATASET_TOML}'s `cameras` {:?} ({} cameras); \
                 they must be the same names in the same order",
                names.len(),
                meta.cameras,
                meta.cameras.len()
            ),
        });
    }
    Ok(())
}

/// One line of `truth/poses.jsonl`, as written.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PoseLine {
    pub(crate) frame: u64,
    pub(crate) timestamp_ns: i64,
    pub(crate) tool_to_world: Vec<f64>,
}

/// Tolerance on the bottom row `[0, 0, 0, 1]` of a rigid transform.
const BOTTOM_ROW_TOLERANCE: f64 = 1e-9;

impl PoseLine {
    pub(crate) fn from_pose(pose: &TruthPose) -> Self {
        let m = &pose.tool_to_world;
        let tool_to_world = (0..4).flat_map(|r| (0..4).map(move |c| m[(r, c)])).collect();
        Self { frame: pose.frame, timestamp_ns: pose.timestamp_ns, tool_to_world }
    }

    /// The pose, after checking 16 finite numbers with a bottom row of `[0, 0, 0, 1]`.
    pub(crate) fn into_pose(self) -> std::result::Result<TruthPose, String> {
        let Ok(values) = <[f64; 16]>::try_from(self.tool_to_world.as_slice()) else {
            return Err(format!(
                "`tool_to_world` must hold 16 numbers (row-major 4x4), found {}",
                self.tool_to_world.len()
            ));
        };
        let m = Matrix4::from_row_slice(&values);
        check_transform(&m)?;
        Ok(TruthPose { frame: self.frame, timestamp_ns: self.timestamp_ns, tool_to_world: m })
    }
}

/// Checks a tool→world matrix: finite, bottom row `[0, 0, 0, 1]`.
pub(crate) fn check_transform(m: &Matrix4<f64>) -> std::result::Result<(), String> {
    if !m.iter().all(|v| v.is_finite()) {
        return Err("`tool_to_world` holds a non-finite number".to_owned());
    }
    let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    let expected = [0.0, 0.0, 0.0, 1.0];
    if bottom.iter().zip(expected).any(|(a, b)| (a - b).abs() > BOTTOM_ROW_TOLERANCE) {
        return Err(format!(
            "`tool_to_world`'s bottom row is {bottom:?}, expected [0, 0, 0, 1] (is the matrix transposed?)"
        ));
    }
    Ok(())
}
