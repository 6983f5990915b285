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
