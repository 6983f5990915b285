//! Triangle meshes come from `hullcut-mesh`, the workspace's one mesh type; this module adds what
//! only the simulator's surface extractors need.

use nalgebra::Point3;

pub use hullcut_mesh::{MeshError, TriMesh, WindingTree};

/// Appends quad `q` (counter-clockwise vertex indices) as two triangles split along its shorter
/// diagonal, as the surface-nets extractors do.
pub(crate) fn push_quad(triangles: &mut Vec<[u32; 3]>, vertices: &[Point3<f64>], q: [u32; 4]) {
    let p = q.map(|i| vertices[i as usize]);
    if (p[0] - p[2]).norm_squared() <= (p[1] - p[3]).norm_squared() {
        triangles.push([q[0], q[1], q[2]]);
        triangles.push([q[0], q[2], q[3]]);
    } else {
        triangles.push([q[0], q[1], q[3]]);
        triangles.push([q[1], q[2], q[3]]);
    }
}
