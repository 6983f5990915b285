//! Bodies: mesh files, winding numbers, voxelization and surface embedding.

use std::path::Path;

use hullcut_sim::{Body, Embedding, MeshError, TriMesh, VoxelizeError, VoxelizeParams, WindingTree, voxelize};
use nalgebra::{Point3, Vector3};

/// Installed by the Debian package opencv-doc (CI and the dev setup install it).
const BUNNY: &str = "/usr/share/doc/opencv-doc/examples/viz/data/bunny.ply";

fn fractions(body: &Body, cell: f64, params: &VoxelizeParams) -> (hullcut_sim::Lattice, Vec<([u32; 3], f32)>) {
    let v = voxelize(body, cell, params).expect("voxelize");
    let f = v.lattice.cells.iter().map(|c| (c.ijk, c.fraction)).collect();
    (v.lattice, f)
}

#[test]
fn aligned_box_is_exact() {
    let body = Body::Box { size: Vector3::new(0.05, 0.03, 0.02) };
    let (lattice, f) = fractions(&body, 0.005, &VoxelizeParams::default());
    assert_eq!(lattice.dims, [10, 6, 4]);
    assert_eq!(f.len(), 240);
    assert!(f.iter().all(|&(_, x)| x == 1.0));
    assert_eq!(lattice.origin, Point3::origin());
    // Exact up to the rounding of summing 240 cell volumes.
    assert!((lattice.volume() - 3e-5).abs() < 1e-12 * 3e-5, "{}", lattice.volume());
}

/// Number of grid boundaries a cell touches (0 interior, 1 face, 2 edge, 3 corner).
fn boundary_order(ijk: [u32; 3], dims: [usize; 3]) -> usize {
    (0..3).filter(|&a| ijk[a] == 0 || ijk[a] as usize == dims[a] - 1).count()
}

#[test]
fn half_cell_offset_box_has_half_cells() {
    let h = 0.005;
    let body = Body::Box { size: Vector3::new(0.05, 0.03, 0.02) };
    let params = VoxelizeParams { anchor: Point3::new(-h / 2.0, -h / 2.0, -h / 2.0), ..VoxelizeParams::default() };
    let (lattice, f) = fractions(&body, h, &params);
    assert_eq!(lattice.dims, [11, 7, 5]);
    assert_eq!(f.len(), 11 * 7 * 5);
    for &(ijk, x) in &f {
        // 0.5 per boundary the cell straddles: exactly representable.
        assert_eq!(x, 0.5f32.powi(boundary_order(ijk, lattice.dims) as i32), "cell {ijk:?}");
    }
    assert!((lattice.volume() - 3e-5).abs() < 1e-12 * 3e-5);

    // The same for the box as a closed mesh, sampled by winding numbers: 4 samples per axis put exactly
    // half of them inside a half-covered cell.
    let mesh = Body::Mesh(TriMesh::cuboid_grid(Point3::origin(), Point3::new(0.05, 0.03, 0.02), [3, 2, 1]), None);
    let v = voxelize(&mesh, h, &params).expect("voxelize");
    assert!(v.warnings.is_empty(), "{:?}", v.warnings);
    let g: Vec<_> = v.lattice.cells.iter().map(|c| (c.ijk, c.fraction)).collect();
    assert_eq!(g, f);

    // A size that is not a multiple of the cell leaves half cells on the far side only.
    let (lattice, f) =
        fractions(&Body::Box { size: Vector3::new(0.045, 0.01, 0.01) }, 0.01, &VoxelizeParams::default());
    assert_eq!(lattice.dims, [5, 1, 1]);
    assert_eq!(f.iter().map(|c| c.1).collect::<Vec<_>>(), vec![1.0, 1.0, 1.0, 1.0, 0.5]);
}

#[test]
fn winding_numbers_of_a_closed_cube() {
    let cube = TriMesh::cuboid_grid(Point3::new(-1.0, -1.0, -1.0), Point3::new(1.0, 1.0, 1.0), [2, 2, 2]);
    let tree = WindingTree::new(&cube);
    for (p, want) in [([0.0, 0.0, 0.0], 1.0), ([0.9, -0.9, 0.5], 1.0), ([1.1, 0.0, 0.0], 0.0), ([5.0, 5.0, -5.0], 0.0)]
    {
        let p = Point3::from(p);
        assert!((cube.winding_number(&p) - want).abs() < 1e-12, "{p}");
        // The tree's moment expansion is accurate to about 5e-3 (WindingTree::winding_number).
        assert!((tree.winding_number(&p) - want).abs() < 6e-3, "{p}");
    }
    // On a face, away from triangle edges.
    assert!((cube.winding_number(&Point3::new(0.3, 0.6, 1.0)) - 0.5).abs() < 1e-12);
    // Just off the face the value jumps towards 1 or 0.
    assert!(cube.winding_number(&Point3::new(0.3, 0.6, 1.0 - 1e-9)) > 0.99);
    assert!(cube.winding_number(&Point3::new(0.3, 0.6, 1.0 + 1e-9)) < 0.01);
}

#[test]
fn ply_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mesh = Body::organ_mesh(1.0);
    for ascii in [false, true] {
        let path = dir.path().join(if ascii { "organ_ascii.ply" } else { "organ.ply" });
        if ascii {
            mesh.write_ply_ascii(&path).expect("write");
        } else {
            mesh.write_ply(&path).expect("write");
        }
        let back = TriMesh::load(&path).expect("load");
        assert_eq!(back.vertices, mesh.vertices, "ascii: {ascii}");
        assert_eq!(back.triangles, mesh.triangles, "ascii: {ascii}");
    }
}

#[test]
fn obj_cube_loads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("cube.OBJ");
    // A unit cube as six quads, with texture and normal indices, relative indices on one face.
    let text = "o cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nvn 0 0 1\nvt 0 0\n\
                f 1/1/1 4/1/1 3/1/1 2/1/1\nf 5//1 6//1 7//1 8//1\nf 1 2 6 5\nf -7 -6 -2 -3\nf 3 4 8 7\nf 4 1 5 8\n";
    std::fs::write(&path, text).expect("write");
    let cube = TriMesh::load(&path).expect("load");
    assert_eq!((cube.vertices.len(), cube.triangles.len()), (8, 12));
    assert!(cube.is_closed());
    assert_eq!(cube.orientation_conflicts(), 0);
    assert!((cube.volume() - 1.0).abs() < 1e-12);
    assert!((cube.winding_number(&Point3::new(0.5, 0.5, 0.5)) - 1.0).abs() < 1e-12);
}

#[test]
fn bad_files_name_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("missing.ply");
    let e = TriMesh::load(&missing).expect_err("missing");
    assert!(matches!(e, MeshError::Read { .. }) && e.to_string().contains("missing.ply"), "{e}");

    let garbage = dir.path().join("garbage.ply");
    std::fs::write(&garbage, "solid cube\nfacet normal 0 0 1\n").expect("write");
    let e = TriMesh::load(&garbage).expect_err("garbage");
    assert!(matches!(e, MeshError::Header { line: 1, .. }) && e.to_string().contains("garbage.ply"), "{e}");

    let truncated = dir.path().join("truncated.ply");
    std::fs::write(
        &truncated,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
    )
    .expect("write");
    let e = TriMesh::load(&truncated).expect_err("truncated");
    assert!(matches!(e, MeshError::Truncated { index: 2, count: 3, .. }), "{e}");
    assert!(e.to_string().contains("truncated.ply") && e.to_string().contains("vertex 2"), "{e}");

    let out_of_range = dir.path().join("range.ply");
    std::fs::write(
        &out_of_range,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
    )
    .expect("write");
    let e = TriMesh::load(&out_of_range).expect_err("index 3");
    assert!(matches!(e, MeshError::IndexOutOfRange { index: 3, vertices: 3, .. }), "{e}");
    assert!(e.to_string().contains("range.ply") && e.to_string().contains("face 0"), "{e}");

    let stl = dir.path().join("cube.stl");
    std::fs::write(&stl, "solid\n").expect("write");
    let e = TriMesh::load(&stl).expect_err("stl");
    assert!(matches!(e, MeshError::UnsupportedFormat { .. }) && e.to_string().contains("cube.stl"), "{e}");

    // A lone triangle loads (it is a mesh) but encloses nothing: voxelizing it names the file.
    let flat = dir.path().join("flat.obj");
    std::fs::write(&flat, "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0.01\nf 1 2 3\n").expect("write");
    let body = Body::load_mesh(&flat, 1.0).expect("load");
    let e = voxelize(&body, 0.005, &VoxelizeParams::default()).expect_err("nothing inside");
    assert!(matches!(e, VoxelizeError::NoMaterial { .. }) && e.to_string().contains("flat.obj"), "{e}");
}

#[test]
fn bunny_voxelizes_despite_holes() {
    assert!(Path::new(BUNNY).exists(), "{BUNNY} is missing: install the Debian package opencv-doc");
    let body = Body::load_mesh(BUNNY, 1.0).expect("bunny");
    let Body::Mesh(mesh, _) = &body else { unreachable!() };
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (1889, 3851));
    // The file is in metres: about 15 x 15 x 12 cm.
    let (lo, hi) = mesh.bounds().expect("bounds");
    let size = hi - lo;
    assert!(size.iter().all(|&s| s > 0.1 && s < 0.2), "{size}");
    assert!(!mesh.is_closed());
    let mesh_volume = mesh.volume();
    assert!(mesh_volume > 0.0, "outward-oriented");

    // The fast winding numbers agree with the exact sum (to the documented 5e-3) around the bunny.
    let tree = WindingTree::new(mesh);
    let mut seed = 1u64;
    let mut unit = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..300 {
        let p = Point3::from(lo.coords + size.component_mul(&Vector3::new(unit(), unit(), unit())));
        let (exact, fast) = (mesh.winding_number(&p), tree.winding_number(&p));
        assert!((exact - fast).abs() < 6e-3, "{p}: exact {exact}, tree {fast}");
    }

    let started = std::time::Instant::now();
    let v = voxelize(&body, 0.005, &VoxelizeParams::default()).expect("voxelize");
    let seconds = started.elapsed().as_secs_f64();
    assert_eq!(v.warnings.len(), 1, "{:?}", v.warnings);
    assert!(v.warnings[0].contains("bunny.ply") && v.warnings[0].contains("not closed"), "{}", v.warnings[0]);
    let voxel_volume = v.lattice.volume() + v.dropped_volume;
    // TriMesh::volume closes the holes with flat fans; the winding number closes them with slightly
    // bulging caps, and 4³ samples resolve the boundary cells' fractions to 1/64. Measured: 0.2 %
    // apart (7.444e-4 and 7.430e-4 m³); the cone-from-a-point volume of the open mesh alone varies by
    // ±4.5 % with the point, so closing the holes matters.
    let rel = (voxel_volume - mesh_volume).abs() / mesh_volume;
    assert!(rel < 0.01, "mesh {mesh_volume:.4e} m³, voxels {voxel_volume:.4e} m³ ({seconds:.2} s)");
    // Dropping cells under 5 % loses little material.
    assert!(v.dropped_volume < 0.01 * mesh_volume);
}

#[test]
fn organ_is_closed_and_liver_sized() {
    let mesh = Body::organ_mesh(1.0);
    assert_eq!(mesh.open_edges(), 0);
    assert_eq!(mesh.orientation_conflicts(), 0);
    let (lo, hi) = mesh.bounds().expect("bounds");
    let size = hi - lo;
    // 15 x 10 x 6 cm, within a surface-net spacing (2.5 mm).
    for (got, want) in size.iter().zip([0.15, 0.10, 0.06]) {
        assert!((got - want).abs() < 0.0025, "size {size}");
    }
    assert!(lo.z.abs() < 1e-9, "rests on the table: {}", lo.z);
    assert!(((lo.x + hi.x) / 2.0).abs() < 0.0025 && ((lo.y + hi.y) / 2.0).abs() < 0.0025, "centred: {lo} {hi}");
    // Analytic: the right lobe, an ellipsoid of semi-axes 5, 5, 4.5 cm centred 1.5 cm above the table,
    // keeps 20/27 of its volume above z = 0: 4/3 π · 0.05 · 0.05 · 0.045 · 20/27 = 3.49e-4 m³; the left
    // lobe (4, 3.5, 3 cm, centre 0.5 cm up, 539/864 kept) 1.10e-4 m³. The union lies between 3.49e-4 and
    // their sum 4.59e-4; the lobes' lens-shaped overlap is 2.7e-5 m³ and the smooth blend adds 3e-6 m³
    // (both by 0.5 mm grid quadrature), so 4.35e-4 m³. Surface nets at 2.5 mm with projected vertices
    // cut corners by well under 1 %.
    let volume = mesh.volume();
    assert!((volume - 4.35e-4).abs() < 0.01 * 4.35e-4, "{volume:.4e}");
    // The lattice agrees with the mesh: SDF sampling at 2.5 mm cells.
    let v = voxelize(&Body::Organ { scale: 1.0 }, 0.0025, &VoxelizeParams::default()).expect("voxelize");
    let voxels = v.lattice.volume() + v.dropped_volume;
    assert!((voxels - volume).abs() < 0.01 * volume, "{voxels:.4e} vs {volume:.4e}");
    // Deep inside and outside.
    assert!((mesh.winding_number(&Point3::new(-0.025, 0.0, 0.03)) - 1.0).abs() < 1e-9);
    assert!(mesh.winding_number(&Point3::new(0.07, -0.045, 0.05)).abs() < 1e-9);
}

#[test]
fn the_large_organ_is_the_organ_scaled_and_has_a_hundred_thousand_nodes_at_2_mm() {
    use hullcut_sim::{LARGE_ORGAN_SCALE, organ_sdf, scaled_organ_sdf};
    let s = LARGE_ORGAN_SCALE;
    let large = Body::Organ { scale: s };
    let mesh = large.surface();
    assert_eq!(mesh.open_edges(), 0);
    assert_eq!(mesh.orientation_conflicts(), 0);
    let (lo, hi) = mesh.bounds().expect("bounds");
    assert!(lo.z.abs() < 1e-9, "rests on the table: {}", lo.z);
    for (got, want) in (hi - lo).iter().zip([0.15, 0.10, 0.06]) {
        assert!((got - want * s).abs() < 0.0025, "size {}", hi - lo);
    }
    // Volume goes with the cube of the size: against the built-in organ's own mesh.
    let ratio = mesh.volume() / Body::organ_mesh(1.0).volume();
    assert!((ratio - s * s * s).abs() < 0.01 * s * s * s, "volume ratio {ratio}");
    // The signed distance scales with the shape: a point and its image agree in sign and scale.
    for p in [Point3::new(0.05, 0.01, 0.02), Point3::new(-0.03, 0.02, 0.05), Point3::new(0.07, -0.04, 0.01)] {
        let (a, b) = (organ_sdf(&p), scaled_organ_sdf(&(p * s), s));
        assert!((b - s * a).abs() < 1e-12, "{p}: {a} {b}");
    }
    // The large organ: at least 100,000 nodes at 2 mm cells (the built-in one has 63k).
    let v = voxelize(&large, 0.002, &VoxelizeParams::default()).expect("voxelize");
    let nodes = v.lattice.node_count();
    assert!(nodes >= 100_000, "{nodes} nodes");
    let small = voxelize(&Body::Organ { scale: 1.0 }, 0.002, &VoxelizeParams::default()).expect("voxelize");
    assert!(small.lattice.node_count() < 100_000, "{}", small.lattice.node_count());
}

/// Node positions of the lattice at rest, as the simulators hold them.
fn rest(lattice: &hullcut_sim::Lattice) -> Vec<Vector3<f32>> {
    lattice.rest.iter().map(|p| p.coords.cast()).collect()
}

#[test]
fn embedding_reproduces_the_rest_surface() {
    for body in [Body::Box { size: Vector3::new(0.05, 0.03, 0.02) }, Body::Organ { scale: 1.0 }] {
        let v = voxelize(&body, 0.005, &VoxelizeParams::default()).expect("voxelize");
        let surface = body.surface();
        let e = Embedding::new(&v.lattice, &surface.vertices).expect("embed");
        assert_eq!(e.clamped, 0, "{body}: every vertex within a cell of an active one");
        let mut out = Vec::new();
        e.positions_into(&v.lattice, &rest(&v.lattice), &mut out);
        assert_eq!(out.len(), surface.vertices.len());
        // f32 positions of ~0.1 m carry ~1e-8 m of rounding.
        let worst = out
            .iter()
            .zip(&surface.vertices)
            .map(|(a, b)| (a.coords.cast::<f64>() - b.coords).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{body}: {worst:e} m");
        if matches!(body, Body::Box { .. }) {
            assert_eq!(e.outside, 0);
        }
    }
}
