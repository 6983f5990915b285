//! [`DatasetWriter`]: writes a dataset into a temporary sibling folder and moves it into place when
//! it is complete.

use std::collections::BTreeMap;
use std::collections::btree_map::Entry;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};

use hullcut_rig::{Camera, Rig};
use image::{GrayImage, ImageBuffer, PixelWithColorType, RgbImage};

use crate::TIMESTAMP_BACKSTEP_TOLERANCE_NS;
use crate::error::{DatasetError, Result};
use crate::images::{DepthImage, PngCompression, save_png};
use crate::layout::{
    DATASET_TOML, DEPTH, FRAMES_CSV, FRAMES_CSV_HEADER, MASKS, MESHES, POSES_JSONL, PoseLine, RIG_YAML, TOOL_JSON,
    TRUTH, check_component, check_rig_cameras, check_timestamp, check_transform, frame_file_name, validate_meta,
};
use crate::ply::write_ply;
use crate::tool::write_tool;
use crate::types::{DatasetMeta, Mesh, ToolGeometry, TruthPose};

/// Distinguishes temporary folders of several writers in one process.
static WRITER_SERIAL: AtomicU64 = AtomicU64::new(0);

/// What the writer collects while images are written, for the files written at [`DatasetWriter::finish`].
#[derive(Debug, Default)]
struct State {
    /// `frames.csv` rows: (frame, camera index) → timestamp, ns.
    rows: BTreeMap<(u64, usize), i64>,
    /// Truth poses by frame.
    poses: BTreeMap<u64, TruthPose>,
}

/// Writes a dataset (DESIGN "Dataset format").
///
/// Everything goes into a hidden temporary folder beside the output (`<parent>/.<name>.partial-…`);
/// [`DatasetWriter::finish`] writes `dataset.toml`, `rig.yaml`, `frames.csv` and
/// `truth/poses.jsonl` and then renames the folder to the output path. A writer dropped without
/// `finish` (an error returned with `?`, a panic that unwinds) removes its temporary folder. A
/// process killed outright leaves the hidden folder behind; either way a half-written dataset never
/// appears under the output name.
///
/// Every `write_*` method takes `&self` and may be called from several threads at once (e.g. one
/// rayon task per camera); each checks its frame number, camera index and image size.
#[derive(Debug)]
pub struct DatasetWriter {
    out: PathBuf,
    tmp: PathBuf,
    meta: DatasetMeta,
    rig: Rig,
    state: Mutex<State>,
    /// Whether an existing output may be replaced.
    force: bool,
    /// Set once the temporary folder has become the output; Drop then leaves it alone.
    finished: bool,
    /// PNG compression of every image written.
    compression: PngCompression,
}

impl DatasetWriter {
    /// Starts a dataset at `out`.
    ///
    /// Refuses ([`DatasetError::Exists`]) when `out` exists and `force` is false; with `force`, an
    /// existing `out` is replaced at [`DatasetWriter::finish`], and only if it is a dataset (has a
    /// `dataset.toml`) or an empty folder ([`DatasetError::NotADataset`] otherwise). `meta` must be
    /// valid (format version, fps from [`crate::MIN_FPS`] to [`crate::MAX_FPS`], at most
    /// [`crate::MAX_FRAME_COUNT`] frames), the rig valid by [`Rig::validate`] (what a reader of the
    /// dataset will check), and `meta`'s cameras the rig's camera names in order. Parent folders of
    /// `out` are created.
    pub fn create(out: &Path, meta: DatasetMeta, rig: &Rig, force: bool) -> Result<Self> {
        let meta_path = out.join(DATASET_TOML);
        validate_meta(&meta_path, &meta)?;
        rig.validate(&out.join(RIG_YAML).display().to_string())?;
        check_rig_cameras(&out.join(RIG_YAML), &meta, rig)?;
        if out.symlink_metadata().is_ok() {
            if !force {
                return Err(DatasetError::Exists { path: out.to_owned() });
            }
            check_replaceable(out)?;
        }
        let Some(name) = out.file_name().map(|n| n.to_string_lossy().into_owned()) else {
            return Err(DatasetError::Inconsistent {
                path: out.to_owned(),
                message: "the output path must end in a folder name".to_owned(),
            });
        };
        let parent = match out.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(DatasetError::io(&parent))?;
        let tmp = create_unique_dir(&parent, &format!(".{name}.partial"))?;
        let writer = Self {
            out: out.to_owned(),
            tmp,
            meta,
            rig: rig.clone(),
            state: Mutex::default(),
            force,
            finished: false,
            compression: PngCompression::Fast,
        };
        for camera in &writer.rig.cameras {
            let dir = writer.tmp.join(&camera.name);
            std::fs::create_dir(&dir).map_err(DatasetError::io(&dir))?;
        }
        tracing::debug!(out = %out.display(), tmp = %writer.tmp.display(), "dataset writer started");
        Ok(writer)
    }

    /// Sets the number of frame sets `dataset.toml` states (a recording whose length is known only at
    /// its end); at most the number the writer was created with.
    pub fn set_frame_count(&mut self, frame_count: u64) -> Result<()> {
        if frame_count > self.meta.frame_count {
            return Err(DatasetError::Inconsistent {
                path: self.out.join(DATASET_TOML),
                message: format!(
                    "frame_count {frame_count} exceeds the {} the writer was created for",
                    self.meta.frame_count
                ),
            });
        }
        self.meta.frame_count = frame_count;
        Ok(())
    }

    /// Sets the PNG compression of everything written from now on (default: fast).
    pub fn with_compression(mut self, compression: PngCompression) -> Self {
        self.compression = compression;
        self
    }

    /// The output folder (it exists only after [`DatasetWriter::finish`]).
    pub fn out(&self) -> &Path {
        &self.out
    }

    /// The dataset's `dataset.toml` values.
    pub fn meta(&self) -> &DatasetMeta {
        &self.meta
    }

    /// The rig written as `rig.yaml`.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Writes camera `camera`'s image of frame `frame` (`<cam>/<frame:06>.png`) and records its
    /// `frames.csv` row. The image must have the camera's size and the timestamp be within
    /// ±[`crate::MAX_ABS_TIMESTAMP_NS`]; each (frame, camera) is written once. A camera's
    /// timestamps are checked for order at [`DatasetWriter::finish`].
    pub fn write_image(&self, frame: u64, camera: usize, image: &RgbImage, timestamp_ns: i64) -> Result<()> {
        let cam = self.camera(camera)?;
        let rel = Path::new(&cam.name).join(frame_file_name(frame));
        self.check_frame(frame)?;
        self.check_size(&rel, cam, image)?;
        check_timestamp(timestamp_ns)
            .map_err(|message| DatasetError::Inconsistent { path: self.out.join(&rel), message })?;
        match self.lock().rows.entry((frame, camera)) {
            Entry::Occupied(_) => {
                return Err(DatasetError::Inconsistent {
                    path: self.out.join(&rel),
                    message: format!("frame {frame} of camera `{}` is written twice", cam.name),
                });
            }
            Entry::Vacant(v) => {
                v.insert(timestamp_ns);
            }
        }
        let result = save_png(&self.tmp.join(&rel), image, self.compression);
        if result.is_err() {
            self.lock().rows.remove(&(frame, camera));
        }
        result
    }

    /// Writes an empty-scene image of camera `camera` for the background model
    /// (`<cam>/background<index:02>.png`).
    pub fn write_background(&self, camera: usize, index: usize, image: &RgbImage) -> Result<()> {
        let cam = self.camera(camera)?;
        let rel = Path::new(&cam.name).join(format!("background{index:02}.png"));
        self.check_size(&rel, cam, image)?;
        save_png(&self.tmp.join(rel), image, self.compression)
    }

    /// Writes a label mask (`masks/<cam>/<frame:06>.png`; labels in [`crate::label`]).
    pub fn write_mask(&self, frame: u64, camera: usize, mask: &GrayImage) -> Result<()> {
        self.write_per_camera(MASKS, frame, camera, mask)
    }

    /// Writes a 16-bit depth image in millimetres (`depth/<cam>/<frame:06>.png`).
    pub fn write_depth(&self, frame: u64, camera: usize, depth: &DepthImage) -> Result<()> {
        self.write_per_camera(DEPTH, frame, camera, depth)
    }

    /// Writes `tool.json` and `tool.ply` (see [`crate::write_tool`] for the checks).
    pub fn write_tool(&self, tool: &ToolGeometry) -> Result<()> {
        write_tool(self.tmp.join(TOOL_JSON), tool)
    }

    /// Records a ground-truth pose; `truth/poses.jsonl` is written, sorted by frame, at
    /// [`DatasetWriter::finish`]. One pose per frame; the timestamp within
    /// ±[`crate::MAX_ABS_TIMESTAMP_NS`]; the matrix finite with a bottom row of `[0, 0, 0, 1]`, a
    /// rotation within [`hullcut_rig::ROTATION_TOLERANCE`] and a translation within
    /// ±[`hullcut_rig::MAX_WORLD_COORDINATE_M`].
    pub fn write_truth_pose(&self, pose: &TruthPose) -> Result<()> {
        let path = self.out.join(POSES_JSONL);
        self.check_frame(pose.frame)?;
        check_timestamp(pose.timestamp_ns).and_then(|()| check_transform(&pose.tool_to_world)).map_err(|message| {
            DatasetError::Inconsistent { path: path.clone(), message: format!("frame {}: {message}", pose.frame) }
        })?;
        match self.lock().poses.entry(pose.frame) {
            Entry::Occupied(_) => Err(DatasetError::Inconsistent {
                path,
                message: format!("frame {}: the truth pose is written twice", pose.frame),
            }),
            Entry::Vacant(v) => {
                v.insert(pose.clone());
                Ok(())
            }
        }
    }

    /// Writes a world-frame ground-truth mesh (`truth/meshes/<label>/<frame:06>.ply`); `label` is a
    /// name such as `hand` or `scalpel`.
    pub fn write_truth_mesh(&self, label: &str, frame: u64, mesh: &Mesh) -> Result<()> {
        let dir_rel = Path::new(MESHES).join(label);
        check_component(label).map_err(|message| DatasetError::Invalid {
            path: self.out.join(MESHES),
            key: "label".to_owned(),
            message,
        })?;
        self.check_frame(frame)?;
        let rel = dir_rel.join(format!("{frame:06}.ply"));
        mesh.validate().map_err(|message| DatasetError::Inconsistent { path: self.out.join(&rel), message })?;
        let dir = self.tmp.join(&dir_rel);
        std::fs::create_dir_all(&dir).map_err(DatasetError::io(&dir))?;
        write_ply(self.tmp.join(rel), mesh)
    }

    /// Writes `dataset.toml`, `rig.yaml`, `frames.csv` (sorted by frame, then rig camera order) and
    /// `truth/poses.jsonl` (when poses were written), then renames the temporary folder to the
    /// output path and returns it. With `force`, an existing output is moved aside first and removed
    /// after the rename. Frames without any image are allowed; readers report them as dropped. A
    /// camera whose timestamps go back by more than [`crate::TIMESTAMP_BACKSTEP_TOLERANCE_NS`] from
    /// one of its frames to its next is refused (readers refuse it too) and nothing is written.
    pub fn finish(mut self) -> Result<PathBuf> {
        let state = std::mem::take(self.state.get_mut().unwrap_or_else(PoisonError::into_inner));
        self.check_timestamp_order(&state)?;

        let meta_text = toml::to_string(&self.meta).map_err(|e| DatasetError::Parse {
            path: self.out.join(DATASET_TOML),
            message: format!("cannot serialize: {e}"),
        })?;
        write_file(&self.tmp.join(DATASET_TOML), meta_text.as_bytes())?;

        let rig_path = self.tmp.join(RIG_YAML);
        self.rig.save(&rig_path)?;

        let mut csv = String::with_capacity(32 * (state.rows.len() + 1));
        csv.push_str(FRAMES_CSV_HEADER);
        csv.push('\n');
        for (&(frame, camera), t) in &state.rows {
            let _ = writeln!(csv, "{frame},{},{t}", self.rig.cameras[camera].name);
        }
        write_file(&self.tmp.join(FRAMES_CSV), csv.as_bytes())?;

        if !state.poses.is_empty() {
            let dir = self.tmp.join(TRUTH);
            std::fs::create_dir_all(&dir).map_err(DatasetError::io(&dir))?;
            let mut text = String::new();
            for pose in state.poses.values() {
                let line = serde_json::to_string(&PoseLine::from_pose(pose)).map_err(|e| DatasetError::Parse {
                    path: self.out.join(POSES_JSONL),
                    message: format!("frame {}: cannot serialize: {e}", pose.frame),
                })?;
                text.push_str(&line);
                text.push('\n');
            }
            write_file(&self.tmp.join(POSES_JSONL), text.as_bytes())?;
        }

        self.move_into_place()?;
        self.finished = true;
        let frames_with_images = state.rows.keys().map(|&(f, _)| f).collect::<std::collections::BTreeSet<_>>().len();
        tracing::info!(
            out = %self.out.display(),
            images = state.rows.len(),
            frames_with_images,
            frame_count = self.meta.frame_count,
            "dataset written"
        );
        Ok(self.out.clone())
    }

    /// Renames the temporary folder to the output, replacing an existing one (moved aside first, so
    /// the output path always holds a complete dataset or nothing).
    fn move_into_place(&self) -> Result<()> {
        let rename = |from: &Path, to: &Path| {
            std::fs::rename(from, to).map_err(|error| DatasetError::Io {
                path: to.to_owned(),
                error: std::io::Error::new(error.kind(), format!("cannot rename {} to it: {error}", from.display())),
            })
        };
        if self.out.symlink_metadata().is_err() {
            return rename(&self.tmp, &self.out);
        }
        // The output was there from the start (`create` refused it without force) or appeared since.
        if !self.force {
            return Err(DatasetError::Exists { path: self.out.clone() });
        }
        check_replaceable(&self.out)?;
        let parent = self.tmp.parent().unwrap_or(Path::new("."));
        let name = self.out.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let old = unique_path(parent, &format!(".{name}.old"));
        rename(&self.out, &old)?;
        if let Err(e) = rename(&self.tmp, &self.out) {
            // Put the old dataset back; the new one stays in the temporary folder and Drop removes it.
            if let Err(back) = std::fs::rename(&old, &self.out) {
                tracing::error!(old = %old.display(), error = %back, "cannot restore the replaced dataset");
            }
            return Err(e);
        }
        if let Err(e) = remove_path(&old) {
            tracing::warn!(path = %old.display(), error = %e, "cannot remove the replaced dataset");
        }
        Ok(())
    }

    /// Each camera's timestamps, in frame order, go back by at most
    /// [`crate::TIMESTAMP_BACKSTEP_TOLERANCE_NS`] (all are within ±`MAX_ABS_TIMESTAMP_NS`, so the
    /// subtraction cannot overflow).
    fn check_timestamp_order(&self, state: &State) -> Result<()> {
        let mut last: BTreeMap<usize, (u64, i64)> = BTreeMap::new();
        for (&(frame, camera), &t) in &state.rows {
            if let Some(&(earlier, t0)) = last.get(&camera)
                && t0 - t > TIMESTAMP_BACKSTEP_TOLERANCE_NS
            {
                let name = self.rig.cameras.get(camera).map_or("?", |c| c.name.as_str());
                return Err(DatasetError::Inconsistent {
                    path: self.out.join(FRAMES_CSV),
                    message: format!(
                        "camera `{name}`'s timestamp {t} ns for frame {frame} is {} ns before its frame {earlier}; a \
                         camera's timestamps may go back by at most {TIMESTAMP_BACKSTEP_TOLERANCE_NS} ns",
                        t0 - t
                    ),
                });
            }
            last.insert(camera, (frame, t));
        }
        Ok(())
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        // A thread that panicked while holding the lock leaves plain maps behind, still consistent.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn camera(&self, camera: usize) -> Result<&Camera> {
        self.rig.cameras.get(camera).ok_or_else(|| DatasetError::NoSuchCamera {
            path: self.out.clone(),
            camera,
            count: self.rig.len(),
        })
    }

    fn check_frame(&self, frame: u64) -> Result<()> {
        if frame >= self.meta.frame_count {
            return Err(DatasetError::NoSuchFrame {
                path: self.out.clone(),
                frame,
                frame_count: self.meta.frame_count,
            });
        }
        Ok(())
    }

    fn check_size<P: image::Pixel>(
        &self,
        rel: &Path,
        cam: &Camera,
        image: &ImageBuffer<P, Vec<P::Subpixel>>,
    ) -> Result<()> {
        if image.dimensions() != (cam.width, cam.height) {
            return Err(DatasetError::Inconsistent {
                path: self.out.join(rel),
                message: format!(
                    "the image is {}x{} but camera `{}` of the rig is {}x{}",
                    image.width(),
                    image.height(),
                    cam.name,
                    cam.width,
                    cam.height
                ),
            });
        }
        Ok(())
    }

    fn write_per_camera<P>(
        &self,
        tree: &str,
        frame: u64,
        camera: usize,
        image: &ImageBuffer<P, Vec<P::Subpixel>>,
    ) -> Result<()>
    where
        P: PixelWithColorType,
        [P::Subpixel]: image::EncodableLayout,
    {
        let cam = self.camera(camera)?;
        let dir_rel = Path::new(tree).join(&cam.name);
        let rel = dir_rel.join(frame_file_name(frame));
        self.check_frame(frame)?;
        self.check_size(&rel, cam, image)?;
        let dir = self.tmp.join(&dir_rel);
        std::fs::create_dir_all(&dir).map_err(DatasetError::io(&dir))?;
        save_png(&self.tmp.join(rel), image, self.compression)
    }
}

impl Drop for DatasetWriter {
    fn drop(&mut self) {
        if self.finished {
            return;
        }
        match std::fs::remove_dir_all(&self.tmp) {
            Ok(()) => tracing::debug!(tmp = %self.tmp.display(), "unfinished dataset removed"),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(tmp = %self.tmp.display(), error = %e, "cannot remove an unfinished dataset"),
        }
    }
}

/// Whether an existing output may be replaced: a folder holding `dataset.toml`, or an empty folder.
fn check_replaceable(out: &Path) -> Result<()> {
    let replaceable = out.is_dir()
        && (out.join(DATASET_TOML).is_file()
            || std::fs::read_dir(out).map_err(DatasetError::io(out))?.next().is_none());
    if replaceable { Ok(()) } else { Err(DatasetError::NotADataset { path: out.to_owned() }) }
}

/// A path `<parent>/<prefix>-<pid>-<n>` that does not exist yet.
fn unique_path(parent: &Path, prefix: &str) -> PathBuf {
    let pid = std::process::id();
    loop {
        let n = WRITER_SERIAL.fetch_add(1, Ordering::Relaxed);
        let path = parent.join(format!("{prefix}-{pid}-{n}"));
        if path.symlink_metadata().is_err() {
            return path;
        }
    }
}

/// Creates a new, empty folder `<parent>/<prefix>-<pid>-<n>`; never reuses an existing one.
fn create_unique_dir(parent: &Path, prefix: &str) -> Result<PathBuf> {
    loop {
        let path = unique_path(parent, prefix);
        match std::fs::create_dir(&path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(error) => return Err(DatasetError::Io { path, error }),
        }
    }
}

fn remove_path(path: &Path) -> std::io::Result<()> {
    if path.is_dir() { std::fs::remove_dir_all(path) } else { std::fs::remove_file(path) }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(DatasetError::io(path))
}
