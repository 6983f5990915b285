//! PLY triangle meshes through `hullcut-mesh`, the workspace's one reader and writer: [`read_ply`]
//! (ASCII and binary, either byte order, with the mesh crate's limits) and [`write_ply`] (binary
//! little endian, double-precision vertices, so a round trip is bit-exact).

use std::path::Path;

use crate::error::Result;
use crate::types::Mesh;

/// Reads a PLY triangle mesh whatever the file's extension: ASCII, binary little endian or binary
/// big endian; vertex `x`, `y`, `z` of any numeric type (other properties and elements are
/// skipped); faces as a `vertex_indices` (or `vertex_index`) list of any integer type, polygons
/// fan-triangulated. A mesh without faces is read as such.
///
/// Errors name the file and, where known, the header line, vertex or face.
pub fn read_ply(path: impl AsRef<Path>) -> Result<Mesh> {
    Ok(Mesh::load_ply(path)?)
}

/// Writes a triangle mesh as binary little-endian PLY with `double` vertices and `uint` indices
/// (so [`read_ply`] returns exactly the same mesh).
pub fn write_ply(path: impl AsRef<Path>, mesh: &Mesh) -> Result<()> {
    Ok(mesh.write_ply(path)?)
}
