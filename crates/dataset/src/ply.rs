//! PLY triangle meshes: [`read_ply`] (ASCII and binary, either byte order) and [`write_ply`] (binary
//! little endian, double-precision vertices, so a round trip is bit-exact).

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use nalgebra::Point3;

use crate::error::{DatasetError, Result};
use crate::types::Mesh;

impl Mesh {
    /// Whether the mesh is closed and consistently oriented: every edge is used by exactly two
    /// triangles, once in each direction. A triangle with a repeated vertex makes it not closed;
    /// an empty mesh is not closed.
    pub fn is_closed(&self) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let mut directed: HashMap<(u32, u32), u32> = HashMap::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                return false;
            }
            for k in 0..3 {
                let count = directed.entry((t[k], t[(k + 1) % 3])).or_insert(0);
                *count += 1;
                if *count > 1 {
                    return false;
                }
            }
        }
        directed.keys().all(|&(a, b)| directed.contains_key(&(b, a)))
    }

    /// Checks that every triangle index refers to a vertex and every vertex is finite; the message
    /// names the first offending triangle or vertex.
    pub(crate) fn check(&self) -> std::result::Result<(), String> {
        if let Some(i) = self.vertices.iter().position(|v| !v.coords.iter().all(|c| c.is_finite())) {
            return Err(format!("vertex {i} is not finite"));
        }
        let n = self.vertices.len();
        if let Some(i) = self.triangles.iter().position(|t| t.iter().any(|&v| v as usize >= n)) {
            return Err(format!("triangle {i} refers to a vertex beyond the {n} vertices"));
        }
        Ok(())
    }
}

/// Scalar types of PLY properties.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }
}

#[derive(Debug, Clone)]
enum Property {
    Scalar { name: String, ty: Scalar },
    List { name: String, count: Scalar, item: Scalar },
}

impl Property {
    fn name(&self) -> &str {
        match self {
            Self::Scalar { name, .. } | Self::List { name, .. } => name,
        }
    }
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLittle,
    BinaryBig,
}

/// Reads the values of a PLY body, ASCII or binary.
trait Values {
    /// The next scalar as f64 (integers are exact up to 2^53, which covers every PLY integer type).
    fn next(&mut self, ty: Scalar) -> std::result::Result<f64, String>;
}

struct AsciiValues<'a> {
    tokens: std::str::SplitAsciiWhitespace<'a>,
}

impl Values for AsciiValues<'_> {
    fn next(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        let token = self.tokens.next().ok_or_else(|| "the file ends early".to_owned())?;
        if ty.is_integer() {
            token.parse::<i64>().map(|v| v as f64).map_err(|_| format!("`{token}` is not an integer"))
        } else {
            token.parse::<f64>().map_err(|_| format!("`{token}` is not a number"))
        }
    }
}

struct BinaryValues<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl Values for BinaryValues<'_> {
    fn next(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        let n = ty.size();
        let Some(raw) = self.bytes.get(self.pos..self.pos + n) else {
            return Err(format!("the file ends early (at byte {} of the body)", self.pos));
        };
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(raw);
        if self.big_endian {
            b[..n].reverse();
        }
        Ok(match ty {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }
}

/// Parses the header; returns the format, the elements and the byte offset of the body.
fn parse_header(bytes: &[u8]) -> std::result::Result<(Format, Vec<Element>, usize), String> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err("the header has no `end_header` line".to_owned());
        };
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        line_no += 1;
        let line = std::str::from_utf8(raw).map_err(|_| format!("header line {line_no} is not text"))?.trim();
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        let bad = || format!("header line {line_no}: cannot read `{line}`");
        if line_no == 1 {
            if line != "ply" {
                return Err("not a PLY file (the first line is not `ply`)".to_owned());
            }
            continue;
        }
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                format = Some(match words.get(1..) {
                    Some(["ascii", "1.0"]) => Format::Ascii,
                    Some(["binary_little_endian", "1.0"]) => Format::BinaryLittle,
                    Some(["binary_big_endian", "1.0"]) => Format::BinaryBig,
                    _ => return Err(format!("header line {line_no}: unsupported format `{line}`")),
                });
            }
            Some("element") => {
                let [_, name, count] = words[..] else { return Err(bad()) };
                let count = count.parse::<usize>().map_err(|_| bad())?;
                elements.push(Element { name: name.to_owned(), count, properties: Vec::new() });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(format!("header line {line_no}: property before any element"));
                };
                let property = match words[..] {
                    [_, "list", count, item, name] => {
                        let (Some(count), Some(item)) = (Scalar::parse(count), Scalar::parse(item)) else {
                            return Err(bad());
                        };
                        if !count.is_integer() {
                            return Err(format!("header line {line_no}: a list count must be an integer type"));
                        }
                        Property::List { name: name.to_owned(), count, item }
                    }
                    [_, ty, name] => {
                        let Some(ty) = Scalar::parse(ty) else { return Err(bad()) };
                        Property::Scalar { name: name.to_owned(), ty }
                    }
                    _ => return Err(bad()),
                };
                element.properties.push(property);
            }
            Some("end_header") => break,
            Some(_) => return Err(bad()),
        }
    }
    let format = format.ok_or_else(|| "the header has no `format` line".to_owned())?;
    Ok((format, elements, pos))
}

/// Reads the body into a mesh.
fn read_body(elements: &[Element], values: &mut dyn Values) -> std::result::Result<Mesh, String> {
    let mut mesh = Mesh::default();
    let mut have_vertices = false;
    for element in elements {
        let props = &element.properties;
        // Never trust a header's count for an allocation: the body may be shorter.
        let capacity = element.count.min(1 << 20);
        match element.name.as_str() {
            "vertex" => {
                let find = |axis: &str| -> std::result::Result<usize, String> {
                    props
                        .iter()
                        .position(|p| matches!(p, Property::Scalar { name, .. } if name == axis))
                        .ok_or_else(|| format!("the vertex element has no scalar `{axis}` property"))
                };
                let axes = [find("x")?, find("y")?, find("z")?];
                have_vertices = true;
                mesh.vertices.reserve(capacity);
                let mut row = vec![0.0; props.len()];
                for i in 0..element.count {
                    read_row(props, values, |k, v| row[k] = v).map_err(|e| format!("vertex {i}: {e}"))?;
                    let p = Point3::new(row[axes[0]], row[axes[1]], row[axes[2]]);
                    if !p.coords.iter().all(|c| c.is_finite()) {
                        return Err(format!("vertex {i} is not finite"));
                    }
                    mesh.vertices.push(p);
                }
            }
            "face" => {
                let index = props
                    .iter()
                    .position(|p| {
                        matches!(p, Property::List { name, .. } if name == "vertex_indices" || name == "vertex_index")
                    })
                    .ok_or_else(|| "the face element has no `vertex_indices` list".to_owned())?;
                if let Property::List { item, .. } = &props[index]
                    && !item.is_integer()
                {
                    return Err("face vertex indices must have an integer type".to_owned());
                }
                mesh.triangles.reserve(capacity);
                let mut polygon: Vec<f64> = Vec::new();
                for i in 0..element.count {
                    polygon.clear();
                    read_row_lists(props, values, index, &mut polygon).map_err(|e| format!("face {i}: {e}"))?;
                    if polygon.len() < 3 {
                        return Err(format!("face {i} has {} vertices; at least 3 are needed", polygon.len()));
                    }
                    let mut idx = Vec::with_capacity(polygon.len());
                    for &v in &polygon {
                        if v < 0.0 || v > f64::from(u32::MAX) {
                            return Err(format!("face {i} has the invalid vertex index {v}"));
                        }
                        if have_vertices && v as usize >= mesh.vertices.len() {
                            return Err(format!(
                                "face {i} refers to vertex {v}, but there are {} vertices",
                                mesh.vertices.len()
                            ));
                        }
                        idx.push(v as u32);
                    }
                    for k in 1..idx.len() - 1 {
                        mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                    }
                }
            }
            _ => {
                for i in 0..element.count {
                    read_row(props, values, |_, _| {}).map_err(|e| format!("{} {i}: {e}", element.name))?;
                }
            }
        }
    }
    if !have_vertices {
        return Err("the file has no vertex element".to_owned());
    }
    mesh.check()?;
    Ok(mesh)
}

/// Reads one row; scalar property `k` is passed to `store(k, value)`, lists are skipped.
fn read_row(
    props: &[Property],
    values: &mut dyn Values,
    mut store: impl FnMut(usize, f64),
) -> std::result::Result<(), String> {
    for (k, p) in props.iter().enumerate() {
        match p {
            Property::Scalar { ty, .. } => store(k, values.next(*ty)?),
            Property::List { count, item, .. } => {
                let n = list_len(values.next(*count)?, p)?;
                for _ in 0..n {
                    values.next(*item)?;
                }
            }
        }
    }
    Ok(())
}

/// Reads one row, keeping the items of list property `keep` in `out`.
fn read_row_lists(
    props: &[Property],
    values: &mut dyn Values,
    keep: usize,
    out: &mut Vec<f64>,
) -> std::result::Result<(), String> {
    for (k, p) in props.iter().enumerate() {
        match p {
            Property::Scalar { ty, .. } => {
                values.next(*ty)?;
            }
            Property::List { count, item, .. } => {
                let n = list_len(values.next(*count)?, p)?;
                for _ in 0..n {
                    let v = values.next(*item)?;
                    if k == keep {
                        out.push(v);
                    }
                }
            }
        }
    }
    Ok(())
}

fn list_len(n: f64, p: &Property) -> std::result::Result<usize, String> {
    if n < 0.0 {
        return Err(format!("list `{}` has a negative length", p.name()));
    }
    Ok(n as usize)
}

/// Reads a PLY triangle mesh: ASCII, binary little endian or binary big endian; vertex `x`, `y`, `z`
/// of any numeric type (other vertex properties and other elements are skipped); faces as a
/// `vertex_indices` (or `vertex_index`) list of any integer types, polygons fan-triangulated.
///
/// Errors name the file and, where known, the header line, vertex or face.
pub fn read_ply(path: impl AsRef<Path>) -> Result<Mesh> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(DatasetError::io(path))?;
    let parse = |message: String| DatasetError::Parse { path: path.to_owned(), message };
    let (format, elements, body) = parse_header(&bytes).map_err(parse)?;
    let rest = &bytes[body..];
    let mesh = match format {
        Format::Ascii => {
            let text = std::str::from_utf8(rest).map_err(|_| parse("the ASCII body is not text".to_owned()))?;
            read_body(&elements, &mut AsciiValues { tokens: text.split_ascii_whitespace() })
        }
        Format::BinaryLittle | Format::BinaryBig => {
            read_body(&elements, &mut BinaryValues { bytes: rest, pos: 0, big_endian: format == Format::BinaryBig })
        }
    };
    mesh.map_err(parse)
}

/// Writes a triangle mesh as binary little-endian PLY with `double` vertices and `uint` indices
/// (so [`read_ply`] returns exactly the same mesh).
pub fn write_ply(path: impl AsRef<Path>, mesh: &Mesh) -> Result<()> {
    let path = path.as_ref();
    let mut out = Vec::with_capacity(200 + mesh.vertices.len() * 24 + mesh.triangles.len() * 13);
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by hullcut-dataset\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    out.extend_from_slice(header.as_bytes());
    for v in &mesh.vertices {
        for c in v.coords.iter() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    let mut file = std::fs::File::create(path).map_err(DatasetError::io(path))?;
    file.write_all(&out).map_err(DatasetError::io(path))
}
