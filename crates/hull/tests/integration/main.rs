//! Carving checked on rendered silhouettes of shapes with known geometry (the default rig, exact
//! masks from the synthetic renderer).

#[cfg(feature = "gpu")]
mod gpu;
mod robustness;

use hullcut_dataset::{Mesh, label};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, Silhouette, carve, is_watertight, silhouettes};
use hullcut_rig::{Rig, default_rig};
use hullcut_synth::{CameraRenderer, Light, Part, TriMesh};
use image::GrayImage;
use nalgebra::{Isometry3, Point3, Vector3};

fn render(rig: &Rig, parts: &[Part]) -> Vec<GrayImage> {
    rig.cameras
        .iter()
        .map(|c| {
            let layers = CameraRenderer::new(c, Light::default()).render(parts);
            GrayImage::from_raw(c.width, c.height, layers.labels).expect("mask size")
        })
        .collect()
}

fn views(rig: &Rig, masks: &[GrayImage]) -> Vec<Option<Silhouette>> {
    let refs: Vec<Option<&GrayImage>> = masks.iter().map(Some).collect();
    silhouettes(rig, &refs).expect("sizes match")
}

const CENTRE: [f64; 3] = [0.01, -0.02, 0.15];
const RADIUS: f64 = 0.05;

fn sphere() -> Part {
    let mesh =
        TriMesh::ellipsoid(&Isometry3::translation(CENTRE[0], CENTRE[1], CENTRE[2]), Vector3::repeat(RADIUS), 96);
    Part { label: label::HAND, albedo: [0.5; 3], mesh }
}

/// Points on a grid inside the sphere (2 mm spacing, 1 mm inside its surface).
fn inside_sphere() -> Vec<Point3<f64>> {
    let c = Point3::from(CENTRE);
    let mut out = Vec::new();
    let n = (RADIUS / 0.002) as i32;
    for i in -n..=n {
        for j in -n..=n {
            for k in -n..=n {
                let p = c + Vector3::new(i as f64, j as f64, k as f64) * 0.002;
                if (p - c).norm() < RADIUS - 0.001 {
                    out.push(p);
                }
            }
        }
    }
    out
}

fn assert_contains_all(occ: &Occupancy, points: &[Point3<f64>], l: Option<u8>) {
    let missing = points.iter().filter(|p| !occ.contains(p, l)).count();
    assert_eq!(missing, 0, "{missing} of {} points inside the object were carved away", points.len());
}

fn signed_volume(m: &Mesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.vertices[i as usize].coords);
            a.dot(&b.cross(&c)) / 6.0
        })
        .sum()
}

#[test]
fn a_sphere_is_kept_whole_and_its_hull_is_tight() {
    let rig = default_rig();
    let masks = render(&rig, &[sphere()]);
    let occ = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    assert_eq!(occ.resolution, 128);
    assert_contains_all(&occ, &inside_sphere(), Some(label::HAND));
    let exact = 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3);
    let ratio = occ.volume(None) / exact;
    // Six views around a sphere leave the hull a little larger than the sphere, and the leaves that
    // straddle the silhouette boundary are kept (3.1 mm leaves on a 50 mm radius): measured 1.28.
    assert!((1.0..1.4).contains(&ratio), "hull / sphere volume {ratio:.3}");
    assert_eq!(occ.stats.views_used, 6);

    let grid = DenseGrid::from_occupancy(&occ, Some(label::HAND)).expect("grid");
    let mesh = grid.surface();
    assert!(is_watertight(&mesh), "the surface is closed and consistently oriented");
    assert!(mesh.triangles.len() > 1000);
    let v = signed_volume(&mesh);
    // Outward normals give a positive volume; surface nets cut the leaf corners, so the enclosed
    // volume lies a little below the leaves' total.
    assert!(v > 0.0 && (v / occ.volume(Some(label::HAND)) - 1.0).abs() < 0.1, "{v} vs {}", occ.volume(None));
}

#[test]
fn a_blade_thinner_than_a_leaf_survives() {
    // A 0.4 mm plate, 38 x 9 mm, tilted 30° out of the table plane: leaves are 3.1 mm.
    let plate = TriMesh::cuboid(Point3::new(-0.019, -0.0045, -0.0002), Point3::new(0.019, 0.0045, 0.0002));
    let pose = Isometry3::new(Vector3::new(0.03, 0.02, 0.12), Vector3::new(0.5f64.to_radians() * 60.0, 0.2, 0.4));
    let part = Part { label: label::SCALPEL, albedo: [0.8; 3], mesh: plate.transformed(&pose) };
    let rig = default_rig();
    let masks = render(&rig, &[part]);
    let occ = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    // Points at least 1 mm inside the outline: masks are sampled at pixel centres (about 1.6 mm
    // apart at this distance), so a sliver of the blade nearer its outline than half a pixel may
    // cover no pixel centre in some view, and that view rightly refutes it.
    let mut points = Vec::new();
    for i in -17..=17 {
        for j in -3..=3 {
            points.push(pose * Point3::new(i as f64 * 0.001, j as f64 * 0.001, 0.0));
        }
    }
    assert_contains_all(&occ, &points, Some(label::SCALPEL));
    // Still a thin object: a few leaves thick, not a slab.
    let volume = occ.volume(Some(label::SCALPEL));
    assert!(volume < 40.0 * 0.038 * 0.009 * occ.leaf_size, "{volume}");
}

#[test]
fn one_bad_silhouette_deletes_the_object_unless_k_of_n_protects_it() {
    let rig = default_rig();
    let mut masks = render(&rig, &[sphere()]);
    masks[2] = GrayImage::new(masks[2].width(), masks[2].height());
    let classic = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    assert_eq!(classic.volume(None), 0.0, "one empty silhouette carves everything");
    let params = HullParams { carve_votes: 2, ..HullParams::default() };
    let robust = carve(&views(&rig, &masks), &params).expect("carve");
    assert_contains_all(&robust, &inside_sphere(), Some(label::HAND));
    assert!(robust.stats.kept_against_refutation > 0);
    // The empty view refutes, alone, every cell the others see.
    assert_eq!(robust.stats.most_disagreeing_view(), Some(2), "{:?}", robust.stats.lone_refutations);
}

#[test]
fn a_missing_view_is_left_out_and_counted() {
    let rig = default_rig();
    let masks = render(&rig, &[sphere()]);
    let all = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    let mut five = views(&rig, &masks);
    five[3] = None;
    let occ = carve(&five, &HullParams::default()).expect("carve");
    assert_eq!((occ.stats.views_used, occ.stats.views_missing), (5, 1));
    assert_contains_all(&occ, &inside_sphere(), Some(label::HAND));
    assert!(occ.volume(None) >= all.volume(None), "fewer views carve less");
}

#[test]
fn labels_separate_a_hand_from_a_scalpel_it_partly_hides() {
    let rig = default_rig();
    let hand = TriMesh::ellipsoid(&Isometry3::translation(-0.03, 0.0, 0.15), Vector3::repeat(0.04), 64);
    let bar_min = Point3::new(0.0, -0.005, 0.147);
    let bar_max = Point3::new(0.09, 0.005, 0.153);
    let bar = TriMesh::cuboid(bar_min, bar_max);
    let parts = [
        Part { label: label::HAND, albedo: [0.3, 0.4, 0.8], mesh: hand },
        Part { label: label::SCALPEL, albedo: [0.6; 3], mesh: bar },
    ];
    let masks = render(&rig, &parts);
    let occ = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    // Every point of the bar outside the hand keeps the scalpel label...
    let bar_points: Vec<Point3<f64>> = (1..45).map(|i| Point3::new(0.012 + i as f64 * 0.0017, 0.0, 0.15)).collect();
    assert_contains_all(&occ, &bar_points, Some(label::SCALPEL));
    // ...and the hand's interior is not taken for scalpel (a cell needs scalpel pixels in two views).
    let core: Vec<Point3<f64>> = (-5..=5).map(|i| Point3::new(-0.03, i as f64 * 0.005, 0.15 + 0.02)).collect();
    let wrong = core.iter().filter(|p| occ.contains(p, Some(label::SCALPEL))).count();
    assert_eq!(wrong, 0, "{wrong} hand points labelled scalpel");
    assert_contains_all(&occ, &core, Some(label::HAND));
}

#[test]
fn accuracy_measures_agree_with_closed_forms() {
    use hullcut_hull::accuracy::{sample_surface, surface_distance, volumetric_iou, winding_number};
    let exact = sphere().mesh.to_dataset();
    let c = Point3::from(CENTRE);
    assert!((winding_number(&exact, &c) - 1.0).abs() < 1e-9);
    assert!(winding_number(&exact, &(c + Vector3::new(0.0, 0.0, 2.0 * RADIUS))).abs() < 1e-9);

    let rig = default_rig();
    let masks = render(&rig, &[sphere()]);
    let occ = carve(&views(&rig, &masks), &HullParams::default()).expect("carve");
    let grid = DenseGrid::from_occupancy(&occ, Some(label::HAND)).expect("grid");
    // The hull holds the sphere (test above), so IoU = sphere / hull volume ≈ 1 / 1.28; Monte Carlo
    // with 20,000 samples has a standard error below 0.005.
    let iou = volumetric_iou(Some(&grid), &exact, 20_000).expect("iou");
    let expected = (4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3)) / occ.volume(None);
    assert!((iou - expected).abs() < 0.03, "{iou} vs {expected}");
    // Surface distances: the sampled sphere against itself is zero; against the hull's surface a
    // few millimetres (the hull bulges between the six views).
    let on_sphere = sample_surface(&exact, 0.002);
    let d = surface_distance(&on_sphere, &on_sphere, 0.004).expect("distance");
    assert!(d.chamfer == 0.0 && d.hausdorff == 0.0);
    let hull_surface = sample_surface(&grid.surface(), 0.002);
    let d = surface_distance(&hull_surface, &on_sphere, 0.004).expect("distance");
    assert!(d.chamfer > 0.0005 && d.chamfer < 0.005 && d.hausdorff < 0.02, "{d:?}");
}
