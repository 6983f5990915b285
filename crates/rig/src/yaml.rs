//! `rig.yaml`: OpenCV FileStorage YAML, read and written without OpenCV.
//!
//! OpenCV writes a `%YAML:1.0` directive and `!!opencv-matrix` tags that YAML 1.2 parsers reject;
//! both are removed before parsing. Matrices are mappings `{rows, cols, dt, data}`.
//!
//! Hostile input. yaml-rust2's loader expands every alias (`*name`) by cloning the anchored node,
//! so a few hundred bytes of nested anchors and aliases ("billion laughs") grow to gigabytes; it
//! also builds (and later drops, recursively) a tree as deep as the input nests. Rig files need
//! neither aliases nor more than four levels of nesting, so before the loader runs, the text (at
//! most [`MAX_RIG_FILE_BYTES`](crate::MAX_RIG_FILE_BYTES)) goes through yaml-rust2's event parser,
//! which never expands anything: an `Alias` event, nesting deeper than [`MAX_YAML_DEPTH`] or more
//! than [`MAX_YAML_EVENTS`] events is refused, naming the line. This is exact where a textual
//! pre-scan for `*` would have to re-implement YAML's quoting and comment rules, and cheap: the
//! parser holds one event at a time.

use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, Vector3};
use yaml_rust2::parser::{Event, Parser};
use yaml_rust2::{ScanError, Yaml, YamlLoader};

use crate::limits::{is_rotation, rotation_deviation};
use crate::{Camera, Distortion, MAX_CAMERAS, Rig, RigError, WorldFrame, shorten, shorten_to};

/// Deepest nesting of YAML collections accepted. A rig needs four (top-level mapping, camera,
/// matrix, data list); the margin is for files that group things differently.
const MAX_YAML_DEPTH: usize = 16;

/// Most YAML events (scalars, collection starts and ends, document markers) accepted: a camera of
/// `rig.yaml` is about 80 events, so [`MAX_CAMERAS`] cameras and any extra keys a calibration tool
/// adds stay far below this, and loading this many nodes takes a few megabytes at most.
const MAX_YAML_EVENTS: usize = 100_000;

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
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(self.invalid(&key_k, "expected [fx 0 cx; 0 fy cy; 0 0 1] (skew is not supported)"));
        }
        let d = self.matrix(node, &p, "distortion_coefficients", &[(1, 5), (5, 1), (1, 4), (4, 1)])?;
        let mut coeffs = [0.0; 5];
        coeffs[..d.len()].copy_from_slice(&d);
        let r = self.matrix(node, &p, "rotation_matrix", &[(3, 3)])?;
        let r = Matrix3::from_row_slice(&r);
        let (deviation, det) = rotation_deviation(&r);
        if !is_rotation(deviation, det) {
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

/// What a node holds, for error messages (values shortened, see [`shorten`]).
fn describe(v: &Yaml) -> String {
    match v {
        Yaml::Real(s) | Yaml::String(s) => format!("`{}`", shorten(s)),
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

/// A parser error as [`RigError::Syntax`], its message shortened (a duplicated key is echoed) and its
/// place as line and column.
fn syntax_error(file: &str, e: &ScanError) -> RigError {
    let mark = e.marker();
    RigError::Syntax {
        file: file.to_owned(),
        message: format!("{} at line {} column {}", shorten_to(e.info(), 160), mark.line(), mark.col() + 1),
    }
}

/// Runs yaml-rust2's event parser over `text` without building anything, refusing aliases, nesting
/// deeper than [`MAX_YAML_DEPTH`] and more than [`MAX_YAML_EVENTS`] events (see the module docs).
/// Syntax errors are reported here too, with the parser's line and column.
fn check_yaml_events(text: &str, file: &str) -> Result<(), RigError> {
    let unsupported = |line: usize, message: String| RigError::Unsupported { file: file.to_owned(), line, message };
    let mut parser = Parser::new_from_str(text);
    let mut depth = 0usize;
    for _ in 0..MAX_YAML_EVENTS {
        let (event, mark) = parser.next_token().map_err(|e| syntax_error(file, &e))?;
        match event {
            Event::StreamEnd => return Ok(()),
            Event::Alias(_) => {
                return Err(unsupported(
                    mark.line(),
                    "YAML aliases (`*name`) are not accepted in rig files (expanding them can exhaust memory); \
                     write the values out"
                        .to_owned(),
                ));
            }
            Event::SequenceStart(..) | Event::MappingStart(..) => {
                depth += 1;
                if depth > MAX_YAML_DEPTH {
                    return Err(unsupported(
                        mark.line(),
                        format!("collections nest deeper than the {MAX_YAML_DEPTH} levels a rig file may use"),
                    ));
                }
            }
            Event::SequenceEnd | Event::MappingEnd => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    Err(unsupported(
        0,
        format!("more than {MAX_YAML_EVENTS} YAML nodes, far more than a rig of {MAX_CAMERAS} cameras has"),
    ))
}

/// The index `N` of a top-level `camera_N` key (`camera_count` and other keys give `None`); an
/// index too large for `u64` is `Some(u64::MAX)`.
fn camera_key_index(key: &str) -> Option<u64> {
    let digits = key.strip_prefix("camera_")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some(digits.parse().unwrap_or(u64::MAX))
}

pub(crate) fn parse_rig(text: &str, file: &str) -> Result<Rig, RigError> {
    let text = strip_opencv_syntax(text);
    check_yaml_events(&text, file)?;
    let docs = YamlLoader::load_from_str(&text).map_err(|e| syntax_error(file, &e))?;
    let Some(root) = docs.first() else {
        return Err(RigError::Syntax { file: file.to_owned(), message: "the file is empty".to_owned() });
    };
    let r = Reader { file };
    let Some(top) = root.as_hash() else {
        return Err(RigError::Syntax { file: file.to_owned(), message: "the top level must be a mapping".to_owned() });
    };
    let count_node = r.get(root, "", "camera_count")?;
    // The count is checked against the limit and against the camera keys actually present before
    // anything is sized from it.
    let count = count_node
        .as_i64()
        .and_then(|n| usize::try_from(n).ok())
        .filter(|n| (1..=MAX_CAMERAS).contains(n))
        .ok_or_else(|| {
            r.invalid(
                "camera_count",
                format!("expected an integer in 1..={MAX_CAMERAS}, found {}", describe(count_node)),
            )
        })?;
    let extra = top.keys().filter_map(Yaml::as_str).filter_map(camera_key_index).find(|&i| i >= count as u64);
    if let Some(i) = extra {
        let key = if i == u64::MAX { "camera_<huge number>".to_owned() } else { format!("camera_{i}") };
        return Err(r.invalid("camera_count", format!("is {count} but the file also has {key}")));
    }
    let mut cameras = Vec::new();
    for i in 0..count {
        let key = format!("camera_{i}");
        let node = r.get(root, "", &key)?;
        cameras.push(r.camera(node, i)?);
    }
    let world_frame = match &root["world_frame"] {
        Yaml::String(s) => WorldFrame::from_key(s),
        _ => WorldFrame::Other("unspecified".to_owned()),
    };
    let rig = Rig { cameras, world_frame };
    rig.validate(file)?;
    Ok(rig)
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
