//! The hullcut dataset format: read, write and validate recordings of a synchronized camera rig
//! (pure Rust; images through the `image` crate). The format is described in DESIGN.md
//! ("Dataset format") and, for users, in `datasets/README.md`.
//!
//! Entry points:
//! - [`Dataset::open`]: opens a dataset folder and checks that `dataset.toml`, `rig.yaml`,
//!   `frames.csv` and the image folders agree (errors name the file); dropped frames are reported by
//!   [`Dataset::dropped`] and read as missing views by [`Dataset::read_frame_set`].
//! - [`DatasetWriter`]: writes a dataset from several threads at once into a temporary folder and
//!   moves it into place at [`DatasetWriter::finish`], so an unfinished dataset never appears.
//! - [`read_ply`] / [`write_ply`]: triangle meshes; [`read_tool`] / [`write_tool`]: `tool.json`.
//! - The plain data types shared by every frame source: [`FrameSet`], [`View`], [`DatasetMeta`],
//!   [`Mesh`], [`ToolGeometry`], [`TruthPose`] and the mask [`label`] values.
//! - Input limits, checked where each value is read and named with the file, key or line in
//!   errors: [`MAX_FRAME_COUNT`], [`MAX_ABS_TIMESTAMP_NS`], [`TIMESTAMP_BACKSTEP_TOLERANCE_NS`],
//!   [`MIN_FPS`]..[`MAX_FPS`], [`MAX_TOOL_COORDINATE_M`], [`MAX_TOOL_EXTENT_M`],
//!   [`MAX_DECODE_BYTES`], [`MAX_SMALL_FILE_BYTES`], [`MAX_LIST_FILE_BYTES`], and the rig's own
//!   (`hullcut_rig::MAX_CAMERAS`, `MAX_IMAGE_SIDE`, `MAX_WORLD_COORDINATE_M`, `ROTATION_TOLERANCE`).
//!
//! No feature flags.
#![warn(missing_docs)]

mod error;
mod images;
mod layout;
mod ply;
mod reader;
mod tool;
mod types;
mod writer;

pub use error::{DatasetError, Result};
pub use images::{DepthImage, PngCompression};
pub use layout::{frame_file_name, parse_frame_file_name};
pub use ply::{read_ply, write_ply};
pub use reader::{Dataset, Dropped};
pub use tool::{read_tool, tool_mesh_path, write_tool};
pub use types::{DatasetMeta, FrameSet, Mesh, ToolGeometry, TruthPose, View, Workspace, label};
pub use writer::DatasetWriter;

/// The `format_version` this crate reads and writes in `dataset.toml`.
pub const FORMAT_VERSION: u32 = 1;

/// The largest `frame_count`: frame numbers are written with six digits.
pub const MAX_FRAME_COUNT: u64 = 1_000_000;

/// The largest magnitude of a timestamp, nanoseconds (about 127 years either side of the clock's
/// epoch). The difference or the sum of any two accepted timestamps fits in an `i64`, so no later
/// arithmetic on them overflows; `frames.csv` and `truth/poses.jsonl` refuse anything beyond.
pub const MAX_ABS_TIMESTAMP_NS: i64 = 4_000_000_000_000_000_000;

/// How far a camera's timestamp may go back from one of its frames to its next, nanoseconds (1 ms):
/// a clock re-synchronized by a little is tolerated, a clock running backwards is refused.
pub const TIMESTAMP_BACKSTEP_TOLERANCE_NS: i64 = 1_000_000;

/// The lowest frame rate `dataset.toml` may state, frames per second.
pub const MIN_FPS: f64 = 1e-3;

/// The highest frame rate `dataset.toml` may state, frames per second.
pub const MAX_FPS: f64 = 1e5;

/// The largest |coordinate| of the tool's tip, cutting edge and blade outline in `tool.json`,
/// metres (tool frame).
pub const MAX_TOOL_COORDINATE_M: f64 = 10.0;

/// The largest side of the box around the tool's tip, cutting edge and blade outline, and the
/// largest blade thickness, metres: a hand-held tool (hullcut-pose bounds the tool's mesh the same
/// way). A file in millimetres fails here rather than sizing later stages a thousand times too big.
pub const MAX_TOOL_EXTENT_M: f64 = 0.5;

/// The most a PNG of a dataset may need once decoded, bytes (a 16384 x 16384 RGBA image); its
/// sides are checked against [`hullcut_rig::MAX_IMAGE_SIDE`] from the header before anything is
/// allocated.
pub const MAX_DECODE_BYTES: u64 = 1 << 30;

/// The largest `dataset.toml` or `tool.json` read, bytes.
pub const MAX_SMALL_FILE_BYTES: u64 = 16 << 20;

/// The largest `frames.csv` or `truth/poses.jsonl` read, bytes (some 25 million rows of
/// `frames.csv`).
pub const MAX_LIST_FILE_BYTES: u64 = 1 << 30;
