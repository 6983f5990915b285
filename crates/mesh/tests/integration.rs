//! The mesh crate's tests: geometry, winding numbers, the PLY and OBJ readers on good files, and on
//! bad ones (hand-made, generated, and the committed corpus of bad files found so far).

use std::fs;

use hullcut_mesh::{MAX_LIST_LEN, MAX_VERTICES, MeshError, TriMesh, WindingTree};
use nalgebra::{Isometry3, Point2, Point3, Vector3};

fn unit_cube() -> TriMesh {
    TriMesh::cuboid_grid(Point3::origin(), Point3::new(1.0, 1.0, 1.0), [1, 1, 1])
}

#[test]
fn cube_topology_and_volume() {
    let m = unit_cube();
    assert_eq!(m.triangles.len(), 12);
    assert_eq!(m.vertices.len(), 8);
    assert!(m.is_closed());
    assert_eq!(m.orientation_conflicts(), 0);
    assert!((m.volume() - 1.0).abs() < 1e-12);
    assert!((m.area() - 6.0).abs() < 1e-12);
    let fine = TriMesh::cuboid_grid(Point3::new(-1.0, 0.0, 0.0), Point3::new(1.0, 3.0, 0.5), [4, 3, 2]);
    assert_eq!(fine.triangles.len(), 4 * (4 * 3 + 3 * 2 + 2 * 4));
    assert!(fine.is_closed());
    assert_eq!(fine.orientation_conflicts(), 0);
    assert!((fine.volume() - 3.0).abs() < 1e-12);
}

#[test]
fn winding_number_of_a_cube() {
    let m = unit_cube();
    let w = |p: [f64; 3]| m.winding_number(&Point3::from(p));
    assert!((w([0.5, 0.5, 0.5]) - 1.0).abs() < 1e-12);
    assert!((w([0.1, 0.9, 0.2]) - 1.0).abs() < 1e-12);
    assert!(w([1.5, 0.5, 0.5]).abs() < 1e-12);
    assert!(w([-3.0, 7.0, 2.0]).abs() < 1e-12);
    // On a face (exactly, and off the diagonal that splits the face into two triangles).
    assert!((w([0.5, 0.3, 0.0]) - 0.5).abs() < 1e-12);
    assert!((w([1.0, 0.2, 0.7]) - 0.5).abs() < 1e-12);
    // An open box (top removed) still reads about 1 deep inside.
    let mut open = m.clone();
    let top: Vec<_> =
        open.triangles.iter().copied().filter(|t| t.iter().all(|&i| open.vertices[i as usize].z == 1.0)).collect();
    open.triangles.retain(|t| !top.contains(t));
    assert_eq!(open.open_edges(), 4);
    let deep = open.winding_number(&Point3::new(0.5, 0.5, 0.1));
    assert!(deep > 0.8 && deep < 1.0, "{deep}");
}

#[test]
fn tree_matches_exact_sum() {
    let m = TriMesh::cuboid_grid(Point3::origin(), Point3::new(1.0, 2.0, 0.5), [10, 20, 5]);
    let tree = WindingTree::new(&m);
    assert_eq!(tree.len(), m.triangles.len());
    for (i, p) in [[0.5, 1.0, 0.25], [0.01, 0.01, 0.01], [1.2, 1.0, 0.25], [3.0, -2.0, 5.0], [0.999, 1.999, 0.499]]
        .iter()
        .enumerate()
    {
        let p = Point3::from(*p);
        let (a, b) = (m.winding_number(&p), tree.winding_number(&p));
        // The documented accuracy at the default far ratio.
        assert!((a - b).abs() < 6e-3, "point {i}: exact {a}, tree {b}");
        let fine = WindingTree::with_far_ratio(&m, 4.0).winding_number(&p);
        assert!((a - fine).abs() < 1e-3, "point {i}: exact {a}, tree at ratio 4: {fine}");
    }
}

#[test]
fn obj_forms() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("quad.obj");
    let text = "# a square and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\nvt 0 0\nvn 0 0 1\n\
                f 1/1/1 2/1/1 3/1/1 4/1/1\ng second\nv 0 0 1\nf -1 1//1 -4\nusemtl x\n";
    fs::write(&path, text).expect("write");
    let m = TriMesh::load(&path).expect("load");
    assert_eq!(m.vertices.len(), 5);
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [4, 0, 1]]);

    fs::write(&path, "v 0 0 0\nv 1 0 0\nf 1 2 3\n").expect("write");
    let e = TriMesh::load(&path).expect_err("index 3 of 2");
    assert!(matches!(e, MeshError::IndexOutOfRange { index: 3, vertices: 2, .. }), "{e}");
    assert!(e.to_string().contains("quad.obj") && e.to_string().contains("line 3"), "{e}");
    fs::write(&path, "v 0 0 zero\n").expect("write");
    let e = TriMesh::load(&path).expect_err("bad number");
    assert!(e.to_string().contains("line 1"), "{e}");
    fs::write(&path, "v 0 0 0\n").expect("write");
    assert!(matches!(TriMesh::load(&path), Err(MeshError::Empty { what: "triangles", .. })));
}

#[test]
fn ply_skips_other_properties_and_elements() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("extra.ply");
    let text = "ply\nformat ascii 1.0\ncomment x\nelement vertex 4\nproperty float confidence\n\
                property double x\nproperty float y\nproperty float z\nproperty list uchar float junk\n\
                element face 1\nproperty uchar flags\nproperty list uint8 int32 vertex_index\n\
                element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n\
                0.5 0 0 0 2 1.5 2.5\n0.5 1 0 0 0\n\n0.5 1 1 0 1 7\n0.5 0 1 0 0\n9 4 0 1 2 3\n0 1\n";
    fs::write(&path, text).expect("write");
    let m = TriMesh::load(&path).expect("load");
    assert_eq!(m.vertices[2], Point3::new(1.0, 1.0, 0.0));
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);

    // Binary big-endian with a float vertex, a short list count and an extra face property.
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                  property float z\nproperty uchar red\nelement face 1\nproperty list ushort uint vertex_indices\n\
                  property float quality\nend_header\n"
        .to_vec();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            b.extend(c.to_be_bytes());
        }
        b.push(255);
    }
    b.extend(3u16.to_be_bytes());
    for i in [0u32, 1, 2] {
        b.extend(i.to_be_bytes());
    }
    b.extend(1.0f32.to_be_bytes());
    fs::write(&path, &b).expect("write");
    let m = TriMesh::load(&path).expect("load");
    assert_eq!(m.vertices[1], Point3::new(1.0, 0.0, 0.0));
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    // Cut inside the face: truncated data names the element.
    fs::write(&path, &b[..b.len() - 6]).expect("write");
    let e = TriMesh::load(&path).expect_err("truncated");
    assert!(e.to_string().contains("extra.ply") && e.to_string().contains("face 0"), "{e}");
    // Cut before the face: Truncated.
    fs::write(&path, &b[..b.len() - 18]).expect("write");
    assert!(matches!(TriMesh::load(&path), Err(MeshError::Truncated { index: 0, count: 1, .. })));
}

#[test]
fn ply_header_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.ply");
    for (text, line) in [
        ("plx\n", 1),
        ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n", 5),
        ("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\n", 4),
        ("ply\nformat ascii 1.0\nelement vertex 1\n", 4),
    ] {
        fs::write(&path, text).expect("write");
        match TriMesh::load(&path) {
            Err(MeshError::Header { line: l, path: p, .. }) => {
                assert_eq!((l, p.as_path()), (line, path.as_path()), "{text}");
            }
            other => panic!("{text}: {other:?}"),
        }
    }
}

#[test]
fn primitives_are_closed_with_the_right_volume() {
    let cube = TriMesh::cuboid(Point3::new(0.0, 0.0, 0.0), Point3::new(0.1, 0.2, 0.3));
    assert!(cube.is_closed_oriented());
    assert!((cube.volume() - 0.006).abs() < 1e-15);

    let r = 0.01;
    let cap = TriMesh::capsule(Point3::new(0.1, 0.0, 0.0), Point3::new(0.1, 0.05, 0.02), r, 48);
    assert!(cap.is_closed_oriented());
    // A polygonal capsule is inscribed: within 1% of the smooth one at 48 segments.
    let exact = std::f64::consts::PI * r * r * (0.05f64.hypot(0.02) + 4.0 / 3.0 * r);
    assert!((cap.volume() - exact).abs() < 0.01 * exact, "{} vs {exact}", cap.volume());

    let radii = Vector3::new(0.03, 0.02, 0.01);
    let e = TriMesh::ellipsoid(&Isometry3::translation(0.0, 0.0, 0.5), radii, 64);
    assert!(e.is_closed_oriented());
    let exact = 4.0 / 3.0 * std::f64::consts::PI * radii.product();
    assert!((e.volume() - exact).abs() < 0.01 * exact);

    let tri = [Point2::new(0.0, 0.0), Point2::new(1.0, 0.0), Point2::new(0.0, 1.0)];
    let p = TriMesh::convex_prism(&tri, -0.5, 0.5);
    assert!(p.is_closed_oriented());
    assert!((p.volume() - 0.5).abs() < 1e-12);

    // A flipped face breaks the oriented check but not the manifold one.
    let mut flipped = cube.clone();
    flipped.triangles[0].swap(1, 2);
    assert!(flipped.is_closed() && !flipped.is_closed_oriented());
}

#[test]
fn ply_round_trips_exactly_in_both_encodings() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut m = TriMesh::ellipsoid(&Isometry3::translation(0.1, -0.2, 0.3), Vector3::new(0.3, 0.2, 0.1), 16);
    m.vertices[0].x = 0.1 + 0.2; // not representable in few digits
    for (name, ascii) in [("b.ply", false), ("a.ply", true)] {
        let path = dir.path().join(name);
        if ascii { m.write_ply_ascii(&path) } else { m.write_ply(&path) }.expect("write");
        assert_eq!(TriMesh::load(&path).expect("load"), m, "{name}");
    }
    let bytes = fs::read(dir.path().join("b.ply")).expect("read");
    assert_eq!(TriMesh::from_ply_bytes(&bytes, "memory.ply").expect("from bytes"), m);
}

/// A binary little-endian PLY with the given header lines after `format` and the given body.
fn binary_ply(header: &str, body: &[u8]) -> Vec<u8> {
    let mut b = format!("ply\nformat binary_little_endian 1.0\n{header}end_header\n").into_bytes();
    b.extend_from_slice(body);
    b
}

fn tetra_body() -> Vec<u8> {
    let mut b = Vec::new();
    for v in [[0.0f64, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        for c in v {
            b.extend(c.to_le_bytes());
        }
    }
    for t in [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        b.push(3);
        for i in t {
            b.extend(i.to_le_bytes());
        }
    }
    b
}

const TETRA_HEADER: &str = "element vertex 4\nproperty double x\nproperty double y\nproperty double z\n\
                            element face 4\nproperty list uchar uint vertex_indices\n";

#[test]
fn ply_counts_are_checked_against_the_data_before_anything_is_allocated() {
    let ok = TriMesh::from_ply_bytes(&binary_ply(TETRA_HEADER, &tetra_body()), "t.ply").expect("tetra");
    assert!(ok.is_closed_oriented() && (ok.volume() - 1.0 / 6.0).abs() < 1e-15);

    // Counts far beyond the data: refused from the header, naming the element and the limit.
    for count in ["18446744073709551615", "9223372036854775807", "1000000000"] {
        let header = TETRA_HEADER.replace("element vertex 4", &format!("element vertex {count}"));
        let e = TriMesh::from_ply_bytes(&binary_ply(&header, &tetra_body()), "huge.ply").expect_err(count);
        assert!(matches!(e, MeshError::Header { .. }), "{count}: {e}");
        assert!(e.to_string().contains("huge.ply") && e.to_string().contains("vertex"), "{e}");
    }
    let header = TETRA_HEADER.replace("element vertex 4", &format!("element vertex {}", MAX_VERTICES + 1));
    let e = TriMesh::from_ply_bytes(&binary_ply(&header, &tetra_body()), "limit.ply").expect_err("limit");
    assert!(e.to_string().contains("limit"), "{e}");

    // An element without properties and a count of 2^63 takes no data: skipped, not looped over.
    for format in ["binary_little_endian", "ascii"] {
        let header = format!("element nothing 9223372036854775808\n{TETRA_HEADER}");
        let mut bytes = binary_ply(&header, &tetra_body());
        if format == "ascii" {
            let text = format!(
                "ply\nformat ascii 1.0\n{header}end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
            );
            bytes = text.into_bytes();
        }
        let m = TriMesh::from_ply_bytes(&bytes, "empty-element.ply").expect(format);
        assert_eq!(m.triangles.len(), 4, "{format}");
    }

    // A list longer than the limit.
    let face0 = 4 * 24;
    let header = TETRA_HEADER.replace("list uchar uint", "list uint uint");
    let mut long = Vec::new();
    long.extend_from_slice(&tetra_body()[..face0]);
    long.extend(u32::MAX.to_le_bytes());
    long.extend(vec![0u8; 64]);
    let e = TriMesh::from_ply_bytes(&binary_ply(&header, &long), "long-list.ply").expect_err("long list");
    assert!(e.to_string().contains(&MAX_LIST_LEN.to_string()), "{e}");
}

#[test]
fn ply_refuses_non_finite_vertices_and_bad_indices() {
    let mut body = tetra_body();
    body[8..16].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = TriMesh::from_ply_bytes(&binary_ply(TETRA_HEADER, &body), "nan.ply").expect_err("nan");
    assert!(e.to_string().contains("not finite") && e.to_string().contains("nan.ply"), "{e}");

    let mut body = tetra_body();
    body[4 * 24 + 1..4 * 24 + 5].copy_from_slice(&7u32.to_le_bytes());
    let e = TriMesh::from_ply_bytes(&binary_ply(TETRA_HEADER, &body), "index.ply").expect_err("index");
    assert!(matches!(e, MeshError::IndexOutOfRange { index: 7, vertices: 4, .. }), "{e}");

    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n";
    let e = TriMesh::from_ply_bytes(text.as_bytes(), "inf.ply").expect_err("inf");
    assert!(e.to_string().contains("line 11"), "{e}");
    let text = text.replace("inf", "0").replace("3 0 1 2", "3 0 1 -2");
    let e = TriMesh::from_ply_bytes(text.as_bytes(), "negative.ply").expect_err("negative index");
    assert!(e.to_string().contains("out of range"), "{e}");
}

#[test]
fn messages_shorten_long_values() {
    let long = "x".repeat(100_000);
    let text = format!("ply\nformat ascii 1.0\nelement {long} 1\nend_header\n");
    let e = TriMesh::from_ply_bytes(text.as_bytes(), "long.ply").expect_err("no vertex element");
    let text = format!("ply\nformat {long} 1.0\nend_header\n");
    let e2 = TriMesh::from_ply_bytes(text.as_bytes(), "long.ply").expect_err("bad format");
    for e in [e, e2] {
        assert!(e.to_string().len() < 300, "{} characters", e.to_string().len());
    }
}

/// Every file in tests/corpus: a bad input found so far, each refused with an error naming it.
#[test]
fn the_corpus_of_bad_files_is_refused() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut seen = 0;
    let mut entries: Vec<_> = fs::read_dir(&dir).expect("corpus").map(|e| e.expect("entry").path()).collect();
    entries.sort();
    for path in entries {
        let e = TriMesh::load(&path).expect_err(&path.display().to_string());
        let name = path.file_name().and_then(|n| n.to_str()).expect("name");
        assert!(e.to_string().contains(name), "{name}: {e}");
        seen += 1;
    }
    assert!(seen >= 8, "the corpus holds {seen} files");
}

mod generated {
    use super::*;
    use proptest::prelude::*;

    fn valid_files() -> Vec<Vec<u8>> {
        let mut ascii = Vec::new();
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("a.ply");
        TriMesh::cuboid(Point3::origin(), Point3::new(1.0, 2.0, 3.0)).write_ply_ascii(&path).expect("write");
        ascii.extend(fs::read(&path).expect("read"));
        vec![binary_ply(TETRA_HEADER, &tetra_body()), ascii]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Arbitrary bytes after a PLY header start: an error or a mesh, never a panic or a hang.
        #[test]
        fn arbitrary_bytes_never_panic(body in proptest::collection::vec(any::<u8>(), 0..400), ascii in any::<bool>()) {
            let mut bytes = if ascii { b"ply\nformat ascii 1.0\n".to_vec() } else { b"ply\n".to_vec() };
            bytes.extend(body);
            if let Ok(m) = TriMesh::from_ply_bytes(&bytes, "arbitrary.ply") {
                prop_assert!(m.validate().is_ok());
            }
        }

        /// Valid files with bytes flipped, inserted or removed: the result, if any, is a valid mesh.
        #[test]
        fn mutated_files_never_panic(
            which in 0usize..2,
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..6),
        ) {
            let mut bytes = valid_files()[which].clone();
            for (at, byte, kind) in edits {
                if bytes.is_empty() { break; }
                let i = at.index(bytes.len());
                match kind {
                    0 => bytes[i] = byte,
                    1 => bytes.insert(i, byte),
                    _ => { bytes.remove(i); }
                }
            }
            if let Ok(m) = TriMesh::from_ply_bytes(&bytes, "mutated.ply") {
                prop_assert!(m.validate().is_ok());
            }
        }

        /// Header counts of any size over a short body: refused or read, never allocated for.
        #[test]
        fn any_declared_count_is_safe(count in any::<u64>(), element in 0usize..3) {
            let name = ["vertex", "face", "extra"][element];
            let header = if name == "extra" {
                format!("element extra {count}\nproperty uchar a\n{TETRA_HEADER}")
            } else {
                TETRA_HEADER.replace(&format!("element {name} 4"), &format!("element {name} {count}"))
            };
            let _ = TriMesh::from_ply_bytes(&binary_ply(&header, &tetra_body()), "count.ply");
        }
    }
}
