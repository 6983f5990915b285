//! Undistortion of images for logging: rerun's Pinhole has no lens distortion, so images are
//! remapped to the ideal pinhole camera with the same `K` before they are logged (DESIGN "rerun
//! entity tree"), or 3-D overlays would not line up with them.

use hullcut_rig::Camera;
use nalgebra::{Point2, Vector2};

/// For each pixel of the ideal (undistorted) image, where to read in the distorted image.
///
/// Build once per camera and reuse: it holds one source position per pixel.
#[derive(Debug, Clone)]
pub struct UndistortMap {
    width: u32,
    height: u32,
    /// Source pixel (u, v) per destination pixel, row-major; NaN where it falls outside.
    source: Vec<[f32; 2]>,
}

impl UndistortMap {
    /// The map of one camera.
    pub fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width, camera.height);
        let limit = camera.distortion.monotonic_radius();
        let mut source = Vec::with_capacity(w as usize * h as usize);
        for j in 0..h {
            for i in 0..w {
                let xn: Vector2<f64> = camera.pixel_to_normalized(Point2::new(f64::from(i), f64::from(j)));
                let uv = camera.normalized_to_pixel(camera.distortion.distort(xn));
                let ok = xn.norm() < limit && camera.contains_pixel(uv);
                source.push(if ok { [uv.x as f32, uv.y as f32] } else { [f32::NAN; 2] });
            }
        }
        UndistortMap { width: w, height: h, source }
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Remaps interleaved 8-bit pixels with `channels` per pixel: bilinear when `interpolate`,
    /// nearest otherwise (labels must not be blended). Pixels with no source are 0.
    /// Returns None when `pixels` is not `width × height × channels` long.
    pub fn remap(&self, pixels: &[u8], channels: usize, interpolate: bool) -> Option<Vec<u8>> {
        let mut out = Vec::new();
        self.remap_into(pixels, channels, interpolate, &mut out).then_some(out)
    }

    /// As [`UndistortMap::remap`], into `out` (resized; its allocation reused from one image to
    /// the next). Returns false, `out` untouched, when `pixels` is not `width × height ×
    /// channels` long.
    pub fn remap_into(&self, pixels: &[u8], channels: usize, interpolate: bool, out: &mut Vec<u8>) -> bool {
        let (w, h) = (self.width as usize, self.height as usize);
        if pixels.len() != w * h * channels {
            return false;
        }
        out.clear();
        out.resize(pixels.len(), 0);
        let at = |i: usize, j: usize, c: usize| f32::from(pixels[(j * w + i) * channels + c]);
        for (k, &[u, v]) in self.source.iter().enumerate() {
            if u.is_nan() {
                continue;
            }
            let dst = &mut out[k * channels..(k + 1) * channels];
            if interpolate {
                let (i0, j0) = ((u.floor().max(0.0) as usize).min(w - 1), (v.floor().max(0.0) as usize).min(h - 1));
                let (i1, j1) = ((i0 + 1).min(w - 1), (j0 + 1).min(h - 1));
                let (fu, fv) = ((u - i0 as f32).clamp(0.0, 1.0), (v - j0 as f32).clamp(0.0, 1.0));
                for (c, d) in dst.iter_mut().enumerate() {
                    let top = at(i0, j0, c) * (1.0 - fu) + at(i1, j0, c) * fu;
                    let bottom = at(i0, j1, c) * (1.0 - fu) + at(i1, j1, c) * fu;
                    *d = (top * (1.0 - fv) + bottom * fv).round() as u8;
                }
            } else {
                let (i, j) = ((u.round().max(0.0) as usize).min(w - 1), (v.round().max(0.0) as usize).min(h - 1));
                for (c, d) in dst.iter_mut().enumerate() {
                    *d = pixels[(j * w + i) * channels + c];
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hullcut_rig::Distortion;

    #[test]
    fn identity_without_distortion_and_labels_stay_labels() {
        let cam = Camera::new("c", 8, 6, 10.0, 10.0, 3.5, 2.5);
        let map = UndistortMap::new(&cam);
        let pixels: Vec<u8> = (0..48).map(|x| x as u8 * 5).collect();
        assert_eq!(map.remap(&pixels, 1, true), Some(pixels.clone()));
        assert_eq!(map.remap(&pixels, 3, true), None);

        let mut cam = Camera::new("c", 64, 48, 40.0, 40.0, 31.5, 23.5);
        cam.distortion = Distortion { k1: -0.2, ..Distortion::default() };
        let map = UndistortMap::new(&cam);
        let labels: Vec<u8> = (0..64 * 48).map(|k| [0u8, 1, 2][(k % 64) / 22]).collect();
        let out = map.remap(&labels, 1, false).unwrap_or_default();
        assert!(out.iter().all(|v| [0u8, 1, 2].contains(v)));
        // Barrel distortion pulls the edges in: undistorting moves the centre column outward.
        assert_ne!(out, labels);
    }
}
