//! Wavefront OBJ reading: `v x y z [w]` and `f` lines (`a`, `a/b`, `a//c`, `a/b/c`, negative indices
//! relative to the end); everything else is skipped.

use std::path::Path;

use nalgebra::Point3;

use crate::ply::fan;
use crate::{MeshError, TriMesh};

/// Parses OBJ text; `path` is for messages.
pub(crate) fn parse_obj(text: &str, path: &Path) -> Result<TriMesh, MeshError> {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut face = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let parse_err =
            |message: String| MeshError::Parse { path: path.to_owned(), at: format!("line {}", n + 1), message };
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0.0f64; 3];
                for v in &mut c {
                    let Some(word) = words.next() else {
                        return Err(parse_err("a vertex needs x, y and z".into()));
                    };
                    *v = word.parse().map_err(|_| parse_err(format!("`{}` is not a number", crate::shorten(word))))?;
                    if !v.is_finite() {
                        return Err(parse_err(format!("`{}` is not a finite coordinate", crate::shorten(word))));
                    }
                }
                vertices.push(Point3::from(c));
            }
            Some("f") => {
                face.clear();
                for word in words {
                    let first = word.split('/').next().unwrap_or(word);
                    let i: i64 = first
                        .parse()
                        .map_err(|_| parse_err(format!("`{}` is not a vertex reference", crate::shorten(word))))?;
                    let resolved = if i < 0 { (vertices.len() as i64).saturating_add(i) } else { i - 1 };
                    if i == 0 || resolved < 0 || resolved as usize >= vertices.len() {
                        return Err(MeshError::IndexOutOfRange {
                            path: path.to_owned(),
                            at: format!("line {}", n + 1),
                            index: i,
                            vertices: vertices.len(),
                        });
                    }
                    face.push(resolved as u32);
                }
                if face.len() < 3 {
                    return Err(parse_err(format!("a face needs at least 3 vertices, this one has {}", face.len())));
                }
                fan(face.iter().copied(), &mut triangles);
            }
            _ => {}
        }
    }
    Ok(TriMesh::new(vertices, triangles))
}
