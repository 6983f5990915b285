//! The colours learned beside the labelling: a trusted frame set that teaches the colours
//! ([`crate::labelling`], `LEARN_EVERY`) hands its lesson to a thread of its own: the fitted tool
//! drawn into every view, its labels sharpened twice and both appearance models taught and
//! compiled. In the main job's loop (`Labelling::learn_beside`) the labelling takes what was
//! learned [`LESSON_DELAY`] frame sets later, waiting for it if it is not done, so that the labels,
//! fits and reports are the same whichever thread ran it and however fast; elsewhere it waits for
//! it before the frame set's labelling returns, as when it learned on its own path. In the loop a frame set that
//! taught the colours took three times as long to label as the others (17-21 ms against 6 on the
//! built-in scene's recording, one in fifteen frame sets): beside it, the segmentation's p95 fell
//! by 20-40%, though on two cores the lesson still shares them with the other stages
//! (docs/benchmarks.md, "The colours learned beside the loop").

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::time::Instant;

use hullcut_capture::segment::{AppearanceModel, ColourLut, Window};
use hullcut_dataset::label;
use hullcut_hull::Occupancy;
use hullcut_pose::ToolRegion;
use image::{GrayImage, RgbImage};
use nalgebra::Point2;

use crate::deferred::PendingLabels;
use crate::error::{Context as _, Error, fail};
use crate::labelling::{compile, compile_explained, sharpen_views, tool_taught_the_hand};

/// The colours a trusted frame set teaches label, hint and sharpen from this many frame sets
/// after it on (1 would be the next): the frame set between gives the lesson's thread the time of
/// one frame set's labelling to finish before it is waited for.
pub const LESSON_DELAY: u32 = 2;

/// The labels a lesson learns from.
pub(crate) enum LessonLabels {
    /// Drawn already (the frame set's masks were wanted at once): per view the labels, the shadows
    /// given back to the table already background, and where the tool is drawn.
    Drawn { masks: Vec<Option<GrayImage>>, tool_regions: Vec<Option<ToolRegion>> },
    /// Still to draw, from what the labelling saw (its sharpening colours left out).
    ToDraw { pending: Box<PendingLabels>, occupancy: Occupancy },
}

/// One trusted frame set's lesson: what its labels teach the two appearance models
/// (`Labelling::learn` explains why two).
pub(crate) struct Lesson {
    pub(crate) labels: LessonLabels,
    /// Per view (rig order), its image; `None` for a missing view.
    pub(crate) images: Vec<Option<RgbImage>>,
    /// Per camera, the drawn blade's outline (counter-clockwise pixels).
    pub(crate) outlines: Vec<Vec<Point2<f64>>>,
    /// Per view, where it was segmented (its labels are background outside).
    pub(crate) windows: Vec<Option<Window>>,
    /// The colours that label only where sure, as they were: they sharpen the labels learned by
    /// the colours that label and hint, and judge the drawn blade once learned where not compiled
    /// again.
    pub(crate) sure: Option<Arc<ColourLut>>,
    /// The sharpening colours as they were: they sharpen the labels handed out.
    pub(crate) explained: Option<Arc<ColourLut>>,
    /// The two models as they were.
    pub(crate) appearance: AppearanceModel,
    pub(crate) sharpening: AppearanceModel,
    /// Frame sets passed since the colours last learned (what they forget).
    pub(crate) passed: u32,
    /// Whether the colours that label and hint, and the sharpening colours, are compiled again.
    pub(crate) compile: (bool, bool),
}

/// What a lesson taught.
pub(crate) struct Learned {
    pub(crate) appearance: AppearanceModel,
    pub(crate) sharpening: AppearanceModel,
    /// The colours that label and those that label only where sure, where compiled again.
    pub(crate) colours: Option<(Option<ColourLut>, Option<Arc<ColourLut>>)>,
    /// The sharpening colours, where compiled again.
    pub(crate) explained: Option<Option<Arc<ColourLut>>>,
    /// Whether the tool's classes came out with the hand's colours: then nothing is taken.
    pub(crate) refused: bool,
    /// The drawn blade's pixels (those labelled scalpel inside its outline before any colour
    /// sharpened them) and how many of them the sure colours, as learned, call the hand's: `None`
    /// where refused or without sure colours.
    pub(crate) blade: Option<(u64, u64)>,
    /// How long the lesson took on its thread, ms.
    pub(crate) ms: f64,
}

impl Lesson {
    /// Draws the labels where they are not drawn, sharpens them, teaches both models and
    /// compiles them as asked.
    fn run(self) -> Learned {
        let clock = Instant::now();
        let (masks, regions) = match self.labels {
            LessonLabels::Drawn { masks, tool_regions } => (masks, tool_regions),
            LessonLabels::ToDraw { pending, occupancy } => pending.draw_plain(&occupancy),
        };
        let images: Vec<Option<&RgbImage>> = self.images.iter().map(Option::as_ref).collect();
        let sharpened = |lut: Option<&ColourLut>| {
            let mut out = masks.clone();
            if let Some(lut) = lut {
                sharpen_views(lut, &images, &mut out, &regions);
            }
            out
        };
        // The colours that label and hint learn from the labels sharpened wherever a colour is
        // surely the likelier, the sharpening colours from the labels handed out.
        let (likelier, handed_out) = (sharpened(self.sure.as_deref()), sharpened(self.explained.as_deref()));
        let inside: Vec<Vec<usize>> = masks
            .iter()
            .zip(&self.outlines)
            .map(|(m, o)| m.as_ref().map_or_else(Vec::new, |m| inside_outline(m.width(), m.height(), o)))
            .collect();
        let (mut appearance, mut sharpening) = (self.appearance, self.sharpening);
        learn_models(
            (&mut appearance, &mut sharpening),
            &images,
            &self.windows,
            (&likelier, &handed_out),
            &inside,
            self.passed,
        );
        let refused = appearance.classes().is_some_and(|c| tool_taught_the_hand(&c));
        let colours = self.compile.0.then(|| compile(appearance.classes()));
        let explained = self.compile.1.then(|| compile_explained(sharpening.classes()).map(Arc::new));
        let sure = colours.as_ref().map_or(self.sure.as_deref(), |c| c.1.as_deref());
        let blade = sure.filter(|_| !refused).map(|sure| {
            images.iter().zip(&masks).zip(&inside).fold((0, 0), |(pixels, hand), ((image, mask), inside)| {
                let (Some(image), Some(mask)) = (image, mask) else { return (pixels, hand) };
                let blade = scalpel_among(mask, inside);
                (pixels + blade.len() as u64, hand + blade_as_hand(sure, image, &blade))
            })
        });
        Learned { appearance, sharpening, colours, explained, refused, blade, ms: clock.elapsed().as_secs_f64() * 1e3 }
    }
}

/// Both models taught one frame set: the colours that label and hint from `likelier`, the blade
/// told apart inside its outline (`blade`, per view the pixels' indices), the sharpening colours
/// from `handed_out`; what they knew forgets the `passed` frame sets since they last learned.
pub(crate) fn learn_models(
    (appearance, sharpening): (&mut AppearanceModel, &mut AppearanceModel),
    images: &[Option<&RgbImage>],
    windows: &[Option<Window>],
    (likelier, handed_out): (&[Option<GrayImage>], &[Option<GrayImage>]),
    blade: &[Vec<usize>],
    passed: u32,
) {
    let learn = |model: &mut AppearanceModel, masks: &[Option<GrayImage>], blade: &[Vec<usize>]| {
        model.age_by(passed.max(1));
        for (k, (image, mask)) in images.iter().zip(masks).enumerate() {
            if let (Some(image), Some(mask)) = (image, mask) {
                let window = Window::of_view(windows, k, mask.width(), mask.height());
                let inside = blade.get(k).map_or(&[][..], Vec::as_slice);
                model.learn_parts(image, mask, true, window, inside);
            }
        }
        model.sources.geometry_frames += 1;
    };
    // The blade is told apart in the colours that label and hint only: in the sharpening
    // colours a grey blade's class took the hand's dark shadow beside it for the tool.
    rayon::join(|| learn(appearance, likelier, blade), || learn(sharpening, handed_out, &[]));
}

/// A lesson on its thread, and the frame sets labelled since it was handed over.
pub(crate) struct InFlight {
    /// The frame set that teaches.
    pub(crate) frame: u64,
    /// Frame sets labelled since (the one now being labelled among them).
    pub(crate) since: u32,
    /// Whether it compiles the colours again (their count of frame sets since restarts).
    pub(crate) refresh: bool,
    /// Frame sets passed since the colours last learned, when it was handed over.
    pub(crate) passed: u32,
    learned: Receiver<std::thread::Result<Learned>>,
}

impl InFlight {
    /// Hands `lesson`, taught by frame set `frame`, to `pool` (one thread: the lesson's parallel
    /// passes run on it, not on the loop's threads).
    pub(crate) fn start(pool: &rayon::ThreadPool, frame: u64, refresh: bool, lesson: Lesson) -> Self {
        let passed = lesson.passed;
        InFlight { frame, since: 0, refresh, passed, learned: spawn(pool, move || lesson.run()) }
    }

    /// What the lesson taught, waited for, and whether it had to be.
    pub(crate) fn wait(&self) -> Result<(Learned, bool), Error> {
        let (learned, waited) = match self.learned.try_recv() {
            Ok(l) => (l, false),
            Err(_) => match self.learned.recv() {
                Ok(l) => (l, true),
                Err(_) => fail!("learning the colours of frame {}: its thread ended without an answer", self.frame),
            },
        };
        match learned {
            Ok(learned) => Ok((learned, waited)),
            Err(_) => fail!("learning the colours of frame {} panicked", self.frame),
        }
    }
}

/// Runs `learn` on `pool`; its answer (or its panic) comes back on the receiver.
fn spawn(
    pool: &rayon::ThreadPool,
    learn: impl FnOnce() -> Learned + Send + 'static,
) -> Receiver<std::thread::Result<Learned>> {
    let (tx, rx) = sync_channel(1);
    pool.spawn(move || {
        let learned = std::panic::catch_unwind(std::panic::AssertUnwindSafe(learn));
        // The labelling may be gone (an error ended its recording): nobody is waiting.
        let _ = tx.send(learned);
    });
    rx
}

/// The one thread lessons run on.
pub(crate) fn pool() -> Result<rayon::ThreadPool, Error> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "hullcut-learn".to_owned())
        .build()
        .context("starting the thread that learns the colours")
}

/// The indices (ascending) of the pixels of a `width` x `height` image inside the convex `outline`
/// (counter-clockwise pixels; none for fewer than three points).
pub(crate) fn inside_outline(width: u32, height: u32, outline: &[Point2<f64>]) -> Vec<usize> {
    if outline.len() < 3 {
        return Vec::new();
    }
    let (w, h) = (f64::from(width), f64::from(height));
    let lo = outline.iter().fold((f64::MAX, f64::MAX), |a, p| (a.0.min(p.x), a.1.min(p.y)));
    let hi = outline.iter().fold((f64::MIN, f64::MIN), |a, p| (a.0.max(p.x), a.1.max(p.y)));
    let (x0, y0) = (lo.0.floor().max(0.0), lo.1.floor().max(0.0));
    let (x1, y1) = (hi.0.ceil().min(w - 1.0), hi.1.ceil().min(h - 1.0));
    if !(x1 >= x0 && y1 >= y0) {
        return Vec::new();
    }
    let inside =
        |q: Point2<f64>| outline.iter().zip(outline.iter().cycle().skip(1)).all(|(a, b)| (b - a).perp(&(q - a)) >= 0.0);
    let stride = width as usize;
    let mut pixels = Vec::new();
    for y in y0 as usize..=y1 as usize {
        for x in x0 as usize..=x1 as usize {
            if inside(Point2::new(x as f64, y as f64)) {
                pixels.push(y * stride + x);
            }
        }
    }
    pixels
}

/// Those of `pixels` (indices) where `mask` is the scalpel.
pub(crate) fn scalpel_among(mask: &GrayImage, pixels: &[usize]) -> Vec<usize> {
    let raw = mask.as_raw();
    pixels.iter().copied().filter(|&k| raw.get(k) == Some(&label::SCALPEL)).collect()
}

/// How many of `image`'s pixels at `pixels` (indices) `sure` calls the hand's (an index outside
/// the image counts none).
pub(crate) fn blade_as_hand(sure: &ColourLut, image: &RgbImage, pixels: &[usize]) -> u64 {
    let raw = image.as_raw();
    pixels
        .iter()
        .filter_map(|&k| raw.get(3 * k..3 * k + 3))
        .map(|p| u64::from(sure.get([p[0], p[1], p[2]]) == label::HAND))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lesson whose thread panics is an error that names the frame set that taught, not a
    /// crash or a wait for ever; a lesson that ends is taken, waited for or not.
    #[test]
    fn a_lesson_that_panics_is_an_error_naming_its_frame_set() {
        let pool = pool().expect("the learning thread starts");
        let in_flight = |frame, learn: Box<dyn FnOnce() -> Learned + Send>| InFlight {
            frame,
            since: 0,
            refresh: false,
            passed: 1,
            learned: spawn(&pool, learn),
        };
        let failed = in_flight(41, Box::new(|| panic!("a lesson that fails")));
        let e = failed.wait().err().expect("a panic is an error");
        assert!(e.to_string().contains("frame 41"), "{e}");
        let learned = || Learned {
            appearance: AppearanceModel::default(),
            sharpening: AppearanceModel::default(),
            colours: None,
            explained: None,
            refused: true,
            blade: None,
            ms: 1.5,
        };
        let done = in_flight(42, Box::new(learned));
        let (taken, _) = done.wait().expect("taken");
        assert!(taken.refused && taken.ms == 1.5);
        // The pool's thread outlives a panic: the next lesson runs.
        let after = in_flight(43, Box::new(learned));
        assert!(after.wait().is_ok());
    }
}
