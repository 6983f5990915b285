//! Fitting the template to the silhouettes: a six-parameter Levenberg–Marquardt over the tool's
//! pose with two kinds of residual per view, both in pixels:
//!
//! - *outline*: every sampled pixel of the scalpel silhouette's outline against the background
//!   (outlines against the hand are where the hand hides the tool, not the tool's edge) should lie
//!   on the outline of the projected tool (the union of the projected blade polygon and the
//!   convex hull of the projected body); the residual is the signed distance;
//! - *cover*: every interior point of the tool should project onto foreground (scalpel, hand or
//!   unknown: the hand may hide the tool); the residual is the distance transform there.
//!
//! The first places the tool's outline on the silhouettes' (a chamfer match from the data to the
//! model), the second keeps it from covering background; together they fix the blade's plane from
//! its projected width in the views that see it face-on and its line in those that see it
//! edge-on. Residuals are Huber-weighted (one bad pixel cannot pull far).

use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};

use crate::evidence::ViewEvidence;
use crate::geometry::{convex_hull, signed_distance_convex};
use crate::template::Template;

/// Huber threshold, pixels.
const HUBER_PX: f64 = 2.0;
/// A pixel counts as explained (a point as covered) within this distance, pixels.
pub(crate) const AGREE_PX: f64 = 1.5;
/// Sine of the angle within which a blade counts as edge-on to a view (15 degrees).
const EDGE_ON_SIN: f64 = 0.2588;
/// Forward-difference steps: radians, metres.
const STEP_ROTATION: f64 = 1e-4;
const STEP_TRANSLATION: f64 = 1e-5;

/// The result of a fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fit {
    /// Tool → world.
    pub pose: Isometry3<f64>,
    /// Sum of squared robust residuals.
    pub cost: f64,
    /// Levenberg–Marquardt iterations taken.
    pub iterations: usize,
    /// Fraction of sampled outline pixels within [`AGREE_PX`] of the projected tool's outline.
    pub explained: f64,
    /// Fraction of the tool's projected interior points within [`AGREE_PX`] of foreground.
    pub covered: f64,
    /// Root mean square of the raw residuals, pixels.
    pub rms_px: f64,
}

/// Residual bookkeeping of one evaluation.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    samples: usize,
    explained: usize,
    points: usize,
    covered: usize,
    sum_sq: f64,
}

/// The pose moved by a twist: rotation `w` (axis-angle, world) about `pivot`, then translation `v`.
pub(crate) fn moved(pose: &Isometry3<f64>, pivot: &Point3<f64>, w: &Vector3<f64>, v: &Vector3<f64>) -> Isometry3<f64> {
    let r = UnitQuaternion::from_scaled_axis(*w);
    let to = Translation3::from(pivot.coords + v);
    let back = Translation3::from(-pivot.coords);
    Isometry3::from_parts(to, r) * Isometry3::from_parts(back, UnitQuaternion::identity()) * pose
}

fn huber(r: f64) -> f64 {
    let a = r.abs();
    if a <= HUBER_PX { r } else { r.signum() * (2.0 * HUBER_PX * a - HUBER_PX * HUBER_PX).sqrt() }
}

/// Evaluates the residuals of a pose (robust, pixels) into `out` (always the same count for the
/// same views), returning the raw tally.
fn residuals(template: &Template, views: &[ViewEvidence], pose: &Isometry3<f64>, out: &mut Vec<f64>) -> Tally {
    out.clear();
    let mut tally = Tally::default();
    let mut blade_px = Vec::with_capacity(template.blade.len());
    let mut body_px = Vec::with_capacity(template.body.len());
    for view in views {
        blade_px.clear();
        body_px.clear();
        blade_px.extend(template.blade.iter().filter_map(|p| view.project(&(pose * p))));
        body_px.extend(template.body.iter().filter_map(|p| view.project(&(pose * p))));
        let blade = convex_hull(&blade_px);
        let body = convex_hull(&body_px);
        for s in &view.samples {
            let sd = signed_distance_convex(&blade, s).min(signed_distance_convex(&body, s));
            let d = if sd.is_finite() { sd } else { 1e3 };
            tally.samples += 1;
            tally.explained += usize::from(d.abs() <= AGREE_PX);
            tally.sum_sq += d * d;
            out.push(huber(d));
        }
        // A blade seen nearly edge-on projects thinner than a pixel: its silhouette may be a
        // broken line or nothing, so its interior says nothing about where it is.
        let sight = (pose * template.blade_centre - view.camera.centre()).normalize();
        let thin = (pose * template.normal).dot(&sight).abs() < EDGE_ON_SIN;
        for (k, p) in template.interior.iter().enumerate() {
            let skip = thin && k < template.blade_interior;
            let d = match view.project(&(pose * p)).filter(|_| !skip) {
                Some(uv) => {
                    let d = view.outside_foreground(&uv);
                    tally.points += 1;
                    tally.covered += usize::from(d <= AGREE_PX);
                    tally.sum_sq += d * d;
                    d
                }
                None => 0.0,
            };
            out.push(huber(d));
        }
    }
    tally
}

fn fraction(k: usize, n: usize) -> f64 {
    if n == 0 { 0.0 } else { k as f64 / n as f64 }
}

/// Cost of a pose without fitting.
pub(crate) fn cost(template: &Template, views: &[ViewEvidence], pose: &Isometry3<f64>) -> f64 {
    let mut r = Vec::new();
    residuals(template, views, pose, &mut r);
    r.iter().map(|x| x * x).sum()
}

/// Levenberg–Marquardt from `start`, at most `max_iterations`.
pub(crate) fn fit(template: &Template, views: &[ViewEvidence], start: &Isometry3<f64>, max_iterations: usize) -> Fit {
    let mut pose = *start;
    let mut r = Vec::new();
    let mut tally = residuals(template, views, &pose, &mut r);
    let mut cost: f64 = r.iter().map(|x| x * x).sum();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut rp = Vec::new();
    let mut jac: Vec<Vec<f64>> = vec![Vec::new(); 6];
    while iterations < max_iterations && !r.is_empty() {
        iterations += 1;
        let pivot = pose * template.blade_centre;
        for (k, col) in jac.iter_mut().enumerate() {
            let mut w = Vector3::zeros();
            let mut v = Vector3::zeros();
            let h = if k < 3 { STEP_ROTATION } else { STEP_TRANSLATION };
            if k < 3 {
                w[k] = h;
            } else {
                v[k - 3] = h;
            }
            residuals(template, views, &moved(&pose, &pivot, &w, &v), &mut rp);
            col.clear();
            col.extend(rp.iter().zip(&r).map(|(a, b)| (a - b) / h));
        }
        let mut a = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        for i in 0..6 {
            g[i] = jac[i].iter().zip(&r).map(|(j, r)| j * r).sum();
            for k in i..6 {
                let s: f64 = jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum();
                a[(i, k)] = s;
                a[(k, i)] = s;
            }
        }
        let mut improved = false;
        for _ in 0..6 {
            let mut damped = a;
            for i in 0..6 {
                damped[(i, i)] += lambda * a[(i, i)].max(1e-9);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
                lambda *= 10.0;
                continue;
            };
            let w = Vector3::new(step[0], step[1], step[2]);
            let v = Vector3::new(step[3], step[4], step[5]);
            let candidate = moved(&pose, &pivot, &w, &v);
            let t = residuals(template, views, &candidate, &mut rp);
            let c: f64 = rp.iter().map(|x| x * x).sum();
            if c < cost {
                let small = w.norm() < 1e-6 && v.norm() < 1e-7;
                pose = candidate;
                std::mem::swap(&mut r, &mut rp);
                tally = t;
                let gain = cost - c;
                cost = c;
                lambda = (lambda / 3.0).max(1e-7);
                improved = !small && gain > 1e-9 * cost.max(1.0);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    let n = tally.samples + tally.points;
    Fit {
        pose,
        cost,
        iterations,
        explained: fraction(tally.explained, tally.samples),
        covered: fraction(tally.covered, tally.points),
        rms_px: if n == 0 { 0.0 } else { (tally.sum_sq / n as f64).sqrt() },
    }
}
