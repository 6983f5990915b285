//! File names of the dataset layout and the checks reader and writer share.

use std::io::Read as _;
use std::path::Path;

use nalgebra::Matrix4;
use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};
use crate::types::{DatasetMeta, TruthPose};
use crate::{FORMAT_VERSION, MAX_ABS_TIMESTAMP_NS, MAX_FPS, MAX_FRAME_COUNT, MIN_FPS};
use hullcut_rig::{MAX_CAMERAS, MAX_WORLD_COORDINATE_M, check_rotation, short_number, shorten, shorten_to};

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
        return Err(format!("`{}` starts with a dot", shorten(name)));
    }
    if name.chars().any(|c| c == '/' || c == '\\' || c == ':' || c.is_control()) {
        return Err(format!("`{}` contains a path separator or control character", shorten(name)));
    }
    Ok(())
}

/// Camera names for a message: each shortened (see [`shorten`]), quoted, comma-separated.
pub(crate) fn name_list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let names: Vec<String> = names.into_iter().map(|n| format!("`{}`", shorten(n))).collect();
    format!("[{}]", names.join(", "))
}

/// Reads a UTF-8 text file of at most `limit` bytes (reading stops there, so a device or an
/// endless file cannot make it read forever). A missing file is [`DatasetError::Missing`] with
/// `missing` as its message when that is given, else [`DatasetError::Io`].
pub(crate) fn read_text(path: &Path, limit: u64, missing: Option<&str>) -> Result<String> {
    let file = match (std::fs::File::open(path), missing) {
        (Ok(f), _) => f,
        (Err(e), Some(message)) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(DatasetError::Missing { path: path.to_owned(), message: message.to_owned() });
        }
        (Err(error), _) => return Err(DatasetError::Io { path: path.to_owned(), error }),
    };
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1)).read_to_end(&mut bytes).map_err(DatasetError::io(path))?;
    if bytes.len() as u64 > limit {
        return Err(DatasetError::TooLarge { path: path.to_owned(), limit });
    }
    String::from_utf8(bytes).map_err(|e| DatasetError::Parse {
        path: path.to_owned(),
        message: format!("not UTF-8 text: {}", e.utf8_error()),
    })
}

/// A `serde_json` error's message shortened (it echoes strings and unknown keys from the file),
/// with its place: line and column for a whole file, the column alone for one line of a
/// line-oriented file (whose error names the line itself).
pub(crate) fn json_message(e: &serde_json::Error, whole_file: bool) -> String {
    let full = e.to_string();
    let suffix = format!(" at line {} column {}", e.line(), e.column());
    let Some(message) = full.strip_suffix(&suffix) else { return shorten_to(&full, 200) };
    let place = if whole_file { suffix } else { format!(" at column {}", e.column()) };
    format!("{}{place}", shorten_to(message, 200))
}

/// A `toml` error's message shortened (its default display quotes the whole offending line), with
/// the line and column of its span in `text`.
pub(crate) fn toml_message(e: &toml::de::Error, text: &str) -> String {
    let message = shorten_to(e.message().trim(), 200);
    let Some(start) = e.span().map(|s| s.start) else { return message };
    let before = text.get(..start).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!("{message} (line {line}, column {column})")
}

/// Checks a timestamp against [`MAX_ABS_TIMESTAMP_NS`].
pub(crate) fn check_timestamp(t: i64) -> std::result::Result<(), String> {
    if t.checked_abs().is_some_and(|a| a <= MAX_ABS_TIMESTAMP_NS) {
        Ok(())
    } else {
        Err(format!(
            "the timestamp {t} ns is outside ±{MAX_ABS_TIMESTAMP_NS} ns (about 127 years around the clock's epoch)"
        ))
    }
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
    if !(MIN_FPS..=MAX_FPS).contains(&meta.fps) {
        return Err(invalid(
            "fps",
            format!("{} is outside [{MIN_FPS}, {MAX_FPS}] frames per second", short_number(meta.fps)),
        ));
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
        let bounded = w.min.iter().chain(&w.max).all(|c| c.abs() <= MAX_WORLD_COORDINATE_M);
        if !bounded || (0..3).any(|a| w.min[a] >= w.max[a]) {
            let corner = |c: &[f64; 3]| c.iter().map(|v| short_number(*v)).collect::<Vec<_>>().join(", ");
            return Err(invalid(
                "workspace",
                format!(
                    "needs corners within ±{MAX_WORLD_COORDINATE_M} m with min < max on every axis, found min [{}], \
                     max [{}]",
                    corner(&w.min),
                    corner(&w.max)
                ),
            ));
        }
    }
    for (i, name) in meta.cameras.iter().enumerate() {
        check_component(name).map_err(|m| invalid("cameras", format!("camera {i}: {m}")))?;
        if RESERVED.contains(&name.as_str()) {
            return Err(invalid("cameras", format!("camera {i}: `{name}` is reserved for the dataset's own folder")));
        }
        if meta.cameras[..i].contains(name) {
            return Err(invalid("cameras", format!("camera `{}` is listed twice", shorten(name))));
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
                "the rig's cameras {} ({} cameras) differ from {DATASET_TOML}'s `cameras` {} ({} cameras); \
                 they must be the same names in the same order",
                name_list(names.iter().copied()),
                names.len(),
                name_list(meta.cameras.iter().map(String::as_str)),
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

    /// The pose, after checking its timestamp ([`check_timestamp`]) and its matrix
    /// ([`check_transform`]).
    pub(crate) fn into_pose(self) -> std::result::Result<TruthPose, String> {
        check_timestamp(self.timestamp_ns).map_err(|m| format!("`timestamp_ns`: {m}"))?;
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

/// Checks a tool→world matrix: finite, bottom row `[0, 0, 0, 1]`, a rotation within
/// [`hullcut_rig::ROTATION_TOLERANCE`] (a rotation entry of 1e19 once hung a rotation fit
/// downstream) and a translation within ±[`MAX_WORLD_COORDINATE_M`].
pub(crate) fn check_transform(m: &Matrix4<f64>) -> std::result::Result<(), String> {
    if !m.iter().all(|v| v.is_finite()) {
        return Err("`tool_to_world` holds a non-finite number".to_owned());
    }
    let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    let expected = [0.0, 0.0, 0.0, 1.0];
    if bottom.iter().zip(expected).any(|(a, b)| (a - b).abs() > BOTTOM_ROW_TOLERANCE) {
        let bottom: Vec<String> = bottom.iter().map(|v| short_number(*v)).collect();
        return Err(format!(
            "`tool_to_world`'s bottom row is [{}], expected [0, 0, 0, 1] (is the matrix transposed?)",
            bottom.join(", ")
        ));
    }
    let rotation = m.fixed_view::<3, 3>(0, 0).into_owned();
    check_rotation(&rotation).map_err(|e| format!("`tool_to_world`'s upper-left 3x3 {e}"))?;
    if let Some(t) = (0..3).map(|r| m[(r, 3)]).find(|t| t.abs() > MAX_WORLD_COORDINATE_M) {
        return Err(format!(
            "`tool_to_world`'s translation {} m is outside ±{MAX_WORLD_COORDINATE_M} m",
            short_number(t)
        ));
    }
    Ok(())
}
