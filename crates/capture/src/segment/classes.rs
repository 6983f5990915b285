//! Colour classes of the foreground: one Gaussian per label in (r/s, b/s, s/765), where s = r+g+b.
//!
//! Chromaticity (r/s, b/s) does not change when shading or exposure scales a colour, so it carries
//! the label; brightness (s/765) is a weak third feature with a wide spread. The classes are
//! compiled into a lookup table over 6-bit-per-channel RGB (256 KiB) so that classifying a
//! foreground pixel is one load.

use hullcut_dataset::label;
use image::{GrayImage, RgbImage};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU8, Ordering};

use crate::error::CaptureError;

/// Pixels darker than this channel sum carry no usable chromaticity; they are left out when
/// learning classes.
const MIN_LEARN_SUM: u32 = 24;

/// Variance added to every diagonal entry of a learnt covariance (keeps it invertible when the
/// training pixels are nearly uniform): 0.01² in chromaticity and brightness.
const COV_FLOOR: f64 = 1e-4;

/// One colour class: a label and a Gaussian over (r/s, b/s, s/765).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColourClass {
    /// The label this class assigns (e.g. [`label::HAND`]).
    pub label: u8,
    /// Mean feature vector (r/s, b/s, s/765).
    pub mean: [f64; 3],
    /// Covariance of the features.
    pub cov: [[f64; 3]; 3],
}

impl ColourClass {
    /// A class from an albedo (8-bit RGB at full light) whose brightness varies uniformly between
    /// `shade.0` and `shade.1` times the albedo, with chromaticity spread `chroma_sd`.
    pub fn from_albedo(label: u8, albedo: [f64; 3], shade: (f64, f64), chroma_sd: f64) -> Self {
        let s = albedo[0] + albedo[1] + albedo[2];
        let (r, b) = if s > 0.0 { (albedo[0] / s, albedo[2] / s) } else { (1.0 / 3.0, 1.0 / 3.0) };
        let (lo, hi) = (s / 765.0 * shade.0, s / 765.0 * shade.1);
        // A uniform distribution on [lo, hi] has standard deviation (hi - lo) / sqrt(12).
        let y_sd = ((hi - lo) / 12f64.sqrt()).max(0.02);
        let c2 = chroma_sd * chroma_sd;
        Self { label, mean: [r, b, 0.5 * (lo + hi)], cov: [[c2, 0.0, 0.0], [0.0, c2, 0.0], [0.0, 0.0, y_sd * y_sd]] }
    }

    /// Squared Mahalanobis distance of a feature vector from the class (`None` for a singular
    /// covariance).
    pub fn mahalanobis2(&self, f: &[f64; 3]) -> Option<f64> {
        let (inv, _) = self.inverse()?;
        let d = [f[0] - self.mean[0], f[1] - self.mean[1], f[2] - self.mean[2]];
        Some((0..3).map(|i| (0..3).map(|j| d[i] * inv[i][j] * d[j]).sum::<f64>()).sum())
    }

    fn inverse(&self) -> Option<([[f64; 3]; 3], f64)> {
        let m = &self.cov;
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        if !(det.is_finite() && det > 0.0) {
            return None;
        }
        let mut inv = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                let (a, b) = ((j + 1) % 3, (j + 2) % 3);
                let (c, d) = ((i + 1) % 3, (i + 2) % 3);
                inv[i][j] = (m[a][c] * m[b][d] - m[a][d] * m[b][c]) / det;
            }
        }
        Some((inv, det.ln()))
    }
}

/// The foreground's colour classes and how to decide between them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColourClasses {
    /// The classes; several may share a label.
    pub classes: Vec<ColourClass>,
    /// A foreground pixel whose squared Mahalanobis distance to every class exceeds this is
    /// labelled [`label::UNKNOWN`]; `None` always takes the most likely class.
    pub reject_mahalanobis2: Option<f64>,
}

fn features(r: f64, g: f64, b: f64) -> [f64; 3] {
    let s = r + g + b;
    if s <= 0.0 { [1.0 / 3.0, 1.0 / 3.0, 0.0] } else { [r / s, b / s, s / 765.0] }
}

impl ColourClasses {
    /// Learns one class per foreground label ([`label::NAMED`]) from images and their truth
    /// masks: the mean and covariance of the features of the label's pixels (pixels darker than a
    /// channel sum of 24 are skipped; a label needs `min_pixels` pixels); no rejection.
    pub fn fit<'a>(
        samples: impl IntoIterator<Item = (&'a RgbImage, &'a GrayImage)>,
        min_pixels: u64,
    ) -> Result<Self, CaptureError> {
        // Per label: count, sum of features, sum of outer products.
        let mut acc = [(0u64, [0.0f64; 3], [[0.0f64; 3]; 3]); 2];
        for (i, (image, mask)) in samples.into_iter().enumerate() {
            if image.dimensions() != mask.dimensions() {
                return Err(CaptureError::ColourClass {
                    label: "any".into(),
                    message: format!(
                        "sample {i}: image is {}x{}, mask is {}x{}",
                        image.width(),
                        image.height(),
                        mask.width(),
                        mask.height()
                    ),
                });
            }
            for (px, &m) in image.pixels().zip(mask.as_raw()) {
                let Some(k) = label::NAMED.iter().position(|&(l, _)| l == m) else { continue };
                let [r, g, b] = px.0;
                if u32::from(r) + u32::from(g) + u32::from(b) < MIN_LEARN_SUM {
                    continue;
                }
                let f = features(f64::from(r), f64::from(g), f64::from(b));
                let (n, sum, outer) = &mut acc[k];
                *n += 1;
                for i in 0..3 {
                    sum[i] += f[i];
                    for j in 0..3 {
                        outer[i][j] += f[i] * f[j];
                    }
                }
            }
        }
        let mut classes = Vec::new();
        for (k, &(lbl, name)) in label::NAMED.iter().enumerate() {
            let (n, sum, outer) = acc[k];
            if n < min_pixels.max(2) {
                return Err(CaptureError::ColourClass {
                    label: name.into(),
                    message: format!("{n} usable pixel(s) in the truth masks, at least {min_pixels} needed"),
                });
            }
            let nf = n as f64;
            let mean = sum.map(|s| s / nf);
            let mut cov = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    cov[i][j] = (outer[i][j] - nf * mean[i] * mean[j]) / (nf - 1.0);
                }
                cov[i][i] += COV_FLOOR;
            }
            classes.push(ColourClass { label: lbl, mean, cov });
        }
        Ok(Self { classes, reject_mahalanobis2: None })
    }

    /// The label of one colour (maximum likelihood over the classes; [`label::UNKNOWN`] when
    /// rejected or when there are no usable classes).
    pub fn classify(&self, rgb: [u8; 3]) -> u8 {
        let compiled = self.compile();
        classify_compiled(
            &compiled,
            self.reject_mahalanobis2,
            0.0,
            features(f64::from(rgb[0]), f64::from(rgb[1]), f64::from(rgb[2])),
        )
    }

    fn compile(&self) -> Vec<Compiled> {
        self.classes
            .iter()
            .filter_map(|c| c.inverse().map(|(inv, log_det)| Compiled { label: c.label, mean: c.mean, inv, log_det }))
            .collect()
    }

    /// Checks that every class has a finite mean and an invertible covariance.
    pub fn validate(&self) -> Result<(), CaptureError> {
        for c in &self.classes {
            if c.mean.iter().any(|v| !v.is_finite()) || c.inverse().is_none() {
                return Err(CaptureError::ColourClass {
                    label: label::NAMED
                        .iter()
                        .find(|n| n.0 == c.label)
                        .map_or_else(|| c.label.to_string(), |n| n.1.into()),
                    message: "mean not finite or covariance not positive definite".into(),
                });
            }
        }
        Ok(())
    }
}

/// A class ready for evaluation: inverse covariance and log-determinant.
#[derive(Debug, Clone, Copy)]
struct Compiled {
    label: u8,
    mean: [f64; 3],
    inv: [[f64; 3]; 3],
    log_det: f64,
}

/// The most likely class's label; [`label::UNKNOWN`] when its squared Mahalanobis distance exceeds
/// `reject`, or when it beats the runner-up by less than `margin` (in units of the score,
/// `m² + ln det Σ`, i.e. twice the log-likelihood ratio).
fn classify_compiled(compiled: &[Compiled], reject: Option<f64>, margin: f64, f: [f64; 3]) -> u8 {
    scores(compiled, f).decide(reject, margin)
}

/// How the classes score one colour: the best score (`m² + ln det Σ`), its label and squared
/// Mahalanobis distance, and the runner-up's score.
#[derive(Debug, Clone, Copy)]
struct Scores {
    best: (f64, u8, f64),
    second: f64,
}

impl Scores {
    /// The label [`classify_compiled`] gives for these scores.
    fn decide(self, reject: Option<f64>, margin: f64) -> u8 {
        let Scores { best, second } = self;
        match reject {
            Some(r) if best.2 > r => label::UNKNOWN,
            _ if second - best.0 < margin => label::UNKNOWN,
            _ => best.1,
        }
    }
}

/// The classes' scores of the features `f`: the runner-up is the best class of another label (a
/// label may have several classes, as the tool's body and its blade: a colour between two of them
/// is still surely that label's).
fn scores(compiled: &[Compiled], f: [f64; 3]) -> Scores {
    let scored = compiled.iter().map(|Compiled { label: lbl, mean, inv, log_det }| {
        let d = [f[0] - mean[0], f[1] - mean[1], f[2] - mean[2]];
        let mut m2 = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                m2 += d[i] * inv[i][j] * d[j];
            }
        }
        // Negative log-likelihood up to a constant.
        (m2 + log_det, *lbl, m2)
    });
    let best =
        scored.clone().fold((f64::INFINITY, label::UNKNOWN, f64::INFINITY), |b, s| if s.0 < b.0 { s } else { b });
    let second = scored.filter(|s| s.1 != best.1).fold(f64::INFINITY, |a, s| a.min(s.0));
    Scores { best, second }
}

/// Bits kept per channel in the lookup table.
const LUT_BITS: u32 = 6;

/// Colour → label lookup over 6-bit-per-channel RGB, in the segmenter's working encoding.
#[derive(Debug, Clone)]
pub(crate) struct ClassLut {
    table: Vec<u8>,
}

impl ClassLut {
    /// Compiles the classes (every colour unknown without them); `encode` maps a label to the
    /// working encoding.
    pub(crate) fn new(classes: Option<&ColourClasses>, encode: impl Fn(u8) -> u8 + Sync) -> Self {
        Self::with_margin(classes, 0.0, encode)
    }

    /// As [`ClassLut::new`], leaving unknown the colours whose best class wins by less than
    /// `margin` (see [`classify_compiled`]).
    pub(crate) fn with_margin(classes: Option<&ColourClasses>, margin: f64, encode: impl Fn(u8) -> u8 + Sync) -> Self {
        let Some(classes) = classes else { return Self::from_fn(|_| label::UNKNOWN, encode) };
        let compiled = classes.compile();
        let reject = classes.reject_mahalanobis2;
        Self::from_fn(
            |[r, g, b]| {
                classify_compiled(&compiled, reject, margin, features(f64::from(r), f64::from(g), f64::from(b)))
            },
            encode,
        )
    }

    /// The table of `label_of` evaluated at every bin's centre colour; `encode` maps a label to
    /// the working encoding.
    pub(crate) fn from_fn(label_of: impl Fn([u8; 3]) -> u8 + Sync, encode: impl Fn(u8) -> u8 + Sync) -> Self {
        let table = Self::bins().map(|rgb| encode(label_of(rgb))).collect();
        Self { table }
    }

    /// Every bin's centre colour, in the table's order.
    fn bins() -> impl IndexedParallelIterator<Item = [u8; 3]> {
        let n = 1usize << LUT_BITS;
        let step = 1usize << (8 - LUT_BITS);
        // Centre of the bin.
        let c = move |v: usize| (v * step + step / 2) as u8;
        (0..n * n * n).into_par_iter().map(move |i| {
            let (r, g, b) = (i >> (2 * LUT_BITS), (i >> LUT_BITS) & (n - 1), i & (n - 1));
            [c(r), c(g), c(b)]
        })
    }

    /// The encoded label of one colour.
    #[inline(always)]
    pub(crate) fn get(&self, r: u8, g: u8, b: u8) -> u8 {
        let s = 8 - LUT_BITS;
        let i = (usize::from(r >> s) << (2 * LUT_BITS)) | (usize::from(g >> s) << LUT_BITS) | usize::from(b >> s);
        self.table.get(i).copied().unwrap_or(0)
    }
}

/// Colour classes compiled for labelling foreground pixels: a table over 6-bit-per-channel RGB
/// (256 KiB) whose bins are classified on their first lookup, from any thread. A frame set asks
/// about a few thousand colours, not all 262,144, and a table serves several frame sets before
/// the colours are compiled again: classifying every bin up front took ~6 ms of a learning frame
/// set's labelling (three tables, on the built-in scene). Lookups give what classifying each bin's
/// centre colour gives, whichever thread asks first.
#[derive(Debug)]
pub struct ColourLut {
    compiled: Vec<Compiled>,
    reject: Option<f64>,
    margin: f64,
    /// Per bin: its label, or [`ColourLut::UNSET`].
    table: Vec<AtomicU8>,
}

impl Clone for ColourLut {
    fn clone(&self) -> Self {
        ColourLut {
            compiled: self.compiled.clone(),
            reject: self.reject,
            margin: self.margin,
            table: self.table.iter().map(|b| AtomicU8::new(b.load(Ordering::Relaxed))).collect(),
        }
    }
}

impl ColourLut {
    /// A bin not classified yet (no label has this value: labels are 0, 1, 2 and 255).
    const UNSET: u8 = 254;

    /// Compiles the classes.
    pub fn new(classes: &ColourClasses) -> Self {
        Self::confident(classes, 0.0)
    }

    /// Compiles the classes, leaving [`label::UNKNOWN`] the colours whose most likely class is
    /// not at least `e^(margin/2)` times as likely as the next: a colour both classes could
    /// explain decides nothing.
    pub fn confident(classes: &ColourClasses, margin: f64) -> Self {
        ColourLut {
            compiled: classes.compile(),
            reject: classes.reject_mahalanobis2,
            margin,
            table: (0..1usize << (3 * LUT_BITS)).map(|_| AtomicU8::new(Self::UNSET)).collect(),
        }
    }

    /// [`ColourLut::new`] and [`ColourLut::confident`] of the same classes.
    pub fn new_and_confident(classes: &ColourClasses, margin: f64) -> (Self, Self) {
        (Self::new(classes), Self::confident(classes, margin))
    }

    /// The label of one colour (its bin's centre, classified on the bin's first lookup).
    #[inline]
    pub fn get(&self, rgb: [u8; 3]) -> u8 {
        let s = 8 - LUT_BITS;
        let [r, g, b] = rgb.map(|v| usize::from(v >> s));
        let Some(slot) = self.table.get((r << (2 * LUT_BITS)) | (g << LUT_BITS) | b) else { return label::UNKNOWN };
        match slot.load(Ordering::Relaxed) {
            Self::UNSET => {
                let step = 1usize << s;
                let c = |v: usize| f64::from((v * step + step / 2) as u8);
                // Threads that meet the bin unset at once store the same label.
                let l = classify_compiled(&self.compiled, self.reject, self.margin, features(c(r), c(g), c(b)));
                slot.store(l, Ordering::Relaxed);
                l
            }
            l => l,
        }
    }

    /// Gives every foreground pixel of `mask` (any non-zero value) the label of its colour in
    /// `image` (same size; nothing is done otherwise).
    pub fn label_foreground(&self, image: &RgbImage, mask: &mut GrayImage) {
        if image.dimensions() != mask.dimensions() {
            return;
        }
        for (m, p) in mask.iter_mut().zip(image.as_raw().chunks_exact(3)) {
            if *m != label::BACKGROUND {
                *m = self.get([p[0], p[1], p[2]]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The label of the centre of `rgb`'s bin, classified directly.
    fn at_bin_centre(classes: &ColourClasses, margin: f64, rgb: [u8; 3]) -> u8 {
        let step = 1u8 << (8 - LUT_BITS);
        let [r, g, b] = rgb.map(|v| f64::from((v / step) * step + step / 2));
        classify_compiled(&classes.compile(), classes.reject_mahalanobis2, margin, features(r, g, b))
    }

    /// Every bin, twice (the second read comes from the table), at two colours in the bin, from
    /// several threads at once: each lookup is the bin centre's class.
    #[test]
    fn the_table_reads_as_classifying_each_bins_centre_from_any_thread() {
        let shade = (0.25, 1.15);
        let classes = ColourClasses {
            classes: vec![
                ColourClass::from_albedo(label::HAND, [200.0, 150.0, 120.0], shade, 0.03),
                ColourClass::from_albedo(label::SCALPEL, [150.0, 150.0, 155.0], shade, 0.02),
                ColourClass::from_albedo(label::SCALPEL, [180.0, 150.0, 60.0], shade, 0.03),
            ],
            reject_mahalanobis2: Some(11.34),
        };
        let lut = ColourLut::confident(&classes, 3.0);
        let expected: Vec<u8> = (0..64usize * 64 * 64)
            .map(|i| at_bin_centre(&classes, 3.0, [(i >> 12) as u8 * 4, ((i >> 6) & 63) as u8 * 4, (i & 63) as u8 * 4]))
            .collect();
        for pass in 0..2u8 {
            // Four threads, each over every bin from its own start: most bins are first met by
            // several at once.
            let labels: Vec<[usize; 256]> = (0..4usize)
                .into_par_iter()
                .map(|t| {
                    let mut labels = [0usize; 256];
                    for n in 0..64usize * 64 * 64 {
                        let i = (n + t * 4099) % (64 * 64 * 64);
                        let rgb = [
                            (i >> 12) as u8 * 4 + pass,
                            ((i >> 6) & 63) as u8 * 4 + 3 * pass,
                            (i & 63) as u8 * 4 + pass,
                        ];
                        let l = lut.get(rgb);
                        assert_eq!(l, expected[i], "{rgb:?}");
                        labels[usize::from(l)] += 1;
                    }
                    labels
                })
                .collect();
            let seen = [label::HAND, label::SCALPEL, label::UNKNOWN].map(|l| labels[0][usize::from(l)]);
            assert!(seen.iter().all(|&n| n > 0), "hand, scalpel and unknown colours all read: {seen:?}");
        }
        // A copy reads as the original, bins classified or not.
        let copy = lut.clone();
        assert_eq!(copy.get([8, 200, 90]), at_bin_centre(&classes, 3.0, [8, 200, 90]));
    }

    #[test]
    fn both_tables_at_once_are_the_tables_with_and_without_the_margin() {
        let shade = (0.25, 1.15);
        for reject in [None, Some(11.34)] {
            let classes = ColourClasses {
                classes: vec![
                    ColourClass::from_albedo(label::HAND, [90.0, 60.0, 160.0], shade, 0.04),
                    ColourClass::from_albedo(label::SCALPEL, [140.0, 140.0, 150.0], shade, 0.02),
                ],
                reject_mahalanobis2: reject,
            };
            let (all, confident) = ColourLut::new_and_confident(&classes, 3.0);
            let mut differ = 0;
            for r in (0..=255u8).step_by(4) {
                for g in (0..=255u8).step_by(4) {
                    for b in (0..=255u8).step_by(4) {
                        let (one, two) =
                            (at_bin_centre(&classes, 0.0, [r, g, b]), at_bin_centre(&classes, 3.0, [r, g, b]));
                        assert_eq!(all.get([r, g, b]), one, "{r} {g} {b}");
                        assert_eq!(confident.get([r, g, b]), two, "{r} {g} {b}");
                        differ += usize::from(one != two);
                    }
                }
            }
            assert!(differ > 100, "the margin leaves {differ} colours unknown");
        }
    }

    /// The margin of the sure labels is against the best class of another label: a colour between
    /// two classes of the tool (a blue handle and a grey blade) is surely the tool's, one between
    /// the tool's and the hand's is not.
    #[test]
    fn a_colour_between_two_classes_of_one_label_is_surely_that_label() {
        let shade = (0.25, 1.15);
        let (blue, grey, purple) = ([50.0, 110.0, 225.0], [120.0, 124.0, 140.0], [150.0, 60.0, 120.0]);
        let classes = ColourClasses {
            classes: vec![
                ColourClass::from_albedo(label::HAND, purple, shade, 0.02),
                ColourClass::from_albedo(label::SCALPEL, blue, shade, 0.03),
                ColourClass::from_albedo(label::SCALPEL, grey, shade, 0.03),
            ],
            reject_mahalanobis2: None,
        };
        let sure = ColourLut::confident(&classes, 3.0);
        let mix = |a: [f64; 3], b: [f64; 3], t: f64| [0, 1, 2].map(|i| (a[i] * (1.0 - t) + b[i] * t) as u8);
        // Where the blue and the grey classes score alike (somewhere between them), the tool.
        let between: Vec<u8> = (0..=20).map(|k| sure.get(mix(blue, grey, f64::from(k) / 20.0))).collect();
        assert!(between.iter().all(|&l| l == label::SCALPEL), "{between:?}");
        // Between the grey and the glove, somewhere not sure.
        let across: Vec<u8> = (0..=20).map(|k| sure.get(mix(grey, purple, f64::from(k) / 20.0))).collect();
        assert!(across.contains(&label::UNKNOWN), "{across:?}");
        assert_eq!((across[0], across[20]), (label::SCALPEL, label::HAND));
    }
}
