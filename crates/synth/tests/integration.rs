//! Renderer checks against closed forms and the camera model, and the synthetic dataset round trip.

use hullcut_dataset::{Dataset, label};
use hullcut_rig::{Camera, Distortion};
use hullcut_synth::{CameraRenderer, Light, Part, Scene, SceneConfig, SceneKind, TriMesh, synthesize};
use nalgebra::{Isometry3, Point2, Point3, Vector3};

fn camera_at_origin(distortion: Distortion) -> Camera {
    let mut cam = Camera::new("test", 640, 480, 600.0, 600.0, 319.5, 239.5);
    cam.distortion = distortion;
    cam
}

#[test]
fn a_sphere_on_the_axis_covers_the_disc_the_closed_form_gives() {
    // Camera at the origin looking along +z (identity extrinsics); sphere of radius r at distance d.
    let (r, d) = (0.05, 0.8);
    let cam = camera_at_origin(Distortion::default());
    let renderer = CameraRenderer::new(&cam, Light::default());
    let sphere = TriMesh::ellipsoid(&Isometry3::translation(0.0, 0.0, d), Vector3::repeat(r), 256);
    let layers = renderer.render(&[Part { label: label::HAND, albedo: [0.5; 3], mesh: sphere }]);
    let pixels = layers.labels.iter().filter(|&&l| l == label::HAND).count() as f64;
    // The silhouette of a sphere seen on axis is a disc of angular radius asin(r/d).
    let rho = 600.0 * (r / d).asin().tan();
    let disc = std::f64::consts::PI * rho * rho;
    assert!((pixels - disc).abs() < 0.005 * disc + 2.0 * std::f64::consts::PI * rho * 0.1, "{pixels} px vs {disc:.1}");
    // Depth at the centre pixel: the sphere's near pole.
    let centre = 240 * 640 + 320;
    let expected = d - r * (1.0 - 1e-4); // 256 segments: the pole vertex is exact
    assert!((layers.depth[centre] - expected).abs() < 2e-4, "{}", layers.depth[centre]);
}

#[test]
fn depth_of_a_flat_face_is_the_exact_ray_plane_distance_with_distortion() {
    let cam = camera_at_origin(Distortion { k1: -0.12, k2: 0.07, p1: 2e-4, p2: -1e-4, k3: 0.0 });
    let renderer = CameraRenderer::new(&cam, Light::default());
    // A slab whose front face is the plane z = 0.5 + 0.2 x (tilted), seen from the front.
    let slab = TriMesh::cuboid(Point3::new(-0.3, -0.2, 0.0), Point3::new(0.3, 0.2, 0.1));
    let tilt = Isometry3::new(Vector3::new(0.0, 0.0, 0.5), Vector3::new(0.0, -0.2f64.atan(), 0.0));
    let mesh = slab.transformed(&(tilt * Isometry3::translation(0.0, 0.0, 0.0)));
    let layers = renderer.render(&[Part { label: label::SCALPEL, albedo: [0.5; 3], mesh }]);
    let normal = tilt.rotation * Vector3::z();
    let point = tilt * Point3::origin();
    let mut checked = 0;
    for j in (0..480).step_by(7) {
        for i in (0..640).step_by(7) {
            let k = j * 640 + i;
            if layers.labels[k] != label::SCALPEL {
                continue;
            }
            let Some(xn) = cam.undistort(Point2::new(i as f64, j as f64)) else { continue };
            let ray = Vector3::new(xn.x, xn.y, 1.0);
            let z = normal.dot(&point.coords) / normal.dot(&ray);
            assert!((layers.depth[k] - z).abs() < 1e-9, "pixel ({i}, {j}): {} vs {z}", layers.depth[k]);
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn points_inside_the_parts_project_onto_their_label_or_something_nearer() {
    // Forward projection (Camera::project: distortion applied to the point) is independent of the
    // renderer's path (undistorted per-pixel rays). Axis points of the handle lie 3 mm inside it,
    // about 2 px at these distances, so the pixel nearest their projection is inside the silhouette.
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 5, 60)).expect("scene");
    let mut checked = 0;
    for frame in [0u64, 20, 40, 59] {
        for camera in 0..scene.config().rig.len() {
            let view = scene.render_view(frame, camera).expect("view");
            let t = Scene::seconds(view.timestamp_ns);
            let pose = scene.trajectory().state_at(t).tool_to_world;
            let cam = &scene.config().rig.cameras[camera];
            for k in 1..40 {
                let p = pose * Point3::new(-0.125 + 0.003 * k as f64, 0.0, 0.0);
                let proj = cam.project(&p);
                if !proj.visible {
                    continue;
                }
                let (i, j) = (proj.pixel.x.round() as u32, proj.pixel.y.round() as u32);
                let l = view.mask.get_pixel(i, j).0[0];
                let depth_mm = f64::from(view.depth.get_pixel(i, j).0[0]);
                let own_mm = cam.world_to_camera(&p).z * 1000.0;
                assert!(
                    l == label::SCALPEL || (l == label::HAND && depth_mm < own_mm),
                    "frame {frame} camera {camera}: handle axis point {k} lands on label {l} at ({i}, {j})"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn rendering_is_deterministic_for_a_seed() {
    let a = Scene::new(SceneConfig::new(SceneKind::Hard, 11, 4)).expect("scene");
    let b = Scene::new(SceneConfig::new(SceneKind::Hard, 11, 4)).expect("scene");
    let c = Scene::new(SceneConfig::new(SceneKind::Hard, 12, 4)).expect("scene");
    let (va, vb, vc) = (a.render_view(2, 1), b.render_view(2, 1), c.render_view(2, 1));
    let (va, vb, vc) = (va.expect("view"), vb.expect("view"), vc.expect("view"));
    assert_eq!(va.image, vb.image);
    assert_eq!(va.mask, vb.mask);
    assert_eq!(va.timestamp_ns, vb.timestamp_ns);
    assert_ne!(va.image, vc.image);
}

#[test]
fn a_synthetic_dataset_reads_back_with_its_drops_jitter_and_truth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("hard");
    let mut config = SceneConfig::new(SceneKind::Hard, 3, 30);
    config.rig.cameras = config.rig.cameras.iter().map(|c| c.scaled(0.25)).collect();
    let scene = Scene::new(config).expect("scene");
    let summary = synthesize(&scene, &out, "hard-test", false, &|| {}).expect("synthesize");
    assert!(summary.dropped_views > 0, "the hard scene drops frames");
    assert_eq!(summary.views + summary.dropped_views, 30 * 6);

    let ds = Dataset::open(&out).expect("open");
    assert_eq!(ds.meta().frame_count, 30);
    assert_eq!(ds.dropped().len(), summary.dropped_views);
    assert!(ds.dropped().iter().all(|d| d.camera == 4), "only camera 4 drops");
    let poses = ds.truth_poses().expect("poses").expect("truth present");
    assert_eq!(poses.len(), 30);
    let tool = ds.tool().expect("tool").expect("tool.json present");
    assert_eq!(tool.cutting_edge, scene.scalpel().geometry.cutting_edge);
    for frame in [0u64, 11, 29] {
        let set = ds.read_frame_set(frame, true).expect("frame set");
        for (camera, view) in set.views.iter().enumerate() {
            let rendered = scene.render_view(frame, camera);
            match (view, rendered) {
                (Some(v), Some(r)) => {
                    assert_eq!(v.image, r.image, "frame {frame} camera {camera}");
                    assert_eq!(v.mask.as_ref(), Some(&r.mask));
                    assert_eq!(v.timestamp_ns, r.timestamp_ns);
                }
                (None, None) => {}
                (v, r) => panic!("frame {frame} camera {camera}: read {} vs rendered {}", v.is_some(), r.is_some()),
            }
        }
        assert_eq!(poses[frame as usize].timestamp_ns, set.timestamp_ns, "truth is at the frame set's time");
    }
    // Timestamps: nominal period plus a per-camera offset (±0.4 ms) and jitter (σ = 150 µs).
    let period = 1e9 / 30.0;
    for camera in 0..6 {
        let dev: Vec<f64> = (0..30)
            .filter_map(|f| ds.timestamp(f, camera).map(|t| (t - hullcut_synth::START_NS) as f64 - f as f64 * period))
            .collect();
        let mean = dev.iter().sum::<f64>() / dev.len() as f64;
        let sd = (dev.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / dev.len() as f64).sqrt();
        assert!(mean.abs() < 0.5e6 && (50e3..300e3).contains(&sd), "camera {camera}: offset {mean} ns, jitter {sd} ns");
    }
}

#[test]
fn an_existing_output_is_refused_and_nothing_half_written_remains() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("ds");
    std::fs::create_dir(&out).expect("mkdir");
    let mut config = SceneConfig::new(SceneKind::Static, 1, 2);
    config.rig.cameras = config.rig.cameras.iter().map(|c| c.scaled(0.25)).collect();
    let scene = Scene::new(config).expect("scene");
    let err = synthesize(&scene, &out, "x", false, &|| {}).expect_err("exists");
    assert!(err.to_string().contains("ds"), "{err}");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).expect("read_dir").collect();
    assert_eq!(leftovers.len(), 1, "only the pre-existing folder");
    synthesize(&scene, &out, "x", true, &|| {}).expect("--force replaces");
    assert!(Dataset::open(&out).is_ok());
}

/// Without depth maps and truth meshes (`hullcut run`'s built-in scene, `hullcut synth --no-depth
/// --no-truth-meshes`) a recording holds the same images, masks, times and true poses, in fewer
/// bytes, and reads back: neither folder is written.
#[test]
fn without_depth_maps_and_truth_meshes_the_recording_is_the_same_and_smaller() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut config = SceneConfig::new(SceneKind::Cut, 5, 3);
    config.rig.cameras = config.rig.cameras.iter().map(|c| c.scaled(0.25)).collect();
    let full = Scene::new(config.clone()).expect("scene");
    (config.truth_meshes, config.depth_maps) = (false, false);
    let lean = Scene::new(config).expect("scene");
    let (a, b) = (dir.path().join("full"), dir.path().join("lean"));
    synthesize(&full, &a, "full", false, &|| {}).expect("synthesize");
    synthesize(&lean, &b, "lean", false, &|| {}).expect("synthesize");
    assert!(a.join("depth").is_dir() && a.join("truth/meshes").is_dir());
    assert!(!b.join("depth").exists() && !b.join("truth/meshes").exists());
    assert!(bytes_under(&b) < bytes_under(&a), "{} bytes against {}", bytes_under(&b), bytes_under(&a));
    let (da, db) = (Dataset::open(&a).expect("open"), Dataset::open(&b).expect("open"));
    assert_eq!(da.truth_poses().expect("poses"), db.truth_poses().expect("poses"));
    for frame in 0..3 {
        let (sa, sb) = (da.read_frame_set(frame, true).expect("set"), db.read_frame_set(frame, true).expect("set"));
        assert_eq!(sa.timestamp_ns, sb.timestamp_ns);
        for (va, vb) in sa.views.iter().zip(&sb.views) {
            let (va, vb) = (va.as_ref().expect("view"), vb.as_ref().expect("view"));
            assert_eq!((&va.image, &va.mask), (&vb.image, &vb.mask), "frame {frame} camera {}", va.camera);
        }
    }
}

/// The bytes of the files under `dir`, at any depth.
fn bytes_under(dir: &std::path::Path) -> u64 {
    std::fs::read_dir(dir)
        .expect("read_dir")
        .flatten()
        .map(|e| if e.path().is_dir() { bytes_under(&e.path()) } else { e.metadata().map_or(0, |m| m.len()) })
        .sum()
}
