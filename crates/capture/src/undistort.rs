//! Undistortion of colour images for display through OpenCV's `remap`: its fixed-point bilinear
//! sampling (positions in 1/32 of a pixel, weights in 1/32768), vectorised. The images logged
//! to rerun go through it: rerun's Pinhole has no lens distortion, so each logged image is
//! remapped to the ideal camera with the same `K` (DESIGN "rerun entity tree").

use hullcut_rig::Camera;
use nalgebra::Point2;
use opencv::core::{BORDER_CONSTANT, CV_8UC3, CV_16SC2, CV_32FC1, Mat, Rect, Scalar, Vec3b};
use opencv::imgproc;
use opencv::prelude::*;

use crate::error::{CaptureError, Context as _};

/// Where a pixel with no source reads: far enough outside the image that all four bilinear taps
/// are border (0), and inside the 16-bit integer range of OpenCV's fixed-point maps.
const NO_SOURCE: f32 = -64.0;

/// Pixels remapped in one call: OpenCV's `remap` splits a call into stripes for its thread pool
/// by 2^16 pixels, so a band smaller than that runs on the calling thread.
const BAND_PIXELS: i32 = (1 << 16) - 1;

/// One camera's undistortion for display: for each pixel of the ideal image, where it reads in
/// the distorted one ([`Camera::distorted_source`]), as OpenCV's fixed-point maps; pixels with
/// no source are black. Build once per camera and reuse; it keeps its output buffer.
#[derive(Debug)]
pub struct ImageUndistorter {
    width: u32,
    height: u32,
    /// Integer source positions (`CV_16SC2`).
    positions: Mat,
    /// Index of each position's fraction in OpenCV's interpolation table (`CV_16UC1`).
    fractions: Mat,
    /// The last undistorted image (`CV_8UC3`).
    undistorted: Mat,
}

impl ImageUndistorter {
    /// The undistortion of `camera`'s images. An error when OpenCV cannot build the maps
    /// (an image too large for its 16-bit positions).
    pub fn new(camera: &Camera) -> Result<Self, CaptureError> {
        let (w, h) = (camera.width, camera.height);
        let ctx = || format!("building camera {}'s {w}x{h} undistortion maps", camera.name);
        let (rows, cols) = (i32::try_from(h), i32::try_from(w));
        let (Ok(rows), Ok(cols)) = (rows, cols) else {
            return Err(CaptureError::Param { name: "camera size", message: format!("{}: {w}x{h}", ctx()) });
        };
        let (max_u, max_v) = (f64::from(w.max(1) - 1), f64::from(h.max(1) - 1));
        let limit = camera.distortion.monotonic_radius();
        let mut map_x = Mat::new_rows_cols_with_default(rows, cols, CV_32FC1, Scalar::all(0.0)).context(ctx)?;
        let mut map_y = Mat::new_rows_cols_with_default(rows, cols, CV_32FC1, Scalar::all(0.0)).context(ctx)?;
        {
            let xs = map_x.data_typed_mut::<f32>().context(ctx)?;
            let ys = map_y.data_typed_mut::<f32>().context(ctx)?;
            let ideal = (0..h).flat_map(|j| (0..w).map(move |i| Point2::new(f64::from(i), f64::from(j))));
            for ((x, y), ideal) in xs.iter_mut().zip(ys.iter_mut()).zip(ideal) {
                // Clamped into the image as the pure-Rust remap does (no tap beyond the last
                // column or row is weighted).
                (*x, *y) = match camera.distorted_source(ideal, limit) {
                    Some(uv) => (uv.x.clamp(0.0, max_u) as f32, uv.y.clamp(0.0, max_v) as f32),
                    None => (NO_SOURCE, NO_SOURCE),
                };
            }
        }
        let (mut positions, mut fractions) = (Mat::default(), Mat::default());
        imgproc::convert_maps(&map_x, &map_y, &mut positions, &mut fractions, CV_16SC2, false).context(ctx)?;
        Ok(ImageUndistorter { width: w, height: h, positions, fractions, undistorted: Mat::default() })
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Undistorts an RGB image (3 bytes a pixel, rows packed, bilinear); the result, the same
    /// size, lives until the next call. An error when `rgb` is not `width × height × 3` bytes
    /// or OpenCV fails.
    pub fn undistort_rgb(&mut self, rgb: &[u8]) -> Result<&[u8], CaptureError> {
        let (w, h) = (self.width, self.height);
        let ctx = || format!("undistorting a {w}x{h} image");
        if rgb.len() != w as usize * h as usize * 3 {
            return Err(CaptureError::Encode(format!("{}: {} bytes of RGB, not {w} x {h} x 3", ctx(), rgb.len())));
        }
        let (rows, cols) = (self.positions.rows(), self.positions.cols());
        if self.undistorted.rows() != rows || self.undistorted.cols() != cols || self.undistorted.typ() != CV_8UC3 {
            self.undistorted = Mat::new_rows_cols_with_default(rows, cols, CV_8UC3, Scalar::all(0.0)).context(ctx)?;
        }
        let src = Mat::new_rows_cols_with_bytes::<Vec3b>(rows, cols, rgb).context(ctx)?;
        // In bands of rows small enough that OpenCV runs each on this thread rather than on its
        // own pool: the loop's threads own the cores, and the logging thread's work is done
        // beside them, not spread over them.
        let band = (BAND_PIXELS / cols.max(1)).max(1);
        for top in (0..rows).step_by(band as usize) {
            let rect = Rect::new(0, top, cols, band.min(rows - top));
            let positions = Mat::roi(&self.positions, rect).context(ctx)?;
            let fractions = Mat::roi(&self.fractions, rect).context(ctx)?;
            let mut out = Mat::roi_mut(&mut self.undistorted, rect).context(ctx)?;
            imgproc::remap(
                &src,
                &mut out,
                &positions,
                &fractions,
                imgproc::INTER_LINEAR,
                BORDER_CONSTANT,
                Scalar::all(0.0),
            )
            .context(ctx)?;
        }
        if self.undistorted.typ() != CV_8UC3 || !self.undistorted.is_continuous() {
            return Err(CaptureError::Encode(format!("{}: OpenCV's remap returned another layout", ctx())));
        }
        self.undistorted.data_bytes().context(ctx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hullcut_rig::Distortion;

    /// A smooth RGB pattern (at most 15 levels a pixel), so that OpenCV's 1/32-pixel positions
    /// keep it within a level of exact bilinear sampling; each channel different.
    fn pattern(w: u32, h: u32) -> Vec<u8> {
        (0..h)
            .flat_map(|j| {
                (0..w).flat_map(move |i| {
                    let (x, y) = (f64::from(i), f64::from(j));
                    [128.0 + 100.0 * (x / 7.0).sin(), 128.0 + 100.0 * (y / 5.0 + x / 40.0).cos(), (x + 2.0 * y) * 0.3]
                        .map(|v| v.round().clamp(0.0, 255.0) as u8)
                })
            })
            .collect()
    }

    #[test]
    fn without_distortion_the_image_is_unchanged() {
        let cam = Camera::new("c", 64, 48, 50.0, 50.0, 31.5, 23.5);
        let rgb = pattern(64, 48);
        let mut undistorter = ImageUndistorter::new(&cam).expect("maps");
        assert_eq!(undistorter.undistort_rgb(&rgb).expect("remaps"), &rgb[..]);
        // A buffer of the wrong size is an error, not a panic.
        assert!(undistorter.undistort_rgb(&rgb[1..]).is_err());
        assert!(undistorter.undistort_rgb(&[]).is_err());
    }

    /// Against bilinear sampling in floating point where [`Camera::distorted_source`] says, black
    /// where it gives none: within a level on a smooth pattern, on an image of more than one band
    /// of rows, with barrel and pincushion distortion (the second leaves the corners without a
    /// source).
    #[test]
    fn samples_where_the_camera_model_says() {
        let (w, h) = (300u32, 250u32);
        assert!(w * h > BAND_PIXELS as u32, "one band only: the bands' seams go untested");
        for k1 in [-0.25, 0.3] {
            let mut cam = Camera::new("c", w, h, 220.0, 225.0, 151.3, 122.8);
            cam.distortion = Distortion { k1, k2: 0.05, p1: 1e-3, p2: -5e-4, k3: 0.0 };
            let rgb = pattern(w, h);
            let mut undistorter = ImageUndistorter::new(&cam).expect("maps");
            let out = undistorter.undistort_rgb(&rgb).expect("remaps").to_vec();
            let (wu, hu) = (w as usize, h as usize);
            let at = |i: usize, j: usize, c: usize| f64::from(rgb[(j * wu + i) * 3 + c]);
            let (mut sampled, mut black, mut worst) = (0, 0, 0.0f64);
            let limit = cam.distortion.monotonic_radius();
            for j in 0..hu {
                for i in 0..wu {
                    let k = (j * wu + i) * 3;
                    let Some(uv) = cam.distorted_source(Point2::new(i as f64, j as f64), limit) else {
                        assert_eq!(&out[k..k + 3], &[0, 0, 0], "pixel ({i}, {j}) has no source");
                        black += 1;
                        continue;
                    };
                    sampled += 1;
                    let (u, v) = (uv.x.clamp(0.0, (wu - 1) as f64), uv.y.clamp(0.0, (hu - 1) as f64));
                    let (i0, j0) = (u.floor() as usize, v.floor() as usize);
                    let (i1, j1) = ((i0 + 1).min(wu - 1), (j0 + 1).min(hu - 1));
                    let (fu, fv) = (u - i0 as f64, v - j0 as f64);
                    for c in 0..3 {
                        let top = at(i0, j0, c) * (1.0 - fu) + at(i1, j0, c) * fu;
                        let bottom = at(i0, j1, c) * (1.0 - fu) + at(i1, j1, c) * fu;
                        worst = worst.max((f64::from(out[k + c]) - (top * (1.0 - fv) + bottom * fv)).abs());
                    }
                }
            }
            assert!(worst <= 1.5, "k1 {k1}: off by {worst:.2} levels");
            assert!(sampled > wu * hu / 2, "k1 {k1}: {sampled} pixels sampled");
            if k1 > 0.0 {
                assert!(black > 0, "pincushion distortion leaves the corners without a source");
            }
            // Undistorting moved the pattern (it is not the identity).
            assert_ne!(out, rgb);
        }
    }
}
