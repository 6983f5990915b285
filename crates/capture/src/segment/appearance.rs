//! An appearance model learned from the recording: per label (hand, scalpel), the colour
//! statistics of pixels whose label is known, from the geometric labels of frames whose tool was
//! trusted or from masks a lab drew for a few frames, with old frames forgotten at a steady rate
//! so that the model follows the light. No colour is written in the code.
//!
//! Each label is one Gaussian over (r/s, b/s, s/765) (s = r + g + b), the features of
//! [`ColourClasses`]: chromaticity does not change when shading or exposure scales a colour. The
//! tool has two where the learner is told which of its pixels are the blade's
//! ([`AppearanceModel::learn_parts`]): a grey blade on a blue handle is neither blue nor their
//! blend, and one class for both learned the handle alone (the hand's class explained the grey
//! better, so the blade's samples were gated out) and left the colours calling the blade the
//! hand's (random:359 in random:367).

use hullcut_dataset::label;
use image::{GrayImage, RgbImage};
use serde::{Deserialize, Serialize};

use super::Window;
use super::classes::{ColourClass, ColourClasses, ColourLut};

/// Pixels darker than this channel sum carry no usable chromaticity and are not learned from.
const MIN_SUM: u32 = 24;
/// Variance added to each diagonal entry (keeps a covariance invertible on uniform samples).
const COV_FLOOR: f64 = 1e-4;
/// Once both labels are learned, a pixel whose colour is e^3 (20) times likelier under the other
/// label is taken as wrongly labelled and not learned.
const GATE_LOG_RATIO: f64 = 3.0;

/// Running sums of one label's features, with forgetting.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
struct Sums {
    weight: f64,
    sum: [f64; 3],
    outer: [[f64; 3]; 3],
}

impl Sums {
    fn add(&mut self, f: [f64; 3]) {
        self.weight += 1.0;
        for i in 0..3 {
            self.sum[i] += f[i];
            for j in 0..3 {
                self.outer[i][j] += f[i] * f[j];
            }
        }
    }

    fn merged(&self, other: &Sums) -> Sums {
        let mut out = *self;
        out.weight += other.weight;
        for i in 0..3 {
            out.sum[i] += other.sum[i];
            for j in 0..3 {
                out.outer[i][j] += other.outer[i][j];
            }
        }
        out
    }

    fn scale(&mut self, k: f64) {
        self.weight *= k;
        self.sum = self.sum.map(|s| s * k);
        self.outer = self.outer.map(|r| r.map(|v| v * k));
    }

    fn class(&self, lbl: u8) -> Option<ColourClass> {
        if self.weight < 2.0 {
            return None;
        }
        let n = self.weight;
        let mean = self.sum.map(|s| s / n);
        let mut cov = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] = (self.outer[i][j] - n * mean[i] * mean[j]) / (n - 1.0);
            }
            cov[i][i] += COV_FLOOR;
        }
        Some(ColourClass { label: lbl, mean, cov })
    }
}

/// Where the model's samples came from, for reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AppearanceSources {
    /// Frame sets whose geometric labels were learned from.
    pub geometry_frames: u64,
    /// Views whose drawn masks were learned from.
    pub mask_views: u64,
}

/// The slots of [`AppearanceModel`]'s sums: per label of [`label::NAMED`] (hand, scalpel: the
/// tool but its blade where that is told apart), then the blade.
const SLOTS: [(u8, &str); 3] = [(label::HAND, "hand"), (label::SCALPEL, "scalpel"), (label::SCALPEL, "blade")];

/// The names of what the model learns, in the order of [`AppearanceModel::summary`] (and of the
/// reports' `appearance[]`): `hand`, `scalpel`, `blade`.
pub const LEARNED_NAMES: [&str; 3] = [SLOTS[0].1, SLOTS[1].1, SLOTS[2].1];

/// The slot of the blade's pixels in [`SLOTS`].
const BLADE: usize = 2;

/// The learned appearance of the hand and the tool (see the module docs).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AppearanceModel {
    /// Per slot of [`SLOTS`]: hand, scalpel (the tool's body where the blade is told apart), blade.
    sums: [Sums; 3],
    /// Kept per new frame set of samples: the weight of what was learned `n` frame sets ago is
    /// `forget^n`.
    pub forget: f64,
    /// Learn from every `stride`-th pixel of every `stride`-th row of the hand (the tool, a small
    /// part of the image, from every pixel).
    pub stride: usize,
    /// Pixels a label needs before it is used.
    pub min_pixels: f64,
    /// Where the samples came from.
    pub sources: AppearanceSources,
    /// The classes as they were at the last [`AppearanceModel::age`], compiled to judge new
    /// samples.
    #[serde(skip)]
    gate: Option<ColourLut>,
}

impl Default for AppearanceModel {
    fn default() -> Self {
        AppearanceModel {
            sums: [Sums::default(); 3],
            forget: 0.97,
            stride: 3,
            min_pixels: 200.0,
            sources: AppearanceSources::default(),
            gate: None,
        }
    }
}

/// One label's learned colour, for reports.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LearnedColour {
    /// `hand`, `scalpel` (the tool, but its blade once that is learned apart) or `blade`.
    pub label: String,
    /// Weight of the samples (pixels, decayed).
    pub pixels: f64,
    /// Mean (r/s, b/s, s/765).
    pub mean: Option<[f64; 3]>,
    /// Standard deviations of the three features.
    pub sd: Option<[f64; 3]>,
    /// The mean as an 8-bit colour at mid brightness, for people.
    pub rgb: Option<[u8; 3]>,
}

fn features(p: [u8; 3]) -> Option<[f64; 3]> {
    let s = u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]);
    (s >= MIN_SUM).then(|| {
        let s = f64::from(s);
        [f64::from(p[0]) / s, f64::from(p[2]) / s, s / 765.0]
    })
}

impl AppearanceModel {
    /// Learns from one image and its labels (hand and scalpel pixels; others ignored). With
    /// `erode`, only pixels whose four neighbours share their label (away from edges, where colours
    /// blend and labels are least sure). Labels from geometry are wrong here and there (a hidden
    /// part of the tool drawn as seen): once both labels are learned, a pixel whose colour the
    /// other label explains far better (e³ times) is not learned.
    pub fn learn(&mut self, image: &RgbImage, labels: &GrayImage, erode: bool) {
        self.learn_within(image, labels, erode, Window::whole(labels.width(), labels.height()));
    }

    /// [`AppearanceModel::learn`] for labels that are background outside `window`: only its
    /// pixels are scanned, and the model learns what it would from the whole image.
    pub fn learn_within(&mut self, image: &RgbImage, labels: &GrayImage, erode: bool, window: Window) {
        self.learn_parts(image, labels, erode, window, &[]);
    }

    /// [`AppearanceModel::learn_within`] with the blade told apart: the scalpel pixels whose
    /// indices (row-major, in `labels`) are in `blade` (sorted ascending; the pixels inside the
    /// drawn blade's outline) are learned as the blade's, the tool's others as its body's.
    pub fn learn_parts(&mut self, image: &RgbImage, labels: &GrayImage, erode: bool, window: Window, blade: &[usize]) {
        if image.dimensions() != labels.dimensions() {
            return;
        }
        let (w, h) = (labels.width() as usize, labels.height() as usize);
        let win = window.clipped(labels.width(), labels.height());
        let (x0, x1) = (win.x0 as usize, win.x1 as usize);
        let (raw, px) = (labels.as_raw(), image.as_raw());
        let stride = self.stride.max(1);
        let gate = self.gate.as_ref();
        // Only the window's rows that hold foreground, and in them only the pixels that are not
        // background (found by a scan that vectorizes), in the order of a plain scan: the sums
        // come out the same. Border pixels (no four neighbours) are never learned.
        let any = |j: usize| raw[j * w + x0..j * w + x1].iter().any(|&p| p != label::BACKGROUND);
        let rows = win.y0 as usize..win.y1 as usize;
        let first = rows.clone().find(|&j| any(j)).unwrap_or(h);
        let last = rows.rev().find(|&j| any(j)).unwrap_or(0);
        let (lo, hi) = (x0.max(1), x1.min(w.saturating_sub(1)));
        // The pixels are visited in increasing index: the blade's next index is all that is kept.
        let mut next_blade = blade.iter().copied().peekable();
        for j in first.max(1)..(last + 1).min(h.saturating_sub(1)) {
            let row = &raw[j * w..(j + 1) * w];
            let mut i = lo;
            while i < hi {
                match row[i..hi].iter().position(|&p| p != label::BACKGROUND) {
                    Some(skip) => i += skip,
                    None => break,
                }
                let x = i;
                i += 1;
                let k = j * w + x;
                let l = raw[k];
                let Some(mut slot) = label::NAMED.iter().position(|&(n, _)| n == l) else { continue };
                if l == label::HAND && !(x.is_multiple_of(stride) && j.is_multiple_of(stride)) {
                    continue;
                }
                if erode && (raw[k - 1] != l || raw[k + 1] != l || raw[k - w] != l || raw[k + w] != l) {
                    continue;
                }
                while next_blade.next_if(|&b| b < k).is_some() {}
                if l == label::SCALPEL && next_blade.peek() == Some(&k) {
                    slot = BLADE;
                }
                let rgb = [px[3 * k], px[3 * k + 1], px[3 * k + 2]];
                if gate.is_some_and(|g| matches!(g.get(rgb), c if c != l && c != label::UNKNOWN)) {
                    continue;
                }
                if let Some(f) = features(rgb) {
                    self.sums[slot].add(f);
                }
            }
        }
    }

    /// Forgets a little of what was learned (call once per frame set learned from, before
    /// learning it), and compiles what is known so far to judge the new samples.
    pub fn age(&mut self) {
        self.age_by(1);
    }

    /// [`AppearanceModel::age`] for a frame set learned from `frame_sets` frame sets after the last
    /// one (those between taught nothing): what was learned keeps `forget^frame_sets` of its weight.
    pub fn age_by(&mut self, frame_sets: u32) {
        self.gate = self.classes().map(|c| ColourLut::confident(&c, 2.0 * GATE_LOG_RATIO));
        let keep = self.forget.powi(frame_sets.min(i32::MAX as u32) as i32);
        for s in &mut self.sums {
            s.scale(keep);
        }
    }

    /// Whether a slot has enough samples to classify with.
    fn learned(&self, slot: usize) -> bool {
        self.sums[slot].weight >= self.min_pixels
    }

    /// The whole tool's sums: its body's and its blade's.
    fn tool(&self) -> Sums {
        self.sums[1].merged(&self.sums[BLADE])
    }

    /// Whether both labels have enough samples to classify with.
    pub fn ready(&self) -> bool {
        self.learned(0) && self.tool().weight >= self.min_pixels
    }

    /// The colour classes to segment with, once both labels are learned: the hand's, and the
    /// tool's, as one class until its blade has enough samples of its own, then one for the blade
    /// and one for the rest where that has enough (two classes of the scalpel label).
    pub fn classes(&self) -> Option<ColourClasses> {
        if !self.ready() {
            return None;
        }
        let hand = self.sums[0].class(label::HAND)?;
        let tool = if self.learned(BLADE) {
            let body = self.learned(1).then(|| self.sums[1].class(label::SCALPEL)).flatten();
            body.into_iter().chain(self.sums[BLADE].class(label::SCALPEL)).collect()
        } else {
            self.tool().class(label::SCALPEL).into_iter().collect::<Vec<_>>()
        };
        (!tool.is_empty())
            .then(|| ColourClasses { classes: std::iter::once(hand).chain(tool).collect(), reject_mahalanobis2: None })
    }

    /// What was learned, per slot: the hand, the scalpel (its body where the blade is told
    /// apart), the blade.
    pub fn summary(&self) -> Vec<LearnedColour> {
        SLOTS
            .iter()
            .zip(&self.sums)
            .map(|(&(l, name), s)| {
                let class = s.class(l);
                LearnedColour {
                    label: name.to_owned(),
                    pixels: s.weight,
                    mean: class.as_ref().map(|c| c.mean),
                    sd: class.as_ref().map(|c| [0, 1, 2].map(|i| c.cov[i][i].sqrt())),
                    rgb: class.as_ref().map(|c| {
                        let (r, b) = (c.mean[0], c.mean[1]);
                        let g = 1.0 - r - b;
                        [r, g, b].map(|x| (x * 3.0 * 128.0).round().clamp(0.0, 255.0) as u8)
                    }),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learns_the_colours_it_is_shown_and_forgets_the_old_ones() {
        let (w, h) = (60, 40);
        let mut image = RgbImage::new(w, h);
        let mut labels = GrayImage::new(w, h);
        for (i, j, p) in image.enumerate_pixels_mut() {
            let hand = i < 30;
            *p = image::Rgb(if hand { [200, 140, 110] } else { [90, 90, 95] });
            labels.put_pixel(i, j, image::Luma([if hand { label::HAND } else { label::SCALPEL }]));
        }
        let mut model = AppearanceModel { min_pixels: 50.0, ..AppearanceModel::default() };
        assert!(model.classes().is_none(), "nothing learned yet");
        model.learn(&image, &labels, true);
        let classes = model.classes().expect("both labels learned");
        assert_eq!(classes.classify([190, 130, 100]), label::HAND, "a darker skin pixel");
        assert_eq!(classes.classify([120, 120, 126]), label::SCALPEL, "a brighter steel pixel");
        let hand = &model.summary()[0];
        assert_eq!(hand.label, "hand");
        assert!(hand.rgb.is_some_and(|c| c[0] > c[1] && c[1] > c[2]), "{hand:?}");
        let before = model.summary()[0].pixels;
        model.age();
        assert!((model.summary()[0].pixels - before * 0.97).abs() < 1e-9);
        // Learned from five frame sets later, it forgets as five frame sets learned from do.
        let mut by_five = model.clone();
        by_five.age_by(5);
        for _ in 0..5 {
            model.age();
        }
        for (a, b) in by_five.summary().iter().zip(model.summary()) {
            assert!((a.pixels - b.pixels).abs() <= 1e-9 * b.pixels, "{a:?} against {b:?}");
            assert_eq!(a.rgb, b.rgb);
        }
    }

    /// A purple glove, a blue handle and a grey blade (columns 0..120, 120..140 and from 140 on, as
    /// many as `blade` columns; the blade's pixels told apart), with a little texture so that no
    /// class is degenerate: the image, its labels and the blade's pixel indices.
    fn glove_handle_blade(blade: u32) -> (RgbImage, GrayImage, Vec<usize>) {
        let (w, h) = (140 + blade, 30);
        let image = RgbImage::from_fn(w, h, |i, j| {
            let d = ((i * 7 + j * 13) % 9) as u8;
            let c = match i {
                0..120 => PURPLE,
                120..140 => BLUE,
                _ => GREY,
            };
            image::Rgb(c.map(|v| v.saturating_add(d)))
        });
        let labels = GrayImage::from_fn(w, h, |i, _| image::Luma([if i < 120 { label::HAND } else { label::SCALPEL }]));
        let inside: Vec<usize> = (0..(w * h) as usize).filter(|k| k % w as usize >= 140).collect();
        (image, labels, inside)
    }

    const PURPLE: [u8; 3] = [125, 100, 160];
    const BLUE: [u8; 3] = [50, 110, 225];
    const GREY: [u8; 3] = [120, 124, 140];

    /// Learned apart, the blade's grey is the tool's with the handle's blue and the glove the
    /// hand's; until the blade has enough samples of its own, the tool is one class, as learned
    /// without telling the blade apart.
    #[test]
    fn a_blade_learned_apart_from_its_handle_is_a_class_of_the_tool_once_it_has_enough_samples() {
        // A blade five columns wide: too few of its samples for a class (min_pixels 200).
        let (image, labels, blade) = glove_handle_blade(5);
        let window = Window::whole(image.width(), image.height());
        let mut few = AppearanceModel::default();
        let mut whole = few.clone();
        few.learn_parts(&image, &labels, true, window, &blade);
        whole.learn_within(&image, &labels, true, window);
        let blade_samples = few.summary()[2].pixels;
        assert!(blade_samples > 0.0 && blade_samples < few.min_pixels, "{:?}", few.summary());
        let (split, one) = (few.classes().expect("learned"), whole.classes().expect("learned"));
        assert_eq!(split.classes.len(), 2);
        for (a, b) in split.classes.iter().zip(&one.classes) {
            assert_eq!(a.label, b.label);
            let near = |x: f64, y: f64| (x - y).abs() <= 1e-9 * (1.0 + y.abs());
            assert!((0..3).all(|i| near(a.mean[i], b.mean[i]) && (0..3).all(|j| near(a.cov[i][j], b.cov[i][j]))));
        }
        assert_eq!(few.summary().iter().map(|c| c.label.as_str()).collect::<Vec<_>>(), ["hand", "scalpel", "blade"]);
        assert_eq!(few.summary().iter().map(|c| c.label.as_str()).collect::<Vec<_>>(), LEARNED_NAMES);

        // Forty columns: three classes, the blade's grey and the handle's blue both the tool's.
        let (image, labels, blade) = glove_handle_blade(40);
        let window = Window::whole(image.width(), image.height());
        let mut apart = AppearanceModel::default();
        apart.learn_parts(&image, &labels, true, window, &blade);
        let classes = apart.classes().expect("learned");
        let labels_of: Vec<u8> = classes.classes.iter().map(|c| c.label).collect();
        assert_eq!(labels_of, [label::HAND, label::SCALPEL, label::SCALPEL]);
        assert_eq!(classes.classify(GREY), label::SCALPEL);
        assert_eq!(classes.classify(BLUE), label::SCALPEL);
        assert_eq!(classes.classify(PURPLE), label::HAND);
        let grey = &apart.summary()[2];
        assert!(grey.rgb.is_some_and(|c| c[2] > c[0] && c[0].abs_diff(c[1]) < 10), "{grey:?}");
        // Learning on, with the classes as the gate, keeps the blade's samples.
        let before = grey.pixels;
        apart.age();
        apart.learn_parts(&image, &labels, true, window, &blade);
        assert!(apart.summary()[2].pixels > 1.9 * before, "{:?}", apart.summary());
    }

    /// What `learn` did before it skipped the background: every pixel visited in turn.
    fn learn_every_pixel(model: &mut AppearanceModel, image: &RgbImage, labels: &GrayImage, erode: bool) {
        let (w, h) = (labels.width() as usize, labels.height() as usize);
        let (raw, px) = (labels.as_raw(), image.as_raw());
        let stride = model.stride.max(1);
        for j in 1..h.saturating_sub(1) {
            for i in 1..w.saturating_sub(1) {
                let k = j * w + i;
                let l = raw[k];
                let Some(slot) = label::NAMED.iter().position(|&(n, _)| n == l) else { continue };
                if l == label::HAND && !(i.is_multiple_of(stride) && j.is_multiple_of(stride)) {
                    continue;
                }
                if erode && (raw[k - 1] != l || raw[k + 1] != l || raw[k - w] != l || raw[k + w] != l) {
                    continue;
                }
                let rgb = [px[3 * k], px[3 * k + 1], px[3 * k + 2]];
                if model.gate.as_ref().is_some_and(|g| matches!(g.get(rgb), c if c != l && c != label::UNKNOWN)) {
                    continue;
                }
                if let Some(f) = features(rgb) {
                    model.sums[slot].add(f);
                }
            }
        }
    }

    /// Skipping the background learns exactly what visiting every pixel learned: random blobs of
    /// hand, scalpel and unknown pixels (some on the image's border rows and columns), with and
    /// without erosion, before and after the learned colours gate the samples.
    #[test]
    fn learning_only_the_foreground_rows_and_pixels_learns_the_same() {
        let (w, h) = (53u32, 37u32);
        let mut seed = 5u64;
        let mut next = |n: u32| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) % u64::from(n)) as u32
        };
        let mut learned = 0;
        for round in 0..6 {
            let mut image = RgbImage::new(w, h);
            let mut labels = GrayImage::new(w, h);
            for p in image.pixels_mut() {
                *p = image::Rgb([next(256) as u8, next(256) as u8, next(256) as u8]);
            }
            for _ in 0..(3 + round) {
                let (ci, cj, r) = (next(w), next(h), 2 + next(6));
                let l = [label::HAND, label::SCALPEL, label::UNKNOWN][next(3) as usize];
                for j in cj.saturating_sub(r)..(cj + r).min(h) {
                    for i in ci.saturating_sub(r)..(ci + r).min(w) {
                        labels.put_pixel(i, j, image::Luma([l]));
                    }
                }
            }
            // The box of the labelled pixels: a window outside which the labels are background.
            let (mut lo, mut hi) = ((w, h), (0, 0));
            for (i, j, p) in labels.enumerate_pixels() {
                if p.0[0] != label::BACKGROUND {
                    (lo, hi) = ((lo.0.min(i), lo.1.min(j)), (hi.0.max(i + 1), hi.1.max(j + 1)));
                }
            }
            let window = Window { x0: lo.0, y0: lo.1, x1: hi.0, y1: hi.1 };
            for erode in [false, true] {
                let mut a = AppearanceModel { min_pixels: 5.0, stride: 2, ..AppearanceModel::default() };
                let (mut b, mut c) = (a.clone(), a.clone());
                for _ in 0..2 {
                    a.learn(&image, &labels, erode);
                    learn_every_pixel(&mut b, &image, &labels, erode);
                    c.learn_within(&image, &labels, erode, window);
                    a.age();
                    b.age();
                    c.age();
                }
                let (a, b, c) = (a.summary(), b.summary(), c.summary());
                assert_eq!(format!("{a:?}"), format!("{b:?}"), "round {round}, erode {erode}");
                assert_eq!(format!("{c:?}"), format!("{b:?}"), "round {round}, erode {erode}, {window:?}");
                learned += a.iter().filter(|c| c.pixels > 0.0).count();
            }
        }
        assert!(learned >= 8, "{learned} labels learned over the rounds");
        // Nothing but background: nothing learned.
        let mut model = AppearanceModel::default();
        model.learn(&RgbImage::new(w, h), &GrayImage::new(w, h), true);
        assert!(model.summary().iter().all(|c| c.pixels == 0.0));
    }
}
