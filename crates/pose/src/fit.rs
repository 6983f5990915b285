//! Fitting the template to the silhouettes: a six-parameter Levenberg–Marquardt over the tool's
//! pose with two kinds of residual per view, both in pixels:
//!
//! - *outline*: every sampled pixel of the scalpel silhouette's outline against the background
//!   (outlines against the hand are where the hand hides the tool, not the tool's edge) should lie
//!   on the outline of the projected tool (the union of the convex hull of the projected blade,
//!   both its faces, and that of the projected body); the residual is the signed distance;
//! - *cover*: every interior point of the tool should project onto foreground (scalpel, hand or
//!   unknown: the hand may hide the tool); the residual is the distance transform there.
//!
//! The first places the tool's outline on the silhouettes' (a chamfer match from the data to the
//! model), the second keeps it from covering background; together they fix the blade's plane from
//! its projected width in the views that see it face-on and its line in those that see it
//! edge-on. Residuals are Huber-weighted (one bad pixel cannot pull far).
//!
//! A seventh parameter, the *outline offset*, lets the silhouettes be uniformly fatter (or
//! thinner) than the tool by up to [`MAX_OFFSET_PX`]: every outline residual is measured from the
//! projected outline pushed out by the offset. Segmented masks take in a blade's blended edge
//! pixels or lose them, depending on the contrast; a thin blade's pose cannot tell a pixel of
//! width in a view that sees it at a slant from a turn about its long axis, so without the offset
//! one pixel of fattening turns the blade by 5-10°. One offset for all views: a turn about the
//! long axis widens the blade in some views and narrows it in others, a fattening widens it in
//! all, so the two stay apart.

use nalgebra::{Isometry3, Point2, Point3, SMatrix, SVector, Translation3, UnitQuaternion, Vector2, Vector3};

use crate::evidence::{Twist2, ViewEvidence};
use crate::geometry::{Convex, convex_hull_indices};
use crate::template::Template;

/// Huber threshold, pixels.
const HUBER_PX: f64 = 2.0;
/// A pixel counts as explained (a point as covered) within this distance, pixels.
pub(crate) const AGREE_PX: f64 = 1.5;
/// Steps smaller than these end the fit (radians, metres): a micrometre at the blade's size.
const MIN_STEP_ROTATION: f64 = 2e-5;
const MIN_STEP_TRANSLATION: f64 = 1e-6;
/// An outline offset step smaller than this (pixels) counts as none.
const MIN_STEP_OFFSET_PX: f64 = 1e-3;
/// Sine of the angle within which a blade counts as edge-on to a view (15 degrees).
const EDGE_ON_SIN: f64 = 0.2588;
/// The outline offset's bound, pixels: the silhouettes may be this much fatter or thinner than the
/// projected tool all around (a pixel of blended edge, and a half more).
pub(crate) const MAX_OFFSET_PX: f64 = 1.5;

/// The fit's parameters: a twist about the blade's centre (rotation, translation) and the outline
/// offset.
const PARAMS: usize = 7;
/// One residual's derivatives with respect to the parameters.
type Row = [f64; PARAMS];

/// The result of a fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fit {
    /// Tool → world.
    pub pose: Isometry3<f64>,
    /// Sum of squared robust residuals.
    pub cost: f64,
    /// Levenberg–Marquardt iterations taken.
    pub iterations: usize,
    /// How far the fit's turn about the blade's long axis (through the blade's centre) may be
    /// off for a pixel of independent noise on every residual, degrees: the square root of that
    /// turn's entry of the inverse of the last Gauss–Newton normal matrix (pose alone, outline
    /// offset held), which lets the other five parameters follow. Infinite where the views leave
    /// the blade free to turn (the matrix singular).
    pub roll_sd_deg: f64,
    /// Fraction of sampled outline pixels within [`AGREE_PX`] of the projected tool's outline.
    pub explained: f64,
    /// Fraction of the tool's projected interior points within [`AGREE_PX`] of foreground, of
    /// those that fall in their view's image (beyond its edge a view says nothing: a tool whose
    /// handle leaves the frame under the hand is not refused for it).
    pub covered: f64,
    /// Root mean square of the raw residuals, pixels.
    pub rms_px: f64,
    /// The outline offset, pixels: how much fatter (positive) than the projected tool the
    /// silhouettes' outlines are, all around.
    pub offset_px: f64,
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

/// The Huber-weighted residual's derivative with respect to the raw one.
fn huber_slope(r: f64) -> f64 {
    let a = r.abs();
    if a <= HUBER_PX { 1.0 } else { HUBER_PX / (2.0 * HUBER_PX * a - HUBER_PX * HUBER_PX).sqrt() }
}

/// Projected vertices of one part of the tool in one view, with the twist derivatives of its
/// outline's corners.
#[derive(Default)]
struct Outline {
    pixels: Vec<Point2<f64>>,
    /// Per pixel, the part's point it is the projection of.
    sources: Vec<usize>,
    /// Per corner of the outline (`hull`'s order), its derivative; empty where the part was
    /// projected without derivatives.
    jacobians: Vec<Twist2>,
    hull: Vec<usize>,
    vertices: Vec<Point2<f64>>,
    polygon: Convex,
    /// A disc holding the outline: its centre (the corners' mean) and radius (NaN without
    /// corners).
    centre: Point2<f64>,
    radius: f64,
}

impl Outline {
    /// Projects the part's points (`world`: placed by the pose, once for all views), with the
    /// twist derivatives about `pivot` of the outline's corners when given (a pose's cost needs
    /// none). Only the corners' derivatives are used, so only theirs are computed: a corner's
    /// pixel from [`ViewEvidence::project_with_jacobian`] is the one [`ViewEvidence::project`]
    /// gave (the same arithmetic).
    fn project(&mut self, world: &[Point3<f64>], view: &ViewEvidence, pivot: Option<&Point3<f64>>) {
        self.pixels.clear();
        self.sources.clear();
        self.jacobians.clear();
        for (k, p) in world.iter().enumerate() {
            if let Some(uv) = view.project(p) {
                self.pixels.push(uv);
                self.sources.push(k);
            }
        }
        convex_hull_indices(&self.pixels, &mut self.hull);
        self.vertices.clear();
        self.vertices.extend(self.hull.iter().map(|&i| self.pixels[i]));
        self.polygon.set(&self.vertices);
        let n = self.vertices.len() as f64;
        self.centre = Point2::from(self.vertices.iter().map(|v| v.coords).sum::<Vector2<f64>>() / n);
        self.radius = self.vertices.iter().map(|v| (v - self.centre).norm()).fold(f64::NAN, f64::max);
        if let Some(pivot) = pivot {
            for &i in &self.hull {
                let j = view.project_with_jacobian(&world[self.sources[i]], pivot).map_or([[0.0; 6]; 2], |(_, j)| j);
                self.jacobians.push(j);
            }
        }
    }

    /// Whether the signed distance of `q` to the projected part is surely greater than `d`: the
    /// part lies in its disc, so no point of it, inside or out, is nearer than `q`'s distance
    /// to the disc (a micro-pixel of slack for the rounding of [`Outline::distance`]).
    fn beyond(&self, q: &Point2<f64>, d: f64) -> bool {
        (q - self.centre).norm() - self.radius - 1e-6 > d
    }

    /// Signed distance of `q` to the projected part and its twist derivative (zero where the part
    /// was projected without derivatives).
    fn distance(&self, q: &Point2<f64>) -> Option<(f64, [f64; 6])> {
        let near = self.polygon.nearest(q)?;
        if self.jacobians.is_empty() {
            return Some((near.sd, [0.0; 6]));
        }
        let n = self.polygon.len();
        let (ja, jb) = (&self.jacobians[near.edge], &self.jacobians[(near.edge + 1) % n]);
        // Moving the nearest boundary point c = a + t (b - a) by dc changes sd by -normal · dc.
        let mut g = [0.0; 6];
        for (k, gk) in g.iter_mut().enumerate() {
            let dc = Vector2::new(
                (1.0 - near.t) * ja[0][k] + near.t * jb[0][k],
                (1.0 - near.t) * ja[1][k] + near.t * jb[1][k],
            );
            *gk = -near.normal.dot(&dc);
        }
        Some((near.sd, g))
    }
}

/// Evaluates the residuals of a pose (robust, pixels) into `out` (always the same count for the
/// same views) and, with `jacobian`, their derivatives with respect to a twist about the blade's
/// centre (one row per residual); returns the raw tally.
///
/// The views are split in two halves evaluated on two threads (rayon).
fn residuals(
    template: &Template,
    views: &[ViewEvidence],
    pose: &Isometry3<f64>,
    offset_px: f64,
    out: &mut Vec<f64>,
    jacobian: Option<&mut Vec<Row>>,
) -> Tally {
    let with_jacobian = jacobian.is_some();
    let part = |views: &[ViewEvidence]| {
        let (mut r, mut j) = (Vec::new(), Vec::new());
        let t = residuals_of(template, views, pose, offset_px, &mut r, with_jacobian.then_some(&mut j));
        (r, j, t)
    };
    let mid = views.len() / 2;
    let ((r0, j0, t0), (r1, j1, t1)) = rayon::join(|| part(&views[..mid]), || part(&views[mid..]));
    out.clear();
    out.extend(r0);
    out.extend(r1);
    if let Some(j) = jacobian {
        j.clear();
        j.extend(j0);
        j.extend(j1);
    }
    Tally {
        samples: t0.samples + t1.samples,
        explained: t0.explained + t1.explained,
        points: t0.points + t1.points,
        covered: t0.covered + t1.covered,
        sum_sq: t0.sum_sq + t1.sum_sq,
    }
}

/// [`residuals`] of some views, appended to `out` (and `jacobian`) on this thread.
fn residuals_of(
    template: &Template,
    views: &[ViewEvidence],
    pose: &Isometry3<f64>,
    offset_px: f64,
    out: &mut Vec<f64>,
    mut jacobian: Option<&mut Vec<Row>>,
) -> Tally {
    let pivot = pose * template.blade_centre;
    let mut tally = Tally::default();
    let (mut blade, mut body) = (Outline::default(), Outline::default());
    // The template placed by the pose once, not once per view.
    let place = |points: &[Point3<f64>]| points.iter().map(|p| pose * p).collect::<Vec<_>>();
    let (blade_world, body_world, interior_world) =
        (place(&template.blade_faces), place(&template.body), place(&template.interior));
    for view in views {
        let derivatives = jacobian.is_some().then_some(&pivot);
        blade.project(&blade_world, view, derivatives);
        body.project(&body_world, view, derivatives);
        for s in &view.samples {
            // The nearer part (the blade on a tie); the body is not measured where its disc shows
            // it farther than the blade.
            let nearest = match blade.distance(s) {
                Some(a) if body.beyond(s, a.0) => Some(a),
                a => match (a, body.distance(s)) {
                    (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
                    (a, b) => a.or(b),
                },
            };
            let (d, g) = nearest.map_or((1e3, [0.0; 6]), |(d, g)| (d - offset_px, g));
            tally.samples += 1;
            tally.explained += usize::from(d.abs() <= AGREE_PX);
            tally.sum_sq += d * d;
            out.push(huber(d));
            if let Some(j) = jacobian.as_mut() {
                let slope = huber_slope(d);
                j.push(std::array::from_fn(|k| if k < 6 { g[k] * slope } else { -slope }));
            }
        }
        // A blade seen nearly edge-on projects thinner than a pixel: its silhouette may be a
        // broken line or nothing, so its interior says nothing about where it is.
        let sight = (pivot - view.camera.centre()).normalize();
        let thin = (pose * template.normal).dot(&sight).abs() < EDGE_ON_SIN;
        for (k, world) in interior_world.iter().enumerate() {
            let skip = thin && k < template.blade_interior;
            if skip {
                out.push(0.0);
                if let Some(j) = jacobian.as_mut() {
                    j.push([0.0; PARAMS]);
                }
                continue;
            }
            // Silhouettes thinner than the tool (a negative offset) leave the tool's rim that much
            // off the foreground: only the distance beyond it counts.
            let thinner = (-offset_px).max(0.0);
            let d = match jacobian.as_mut() {
                None => view
                    .project(world)
                    .filter(|uv| view.in_image(uv))
                    .map(|uv| (view.outside_foreground_with_gradient(&uv).0 - thinner).max(0.0)),
                Some(j) => {
                    let projected = view.project_with_jacobian(world, &pivot);
                    let (d, g) = match projected {
                        Some((uv, jp)) if view.in_image(&uv) => {
                            let (d, grad) = view.outside_foreground_with_gradient(&uv);
                            let beyond = d - thinner;
                            let g: Row = if beyond > 0.0 {
                                std::array::from_fn(|k| match k {
                                    6 if offset_px < 0.0 => 1.0,
                                    6 => 0.0,
                                    _ => grad.x * jp[0][k] + grad.y * jp[1][k],
                                })
                            } else {
                                [0.0; PARAMS]
                            };
                            (Some(beyond.max(0.0)), g)
                        }
                        _ => (None, [0.0; PARAMS]),
                    };
                    let slope = huber_slope(d.unwrap_or(0.0));
                    j.push(g.map(|x: f64| x * slope));
                    d
                }
            };
            if let Some(d) = d {
                tally.points += 1;
                tally.covered += usize::from(d <= AGREE_PX);
                tally.sum_sq += d * d;
            }
            out.push(huber(d.unwrap_or(0.0)));
        }
    }
    tally
}

/// The standard deviation of a turn about `axis` (world, unit) for a pixel of noise on every
/// residual, degrees, from a Gauss–Newton normal matrix over the twist and the outline offset
/// ([`Fit::roll_sd_deg`]): the pose's 6x6 block inverted, infinite where it is singular.
fn turn_sd_deg(normal: &SMatrix<f64, PARAMS, PARAMS>, axis: &Vector3<f64>) -> f64 {
    let pose_block: SMatrix<f64, 6, 6> = normal.fixed_view::<6, 6>(0, 0).into_owned();
    let along = SVector::<f64, 6>::new(axis.x, axis.y, axis.z, 0.0, 0.0, 0.0);
    pose_block
        .cholesky()
        .map(|c| along.dot(&c.solve(&along)))
        .filter(|v| v.is_finite() && *v >= 0.0)
        .map_or(f64::INFINITY, |v| v.sqrt().to_degrees())
}

fn fraction(k: usize, n: usize) -> f64 {
    if n == 0 { 0.0 } else { k as f64 / n as f64 }
}

/// Cost of a pose without fitting (no outline offset).
pub(crate) fn cost(template: &Template, views: &[ViewEvidence], pose: &Isometry3<f64>) -> f64 {
    let mut r = Vec::new();
    residuals(template, views, pose, 0.0, &mut r, None);
    r.iter().map(|x| x * x).sum()
}

/// Each view's part of the cost of a pose with the outline offset `offset_px` (the sum of its
/// squared robust residuals, as [`Fit::cost`] sums them over all views), in the order of `views`:
/// one evaluation of them all, split view by view (each view's residuals are its outline samples'
/// and then the tool's interior points', in turn).
pub(crate) fn view_costs(
    template: &Template,
    views: &[ViewEvidence],
    pose: &Isometry3<f64>,
    offset_px: f64,
) -> Vec<f64> {
    let mut r = Vec::new();
    residuals(template, views, pose, offset_px, &mut r, None);
    let mut rest = r.as_slice();
    views
        .iter()
        .map(|view| {
            let (own, more) = rest.split_at((view.samples.len() + template.interior.len()).min(rest.len()));
            rest = more;
            own.iter().map(|x| x * x).sum()
        })
        .collect()
}

/// How one view's mask sits against the tool projected at a pose, with the outline offset
/// `offset_px`: the shares of its outline samples that lie outside the tool's outline by more than
/// [`AGREE_PX`] (scalpel pixels the tool there does not explain), and of the blade's interior
/// points that lie farther than that from its foreground (where the view shows no tool); 0 of none.
pub(crate) fn view_sides(
    template: &Template,
    view: &ViewEvidence,
    pose: &Isometry3<f64>,
    offset_px: f64,
) -> (f64, f64) {
    let mut r = Vec::new();
    residuals_of(template, std::slice::from_ref(view), pose, offset_px, &mut r, None);
    // The samples' residuals come first, robust but of the raw residual's sign and order, then
    // the interior's, the blade's first (0 where the blade is seen edge-on).
    let n = view.samples.len().min(r.len());
    let (samples, interior) = r.split_at(n);
    let blade = &interior[..template.blade_interior.min(interior.len())];
    let beyond = |v: &[f64]| fraction(v.iter().filter(|&&d| d > AGREE_PX).count(), v.len());
    (beyond(samples), beyond(blade))
}

/// Agreement of a pose without fitting (no outline offset): the lower of the share of outline
/// samples it explains and the share of its interior on foreground, as [`Fit`] counts them.
pub(crate) fn agreement(template: &Template, views: &[ViewEvidence], pose: &Isometry3<f64>) -> f64 {
    let mut r = Vec::new();
    let tally = residuals(template, views, pose, 0.0, &mut r, None);
    fraction(tally.explained, tally.samples).min(fraction(tally.covered, tally.points))
}

/// How a fit treats the outline offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Offset {
    /// Held at 0.
    Fixed,
    /// Held at 0 until the pose alone converges or has taken half the iterations, then fitted
    /// with it from there: from a far start the offset refines the fit and never steers the
    /// search, and a pose still creeping towards fat or thin masks gets it in time.
    Refine,
    /// Fitted with the pose from this value on (a start near the answer: the track's prediction
    /// and the last trusted offset).
    From(f64),
}

/// Levenberg–Marquardt from `start`, at most `max_iterations`, with the outline offset as `offset`
/// says.
pub(crate) fn fit(
    template: &Template,
    views: &[ViewEvidence],
    start: &Isometry3<f64>,
    max_iterations: usize,
    offset_mode: Offset,
) -> Fit {
    let mut pose = *start;
    let (mut offset, mut offset_free) = match offset_mode {
        Offset::From(o) => (o.clamp(-MAX_OFFSET_PX, MAX_OFFSET_PX), true),
        Offset::Fixed | Offset::Refine => (0.0, false),
    };
    let mut r = Vec::new();
    let mut tally = residuals(template, views, &pose, offset, &mut r, None);
    let mut cost: f64 = r.iter().map(|x| x * x).sum();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut rp = Vec::new();
    let mut jac: Vec<Row> = Vec::new();
    let mut normal = SMatrix::<f64, PARAMS, PARAMS>::zeros();
    while iterations < max_iterations && !r.is_empty() {
        iterations += 1;
        let pivot = pose * template.blade_centre;
        residuals(template, views, &pose, offset, &mut rp, Some(&mut jac));
        let mut a = SMatrix::<f64, PARAMS, PARAMS>::zeros();
        let mut g = SVector::<f64, PARAMS>::zeros();
        for (row, res) in jac.iter().zip(&r) {
            let row = SVector::<f64, PARAMS>::from_row_slice(row);
            g += row * *res;
            a += row * row.transpose();
        }
        normal = a;
        if !offset_free {
            a.row_mut(PARAMS - 1).fill(0.0);
            a.column_mut(PARAMS - 1).fill(0.0);
            a[(PARAMS - 1, PARAMS - 1)] = 1.0;
            g[PARAMS - 1] = 0.0;
        }
        let mut improved = false;
        for _ in 0..6 {
            let mut damped = a;
            for i in 0..PARAMS {
                damped[(i, i)] += lambda * a[(i, i)].max(1e-9);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
                lambda *= 10.0;
                continue;
            };
            let w = Vector3::new(step[0], step[1], step[2]);
            let v = Vector3::new(step[3], step[4], step[5]);
            let candidate = moved(&pose, &pivot, &w, &v);
            let shifted = (offset + step[6]).clamp(-MAX_OFFSET_PX, MAX_OFFSET_PX);
            let t = residuals(template, views, &candidate, shifted, &mut rp, None);
            let c: f64 = rp.iter().map(|x| x * x).sum();
            if c < cost {
                let small = w.norm() < MIN_STEP_ROTATION
                    && v.norm() < MIN_STEP_TRANSLATION
                    && (shifted - offset).abs() < MIN_STEP_OFFSET_PX;
                pose = candidate;
                offset = shifted;
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
            if offset_free || offset_mode == Offset::Fixed {
                break;
            }
            offset_free = true;
        } else if offset_mode == Offset::Refine && 2 * iterations >= max_iterations {
            // A pose still creeping at half its iterations has the rest with the offset.
            offset_free = true;
        }
    }
    let n = tally.samples + tally.points;
    Fit {
        pose,
        cost,
        iterations,
        roll_sd_deg: turn_sd_deg(&normal, &(pose.rotation * template.long_axis())),
        explained: fraction(tally.explained, tally.samples),
        covered: fraction(tally.covered, tally.points),
        rms_px: if n == 0 { 0.0 } else { (tally.sum_sq / n as f64).sqrt() },
        offset_px: offset,
    }
}

#[cfg(test)]
mod tests {
    use hullcut_rig::{Camera, Distortion};
    use image::GrayImage;
    use nalgebra::Vector3;

    use super::*;

    /// The pointed tool's template, a 320x240 camera with strong distortion 45 cm from the point
    /// 5 cm above the origin and looking at it, and a mask all foreground.
    fn pointed_tool_in_view() -> (Template, Camera, GrayImage) {
        let geometry = hullcut_synth::Scalpel::pointed().geometry;
        let template = Template::new(&geometry).expect("a template");
        let mut camera = Camera::new("c", 320, 240, 300.0, 290.0, 161.0, 118.0)
            .looking_at(Point3::new(0.12, -0.35, 0.3), Point3::new(0.0, 0.0, 0.05), Vector3::z())
            .expect("a camera looking at the tool");
        camera.distortion = Distortion { k1: -0.2, k2: 0.05, p1: 4e-4, p2: -3e-4, k3: 0.0 };
        (template, camera, GrayImage::from_pixel(320, 240, image::Luma([1])))
    }

    /// One distorted view of the pointed tool with three masks: all hand, a scalpel square
    /// around the whole tool (its outline everywhere outside the tool's), all background. Each
    /// view's cost adds up to the cost of the three together; the square's outline lies outside
    /// the tool and the blade on its foreground, the background mask shows no blade anywhere.
    #[test]
    fn each_views_cost_adds_up_to_the_whole_and_its_sides_say_where_its_mask_lies() {
        let (template, camera, hand) = pointed_tool_in_view();
        let radius = camera.distortion.monotonic_radius();
        let pose = Isometry3::new(Vector3::new(0.0, 0.0, 0.05), Vector3::new(0.2, -0.1, 0.4));
        let around: Vec<Point3<f64>> = template.blade.iter().chain(&template.body).map(|p| pose * p).collect();
        let pixels: Vec<Point2<f64>> =
            around.iter().filter_map(|p| crate::evidence::project(&camera, radius, p)).collect();
        let (lo, hi) = pixels.iter().fold(((f64::MAX, f64::MAX), (f64::MIN, f64::MIN)), |(lo, hi), q| {
            ((lo.0.min(q.x), lo.1.min(q.y)), (hi.0.max(q.x), hi.1.max(q.y)))
        });
        let mut square = GrayImage::new(320, 240);
        for (x, y, p) in square.enumerate_pixels_mut() {
            let (x, y) = (f64::from(x), f64::from(y));
            if x >= lo.0 - 6.0 && x <= hi.0 + 6.0 && y >= lo.1 - 6.0 && y <= hi.1 + 6.0 {
                p.0[0] = hullcut_dataset::label::SCALPEL;
            }
        }
        assert!(lo.0 > 10.0 && lo.1 > 10.0 && hi.0 < 310.0 && hi.1 < 230.0, "the tool within the image");
        let background = GrayImage::new(320, 240);
        let views: Vec<ViewEvidence> = [&hand, &square, &background]
            .iter()
            .map(|m| ViewEvidence::new(&camera, radius, m, &around, 12.0).expect("the tool in view"))
            .collect();
        let each = view_costs(&template, &views, &pose, 0.0);
        let whole = cost(&template, &views, &pose);
        assert!((each.iter().sum::<f64>() - whole).abs() <= 1e-9 * whole.max(1.0), "{each:?} against {whole}");
        for (k, own) in each.iter().enumerate() {
            let alone = cost(&template, &views[k..=k], &pose);
            assert!((own - alone).abs() <= 1e-9 * alone.max(1.0), "view {k}: {own} in the whole, {alone} alone");
        }
        assert!(each[2] > each[0], "no foreground under the blade costs more than foreground all over: {each:?}");
        assert_eq!(view_sides(&template, &views[0], &pose, 0.0), (0.0, 0.0), "all hand: no outline, all on it");
        let (outside, off) = view_sides(&template, &views[1], &pose, 0.0);
        assert!(views[1].samples.len() > 50 && outside == 1.0 && off == 0.0, "the square: {outside}, {off}");
        assert_eq!(view_sides(&template, &views[2], &pose, 0.0), (0.0, 1.0), "all background: the blade off it");
    }

    /// The pointed tool's handle (hundreds of vertices) seen by a distorted camera at several
    /// poses: the outline's corners are those of every projected vertex's hull, each with the
    /// derivative [`ViewEvidence::project_with_jacobian`] gives its vertex, and the pixel it
    /// gives too.
    /// The same view cut at its middle column: the half of the tool beyond the image's edge is
    /// neither covered nor uncovered (the view cannot say), with or without derivatives, and the
    /// half inside lies all on the all-foreground mask; a background mask still refutes it.
    #[test]
    fn a_tool_reaching_beyond_the_images_edge_is_judged_by_what_the_image_holds() {
        let (template, full, _) = pointed_tool_in_view();
        let radius = full.distortion.monotonic_radius();
        let pose = Isometry3::new(Vector3::new(0.0, 0.0, 0.05), Vector3::new(0.2, -0.1, 0.4));
        let interior: Vec<Point3<f64>> = template.interior.iter().map(|p| pose * p).collect();
        let us: Vec<f64> =
            interior.iter().filter_map(|p| crate::evidence::project(&full, radius, p)).map(|q| q.x).collect();
        let (lo, hi) = us.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &u| (lo.min(u), hi.max(u)));
        assert!(us.len() == interior.len() && hi - lo > 40.0, "the tool spans {lo:.0}-{hi:.0}");
        let whole = GrayImage::from_pixel(320, 240, image::Luma([1]));
        let view = ViewEvidence::new(&full, radius, &whole, &interior, 12.0).expect("the tool in view");
        let tally = residuals(&template, std::slice::from_ref(&view), &pose, 0.0, &mut Vec::new(), None);
        assert_eq!(
            (tally.points, tally.covered),
            (interior.len(), interior.len()),
            "every point judged in the whole view"
        );
        let width = (0.5 * (lo + hi)).round() as u32;
        let mut cut = full.clone();
        cut.width = width;
        let (hand, background) = (GrayImage::from_pixel(width, 240, image::Luma([1])), GrayImage::new(width, 240));
        let inside = us.iter().filter(|&&u| u.round() < f64::from(width)).count();
        assert!(inside > 0 && inside < interior.len(), "{inside} of {} inside", interior.len());
        for (mask, covered) in [(&hand, inside), (&background, 0)] {
            let view = ViewEvidence::new(&cut, radius, mask, &interior, 12.0).expect("the tool in view");
            for jacobian in [false, true] {
                let (mut r, mut j) = (Vec::new(), Vec::new());
                let tally =
                    residuals(&template, std::slice::from_ref(&view), &pose, 0.0, &mut r, jacobian.then_some(&mut j));
                assert_eq!((tally.points, tally.covered), (inside, covered), "derivatives {jacobian}");
            }
        }
    }

    #[test]
    fn the_outline_carries_each_corners_own_derivative() {
        let (template, camera, mask) = pointed_tool_in_view();
        let radius = camera.distortion.monotonic_radius();
        assert!(template.body.len() > 100, "{} body points", template.body.len());
        let mut checked = 0;
        for k in 0..12 {
            let a = f64::from(k) * 0.5;
            let pose = Isometry3::new(
                Vector3::new(0.01 * a.cos(), 0.01 * a.sin(), 0.05),
                Vector3::new(0.3 * a.sin(), 0.2 * a.cos(), a),
            );
            let pivot = pose * template.blade_centre;
            let points: Vec<Point3<f64>> = template.body.iter().map(|p| pose * p).collect();
            let view = ViewEvidence::new(&camera, radius, &mask, &points, 4.0).expect("the tool in view");
            let mut outline = Outline::default();
            outline.project(&points, &view, Some(&pivot));
            let all: Vec<(Point2<f64>, Twist2)> =
                points.iter().filter_map(|p| view.project_with_jacobian(p, &pivot)).collect();
            let pixels: Vec<Point2<f64>> = all.iter().map(|(uv, _)| *uv).collect();
            assert_eq!(outline.pixels, pixels, "pose {k}: the same pixels");
            let mut hull = Vec::new();
            convex_hull_indices(&pixels, &mut hull);
            assert_eq!(outline.hull, hull, "pose {k}");
            assert_eq!(outline.jacobians.len(), hull.len());
            for (corner, &i) in outline.jacobians.iter().zip(&hull) {
                assert_eq!(corner, &all[i].1, "pose {k}, corner of vertex {i}");
                checked += 1;
            }
            // Without derivatives, none.
            outline.project(&points, &view, None);
            assert!(outline.jacobians.is_empty() && outline.hull == hull);
        }
        assert!(checked > 12 * 6, "{checked} corners");
    }

    /// Wherever the body's disc puts it farther from a pixel than the blade, its measured
    /// distance is farther too (the blade is chosen either way): every pixel of a grid over the
    /// image, the pointed tool at twelve poses through a distorted camera.
    #[test]
    fn the_body_is_left_unmeasured_only_where_it_is_farther_than_the_blade() {
        let (template, camera, mask) = pointed_tool_in_view();
        let radius = camera.distortion.monotonic_radius();
        let (mut skipped, mut measured) = (0, 0);
        for k in 0..12 {
            let a = f64::from(k) * 0.5;
            let pose = Isometry3::new(Vector3::new(0.0, 0.01 * a.sin(), 0.05), Vector3::new(0.3 * a.sin(), 0.2, a));
            let place = |points: &[Point3<f64>]| points.iter().map(|p| pose * p).collect::<Vec<_>>();
            let (blade_world, body_world) = (place(&template.blade), place(&template.body));
            let view = ViewEvidence::new(&camera, radius, &mask, &body_world, 4.0).expect("the tool in view");
            let (mut blade, mut body) = (Outline::default(), Outline::default());
            blade.project(&blade_world, &view, None);
            body.project(&body_world, &view, None);
            for j in (0..240).step_by(3) {
                for i in (0..320).step_by(3) {
                    let q = Point2::new(f64::from(i) + 0.25, f64::from(j) + 0.5);
                    let Some((d, _)) = blade.distance(&q) else { continue };
                    if body.beyond(&q, d) {
                        let (b, _) = body.distance(&q).expect("a body outline");
                        assert!(b > d, "pose {k} at {q:?}: body {b} against blade {d}");
                        skipped += 1;
                    } else {
                        measured += 1;
                    }
                }
            }
        }
        assert!(skipped > 1000 && measured > 1000, "{skipped} skipped, {measured} measured");
    }

    /// The turn's deviation from a normal matrix: along an axis of a diagonal matrix it is one
    /// over the root of that entry (radians, given in degrees), along a slanted axis the two
    /// entries' inverses mixed by the axis, and infinite where the pose block is singular; the
    /// outline offset's row and column take no part.
    #[test]
    fn the_turns_deviation_is_read_from_the_inverse_of_the_pose_block() {
        let mut normal = SMatrix::<f64, PARAMS, PARAMS>::zeros();
        for (i, v) in [4.0, 16.0, 1.0, 9.0, 9.0, 9.0, 1e-12].into_iter().enumerate() {
            normal[(i, i)] = v;
        }
        normal[(0, 6)] = 1e3;
        normal[(6, 0)] = 1e3;
        let sd = |normal: &SMatrix<f64, PARAMS, PARAMS>, axis: Vector3<f64>| turn_sd_deg(normal, &axis.normalize());
        assert!((sd(&normal, Vector3::x()) - 0.5f64.to_degrees()).abs() < 1e-9, "{}", sd(&normal, Vector3::x()));
        assert!((sd(&normal, Vector3::y()) - 0.25f64.to_degrees()).abs() < 1e-9);
        let slanted = (0.5f64 * (1.0 / 4.0 + 1.0 / 16.0)).sqrt().to_degrees();
        assert!((sd(&normal, Vector3::new(1.0, 1.0, 0.0)) - slanted).abs() < 1e-9);
        normal[(2, 2)] = 0.0;
        assert_eq!(sd(&normal, Vector3::z()), f64::INFINITY);
    }
}
