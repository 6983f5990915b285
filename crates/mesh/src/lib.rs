//! The workspace's one triangle-mesh type, [`TriMesh`], and its files.
//!
//! - Reading: [`TriMesh::load`] (`.ply` ASCII or binary, either byte order; `.obj`), with limits
//!   that hold for every caller: the file's size ([`MAX_FILE_BYTES`]), row counts checked against
//!   the data and [`MAX_VERTICES`] / [`MAX_TRIANGLES`], list lengths ([`MAX_LIST_LEN`]), finite
//!   vertices, indices in range. [`TriMesh::from_ply_bytes`] reads from memory.
//! - Writing: [`TriMesh::write_ply`] (binary, exact round trip) and [`TriMesh::write_ply_ascii`].
//! - Geometry: volume (holes closed by fans), area, bounds, holes, open edges, orientation,
//!   generalized winding numbers (exact, and fast with [`WindingTree`]), primitives (boxes,
//!   capsules, ellipsoids, prisms).
//!
//! Pure Rust: no OpenCV, no rerun, no GPU.

#![warn(missing_docs)]

mod error;
mod obj;
mod ply;
mod primitives;
mod trimesh;
mod winding;

use std::borrow::Cow;
use std::fs;
use std::io::BufWriter;
use std::path::Path;

pub use error::MeshError;
pub use ply::{MAX_LIST_LEN, MAX_TRIANGLES, MAX_VERTICES};
pub use trimesh::TriMesh;
pub use winding::{FAR_RATIO, WindingTree};

/// Largest mesh file [`TriMesh::load`] reads (4 GiB), checked before reading.
pub const MAX_FILE_BYTES: u64 = 1 << 32;

impl TriMesh {
    /// Reads a `.ply` (ASCII or binary, either byte order) or `.obj` file; the extension decides.
    /// Polygons are split into triangle fans; a face with fewer than three vertices is an error.
    /// Errors name the file and, where known, the header line, data line, vertex or face; a file
    /// without vertices or triangles is an error.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MeshError> {
        let path = path.as_ref();
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let mesh = match ext.as_deref() {
            Some("ply") => ply::parse_ply(&read_limited(path)?, path)?,
            Some("obj") => obj::parse_obj(&String::from_utf8_lossy(&read_limited(path)?), path)?,
            _ => return Err(MeshError::UnsupportedFormat { path: path.to_owned() }),
        };
        mesh.non_empty(path)
    }

    /// Reads a PLY file whatever its extension, with the same limits and checks as
    /// [`TriMesh::load`], but a mesh without triangles (or vertices) is returned as it is (an empty
    /// hull written by `reconstruct` reads back).
    pub fn load_ply(path: impl AsRef<Path>) -> Result<Self, MeshError> {
        let path = path.as_ref();
        ply::parse_ply(&read_limited(path)?, path)
    }

    /// Reads PLY data from memory, with the same checks as [`TriMesh::load`]; `name` stands for
    /// the file in messages.
    pub fn from_ply_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<Self, MeshError> {
        let path = name.as_ref();
        ply::parse_ply(bytes, path)?.non_empty(path)
    }

    fn non_empty(self, path: &Path) -> Result<Self, MeshError> {
        if self.vertices.is_empty() {
            return Err(MeshError::Empty { path: path.to_owned(), what: "vertices" });
        }
        if self.triangles.is_empty() {
            return Err(MeshError::Empty { path: path.to_owned(), what: "triangles" });
        }
        Ok(self)
    }

    /// Writes binary little-endian PLY: vertices as `double x y z` (exact round trip), faces as
    /// `list uchar uint vertex_indices`.
    pub fn write_ply(&self, path: impl AsRef<Path>) -> Result<(), MeshError> {
        self.write_ply_with(path.as_ref(), false)
    }

    /// Writes ASCII PLY with the same layout as [`TriMesh::write_ply`]; coordinates are printed with
    /// the shortest representation that reads back to the same `f64`.
    pub fn write_ply_ascii(&self, path: impl AsRef<Path>) -> Result<(), MeshError> {
        self.write_ply_with(path.as_ref(), true)
    }

    fn write_ply_with(&self, path: &Path, ascii: bool) -> Result<(), MeshError> {
        let err = |error| MeshError::Write { path: path.to_owned(), error };
        let file = fs::File::create(path).map_err(err)?;
        ply::write_ply(self, &mut BufWriter::new(file), ascii).map_err(err)
    }
}

/// The file's bytes, refused above [`MAX_FILE_BYTES`] before reading.
fn read_limited(path: &Path) -> Result<Vec<u8>, MeshError> {
    let read = |error| MeshError::Read { path: path.to_owned(), error };
    let len = fs::metadata(path).map_err(read)?.len();
    if len > MAX_FILE_BYTES {
        return Err(MeshError::TooLarge { path: path.to_owned(), bytes: len, limit: MAX_FILE_BYTES });
    }
    fs::read(path).map_err(read)
}

/// A value from a file as it may appear in a message: at most 80 characters, the rest counted.
pub(crate) fn shorten(value: &str) -> Cow<'_, str> {
    const KEEP: usize = 80;
    match value.char_indices().nth(KEEP) {
        None => Cow::Borrowed(value),
        Some((cut, _)) => Cow::Owned(format!("{}…({} more characters)", &value[..cut], value[cut..].chars().count())),
    }
}
