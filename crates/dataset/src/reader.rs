//! [`Dataset`]: opens and validates a recorded or synthetic dataset and reads its frame sets.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use hullcut_rig::{Camera, Rig, shorten};
use image::{GrayImage, RgbImage};

use crate::error::{DatasetError, Result};
use crate::images::{DepthImage, load_depth, load_mask, load_rgb, png_size};
use crate::layout::{
    DATASET_TOML, DEPTH, FRAMES_CSV, FRAMES_CSV_HEADER, MASKS, MESHES, POSES_JSONL, PoseLine, RIG_YAML, TOOL_JSON,
    TRUTH, check_component, check_rig_cameras, check_timestamp, frame_file_name, json_message, name_list,
    parse_frame_file_name, read_text, toml_message, validate_meta,
};
use crate::ply::read_ply;
use crate::tool::read_tool;
use crate::types::{DatasetMeta, FrameSet, Mesh, ToolGeometry, TruthPose, View};
use crate::{FORMAT_VERSION, MAX_LIST_FILE_BYTES, MAX_SMALL_FILE_BYTES, TIMESTAMP_BACKSTEP_TOLERANCE_NS};

/// A camera image that `frames.csv` does not list: the camera dropped that frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Dropped {
    /// Frame number.
    pub frame: u64,
    /// Camera index in rig order.
    pub camera: usize,
}

/// An opened, validated dataset (DESIGN "Dataset format").
///
/// [`Dataset::open`] reads `dataset.toml`, `rig.yaml` and `frames.csv` and checks that they agree
/// with each other and with the folders; images are decoded only when a frame set is read.
#[derive(Debug, Clone)]
pub struct Dataset {
    root: PathBuf,
    meta: DatasetMeta,
    rig: Rig,
    /// Timestamps by frame for frames with at least one image, one entry per camera.
    rows: BTreeMap<u64, Vec<Option<i64>>>,
    dropped: Vec<Dropped>,
    has_masks: bool,
    has_depth: bool,
}

impl Dataset {
    /// Opens and validates the dataset in `dir`.
    ///
    /// Checks, each error naming the file or folder: `dataset.toml` (format version
    /// [`FORMAT_VERSION`], no unknown keys, values in their documented ranges); `rig.yaml` (valid
    /// by [`Rig::load`], with the same camera names in the same order as `dataset.toml`); a folder
    /// for every camera and no folder of frame images for a camera the rig lacks; `frames.csv`
    /// (present; header; every row with a frame below `frame_count`, a rig camera and an integer
    /// timestamp within ±[`MAX_ABS_TIMESTAMP_NS`](crate::MAX_ABS_TIMESTAMP_NS); no duplicates; each
    /// camera's timestamps, in frame order, never going back by more than
    /// [`TIMESTAMP_BACKSTEP_TOLERANCE_NS`]); a PNG for every row and a row for every frame PNG
    /// (`^[0-9]{6}\.png$`); the size in the header of each camera's first image against the rig; a
    /// per-camera folder under `masks/` and `depth/` when those exist.
    ///
    /// A (frame, camera) without a row is a dropped frame: it is listed in [`Dataset::dropped`],
    /// logged as one warning, and read as a missing view.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let root = dir.as_ref().to_owned();
        if !root.is_dir() {
            return Err(DatasetError::Missing { path: root, message: "the dataset folder does not exist".to_owned() });
        }
        let meta = read_meta(&root.join(DATASET_TOML))?;

        let rig_path = root.join(RIG_YAML);
        if !rig_path.is_file() {
            return Err(DatasetError::Missing {
                path: rig_path,
                message: "every dataset has its calibration".to_owned(),
            });
        }
        let rig = Rig::load(&rig_path)?;
        check_rig_cameras(&rig_path, &meta, &rig)?;
        check_camera_folders(&root, &rig)?;

        let csv_path = root.join(FRAMES_CSV);
        let rows = read_frames_csv(&csv_path, &meta, &rig)?;
        check_images_against_rows(&root, &rig, &rows)?;
        check_image_sizes(&root, &rig, &rows)?;

        let has_masks = check_optional_tree(&root, MASKS, &rig)?;
        let has_depth = check_optional_tree(&root, DEPTH, &rig)?;

        let rows: BTreeMap<u64, Vec<Option<i64>>> = rows
            .into_iter()
            .map(|(frame, cams)| (frame, cams.into_iter().map(|c| c.map(|(t, _)| t)).collect()))
            .collect();
        let dropped = find_dropped(&rows, meta.frame_count, rig.len());
        if !dropped.is_empty() {
            let empty = meta.frame_count - rows.len() as u64;
            let first: Vec<String> =
                dropped.iter().take(5).map(|d| format!("frame {} {}", d.frame, rig.cameras[d.camera].name)).collect();
            tracing::warn!(
                dataset = %root.display(),
                dropped_images = dropped.len(),
                frame_sets_without_images = empty,
                first = %first.join(", "),
                "dropped frames: these views are read as missing"
            );
        }
        Ok(Self { root, meta, rig, rows, dropped, has_masks, has_depth })
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `dataset.toml`.
    pub fn meta(&self) -> &DatasetMeta {
        &self.meta
    }

    /// The rig from `rig.yaml`.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Frame numbers with at least one camera image, ascending.
    pub fn frame_numbers(&self) -> Vec<u64> {
        self.rows.keys().copied().collect()
    }

    /// Every (frame, camera) in `0..frame_count` × cameras without an image, sorted by frame then
    /// camera. A frame set without any image lists all its cameras.
    pub fn dropped(&self) -> &[Dropped] {
        &self.dropped
    }

    /// The capture time of camera `camera`'s image of `frame`, nanoseconds; `None` when dropped.
    pub fn timestamp(&self, frame: u64, camera: usize) -> Option<i64> {
        self.rows.get(&frame).and_then(|cams| cams.get(camera).copied().flatten())
    }

    /// The frame set's time: the median of its cameras' timestamps (see [`FrameSet::median_timestamp`]);
    /// `None` when no camera has the frame.
    pub fn frame_timestamp(&self, frame: u64) -> Option<i64> {
        let cams = self.rows.get(&frame)?;
        let mut t: Vec<i64> = cams.iter().flatten().copied().collect();
        t.sort_unstable();
        t.get((t.len().max(1) - 1) / 2).copied()
    }

    /// Whether the dataset has label masks (`masks/`).
    pub fn has_masks(&self) -> bool {
        self.has_masks
    }

    /// Whether the dataset has depth images (`depth/`).
    pub fn has_depth(&self) -> bool {
        self.has_depth
    }

    /// Path of camera `camera`'s image of `frame` (whether or not it exists).
    pub fn image_path(&self, frame: u64, camera: usize) -> Result<PathBuf> {
        Ok(self.root.join(&self.camera(camera)?.name).join(frame_file_name(frame)))
    }

    /// Path of camera `camera`'s label mask of `frame` (whether or not it exists).
    pub fn mask_path(&self, frame: u64, camera: usize) -> Result<PathBuf> {
        Ok(self.root.join(MASKS).join(&self.camera(camera)?.name).join(frame_file_name(frame)))
    }

    /// Path of camera `camera`'s depth image of `frame` (whether or not it exists).
    pub fn depth_path(&self, frame: u64, camera: usize) -> Result<PathBuf> {
        Ok(self.root.join(DEPTH).join(&self.camera(camera)?.name).join(frame_file_name(frame)))
    }

    /// The instrument's geometry from `tool.json`, when the dataset has one.
    pub fn tool(&self) -> Result<Option<ToolGeometry>> {
        let path = self.root.join(TOOL_JSON);
        if path.symlink_metadata().is_err() {
            return Ok(None);
        }
        read_tool(path).map(Some)
    }

    /// Ground-truth poses from `truth/poses.jsonl` sorted by frame, when the dataset has them.
    ///
    /// Each line must be a JSON object with `frame` (below `frame_count`, not repeated),
    /// `timestamp_ns` (within ±[`MAX_ABS_TIMESTAMP_NS`](crate::MAX_ABS_TIMESTAMP_NS)) and
    /// `tool_to_world` (16 finite numbers, row-major, bottom row `[0, 0, 0, 1]`, a rotation within
    /// [`hullcut_rig::ROTATION_TOLERANCE`], a translation within
    /// ±[`hullcut_rig::MAX_WORLD_COORDINATE_M`]); errors name the file and the line. Blank lines are
    /// skipped.
    pub fn truth_poses(&self) -> Result<Option<Vec<TruthPose>>> {
        let path = self.root.join(POSES_JSONL);
        if path.symlink_metadata().is_err() {
            return Ok(None);
        }
        let text = read_text(&path, MAX_LIST_FILE_BYTES, None)?;
        let mut poses: BTreeMap<u64, (usize, TruthPose)> = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            let line_no = i + 1;
            if line.trim().is_empty() {
                continue;
            }
            let err = |message: String| DatasetError::Line { path: path.clone(), line: line_no, message };
            let parsed: PoseLine = serde_json::from_str(line).map_err(|e| err(json_message(&e, false)))?;
            let pose = parsed.into_pose().map_err(err)?;
            if pose.frame >= self.meta.frame_count {
                return Err(err(format!(
                    "frame {} is outside the dataset (dataset.toml: frame_count = {})",
                    pose.frame, self.meta.frame_count
                )));
            }
            if let Some((first, _)) = poses.get(&pose.frame) {
                return Err(err(format!("frame {} already has a pose on line {first}", pose.frame)));
            }
            poses.insert(pose.frame, (line_no, pose));
        }
        Ok(Some(poses.into_values().map(|(_, p)| p).collect()))
    }

    /// The empty-scene images of camera `camera` (`<cam>/background*.png`, sorted by file name);
    /// empty when there are none.
    pub fn background_images(&self, camera: usize) -> Result<Vec<RgbImage>> {
        let cam = self.camera(camera)?;
        let dir = self.root.join(&cam.name);
        let mut paths = Vec::new();
        for entry in std::fs::read_dir(&dir).map_err(DatasetError::io(&dir))? {
            let entry = entry.map_err(DatasetError::io(&dir))?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            if name.starts_with("background") && name.ends_with(".png") {
                paths.push(entry.path());
            }
        }
        paths.sort();
        paths
            .iter()
            .map(|path| {
                let check = |size: (u32, u32)| check_size(path, cam, size);
                load_rgb(path, "background image", &check)
            })
            .collect()
    }

    /// Camera `camera`'s colour image of `frame`. A dropped frame is a [`DatasetError::Missing`];
    /// an image whose header disagrees with the rig is refused before it is decoded.
    pub fn read_image(&self, frame: u64, camera: usize) -> Result<RgbImage> {
        self.check_frame(frame)?;
        let path = self.image_path(frame, camera)?;
        let cam = &self.rig.cameras[camera];
        let check = |size: (u32, u32)| check_size(&path, cam, size);
        load_rgb(&path, &format!("camera `{}` has no image of frame {frame}", cam.name), &check)
    }

    /// Camera `camera`'s label mask of `frame`.
    pub fn read_mask(&self, frame: u64, camera: usize) -> Result<GrayImage> {
        self.check_frame(frame)?;
        let path = self.mask_path(frame, camera)?;
        let cam = &self.rig.cameras[camera];
        let check = |size: (u32, u32)| check_size(&path, cam, size);
        load_mask(&path, &format!("camera `{}` has no label mask of frame {frame}", cam.name), &check)
    }

    /// Camera `camera`'s depth image of `frame`, millimetres.
    pub fn read_depth(&self, frame: u64, camera: usize) -> Result<DepthImage> {
        self.check_frame(frame)?;
        let path = self.depth_path(frame, camera)?;
        let cam = &self.rig.cameras[camera];
        let check = |size: (u32, u32)| check_size(&path, cam, size);
        load_depth(&path, &format!("camera `{}` has no depth image of frame {frame}", cam.name), &check)
    }

    /// Reads frame set `frame`: one view per camera in rig order, `None` for a dropped camera, with
    /// label masks when `with_masks` (an error when the dataset has none). A frame set without any
    /// image has no views and timestamp 0. A missing, corrupt or truncated PNG is an error naming it.
    pub fn read_frame_set(&self, frame: u64, with_masks: bool) -> Result<FrameSet> {
        self.check_frame(frame)?;
        if with_masks && !self.has_masks {
            return Err(DatasetError::Missing {
                path: self.root.join(MASKS),
                message: "label masks were asked for, but the dataset has none".to_owned(),
            });
        }
        let mut views = Vec::with_capacity(self.rig.len());
        for camera in 0..self.rig.len() {
            let Some(timestamp_ns) = self.timestamp(frame, camera) else {
                views.push(None);
                continue;
            };
            let image = self.read_image(frame, camera)?;
            let mask = if with_masks { Some(self.read_mask(frame, camera)?) } else { None };
            views.push(Some(View { camera, timestamp_ns, image, mask }));
        }
        let timestamp_ns = FrameSet::median_timestamp(&views);
        Ok(FrameSet { frame, timestamp_ns, views })
    }

    /// The ground-truth mesh of `label` (e.g. `hand`, `scalpel`) at `frame`, when the dataset has one.
    pub fn read_truth_mesh(&self, label: &str, frame: u64) -> Result<Option<Mesh>> {
        let dir = self.root.join(MESHES);
        check_component(label).map_err(|message| DatasetError::Invalid {
            path: dir.clone(),
            key: "label".to_owned(),
            message,
        })?;
        let path = dir.join(label).join(format!("{frame:06}.ply"));
        if path.symlink_metadata().is_err() {
            return Ok(None);
        }
        read_ply(path).map(Some)
    }

    /// Whether the dataset has a `truth/` folder.
    pub fn has_truth(&self) -> bool {
        self.root.join(TRUTH).is_dir()
    }

    fn camera(&self, camera: usize) -> Result<&Camera> {
        self.rig.cameras.get(camera).ok_or_else(|| DatasetError::NoSuchCamera {
            path: self.root.clone(),
            camera,
            count: self.rig.len(),
        })
    }

    fn check_frame(&self, frame: u64) -> Result<()> {
        if frame >= self.meta.frame_count {
            return Err(DatasetError::NoSuchFrame {
                path: self.root.clone(),
                frame,
                frame_count: self.meta.frame_count,
            });
        }
        Ok(())
    }
}

/// Reads `dataset.toml`: the format version first (so a newer file is named as such rather than
/// for its unknown keys), then every key.
fn read_meta(path: &Path) -> Result<DatasetMeta> {
    let text = read_text(path, MAX_SMALL_FILE_BYTES, Some("not a dataset: every dataset has a dataset.toml"))?;
    let parse = |e: toml::de::Error| DatasetError::Parse { path: path.to_owned(), message: toml_message(&e, &text) };
    let table: toml::Table = toml::from_str(&text).map_err(parse)?;
    match table.get("format_version").and_then(toml::Value::as_integer) {
        Some(v) if v == i64::from(FORMAT_VERSION) => {}
        Some(v) => {
            return Err(DatasetError::Invalid {
                path: path.to_owned(),
                key: "format_version".to_owned(),
                message: format!("this reader knows version {FORMAT_VERSION}, the file has {v}"),
            });
        }
        None => {
            return Err(DatasetError::Invalid {
                path: path.to_owned(),
                key: "format_version".to_owned(),
                message: "missing, or not an integer".to_owned(),
            });
        }
    }
    let meta: DatasetMeta = toml::from_str(&text).map_err(parse)?;
    validate_meta(path, &meta)?;
    Ok(meta)
}

/// Every camera has a folder; no other folder holds frame images.
fn check_camera_folders(root: &Path, rig: &Rig) -> Result<()> {
    for cam in &rig.cameras {
        let dir = root.join(&cam.name);
        if !dir.is_dir() {
            return Err(DatasetError::Missing {
                path: dir,
                message: format!("camera `{}` of {RIG_YAML} and {DATASET_TOML} has no image folder", cam.name),
            });
        }
    }
    let mut extra = Vec::new();
    for entry in std::fs::read_dir(root).map_err(DatasetError::io(root))? {
        let entry = entry.map_err(DatasetError::io(root))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || [MASKS, DEPTH, TRUTH].contains(&name.as_str()) || rig.index_of(&name).is_some() {
            continue;
        }
        let path = entry.path();
        if path.is_dir() && !frame_files(&path)?.is_empty() {
            extra.push(path);
        }
    }
    extra.sort();
    if let Some(path) = extra.into_iter().next() {
        return Err(DatasetError::Inconsistent {
            path: path.clone(),
            message: format!(
                "this folder holds frame images, but `{}` is not a camera of {} (its {} cameras are {})",
                shorten(&path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()),
                root.join(RIG_YAML).display(),
                rig.len(),
                name_list(rig.cameras.iter().map(|c| c.name.as_str()))
            ),
        });
    }
    Ok(())
}

/// Frame numbers of the files named like `^[0-9]{6}\.png$` in `dir`.
fn frame_files(dir: &Path) -> Result<BTreeSet<u64>> {
    let mut frames = BTreeSet::new();
    for entry in std::fs::read_dir(dir).map_err(DatasetError::io(dir))? {
        let entry = entry.map_err(DatasetError::io(dir))?;
        if let Some(frame) = entry.file_name().to_str().and_then(parse_frame_file_name) {
            frames.insert(frame);
        }
    }
    Ok(frames)
}

/// Rows of `frames.csv`: frame → per camera (timestamp, line number).
type Rows = BTreeMap<u64, Vec<Option<(i64, usize)>>>;

/// Reads `frames.csv` (at most [`MAX_LIST_FILE_BYTES`]): the header, then rows whose frame, camera
/// and timestamp are each checked where they are read (see [`Dataset::open`]); then each camera's
/// timestamps in frame order.
fn read_frames_csv(path: &Path, meta: &DatasetMeta, rig: &Rig) -> Result<Rows> {
    let text = read_text(path, MAX_LIST_FILE_BYTES, Some("it lists every captured image with its timestamp"))?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l.trim()).unwrap_or_default();
    if header != FRAMES_CSV_HEADER {
        return Err(DatasetError::Line {
            path: path.to_owned(),
            line: 1,
            message: format!("the header must be `{FRAMES_CSV_HEADER}`, found `{}`", shorten(header)),
        });
    }
    let mut rows = Rows::new();
    for (i, line) in lines {
        let line_no = i + 1;
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let err = |message: String| DatasetError::Line { path: path.to_owned(), line: line_no, message };
        let fields: Vec<&str> = line.splitn(4, ',').map(str::trim).collect();
        let [frame, camera, timestamp] = fields[..] else {
            return Err(err(format!(
                "expected 3 fields (`{FRAMES_CSV_HEADER}`), found {}: `{}`",
                line.split(',').count(),
                shorten(line)
            )));
        };
        let frame: u64 =
            frame.parse().map_err(|_| err(format!("the frame `{}` is not a non-negative integer", shorten(frame))))?;
        if frame >= meta.frame_count {
            return Err(err(format!(
                "frame {frame} is outside the dataset (dataset.toml: frame_count = {})",
                meta.frame_count
            )));
        }
        let Some(cam) = rig.index_of(camera) else {
            return Err(err(format!(
                "`{}` is not a camera of the rig (cameras: {})",
                shorten(camera),
                name_list(meta.cameras.iter().map(String::as_str))
            )));
        };
        let timestamp: i64 = timestamp.parse().map_err(|_| {
            err(format!("the timestamp `{}` is not an integer (nanoseconds) in the range of i64", shorten(timestamp)))
        })?;
        check_timestamp(timestamp).map_err(err)?;
        let slot = &mut rows.entry(frame).or_insert_with(|| vec![None; rig.len()])[cam];
        if let Some((_, first)) = slot {
            return Err(err(format!("frame {frame} of camera `{camera}` is listed twice (first on line {first})")));
        }
        *slot = Some((timestamp, line_no));
    }
    check_timestamp_order(path, rig, &rows)?;
    Ok(rows)
}

/// Each camera's timestamps, in frame order, go back by at most
/// [`TIMESTAMP_BACKSTEP_TOLERANCE_NS`] from one of its frames to its next; the error names the
/// later row's line. Timestamps are already within ±`MAX_ABS_TIMESTAMP_NS`, so the subtraction
/// cannot overflow.
fn check_timestamp_order(path: &Path, rig: &Rig, rows: &Rows) -> Result<()> {
    for (c, cam) in rig.cameras.iter().enumerate() {
        let mut previous: Option<(u64, i64, usize)> = None;
        for (&frame, cams) in rows {
            let Some((t, line)) = cams.get(c).copied().flatten() else { continue };
            if let Some((earlier, t0, line0)) = previous
                && t0 - t > TIMESTAMP_BACKSTEP_TOLERANCE_NS
            {
                return Err(DatasetError::Line {
                    path: path.to_owned(),
                    line,
                    message: format!(
                        "camera `{}`'s timestamp {t} ns for frame {frame} is {} ns before its frame {earlier} \
                         (line {line0}); a camera's timestamps may go back by at most \
                         {TIMESTAMP_BACKSTEP_TOLERANCE_NS} ns",
                        cam.name,
                        t0 - t
                    ),
                });
            }
            previous = Some((frame, t, line));
        }
    }
    Ok(())
}

/// Every row has its PNG, every frame PNG has its row.
fn check_images_against_rows(root: &Path, rig: &Rig, rows: &Rows) -> Result<()> {
    for (c, cam) in rig.cameras.iter().enumerate() {
        let dir = root.join(&cam.name);
        let files = frame_files(&dir)?;
        for (&frame, cams) in rows {
            if let Some((_, line)) = cams[c]
                && !files.contains(&frame)
            {
                return Err(DatasetError::Missing {
                    path: dir.join(frame_file_name(frame)),
                    message: format!("{FRAMES_CSV} line {line} lists frame {frame} of camera `{}`", cam.name),
                });
            }
        }
        for &frame in &files {
            if rows.get(&frame).and_then(|cams| cams[c]).is_none() {
                return Err(DatasetError::Inconsistent {
                    path: dir.join(frame_file_name(frame)),
                    message: format!(
                        "frame {frame} of camera `{}` has no row in {}",
                        cam.name,
                        root.join(FRAMES_CSV).display()
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Each camera's first image has the rig's size (read from the PNG header only).
fn check_image_sizes(root: &Path, rig: &Rig, rows: &Rows) -> Result<()> {
    for (c, cam) in rig.cameras.iter().enumerate() {
        let Some((&frame, _)) = rows.iter().find(|(_, cams)| cams[c].is_some()) else { continue };
        let path = root.join(&cam.name).join(frame_file_name(frame));
        let size = png_size(&path, &format!("{FRAMES_CSV} lists frame {frame} of camera `{}`", cam.name))?;
        check_size(&path, cam, size)?;
    }
    Ok(())
}

fn check_size(path: &Path, cam: &Camera, (width, height): (u32, u32)) -> Result<()> {
    if (width, height) != (cam.width, cam.height) {
        return Err(DatasetError::Inconsistent {
            path: path.to_owned(),
            message: format!(
                "the image is {width}x{height} but camera `{}` in {RIG_YAML} is {}x{}",
                cam.name, cam.width, cam.height
            ),
        });
    }
    Ok(())
}

/// When `root/tree` exists, it has a folder per camera; returns whether it exists.
fn check_optional_tree(root: &Path, tree: &str, rig: &Rig) -> Result<bool> {
    let base = root.join(tree);
    if !base.is_dir() {
        return Ok(false);
    }
    for cam in &rig.cameras {
        let dir = base.join(&cam.name);
        if !dir.is_dir() {
            return Err(DatasetError::Missing {
                path: dir,
                message: format!("{tree}/ exists, so every camera of {RIG_YAML} needs a folder in it"),
            });
        }
    }
    Ok(true)
}

fn find_dropped(rows: &BTreeMap<u64, Vec<Option<i64>>>, frame_count: u64, cameras: usize) -> Vec<Dropped> {
    let mut dropped = Vec::new();
    for frame in 0..frame_count {
        match rows.get(&frame) {
            Some(cams) => {
                dropped.extend(
                    cams.iter().enumerate().filter(|(_, t)| t.is_none()).map(|(camera, _)| Dropped { frame, camera }),
                );
            }
            None => dropped.extend((0..cameras).map(|camera| Dropped { frame, camera })),
        }
    }
    dropped
}
