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
        let (i, j) = (uv.x.round(), uv.y.round());
        if i < 0.0 || j < 0.0 || i >= self.mask.width() as f64 || j >= self.mask.height() as f64 {
            return None;
        }
        Some(self.mask.get_pixel(i as u32, j as u32).0[0])
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
