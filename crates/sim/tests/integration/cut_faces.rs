//! Cut faces placed exactly: a planar cut through a box and through a mesh tissue leaves faces on
//! the true plane, pieces whose volumes sum to the body's, watertight surfaces with consistent
//! orientation and no self-intersections (parry's triangle-triangle test over a BVH).

use std::collections::HashMap;

use hullcut_sim::body::{Body, VoxelizeParams, box_sdf, voxelize};
use hullcut_sim::cut_surface::{BodySamples, piece_surfaces};
use hullcut_sim::{CellTree, CutTopology, Lattice, SweptSurface, TriMesh, WindingTree, cut_edges};
use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::math::{Pose, Vector as PVector};
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy};
use parry3d_f64::query::intersection_test;
use parry3d_f64::shape::Triangle;

/// A swept surface covering the plane through `point` with unit `normal` for 20 cm around it.
fn plane_sweep(point: Point3<f64>, normal: Vector3<f64>) -> SweptSurface {
    let e1 = normal.cross(&Vector3::new(0.3, 0.5, 0.8)).normalize();
    let e2 = normal.cross(&e1);
    let edge = [point - 0.2 * e1, point + 0.2 * e1];
    let from = Isometry3::translation(-0.2 * e2.x, -0.2 * e2.y, -0.2 * e2.z);
    let to = Isometry3::translation(0.2 * e2.x, 0.2 * e2.y, 0.2 * e2.z);
    SweptSurface::between(&edge, &from, &to, 0.5, 0.5).expect("a sweep")
}

/// Pairs of triangles of `mesh` that share no vertex and intersect.
fn self_intersections(mesh: &TriMesh) -> usize {
    let p = |i: u32| {
        let v = mesh.vertices[i as usize];
        PVector::new(v.x, v.y, v.z)
    };
    let triangles: Vec<Triangle> = mesh.triangles.iter().map(|t| Triangle::new(p(t[0]), p(t[1]), p(t[2]))).collect();
    let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::new(t.a.min(t.b).min(t.c), t.a.max(t.b).max(t.c))).collect();
    let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &boxes);
    let mut count = 0;
    for (i, t) in mesh.triangles.iter().enumerate() {
        for j in bvh.intersect_aabb(&boxes[i]) {
            let u = mesh.triangles[j as usize];
            if j as usize <= i || t.iter().any(|v| u.contains(v)) {
                continue;
            }
            let hit = intersection_test(&Pose::IDENTITY, &triangles[i], &Pose::IDENTITY, &triangles[j as usize])
                .expect("triangles are supported");
            count += usize::from(hit.intersecting);
        }
    }
    count
}

/// Volume of the box `[0, a]³` on the side `n · x < d` of a plane with `n` all positive
/// (inclusion–exclusion over the corners' simplices).
fn box_below(a: f64, n: Vector3<f64>, d: f64) -> f64 {
    let mut v = 0.0;
    for c in 0..8 {
        let corner = Vector3::new((c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64) * a;
        let sign = if (c as u32).count_ones().is_multiple_of(2) { 1.0 } else { -1.0 };
        v += sign * (d - n.dot(&corner)).max(0.0).powi(3);
    }
    v / (6.0 * n.x * n.y * n.z)
}

/// What a planar cut left: each piece closed, oriented and free of self-intersections, the
/// pieces' volumes, and the largest distance to the plane (in cells) of the vertices deep enough
/// inside the body (by `depth`, a signed distance) to lie on the cut face, with their count.
struct Cut {
    volumes: Vec<f64>,
    whole: f64,
    face_error_cells: f64,
    face_vertices: usize,
}

fn cut(
    lattice: &Lattice,
    samples: &BodySamples,
    depth: &dyn Fn(&Point3<f64>) -> f64,
    point: Point3<f64>,
    normal: Vector3<f64>,
) -> Cut {
    let whole = piece_surfaces(lattice, &CutTopology::rebuild(lattice, []), samples)[0].rest.volume();
    let tree = CellTree::new(lattice, &lattice.rest);
    let edges = cut_edges(lattice, &lattice.rest, &tree, &plane_sweep(point, normal)).edges;
    let topology = CutTopology::rebuild(lattice, edges);
    assert_eq!(topology.pieces, 2);
    let surfaces = piece_surfaces(lattice, &topology, samples);
    let (mut face_error, mut face_vertices) = (0.0f64, 0);
    let mut volumes = Vec::new();
    for s in &surfaces {
        assert!(s.rest.is_closed(), "watertight");
        assert_eq!(s.rest.orientation_conflicts(), 0);
        assert_eq!(self_intersections(&s.rest), 0, "no self-intersections");
        volumes.push(s.rest.volume());
        for v in &s.rest.vertices {
            if depth(v) < -1.5 * samples.h {
                let e = (v - point).dot(&normal).abs() / lattice.cell;
                if e > 0.005 {
                    eprintln!("vertex {v} off by {e} cells, depth {}", depth(v) / samples.h);
                }
                face_error = face_error.max(e);
                face_vertices += 1;
            }
        }
    }
    let total: f64 = volumes.iter().sum();
    eprintln!(
        "plane {normal:?}: {face_vertices} cut-face vertices within {face_error:.2e} cells of it; pieces {:.4e} m³ against the body's {whole:.4e} ({:+.3}%)",
        total,
        100.0 * (total - whole) / whole
    );
    Cut { volumes, whole, face_error_cells: face_error, face_vertices }
}

#[test]
fn a_planar_cut_through_a_box_lies_on_the_plane_and_keeps_the_volume() {
    let side = 0.06;
    let l = Lattice::block(Point3::origin(), 0.01, [6, 6, 6]);
    let sdf = box_sdf(Vector3::repeat(side));
    let samples = BodySamples::new(&l, 4, &sdf);
    for (normal, point) in [
        (Vector3::new(1.0, 0.3, 0.2), Point3::new(0.023, 0.031, 0.027)),
        (Vector3::new(0.5, 0.7, 0.9), Point3::new(0.034, 0.029, 0.03)),
        (Vector3::new(0.2, 0.1, 1.0), Point3::new(0.03, 0.03, 0.0415)),
    ] {
        let n = normal.normalize();
        let c = cut(&l, &samples, &sdf, point, n);
        let total: f64 = c.volumes.iter().sum();
        assert!((total - c.whole).abs() < 0.01 * c.whole, "pieces {total} against the body's {}", c.whole);
        // The piece below the plane against the exact split of the box (the body's surface nets
        // round the box's edges and corners, about 2% of it).
        let below = box_below(side, n, n.dot(&point.coords));
        let found = c.volumes.iter().copied().min_by(|a, b| (a - below).abs().total_cmp(&(b - below).abs()));
        let found = found.expect("a piece");
        assert!((found - below).abs() < 0.02 * side.powi(3), "{found} against {below}");
        assert!(c.face_vertices > 50, "{} cut-face vertices", c.face_vertices);
        assert!(c.face_error_cells < 1e-6, "cut face {} cells off the plane", c.face_error_cells);
    }
}

/// A sphere of `radius` around `centre` triangulated from an octahedron's faces split into
/// `k`² triangles each, vertices pushed onto the sphere (closed, outward).
fn sphere(centre: Point3<f64>, radius: f64, k: usize) -> TriMesh {
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    let mut index: HashMap<[i64; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut vertex = |p: Vector3<f64>| -> u32 {
        let key = [p.x, p.y, p.z].map(|c| (c * 1e9).round() as i64);
        *index.entry(key).or_insert_with(|| {
            vertices.push(centre + p.normalize() * radius);
            (vertices.len() - 1) as u32
        })
    };
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let (a, b, c) = (axes[0] * sx, axes[1] * sy, axes[2] * sz);
                let point = |i: usize, j: usize| a + (b - a) * (i as f64 / k as f64) + (c - a) * (j as f64 / k as f64);
                for i in 0..k {
                    for j in 0..k - i {
                        let mut tri = [vertex(point(i, j)), vertex(point(i + 1, j)), vertex(point(i, j + 1))];
                        let mut more = (i + j + 1 < k)
                            .then(|| [vertex(point(i + 1, j)), vertex(point(i + 1, j + 1)), vertex(point(i, j + 1))]);
                        // Outward: flip where the octant's axes run clockwise.
                        if sx * sy * sz < 0.0 {
                            tri.swap(1, 2);
                            if let Some(m) = more.as_mut() {
                                m.swap(1, 2);
                            }
                        }
                        triangles.push(tri);
                        triangles.extend(more);
                    }
                }
            }
        }
    }
    TriMesh::new(vertices, triangles)
}

#[test]
fn a_planar_cut_through_a_mesh_tissue_lies_on_the_plane_and_keeps_the_volume() {
    let (centre, radius) = (Point3::new(0.0, 0.0, 0.03), 0.03);
    let mesh = sphere(centre, radius, 24);
    assert!(mesh.is_closed_oriented() && mesh.volume() > 0.0);
    let cell = 0.006;
    let voxelized = voxelize(&Body::Mesh(mesh.clone(), None), cell, &VoxelizeParams::default()).expect("voxelized");
    let l = voxelized.lattice;
    // As `hullcut run` samples a mesh tissue: inside where the generalized winding number
    // exceeds one half.
    let tree = WindingTree::new(&mesh);
    let signed = move |p: &Point3<f64>| (0.5 - tree.winding_number(p).abs()) * cell;
    let samples = BodySamples::new(&l, 4, &signed);
    let depth = move |p: &Point3<f64>| (p - centre).norm() - radius;
    let n = Vector3::new(0.8, 0.35, 0.3).normalize();
    let offset = 0.011;
    let c = cut(&l, &samples, &depth, centre + n * offset, n);
    let total: f64 = c.volumes.iter().sum();
    assert!((total - c.whole).abs() < 0.01 * c.whole, "pieces {total} against the body's {}", c.whole);
    // The cap beyond the plane against the sphere's, scaled to the mesh's volume.
    let h = radius - offset;
    let cap = std::f64::consts::PI * h * h * (3.0 * radius - h) / 3.0;
    let cap = cap * mesh.volume() / (4.0 / 3.0 * std::f64::consts::PI * radius.powi(3));
    let found = c.volumes.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((found - cap).abs() < 0.05 * cap, "cap {found} against {cap}");
    assert!(c.face_vertices > 50, "{} cut-face vertices", c.face_vertices);
    assert!(c.face_error_cells < 0.01, "cut face {} cells off the plane", c.face_error_cells);
}
