//! The organ's logging and export in `hullcut run`.

use std::path::Path;

use anyhow::Context as _;
use hullcut_pipeline::TissueStep;
use hullcut_sim::TriMesh;

/// RGBA of the organ's surface.
pub(crate) const TISSUE_RED: [u8; 4] = [170, 60, 50, 255];
/// RGBA of the swept blade surface.
pub(crate) const SWEPT_CYAN: [u8; 4] = [80, 220, 240, 160];

/// The surface as last logged, to log it again only when it has changed visibly.
#[derive(Debug, Default)]
pub struct SurfaceLog {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Surfaces logged and skipped.
    pub logged: u64,
    pub skipped: u64,
}

/// A surface is logged again when a vertex has moved this far since it was last logged, metres.
pub const SURFACE_LOG_TOLERANCE_M: f32 = 2e-4;

impl SurfaceLog {
    /// Whether `vertices`/`triangles` differ visibly from what was last logged.
    fn changed(&self, vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> bool {
        let tol2 = SURFACE_LOG_TOLERANCE_M * SURFACE_LOG_TOLERANCE_M;
        triangles != self.triangles
            || vertices.len() != self.vertices.len()
            || vertices
                .iter()
                .zip(&self.vertices)
                .any(|(a, b)| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2) > tol2)
    }
}

/// Logs one step: the surface when it has changed (its topology, or a vertex moved by more than
/// [`SURFACE_LOG_TOLERANCE_M`]: a tissue at rest costs nothing), the lattice nodes every
/// `every`-th frame, the swept blade surface when there is one (else it is cleared), the piece
/// count.
pub fn log(
    rec: &hullcut_viz::RecordingStream,
    step: &TissueStep,
    frame: u64,
    every: u64,
    last: &mut SurfaceLog,
) -> anyhow::Result<()> {
    let (vertices, triangles) = merged(&step.surfaces);
    if last.changed(&vertices, &triangles) {
        hullcut_viz::log_mesh3d(rec, "world/tissue/surface", &vertices, &triangles, TISSUE_RED)?;
        last.vertices = vertices;
        last.triangles = triangles;
        last.logged += 1;
    } else {
        last.skipped += 1;
    }
    if frame.is_multiple_of(every) {
        let nodes: Vec<[f32; 3]> = step.nodes.iter().map(|p| [p.x, p.y, p.z]).collect();
        let colors: Vec<[u8; 4]> = step.roles.iter().map(|r| r.color()).collect();
        hullcut_viz::log_points3d_colored(rec, "world/tissue/nodes", &nodes, &colors, 0.0008)?;
    }
    match &step.swept {
        Some(swept) => {
            let v: Vec<[f32; 3]> = swept.vertices.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
            hullcut_viz::log_mesh3d(rec, "world/tissue/cut", &v, &swept.triangles, SWEPT_CYAN)?;
        }
        None => hullcut_viz::log_clear(rec, "world/tissue/cut")?,
    }
    hullcut_viz::log_scalar(rec, "metrics/tissue/pieces", step.pieces as f64)?;
    hullcut_viz::log_scalar(rec, "metrics/tissue/table_contacts", step.table_contacts as f64)?;
    hullcut_viz::log_scalar(rec, "metrics/tissue/piece_contacts", step.piece_contacts as f64)?;
    Ok(())
}

/// The pieces' surfaces as one vertex and triangle list.
pub(crate) fn merged(surfaces: &[TriMesh]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for mesh in surfaces {
        let base = vertices.len() as u32;
        vertices.extend(mesh.vertices.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]));
        triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    (vertices, triangles)
}

/// Writes the pieces as DIR/NNNNNN/pieceK.ply; returns how many.
pub fn export(dir: &Path, frame: u64, surfaces: &[TriMesh]) -> anyhow::Result<u64> {
    let folder = dir.join(format!("{frame:06}"));
    std::fs::create_dir_all(&folder).with_context(|| format!("creating {}", folder.display()))?;
    for (k, mesh) in surfaces.iter().enumerate() {
        let path = folder.join(format!("piece{k}.ply"));
        mesh.write_ply(&path).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(surfaces.len() as u64)
}
