//! Segmentation of camera images into label masks (0 background, 1 hand, 2 scalpel, 255
//! unknown).
//!
//! Per camera: a foreground test against a per-pixel background model ([`BackgroundModel`], robust
//! to shading and global exposure change) built from empty-scene images ([`Method::Background`]) or
//! from the recording itself ([`Method::Median`]: a temporal median, the moving hand rejected), or
//! OpenCV's MOG2 on a live stream ([`Method::Mog2`]); each foreground pixel gets a label from the
//! colour classes when there are any ([`ColourClasses`], learned: [`AppearanceModel`]; no colour is
//! written in the code), else the unknown label (the known tool's geometry labels it then:
//! `hullcut_pose::ToolLabeller`); a pixel darker than its background with its chromaticity
//! unchanged may be a cast shadow and can be left for the caller to resolve
//! ([`SegmentParams::shadow_depth`], [`SHADOW_LIKE`]); pixels that pass the tests only at half
//! their tolerances join the foreground they touch, its one-pixel rim apart (hysteresis,
//! [`SegmentParams::weak_share`]); then clean-up: isolated pixels are removed (a pixel needs
//! `min_neighbors` foreground neighbours, which keeps one-pixel-wide blade edges), an optional
//! opening, and a closing that fills small holes; last, the holes the objects enclose whose
//! pixels, taken together, are not their background are filled ([`SegmentParams::fill_holes`]).
//! [`Segmenter::segment_frame_set`] runs the
//! cameras in parallel (rayon) with per-camera buffers that are reused from frame to frame.

mod appearance;
mod background;
mod classes;
mod holes;
mod hysteresis;
mod mog2;
mod morph;
mod report;

use hullcut_dataset::{Dataset, FrameSet, label};
use image::{GrayImage, RgbImage};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use appearance::{AppearanceModel, AppearanceSources, LEARNED_NAMES, LearnedColour};
pub use background::BackgroundModel;
pub use classes::{ColourClass, ColourClasses, ColourLut};
pub use mog2::Mog2Params;
pub use report::{IouAccumulator, LabelScore, SegmentationReport, iou};

use crate::error::CaptureError;
use background::Thresholds;
use classes::ClassLut;
use holes::HoleRule;
use mog2::Mog2;

/// Settings of segmentation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SegmentParams {
    /// β: how much brighter than expected (relative, after exposure compensation) a pixel may
    /// be and still be background. Small, because a static scene's shading does not change;
    /// 0.08 leaves room for exposure non-linearity.
    pub brightness_tolerance: f64,
    /// β for darker pixels: how much darker than expected (relative) a pixel of unchanged
    /// chromaticity may be and still be background. Equal to `brightness_tolerance` by default
    /// (the synthetic scenes have no cast shadows, and a grey scalpel darker than a grey wall is
    /// told apart only by brightness); raise it (e.g. 0.5) where the hand casts shadows.
    pub shadow_tolerance: f64,
    /// How much darker (relative) than expected a pixel of unchanged chromaticity may be and
    /// still be a possible cast shadow: such pixels, darker than `shadow_tolerance` allows but
    /// not darker than this, come out as [`SHADOW_LIKE`] for the caller to resolve (a dark
    /// object of the background's colour looks the same in one view; the hull of all views tells
    /// them apart). At most `shadow_tolerance` (the default) turns it off.
    pub shadow_depth: f64,
    /// κ: chromaticity distortion, relative to the pixel's channel sum, beyond which a pixel is
    /// foreground.
    pub chroma_tolerance: f64,
    /// ν: the share of the noise allowance 3τ the chromaticity test adds to κ·s (the brightness
    /// tests add all of it). Both terms are allowances for the worst case, and their sum let a
    /// pale hand over light wood pass as background: the hand's pixels differed from the wood's
    /// chromaticity by 0.108 of their channel sum (median), the wood's own pixels by 0.021 (90th
    /// percentile 0.036), while κ·s + 3τ came to 0.13 of it. At ½, that recording's foreground IoU
    /// went from 0.849 to 0.989 over 30 frame sets and no other recording tried lost more than
    /// 0.002 of it; at ⅓ the blurred, exposure-drifting `hard` scene began to lose (see
    /// docs/benchmarks.md, "The chromaticity test's noise allowance").
    /// Settings read back from a report written before ν was a setting have the whole
    /// allowance, as that code did.
    #[serde(default = "whole_allowance")]
    pub chroma_noise: f64,
    /// Smallest per-pixel noise allowance τ, grey levels per channel (about 2.5σ of a sensor
    /// with σ = 2 levels; the tests add 3τ over three channels).
    pub noise_floor: u8,
    /// τ in standard deviations of the spread over the empty-scene images (three or more images).
    pub noise_sigmas: f64,
    /// Estimate each image's exposure gain against the model (global auto-exposure).
    pub exposure_compensation: bool,
    /// A foreground pixel with fewer foreground neighbours (of 8) is removed; 0 disables.
    pub min_neighbors: u8,
    /// Radius of the opening (square (2r+1)²); 0 disables. Opening erases structures thinner
    /// than 2r+1 pixels, a blade seen edge-on among them, so it is off by default.
    pub open_radius: u32,
    /// Radius of the closing that fills holes and gaps; 0 disables.
    pub close_radius: u32,
    /// The MOG2 fallback.
    pub mog2: Mog2Params,
    /// Colour classes of the foreground; without them every foreground pixel is unknown.
    pub classes: Option<ColourClasses>,
    /// Frames of the recording its background is estimated from ([`Method::Median`]).
    pub median_frames: usize,
    /// Hysteresis: a pixel that the tests call background at their full tolerances but not at
    /// this share of each (brightness, chromaticity) is foreground where it touches foreground
    /// (a foreground pixel with two or more foreground pixels beside it), 8-connected through
    /// other such pixels, each one's colour nearer (L1) to the pixel it is reached from than to
    /// its own background's (a streak of a brushed steel table beside the hand is not reached,
    /// and lost the tool's track for 40-65 frame sets where it was); one that is only darker
    /// than this share of the shadow tolerance allows becomes a possible shadow there
    /// ([`SHADOW_LIKE`], when `shadow_depth` asks for them; else it stays background). With
    /// possible shadows asked for, those only darker that no foreground reached but that touch a
    /// possible shadow (one with two or more beside it) join it, through each other, by the same
    /// colour rule: a dull tool of the table's shade is a possible shadow in patches, only
    /// darker between them and along its thin end, and each view's gap carved it from the hull
    /// (random:2711 in random:2713; the hull then tells it from a shadow on the table). Such
    /// pixels next to what they joined and to background, the rim that every edge's partly
    /// covered pixels make, stay background. A hand or blade close to its
    /// background's colour is seen at the full tolerances in patches only, and every view's gap
    /// carves the hull: a grey latex glove over a grey table lost a tenth of its pixels over
    /// seven views, in holes; a steel blade over it a sixth to a third in five of seven views;
    /// neither tool was ever found (docs/benchmarks.md, "Hysteresis in the foreground test").
    /// Pixels as weak that touch no foreground (noise, drift) stay background. 1 turns it off;
    /// settings read back from a report written before it was a setting have it off, as that
    /// code did.
    #[serde(default = "no_hysteresis")]
    pub weak_share: f64,
    /// Fill the holes in the foreground whose pixels, taken together, are not their
    /// background: background pixels enclosed by a view's foreground (4-connected, touching no
    /// edge of the tested window) with more objects than possible shadows beside them (among
    /// shadows a hole may be the table lit between them) and 4 or more pixels clear of the
    /// hole's edge, filled where those pixels' mean colour is brighter than their background's
    /// mean (exposure compensated) by more than the weak share of the brightness tolerance, or
    /// differs from it in chromaticity by more than the weak share of κ, towards the colour of
    /// the objects around the hole (within 60°; objects within that share of the background's
    /// chromaticity give no direction), and is not darker than the shadow tolerance allows with
    /// less than κ (a shadow seen through a gap). Each pixel's test allows for the
    /// sensor's noise, which falls by √n over a hole's n pixels: a pale hand over a grey
    /// backdrop was background pixel by pixel in holes of up to 138 pixels (random:2473 in
    /// random:2593), each carving the hull through the hand, while a gap between the fingers
    /// shows the background itself (see docs/benchmarks.md, "Holes that are not the
    /// background"). The background model's tests only (not MOG2). Settings read back from a
    /// report written before it was a setting have it off, as that code did.
    #[serde(default)]
    pub fill_holes: bool,
}

impl Default for SegmentParams {
    fn default() -> Self {
        Self {
            brightness_tolerance: 0.08,
            shadow_tolerance: 0.08,
            shadow_depth: 0.08,
            chroma_tolerance: 0.06,
            chroma_noise: 0.5,
            noise_floor: 5,
            noise_sigmas: 3.0,
            exposure_compensation: true,
            min_neighbors: 2,
            open_radius: 0,
            close_radius: 1,
            mog2: Mog2Params::default(),
            classes: None,
            median_frames: 25,
            weak_share: 0.5,
            fill_holes: true,
        }
    }
}

/// [`SegmentParams::weak_share`] as it was before it was a setting: off.
fn no_hysteresis() -> f64 {
    1.0
}

/// [`SegmentParams::chroma_noise`] as it was before it was a setting.
fn whole_allowance() -> f64 {
    1.0
}

impl SegmentParams {
    fn validate(&self) -> Result<(), CaptureError> {
        let check = |name: &'static str, v: f64| {
            if (0.0..=0.99).contains(&v) {
                Ok(())
            } else {
                Err(CaptureError::Param { name, message: format!("{v} is outside 0..0.99") })
            }
        };
        check("brightness_tolerance", self.brightness_tolerance)?;
        check("shadow_tolerance", self.shadow_tolerance)?;
        check("shadow_depth", self.shadow_depth)?;
        check("chroma_tolerance", self.chroma_tolerance)?;
        if !(0.0..=1.0).contains(&self.chroma_noise) {
            return Err(CaptureError::Param {
                name: "chroma_noise",
                message: format!("{} is outside 0..1", self.chroma_noise),
            });
        }
        if !(self.weak_share > 0.0 && self.weak_share <= 1.0) {
            return Err(CaptureError::Param {
                name: "weak_share",
                message: format!("{} is outside (0, 1]", self.weak_share),
            });
        }
        if !(self.noise_sigmas.is_finite() && self.noise_sigmas >= 0.0) {
            return Err(CaptureError::Param {
                name: "noise_sigmas",
                message: format!("{} is negative", self.noise_sigmas),
            });
        }
        if self.min_neighbors > 8 {
            return Err(CaptureError::Param {
                name: "min_neighbors",
                message: format!("{} exceeds 8", self.min_neighbors),
            });
        }
        self.classes.as_ref().map_or(Ok(()), ColourClasses::validate)
    }
}

/// How a camera finds its foreground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Per-pixel model from empty-scene images.
    Background,
    /// Per-pixel model estimated from the recording's own frames (temporal median).
    Median,
    /// OpenCV's MOG2, learnt from the stream (no empty-scene images, no recording to look ahead).
    Mog2,
}

/// What a camera's background is learned from.
#[derive(Debug, Clone)]
pub enum BackgroundSource {
    /// Images of the empty scene.
    EmptyScene(Vec<RgbImage>),
    /// Frames of the recording, spread over it (the foreground moving).
    Recording(Vec<RgbImage>),
    /// Nothing ahead of time: MOG2 learns from the stream.
    Stream,
}

/// Working encoding of labels inside the segmenter: ordered so that dilation by maximum lets
/// scalpel win over hand, both over unknown, and all over a possible shadow.
const ENC_SHADOW: u8 = 1;
const ENC_UNKNOWN: u8 = 2;
const ENC_HAND: u8 = 3;
const ENC_SCALPEL: u8 = 4;
/// A pixel background at the full tolerances, not at their [`SegmentParams::weak_share`]
/// (brighter or of another chromaticity); resolved before the clean-up, never decoded.
const ENC_WEAK: u8 = 5;
/// A pixel darker than the weak share of the shadow tolerance allows, its chromaticity unchanged;
/// resolved before the clean-up, never decoded.
const ENC_WEAK_DARK: u8 = 6;

/// The value of a mask pixel that may be a cast shadow (see [`SegmentParams::shadow_depth`]): not
/// a dataset label; whoever asks for it resolves it to foreground or background.
pub const SHADOW_LIKE: u8 = 128;

fn encode(l: u8) -> u8 {
    match l {
        label::BACKGROUND => 0,
        label::HAND => ENC_HAND,
        label::SCALPEL => ENC_SCALPEL,
        _ => ENC_UNKNOWN,
    }
}

#[derive(Debug)]
enum Model {
    Background(BackgroundModel, Method),
    Mog2(Box<Mog2>),
}

/// Buffers reused from frame to frame.
#[derive(Debug, Default)]
struct Scratch {
    labels: Vec<u8>,
    work1: Vec<u8>,
    work2: Vec<u8>,
    tmp: Vec<u8>,
    vsum: Vec<u8>,
    ratios: Vec<f32>,
    /// Rows that may hold foreground, per buffer.
    act0: Vec<bool>,
    act1: Vec<bool>,
    act2: Vec<bool>,
    /// The hysteresis's pixels to visit.
    stack: Vec<u32>,
    /// The hole filling's runs and sums.
    holes: holes::Holes,
    /// What each row of `labels` may hold.
    row_kinds: Vec<background::RowKinds>,
}

/// Working encoding → label: 0 → 0, 1 → [`SHADOW_LIKE`], 2 → 255, 3 → 1, 4 → 2 (5 and above,
/// never decoded, → 0). Written as byte masks, not a table, so that a row of them vectorizes (a
/// table lookup per pixel kept the clean-up's last pass scalar).
#[inline(always)]
fn decode(v: u8) -> u8 {
    let all = |b: bool| u8::from(b).wrapping_neg();
    (all(v == ENC_SHADOW) & SHADOW_LIKE)
        | (all(v == ENC_UNKNOWN) & label::UNKNOWN)
        | (all(v.wrapping_sub(ENC_HAND) < 2) & v.wrapping_sub(ENC_HAND - label::HAND))
}

/// The closing's pixel: the raw foreground's label `a` where it has one, else the dilation's `d`
/// where the closing `c` kept the pixel; without branches.
#[inline(always)]
fn closed(a: u8, d: u8, c: u8) -> u8 {
    let raw = u8::from(a != 0).wrapping_neg();
    (a & raw) | (d & !raw & u8::from(c != 0).wrapping_neg())
}

#[derive(Debug)]
struct CameraSegmenter {
    camera: usize,
    model: Model,
    scratch: Scratch,
    /// Size of the MOG2 stream, fixed by its first frame.
    size: Option<(u32, u32)>,
    last_gain: f64,
    /// The mask this camera last wrote (its first pixel's address and its length) and the
    /// window it wrote in: outside it, that mask is background ([`Segmenter::keep_masks`]).
    written: Option<((usize, usize), Window)>,
}

/// Segments the images of a rig's cameras; see the module docs.
#[derive(Debug)]
pub struct Segmenter {
    params: SegmentParams,
    lut: ClassLut,
    cameras: Vec<CameraSegmenter>,
    /// Whether the masks handed back are those this segmenter wrote, background outside their
    /// windows ([`Segmenter::keep_masks`]).
    kept: bool,
}

impl Segmenter {
    /// A segmenter with one entry of `backgrounds` per camera: its empty-scene images, or none
    /// for the MOG2 fallback.
    pub fn new(params: SegmentParams, backgrounds: &[Vec<RgbImage>]) -> Result<Self, CaptureError> {
        let sources: Vec<BackgroundSource> = backgrounds
            .iter()
            .map(|b| if b.is_empty() { BackgroundSource::Stream } else { BackgroundSource::EmptyScene(b.clone()) })
            .collect();
        Self::with_sources(params, sources)
    }

    /// A segmenter with one background source per camera.
    pub fn with_sources(params: SegmentParams, sources: Vec<BackgroundSource>) -> Result<Self, CaptureError> {
        params.validate()?;
        let cameras = sources
            .into_iter()
            .enumerate()
            .map(|(camera, source)| {
                let model = match source {
                    BackgroundSource::Stream => {
                        tracing::info!(camera, "no empty-scene images and no recording: MOG2 background subtraction");
                        Model::Mog2(Box::new(Mog2::new(camera, &params.mog2)?))
                    }
                    BackgroundSource::EmptyScene(images) => {
                        Model::Background(BackgroundModel::from_images(camera, &images, &params)?, Method::Background)
                    }
                    BackgroundSource::Recording(frames) => {
                        Model::Background(BackgroundModel::from_recording(camera, &frames, &params)?, Method::Median)
                    }
                };
                let size = match &model {
                    Model::Background(m, _) => Some((m.width(), m.height())),
                    Model::Mog2(_) => None,
                };
                Ok(CameraSegmenter { camera, model, scratch: Scratch::default(), size, last_gain: 1.0, written: None })
            })
            .collect::<Result<Vec<_>, CaptureError>>()?;
        let lut = ClassLut::new(params.classes.as_ref(), encode);
        Ok(Self { params, lut, cameras, kept: false })
    }

    /// A segmenter for a dataset's cameras: from their `<cam>/background*.png` images, or, for a
    /// camera without any, from `median_frames` of its frames spread over the recording.
    pub fn from_dataset(dataset: &Dataset, params: SegmentParams) -> Result<Self, CaptureError> {
        let frames = dataset.frame_numbers();
        let k = params.median_frames.clamp(1, frames.len().max(1));
        let picked: Vec<u64> = (0..k).filter_map(|i| frames.get(i * frames.len() / k).copied()).collect();
        let sources = (0..dataset.meta().cameras.len())
            .map(|c| {
                let empty = dataset.background_images(c)?;
                if !empty.is_empty() {
                    return Ok(BackgroundSource::EmptyScene(empty));
                }
                let images: Vec<RgbImage> = picked.iter().filter_map(|&f| dataset.read_image(f, c).ok()).collect();
                Ok(if images.len() >= 3 { BackgroundSource::Recording(images) } else { BackgroundSource::Stream })
            })
            .collect::<Result<Vec<_>, CaptureError>>()?;
        Self::with_sources(params, sources)
    }

    /// With `kept`, the caller promises that the masks it hands to
    /// [`Self::segment_frame_set_stretches`] (and the calls built on it) are the ones this
    /// segmenter last wrote for those views, with nothing but background written outside each
    /// one's window since (changing the foreground inside it is fine): the segmenter then clears
    /// only what the last window held outside the new one, instead of every pixel outside the
    /// new window (six full masks a frame set). A mask it did not write last (another buffer)
    /// is cleared whole as without. Off by default.
    pub fn keep_masks(&mut self, kept: bool) {
        self.kept = kept;
    }

    /// The settings.
    pub fn params(&self) -> &SegmentParams {
        &self.params
    }

    /// Number of cameras.
    pub fn cameras(&self) -> usize {
        self.cameras.len()
    }

    /// How camera `camera` finds its foreground (`None` outside the rig).
    pub fn method(&self, camera: usize) -> Option<Method> {
        self.cameras.get(camera).map(|c| match c.model {
            Model::Background(_, method) => method,
            Model::Mog2(_) => Method::Mog2,
        })
    }

    /// The mean image of camera `camera`'s background model (`None` outside the rig, and for
    /// MOG2, whose background is not one image).
    pub fn background_mean(&self, camera: usize) -> Option<&RgbImage> {
        self.cameras.get(camera).and_then(|c| match &c.model {
            Model::Background(m, _) => Some(m.mean_image()),
            Model::Mog2(_) => None,
        })
    }

    /// Exposure gain estimated for camera `camera`'s last image (1 without compensation or MOG2).
    pub fn last_exposure_gain(&self, camera: usize) -> Option<f64> {
        self.cameras.get(camera).map(|c| c.last_gain)
    }

    /// Replaces the colour classes (recompiles the lookup table); `None` labels every foreground
    /// pixel unknown.
    pub fn set_classes(&mut self, classes: Option<ColourClasses>) -> Result<(), CaptureError> {
        if let Some(c) = &classes {
            c.validate()?;
        }
        self.lut = ClassLut::new(classes.as_ref(), encode);
        self.params.classes = classes;
        Ok(())
    }

    /// Segments one image of camera `camera`.
    pub fn segment(&mut self, camera: usize, image: &RgbImage) -> Result<GrayImage, CaptureError> {
        let mut out = GrayImage::new(image.width(), image.height());
        self.segment_into(camera, image, &mut out)?;
        Ok(out)
    }

    /// Segments one image of camera `camera` into `out` (resized when its size differs).
    pub fn segment_into(&mut self, camera: usize, image: &RgbImage, out: &mut GrayImage) -> Result<(), CaptureError> {
        let cameras = self.cameras.len();
        let cam = self.cameras.get_mut(camera).ok_or(CaptureError::UnknownCamera { camera, cameras })?;
        if out.dimensions() != image.dimensions() {
            *out = GrayImage::new(image.width(), image.height());
        }
        let (w, h) = image.dimensions();
        cam.run(image, &self.params, &self.lut, (out, false), Window::whole(w, h), None).map(|_| ())
    }

    /// Segments every view of a frame set, cameras in parallel; `None` where the view is missing.
    pub fn segment_frame_set(&mut self, set: &FrameSet) -> Result<Vec<Option<GrayImage>>, CaptureError> {
        let mut masks = Vec::new();
        self.segment_frame_set_into(set, &mut masks)?;
        Ok(masks)
    }

    /// Like [`Self::segment_frame_set`], reusing the masks already in `masks` (one entry per
    /// view afterwards): a pipeline that hands the same vector back each frame allocates nothing.
    pub fn segment_frame_set_into(
        &mut self,
        set: &FrameSet,
        masks: &mut Vec<Option<GrayImage>>,
    ) -> Result<(), CaptureError> {
        self.segment_frame_set_within(set, masks, &[])
    }

    /// Like [`Self::segment_frame_set_into`], testing only the pixels of each view's window
    /// (`windows[k]` for view `k`; none, or a view beyond `windows`, tests the whole image): the
    /// rest of its mask is background. A caller that knows where the objects can be (the
    /// projection of the box it carves in) saves the work elsewhere. The clean-up sees pixels
    /// outside the window as background; a window of the whole image gives the same masks as
    /// [`Self::segment_frame_set_into`]. The MOG2 fallback, which must see every pixel to keep
    /// its model, tests the whole image.
    pub fn segment_frame_set_within(
        &mut self,
        set: &FrameSet,
        masks: &mut Vec<Option<GrayImage>>,
        windows: &[Option<Window>],
    ) -> Result<(), CaptureError> {
        self.segment_frame_set_stretches(set, masks, windows, &[]).map(|_| ())
    }

    /// Like [`Self::segment_frame_set_within`], testing in view `k` with `stretches[k]` only the
    /// columns `a..b` of each image row `y` that `stretches[k][y]` names, within its window (a
    /// row beyond it has none): a caller that knows where the objects can be more closely than
    /// a rectangle (around the last hull's projection) saves the rest. Returns per view the
    /// pixels tested and whether its mask has foreground at the end of a stretch that lies
    /// inside the window (or in a row beside a row with none): there the objects may reach past
    /// the stretches, and the caller should test the whole window next time. The MOG2 fallback
    /// tests the whole image (its stretches are not needed).
    pub fn segment_frame_set_stretches(
        &mut self,
        set: &FrameSet,
        masks: &mut Vec<Option<GrayImage>>,
        windows: &[Option<Window>],
        stretches: &[Option<Vec<(u32, u32)>>],
    ) -> Result<Vec<ViewTested>, CaptureError> {
        if set.views.len() > self.cameras.len() {
            return Err(CaptureError::UnknownCamera { camera: set.views.len() - 1, cameras: self.cameras.len() });
        }
        masks.resize(set.views.len(), None);
        let (params, lut, kept) = (&self.params, &self.lut, self.kept);
        self.cameras
            .par_iter_mut()
            .zip(set.views.par_iter())
            .zip(masks.par_iter_mut())
            .enumerate()
            .map(|(k, ((cam, view), mask))| {
                let Some(view) = view else {
                    *mask = None;
                    return Ok(ViewTested::default());
                };
                let (w, h) = view.image.dimensions();
                let out = match mask {
                    Some(m) if m.dimensions() == (w, h) => m,
                    _ => mask.insert(GrayImage::new(w, h)),
                };
                let stretches = stretches.get(k).and_then(Option::as_deref);
                cam.run(&view.image, params, lut, (out, kept), Window::of_view(windows, k, w, h), stretches)
            })
            .collect()
    }
}

/// What segmenting one view tested ([`Segmenter::segment_frame_set_stretches`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ViewTested {
    /// Pixels whose foreground was tested (the rest of the mask is background); 0 for a view
    /// with no image.
    pub pixels: u64,
    /// Whether the mask has an object's pixel at the end of a stretch inside the window: the
    /// objects may reach past the stretches.
    pub reached_past: bool,
    /// Pixels that passed the foreground tests only at their weak share and joined the
    /// foreground, or (only darker) a possible shadow, they touch
    /// ([`SegmentParams::weak_share`]), before the clean-up.
    pub joined: u64,
    /// Background pixels enclosed by the foreground that filled it as holes of another colour
    /// than their background's ([`SegmentParams::fill_holes`]), after the clean-up.
    pub filled: u64,
}

/// A rectangle of pixels (columns `x0..x1`, rows `y0..y1`, ends excluded) that segmentation tests
/// ([`Segmenter::segment_frame_set_within`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl Window {
    /// The whole of a `w`×`h` image.
    pub fn whole(w: u32, h: u32) -> Self {
        Window { x0: 0, y0: 0, x1: w, y1: h }
    }

    /// The window within a `w`×`h` image (empty where they do not meet).
    pub fn clipped(self, w: u32, h: u32) -> Self {
        let (x1, y1) = (self.x1.min(w), self.y1.min(h));
        Window { x0: self.x0.min(x1), y0: self.y0.min(y1), x1, y1 }
    }

    /// View `k`'s window in `windows` within its `w`×`h` image: the whole image where `windows`
    /// names none for it.
    pub fn of_view(windows: &[Option<Window>], k: usize, w: u32, h: u32) -> Self {
        windows.get(k).copied().flatten().map_or(Window::whole(w, h), |win| win.clipped(w, h))
    }

    /// Its pixels in a `w`×`h` image (clipped to it) as index ranges, row by row.
    pub fn spans(self, w: u32, h: u32) -> impl Iterator<Item = std::ops::Range<usize>> {
        let win = self.clipped(w, h);
        let (w, x0, x1) = (w as usize, win.x0 as usize, win.x1 as usize);
        (win.y0 as usize..win.y1 as usize).map(move |y| y * w + x0..y * w + x1)
    }

    /// Its columns.
    pub fn width(&self) -> u32 {
        self.x1.saturating_sub(self.x0)
    }

    /// Pixels in it.
    pub fn area(&self) -> u64 {
        u64::from(self.x1.saturating_sub(self.x0)) * u64::from(self.y1.saturating_sub(self.y0))
    }
}

impl CameraSegmenter {
    fn run(
        &mut self,
        image: &RgbImage,
        params: &SegmentParams,
        lut: &ClassLut,
        (out, kept): (&mut GrayImage, bool),
        window: Window,
        stretches: Option<&[(u32, u32)]>,
    ) -> Result<ViewTested, CaptureError> {
        let (w, h) = image.dimensions();
        match self.size {
            Some((ew, eh)) if (ew, eh) != (w, h) => {
                return Err(CaptureError::ImageSize {
                    camera: self.camera,
                    what: "image".into(),
                    w: ew,
                    h: eh,
                    found_w: w,
                    found_h: h,
                });
            }
            _ => self.size = Some((w, h)),
        }
        let full_w = w as usize;
        // MOG2 keeps its model from every pixel.
        let mog2 = matches!(self.model, Model::Mog2(_));
        let (window, stretches) = if mog2 { (Window::whole(w, h), None) } else { (window, stretches) };
        let (x0, y0) = (window.x0 as usize, window.y0 as usize);
        // The buffers hold the window; rows and columns below are the window's.
        let (w, h) = (window.x1 as usize - x0, window.y1 as usize - y0);
        let pixels = (0..h)
            .map(|j| {
                let (a, b) = background::tested_columns(stretches, y0 + j, x0, w);
                (b - a) as u64
            })
            .sum();
        let s = &mut self.scratch;
        for buf in [&mut s.labels, &mut s.work1, &mut s.work2] {
            buf.resize(w * h, 0);
        }
        for act in [&mut s.act0, &mut s.act1, &mut s.act2] {
            act.resize(h, false);
        }
        s.row_kinds.resize(h, background::RowKinds::default());
        let raw = image.as_raw();
        // 1. Foreground, labelled by colour class, into `labels`; `act0` marks rows with any; the
        // weak pixels joined to it or dropped.
        let mut joined = 0;
        match &mut self.model {
            Model::Background(model, _) => {
                let gain =
                    if params.exposure_compensation { model.exposure_gain(image, params, &mut s.ratios) } else { 1.0 };
                self.last_gain = gain;
                let t = Thresholds::new(params, gain);
                // An empty window marks no row active.
                model.foreground_window(
                    raw,
                    full_w,
                    (x0, y0, w),
                    stretches,
                    t,
                    lut,
                    &mut s.labels,
                    &mut s.act0,
                    &mut s.row_kinds,
                );
                if params.weak_share < 1.0 {
                    let background = model.mean_image().as_raw();
                    let image = hysteresis::ImageWindow { raw, full_w, x0, y0, background, gain: gain as f32 };
                    let shadows = params.shadow_depth > params.shadow_tolerance;
                    let rows = hysteresis::Rows { active: &mut s.act0, kinds: &s.row_kinds };
                    joined = hysteresis::grow_into_weak(&mut s.labels, rows, w, &image, lut, shadows, &mut s.stack);
                }
            }
            Model::Mog2(m) => {
                m.apply(image, &mut s.labels)?;
                for (y, (row, labels)) in raw.chunks_exact(3 * w).zip(s.labels.chunks_exact_mut(w)).enumerate() {
                    s.act0[y] = morph::any(labels);
                    if s.act0[y] {
                        for (l, p) in labels.iter_mut().zip(row.chunks_exact(3)) {
                            if *l != 0 {
                                *l = lut.get(p[0], p[1], p[2]);
                            }
                        }
                    }
                }
            }
        }
        // 2. Isolated pixels: labels -> work1 (act1).
        morph::neighbour_filter(&s.labels, &mut s.work1, w, params.min_neighbors, &s.act0, &mut s.act1, &mut s.vsum);
        // 3. Opening: work1 -> work1, masked by erode-then-dilate (labels kept).
        if params.open_radius > 0 {
            let r = params.open_radius as usize;
            morph::erode_min(&s.work1, &mut s.work2, w, r, &s.act1, &mut s.act2, &mut s.tmp);
            morph::dilate_max(&s.work2, &mut s.labels, w, r, &s.act2, &mut s.act0, &mut s.tmp);
            for y in 0..h {
                if s.act1[y] && s.act0[y] {
                    let row = &mut s.work1[y * w..(y + 1) * w];
                    for (a, &o) in row.iter_mut().zip(&s.labels[y * w..(y + 1) * w]) {
                        *a = if o != 0 { *a } else { 0 };
                    }
                    s.act1[y] = morph::any(row);
                } else {
                    s.act1[y] = false;
                }
            }
        }
        // 4. Closing: pixels the closing adds take the label of the dilation (scalpel first).
        // Rows inactive in a buffer count as zero there (their bytes are stale).
        let full: &mut [u8] = out;
        // Outside the window: background. `out` is the window's part of each row below. A mask
        // this camera wrote last, kept ([`Segmenter::keep_masks`]), is background outside the
        // window it was written in: only that window's pixels outside this one are cleared.
        let written = (full.as_ptr() as usize, full.len());
        let held = self.written.filter(|&(a, _)| kept && a == written).map(|(_, held)| held);
        let held = held.unwrap_or_else(|| Window::whole(full_w as u32, (full.len() / full_w.max(1)) as u32));
        let (hx0, hx1) = ((held.x0 as usize).min(full_w), (held.x1 as usize).min(full_w));
        for (y, row) in full.chunks_exact_mut(full_w.max(1)).enumerate().take(held.y1 as usize).skip(held.y0 as usize) {
            if y < y0 || y >= y0 + h {
                row[hx0..hx1.max(hx0)].fill(0);
            } else {
                row[hx0..x0.clamp(hx0, hx1.max(hx0))].fill(0);
                row[(x0 + w).clamp(hx0, hx1.max(hx0))..hx1.max(hx0)].fill(0);
            }
        }
        self.written = Some((written, window));
        let mut out = WindowRows { full, full_w, x0, y0, w };
        if params.close_radius > 0 {
            let r = params.close_radius as usize;
            morph::dilate_max(&s.work1, &mut s.work2, w, r, &s.act1, &mut s.act2, &mut s.tmp);
            morph::erode_min(&s.work2, &mut s.labels, w, r, &s.act2, &mut s.act0, &mut s.tmp);
            for y in 0..h {
                let o = out.row(y);
                let (a, d, c) =
                    (&s.work1[y * w..(y + 1) * w], &s.work2[y * w..(y + 1) * w], &s.labels[y * w..(y + 1) * w]);
                match (s.act1[y], s.act0[y]) {
                    (false, false) => o.fill(0),
                    (true, false) => o.iter_mut().zip(a).for_each(|(o, &a)| *o = decode(a)),
                    // Closed but no raw foreground: every pixel comes from the dilation.
                    (false, true) => o.iter_mut().zip(d).zip(c).for_each(|((o, &d), &c)| *o = decode(closed(0, d, c))),
                    (true, true) => {
                        o.iter_mut().zip(a).zip(d).zip(c).for_each(|(((o, &a), &d), &c)| *o = decode(closed(a, d, c)))
                    }
                }
            }
        } else {
            for y in 0..h {
                let o = out.row(y);
                if s.act1[y] {
                    o.iter_mut().zip(&s.work1[y * w..(y + 1) * w]).for_each(|(o, &a)| *o = decode(a));
                } else {
                    o.fill(0);
                }
            }
        }
        // 5. Holes of another colour than their background's.
        let mut filled = 0;
        if let (Model::Background(model, _), true) = (&self.model, params.fill_holes) {
            let behind = holes::Behind { raw, full_w, background: model.mean_image().as_raw(), gain: self.last_gain };
            filled = s.holes.fill(&mut out, h, &behind, &HoleRule::of(params), lut);
        }
        Ok(ViewTested {
            pixels,
            reached_past: stretches.is_some_and(|st| reaches_past(&mut out, st, h)),
            joined: joined as u64,
            filled,
        })
    }
}

/// Whether a mask's window has foreground at the end of a row's stretch (`stretches`, the
/// tested columns per image row) that lies inside the window, or in a row whose neighbour in the
/// window has no stretch: the objects may go on past the stretches there. Possible shadows do
/// not count: a hand's shadow on the table reaches farther from the hand than objects move
/// between frame sets, and only near the objects does the hull tell it from them.
fn reaches_past(out: &mut WindowRows, stretches: &[(u32, u32)], h: usize) -> bool {
    let object = |p: u8| p != label::BACKGROUND && p != SHADOW_LIKE;
    let (x0, y0, w) = (out.x0, out.y0, out.w);
    let columns = |j: usize| background::tested_columns(Some(stretches), y0 + j, x0, w);
    (0..h).any(|j| {
        let (a, b) = columns(j);
        if a >= b {
            return false;
        }
        let row = out.row(j);
        let ends = (a > 0 && object(row[a])) || (b < w && object(row[b - 1]));
        let open = |n: usize| {
            let (c, d) = columns(n);
            c >= d
        };
        let edge_row = (j > 0 && open(j - 1)) || (j + 1 < h && open(j + 1));
        ends || edge_row && row[a..b].iter().any(|&p| object(p))
    })
}

/// The rows of a window within a mask.
struct WindowRows<'a> {
    full: &'a mut [u8],
    full_w: usize,
    x0: usize,
    y0: usize,
    w: usize,
}

impl WindowRows<'_> {
    /// Row `y` of the window.
    fn row(&mut self, y: usize) -> &mut [u8] {
        let start = (self.y0 + y) * self.full_w + self.x0;
        &mut self.full[start..start + self.w]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_inverts_encode() {
        for l in [label::BACKGROUND, label::HAND, label::SCALPEL, label::UNKNOWN] {
            assert_eq!(decode(encode(l)), l);
        }
        assert_eq!(decode(ENC_SHADOW), SHADOW_LIKE);
        for v in [ENC_WEAK, ENC_WEAK_DARK, 7, 8, 200, 255] {
            assert_eq!(decode(v), label::BACKGROUND, "{v}");
        }
    }

    #[test]
    fn the_closing_keeps_the_raw_label_else_the_dilations_where_it_closed() {
        for (a, d, c, want) in [(0, 0, 0, 0), (3, 4, 0, 3), (3, 4, 9, 3), (0, 4, 0, 0), (0, 4, 1, 4), (0, 0, 1, 0)] {
            assert_eq!(closed(a, d, c), want, "{a} {d} {c}");
        }
    }
}
