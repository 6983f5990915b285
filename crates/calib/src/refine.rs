//! Joint refinement of every camera's intrinsics and pose and every board pose (bundle adjustment
//! over all cameras and views), by Levenberg–Marquardt on the reprojection error.
//!
//! The root camera's pose is held at the identity (it fixes the gauge). Jacobians are central
//! finite differences per (camera, view) block; the normal equations are accumulated block by block,
//! so memory grows with the number of parameters squared, not with the number of corners.

use hullcut_rig::{Camera, Distortion};
use nalgebra::{DMatrix, DVector, Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

/// Intrinsic parameters per camera in the refinement: fx, fy, cx, cy, k1, k2, p1, p2, k3.
const INTRINSICS: usize = 9;
/// Finite-difference steps for the intrinsic parameters (pixels for fx..cy, unitless for k, p).
const INTRINSIC_STEPS: [f64; INTRINSICS] = [1e-4, 1e-4, 1e-4, 1e-4, 1e-7, 1e-7, 1e-8, 1e-8, 1e-7];
/// Finite-difference step for pose parameters (radians, metres).
const POSE_STEP: f64 = 1e-7;

/// Settings of the refinement.
#[derive(Debug, Clone, Copy)]
pub struct RefineParams {
    /// Also refine focal lengths, principal points and distortion (else only poses).
    pub intrinsics: bool,
    /// Largest number of Levenberg–Marquardt iterations.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub relative_tolerance: f64,
}

impl Default for RefineParams {
    fn default() -> Self {
        Self { intrinsics: true, max_iterations: 100, relative_tolerance: 1e-10 }
    }
}

/// How the refinement went.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineSummary {
    /// Iterations taken.
    pub iterations: usize,
    /// RMS reprojection error before, pixels.
    pub initial_rms_px: f64,
    /// RMS reprojection error after, pixels.
    pub final_rms_px: f64,
    /// Whether it stopped on the tolerance (not on the iteration limit).
    pub converged: bool,
}

/// The state being refined: cameras with poses relative to the root, and board poses (board → root).
#[derive(Debug, Clone)]
pub struct BundleState {
    /// Cameras; `rotation`/`translation` map root-frame points into each camera.
    pub cameras: Vec<Camera>,
    /// Board → root-frame pose per view (`None` where no camera saw it).
    pub boards: Vec<Option<Isometry3<f64>>>,
}

/// One (camera, view) observation: the corners seen.
#[derive(Debug, Clone, Copy)]
pub struct Obs<'a> {
    /// Camera index.
    pub camera: usize,
    /// View index.
    pub view: usize,
    /// Detected corners, pixels.
    pub corners: &'a [Point2<f64>],
}

pub(crate) fn camera_pose(c: &Camera) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(c.translation), UnitQuaternion::from_rotation_matrix(&c.rotation))
}

pub(crate) fn set_camera_pose(c: &mut Camera, pose: &Isometry3<f64>) {
    c.rotation = pose.rotation.to_rotation_matrix();
    c.translation = pose.translation.vector;
}

fn intrinsics_of(c: &Camera) -> [f64; INTRINSICS] {
    let d = c.distortion;
    [c.fx, c.fy, c.cx, c.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
}

fn set_intrinsics(c: &mut Camera, p: &[f64; INTRINSICS]) {
    c.fx = p[0];
    c.fy = p[1];
    c.cx = p[2];
    c.cy = p[3];
    c.distortion = Distortion { k1: p[4], k2: p[5], p1: p[6], p2: p[7], k3: p[8] };
}

/// Applies a 6-vector increment (rotation vector, translation) on the left: `exp(ω) · T + t`.
fn perturb(pose: &Isometry3<f64>, d: &[f64]) -> Isometry3<f64> {
    let rot = UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2]));
    let r = rot * pose.rotation;
    let t = rot * pose.translation.vector + Vector3::new(d[3], d[4], d[5]);
    Isometry3::from_parts(Translation3::from(t), r)
}

/// Residuals (projected − observed, pixels) of one observation.
fn residuals(
    cam: &Camera,
    cam_pose: &Isometry3<f64>,
    board: &Isometry3<f64>,
    object: &[Point3<f64>],
    seen: &[Point2<f64>],
    out: &mut [f64],
) {
    let t = cam_pose * board;
    for (k, (x, p)) in object.iter().zip(seen).enumerate() {
        let pc = t * x;
        let q = cam.project_camera_point(&pc);
        out[2 * k] = q.x - p.x;
        out[2 * k + 1] = q.y - p.y;
    }
}

/// Sum of squared residuals and number of residual pairs over all observations.
pub fn cost(state: &BundleState, object: &[Point3<f64>], obs: &[Obs]) -> (f64, usize) {
    let mut r = vec![0.0; 2 * object.len()];
    let mut sum = 0.0;
    let mut n = 0;
    for o in obs {
        let Some(board) = &state.boards[o.view] else { continue };
        let cam = &state.cameras[o.camera];
        residuals(cam, &camera_pose(cam), board, object, o.corners, &mut r);
        sum += r.iter().map(|x| x * x).sum::<f64>();
        n += o.corners.len();
    }
    (sum, n)
}

/// RMS reprojection error (pixels) of each observation, in the order given.
pub fn observation_rms(state: &BundleState, object: &[Point3<f64>], obs: &[Obs]) -> Vec<f64> {
    let mut r = vec![0.0; 2 * object.len()];
    obs.iter()
        .map(|o| {
            let Some(board) = &state.boards[o.view] else { return f64::NAN };
            let cam = &state.cameras[o.camera];
            residuals(cam, &camera_pose(cam), board, object, o.corners, &mut r);
            (r.iter().map(|x| x * x).sum::<f64>() / o.corners.len() as f64).sqrt()
        })
        .collect()
}

/// Parameter layout: intrinsics of every camera, then poses of non-root cameras, then board poses.
struct Layout {
    intrinsics: bool,
    cameras: usize,
    root: usize,
    views: usize,
}

impl Layout {
    fn intrinsic_offset(&self, c: usize) -> Option<usize> {
        self.intrinsics.then_some(c * INTRINSICS)
    }
    fn pose_offset(&self, c: usize) -> Option<usize> {
        if c == self.root {
            return None;
        }
        let base = if self.intrinsics { self.cameras * INTRINSICS } else { 0 };
        Some(base + 6 * if c > self.root { c - 1 } else { c })
    }
    fn view_offset(&self, v: usize) -> usize {
        let base = if self.intrinsics { self.cameras * INTRINSICS } else { 0 };
        base + 6 * (self.cameras - 1) + 6 * v
    }
    fn len(&self) -> usize {
        self.view_offset(self.views)
    }
}

/// Refines `state` in place; `root` is the camera whose pose stays fixed.
pub fn refine(
    state: &mut BundleState,
    root: usize,
    object: &[Point3<f64>],
    obs: &[Obs],
    params: &RefineParams,
) -> RefineSummary {
    let layout =
        Layout { intrinsics: params.intrinsics, cameras: state.cameras.len(), root, views: state.boards.len() };
    let n = layout.len();
    let (mut current, count) = cost(state, object, obs);
    let rms = |c: f64| (c / count.max(1) as f64).sqrt();
    let initial_rms_px = rms(current);
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut iterations = 0;
    let m = 2 * object.len();
    let mut r0 = vec![0.0; m];
    let mut rp = vec![0.0; m];
    let mut rm = vec![0.0; m];
    while iterations < params.max_iterations {
        iterations += 1;
        let mut h = DMatrix::<f64>::zeros(n, n);
        let mut g = DVector::<f64>::zeros(n);
        for o in obs {
            let Some(board) = state.boards[o.view] else { continue };
            let cam = &state.cameras[o.camera];
            let pose = camera_pose(cam);
            residuals(cam, &pose, &board, object, o.corners, &mut r0);
            // Columns of this block's Jacobian, with their global parameter index.
            let mut cols: Vec<(usize, Vec<f64>)> = Vec::with_capacity(INTRINSICS + 12);
            let column = |rp: &[f64], rm: &[f64], h: f64| -> Vec<f64> {
                rp.iter().zip(rm).map(|(a, b)| (a - b) / (2.0 * h)).collect()
            };
            if let Some(off) = layout.intrinsic_offset(o.camera) {
                let base = intrinsics_of(cam);
                for (i, step) in INTRINSIC_STEPS.iter().enumerate() {
                    let mut c2 = cam.clone();
                    let mut p = base;
                    p[i] += step;
                    set_intrinsics(&mut c2, &p);
                    residuals(&c2, &pose, &board, object, o.corners, &mut rp);
                    p[i] -= 2.0 * step;
                    set_intrinsics(&mut c2, &p);
                    residuals(&c2, &pose, &board, object, o.corners, &mut rm);
                    cols.push((off + i, column(&rp, &rm, *step)));
                }
            }
            if let Some(off) = layout.pose_offset(o.camera) {
                for i in 0..6 {
                    let mut d = [0.0; 6];
                    d[i] = POSE_STEP;
                    residuals(cam, &perturb(&pose, &d), &board, object, o.corners, &mut rp);
                    d[i] = -POSE_STEP;
                    residuals(cam, &perturb(&pose, &d), &board, object, o.corners, &mut rm);
                    cols.push((off + i, column(&rp, &rm, POSE_STEP)));
                }
            }
            let off = layout.view_offset(o.view);
            for i in 0..6 {
                let mut d = [0.0; 6];
                d[i] = POSE_STEP;
                residuals(cam, &pose, &perturb(&board, &d), object, o.corners, &mut rp);
                d[i] = -POSE_STEP;
                residuals(cam, &pose, &perturb(&board, &d), object, o.corners, &mut rm);
                cols.push((off + i, column(&rp, &rm, POSE_STEP)));
            }
            for (a, ja) in &cols {
                g[*a] += ja.iter().zip(&r0).map(|(x, y)| x * y).sum::<f64>();
                for (b, jb) in &cols {
                    h[(*a, *b)] += ja.iter().zip(jb).map(|(x, y)| x * y).sum::<f64>();
                }
            }
        }
        // Unobserved parameters (views nobody saw) get a unit diagonal so the system stays regular.
        for i in 0..n {
            if h[(i, i)] == 0.0 {
                h[(i, i)] = 1.0;
            }
        }
        let mut accepted = false;
        while lambda < 1e12 {
            let mut a = h.clone();
            for i in 0..n {
                a[(i, i)] += lambda * h[(i, i)];
            }
            let Some(chol) = a.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&g));
            let candidate = apply(state, &layout, &delta);
            let (c, _) = cost(&candidate, object, obs);
            if c.is_finite() && c < current {
                let gain = (current - c) / current.max(f64::MIN_POSITIVE);
                *state = candidate;
                current = c;
                lambda = (lambda * 0.3).max(1e-12);
                accepted = true;
                if gain < params.relative_tolerance {
                    converged = true;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !accepted {
            // No step lowers the cost: we are at a minimum to machine precision.
            converged = true;
        }
        if converged {
            break;
        }
    }
    RefineSummary { iterations, initial_rms_px, final_rms_px: rms(current), converged }
}

fn apply(state: &BundleState, layout: &Layout, delta: &DVector<f64>) -> BundleState {
    let mut next = state.clone();
    for (c, cam) in next.cameras.iter_mut().enumerate() {
        if let Some(off) = layout.intrinsic_offset(c) {
            let mut p = intrinsics_of(cam);
            for (i, v) in p.iter_mut().enumerate() {
                *v += delta[off + i];
            }
            set_intrinsics(cam, &p);
        }
        if let Some(off) = layout.pose_offset(c) {
            let pose = perturb(&camera_pose(cam), &delta.as_slice()[off..off + 6]);
            set_camera_pose(cam, &pose);
        }
    }
    for (v, board) in next.boards.iter_mut().enumerate() {
        if let Some(b) = board {
            let off = layout.view_offset(v);
            *b = perturb(b, &delta.as_slice()[off..off + 6]);
        }
    }
    next
}
