//! The blade's pose (plane, cutting edge, tip) from the scalpel hull and the silhouettes,
//! tracked over time, with a confidence that can refuse a frame.
//!
//! Method:
//! - [`Template`]: the instrument's known shape from `tool.json` (blade polygon, body, interior
//!   points). The hull's thickness says nothing about a 0.4 mm blade, so the known blade is fitted
//!   instead of reading the plane off the hull.
//! - The scalpel hull gives the starting poses (its largest connected component's axis and
//!   extent; both directions, twelve rolls) when there is no track; otherwise the track's
//!   constant-velocity prediction starts the fit.
//! - The fit: Levenberg–Marquardt over six parameters so that every sampled scalpel pixel lies in
//!   the projected tool and every interior point of the tool projects onto foreground (the hand may
//!   hide the tool, so hand pixels count), Huber-weighted, in pixels.
//! - [`Tracker`]: confidence from the fit's agreement, the number of views that see the blade's
//!   face (not edge-on, not hidden by the hand; on a rig of four or five views, two seeing it and
//!   two edge-on count where those fix the blade's turn about its long axis), the scalpel leaf
//!   count and the step from the last trusted pose; a frame below the threshold is refused with a
//!   reason, the last trusted pose is held for a bounded time. Trusted poses pass a One Euro
//!   filter on SE(3) ([`OneEuro`]).
//! - [`pose_error`]: normal angle, edge distance and tip distance against a true pose;
//!   [`rigid_from_matrix`]: a true pose's 4x4 matrix checked (finite, orthonormal within
//!   [`ORTHONORMAL_TOLERANCE`], no reflection) before it is made a rotation, in a bounded number
//!   of steps.
//! - [`check_tool`]: a `tool.json` is refused before any template or grid is sized from it
//!   (non-finite numbers, a tool larger than [`labels::MAX_TOOL_SIDE_M`]).
//! - [`ToolLabeller`]: labels from geometry: the tool fitted into the hull of the foreground
//!   (hand and tool together), drawn into every view with the hand's occlusion, so that scalpel
//!   and hand pixels are told apart with no colour model ([`labels`]).
#![warn(missing_docs)]

mod evidence;
mod filter;
mod fit;
mod geometry;
mod holes;
mod init;
pub mod labels;
mod metrics;
mod part_colours;
mod table_shadow;
mod template;
mod track;

pub use filter::{OneEuro, OneEuroParams};
pub use labels::{
    DrawnViews, LabelParams, LabelStats, LabelledFrame, POSSIBLE_SHADOW, TABLE_SHADOW, TOOL_COLOURED_SHADOW,
    ToolDrawer, ToolLabeller, ToolRegion,
};
pub use metrics::{PoseError, pose_error};
pub use table_shadow::{SHADE_TOLERANCE, Shading, TableShadows};
pub use template::{Template, check_tool};
pub use track::{
    BladePose, Diagnostics, MANY_VIEWS, MIN_VIEWS_LEFT, MatrixError, ORTHONORMAL_TOLERANCE, PoseEstimate, Sight,
    Tracker, TrackerParams, ViewInput, isometry_from_matrix, rigid_from_matrix,
};

/// Why a pose estimator could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum ToolError {
    /// The tool geometry cannot serve as a template.
    #[error("the tool cannot serve as a blade template: {0}")]
    Template(String),
}
