//! Accuracy of label masks against truth masks: intersection over union per label.

use hullcut_dataset::label;
use image::GrayImage;
use serde::{Deserialize, Serialize};

use crate::error::CaptureError;

/// Intersection over union of `label` between a predicted and a true mask. Truth pixels marked
/// [`label::UNKNOWN`] are not counted. `None` when the label is in neither mask (nothing to
/// score) or when the masks differ in size.
pub fn iou(pred: &GrayImage, truth: &GrayImage, label: u8) -> Option<f64> {
    let c = Counts::of(pred, truth, label)?;
    c.iou()
}

#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    tp: u64,
    fp: u64,
    fn_: u64,
}

impl Counts {
    fn of(pred: &GrayImage, truth: &GrayImage, l: u8) -> Option<Self> {
        Self::matching(pred, truth, |v| v == l)
    }

    /// Counts of the pixels `is` holds for, in the prediction against the truth.
    fn matching(pred: &GrayImage, truth: &GrayImage, is: impl Fn(u8) -> bool) -> Option<Self> {
        if pred.dimensions() != truth.dimensions() {
            return None;
        }
        let mut c = Self::default();
        for (&p, &t) in pred.as_raw().iter().zip(truth.as_raw()) {
            if t == label::UNKNOWN {
                continue;
            }
            let (p, t) = (is(p), is(t));
            c.tp += u64::from(p & t);
            c.fp += u64::from(p & !t);
            c.fn_ += u64::from(!p & t);
        }
        Some(c)
    }

    fn iou(&self) -> Option<f64> {
        let union = self.tp + self.fp + self.fn_;
        (union > 0).then(|| self.tp as f64 / union as f64)
    }
}

/// Accuracy of one label over many views.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelScore {
    /// Label value.
    pub label: u8,
    /// Label name (`hand`, `scalpel`).
    pub name: String,
    /// Views in which the label appears in the prediction or the truth.
    pub views: u64,
    /// Mean of the per-view IoU over those views.
    pub iou_mean: Option<f64>,
    /// Smallest per-view IoU.
    pub iou_min: Option<f64>,
    /// IoU of all pixels pooled (large views weigh more).
    pub iou_pooled: Option<f64>,
    /// Pooled true positives / predicted positives.
    pub precision: Option<f64>,
    /// Pooled true positives / true positives plus misses.
    pub recall: Option<f64>,
    /// Pixels of the label in both masks.
    pub true_positive: u64,
    /// Pixels predicted as the label but not so in truth.
    pub false_positive: u64,
    /// Pixels of the label in truth that the prediction missed.
    pub false_negative: u64,
}

/// Per-label accuracy of a segmentation run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentationReport {
    /// Views scored.
    pub views: u64,
    /// One entry per foreground label ([`label::NAMED`]).
    pub labels: Vec<LabelScore>,
    /// The foreground whatever its label (a pixel predicted unknown counts as foreground): how
    /// well the background model and the shadows were settled, apart from the labelling. Its
    /// `label` is [`label::BACKGROUND`] (scored as its complement) and its name `foreground`.
    pub foreground: LabelScore,
}

/// Collects per-label counts and per-view IoU over many (prediction, truth) pairs.
#[derive(Debug, Clone, Default)]
pub struct IouAccumulator {
    views: u64,
    /// Hand, scalpel, then the foreground whatever its label.
    counts: [Counts; 3],
    ious: [Vec<f64>; 3],
}

impl IouAccumulator {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Scores one view of camera `camera` (named in the error when the sizes differ).
    pub fn add(&mut self, camera: usize, pred: &GrayImage, truth: &GrayImage) -> Result<(), CaptureError> {
        if pred.dimensions() != truth.dimensions() {
            return Err(CaptureError::ImageSize {
                camera,
                what: "predicted mask".into(),
                w: truth.width(),
                h: truth.height(),
                found_w: pred.width(),
                found_h: pred.height(),
            });
        }
        self.views += 1;
        let foreground = Counts::matching(pred, truth, |v| v != label::BACKGROUND);
        let named = label::NAMED.iter().map(|&(l, _)| Counts::of(pred, truth, l));
        for (k, c) in named.chain([foreground]).enumerate() {
            if let Some(c) = c {
                self.counts[k].tp += c.tp;
                self.counts[k].fp += c.fp;
                self.counts[k].fn_ += c.fn_;
                if let Some(v) = c.iou() {
                    self.ious[k].push(v);
                }
            }
        }
        Ok(())
    }

    /// The report so far.
    pub fn report(&self) -> SegmentationReport {
        let ratio = |a: u64, b: u64| (b > 0).then(|| a as f64 / b as f64);
        let score = |k: usize, l: u8, name: &str| {
            let c = self.counts[k];
            let ious = &self.ious[k];
            LabelScore {
                label: l,
                name: name.to_owned(),
                views: ious.len() as u64,
                iou_mean: (!ious.is_empty()).then(|| ious.iter().sum::<f64>() / ious.len() as f64),
                iou_min: ious.iter().copied().reduce(f64::min),
                iou_pooled: c.iou(),
                precision: ratio(c.tp, c.tp + c.fp),
                recall: ratio(c.tp, c.tp + c.fn_),
                true_positive: c.tp,
                false_positive: c.fp,
                false_negative: c.fn_,
            }
        };
        let labels = label::NAMED.iter().enumerate().map(|(k, &(l, name))| score(k, l, name)).collect();
        let foreground = score(label::NAMED.len(), label::BACKGROUND, "foreground");
        SegmentationReport { views: self.views, labels, foreground }
    }
}
