//! Undistortion of images for logging: rerun's Pinhole has no lens distortion, so images are
//! remapped to the ideal pinhole camera with the same `K` before they are logged (DESIGN "rerun
//! entity tree"), or 3-D overlays would not line up with them.

use hullcut_rig::Camera;
use nalgebra::Point2;

/// For each pixel of the ideal (undistorted) image, where to read in the distorted image.
///
/// Build once per camera and reuse: it holds one source tap (8 bytes) per pixel.
#[derive(Debug, Clone)]
pub struct UndistortMap {
    width: u32,
    height: u32,
    /// Source tap per destination pixel, row-major.
    source: Vec<Tap>,
}

/// Where one destination pixel reads: the source pixel at the top left of its bilinear 2x2
/// (`NONE` where it falls outside the image) and its position within it in 1/256 of a pixel, with
/// the steps to the right and down (0 at the image's last column or row) and the nearest of the
/// four.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Tap {
    /// Index of the top-left source pixel.
    base: u32,
    /// Weight of the right column, 1/256.
    fu: u8,
    /// Weight of the bottom row, 1/256.
    fv: u8,
    /// [`Tap::RIGHT`], [`Tap::DOWN`]: the 2x2 goes right and down; [`Tap::NEAR_RIGHT`],
    /// [`Tap::NEAR_DOWN`]: the nearest pixel is to the right of or below the top left one.
    flags: u8,
}

impl Tap {
    const NONE: u32 = u32::MAX;
    const RIGHT: u8 = 1;
    const DOWN: u8 = 2;
    const NEAR_RIGHT: u8 = 4;
    const NEAR_DOWN: u8 = 8;

    /// The tap of source position (`u`, `v`) in a `w` x `h` image (inside it).
    fn new(u: f64, v: f64, w: usize, h: usize) -> Tap {
        let (i0, j0) = ((u.floor().max(0.0) as usize).min(w - 1), (v.floor().max(0.0) as usize).min(h - 1));
        let (fu, fv) = ((u - i0 as f64).clamp(0.0, 1.0), (v - j0 as f64).clamp(0.0, 1.0));
        let (ni, nj) = ((u.round().max(0.0) as usize).min(w - 1), (v.round().max(0.0) as usize).min(h - 1));
        let mut flags = 0;
        if i0 + 1 < w {
            flags |= Tap::RIGHT;
        }
        if j0 + 1 < h {
            flags |= Tap::DOWN;
        }
        if ni > i0 {
            flags |= Tap::NEAR_RIGHT;
        }
        if nj > j0 {
            flags |= Tap::NEAR_DOWN;
        }
        // A weight of 256/256 only where the 2x2 cannot step on (u at the last column).
        let q = |f: f64| (f * 256.0).round().min(255.0) as u8;
        Tap { base: u32::try_from(j0 * w + i0).unwrap_or(Tap::NONE), fu: q(fu), fv: q(fv), flags }
    }
}

impl UndistortMap {
    /// The map of one camera.
    pub fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width, camera.height);
        let limit = camera.distortion.monotonic_radius();
        let mut source = Vec::with_capacity(w as usize * h as usize);
        for j in 0..h {
            for i in 0..w {
                source.push(match camera.distorted_source(Point2::new(f64::from(i), f64::from(j)), limit) {
                    // Positions rounded to f32 as before, so that the nearest pixel is the same.
                    Some(uv) => Tap::new(f64::from(uv.x as f32), f64::from(uv.y as f32), w as usize, h as usize),
                    None => Tap { base: Tap::NONE, fu: 0, fv: 0, flags: 0 },
                });
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
        // The usual pixel sizes with the channel count known to the compiler (a pass with it
        // unrolled, no call per pixel to copy a runtime-sized slice); any other the same way.
        match (channels, interpolate) {
            (1, true) => remap_taps::<1, true>(&self.source, pixels, w, out),
            (1, false) => remap_taps::<1, false>(&self.source, pixels, w, out),
            (3, true) => remap_taps::<3, true>(&self.source, pixels, w, out),
            (3, false) => remap_taps::<3, false>(&self.source, pixels, w, out),
            (4, true) => remap_taps::<4, true>(&self.source, pixels, w, out),
            (4, false) => remap_taps::<4, false>(&self.source, pixels, w, out),
            _ => {
                for (tap, dst) in self.source.iter().zip(out.chunks_exact_mut(channels.max(1))) {
                    sample(tap, pixels, w * channels, channels, interpolate, dst);
                }
            }
        }
        true
    }
}

/// [`UndistortMap::remap_into`]'s pass for `C` channels: each destination pixel sampled through
/// its tap (bilinear when `INTERPOLATE`, else nearest).
fn remap_taps<const C: usize, const INTERPOLATE: bool>(taps: &[Tap], pixels: &[u8], w: usize, out: &mut [u8]) {
    for (tap, dst) in taps.iter().zip(out.chunks_exact_mut(C)) {
        sample(tap, pixels, w * C, C, INTERPOLATE, dst);
    }
}

/// Samples the `channels` of one destination pixel (`dst`) through `tap` from `pixels` (rows of
/// `row` bytes); left as it is (0) where the tap has no source.
#[inline(always)]
fn sample(tap: &Tap, pixels: &[u8], row: usize, channels: usize, interpolate: bool, dst: &mut [u8]) {
    if tap.base == Tap::NONE {
        return;
    }
    let a = tap.base as usize * channels;
    if interpolate {
        // Fixed point: weights in 1/256 per axis, the sum rounded back to 8 bits.
        let right = if tap.flags & Tap::RIGHT != 0 { channels } else { 0 };
        let down = if tap.flags & Tap::DOWN != 0 { row } else { 0 };
        let (fu, fv) = (u32::from(tap.fu), u32::from(tap.fv));
        let (Some(top), Some(bottom)) =
            (pixels.get(a..a + right + channels), pixels.get(a + down..a + down + right + channels))
        else {
            return;
        };
        for (c, d) in dst.iter_mut().enumerate().take(channels) {
            let t = u32::from(top[c]) * (256 - fu) + u32::from(top[right + c]) * fu;
            let b = u32::from(bottom[c]) * (256 - fu) + u32::from(bottom[right + c]) * fu;
            *d = ((t * (256 - fv) + b * fv + (1 << 15)) >> 16) as u8;
        }
    } else {
        let right = if tap.flags & Tap::NEAR_RIGHT != 0 { channels } else { 0 };
        let down = if tap.flags & Tap::NEAR_DOWN != 0 { row } else { 0 };
        if let Some(src) = pixels.get(a + right + down..a + right + down + channels) {
            dst.copy_from_slice(src);
        }
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

    /// The fixed-point remap against the same sampling in floating point: bilinear within one
    /// grey level, nearest exact, on a distorted camera and random pixels of one to four channels.
    #[test]
    fn fixed_point_taps_sample_as_floating_point_does() {
        // 1, 3 and 4 channels have passes of their own; 2 takes the general one.
        for channels in 1..=4 {
            fixed_point_taps_sample_as_floating_point_does_with(channels);
        }
    }

    fn fixed_point_taps_sample_as_floating_point_does_with(channels: usize) {
        let mut cam = Camera::new("c", 97, 61, 70.0, 72.0, 47.3, 30.8);
        cam.distortion = Distortion { k1: -0.25, k2: 0.06, p1: 1e-3, p2: -5e-4, k3: 0.0 };
        let (w, h) = (97usize, 61usize);
        let mut seed = 7u64;
        let pixels: Vec<u8> = (0..w * h * channels)
            .map(|_| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 56) as u8
            })
            .collect();
        let map = UndistortMap::new(&cam);
        let bilinear = map.remap(&pixels, channels, true).unwrap_or_default();
        let nearest = map.remap(&pixels, channels, false).unwrap_or_default();
        let limit = cam.distortion.monotonic_radius();
        let at = |i: usize, j: usize, c: usize| f32::from(pixels[(j * w + i) * channels + c]);
        let (mut sampled, mut worst) = (0, 0i32);
        for j in 0..h {
            for i in 0..w {
                let xn = cam.pixel_to_normalized(Point2::new(i as f64, j as f64));
                let uv = cam.normalized_to_pixel(cam.distortion.distort(xn));
                let k = (j * w + i) * channels;
                if !(xn.norm() < limit && cam.contains_pixel(uv)) {
                    assert!(bilinear[k..k + channels].iter().chain(&nearest[k..k + channels]).all(|&p| p == 0));
                    continue;
                }
                sampled += 1;
                let (u, v) = (uv.x as f32, uv.y as f32);
                let (i0, j0) = ((u.floor().max(0.0) as usize).min(w - 1), (v.floor().max(0.0) as usize).min(h - 1));
                let (i1, j1) = ((i0 + 1).min(w - 1), (j0 + 1).min(h - 1));
                let (fu, fv) = ((u - i0 as f32).clamp(0.0, 1.0), (v - j0 as f32).clamp(0.0, 1.0));
                let (ni, nj) = ((u.round().max(0.0) as usize).min(w - 1), (v.round().max(0.0) as usize).min(h - 1));
                for c in 0..channels {
                    let top = at(i0, j0, c) * (1.0 - fu) + at(i1, j0, c) * fu;
                    let bottom = at(i0, j1, c) * (1.0 - fu) + at(i1, j1, c) * fu;
                    let expected = (top * (1.0 - fv) + bottom * fv).round() as i32;
                    worst = worst.max((i32::from(bilinear[k + c]) - expected).abs());
                    assert_eq!(
                        nearest[k + c],
                        pixels[(nj * w + ni) * channels + c],
                        "pixel ({i}, {j}), {channels} channels"
                    );
                }
            }
        }
        assert!(sampled > w * h / 2, "{sampled} pixels sampled");
        assert!(worst <= 1, "bilinear off by {worst} grey levels, {channels} channels");
    }
}
