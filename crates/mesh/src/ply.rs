//! PLY triangle meshes: the workspace's one reader (ASCII and binary, either byte order) and writer
//! (binary little endian or ASCII, double-precision vertices, so a round trip is exact).
//!
//! Nothing in the header is trusted for an allocation or a loop: an element's row count is checked
//! against the bytes that follow the header (a row takes at least one byte per value in binary, and
//! a line of its own in ASCII) and against [`MAX_VERTICES`] and [`MAX_TRIANGLES`]; a list's length
//! against [`MAX_LIST_LEN`]; an element without properties takes no data and is skipped without
//! visiting its rows. Vertices must be finite and face indices must name a vertex.

use std::borrow::Cow;
use std::io::{self, Write};
use std::path::Path;

use nalgebra::Point3;

use crate::{MeshError, TriMesh};

/// Most vertices a mesh file may declare (2^26, about 67 million: 1.6 GB of `f64` coordinates).
pub const MAX_VERTICES: usize = 1 << 26;
/// Most triangles a mesh file may hold after fan triangulation (2^27, about 134 million).
pub const MAX_TRIANGLES: usize = 1 << 27;
/// Longest list property (a polygon's vertex count) a PLY row may declare.
pub const MAX_LIST_LEN: usize = 1 << 16;

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
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
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

    /// Decodes one value from exactly `self.size()` bytes.
    fn decode(self, b: &[u8], little: bool) -> f64 {
        let mut a = [0u8; 8];
        a[..b.len().min(8)].copy_from_slice(&b[..b.len().min(8)]);
        if !little {
            a[..self.size()].reverse();
        }
        match self {
            Self::I8 => f64::from(a[0] as i8),
            Self::U8 => f64::from(a[0]),
            Self::I16 => f64::from(i16::from_le_bytes([a[0], a[1]])),
            Self::U16 => f64::from(u16::from_le_bytes([a[0], a[1]])),
            Self::I32 => f64::from(i32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Self::U32 => f64::from(u32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Self::F32 => f64::from(f32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Self::F64 => f64::from_le_bytes(a),
        }
    }
}

#[derive(Debug)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

impl Element {
    /// The fewest bytes one binary row takes: every scalar and every list's count.
    fn min_binary_row(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(s) | PropKind::List { count: s, .. } => s.size(),
            })
            .sum()
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Binary { little: bool },
}

/// The parsed header.
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// 1-based number of the `end_header` line.
    lines: usize,
    /// Byte offset of the body.
    body: usize,
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, MeshError> {
    let header_err = |line: usize, message: String| MeshError::Header { path: path.to_owned(), line, message };
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(header_err(line_no + 1, "no `end_header` line".into()));
        };
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        line_no += 1;
        let line = String::from_utf8_lossy(raw);
        let words: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if words != ["ply"] {
                return Err(header_err(1, "not a PLY file (first line is not `ply`)".into()));
            }
            continue;
        }
        match words.as_slice() {
            [] => {}
            ["end_header"] => break,
            ["comment" | "obj_info", ..] => {}
            ["format", f, version] => {
                if *version != "1.0" {
                    return Err(header_err(
                        line_no,
                        format!("unsupported format version `{}` (1.0 is read)", crate::shorten(version)),
                    ));
                }
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Binary { little: true },
                    "binary_big_endian" => Format::Binary { little: false },
                    other => return Err(header_err(line_no, format!("unknown format `{}`", crate::shorten(other)))),
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| {
                    header_err(
                        line_no,
                        format!("element `{}` has a bad count `{}`", crate::shorten(name), crate::shorten(count)),
                    )
                })?;
                elements.push(Element { name: (*name).to_owned(), count, props: Vec::new() });
            }
            ["property", rest @ ..] => {
                let Some(element) = elements.last_mut() else {
                    return Err(header_err(line_no, "property before any element".into()));
                };
                let scalar = |name: &str| {
                    Scalar::parse(name)
                        .ok_or_else(|| header_err(line_no, format!("unknown property type `{}`", crate::shorten(name))))
                };
                let prop = match rest {
                    ["list", count, item, name] => {
                        let count = scalar(count)?;
                        if !count.is_integer() {
                            return Err(header_err(line_no, "list count type must be an integer".into()));
                        }
                        Property { name: (*name).to_owned(), kind: PropKind::List { count, item: scalar(item)? } }
                    }
                    [ty, name] => Property { name: (*name).to_owned(), kind: PropKind::Scalar(scalar(ty)?) },
                    _ => {
                        return Err(header_err(
                            line_no,
                            format!("malformed property line `{}`", crate::shorten(line.trim())),
                        ));
                    }
                };
                element.props.push(prop);
            }
            _ => {
                return Err(header_err(line_no, format!("unexpected header line `{}`", crate::shorten(line.trim()))));
            }
        }
    }
    let Some(format) = format else {
        return Err(header_err(line_no, "no `format` line".into()));
    };
    Ok(Header { format, elements, lines: line_no, body: pos })
}

/// Checks every element's declared row count against the data that follows the header and the
/// documented limits, before anything is allocated or visited.
fn check_counts(header: &Header, body_len: usize, path: &Path) -> Result<(), MeshError> {
    let header_err = |message: String| MeshError::Header { path: path.to_owned(), line: header.lines, message };
    for e in &header.elements {
        if e.props.is_empty() {
            continue;
        }
        let limit = match e.name.as_str() {
            "vertex" => MAX_VERTICES,
            "face" => MAX_TRIANGLES,
            _ => usize::MAX,
        };
        if e.count > limit {
            return Err(header_err(format!(
                "element `{}` declares {} rows, more than the limit of {limit}",
                crate::shorten(&e.name),
                e.count
            )));
        }
        // A binary row takes at least its scalars and list counts; an ASCII row a non-blank line (a
        // character and a line break, but for the last line).
        let (per_row, what) = match header.format {
            Format::Binary { .. } => (e.min_binary_row(), "bytes"),
            Format::Ascii => (2, "bytes (a line each)"),
        };
        let needed = e.count.saturating_mul(per_row).saturating_sub(1);
        if needed > body_len {
            return Err(header_err(format!(
                "element `{}` declares {} rows of at least {per_row} {what}, but only {body_len} bytes follow the header",
                crate::shorten(&e.name),
                e.count
            )));
        }
    }
    Ok(())
}

/// Parses a PLY file's bytes; `path` is for messages.
pub(crate) fn parse_ply(bytes: &[u8], path: &Path) -> Result<TriMesh, MeshError> {
    let header = parse_header(bytes, path)?;
    let header_err = |message: String| MeshError::Header { path: path.to_owned(), line: header.lines, message };
    let data = &bytes[header.body..];
    check_counts(&header, data.len(), path)?;

    // Which properties hold what.
    let mut xyz_at = None;
    let mut faces_at = None;
    for (ei, e) in header.elements.iter().enumerate() {
        if e.name == "vertex" {
            let find = |n: &str| e.props.iter().position(|p| p.name == n && matches!(p.kind, PropKind::Scalar(_)));
            let mut at = [0; 3];
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                at[k] = find(axis)
                    .ok_or_else(|| header_err(format!("element `vertex` has no scalar `{axis}` property")))?;
            }
            xyz_at = Some((ei, at));
        } else if e.name == "face" {
            let Some(p) = e.props.iter().position(|p| {
                matches!(p.kind, PropKind::List { item, .. } if item.is_integer())
                    && (p.name == "vertex_indices" || p.name == "vertex_index")
            }) else {
                return Err(header_err("element `face` lacks an integer list `vertex_indices`".into()));
            };
            faces_at = Some((ei, p));
        }
    }
    let Some((vertex_element, xyz)) = xyz_at else {
        return Err(header_err("no `vertex` element".into()));
    };

    let mut vertices = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    // The face element may come before the vertices: indices are checked once all are read.
    let mut largest_index: Option<(u32, usize)> = None;
    let mut reader = match header.format {
        Format::Ascii => DataReader::Ascii { text: String::from_utf8_lossy(data), offset: 0, line: header.lines },
        Format::Binary { little } => DataReader::Binary { data, offset: 0, little },
    };
    let mut values: Vec<f64> = Vec::new();
    let mut polygon: Vec<u32> = Vec::new();
    for (ei, e) in header.elements.iter().enumerate() {
        if e.props.is_empty() {
            continue;
        }
        // The counts were checked against the data; still, grow from a modest start.
        let start = e.count.min(1 << 20);
        if ei == vertex_element {
            vertices.reserve(start);
        } else if Some(ei) == faces_at.map(|f| f.0) {
            triangles.reserve(start);
        }
        for index in 0..e.count {
            values.clear();
            polygon.clear();
            let at_err = |reader: &DataReader, message: String| MeshError::Parse {
                path: path.to_owned(),
                at: reader.location(&e.name, index),
                message,
            };
            reader.begin().ok_or_else(|| MeshError::Truncated {
                path: path.to_owned(),
                element: e.name.clone(),
                index,
                count: e.count,
            })?;
            for (pi, p) in e.props.iter().enumerate() {
                let wants_list = Some((ei, pi)) == faces_at;
                match p.kind {
                    PropKind::Scalar(s) => {
                        let v = reader.value(s).map_err(|m| at_err(&reader, m))?;
                        values.push(v);
                    }
                    PropKind::List { count, item } => {
                        let n = reader.value(count).map_err(|m| at_err(&reader, m))?;
                        if !(0.0..=MAX_LIST_LEN as f64).contains(&n) {
                            return Err(at_err(
                                &reader,
                                format!(
                                    "list `{}` has length {n}, outside 0..={MAX_LIST_LEN}",
                                    crate::shorten(&p.name)
                                ),
                            ));
                        }
                        for _ in 0..n as usize {
                            let v = reader.value(item).map_err(|m| at_err(&reader, m))?;
                            if wants_list {
                                if !(0.0..=f64::from(u32::MAX)).contains(&v) {
                                    return Err(at_err(&reader, format!("vertex index {v} is out of range")));
                                }
                                polygon.push(v as u32);
                            }
                        }
                        values.push(f64::NAN);
                    }
                }
            }
            reader.end().map_err(|m| at_err(&reader, m))?;
            if ei == vertex_element {
                let p = Point3::new(values[xyz[0]], values[xyz[1]], values[xyz[2]]);
                if !p.coords.iter().all(|c| c.is_finite()) {
                    return Err(at_err(&reader, format!("vertex {index} is not finite")));
                }
                vertices.push(p);
            } else if Some(ei) == faces_at.map(|f| f.0) {
                if polygon.len() < 3 {
                    return Err(at_err(
                        &reader,
                        format!("face {index} has {} vertices; a face needs at least 3", polygon.len()),
                    ));
                }
                if let Some(&m) = polygon.iter().max()
                    && largest_index.is_none_or(|(l, _)| m > l)
                {
                    largest_index = Some((m, index));
                }
                fan(polygon.iter().copied(), &mut triangles);
                if triangles.len() > MAX_TRIANGLES {
                    return Err(at_err(&reader, format!("more than {MAX_TRIANGLES} triangles")));
                }
            }
        }
    }
    if let Some((index, face)) = largest_index
        && index as usize >= vertices.len()
    {
        return Err(MeshError::IndexOutOfRange {
            path: path.to_owned(),
            at: format!("face {face}"),
            index: i64::from(index),
            vertices: vertices.len(),
        });
    }
    Ok(TriMesh::new(vertices, triangles))
}

/// Splits the polygon `face` into a fan of triangles around its first vertex.
pub(crate) fn fan(face: impl Iterator<Item = u32>, triangles: &mut Vec<[u32; 3]>) {
    let mut first = None;
    let mut prev = None;
    for v in face {
        match (first, prev) {
            (None, _) => first = Some(v),
            (Some(_), None) => prev = Some(v),
            (Some(f), Some(p)) => {
                triangles.push([f, p, v]);
                prev = Some(v);
            }
        }
    }
}

/// Reads the element data of a PLY file, ASCII (one element per line) or binary.
enum DataReader<'a> {
    Ascii { text: Cow<'a, str>, offset: usize, line: usize },
    Binary { data: &'a [u8], offset: usize, little: bool },
}

impl DataReader<'_> {
    fn location(&self, element: &str, index: usize) -> String {
        match self {
            Self::Ascii { line, .. } => format!("line {line} ({} {index})", crate::shorten(element)),
            Self::Binary { .. } => format!("{} {index}", crate::shorten(element)),
        }
    }

    /// Starts an element: for ASCII, moves to the next non-blank line. `None` at the end of the data.
    fn begin(&mut self) -> Option<()> {
        match self {
            Self::Ascii { text, offset, line } => loop {
                if *offset >= text.len() {
                    return None;
                }
                let rest = &text[*offset..];
                let len = rest.find('\n').unwrap_or(rest.len());
                *line += 1;
                if !rest[..len].trim().is_empty() {
                    return Some(());
                }
                *offset += (len + 1).min(rest.len());
            },
            Self::Binary { data, offset, .. } => (*offset < data.len()).then_some(()),
        }
    }

    /// The next value, as `f64`.
    fn value(&mut self, s: Scalar) -> Result<f64, String> {
        match self {
            Self::Ascii { text, offset, .. } => {
                let rest = &text[*offset..];
                let line_end = rest.find('\n').unwrap_or(rest.len());
                let trimmed = rest[..line_end].trim_start_matches([' ', '\t', '\r']);
                let skipped = line_end - trimmed.len();
                let word_len = trimmed.find([' ', '\t', '\r']).unwrap_or(trimmed.len());
                if word_len == 0 {
                    return Err("too few values on the line".into());
                }
                let word = &trimmed[..word_len];
                let v: f64 = word.parse().map_err(|_| format!("`{}` is not a number", crate::shorten(word)))?;
                if s.is_integer() && v.fract() != 0.0 {
                    return Err(format!("`{}` is not an integer", crate::shorten(word)));
                }
                *offset += skipped + word_len;
                Ok(v)
            }
            Self::Binary { data, offset, little } => {
                let n = s.size();
                let Some(raw) = data.get(*offset..*offset + n) else {
                    return Err("data ends inside the element".into());
                };
                let v = s.decode(raw, *little);
                *offset += n;
                Ok(v)
            }
        }
    }

    /// Ends an element: for ASCII, checks nothing but whitespace remains on the line.
    fn end(&mut self) -> Result<(), String> {
        match self {
            Self::Ascii { text, offset, .. } => {
                let rest = &text[*offset..];
                let line_end = rest.find('\n').unwrap_or(rest.len());
                if !rest[..line_end].trim().is_empty() {
                    return Err(format!("unexpected extra values `{}`", crate::shorten(rest[..line_end].trim())));
                }
                *offset += (line_end + 1).min(rest.len());
                Ok(())
            }
            Self::Binary { .. } => Ok(()),
        }
    }
}

/// Writes `mesh` as PLY to `w`: vertices as `double x y z` (exact round trip), faces as
/// `list uchar uint vertex_indices`; binary little endian, or ASCII with the shortest representation
/// of each coordinate that reads back to the same `f64`.
pub(crate) fn write_ply(mesh: &TriMesh, w: &mut impl Write, ascii: bool) -> io::Result<()> {
    let format = if ascii { "ascii" } else { "binary_little_endian" };
    write!(
        w,
        "ply\nformat {format} 1.0\ncomment written by hullcut\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nelement face {}\nproperty list uchar uint vertex_indices\n\
         end_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    if ascii {
        for v in &mesh.vertices {
            writeln!(w, "{} {} {}", v.x, v.y, v.z)?;
        }
        for t in &mesh.triangles {
            writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
        }
    } else {
        for v in &mesh.vertices {
            for c in [v.x, v.y, v.z] {
                w.write_all(&c.to_le_bytes())?;
            }
        }
        for t in &mesh.triangles {
            w.write_all(&[3])?;
            for i in t {
                w.write_all(&i.to_le_bytes())?;
            }
        }
    }
    w.flush()
}
