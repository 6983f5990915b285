//! `tool.json`: the instrument's known geometry ([`read_tool`], [`write_tool`]).

use std::path::{Path, PathBuf};

use hullcut_rig::{short_number, shorten};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};
use crate::layout::{json_message, read_text};
use crate::ply::{read_ply, write_ply};
use crate::types::ToolGeometry;
use crate::{MAX_SMALL_FILE_BYTES, MAX_TOOL_COORDINATE_M, MAX_TOOL_EXTENT_M};

/// Normals shorter than this are refused as zero.
const MIN_NORMAL_LENGTH: f64 = 1e-12;

/// The longest mesh path `tool.json` may name, bytes.
const MAX_MESH_PATH_BYTES: usize = 4096;

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

/// A point for a message, its coordinates through [`short_number`].
fn show(p: &Point3<f64>) -> String {
    format!("[{}, {}, {}]", short_number(p.x), short_number(p.y), short_number(p.z))
}

/// Checks the geometry's numbers (not the mesh): finite; tip, cutting edge and outline within
/// ±[`MAX_TOOL_COORDINATE_M`] and together within a box of side [`MAX_TOOL_EXTENT_M`]; a cutting
/// edge of at least two points; a non-zero blade normal; a positive blade thickness of at most
/// [`MAX_TOOL_EXTENT_M`]. Returns the unit blade normal.
fn check_numbers(
    path: &Path,
    tip: &Point3<f64>,
    cutting_edge: &[Point3<f64>],
    blade_normal: &Vector3<f64>,
    blade_thickness: f64,
    blade_outline: Option<&[Point3<f64>]>,
) -> Result<Vector3<f64>> {
    let invalid =
        |key: &str, message: String| DatasetError::Invalid { path: path.to_owned(), key: key.to_owned(), message };
    let bounded = |p: &Point3<f64>| p.coords.iter().all(|c| c.abs() <= MAX_TOOL_COORDINATE_M);
    let range = format!("finite and within ±{MAX_TOOL_COORDINATE_M} m (tool frame, metres)");
    if !bounded(tip) {
        return Err(invalid("tip", format!("{} must be {range}", show(tip))));
    }
    if cutting_edge.len() < 2 {
        return Err(invalid(
            "cutting_edge",
            format!("a polyline of at least 2 points is needed, found {}", cutting_edge.len()),
        ));
    }
    if let Some(i) = cutting_edge.iter().position(|p| !bounded(p)) {
        return Err(invalid("cutting_edge", format!("point {i} {} must be {range}", show(&cutting_edge[i]))));
    }
    if let Some(outline) = blade_outline
        && let Some(i) = outline.iter().position(|p| !bounded(p))
    {
        return Err(invalid("blade_outline", format!("point {i} {} must be {range}", show(&outline[i]))));
    }
    let points = std::iter::once(tip).chain(cutting_edge).chain(blade_outline.unwrap_or_default());
    let (lo, hi) = points.fold((tip.coords, tip.coords), |(lo, hi), p| (lo.inf(&p.coords), hi.sup(&p.coords)));
    let side = (hi - lo).max();
    if side > MAX_TOOL_EXTENT_M {
        return Err(invalid(
            "cutting_edge",
            format!(
                "the tip, cutting edge and blade outline span {} m, more than the {MAX_TOOL_EXTENT_M} m of a hand-held \
                 tool (tool.json is in metres: a file in millimetres?)",
                short_number(side)
            ),
        ));
    }
    let n = blade_normal;
    let length = n.norm();
    if !length.is_finite() || length < MIN_NORMAL_LENGTH {
        return Err(invalid(
            "blade_normal",
            format!(
                "must be a non-zero finite vector, found [{}, {}, {}]",
                short_number(n.x),
                short_number(n.y),
                short_number(n.z)
            ),
        ));
    }
    if !(blade_thickness > 0.0 && blade_thickness <= MAX_TOOL_EXTENT_M) {
        return Err(invalid(
            "blade_thickness",
            format!("{} must be in (0, {MAX_TOOL_EXTENT_M}] (metres)", short_number(blade_thickness)),
        ));
    }
    // A normal that is already unit (to rounding) is kept bit for bit, so files round-trip exactly.
    Ok(if (length - 1.0).abs() <= 4.0 * f64::EPSILON { *n } else { n / length })
}

/// Checks the geometry's values and its mesh; returns the unit blade normal.
fn validate(path: &Path, tool: &ToolGeometry) -> Result<Vector3<f64>> {
    let normal = check_numbers(
        path,
        &tool.tip,
        &tool.cutting_edge,
        &tool.blade_normal,
        tool.blade_thickness,
        tool.blade_outline.as_deref(),
    )?;
    let invalid =
        |key: &str, message: String| DatasetError::Invalid { path: path.to_owned(), key: key.to_owned(), message };
    tool.mesh.validate().map_err(|message| invalid("mesh", message))?;
    if tool.mesh.triangles.is_empty() {
        return Err(invalid("mesh", "the mesh has no triangles".to_owned()));
    }
    Ok(normal)
}

/// Reads and validates a `tool.json` (at most [`MAX_SMALL_FILE_BYTES`]) and the mesh it names
/// (relative to the JSON file).
///
/// Checks, each error naming the file and the key, before the mesh is read: unknown keys; finite
/// tip, cutting edge and blade outline within ±[`MAX_TOOL_COORDINATE_M`] and together within a
/// box of side [`MAX_TOOL_EXTENT_M`]; a cutting edge of at least two points; a non-zero blade
/// normal (returned normalized); a positive blade thickness of at most [`MAX_TOOL_EXTENT_M`].
/// Then the mesh must be readable and non-empty. A mesh that is not closed is accepted with a warning.
pub fn read_tool(path: impl AsRef<Path>) -> Result<ToolGeometry> {
    let path = path.as_ref();
    let text = read_text(path, MAX_SMALL_FILE_BYTES, None)?;
    let file: ToolFile = serde_json::from_str(&text)
        .map_err(|e| DatasetError::Parse { path: path.to_owned(), message: json_message(&e, true) })?;
    let tip = point(file.tip);
    let cutting_edge: Vec<Point3<f64>> = file.cutting_edge.into_iter().map(point).collect();
    let blade_normal = Vector3::from(file.blade_normal);
    let blade_outline: Option<Vec<Point3<f64>>> = file.blade_outline.map(|o| o.into_iter().map(point).collect());
    check_numbers(path, &tip, &cutting_edge, &blade_normal, file.blade_thickness, blade_outline.as_deref())?;
    if file.mesh.len() > MAX_MESH_PATH_BYTES {
        return Err(DatasetError::Invalid {
            path: path.to_owned(),
            key: "mesh".to_owned(),
            message: format!("the path `{}` is longer than {MAX_MESH_PATH_BYTES} bytes", shorten(&file.mesh)),
        });
    }
    let mesh_path = path.parent().unwrap_or(Path::new("")).join(&file.mesh);
    let mesh = read_ply(&mesh_path).map_err(|e| DatasetError::Invalid {
        path: path.to_owned(),
        key: "mesh".to_owned(),
        message: format!("cannot read the mesh: {e}"),
    })?;
    if mesh.triangles.is_empty() {
        return Err(DatasetError::Invalid {
            path: path.to_owned(),
            key: "mesh".to_owned(),
            message: format!("{} has no triangles", mesh_path.display()),
        });
    }
    // The mesh is the tool too: its vertices obey the tool's bounds (a vertex at 1e300 would size
    // the pose template's grids), and the error names the mesh file.
    if let Some((lo, hi)) = mesh.bounds() {
        let far = lo.coords.iter().chain(hi.coords.iter()).any(|c| c.abs() > MAX_TOOL_COORDINATE_M);
        let extent = (hi - lo).max();
        if far || extent > MAX_TOOL_EXTENT_M {
            return Err(DatasetError::Invalid {
                path: path.to_owned(),
                key: "mesh".to_owned(),
                message: format!(
                    "{} spans {} m, from [{}] to [{}]; a hand-held tool is within ±{MAX_TOOL_COORDINATE_M} m and at \
                     most {MAX_TOOL_EXTENT_M} m across (a mesh in millimetres?)",
                    mesh_path.display(),
                    short_number(extent),
                    lo.coords.iter().map(|&c| short_number(c)).collect::<Vec<_>>().join(", "),
                    hi.coords.iter().map(|&c| short_number(c)).collect::<Vec<_>>().join(", "),
                ),
            });
        }
    }
    let mut tool =
        ToolGeometry { mesh, tip, cutting_edge, blade_normal, blade_thickness: file.blade_thickness, blade_outline };
    tool.blade_normal = validate(path, &tool)?;
    if !tool.mesh.is_closed_oriented() {
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
