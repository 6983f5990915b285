//! `rig.yaml`: OpenCV FileStorage YAML, read and written without OpenCV.
//!
//! OpenCV writes a `%YAML:1.0` directive and `!!opencv-matrix` tags that YAML 1.2 parsers reject;
//! both are removed before parsing. Matrices are mappings `{rows, cols, dt, data}`.

use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, Vector3};
use yaml_rust2::{Yaml, YamlLoader};

use crate::{Camera, Distortion, Rig, RigError, WorldFrame};

/// Largest accepted max |RᵀR − I| of a stored rotation (files rounded to ~6 significant digits pass);
/// accepted rotations are re-orthonormalized.
const ROTATION_TOLERANCE: f64 = 1e-5;

struct Reader<'a> {
    file: &'a str,
}

impl Reader<'_> {
    fn get<'y>(&self, node: &'y Yaml, parent: &str, key: &str) -> Result<&'y Yaml, RigError> {
        let v = &node[key];
        if v.is_badvalue() || v.is_null() {
            return Err(RigError::MissingKey { file: self.file.to_owned(), key: join(parent, key) });
        }
        Ok(v)
    }

    fn invalid(&self, key: &str, message: impl Into<String>) -> RigError {
        RigError::Invalid { file: self.file.to_owned(), key: key.to_owned(), message: message.into() }
    }

    fn number(&self, v: &Yaml, key: &str) -> Result<f64, RigError> {
        let x = match v {
            Yaml::Real(_) => v.as_f64(),
            Yaml::Integer(i) => Some(*i as f64),
            _ => None,
        }
        .ok_or_else(|| self.invalid(key, format!("expected a number, found {}", describe(v))))?;
        if !x.is_finite() {
            return Err(RigError::NonFinite { file: self.file.to_owned(), key: key.to_owned() });
        }
        Ok(x)
    }

    fn size(&self, node: &Yaml, parent: &str, key: &str) -> Result<u32, RigError> {
        let full = join(parent, key);
        let v = self.get(node, parent, key)?;
        let n = v.as_i64().ok_or_else(|| self.invalid(&full, format!("expected an integer, found {}", describe(v))))?;
        if n == 0 {
            return Err(RigError::ZeroImageSize { file: self.file.to_owned(), key: full });
        }
        u32::try_from(n)
            .ok()
            .filter(|&v| v <= crate::MAX_IMAGE_SIDE)
            .ok_or_else(|| self.invalid(&full, format!("{n} is not an image size in 1..={}", crate::MAX_IMAGE_SIDE)))
    }

    /// A `rows x cols` opencv-matrix; `alt_shapes` lists other accepted shapes (e.g. 5x1 for 1x5).
    fn matrix(&self, node: &Yaml, parent: &str, key: &str, shapes: &[(i64, i64)]) -> Result<Vec<f64>, RigError> {
        let full = join(parent, key);
        let m = self.get(node, parent, key)?;
        if m.as_hash().is_none() {
            return Err(self.invalid(&full, format!("expected an opencv-matrix mapping, found {}", describe(m))));
        }
        let rows = self.get(m, &full, "rows")?.as_i64();
        let cols = self.get(m, &full, "cols")?.as_i64();
        let data = self.get(m, &full, "data")?;
        let data = data
            .as_vec()
            .ok_or_else(|| self.invalid(&join(&full, "data"), format!("expected a list, found {}", describe(data))))?;
        let expected = shapes.iter().map(|(r, c)| format!("{r}x{c}")).collect::<Vec<_>>().join(" or ");
        let (Some(rows), Some(cols)) = (rows, cols) else {
            return Err(self.invalid(&full, "rows and cols must be integers"));
        };
        if !shapes.contains(&(rows, cols)) {
            return Err(RigError::MatrixSize {
                file: self.file.to_owned(),
                key: full,
                expected,
                found: format!("{rows}x{cols}"),
            });
        }
        if data.len() as i64 != rows * cols {
            return Err(RigError::MatrixSize {
                file: self.file.to_owned(),
                key: full,
                expected,
                found: format!("{rows}x{cols} with {} data values", data.len()),
            });
        }
        data.iter().map(|v| self.number(v, &join(&full, "data"))).collect()
    }

    fn camera(&self, node: &Yaml, index: usize) -> Result<Camera, RigError> {
        let p = format!("camera_{index}");
        let name = match &node["name"] {
            Yaml::String(s) => s.clone(),
            Yaml::BadValue | Yaml::Null => format!("cam{index}"),
            other => {
                return Err(self.invalid(&join(&p, "name"), format!("expected a string, found {}", describe(other))));
            }
        };
        let width = self.size(node, &p, "image_width")?;
        let height = self.size(node, &p, "image_height")?;
        let k = self.matrix(node, &p, "camera_matrix", &[(3, 3)])?;
        let key_k = join(&p, "camera_matrix");
        if k[0] <= 0.0 || k[4] <= 0.0 {
            return Err(self.invalid(&key_k, "focal lengths (fx, fy) must be positive"));
        }
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(self.invalid(&key_k, "expected [fx 0 cx; 0 fy cy; 0 0 1] (skew is not supported)"));
        }
        let d = self.matrix(node, &p, "distortion_coefficients", &[(1, 5), (5, 1), (1, 4), (4, 1)])?;
        let mut coeffs = [0.0; 5];
        coeffs[..d.len()].copy_from_slice(&d);
        let r = self.matrix(node, &p, "rotation_matrix", &[(3, 3)])?;
        let r = Matrix3::from_row_slice(&r);
        let deviation = (r.transpose() * r - Matrix3::identity()).abs().max();
        let det = r.determinant();
        if deviation > ROTATION_TOLERANCE || det <= 0.0 {
            return Err(RigError::NotRotation {
                file: self.file.to_owned(),
                key: join(&p, "rotation_matrix"),
                deviation,
                det,
            });
        }
        let t = self.matrix(node, &p, "translation_vector", &[(3, 1), (1, 3)])?;
        let rms = match &node["rms_reprojection_error"] {
            Yaml::BadValue | Yaml::Null => None,
            v => Some(self.number(v, &join(&p, "rms_reprojection_error"))?),
        };
        Ok(Camera {
            name,
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion: Distortion::from_array(coeffs),
            rotation: orthonormalize(r),
            translation: Vector3::new(t[0], t[1], t[2]),
            rms_reprojection_error: rms,
        })
    }
}

/// The rotation nearest `r` (polar decomposition); `r` itself when it is orthonormal to 1e-14, so
/// files written at full precision read back bit for bit.
fn orthonormalize(r: Matrix3<f64>) -> Rotation3<f64> {
    if (r.transpose() * r - Matrix3::identity()).abs().max() <= 1e-14 {
        return Rotation3::from_matrix_unchecked(r);
    }
    let svd = r.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => Rotation3::from_matrix_unchecked(u * v_t),
        _ => Rotation3::from_matrix_unchecked(r),
    }
}

fn join(parent: &str, key: &str) -> String {
    if parent.is_empty() { key.to_owned() } else { format!("{parent}.{key}") }
}

fn describe(v: &Yaml) -> String {
    match v {
        Yaml::Real(s) | Yaml::String(s) => format!("`{s}`"),
        Yaml::Integer(i) => format!("`{i}`"),
        Yaml::Boolean(b) => format!("`{b}`"),
        Yaml::Array(_) => "a list".to_owned(),
        Yaml::Hash(_) => "a mapping".to_owned(),
        _ => "nothing".to_owned(),
    }
}

/// Removes what OpenCV writes but YAML 1.2 parsers reject: the `%YAML:1.0` directive and
/// `!!opencv-matrix` (and other `!!opencv-*`) tags.
fn strip_opencv_syntax(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        if line.trim_start().starts_with("%YAML") {
            continue;
        }
        let mut rest = line;
        while let Some(pos) = rest.find("!!opencv-") {
            out.push_str(&rest[..pos]);
            let after = &rest[pos..];
            let end = after.find(|c: char| c.is_whitespace() || c == '{').unwrap_or(after.len());
            rest = &after[end..];
        }
        out.push_str(rest);
        out.push('\n');
    }
    out
}

pub(crate) fn parse_rig(text: &str, file: &str) -> Result<Rig, RigError> {
    let docs = YamlLoader::load_from_str(&strip_opencv_syntax(text))
        .map_err(|e| RigError::Syntax { file: file.to_owned(), message: e.to_string() })?;
    let Some(root) = docs.first() else {
        return Err(RigError::Syntax { file: file.to_owned(), message: "the file is empty".to_owned() });
    };
    let r = Reader { file };
    if root.as_hash().is_none() {
        return Err(RigError::Syntax { file: file.to_owned(), message: "the top level must be a mapping".to_owned() });
    }
    let count = r.get(root, "", "camera_count")?;
    let count = count
        .as_i64()
        .filter(|&n| n > 0)
        .ok_or_else(|| r.invalid("camera_count", format!("expected a positive integer, found {}", describe(count))))?;
    if count as u64 > crate::MAX_CAMERAS as u64 {
        return Err(
            r.invalid("camera_count", format!("{count} exceeds the {} cameras a rig may have", crate::MAX_CAMERAS))
        );
    }
    let mut cameras = Vec::with_capacity(count as usize);
    for i in 0..count as usize {
        let key = format!("camera_{i}");
        let node = r.get(root, "", &key)?;
        cameras.push(r.camera(node, i)?);
    }
    if !root[format!("camera_{count}").as_str()].is_badvalue() {
        return Err(r.invalid("camera_count", format!("is {count} but the file also has camera_{count}")));
    }
    for (i, c) in cameras.iter().enumerate() {
        if let Some(j) = cameras[..i].iter().position(|o| o.name == c.name) {
            return Err(r.invalid(&format!("camera_{i}.name"), format!("`{}` is also camera_{j}'s name", c.name)));
        }
    }
    let world_frame = match &root["world_frame"] {
        Yaml::String(s) => WorldFrame::from_key(s),
        _ => WorldFrame::Other("unspecified".to_owned()),
    };
    Ok(Rig { cameras, world_frame })
}

fn write_matrix(out: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]) {
    let values = data.iter().map(|v| format!("{v:.17e}")).collect::<Vec<_>>().join(", ");
    let _ = write!(
        out,
        "   {key}: !!opencv-matrix\n      rows: {rows}\n      cols: {cols}\n      dt: d\n      data: [ {values} ]\n"
    );
}

/// Quotes a string the way OpenCV does when it is not a plain token.
fn yaml_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

pub(crate) fn write_rig(rig: &Rig) -> String {
    let mut out = String::from("%YAML:1.0\n---\n");
    let _ = writeln!(out, "camera_count: {}", rig.cameras.len());
    let _ = writeln!(out, "world_frame: {}", yaml_string(&rig.world_frame.to_key()));
    for (i, c) in rig.cameras.iter().enumerate() {
        let _ = writeln!(out, "camera_{i}:");
        let _ = writeln!(out, "   name: {}", yaml_string(&c.name));
        let _ = writeln!(out, "   image_width: {}", c.width);
        let _ = writeln!(out, "   image_height: {}", c.height);
        let k = c.k_matrix();
        write_matrix(&mut out, "camera_matrix", 3, 3, k.transpose().as_slice());
        write_matrix(&mut out, "distortion_coefficients", 1, 5, &c.distortion.to_array());
        write_matrix(&mut out, "rotation_matrix", 3, 3, c.rotation.matrix().transpose().as_slice());
        write_matrix(&mut out, "translation_vector", 3, 1, c.translation.as_slice());
        if let Some(rms) = c.rms_reprojection_error {
            let _ = writeln!(out, "   rms_reprojection_error: {rms:.17e}");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_opencv_header_and_tags() {
        let s = strip_opencv_syntax("%YAML:1.0\n---\nm: !!opencv-matrix\n   rows: 1\nn: !!opencv-matrix {rows: 1}\n");
        assert_eq!(s, "---\nm: \n   rows: 1\nn:  {rows: 1}\n");
    }
}
