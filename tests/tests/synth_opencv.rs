//! The renderer checked against an independent computation: mesh vertices projected with OpenCV's
//! `projectPoints` land on pixels the renderer labelled as that object (or on something nearer).

use hullcut_dataset::label;
use hullcut_synth::{Part, Scene, SceneConfig, SceneKind};

use nalgebra::Point3;
use opencv::calib3d;
use opencv::core::{Mat, Point2d, Point3d, Vector};
use opencv::prelude::*;

fn project_points(cam: &hullcut_rig::Camera, points: &[Point3<f64>]) -> Vec<Point2d> {
    let obj: Vector<Point3d> = points.iter().map(|p| Point3d::new(p.x, p.y, p.z)).collect();
    let rvec = Mat::from_slice(cam.rotation.scaled_axis().as_slice()).and_then(|m| m.try_clone()).expect("rvec");
    let tvec = Mat::from_slice(cam.translation.as_slice()).and_then(|m| m.try_clone()).expect("tvec");
    let k = Mat::from_slice_2d(&[[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]]).expect("K");
    let d = Mat::from_slice(&cam.distortion.to_array()).and_then(|m| m.try_clone()).expect("D");
    let mut out = Vector::<Point2d>::new();
    calib3d::project_points_def(&obj, &rvec, &tvec, &k, &d, &mut out).expect("projectPoints");
    out.to_vec()
}

#[test]
fn vertices_projected_by_opencv_land_on_their_object() {
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 2, 90)).expect("scene");
    let (mut hits, mut occluded) = (0usize, 0usize);
    for frame in [0u64, 30, 45, 60, 89] {
        for (camera, cam) in scene.config().rig.cameras.iter().enumerate() {
            let view = scene.render_view(frame, camera).expect("no drops in the cut scene");
            let parts: Vec<Part> = scene.parts_at(Scene::seconds(view.timestamp_ns));
            // The hand's vertices (smooth capsules and ellipsoids: near a silhouette the surface is
            // locally a half-plane, so a pixel centre within 1 px of a vertex's projection lies
            // inside). The handle is a box whose silhouette corners can be too acute for that, so
            // its face centres stand in for its vertices. The 0.4 mm blade is thinner than a
            // pixel edge-on and may cover no pixel centre at all: it is left out.
            let pose = scene.trajectory().state_at(Scene::seconds(view.timestamp_ns)).tool_to_world;
            let h = hullcut_synth::HANDLE_LENGTH;
            let (w, t) = (hullcut_synth::HANDLE_WIDTH / 2.0, hullcut_synth::HANDLE_THICKNESS / 2.0);
            let mut handle_points = Vec::new();
            for k in 1..26 {
                let x = -h * k as f64 / 26.0;
                for (y, z) in [(w, 0.0), (-w, 0.0), (0.0, t), (0.0, -t)] {
                    handle_points.push(pose * Point3::new(x, y, z));
                }
            }
            let hand =
                parts.iter().find(|p| p.label == label::HAND).map(|p| p.mesh.vertices.clone()).unwrap_or_default();
            for (object, points) in [(label::HAND, hand), (label::SCALPEL, handle_points)] {
                let projected = project_points(cam, &points);
                for (v, q) in points.iter().zip(&projected) {
                    let (i, j) = (q.x.round() as i64, q.y.round() as i64);
                    if i < 1 || j < 1 || i >= cam.width as i64 - 1 || j >= cam.height as i64 - 1 {
                        continue;
                    }
                    let own_mm = cam.world_to_camera(v).z * 1000.0;
                    // A vertex lies on the surface: the pixel centres around its projection
                    // (within 1 px) include one inside the object's silhouette, unless something
                    // nearer covers it there.
                    let mut found = false;
                    for dj in -1..=1 {
                        for di in -1..=1 {
                            found |= view.mask.get_pixel((i + di) as u32, (j + dj) as u32).0[0] == object;
                        }
                    }
                    // Depth is stored in whole millimetres.
                    let centre_mm = f64::from(view.depth.get_pixel(i as u32, j as u32).0[0]);
                    if found {
                        hits += 1;
                    } else {
                        assert!(
                            centre_mm > 0.0 && centre_mm < own_mm - 0.5,
                            "frame {frame} {}: label {object} point {v:?} at ({i}, {j}) is neither drawn nor hidden",
                            cam.name
                        );
                        occluded += 1;
                    }
                }
            }
        }
    }
    assert!(hits > 10_000, "{hits} vertices checked ({occluded} hidden)");
}
