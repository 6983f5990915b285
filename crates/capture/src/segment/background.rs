//! Per-pixel background model from empty-scene images, and the foreground test.
//!
//! The test follows Horprasert et al. (1999): a pixel's colour is compared with the expected
//! background colour after splitting the difference into a brightness part and a chromaticity
//! part. With I = (r, g, b), s = r+g+b and the model mean E with sum Eₛ:
//! - brightness distortion: s − γ·Eₛ > β·γ·Eₛ + 3τ (brighter) or γ·Eₛ − s > β_shadow·γ·Eₛ + 3τ
//!   (darker), where γ is the image's exposure gain (estimated per image as the median s/Eₛ of
//!   pixels whose chromaticity matches the model, so a global exposure change is no foreground)
//!   and a larger β_shadow lets cast shadows, darker but of unchanged chromaticity, stay
//!   background;
//! - chromaticity distortion: Σ_c |c − ê_c·s| > κ·s + ν·3τ with ê = E/Eₛ, the L1 colour
//!   difference after matching brightness, which does not change when shading or exposure scale
//!   the colour. ν (`chroma_noise`, ½ by default) takes part of the noise allowance only: κ·s
//!   already allows for the scene's own chromaticity drift, and stacking the whole worst-case
//!   noise on top of it hid a pale hand over light wood (see [`SegmentParams::chroma_noise`]).
//!
//! τ is the pixel's noise allowance in grey levels (from the spread over the empty-scene images,
//! never below the noise floor). The model is stored in planes (ê_r, ê_g in Q16, 2·Eₛ, τ) and the
//! test runs in 16-bit integer lanes, 16 pixels at a time with no branches, so the compiler
//! vectorizes it with baseline SSE2: products are "high half of a 16×16-bit product"
//! (`pmulhuw`), every intermediate stays below 2¹⁶ (bounds at [`BackgroundModel::foreground_row`]).

use image::RgbImage;
use rayon::prelude::*;

use crate::error::CaptureError;

use super::classes::ClassLut;
use super::{ENC_SHADOW, ENC_WEAK, ENC_WEAK_DARK, SegmentParams};

/// Pixels used for the exposure estimate: every `GAIN_STEP`-th pixel of every `GAIN_STEP`-th row.
const GAIN_STEP: usize = 16;

/// Model pixels darker than this channel sum are not used for the exposure estimate.
const GAIN_MIN_SUM: u32 = 48;

/// Range of the exposure gain estimate.
const GAIN_RANGE: (f64, f64) = (0.5, 1.99);

/// Pixels per step of the vectorized test.
const LANES: usize = 16;

/// Background colour and noise allowance per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct BackgroundModel {
    width: u32,
    height: u32,
    /// The mean empty-scene image.
    mean: RgbImage,
    /// ê_r = E_r/Eₛ in Q16 (65535 = 1), per pixel.
    chroma_r: Vec<u16>,
    /// ê_g = E_g/Eₛ in Q16.
    chroma_g: Vec<u16>,
    /// ê_b = E_b/Eₛ in Q16.
    chroma_b: Vec<u16>,
    /// 2·Eₛ (the factor 2 makes γ·Eₛ one high-half product with γ in Q15).
    sum2: Vec<u16>,
    /// 3τ, grey levels.
    tol3: Vec<u16>,
}

/// Fixed-point thresholds for one image.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Thresholds {
    /// Exposure gain γ, Q15 (32768 = 1).
    gain: u16,
    /// β, Q16.
    beta: u16,
    /// β for darker pixels (shadows), Q16.
    shadow: u16,
    /// How much darker a pixel of unchanged chromaticity may be and still be a possible cast
    /// shadow, Q16 (≥ `shadow`).
    deep: u16,
    /// κ, Q16.
    kappa: u16,
    /// ν, Q16 (1 rounds to 65535/65536: at most one grey level less).
    chroma_noise: u16,
    /// The weak share of every tolerance, Q16; 0: no weak pixels ([`SegmentParams::weak_share`]
    /// 1).
    weak: u16,
}

impl Thresholds {
    pub(crate) fn new(params: &SegmentParams, gain: f64) -> Self {
        let q16 = |v: f64| (v * 65536.0).round().clamp(0.0, 65535.0) as u16;
        Self {
            gain: (gain * 32768.0).round().clamp(0.0, 65535.0) as u16,
            beta: q16(params.brightness_tolerance),
            shadow: q16(params.shadow_tolerance),
            deep: q16(params.shadow_depth.max(params.shadow_tolerance)),
            kappa: q16(params.chroma_tolerance),
            chroma_noise: q16(params.chroma_noise),
            weak: if params.weak_share < 1.0 { q16(params.weak_share).max(1) } else { 0 },
        }
    }
}

/// High half of a 16×16-bit product.
#[inline(always)]
fn mulhi(a: u16, b: u16) -> u16 {
    ((u32::from(a) * u32::from(b)) >> 16) as u16
}

impl BackgroundModel {
    /// Builds the model from empty-scene images of one camera: the per-pixel mean, and a noise
    /// allowance τ of `noise_sigmas` standard deviations of the per-channel spread when three or
    /// more images are given, never below `noise_floor`.
    pub fn from_images(camera: usize, images: &[RgbImage], params: &SegmentParams) -> Result<Self, CaptureError> {
        let Some(first) = images.first() else {
            return Err(CaptureError::Param {
                name: "backgrounds",
                message: format!("camera {camera}: no empty-scene images"),
            });
        };
        let (w, h) = first.dimensions();
        for (i, im) in images.iter().enumerate() {
            if im.dimensions() != (w, h) {
                return Err(CaptureError::ImageSize {
                    camera,
                    what: format!("background image {i}"),
                    w,
                    h,
                    found_w: im.width(),
                    found_h: im.height(),
                });
            }
        }
        let n = images.len() as u32;
        let len = w as usize * h as usize;
        let mut sum = vec![0u32; 3 * len];
        for im in images {
            for (s, &v) in sum.iter_mut().zip(im.as_raw()) {
                *s += u32::from(v);
            }
        }
        let mean_raw: Vec<u8> = sum.iter().map(|&s| ((s + n / 2) / n) as u8).collect();
        let floor = u16::from(params.noise_floor);
        let mut tol = vec![floor; len];
        if n >= 3 {
            let tol_of = |sd: f64| (params.noise_sigmas * sd).ceil().clamp(f64::from(floor), 255.0) as u16;
            let mut sq = vec![0u32; len];
            for im in images {
                for ((q, p), m) in sq.iter_mut().zip(im.as_raw().chunks_exact(3)).zip(mean_raw.chunks_exact(3)) {
                    for c in 0..3 {
                        let d = i32::from(p[c]) - i32::from(m[c]);
                        *q += (d * d) as u32;
                    }
                }
            }
            let denom = f64::from(3 * (n - 1));
            for (t, q) in tol.iter_mut().zip(&sq) {
                *t = tol_of((f64::from(*q) / denom).sqrt());
            }
        }
        Ok(Self::from_mean(w, h, mean_raw, &tol))
    }

    /// Builds the model from frames of the recording itself, where the foreground moves: per pixel
    /// and channel the median of the frames (what the pixel shows most of the time), and a noise
    /// allowance from the median absolute deviation around it (1.4826 MAD estimates a standard
    /// deviation without the frames where the hand passed). A pixel the foreground covers in more
    /// than half of the frames is learned as background: the frames must be spread over the
    /// recording, with the hand moving.
    pub fn from_recording(camera: usize, frames: &[RgbImage], params: &SegmentParams) -> Result<Self, CaptureError> {
        let Some(first) = frames.first() else {
            return Err(CaptureError::Param {
                name: "frames",
                message: format!("camera {camera}: no frames to learn from"),
            });
        };
        let (w, h) = first.dimensions();
        if let Some((i, im)) = frames.iter().enumerate().find(|(_, im)| im.dimensions() != (w, h)) {
            return Err(CaptureError::ImageSize {
                camera,
                what: format!("frame {i}"),
                w,
                h,
                found_w: im.width(),
                found_h: im.height(),
            });
        }
        // The frames' exposures differ (auto-exposure, lighting drift): a first median gives each
        // frame's gain against it, and the second takes the median of the frames brought to one
        // exposure, so drift widens no pixel's noise allowance.
        let (median, tol) = temporal_median(frames, &vec![1.0; frames.len()], params);
        let first = Self::from_mean(w, h, median, &tol);
        let mut ratios = Vec::new();
        let gains: Vec<f32> = frames.iter().map(|im| first.exposure_gain(im, params, &mut ratios) as f32).collect();
        let (median, tol) = temporal_median(frames, &gains, params);
        Ok(Self::from_mean(w, h, median, &tol))
    }

    /// The model of an expected image and per-pixel noise allowances τ.
    fn from_mean(w: u32, h: u32, mean_raw: Vec<u8>, tol: &[u16]) -> Self {
        let len = w as usize * h as usize;
        let mut model = Self {
            width: w,
            height: h,
            mean: RgbImage::from_raw(w, h, mean_raw).unwrap_or_else(|| RgbImage::new(w, h)),
            chroma_r: Vec::with_capacity(len),
            chroma_g: Vec::with_capacity(len),
            chroma_b: Vec::with_capacity(len),
            sum2: Vec::with_capacity(len),
            tol3: tol.iter().map(|&t| 3 * t).collect(),
        };
        for p in model.mean.pixels() {
            let [r, g, b] = p.0.map(u32::from);
            let es = r + g + b;
            let q = |c: u32| (c * 65535 + es / 2).checked_div(es).unwrap_or(0) as u16;
            model.chroma_r.push(q(r));
            model.chroma_g.push(q(g));
            model.chroma_b.push(q(b));
            model.sum2.push((2 * es) as u16);
        }
        model
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The mean empty-scene image (the model's expected image).
    pub fn mean_image(&self) -> &RgbImage {
        &self.mean
    }

    /// Exposure gain of `image` against the model, clamped to 0.5..1.99: the median brightness
    /// ratio s/Eₛ over a sparse grid of pixels whose chromaticity matches the model (so the
    /// foreground hardly biases it).
    pub(crate) fn exposure_gain(&self, image: &RgbImage, params: &SegmentParams, ratios: &mut Vec<f32>) -> f64 {
        let w = self.width as usize;
        let raw = image.as_raw();
        let mean = self.mean.as_raw();
        let kappa = params.chroma_tolerance as f32;
        ratios.clear();
        for y in (GAIN_STEP / 2..self.height as usize).step_by(GAIN_STEP) {
            for x in (GAIN_STEP / 2..w).step_by(GAIN_STEP) {
                let k = y * w + x;
                let (p, e) = (&raw[3 * k..3 * k + 3], &mean[3 * k..3 * k + 3]);
                let es: u32 = e.iter().map(|&v| u32::from(v)).sum();
                if es < GAIN_MIN_SUM {
                    continue;
                }
                let s = p.iter().map(|&v| f32::from(v)).sum::<f32>();
                let k_s = s / es as f32;
                let dc: f32 = (0..3).map(|c| (f32::from(p[c]) - f32::from(e[c]) * k_s).abs()).sum();
                if dc > kappa * s + f32::from(self.tol3[k]) {
                    continue;
                }
                ratios.push(k_s);
            }
        }
        if ratios.is_empty() {
            return 1.0;
        }
        let mid = ratios.len() / 2;
        let (_, m, _) = ratios.select_nth_unstable_by(mid, f32::total_cmp);
        f64::from(*m).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
    }

    /// [`BackgroundModel::foreground_row`] for each row of a window `w` pixels wide from column
    /// `x0`, row `y0`, of an image `full_w` pixels wide (`raw`, RGB): `labels` holds the window's
    /// rows, `active[j]` is set to whether row `j` has any foreground, `kinds[j]` to what it may
    /// hold ([`RowKinds`]). With `stretches`, only the
    /// columns `a..b` of image row `y` that `stretches[y]` names are tested (within the window;
    /// a row beyond `stretches` has none); the rest of the window is background. Compiled for
    /// the widest vector instructions the processor has (pulp's run-time dispatch: the same
    /// integer arithmetic, so the same labels, on any of them).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn foreground_window(
        &self,
        raw: &[u8],
        full_w: usize,
        (x0, y0, w): (usize, usize, usize),
        stretches: Option<&[(u32, u32)]>,
        t: Thresholds,
        lut: &ClassLut,
        labels: &mut [u8],
        active: &mut [bool],
        kinds: &mut [RowKinds],
    ) {
        if w == 0 {
            active.fill(false);
            kinds.fill(RowKinds::default());
            return;
        }
        pulp::Arch::new().dispatch(WindowPass {
            model: self,
            raw,
            full_w,
            x0,
            y0,
            w,
            stretches,
            t,
            lut,
            labels,
            active,
            kinds,
        });
    }

    /// Foreground test and colour classes for the `out.len()` pixels from pixel index `start`
    /// (`y · width + x`, within one row; `row_rgb` holds their colours): `out[i]` = 0 for
    /// background, else the encoded class of the pixel's colour (or [`test_pixel`]'s code for a
    /// possible shadow or a weak pixel). Returns whether any is not background, and what the
    /// pixels hold (columns from the first of `out`).
    ///
    /// Bounds (all u16): s ≤ 765; 2Eₛ ≤ 1530; γ·Eₛ = hi(γ·2Eₛ) ≤ 1.99·765 < 1530; β·γEₛ + 3τ ≤
    /// 1530 + 765; ê_c·s = hi(ê_c·s) ≤ s; Σ_c |c − ê_c·s| ≤ 3·765; κ·s + ν·3τ ≤ 765 + 765.
    /// Differences that could go negative saturate at 0.
    #[inline(always)]
    pub(crate) fn foreground_row(
        &self,
        row_rgb: &[u8],
        start: usize,
        t: Thresholds,
        lut: &ClassLut,
        out: &mut [u8],
    ) -> (bool, RowKinds) {
        let w = out.len();
        let range = start..start + w;
        let (hr, hg, hb) =
            (&self.chroma_r[range.clone()], &self.chroma_g[range.clone()], &self.chroma_b[range.clone()]);
        let (es2, tol3) = (&self.sum2[range.clone()], &self.tol3[range]);
        let (mut any, mut bits, mut sure) = (false, 0, (u32::MAX, 0));
        let chunks = w / LANES;
        for c in 0..chunks {
            let span = c * LANES..(c + 1) * LANES;
            let (Ok(p), Ok(o)) = (
                <&[u8; 3 * LANES]>::try_from(&row_rgb[3 * span.start..3 * span.end]),
                <&mut [u8; LANES]>::try_from(&mut out[span.clone()]),
            ) else {
                continue;
            };
            let fg = test_lanes(
                p,
                [&hr[span.clone()], &hg[span.clone()], &hb[span.clone()], &es2[span.clone()], &tol3[span]],
                t,
                o,
            );
            if fg != 0 {
                any = true;
                bits |= fg & (WEAK_BIT | SURE_BIT);
                if fg & SURE_BIT != 0 {
                    classify(p, lut, o);
                    sure = (sure.0.min((c * LANES) as u32), ((c + 1) * LANES) as u32);
                }
            }
        }
        // The last pixels of a row whose width is not a multiple of LANES, one at a time.
        for x in chunks * LANES..w {
            let p = [row_rgb[3 * x], row_rgb[3 * x + 1], row_rgb[3 * x + 2]];
            let code = test_pixel(p.map(u16::from), [hr[x], hg[x], hb[x], es2[x], tol3[x]], t);
            out[x] = match code {
                SURE => lut.get(p[0], p[1], p[2]),
                _ => code,
            };
            any |= code != 0;
            bits |= (code & WEAK_BIT) | (u8::from(code == SURE) * SURE_BIT);
            if code == SURE {
                sure = (sure.0.min(x as u32), x as u32 + 1);
            }
        }
        (any, RowKinds { bits, sure: if sure.0 < sure.1 { sure } else { (0, 0) } })
    }
}

/// The rows of one window through [`BackgroundModel::foreground_row`], as one dispatched pass
/// ([`BackgroundModel::foreground_window`]).
struct WindowPass<'a> {
    model: &'a BackgroundModel,
    raw: &'a [u8],
    full_w: usize,
    x0: usize,
    y0: usize,
    w: usize,
    stretches: Option<&'a [(u32, u32)]>,
    t: Thresholds,
    lut: &'a ClassLut,
    labels: &'a mut [u8],
    active: &'a mut [bool],
    kinds: &'a mut [RowKinds],
}

/// The columns of a window's row that are tested: image row `y`'s stretch in `stretches` (none
/// beyond it), clipped to the window's `w` columns from `x0`, as columns of the window; all of
/// them without stretches.
#[inline]
pub(crate) fn tested_columns(stretches: Option<&[(u32, u32)]>, y: usize, x0: usize, w: usize) -> (usize, usize) {
    let Some(stretches) = stretches else { return (0, w) };
    let (a, b) = stretches.get(y).map_or((0, 0), |&(a, b)| (a as usize, b as usize));
    let (a, b) = (a.clamp(x0, x0 + w) - x0, b.clamp(x0, x0 + w) - x0);
    (a, b.max(a))
}

impl pulp::WithSimd for WindowPass<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let WindowPass { model, raw, full_w, x0, y0, w, stretches, t, lut, labels, active, kinds } = self;
        for (((j, row_labels), any), kind) in labels.chunks_exact_mut(w).enumerate().zip(active.iter_mut()).zip(kinds) {
            let (a, b) = tested_columns(stretches, y0 + j, x0, w);
            // A stretch is tested in whole vector steps where the window has room (the pixels
            // one at a time cost several times as much), the pixels beyond it cleared after.
            let steps = (b - a).div_ceil(LANES) * LANES;
            let (c, d) = if a + steps <= w {
                (a, a + steps)
            } else if b >= steps {
                (b - steps, b)
            } else {
                (a, b)
            };
            let start = (y0 + j) * full_w + x0 + c;
            let (found, found_kinds) =
                model.foreground_row(&raw[3 * start..3 * (start + d - c)], start, t, lut, &mut row_labels[c..d]);
            row_labels[..a].fill(0);
            row_labels[b..].fill(0);
            *any = found && ((c, d) == (a, b) || row_labels[a..b].iter().any(|&l| l != 0));
            *kind = if *any {
                RowKinds {
                    bits: found_kinds.bits,
                    sure: (found_kinds.sure.0 + c as u32, found_kinds.sure.1 + c as u32),
                }
            } else {
                RowKinds::default()
            };
        }
    }
}

/// [`test_pixel`]'s answer for a pixel that is foreground.
const SURE: u8 = 2;

/// What one row of a window may hold ([`BackgroundModel::foreground_window`]): every row that
/// holds a kind of pixel says so, and some may say so that do not.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct RowKinds {
    /// [`WEAK_BIT`]: weak pixels ([`ENC_WEAK`], [`ENC_WEAK_DARK`]); [`SURE_BIT`]: sure foreground.
    pub bits: u8,
    /// The window's columns `from..to` that hold every sure foreground pixel of the row (empty
    /// without any).
    pub sure: (u32, u32),
}

/// The bit of [`test_pixel`]'s codes that only the weak ones set.
pub(crate) const WEAK_BIT: u8 = 4;
/// The bit [`test_lanes`] sets in its answer where some pixel is [`SURE`] (no code sets it).
pub(crate) const SURE_BIT: u8 = 8;
const _: () = assert!(
    ENC_WEAK & WEAK_BIT != 0
        && ENC_WEAK_DARK & WEAK_BIT != 0
        && SURE & WEAK_BIT == 0
        && ENC_SHADOW & WEAK_BIT == 0
        && (ENC_WEAK | ENC_WEAK_DARK | SURE | ENC_SHADOW) & SURE_BIT == 0
);

/// The foreground test for one pixel (see the module docs): 0 background, [`SURE`] foreground,
/// [`ENC_SHADOW`] darker than the background by between β_shadow and the shadow depth with its
/// chromaticity unchanged (a cast shadow, or a dark object of the background's colour); else,
/// with a weak share ([`SegmentParams::weak_share`]), [`ENC_WEAK`] brighter or of another
/// chromaticity than that share of the tolerances allows, [`ENC_WEAK_DARK`] only darker than
/// that share of β_shadow allows.
#[inline(always)]
fn test_pixel([r, g, b]: [u16; 3], m: [u16; 5], t: Thresholds) -> u8 {
    let [hr, hg, hb, es2, tol3] = m;
    let s = r + g + b;
    let ges = mulhi(t.gain, es2);
    let lighter = s.saturating_sub(ges);
    let bright_tol = mulhi(t.beta, ges) + tol3;
    let brighter = lighter > bright_tol;
    let dark = ges.saturating_sub(s);
    let dark_tol = mulhi(t.shadow, ges) + tol3;
    let darker = dark > dark_tol;
    let deeper = dark > mulhi(t.deep, ges) + tol3;
    let dc = r.abs_diff(mulhi(hr, s)) + g.abs_diff(mulhi(hg, s)) + b.abs_diff(mulhi(hb, s));
    let tc = mulhi(t.kappa, s) + mulhi(t.chroma_noise, tol3);
    let sure = brighter | deeper | (dc > tc);
    let tested = (t.weak != 0) & !sure & !darker;
    let weak = tested & ((lighter > mulhi(t.weak, bright_tol)) | (dc > mulhi(t.weak, tc)));
    let weak_dark = tested & !weak & (dark > mulhi(t.weak, dark_tol));
    SURE * u8::from(sure)
        + ENC_SHADOW * u8::from(darker & !sure)
        + ENC_WEAK * u8::from(weak)
        + ENC_WEAK_DARK * u8::from(weak_dark)
}

/// The foreground test for `LANES` pixels ([`test_pixel`]'s codes), written for the
/// auto-vectorizer: fixed-size arrays, planar inputs, no branches. Returns the codes' bitwise or
/// (reduced in registers: reading `out` back would stall on store forwarding): 0 where every pixel
/// is background, [`WEAK_BIT`] set where some pixel is weak, [`SURE_BIT`] where some is sure
/// foreground.
#[inline(always)]
fn test_lanes(p: &[u8; 3 * LANES], m: [&[u16]; 5], t: Thresholds, out: &mut [u8; LANES]) -> u8 {
    let [hr, hg, hb, es2, tol3] = m;
    let (Ok(hr), Ok(hg), Ok(hb), Ok(es2), Ok(tol3)) = (
        <&[u16; LANES]>::try_from(hr),
        <&[u16; LANES]>::try_from(hg),
        <&[u16; LANES]>::try_from(hb),
        <&[u16; LANES]>::try_from(es2),
        <&[u16; LANES]>::try_from(tol3),
    ) else {
        return 0;
    };
    let mut acc = 0u8;
    for i in 0..LANES {
        let px = [u16::from(p[3 * i]), u16::from(p[3 * i + 1]), u16::from(p[3 * i + 2])];
        let f = test_pixel(px, [hr[i], hg[i], hb[i], es2[i], tol3[i]], t);
        out[i] = f;
        acc |= f | (u8::from(f == SURE) * SURE_BIT);
    }
    acc
}

/// Replaces sure foreground by encoded colour classes.
#[inline]
fn classify(p: &[u8; 3 * LANES], lut: &ClassLut, out: &mut [u8; LANES]) {
    for (i, o) in out.iter_mut().enumerate() {
        if *o == SURE {
            *o = lut.get(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
        }
    }
}

/// Per pixel and channel the median of `frames` (each divided by its exposure gain), and the noise
/// allowance τ from the median absolute deviation around it (1.4826 MAD estimates a standard
/// deviation without the frames where the hand passed), in the model's layout.
fn temporal_median(frames: &[RgbImage], gains: &[f32], params: &SegmentParams) -> (Vec<u8>, Vec<u16>) {
    let (w, h) = frames.first().map_or((0, 0), |f| (f.width() as usize, f.height() as usize));
    let floor = u16::from(params.noise_floor);
    let inverse: Vec<f32> = gains.iter().map(|g| 1.0 / g.max(1e-3)).collect();
    let rows: Vec<(Vec<u8>, Vec<u16>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let (mut median, mut tol) = (vec![0u8; 3 * w], vec![floor; w]);
            let mut values = Vec::with_capacity(frames.len());
            let mut deviations = Vec::with_capacity(frames.len());
            for x in 0..w {
                let mut mad_sum = 0.0;
                for c in 0..3 {
                    values.clear();
                    values.extend(frames.iter().zip(&inverse).map(|(im, g)| {
                        (f32::from(im.as_raw()[3 * (y * w + x) + c]) * g).round().clamp(0.0, 255.0) as u8
                    }));
                    let mid = values.len() / 2;
                    let (_, m, _) = values.select_nth_unstable(mid);
                    let m = *m;
                    median[3 * x + c] = m;
                    deviations.clear();
                    deviations.extend(values.iter().map(|&v| v.abs_diff(m)));
                    let (_, d, _) = deviations.select_nth_unstable(mid);
                    mad_sum += f64::from(*d);
                }
                let sd = 1.4826 * mad_sum / 3.0;
                tol[x] = (params.noise_sigmas * sd).ceil().clamp(f64::from(floor), 255.0) as u16;
            }
            (median, tol)
        })
        .collect();
    let mut median_raw = Vec::with_capacity(3 * w * h);
    let mut tol = Vec::with_capacity(w * h);
    for (m, t) in rows {
        median_raw.extend(m);
        tol.extend(t);
    }
    (median_raw, tol)
}

#[cfg(test)]
mod tests {
    use hullcut_dataset::label;

    use super::*;

    /// A reproducible image whose pixels scatter around `base` by up to `spread` per channel.
    fn noisy(w: u32, h: u32, seed: u64, base: [u8; 3], spread: u8) -> RgbImage {
        let mut state = seed;
        RgbImage::from_fn(w, h, |_, _| {
            image::Rgb(base.map(|c| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let offset = (state >> 33) as u32 % (2 * u32::from(spread) + 1);
                (u32::from(c) + offset).saturating_sub(u32::from(spread)).min(255) as u8
            }))
        })
    }

    #[test]
    fn the_dispatched_window_pass_labels_every_pixel_as_the_one_pixel_test_does() -> Result<(), CaptureError> {
        // Possible shadows down to 0.5 of the background's brightness (the loop's setting).
        let params = SegmentParams { shadow_depth: 0.5, ..SegmentParams::default() };
        // Pixels seen as background, possible shadow, sure foreground and weak.
        let mut seen = [0usize; 4];
        // Widths that are and are not multiples of the vector step, windows at odd offsets.
        for (seed, (w, h)) in [(1, (64, 9)), (2, (97, 13)), (3, (37, 21))].into_iter() {
            let empty: Vec<RgbImage> = (0..3).map(|k| noisy(w, h, seed * 10 + k, [120, 110, 90], 6)).collect();
            let model = BackgroundModel::from_images(0, &empty, &params)?;
            // Background with its noise, the background darkened (possible shadows), other colours.
            let (calm, wild) =
                (noisy(w, h, seed * 100, [120, 110, 90], 4), noisy(w, h, seed * 200, [110, 100, 95], 90));
            let scene = RgbImage::from_fn(w, h, |x, y| match (x / 3 + 2 * y) % 3 {
                0 => *calm.get_pixel(x, y),
                1 => image::Rgb(calm.get_pixel(x, y).0.map(|c| (f64::from(c) * 0.7) as u8)),
                _ => *wild.get_pixel(x, y),
            });
            let lut = ClassLut::from_fn(|[r, _, b]| if r > b { label::HAND } else { label::SCALPEL }, |l| l + 10);
            for gain in [1.0, 0.8, 1.3] {
                let t = Thresholds::new(&params, gain);
                // Stretches that start and end anywhere (off the window, reversed, empty), and
                // none for the last rows.
                let stretches: Vec<(u32, u32)> = (0..h - 2)
                    .map(|y| ((y * 7 + seed as u32) % (w + 4), (y * 13 + 2 * seed as u32) % (w + 6)))
                    .collect();
                let windows = [(0, 0, w as usize), (3, 2, w as usize - 5), (w as usize / 2, 1, 1), (4, 4, 0)];
                for ((x0, y0, ww), stretches) in
                    windows.into_iter().flat_map(|win| [(win, None), (win, Some(&stretches[..]))])
                {
                    let rows = h as usize - y0;
                    let (mut labels, mut active, mut kinds) =
                        (vec![7u8; ww * rows], vec![true; rows], vec![RowKinds::default(); rows]);
                    model.foreground_window(
                        scene.as_raw(),
                        w as usize,
                        (x0, y0, ww),
                        stretches,
                        t,
                        &lut,
                        &mut labels,
                        &mut active,
                        &mut kinds,
                    );
                    for j in 0..rows {
                        let (mut any, mut any_weak) = (false, false);
                        for i in 0..ww {
                            let k = (y0 + j) * w as usize + x0 + i;
                            let tested = stretches.is_none_or(|s| {
                                s.get(y0 + j).is_some_and(|&(a, b)| (a as usize..b as usize).contains(&(x0 + i)))
                            });
                            let p = [0, 1, 2].map(|c| scene.as_raw()[3 * k + c]);
                            let m =
                                [model.chroma_r[k], model.chroma_g[k], model.chroma_b[k], model.sum2[k], model.tol3[k]];
                            let code = if tested { test_pixel(p.map(u16::from), m, t) } else { 0 };
                            let expected = if code == SURE { lut.get(p[0], p[1], p[2]) } else { code };
                            assert_eq!(
                                labels[j * ww + i],
                                expected,
                                "pixel ({}, {}), window from {x0}",
                                x0 + i,
                                y0 + j
                            );
                            any |= code != 0;
                            any_weak |= code == ENC_WEAK || code == ENC_WEAK_DARK;
                            if code == SURE {
                                let (from, to) = kinds[j].sure;
                                assert!(kinds[j].bits & SURE_BIT != 0, "row {} has sure pixels", y0 + j);
                                assert!(
                                    (from as usize..to as usize).contains(&i),
                                    "({}, {}) in {from}..{to}",
                                    x0 + i,
                                    y0 + j
                                );
                            }
                            seen[match code {
                                0 => 0,
                                ENC_SHADOW => 1,
                                ENC_WEAK | ENC_WEAK_DARK => 3,
                                _ => 2,
                            }] += 1;
                        }
                        assert_eq!(active[j], any, "row {}", y0 + j);
                        assert!(kinds[j].bits & WEAK_BIT != 0 || !any_weak, "row {} has weak pixels", y0 + j);
                    }
                }
            }
        }
        assert!(seen.iter().all(|&n| n > 100), "every kind of pixel tested: {seen:?}");
        Ok(())
    }

    #[test]
    fn the_exposure_estimate_is_the_median_ratio_over_the_grid_pixels_of_the_backgrounds_colour()
    -> Result<(), CaptureError> {
        let params = SegmentParams::default();
        // Dark model pixels (skipped), an image smaller than a step and sizes off the grid.
        for (seed, (w, h), base) in
            [(1, (70, 41), [120, 110, 90]), (2, (33, 50), [20, 14, 12]), (3, (9, 7), [90, 90, 90])]
        {
            let empty: Vec<RgbImage> = (0..3).map(|k| noisy(w, h, seed * 10 + k, base, 12)).collect();
            let model = BackgroundModel::from_images(0, &empty, &params)?;
            for gain in [0.7f32, 1.0, 1.4] {
                // The background scaled by the gain, with a band of another colour (not its
                // chromaticity: left out of the median).
                let calm = noisy(w, h, seed * 100, base, 3);
                let image = RgbImage::from_fn(w, h, |x, y| {
                    if (x + y) % 5 == 0 {
                        image::Rgb([30, 200, 240])
                    } else {
                        image::Rgb(calm.get_pixel(x, y).0.map(|c| (f32::from(c) * gain).min(255.0) as u8))
                    }
                });
                // The estimate written out plainly: every GAIN_STEP-th pixel of every
                // GAIN_STEP-th row, from the model's per-pixel arrays.
                let mut ratios = Vec::new();
                for y in (GAIN_STEP / 2..h as usize).step_by(GAIN_STEP) {
                    for x in (GAIN_STEP / 2..w as usize).step_by(GAIN_STEP) {
                        let k = y * w as usize + x;
                        let (p, e) =
                            (image.get_pixel(x as u32, y as u32).0, model.mean.get_pixel(x as u32, y as u32).0);
                        let es: u32 = e.iter().map(|&v| u32::from(v)).sum();
                        let s: f32 = p.iter().map(|&v| f32::from(v)).sum();
                        let k_s = s / es as f32;
                        let dc: f32 = (0..3).map(|c| (f32::from(p[c]) - f32::from(e[c]) * k_s).abs()).sum();
                        if es >= GAIN_MIN_SUM && dc <= params.chroma_tolerance as f32 * s + f32::from(model.tol3[k]) {
                            ratios.push(k_s);
                        }
                    }
                }
                ratios.sort_by(f32::total_cmp);
                let expected =
                    ratios.get(ratios.len() / 2).map_or(1.0, |&m| f64::from(m).clamp(GAIN_RANGE.0, GAIN_RANGE.1));
                let estimated = model.exposure_gain(&image, &params, &mut Vec::new());
                assert_eq!(estimated, expected, "seed {seed}, gain {gain}");
                if base == [120, 110, 90] {
                    assert!((estimated - f64::from(gain)).abs() < 0.05, "gain {gain} estimated {estimated}");
                }
            }
        }
        Ok(())
    }
}
