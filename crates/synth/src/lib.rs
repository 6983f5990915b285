//! Synthetic capture scenes with exact ground truth, written in the same dataset format as real
//! recordings.
//!
//! - Scene model: a [`Scalpel`] of a [`ToolKind`] (handle and blade, described by `tool.json`), a
//!   hand ([`hand_mesh_on`]) whose grip changes over time, and [`Trajectory`]s (approach, press,
//!   cut strokes, lift) for the scenes of [`SceneKind`], on any rig.
//! - Looks: [`Appearance`] (hand colour, tool finish, table [`Background`], light colour and
//!   drift, cast shadows through a [`ShadowMap`]), by preset name or seeded at random.
//! - Renderer: [`CameraRenderer`], a z-buffered rasterizer in double precision that applies the
//!   rig's distortion exactly (per-pixel undistorted rays), with Lambert shading, a textured static
//!   background, sensor noise, motion blur and exposure drift ([`Scene::render_view`]); labels and
//!   depth are those of the first surface hit by each pixel's centre ray.
//! - [`synthesize`]: renders every frame set in parallel and writes a dataset with masks, depth,
//!   `tool.json` and `truth/`, appearing at its path only once complete.
//!
//! Everything is deterministic for a seed. No OpenCV, no rerun.
#![warn(missing_docs)]

mod appearance;
mod hand;
pub mod render;
mod scalpel;
mod scene;
pub mod sensor;
mod synthesize;
pub mod texture;
mod trajectory;

pub use appearance::{Appearance, Background};
pub use hand::{hand_mesh, hand_mesh_on};
pub use hullcut_mesh::TriMesh;
pub use render::{CameraRenderer, Layers, Light, Part, ShadowMap};
pub use scalpel::{
    BLADE_LENGTH, BLADE_THICKNESS, BLADE_WIDTH, HANDLE_LENGTH, HANDLE_THICKNESS, HANDLE_WIDTH, HandleFit, Scalpel,
    ToolKind,
};
pub use scene::{DEFAULT_STROKE_DEPTH, DepthImage, RenderedView, START_NS, Scene, SceneConfig};
pub use synthesize::{SynthSummary, synthesize};
pub use trajectory::{Key, ORGAN_TOP, Resection, SceneKind, ToolState, Trajectory, tool_rotation};

/// Why a synthesis failed.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The scene's configuration is unusable.
    #[error("synthetic scene: {0}")]
    Config(String),
    /// Writing the dataset failed.
    #[error(transparent)]
    Dataset(#[from] hullcut_dataset::DatasetError),
}
