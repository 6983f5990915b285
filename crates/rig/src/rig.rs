//! A rig of N calibrated cameras in one world frame.

use std::io::Read as _;
use std::path::Path;

use crate::limits::check_camera;
use crate::{Camera, MAX_CAMERAS, MAX_RIG_FILE_BYTES, RigError, shorten};

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
    ///
    /// At most [`MAX_RIG_FILE_BYTES`] are read (a larger file, or an endless one such as a device,
    /// is refused without reading further); see [`Rig::from_yaml_str`] for what is checked.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, RigError> {
        let path = path.as_ref();
        let read = |error| RigError::Read { path: path.to_owned(), error };
        let file = std::fs::File::open(path).map_err(read)?;
        let mut bytes = Vec::new();
        file.take(MAX_RIG_FILE_BYTES + 1).read_to_end(&mut bytes).map_err(read)?;
        let name = path.display().to_string();
        if bytes.len() as u64 > MAX_RIG_FILE_BYTES {
            return Err(RigError::TooLarge { file: name, limit: MAX_RIG_FILE_BYTES });
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            read(std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {}", e.utf8_error())))
        })?;
        Self::from_yaml_str(&text, &name)
    }

    /// Parses and validates `rig.yaml` text; `file` names the source in error messages.
    ///
    /// Refused, each error naming the file and the key (or line) and, for numbers, the allowed
    /// range: text over [`MAX_RIG_FILE_BYTES`]; YAML aliases, deep nesting or more nodes than a rig
    /// needs (see the `yaml` module); a `camera_count` outside `1..=`[`MAX_CAMERAS`] or disagreeing
    /// with the `camera_N` keys present; missing keys, wrong types and matrix shapes; non-finite
    /// numbers; rotations that are not rotations; and every range [`Rig::validate`] checks.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Self, RigError> {
        if text.len() as u64 > MAX_RIG_FILE_BYTES {
            return Err(RigError::TooLarge { file: file.to_owned(), limit: MAX_RIG_FILE_BYTES });
        }
        crate::yaml::parse_rig(text, file)
    }

    /// Checks a rig against the limits every reader applies, naming `file` and the `rig.yaml` key
    /// (`camera_2.camera_matrix`) in errors: 1..=[`MAX_CAMERAS`] cameras with unique, non-empty
    /// names; image sides in `1..=`[`MAX_IMAGE_SIDE`](crate::MAX_IMAGE_SIDE); `fx`, `fy` from
    /// [`MIN_FOCAL_PX`](crate::MIN_FOCAL_PX) to [`MAX_FOCAL_PX`](crate::MAX_FOCAL_PX); the principal
    /// point within minus the image side to twice it; distortion coefficients within
    /// ±[`MAX_DISTORTION_COEFFICIENT`](crate::MAX_DISTORTION_COEFFICIENT); rotations within
    /// [`ROTATION_TOLERANCE`](crate::ROTATION_TOLERANCE); translations within
    /// ±[`MAX_WORLD_COORDINATE_M`](crate::MAX_WORLD_COORDINATE_M); an RMS error in
    /// `[0, MAX_IMAGE_SIDE]` px. Every number must be finite.
    pub fn validate(&self, file: &str) -> Result<(), RigError> {
        let invalid = |key: String, message: String| RigError::Invalid { file: file.to_owned(), key, message };
        if !(1..=MAX_CAMERAS).contains(&self.cameras.len()) {
            return Err(invalid(
                "camera_count".to_owned(),
                format!("{} cameras, outside 1..={MAX_CAMERAS}", self.cameras.len()),
            ));
        }
        for (i, c) in self.cameras.iter().enumerate() {
            if c.name.is_empty() {
                return Err(invalid(format!("camera_{i}.name"), "the name is empty".to_owned()));
            }
            if let Some(j) = self.cameras[..i].iter().position(|o| o.name == c.name) {
                return Err(invalid(
                    format!("camera_{i}.name"),
                    format!("`{}` is also camera_{j}'s name", shorten(&c.name)),
                ));
            }
            check_camera(c).map_err(|p| invalid(format!("camera_{i}.{}", p.part.yaml_key()), p.message))?;
        }
        Ok(())
    }

    /// The rig as `rig.yaml` text (OpenCV FileStorage YAML).
    pub fn to_yaml_string(&self) -> String {
        crate::yaml::write_rig(self)
    }

    /// Writes `rig.yaml`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), RigError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_yaml_string()).map_err(|error| RigError::Write { path: path.to_owned(), error })
    }
}
