//! Procedural test scenes in the synthetic palette (DESIGN / synth): a textured green drape and a
//! grey-blue wall, a blue glove blob and a steel scalpel bar (handle and brighter thin blade)
//! moving over it; Lambert-like shading 0.3–1.0, 2×2 supersampled edges, sensor noise σ = 2
//! levels and an optional exposure gain. Truth labels are taken at pixel centres.
//!
//! Shared by the integration tests and `examples/segment_bench.rs`.
#![allow(dead_code)] // each user takes the helpers it needs

use hullcut_dataset::label;
use image::{GrayImage, RgbImage};
use rayon::prelude::*;

/// Frame period at 30 frames per second, nanoseconds.
pub const PERIOD_NS: i64 = 33_333_333;

/// A deterministic 64-bit mix (splitmix64).
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from a key.
pub fn uniform(key: u64) -> f64 {
    (mix(key) >> 11) as f64 / (1u64 << 53) as f64
}

/// An approximately standard normal number from a key (sum of four uniforms).
pub fn normal(key: u64) -> f64 {
    let h = mix(key);
    let s: f64 = (0..4).map(|i| ((h >> (16 * i)) & 0xffff) as f64 / 65535.0).sum();
    (s - 2.0) * 3f64.sqrt()
}

const DRAPE: [f64; 3] = [40.0, 110.0, 70.0];
const WALL: [f64; 3] = [120.0, 130.0, 140.0];
const GLOVE: [f64; 3] = [60.0, 110.0, 200.0];
const HANDLE: [f64; 3] = [150.0, 150.0, 155.0];
const BLADE: [f64; 3] = [205.0, 205.0, 210.0];

/// Where the objects are in one view.
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    /// Hand ellipse centre (pixels) and radii.
    pub hand: [f64; 4],
    /// Scalpel: start point (handle end), direction angle, handle length, blade length.
    pub scalpel: [f64; 5],
}

/// Object poses of camera `camera` at frame `frame` for a `w`×`h` image: the blob drifts right and
/// bobs, the bar turns slowly; each camera sees it shifted.
pub fn pose(w: u32, h: u32, camera: usize, frame: u64) -> Pose {
    let (w, h, t, c) = (f64::from(w), f64::from(h), frame as f64, camera as f64);
    let cx = w * (0.30 + 0.015 * t) + 9.0 * c;
    let cy = h * (0.58 + 0.08 * (0.3 * t + c).sin());
    let hand = [cx, cy, 0.10 * w, 0.09 * h];
    let angle = -0.5 + 0.04 * t + 0.2 * c;
    let scalpel = [cx - 0.02 * w, cy - 0.02 * h, angle, 0.20 * w, 0.09 * w];
    Pose { hand, scalpel }
}

/// Colour (before exposure and noise) and label at a sub-pixel position.
fn sample(x: f64, y: f64, w: f64, h: f64, camera: usize, pose: Option<&Pose>) -> ([f64; 3], u8) {
    if let Some(p) = pose {
        // Scalpel on top: a bar of width 7 px (handle) then 3 px (blade), at 640 px image width.
        let [sx, sy, a, lh, lb] = p.scalpel;
        let (dx, dy) = (x - sx, y - sy);
        let (u, v) = (dx * a.cos() + dy * a.sin(), -dx * a.sin() + dy * a.cos());
        let scale = w / 640.0;
        let shade = 0.45 + 0.5 * (0.5 + 0.5 * (u / (lh + lb) * 3.0).cos());
        if (0.0..lh).contains(&u) && v.abs() <= 3.5 * scale {
            return (HANDLE.map(|c| c * shade), label::SCALPEL);
        }
        if (lh..lh + lb).contains(&u) && v.abs() <= 1.5 * scale * (1.0 - 0.6 * (u - lh) / lb) + 0.2 {
            return (BLADE.map(|c| c * shade), label::SCALPEL);
        }
        let [cx, cy, rx, ry] = p.hand;
        let rho2 = ((x - cx) / rx).powi(2) + ((y - cy) / ry).powi(2);
        if rho2 <= 1.0 {
            // Sphere-like Lambert shading, 0.3 at the rim to 1.0 at the top.
            let shade = 0.3 + 0.7 * (1.0 - rho2).sqrt();
            return (GLOVE.map(|c| c * shade), label::HAND);
        }
    }
    let c = camera as f64;
    if y < 0.2 * h {
        let n = 1.0 + 0.05 * (x / 37.0 + c).sin() + 0.1 * (y / (0.2 * h));
        return (WALL.map(|v| v * 0.8 * n), label::BACKGROUND);
    }
    let weave = 0.15 * (std::f64::consts::TAU * x / 5.0).sin() * (std::f64::consts::TAU * y / 5.0).sin();
    let mottle = 0.08 * ((x / 23.0 + c).sin() * (y / 17.0).cos());
    let shade = 0.55 + 0.45 * (0.5 + 0.5 * ((x / w) * 2.0 + (y / h) * 1.5 + c).sin());
    (DRAPE.map(|v| v * (1.0 + weave + mottle) * shade), label::BACKGROUND)
}

/// Renders one view: image (with exposure `gain` and noise seeded by `seed`) and truth mask.
/// `pose = None` renders the empty scene.
pub fn render(w: u32, h: u32, camera: usize, pose: Option<&Pose>, gain: f64, seed: u64) -> (RgbImage, GrayImage) {
    let (wf, hf) = (f64::from(w), f64::from(h));
    let rows: Vec<(Vec<u8>, Vec<u8>)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut rgb = Vec::with_capacity(w as usize * 3);
            let mut lab = Vec::with_capacity(w as usize);
            for i in 0..w {
                let (x, y) = (f64::from(i), f64::from(j));
                let mut sum = [0.0; 3];
                for (ox, oy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                    let (c, _) = sample(x + ox, y + oy, wf, hf, camera, pose);
                    for k in 0..3 {
                        sum[k] += 0.25 * c[k];
                    }
                }
                lab.push(sample(x, y, wf, hf, camera, pose).1);
                let key = seed ^ (u64::from(j) << 32 | u64::from(i)).wrapping_mul(0x2545_f491_4f6c_dd1d);
                for k in 0..3 {
                    let v = gain * sum[k] + 2.0 * normal(key.wrapping_add(k as u64));
                    rgb.push(v.round().clamp(0.0, 255.0) as u8);
                }
            }
            (rgb, lab)
        })
        .collect();
    let mut rgb = Vec::with_capacity((w * h * 3) as usize);
    let mut lab = Vec::with_capacity((w * h) as usize);
    for (r, l) in rows {
        rgb.extend_from_slice(&r);
        lab.extend_from_slice(&l);
    }
    (
        RgbImage::from_raw(w, h, rgb).expect("buffer has w*h*3 bytes"),
        GrayImage::from_raw(w, h, lab).expect("buffer has w*h bytes"),
    )
}

/// Renders view `camera` of frame `frame` with objects.
pub fn render_frame(w: u32, h: u32, camera: usize, frame: u64, gain: f64) -> (RgbImage, GrayImage) {
    let p = pose(w, h, camera, frame);
    render(w, h, camera, Some(&p), gain, mix(frame * 131 + camera as u64 + 1))
}

/// `n` empty-scene images of camera `camera`, each with its own noise.
pub fn backgrounds(w: u32, h: u32, camera: usize, n: usize) -> Vec<RgbImage> {
    (0..n).map(|k| render(w, h, camera, None, 1.0, mix(0xb6 + 1000 * camera as u64 + k as u64)).0).collect()
}

/// Mean absolute difference per channel value between two images of one size.
pub fn mean_abs_diff(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: u64 = a.as_raw().iter().zip(b.as_raw()).map(|(&x, &y)| u64::from(x.abs_diff(y))).sum();
    sum as f64 / a.as_raw().len() as f64
}
