//! The whole calibration: intrinsics per camera, spanning-tree extrinsics, joint refinement, world frame.

use hullcut_rig::{Rig, WorldFrame};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::extrinsics::initial_poses;
use crate::refine::{BundleState, Obs, RefineParams, observation_rms, refine, set_camera_pose};
use crate::report::{CalibReport, CameraReport, ImageReport, PairReport, TreeEdgeReport};
use crate::{CalibError, Observations, Pattern, calibrate_intrinsics};

/// Settings of [`calibrate`].
#[derive(Debug, Clone, Copy)]
pub struct CalibParams {
    /// The joint refinement.
    pub refine: RefineParams,
    /// Fewest board views a camera needs for its intrinsics (OpenCV needs 3 for Zhang's method to be
    /// well posed with 5 distortion coefficients; more is better).
    pub min_views: usize,
    /// An image is flagged as an outlier when its RMS error exceeds this many times the median
    /// image RMS (and 0.5 px, so a uniformly excellent calibration flags nothing).
    pub outlier_factor: f64,
}

impl Default for CalibParams {
    fn default() -> Self {
        Self { refine: RefineParams::default(), min_views: 3, outlier_factor: 3.0 }
    }
}

/// A calibrated rig with what was measured.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The rig, in the chosen world frame.
    pub rig: Rig,
    /// Board → world pose per view (`None` where no camera saw the board).
    pub boards: Vec<Option<Isometry3<f64>>>,
    /// Accuracy per camera, pair and image.
    pub report: CalibReport,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 { v[m] } else { 0.5 * (v[m - 1] + v[m]) }
}

/// Board frame → world frame for a board lying on the table: x along the board's rows, z toward the
/// cameras. OpenCV's board frame has z pointing away from the cameras that see it, so the world is
/// the board frame turned 180° about x unless the cameras already lie on the board's +z side.
fn table_frame(cameras: &[Isometry3<f64>], board: &Isometry3<f64>) -> Isometry3<f64> {
    let above = cameras.iter().map(|c| (board.inverse() * c.inverse() * Point3::origin()).z).sum::<f64>();
    let flip = if above > 0.0 {
        UnitQuaternion::identity()
    } else {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    };
    // world → board-on-table frame, expressed as board → world's inverse.
    board * Isometry3::from_parts(Translation3::identity(), flip)
}

/// Calibrates a rig from detected corners.
///
/// `world_board` names a view (file name) showing a board lying on the table; the world frame is
/// then that board's (origin at its first inner corner, x along its rows, z up toward the
/// cameras). Without one, camera 0's frame is the world.
pub fn calibrate(
    obs: &Observations,
    pattern: &Pattern,
    world_board: Option<&str>,
    params: &CalibParams,
) -> Result<Calibration, CalibError> {
    let n = obs.cameras.len();
    let object = pattern.object_points();
    // Intrinsics per camera (OpenCV), in parallel.
    let fits = (0..n)
        .into_par_iter()
        .map(|c| {
            let used: Vec<usize> = (0..obs.views.len()).filter(|&v| obs.corners[c][v].is_some()).collect();
            if used.len() < params.min_views {
                return Err(CalibError::TooFewViews {
                    camera: obs.cameras[c].clone(),
                    found: used.len(),
                    needed: params.min_views,
                    cols: pattern.cols,
                    rows: pattern.rows,
                });
            }
            let views: Vec<&[_]> = used.iter().filter_map(|&v| obs.corners[c][v].as_deref()).collect();
            let fit = calibrate_intrinsics(&obs.cameras[c], obs.image_sizes[c], &object, &views)?;
            let mut per_view = vec![None; obs.views.len()];
            for (&v, p) in used.iter().zip(&fit.board_poses) {
                per_view[v] = Some(*p);
            }
            Ok((fit, per_view))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let board_in_camera: Vec<_> = fits.iter().map(|(_, p)| p.clone()).collect();
    let init =
        initial_poses(&board_in_camera, 0).map_err(|c| CalibError::Disconnected { camera: obs.cameras[c].clone() })?;
    let mut state = BundleState {
        cameras: fits
            .iter()
            .zip(&init.cameras)
            .map(|((fit, _), pose)| {
                let mut cam = fit.camera.clone();
                set_camera_pose(&mut cam, pose);
                cam
            })
            .collect(),
        boards: init.boards.clone(),
    };
    let observations: Vec<Obs> = (0..n)
        .flat_map(|c| (0..obs.views.len()).map(move |v| (c, v)))
        .filter_map(|(c, v)| obs.corners[c][v].as_deref().map(|corners| Obs { camera: c, view: v, corners }))
        .collect();
    let summary = refine(&mut state, 0, &object, &observations, &params.refine);
    tracing::info!(
        iterations = summary.iterations,
        initial_rms_px = summary.initial_rms_px,
        final_rms_px = summary.final_rms_px,
        "joint refinement"
    );

    // World frame.
    let (world_from_root, world_frame) = match world_board {
        None => (Isometry3::identity(), WorldFrame::Camera0),
        Some(name) => {
            let v = obs.views.iter().position(|x| x == name).ok_or_else(|| CalibError::WorldBoard {
                image: name.to_owned(),
                reason: "no camera folder holds an image with this name".to_owned(),
            })?;
            let board = state.boards[v].ok_or_else(|| CalibError::WorldBoard {
                image: name.to_owned(),
                reason: "the board was not detected in this view by any camera".to_owned(),
            })?;
            let poses: Vec<_> = state.cameras.iter().map(crate::refine::camera_pose).collect();
            (table_frame(&poses, &board).inverse(), WorldFrame::Board { image: name.to_owned() })
        }
    };
    let root_from_world = world_from_root.inverse();

    // Per-observation errors, then per camera, pair and image.
    let rms = observation_rms(&state, &object, &observations);
    let mut per_obs = vec![vec![None; obs.views.len()]; n];
    for (o, r) in observations.iter().zip(&rms) {
        per_obs[o.camera][o.view] = Some(*r);
    }
    let mean_sq = |items: &[(usize, usize)]| -> f64 {
        let s: Vec<f64> = items.iter().filter_map(|&(c, v)| per_obs[c][v]).map(|r| r * r).collect();
        (s.iter().sum::<f64>() / s.len().max(1) as f64).sqrt()
    };
    let mut cameras = Vec::with_capacity(n);
    for (c, cam) in state.cameras.iter_mut().enumerate() {
        let pose = crate::refine::camera_pose(cam) * root_from_world;
        set_camera_pose(cam, &pose);
        let items: Vec<_> = (0..obs.views.len()).map(|v| (c, v)).collect();
        cam.rms_reprojection_error = Some(mean_sq(&items));
    }
    for (c, cam) in state.cameras.iter().enumerate() {
        let centre = cam.centre();
        let dir = cam.viewing_direction();
        cameras.push(CameraReport {
            name: cam.name.clone(),
            image_width: cam.width,
            image_height: cam.height,
            images: obs.has_image[c].iter().filter(|&&h| h).count(),
            views_detected: obs.detected_count(c),
            rms_intrinsic_px: fits[c].0.rms_px,
            rms_px: cam.rms_reprojection_error.unwrap_or(f64::NAN),
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            distortion: cam.distortion.to_array(),
            centre: [centre.x, centre.y, centre.z],
            viewing_direction: [dir.x, dir.y, dir.z],
        });
    }
    let mut pairs = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let shared = obs.shared_views(a, b);
            if shared.is_empty() {
                continue;
            }
            let items: Vec<_> = shared.iter().flat_map(|&v| [(a, v), (b, v)]).collect();
            pairs.push(PairReport {
                a: obs.cameras[a].clone(),
                b: obs.cameras[b].clone(),
                shared_views: shared.len(),
                rms_px: mean_sq(&items),
                baseline_m: (state.cameras[a].centre() - state.cameras[b].centre()).norm(),
            });
        }
    }
    let mut all: Vec<f64> = rms.clone();
    let med = median(&mut all);
    let threshold = (params.outlier_factor * med).max(0.5);
    let mut images = Vec::new();
    for (c, errors) in per_obs.iter().enumerate() {
        for (v, &r) in errors.iter().enumerate().filter(|&(v, _)| obs.has_image[c][v]) {
            images.push(ImageReport {
                camera: obs.cameras[c].clone(),
                image: obs.views[v].clone(),
                detected: obs.corners[c][v].is_some(),
                rms_px: r,
                outlier: r.is_some_and(|r| r > threshold),
            });
        }
    }
    let boards: Vec<_> = state.boards.iter().map(|b| b.map(|b| world_from_root * b)).collect();
    let all_items: Vec<_> = observations.iter().map(|o| (o.camera, o.view)).collect();
    let report = CalibReport {
        pattern: *pattern,
        world_frame: world_frame.to_key(),
        rms_px: mean_sq(&all_items),
        cameras,
        pairs,
        skipped_images: images.iter().filter(|i| !i.detected).count(),
        outlier_images: images.iter().filter(|i| i.outlier).count(),
        images,
        spanning_tree: init
            .tree
            .iter()
            .map(|e| TreeEdgeReport {
                parent: obs.cameras[e.parent].clone(),
                child: obs.cameras[e.child].clone(),
                shared_views: e.shared_views,
            })
            .collect(),
        refinement: summary,
    };
    Ok(Calibration { rig: Rig::new(state.cameras, world_frame), boards, report })
}
