//! What one camera's label mask says about the tool: points on the scalpel's outline against the
//! background (what the tool must explain), sampled in a region of interest around it, and the
//! distance from any point to the nearest foreground pixel (where the tool may be: scalpel, hand
//! or unknown pixels, since the hand may hide it), searched locally where it is asked for.

use hullcut_dataset::label;
use hullcut_rig::Camera;
use image::GrayImage;
use nalgebra::{Matrix2, Matrix2x3, Point2, Point3, Vector2};

/// A pixel's derivative with respect to a twist (rotation then translation), rows u and v.
pub(crate) type Twist2 = [[f64; 6]; 2];

/// Scalpel pixels kept per view (evenly strided); the fit's cost grows with them.
const MAX_SAMPLES: usize = 192;
/// How far the nearest foreground pixel is searched for, pixels.
const SEARCH_PX: i64 = 8;

/// One view's evidence.
#[derive(Debug, Clone)]
pub struct ViewEvidence<'a> {
    /// The camera.
    pub camera: &'a Camera,
    radius: f64,
    mask: &'a GrayImage,
    /// Points on the scalpel silhouette's outline against the background, in the region: the
    /// midpoints between scalpel pixels and their background 4-neighbours (at most
    /// [`MAX_SAMPLES`], evenly strided).
    pub samples: Vec<Point2<f64>>,
}

impl<'a> ViewEvidence<'a> {
    /// The evidence of a mask (sizes must agree with the camera) in the region covering the
    /// projections of `around`, widened by `margin_px`. `None` when none of `around` projects
    /// into the image.
    pub fn new(
        camera: &'a Camera,
        monotonic_radius: f64,
        mask: &'a GrayImage,
        around: &[Point3<f64>],
        margin_px: f64,
    ) -> Option<Self> {
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in around {
            if let Some(uv) = project(camera, monotonic_radius, p) {
                u0 = u0.min(uv.x);
                v0 = v0.min(uv.y);
                u1 = u1.max(uv.x);
                v1 = v1.max(uv.y);
            }
        }
        let (iw, ih) = (mask.width() as f64, mask.height() as f64);
        let x0 = (u0 - margin_px).floor().max(0.0);
        let y0 = (v0 - margin_px).floor().max(0.0);
        let x1 = (u1 + margin_px).ceil().min(iw - 1.0);
        let y1 = (v1 + margin_px).ceil().min(ih - 1.0);
        if !(x1 >= x0 && y1 >= y0) {
            return None;
        }
        let (x0, y0) = (x0 as usize, y0 as usize);
        let (w, h) = (x1 as usize - x0 + 1, y1 as usize - y0 + 1);
        let raw = mask.as_raw();
        let stride = mask.width() as usize;
        let mut scalpel = Vec::new();
        for j in 0..h {
            let row = &raw[(y0 + j) * stride + x0..(y0 + j) * stride + x0 + w];
            for (i, &l) in row.iter().enumerate() {
                if l == label::SCALPEL {
                    outline_points(raw, stride, mask.height() as usize, x0 + i, y0 + j, &mut scalpel);
                }
            }
        }
        let step = scalpel.len().div_ceil(MAX_SAMPLES).max(1);
        let samples = scalpel.into_iter().step_by(step).collect();
        Some(ViewEvidence { camera, radius: monotonic_radius, mask, samples })
    }

    /// World point → pixel, or `None` behind the camera or beyond the lens' invertible radius.
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        project(self.camera, self.radius, p)
    }

    /// World point → pixel and the pixel's derivative with respect to a twist of the tool (a
    /// rotation `w` about `pivot`, then a translation `v`; columns w then v), or `None` where
    /// [`ViewEvidence::project`] gives none.
    pub fn project_with_jacobian(&self, p: &Point3<f64>, pivot: &Point3<f64>) -> Option<(Point2<f64>, Twist2)> {
        let cam = self.camera;
        let pc = cam.world_to_camera(p);
        if pc.z <= 1e-3 {
            return None;
        }
        let xn = Vector2::new(pc.x / pc.z, pc.y / pc.z);
        if xn.norm() >= self.radius {
            return None;
        }
        let (xd, jd) = cam.distortion.distort_with_jacobian(xn);
        let z = pc.z;
        let dxn = Matrix2x3::new(1.0 / z, 0.0, -pc.x / (z * z), 0.0, 1.0 / z, -pc.y / (z * z));
        let j_world = Matrix2::new(cam.fx, 0.0, 0.0, cam.fy) * jd * dxn * cam.rotation.matrix();
        let r = p - pivot;
        // d p = w × r + v = -[r]× w + v.
        let j_w = j_world * -r.cross_matrix();
        let mut j = [[0.0; 6]; 2];
        for row in 0..2 {
            for k in 0..3 {
                j[row][k] = j_w[(row, k)];
                j[row][k + 3] = j_world[(row, k)];
            }
        }
        Some((cam.normalized_to_pixel(xd), j))
    }

    /// How far a pixel position lies outside the foreground: the distance to the nearest
    /// foreground pixel centre (scalpel, hand or unknown), less one pixel, since a point of the
    /// tool may project anywhere short of the next background pixel's centre; 0 on or next to
    /// foreground. With its gradient with respect to the pixel position. The nearest pixel is
    /// searched in growing square rings up to [`SEARCH_PX`]; beyond, the value is that radius
    /// and the gradient 0.
    pub fn outside_foreground_with_gradient(&self, uv: &Point2<f64>) -> (f64, Vector2<f64>) {
        let (w, h) = (self.mask.width() as i64, self.mask.height() as i64);
        let raw = self.mask.as_raw();
        let foreground =
            |i: i64, j: i64| i >= 0 && j >= 0 && i < w && j < h && raw[(j * w + i) as usize] != label::BACKGROUND;
        let (ci, cj) = (uv.x.round() as i64, uv.y.round() as i64);
        if foreground(ci, cj) {
            return (0.0, Vector2::zeros());
        }
        let mut best: Option<(f64, Vector2<f64>)> = None;
        for r in 1..=SEARCH_PX {
            // Every pixel of ring r is at least r - 0.5 px from uv (in Chebyshev distance, so also
            // in Euclidean): once the best is closer than that, no later ring can do better.
            if best.is_some_and(|(d, _)| d <= r as f64 - 0.5) {
                break;
            }
            for k in -r..=r {
                for (i, j) in [(ci + k, cj - r), (ci + k, cj + r), (ci - r, cj + k), (ci + r, cj + k)] {
                    if foreground(i, j) {
                        let off = Vector2::new(uv.x - i as f64, uv.y - j as f64);
                        let d = off.norm();
                        if best.is_none_or(|(b, _)| d < b) {
                            best = Some((d, off));
                        }
                    }
                }
            }
        }
        match best {
            Some((d, off)) if d > 1.0 => (d - 1.0, off / d),
            Some(_) => (0.0, Vector2::zeros()),
            None => (SEARCH_PX as f64, Vector2::zeros()),
        }
    }

    /// Label of the pixel containing `uv`, or `None` outside the image.
    pub fn label_at(&self, uv: &Point2<f64>) -> Option<u8> {
        self.in_image(uv).then(|| self.mask.get_pixel(uv.x.round() as u32, uv.y.round() as u32).0[0])
    }

    /// Whether `uv` falls on a pixel of the image (the pixel nearest it exists): beyond the
    /// image's edge the view cannot tell the tool's presence either way.
    pub fn in_image(&self, uv: &Point2<f64>) -> bool {
        let (i, j) = (uv.x.round(), uv.y.round());
        i >= 0.0 && j >= 0.0 && i < self.mask.width() as f64 && j < self.mask.height() as f64
    }
}

/// The outline points of a scalpel pixel: the midpoints between it and each of its 4-neighbours
/// that is background. The tool's outline crosses the segment between the two pixel centres
/// (one ray hits it, the other misses) at a uniformly unknown place, so the midpoint is its
/// unbiased estimate. Outlines against the hand are the hand's and give no point; neither does
/// the image border.
fn outline_points(raw: &[u8], stride: usize, height: usize, i: usize, j: usize, out: &mut Vec<Point2<f64>>) {
    let (x, y) = (i as f64, j as f64);
    if i > 0 && raw[j * stride + i - 1] == label::BACKGROUND {
        out.push(Point2::new(x - 0.5, y));
    }
    if i + 1 < stride && raw[j * stride + i + 1] == label::BACKGROUND {
        out.push(Point2::new(x + 0.5, y));
    }
    if j > 0 && raw[(j - 1) * stride + i] == label::BACKGROUND {
        out.push(Point2::new(x, y - 0.5));
    }
    if j + 1 < height && raw[(j + 1) * stride + i] == label::BACKGROUND {
        out.push(Point2::new(x, y + 0.5));
    }
}

/// World point → pixel, or `None` behind the camera or beyond the lens' invertible radius.
pub(crate) fn project(camera: &Camera, radius: f64, p: &Point3<f64>) -> Option<Point2<f64>> {
    project_camera_point(camera, radius, &camera.world_to_camera(p))
}

/// [`project`] of a point already in the camera's frame (`pc`), for callers that also want its
/// depth.
#[inline]
pub(crate) fn project_camera_point(camera: &Camera, radius: f64, pc: &Point3<f64>) -> Option<Point2<f64>> {
    if pc.z <= 1e-3 {
        return None;
    }
    let xn = Vector2::new(pc.x / pc.z, pc.y / pc.z);
    if xn.norm() >= radius {
        return None;
    }
    Some(camera.normalized_to_pixel(camera.distortion.distort(xn)))
}

/// Points projected in one batch ([`project_batch`]).
pub(crate) const BATCH: usize = 16;

/// Up to [`BATCH`] world points projected into one view: for point `k` of the batch, its depth in
/// the camera's frame and, where `ok[k]`, its pixel, both exactly as
/// [`Camera::world_to_camera`] and [`project_camera_point`] give them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ProjectedBatch {
    /// Pixel columns.
    pub u: [f64; BATCH],
    /// Pixel rows.
    pub v: [f64; BATCH],
    /// Depths, metres.
    pub z: [f64; BATCH],
    /// Whether the point projects (in front of the camera, within the lens' invertible radius);
    /// false beyond the batch's points.
    pub ok: [bool; BATCH],
}

/// The points `p(0)`, … `p(len - 1)` (`len` at most [`BATCH`]) projected into `camera` in one
/// batch, written for the auto-vectorizer: planar arrays, no branches, the same operations in the
/// same order as the point-by-point path (Rust neither reassociates nor fuses floating-point
/// operations), so the same bits (test `a_batch_projects_as_point_by_point`). A cell's
/// projection costs two divisions and a square root, which a batch shares across the vector
/// lanes.
#[inline]
// The refusals are negated as written there: `!(z <= 1e-3)` holds for NaN, `z > 1e-3` would not.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub(crate) fn project_batch(
    camera: &Camera,
    radius: f64,
    len: usize,
    p: impl Fn(usize) -> Point3<f64>,
) -> ProjectedBatch {
    let len = len.min(BATCH);
    let (mut wx, mut wy, mut wz) = ([0.0; BATCH], [0.0; BATCH], [0.0; BATCH]);
    for k in 0..len {
        let q = p(k);
        (wx[k], wy[k], wz[k]) = (q.x, q.y, q.z);
    }
    let r = camera.rotation.matrix();
    let t = camera.translation;
    let d = &camera.distortion;
    let mut out = ProjectedBatch { u: [0.0; BATCH], v: [0.0; BATCH], z: [0.0; BATCH], ok: [false; BATCH] };
    for k in 0..BATCH {
        // `R p + t` as nalgebra forms it: column by column, then the translation.
        let x = r[(0, 0)] * wx[k] + r[(0, 1)] * wy[k] + r[(0, 2)] * wz[k] + t.x;
        let y = r[(1, 0)] * wx[k] + r[(1, 1)] * wy[k] + r[(1, 2)] * wz[k] + t.y;
        let z = r[(2, 0)] * wx[k] + r[(2, 1)] * wy[k] + r[(2, 2)] * wz[k] + t.z;
        let (xn, yn) = (x / z, y / z);
        let norm = (xn * xn + yn * yn).sqrt();
        // As `project_camera_point`'s refusals, negated (true for NaN as there).
        out.ok[k] = !(z <= 1e-3) && !(norm >= radius);
        let r2 = xn * xn + yn * yn;
        let radial = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
        let xd = xn * radial + 2.0 * d.p1 * xn * yn + d.p2 * (r2 + 2.0 * xn * xn);
        let yd = yn * radial + d.p1 * (r2 + 2.0 * yn * yn) + 2.0 * d.p2 * xn * yn;
        out.u[k] = camera.fx * xd + camera.cx;
        out.v[k] = camera.fy * yd + camera.cy;
        out.z[k] = z;
    }
    for ok in &mut out.ok[len..] {
        *ok = false;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use hullcut_rig::Distortion;
    use nalgebra::{Rotation3, Vector3};

    /// A reproducible stream of numbers in [0, 1).
    fn numbers(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn a_batch_projects_as_point_by_point() {
        let mut next = numbers(7);
        for view in 0..20 {
            let mut camera = Camera::new("c", 640, 480, 500.0 + 400.0 * next(), 500.0 + 400.0 * next(), 320.0, 240.0);
            camera.rotation = Rotation3::from_euler_angles(next() * 6.0, next() * 6.0, next() * 6.0);
            camera.translation = Vector3::new(next() - 0.5, next() - 0.5, 0.3 + next());
            camera.distortion = Distortion {
                k1: 0.4 * (next() - 0.5),
                k2: 0.2 * (next() - 0.5),
                p1: 0.01 * (next() - 0.5),
                p2: 0.01 * (next() - 0.5),
                k3: 0.1 * (next() - 0.5),
            };
            // Some views with the lens' invertible radius, some without a bound.
            let radius = if view % 2 == 0 { camera.distortion.monotonic_radius() } else { 0.6 };
            let points: Vec<Point3<f64>> =
                (0..BATCH * 5 + 3).map(|_| Point3::new(next() - 0.5, next() - 0.5, next() - 0.5)).collect();
            let (mut projected, mut refused) = (0, 0);
            for chunk in points.chunks(BATCH) {
                let batch = project_batch(&camera, radius, chunk.len(), |k| chunk[k]);
                for (k, p) in chunk.iter().enumerate() {
                    let pc = camera.world_to_camera(p);
                    assert_eq!(batch.z[k].to_bits(), pc.z.to_bits());
                    match project_camera_point(&camera, radius, &pc) {
                        Some(uv) => {
                            assert!(batch.ok[k]);
                            assert_eq!((batch.u[k].to_bits(), batch.v[k].to_bits()), (uv.x.to_bits(), uv.y.to_bits()));
                            projected += 1;
                        }
                        None => {
                            assert!(!batch.ok[k]);
                            refused += 1;
                        }
                    }
                }
                assert!(batch.ok[chunk.len()..].iter().all(|&ok| !ok));
            }
            assert!(projected > 0, "view {view}: nothing projected");
            if view == 0 {
                assert!(refused > 0, "some points lie behind the camera");
            }
        }
    }
}
