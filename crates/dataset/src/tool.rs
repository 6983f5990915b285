//! `tool.json`: the instrument's known geometry ([`read_tool`], [`write_tool`]).

use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};
use crate::ply::{read_ply, write_ply};
use crate::types::ToolGeometry;

/// Normals shorter than this are refused as zero.
const MIN_NORMAL_LENGTH: f64 = 1e-12;

/// The file as written: arrays of numbers, the mesh as a path relative to the JSON file.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolFile {
    mesh: String,
    tip: [f64; 3],
    cutting_edge: Vec<[f64; 3]>,
    blade_normal: [f64; 3],
    blade_thickness: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    blade_outline: Option<Vec<[f64; 3]>>,
}

fn point(p: [f64; 3]) -> Point3<f64> {
    Point3::new(p[0], p[1], p[2])
}

fn array(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// Checks the geometry's values (not the mesh file); returns the unit blade normal.
fn validate(path: &Path, tool: &ToolGeometry) -> Result<Vector3<f64>> {
    let invalid =
        |key: &str, message: String| DatasetError::Invalid { path: path.to_owned(), key: key.to_owned(), message };
    let finite = |p: &Point3<f64>| p.coords.iter().all(|c| c.is_finite());
    if !finite(&tool.tip) {
        return Err(invalid("tip", "not finite".to_owned()));
    }
    if tool.cutting_edge.len() < 2 {
        return Err(invalid(
            "cutting_edge",
            format!("a polyline of at least 2 points is needed, found {}", tool.cutting_edge.len()),
        ));
    }
    if let Some(i) = tool.cutting_edge.iter().position(|p| !finite(p)) {
        return Err(invalid("cutting_edge", format!("point {i} is not finite")));
    }
    let n = tool.blade_normal;
    let length = n.norm();
    if !length.is_finite() || length < MIN_NORMAL_LENGTH {
        return Err(invalid(
            "blade_normal",
            format!("must be a non-zero finite vector, found [{}, {}, {}]", n.x, n.y, n.z),
        ));
    }
    if !(tool.blade_thickness.is_finite() && tool.blade_thickness > 0.0) {
        return Err(invalid("blade_thickness", format!("must be positive (metres), found {}", tool.blade_thickness)));
    }
    if let Some(outline) = &tool.blade_outline
        && let Some(i) = outline.iter().position(|p| !finite(p))
    {
        return Err(invalid("blade_outline", format!("point {i} is not finite")));
    }
    tool.mesh.check().map_err(|message| invalid("mesh", message))?;
    if tool.mesh.triangles.is_empty() {
        return Err(invalid("mesh", "the mesh has no triangles".to_owned()));
    }
    // A normal that is already unit (to rounding) is kept bit for bit, so files round-trip exactly.
    Ok(if (length - 1.0).abs() <= 4.0 * f64::EPSILON { n } else { n / length })
}

/// Reads and validates a `tool.json` and the mesh it names (relative to the JSON file).
///
/// Checks, each error naming the file and the key: unknown keys, a cutting edge of at least two
/// points, a non-zero blade normal (returned normalized), a positive blade thickness, finite
/// numbers, and a readable, non-empty mesh. A mesh that is not closed is accepted with a warning.
pub fn read_tool(path: impl AsRef<Path>) -> Result<ToolGeometry> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(DatasetError::io(path))?;
    let file: ToolFile = serde_json::from_str(&text)
        .map_err(|e| DatasetError::Parse { path: path.to_owned(), message: e.to_string() })?;
    let mesh_path = path.parent().unwrap_or(Path::new("")).join(&file.mesh);
    let mesh = read_ply(&mesh_path).map_err(|e| DatasetError::Invalid {
        path: path.to_owned(),
        key: "mesh".to_owned(),
        message: format!("cannot read the mesh: {e}"),
    })?;
    let mut tool = ToolGeometry {
        mesh,
        tip: point(file.tip),
        cutting_edge: file.cutting_edge.into_iter().map(point).collect(),
        blade_normal: Vector3::from(file.blade_normal),
        blade_thickness: file.blade_thickness,
        blade_outline: file.blade_outline.map(|o| o.into_iter().map(point).collect()),
    };
    tool.blade_normal = validate(path, &tool)?;
    if !tool.mesh.is_closed() {
        tracing::warn!(file = %mesh_path.display(), "the tool mesh is not closed");
    }
    Ok(tool)
}

/// The mesh file written beside a tool JSON file: same stem, `.ply` (`tool.json` → `tool.ply`).
pub fn tool_mesh_path(json_path: &Path) -> PathBuf {
    json_path.with_extension("ply")
}

/// Writes `tool.json` (pretty-printed) and its mesh beside it ([`tool_mesh_path`]), after the same
/// checks [`read_tool`] makes; the blade normal is written normalized.
pub fn write_tool(json_path: impl AsRef<Path>, tool: &ToolGeometry) -> Result<()> {
    let path = json_path.as_ref();
    let normal = validate(path, tool)?;
    let mesh_path = tool_mesh_path(path);
    let mesh_name = mesh_path.file_name().map(|n| n.to_string_lossy().into_owned()).ok_or_else(|| {
        DatasetError::Invalid { path: path.to_owned(), key: "mesh".to_owned(), message: "no file name".to_owned() }
    })?;
    let file = ToolFile {
        mesh: mesh_name,
        tip: array(&tool.tip),
        cutting_edge: tool.cutting_edge.iter().map(array).collect(),
        blade_normal: [normal.x, normal.y, normal.z],
        blade_thickness: tool.blade_thickness,
        blade_outline: tool.blade_outline.as_ref().map(|o| o.iter().map(array).collect()),
    };
    let mut text = serde_json::to_string_pretty(&file)
        .map_err(|e| DatasetError::Parse { path: path.to_owned(), message: e.to_string() })?;
    text.push('\n');
    write_ply(&mesh_path, &tool.mesh)?;
    std::fs::write(path, text).map_err(DatasetError::io(path))
}
