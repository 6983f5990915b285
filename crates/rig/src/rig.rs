//! A rig of N calibrated cameras in one world frame.

use std::path::Path;

use crate::{Camera, RigError};

/// Which frame the rig's world coordinates are expressed in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WorldFrame {
    /// Camera 0's frame is the world (no world board was given at calibration).
    Camera0,
    /// The frame of a chessboard lying on the table, seen in the named image: origin at the board's
    /// first inner corner, x along its rows, z up toward the cameras.
    Board {
        /// File name of the image that showed the board.
        image: String,
    },
    /// A table's frame, described in words (key starting with `table`): z up, the table top at
    /// z = 0, as the synthetic scenes use.
    Table(String),
    /// Any other frame, described in words.
    Other(String),
}

impl WorldFrame {
    /// The value written to `rig.yaml`'s `world_frame` key.
    pub fn to_key(&self) -> String {
        match self {
            Self::Camera0 => "camera_0".to_owned(),
            Self::Board { image } => format!("board:{image}"),
            Self::Table(s) | Self::Other(s) => s.clone(),
        }
    }

    /// Parses the `world_frame` key (inverse of [`WorldFrame::to_key`]).
    pub fn from_key(s: &str) -> Self {
        match s {
            "camera_0" => Self::Camera0,
            _ => match s.strip_prefix("board:") {
                Some(image) => Self::Board { image: image.to_owned() },
                None if s.starts_with("table") => Self::Table(s.to_owned()),
                None => Self::Other(s.to_owned()),
            },
        }
    }

    /// Whether the frame is a table's (z up, the table top at z = 0): a world board's, or one
    /// described as a table's. The working volume derived from the rig then stays above z = 0.
    pub fn is_table(&self) -> bool {
        matches!(self, Self::Board { .. } | Self::Table(_))
    }
}

/// N cameras sharing one world frame, in rig order.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// The cameras, in rig order (camera_0, camera_1, ...).
    pub cameras: Vec<Camera>,
    /// What the world frame is.
    pub world_frame: WorldFrame,
}

impl Rig {
    /// A rig from cameras; camera names must be unique.
    pub fn new(cameras: Vec<Camera>, world_frame: WorldFrame) -> Self {
        Self { cameras, world_frame }
    }

    /// Number of cameras.
    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    /// Whether the rig has no cameras.
    pub fn is_empty(&self) -> bool {
        self.cameras.is_empty()
    }

    /// The camera with this name.
    pub fn camera(&self, name: &str) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.name == name)
    }

    /// Index of the camera with this name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.cameras.iter().position(|c| c.name == name)
    }

    /// Reads and validates a `rig.yaml` (ours or one written by OpenCV's FileStorage).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, RigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| RigError::Read { path: path.to_owned(), source })?;
        Self::from_yaml_str(&text, &path.display().to_string())
    }

    /// Parses and validates `rig.yaml` text; `file` names the source in error messages.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Self, RigError> {
        crate::yaml::parse_rig(text, file)
    }

    /// The rig as `rig.yaml` text (OpenCV FileStorage YAML).
    pub fn to_yaml_string(&self) -> String {
        crate::yaml::write_rig(self)
    }

    /// Writes `rig.yaml`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), RigError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_yaml_string()).map_err(|source| RigError::Write { path: path.to_owned(), source })
    }
}
