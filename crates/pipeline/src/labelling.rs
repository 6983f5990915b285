//! Masks from a recording's images (`hullcut segment`, `reconstruct` and `run`): the foreground from the
//! background model (empty-scene images, else the recording's own median), its labels from the
//! known tool's geometry ([`ToolLabeller`]: the tool fitted into the foreground's hull and drawn
//! into every view, the hand's occlusion respected), and where the tool cannot be fitted, or there
//! is no tool.json, from the colours learned from the recording ([`AppearanceModel`]: from the
//! geometric labels of trusted frames and from frames a lab has masked, `--label-frames`).

use std::sync::Arc;
use std::time::Instant;

use hullcut_capture::segment::{
    AppearanceModel, ColourClasses, ColourLut, LearnedColour, Method, SHADOW_LIKE, SegmentParams, Segmenter, Window,
};
use hullcut_dataset::{Dataset, FrameSet, ToolGeometry, label};
use hullcut_hull::shadow::{SHADOW_HULL_HEIGHT, cover, cover_split, keep_supported, still_seen};
use hullcut_hull::{HullError, HullParams, Occupancy, Silhouette, direct_silhouettes, refine_cells, silhouettes};
use hullcut_pose::{
    LabelParams, LabelStats, MANY_VIEWS, POSSIBLE_SHADOW, PoseEstimate, Shading, TABLE_SHADOW, TOOL_COLOURED_SHADOW,
    TableShadows, ToolLabeller, ToolRegion, TrackerParams, ViewInput,
};
use image::GrayImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::backend::Carver;
use crate::deferred::PendingLabels;
use crate::error::{Context as _, Error, fail};
use crate::lesson::{InFlight, LESSON_DELAY, Learned, Lesson, LessonLabels, inside_outline, learn_models};
use crate::region::{BLOCK_M, CarveRegion, PAD_M};

/// A trusted frame set's geometric labels teach the appearance model when its confidence is at
/// least this, or, seen by fewer than [`MANY_VIEWS`] views, when neither a trusted frame set nor
/// masked frames have taught it yet: there the first trusted one teaches at any confidence. On
/// four cameras without colours the band around the held tool keeps some of the fingers, right
/// fits explain 83-90% of it and are trusted at 0.5-0.8 if at all, and the colours that would tell
/// the fingers from the tool never came (random:1061 in random:1093: 10 of 150 frame sets trusted,
/// none teaching; 53 once the first, at 0.58, taught; random:1307 in random:1193: 1 trusted at
/// 0.64, then none; 22 once it taught). Both now trust their first fits at 0.84 or more; of 21
/// four- and five-camera recordings swept on 2026-12-03 only random:3231 in random:3233 trusts
/// its first below 0.8 (0.54), a weak recording either way (1 trusted fit, off; without this
/// rule 2, both off). Later frame sets refresh what the first taught, recent ones weighing more.
/// On six cameras the first trusted fits come soon and confident enough, and a marginal first
/// one taught worse colours (the built-in rig and look, 24 frame sets of the cut
/// at 10 fps in `hullcut segment`: scalpel IoU 0.863 -> 0.693).
const LEARN_CONFIDENCE: f64 = 0.8;
/// The tool's fit to foreground evidence counts as agreeing from 82% (none) to 92% (full) of its
/// samples explained: the band around the tool holds some of the hand's outline too.
const GEOMETRY_AGREEMENT: (f64, f64) = (0.82, 0.92);
/// Until a trusted frame set has taught the colours, up to this many frame sets whose fit the
/// tracker refused but whose outline agrees with the silhouettes (at least the second bound of
/// [`GEOMETRY_AGREEMENT`]) teach them from the pixels that fit alone decides: the drawn tool where
/// no cell of the hand's hull lies in front of it, and the foreground farther than [`SHARPEN_PX`]
/// from the drawn tool. On a rig of four cameras the hand's hull is fat around the held tool, and
/// its phantom cells hide the blade from the evidence of half the views (random:503 in
/// random:509: right fits, 0.4-1.3° and 1-2 mm, refused as seen by two views of four, frame set
/// after frame set); the colours so taught tell the blade's pixels from the hand's there. They
/// hint the fit, but label no frame set alone ([`Labelling::colours_label`]), and are taught only
/// from a steady fit ([`BOOTSTRAP_STEP_M`]) whose tool the hand's colours do not explain
/// ([`tool_apart_from_hand`]).
const BOOTSTRAP_FRAMES: u64 = 10;
/// ... when the frame set before had such a fit too, its tip within this distance (metres) and
/// its blade's normal within [`BOOTSTRAP_TURN_DEG`] of this one's: a right fit holds from frame set
/// to frame set, while fits that agree with the silhouettes by chance do not (random:257 in
/// random:263, a blue glove holding a blue handle over brushed steel: agreeing fits 66-263 mm
/// off, none two frame sets running, taught the table's grey as the tool's colour, and 17 fits
/// were then trusted, all 12 mm off; random:503 in random:509's agreeing fits hold from frame set
/// 3 to 21).
const BOOTSTRAP_STEP_M: f64 = 0.005;
/// ... (see [`BOOTSTRAP_STEP_M`]), degrees.
const BOOTSTRAP_TURN_DEG: f64 = 5.0;
/// ... when the fit's unoccluded tool pixels number at least this many over the views (a
/// handful of pixels teaches nothing, and on a tool wholly hidden the fit decides nothing).
const BOOTSTRAP_MIN_PIXELS: usize = 200;
/// A trusted frame set teaches the colours when at least this many frame sets have passed since
/// the last one that taught them (trusted, or agreeing before any trusted one did:
/// [`BOOTSTRAP_FRAMES`]); while none has, the first trusted one teaches. The colours of a hand and a
/// tool change little from one frame set to the next, and learning needs the fitted tool drawn
/// into every view, most of the labelling's time: it is done beside the labelling, on a thread of
/// its own ([`crate::lesson`]). Inside the main job's loop a frame set is labelled only as far as
/// the loop needs: the tool's fit and the hull's cells near it ([`Labelling::label_with`]); the
/// label masks of those logged with their images are drawn beside the loop
/// ([`Labelling::defer_drawing`]). What was learned is forgotten by the frame sets
/// passed, not by those learned from. Every fifteenth rather than every fifth (2026-12-01, 18
/// resections of 150 frame sets on random rigs and looks, both tools, five never run before):
/// 2,370 frame sets trusted instead of 2,301, 169 of them off instead of 185, 34 lobes cut off
/// instead of 33, pooled IoU in `hullcut segment` hand 0.955 and scalpel 0.805 on the mean
/// instead of 0.945 and 0.770 (random:1607 in random:1627: 139 trusted instead of 65, the lobe
/// cut off; random:199 in random:211: scalpel 0.610 instead of 0.201); every thirtieth halved
/// random:199's trusted frame sets (61 -> 31). Inside the main job's loop 12 frame sets of 180
/// teach instead of 36.
const LEARN_EVERY: u64 = 15;

/// Where the tool's track predicts it, the foreground's hull is carved at the leaf within this
/// distance of the predicted tool and at twice the leaf beyond ([`Labelling::carve_foreground`]),
/// metres: room for the prediction's error and the fingers around the handle.
const FINE_NEAR_TOOL_M: f64 = 0.015;

/// The hull is carved finer only near the predicted tool where the prediction carries the tool at
/// most this far from its last trusted pose, metres, looking at most [`MAX_PREDICTED_AHEAD_S`]
/// ahead ([`hullcut_pose::Tracker::prediction_reach`]): the tool moves 5-10 mm from one frame set
/// to the next at 30 fps in the resection; at 10 fps 4-17 cm, and the prediction may be off by as
/// much, the tool carved coarse where it is fitted.
const MAX_PREDICTED_SHIFT_M: f64 = 0.01;

/// See [`MAX_PREDICTED_SHIFT_M`], seconds: a frame set at 20 fps or faster after a trusted one.
const MAX_PREDICTED_AHEAD_S: f64 = 0.05;

/// The colour classes are compiled when they first learn, and again when they learn at least this
/// many frame sets after that.
const REFRESH_EVERY: u32 = 15;
/// Foreground this close (pixels, square neighbourhood) to the drawn tool takes the label of its
/// colour where the colour is sure: the geometry puts the tool to a pixel or two, and where the
/// hand crosses it the hull cannot say which is in front to the pixel.
const SHARPEN_PX: usize = 12;
/// A colour is sure when it is at least e^3 (20) times as likely under its label as under the other.
const SHARPEN_LOG_RATIO: f64 = 3.0;
/// ... and when its label's class explains it: its squared Mahalanobis distance from that class
/// is below the 99th percentile of a χ² with three degrees of freedom. A colour neither the hand
/// nor the tool has (a shadow on a green mat kept beside the blade) is likelier under the broader
/// class, but decides nothing.
const SURE_MAHALANOBIS2: f64 = 11.34;
/// The fit's hand hints are given only while the sure colours call at most this share of the
/// drawn blade's pixels the hand's (on the frame sets learned from): above it, the blade looks
/// like the hand to them (a thin steel blade, eroded away as too thin to learn from, beside a
/// handle of another colour), and a hint would hide the blade from the fit, which then never
/// takes hold again. Measured (`hullcut segment`): random:59 in random:101, where the hints keep
/// the track, 0.1-0.3%; the pointed tool in random:137 17% from its first learned frame set, in
/// random:271 64%.
const TOOL_AS_HAND_MAX: f64 = 0.1;
/// How much of the drawn blade's tally is kept per frame set passed (the appearance model
/// forgets at the same pace).
const TOOL_AS_HAND_KEEP: f64 = 0.97;
/// A view's foreground is degraded when it is this many times its usual (the median over its
/// last [`DEGRADED_HISTORY`] frame sets)...
const DEGRADED_JUMP: f64 = 3.0;
/// ... where the usual is taken as at least this fraction of the image (a jump of a small
/// foreground is a hand coming closer to the camera or into view, not a change of the scene).
const DEGRADED_MIN_FRACTION: f64 = 0.01;
/// Frame sets of each camera's usual foreground.
const DEGRADED_HISTORY: usize = 16;
/// Marks the foreground the hull explains while a degraded view is cut back (no label uses it).
const EXPLAINED: u8 = 254;
/// Marks the possible shadows that a hull cell low over the table covers, to be asked of the
/// other views whether they lie on the table (no label uses it).
const ASK_TABLE: u8 = 253;
/// Marks, for a moment, the covered possible shadows that are not asked (only cells high over
/// the table cover them): they become unknown foreground.
const COVERED: u8 = 252;
/// Marks weak foreground until the other views' hull confirms it (no label uses it).
const WEAK: u8 = 251;
/// The weak foreground test's tolerances (brightness, shadow, chromaticity and its share of the
/// noise allowance), as a share of the foreground test's. Measured on ten recordings over ten frame
/// sets each (docs/benchmarks.md, "Weak foreground the other views confirm"): at ½ the pale glove
/// of random:71 in random:109 went from 0.81 to 0.97 foreground IoU, a light hand on wood of its
/// tone from 0.78 to 0.97, and lab8's dark hand with cast shadows lost 0.02; at ¼ the other views'
/// hulls confirmed the table around every hand (0.68-0.93 everywhere).
const WEAK_SCALE: f64 = 0.5;
/// Weak foreground is not confirmed within this many pixels beside the tool where its track
/// expects it (it is, on the drawn tool): the hull near the blade is fat, and the blade's blended
/// edge and the soft rim of its shadow, confirmed there, grew the hand's hull in front of the
/// blade until most views counted it hidden. With the flag, trusted frame sets of 150 without a
/// band, at 6 px, at 12 px: random:269 in random:271 76, 113, 150 (cut off only at 12), random:97
/// in random:137 97, 150, 150 (cut off from 6); the built-in scene and lab8 all trusted and cut off
/// at both, random:397 in random:401 122, 120, 110, cut off at all three (docs/benchmarks.md,
/// "Weak foreground the other views confirm").
const WEAK_TOOL_BAND_PX: usize = 12;
const _: () =
    assert!(WEAK != SHADOW_LIKE && WEAK != EXPLAINED && WEAK != ASK_TABLE && WEAK != COVERED && WEAK != label::UNKNOWN);
const _: () = assert!(
    ASK_TABLE != SHADOW_LIKE
        && ASK_TABLE != EXPLAINED
        && ASK_TABLE != label::UNKNOWN
        && COVERED != SHADOW_LIKE
        && COVERED != EXPLAINED
        && COVERED != ASK_TABLE
        && COVERED != label::UNKNOWN
);

// The segmenter's possible shadows are what the tool's labeller reads as such ([`TableShadows`]
// reads the masks before the hull resolves them).
const _: () = assert!(SHADOW_LIKE == POSSIBLE_SHADOW);
const _: () = assert!(
    TOOL_COLOURED_SHADOW != POSSIBLE_SHADOW && TOOL_COLOURED_SHADOW != TABLE_SHADOW && TOOL_COLOURED_SHADOW != WEAK
);
/// Pixels down to this much darker than their background (relative) with their chromaticity
/// unchanged may be cast shadows, resolved by the hull ([`hullcut_hull::shadow`]): a shadow in
/// full (ambient light only) keeps a fifth of the light or more.
const SHADOW_DEPTH: f64 = 0.8;

/// Hull cells within this distance of the tool where its track predicts it are an object, not a
/// cast shadow, metres: enough for the prediction's error and for a tip the fit fell short of.
const TOOL_OBJECT_MARGIN: f64 = 0.004;

/// Which evidence labels the foreground (`--labels`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum LabelMethod {
    /// The fitted tool's geometry, sharpened by the learned colours near the tool, and the colours
    /// alone where the tool cannot be fitted.
    #[default]
    Both,
    /// The fitted tool's geometry alone: nothing learned, the foreground left unknown where the
    /// tool cannot be fitted.
    Geometry,
    /// The colours learned from `--label-frames`' masks alone (tool.json ignored).
    Colour,
}

impl LabelMethod {
    /// Its name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            LabelMethod::Both => "both",
            LabelMethod::Geometry => "geometry",
            LabelMethod::Colour => "colour",
        }
    }
}

/// Where a frame set's labels came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelSource {
    /// The fitted tool drawn into the views.
    Geometry,
    /// The colours learned from the recording.
    Colour,
    /// The fitted tool drawn into the views although the tracker did not trust the fit (no
    /// colours learned yet to do better, or `--labels geometry`).
    UntrustedGeometry,
    /// Neither: foreground of unknown label.
    Unknown,
}

/// What labelled one frame set, and the colours learned by then: what the run logs for it.
#[derive(Debug, Clone)]
pub struct LabelTrace {
    /// Where its labels came from.
    pub source: LabelSource,
    /// The colours learned so far ([`Labelling::learned`]).
    pub learned: Vec<LearnedColour>,
    /// The share of the drawn blade the learned colours call the hand's, once a blade was drawn
    /// on a frame set learned from ([`Labelling::blade_as_hand`]).
    pub blade_as_hand: Option<f64>,
    /// Possible shadows given back to the table in the frame set, over its views (`None` where
    /// none were asked: no shadows, no tool, or no table; [`Labelling::shadow_on_table`]).
    pub shadow_on_table: Option<u64>,
    /// Pixels of weak foreground the other views' hull confirmed in the frame set, over its views
    /// (`None` without [`Labelling::confirm_weak_foreground`]; [`Labelling::weak_confirmed`]).
    pub weak_confirmed: Option<u64>,
    /// The pixels its untrusted fit taught the colours, over its views, where it agreed with the
    /// silhouettes and taught them ([`Labelling::taught`]; `None` where it taught nothing).
    pub taught: Option<u64>,
    /// What its segmentation tested ([`Labelling::segmented`]).
    pub segmented: Segmented,
    /// Whether the foreground's hull was searched for a lost tool in it ([`Labelled::hull_search`]).
    pub hull_search: Option<bool>,
    /// The time the lesson whose colours its labelling took had taken on its own thread, ms
    /// ([`Labelled::lesson_ms`]; `None` where none was taken).
    pub lesson_ms: Option<f64>,
}

/// What one frame set's segmentation tested.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Segmented {
    /// Whether each view was tested only where the last hull can be seen, row by row (else in
    /// the whole rectangle of the box carved in).
    pub near_hull: bool,
    /// Pixels whose foreground was tested, over the views.
    pub pixels: u64,
    /// Pixels that passed the foreground test only at its weak share of the tolerances and
    /// joined the foreground, or (only darker) a possible shadow, they touch, over the views (the
    /// segmenter's hysteresis; the report's `counters.weak_joined`, frame set by frame set).
    pub weak_joined: u64,
    /// Background pixels enclosed by the foreground that filled it as holes of another colour
    /// than their background's, over the views (`SegmentParams::fill_holes`; the report's
    /// `counters.holes_filled`, frame set by frame set).
    pub holes_filled: u64,
}

impl LabelSource {
    /// Its name in reports and logs.
    pub fn name(self) -> &'static str {
        match self {
            LabelSource::Geometry => "geometry",
            LabelSource::Colour => "colour",
            LabelSource::UntrustedGeometry => "untrusted_geometry",
            LabelSource::Unknown => "unknown",
        }
    }
}

/// Counts per label source, and what was learned.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct LabelCounters {
    /// Frame sets labelled by the tool's geometry.
    pub geometry: u64,
    /// Frame sets labelled by the learned colours.
    pub colour: u64,
    /// Frame sets labelled by a fit the tracker did not trust (drawn all the same: no colours
    /// were learned yet, or `--labels geometry`).
    pub untrusted: u64,
    /// Frame sets whose foreground stayed unknown.
    pub unknown: u64,
    /// Of the untrusted and unknown ones, frame sets labelled again by the colours learned from
    /// the whole recording (`segment`, which sees all of it before it writes).
    pub relabelled: u64,
    /// Frame sets whose geometric labels the appearance model learned from.
    pub learned: u64,
    /// Of those, frame sets whose fit the tracker refused but that taught the colours the pixels
    /// it alone decides, before any trusted frame set had (the tool drawn where no hull cell lies
    /// in front of it, the foreground far from it).
    #[serde(default)]
    pub bootstrapped: u64,
    /// Frame sets whose untrusted fit would have taught the colours, but whose hand's colours
    /// then explained the tool's mean colour (within their 99% ellipsoid): nothing was learned
    /// from them.
    #[serde(default)]
    pub bootstrap_refused: u64,
    /// Trusted frame sets that would have taught the colours, but after which every class of the
    /// tool had its mean within the hand's own spread (squared Mahalanobis distance 3 of the
    /// hand's: the tool taught the hand's colours): rolled back, nothing learned, and no trusted
    /// frame set taught for fifteen frame sets (0 in reports written before the thirty-ninth
    /// session).
    #[serde(default)]
    pub learn_refused: u64,
    /// Pixels that looked like cast shadows (darker, chromaticity unchanged), over all views.
    pub shadow_pixels: u64,
    /// Of those, pixels the hull showed to be foreground (a dark object, not a shadow).
    pub shadow_foreground: u64,
    /// Hull cells dropped as shadows on the table: more views saw only shadow in them than sure
    /// foreground, and fewer than two saw sure foreground in front of every other cell kept.
    pub shadow_cells_dropped: u64,
    /// Of those, cells that two or more views saw as sure foreground, but only through an object
    /// in front of them (the hand over its own shadow, seen by the views near the light's
    /// direction).
    #[serde(default)]
    pub shadow_cells_seen_through: u64,
    /// Of `shadow_foreground`, pixels given back to the background: their ray meets the table at
    /// a point the other views see darkened as much (a shadow on the table under the hand's hull,
    /// which the hull alone kept).
    #[serde(default)]
    pub shadow_on_table: u64,
    /// Views whose foreground jumped far above their usual (someone behind the table, a light
    /// switched on): their foreground was cut to what the hull explains, the frame set kept.
    pub degraded_views: u64,
    /// Frame sets whose foreground hull was carved at twice the leaf away from the tool and at
    /// the leaf within 1.5 cm of where its track predicted it (the others, at the leaf throughout:
    /// no prediction yet, the track lost, or a prediction that looks more than 50 ms ahead or
    /// carries the tool more than 1 cm).
    #[serde(default)]
    pub hull_fine_near_tool: u64,
    /// The share of the drawn blade's pixels (the tool's labels within the blade's outline), on
    /// the frame sets learned from (recent ones weighing more), that the sure colours call the
    /// hand's.
    #[serde(default)]
    pub tool_as_hand: f64,
    /// Whether the tool's fit gets hints where a colour is surely the hand's (while
    /// `tool_as_hand` is at most 0.1: above it the colours would hide the blade from the fit).
    #[serde(default = "yes")]
    pub hand_hints: bool,
    /// Pixels of weak foreground the other views' hull confirmed (with
    /// `--confirm-weak-foreground`), over all views.
    #[serde(default)]
    pub weak_confirmed: u64,
    /// Frame sets whose views were segmented only where the last hull, grown by the motion
    /// allowed for, can be seen (row by row: [`crate::region::stretches`]); the others, in the
    /// whole rectangle of the box carved in (the first frame set, the whole volume every 15th,
    /// after one whose foreground reached past its stretches; all with the weak foreground
    /// confirmed).
    #[serde(default)]
    pub segmented_near_hull: u64,
    /// Of those, frame sets whose foreground reached the end of a stretch in some view (the next
    /// one is segmented in the box's whole rectangle).
    #[serde(default)]
    pub reached_past_hull: u64,
    /// Pixels whose foreground was tested, over every view and frame set (the rest of each mask
    /// is background without a test: outside the box's rectangle, or the last hull's stretches).
    #[serde(default)]
    pub pixels_tested: u64,
    /// Pixels that passed the foreground tests only at half their tolerances and joined the
    /// foreground they touch (the segmenter's hysteresis, `SegmentParams::weak_share`), or
    /// (only darker) a possible shadow they touch, over every view and frame set, before the
    /// clean-up.
    #[serde(default)]
    pub weak_joined: u64,
    /// Background pixels enclosed by the foreground, filled as holes whose mean colour is not
    /// their background's (`SegmentParams::fill_holes`), over every view and frame set.
    #[serde(default)]
    pub holes_filled: u64,
    /// Frame sets whose hull's thin parts were searched for the tool (nothing trusted from the
    /// track: it was lost, or its prediction's fit refused).
    #[serde(default)]
    pub searches: u64,
    /// Frame sets that trusted nothing from the track and were not searched: the searches before
    /// found no trusted fit, and are paced (`hullcut_pose::LabelParams::max_search_gap`).
    #[serde(default)]
    pub searches_paused: u64,
}

/// Reports written before `hand_hints` was counted gave the fit its hand hints throughout.
fn yes() -> bool {
    true
}

/// When the weak foreground test runs ([`Labelling::confirm_weak_foreground_when`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WeakWhen {
    /// On every frame set.
    Always,
    /// From the frame set after the tool's track was lost on.
    TrackLost,
}

/// Frame sets over which [`WeakWhen::TrackLost`] counts the track's refusals.
pub const LOST_WINDOW: usize = 30;

/// Refused frame sets within [`LOST_WINDOW`] that count the track as lost: a fifth.
pub const LOST_REFUSED: usize = 6;

/// The tool's track over the last [`LOST_WINDOW`] frame sets, for [`WeakWhen::TrackLost`].
#[derive(Debug, Clone, Default)]
struct LostTrack {
    /// Refused (true) or trusted, oldest first.
    recent: std::collections::VecDeque<bool>,
    /// The frame set from which on the track counts as lost (set once, for good).
    since: Option<u64>,
}

impl LostTrack {
    /// Records frame set `frame`'s fit: the track is lost, from the next frame set on, once
    /// [`LOST_REFUSED`] of the last [`LOST_WINDOW`] were refused.
    fn record(&mut self, frame: u64, trusted: bool) {
        if self.since.is_some() {
            return;
        }
        if self.recent.len() == LOST_WINDOW {
            self.recent.pop_front();
        }
        self.recent.push_back(!trusted);
        if self.recent.iter().filter(|&&r| r).count() >= LOST_REFUSED {
            self.since = Some(frame.saturating_add(1));
        }
    }
}

/// What the labelling of a run did, for its report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LabellingReport {
    /// How each camera found its foreground: `background` (empty-scene images), `median` (the
    /// recording's median), `mog2`.
    pub foreground: Vec<Option<Method>>,
    /// Which evidence was asked for (`--labels`).
    pub method: LabelMethod,
    /// Whether the tool's geometry labelled (a tool.json was there and `--labels` is not
    /// `colour`).
    pub tool: bool,
    /// Frames whose masks/ seeded the colours (`--label-frames`).
    pub label_frames: Vec<u64>,
    /// Whether weak foreground the other views confirm may become foreground
    /// (`--confirm-weak-foreground`; `counters.weak_confirmed` counts it).
    #[serde(default)]
    pub confirm_weak_foreground: bool,
    /// When the weak foreground test runs (`always`, `track_lost`); `None` without it.
    #[serde(default)]
    pub weak_foreground_when: Option<WeakWhen>,
    /// With `track_lost`: the frame set from which on it ran (`None`: the track was never lost).
    #[serde(default)]
    pub weak_foreground_from: Option<u64>,
    /// Counts per label source.
    pub counters: LabelCounters,
    /// The learned colours that label by colour and give the tool's fit its hints (learned from
    /// the labels sharpened wherever a colour is surely the likelier).
    pub appearance: Vec<LearnedColour>,
    /// The learned colours that sharpen the labels near the drawn tool (learned from the labels
    /// handed out).
    #[serde(default)]
    pub sharpening_appearance: Vec<LearnedColour>,
    /// Frame sets and views it learned from.
    pub appearance_sources: hullcut_capture::segment::AppearanceSources,
    /// Frame sets whose fitted tool was drawn into the views to label them: every fitted one
    /// outside the main job's loop; inside it, those whose untrusted fit may teach the colours
    /// ([`Labelling::label_with`]). 0 in reports written before it was counted.
    #[serde(default)]
    pub drawn: u64,
    /// Fitted frame sets whose label masks were wanted but left to be drawn later, beside the loop
    /// (the main job's logged frame sets that teach nothing: [`Labelling::defer_drawing`]); not
    /// among `drawn`. 0 in reports written before it was counted.
    #[serde(default)]
    pub deferred: u64,
    /// Trusted frame sets whose labels taught the colours on a thread of their own (drawn there
    /// where they were not drawn at once: not among `drawn`), their colours taken two frame sets
    /// later in the main job's loop ([`Labelling::learn_beside`]), at once elsewhere; those of
    /// them the loop had to wait for when they were due (`lessons_waited`). 0 in reports written
    /// before they were counted.
    #[serde(default)]
    pub lessons: u64,
    /// See `lessons`.
    #[serde(default)]
    pub lessons_waited: u64,
}

/// One frame set's labels.
#[derive(Debug)]
pub struct Labelled {
    /// Per view: 0 background, 1 hand, 2 scalpel, 255 unknown; `None` for a missing view, and for
    /// every view of a frame set labelled without its masks ([`Labelling::label_with`]).
    pub masks: Vec<Option<GrayImage>>,
    /// The foreground's hull with the tool's cells labelled, when the geometry ran (no need to
    /// carve again).
    pub occupancy: Option<Occupancy>,
    /// The tool's pose, when there is a tool.json (the labelling's track is the pose's).
    pub estimate: Option<PoseEstimate>,
    /// Where the labels came from.
    pub source: LabelSource,
    /// Foreground extraction, ms.
    pub foreground_ms: f64,
    /// Carving the foreground's hull, ms.
    pub carve_ms: f64,
    /// The geometric labeller's counters and timings.
    pub stats: Option<LabelStats>,
    /// Whether the fitted tool was drawn into the views for these labels (their masks wanted, or
    /// an untrusted fit may teach the colours: [`Labelling::label_with`]), the costliest frame
    /// sets to label ([`LabellingReport::drawn`] counts them).
    pub drawn: bool,
    /// The label masks left to be drawn later ([`Labelling::defer_drawing`]; `masks` are `None`
    /// then): the caller draws them when it needs them.
    pub pending: Option<PendingLabels>,
    /// The time a trusted frame set's lesson took on its own thread, beside the labelling
    /// ([`crate::lesson`]), where its colours were taken at the start of this frame set's
    /// labelling, ms.
    pub lesson_ms: Option<f64>,
}

impl Labelled {
    /// Whether the foreground's hull was searched for the tool (`Some(true)`) or the search was
    /// paused while the searches before found nothing (`Some(false)`,
    /// [`Labelling::set_search_gap`]); `None` where no search was due (the track's prediction was
    /// trusted) or there is no tool.
    pub fn hull_search(&self) -> Option<bool> {
        let stats = self.stats.as_ref()?;
        if stats.from_thin_parts {
            Some(true)
        } else if stats.search_paused {
            Some(false)
        } else {
            None
        }
    }
}

/// What one view's foreground mask holds.
#[derive(Debug, Clone, Copy)]
struct MaskCounts {
    /// Pixels not background.
    foreground: usize,
    /// Pixels that may be cast shadows ([`SHADOW_LIKE`]).
    shadow: u64,
    /// Pixels of the image.
    pixels: usize,
}

impl MaskCounts {
    /// One pass over the window `win` of `mask` (outside it the mask is background): both counts
    /// kept in bytes over runs of 255 pixels, which vectorizes 32 pixels wide (two passes with
    /// word-sized sums took about 1 ms per frame set of six 640x480 views inside the loop).
    fn within(mask: &GrayImage, win: Window) -> MaskCounts {
        let (mut foreground, mut shadow) = (0, 0);
        let raw = mask.as_raw();
        for span in win.spans(mask.width(), mask.height()) {
            for run in raw[span].chunks(usize::from(u8::MAX)) {
                let (f, s) = run.iter().fold((0u8, 0u8), |(f, s), &p| {
                    (f + u8::from(p != label::BACKGROUND), s + u8::from(p == SHADOW_LIKE))
                });
                foreground += usize::from(f);
                shadow += u64::from(s);
            }
        }
        MaskCounts { foreground, shadow, pixels: mask.width() as usize * mask.height() as usize }
    }
}

/// Labels frame sets (see the module docs).
pub struct Labelling {
    method: LabelMethod,
    segmenter: Segmenter,
    /// The weak foreground test ([`Labelling::confirm_weak_foreground`]).
    weak: Option<Segmenter>,
    /// When the weak foreground test runs, once set up.
    weak_when: WeakWhen,
    /// The tool's track over the last frame sets, refused or not, while the weak test waits for
    /// it to be lost ([`WeakWhen::TrackLost`]).
    lost: LostTrack,
    /// Where the weak foreground's hull is carved: around the last frame set's hull, as the main
    /// job's loop carves ([`CarveRegion`]).
    weak_region: Option<CarveRegion>,
    /// Per view, the pixels segmented ([`Labelling::set_workspace`]; empty: every pixel).
    windows: Vec<Option<Window>>,
    /// Per view, the columns of each row segmented within its window (empty: the whole window).
    stretches: Vec<Option<Vec<(u32, u32)>>>,
    /// The blocks ([`crate::region::blocks`]) of the last frame set's hull, unless its
    /// foreground reached past its stretches (or nothing was carved).
    last_blocks: Option<Vec<nalgebra::Point3<f64>>>,
    /// The whole working volume (a workspace of its own is segmented in its whole rectangle).
    full_workspace: hullcut_hull::Aabb,
    /// The pixels of each view that the other views confirmed as foreground in this frame set.
    weak_pixels: Vec<Vec<usize>>,
    /// The weak test's masks, reused from frame set to frame set.
    loose: Vec<Option<GrayImage>>,
    tool: Option<ToolLabeller>,
    /// The colours of the labels sharpened wherever a colour is surely the likelier: they label
    /// by colour and give the fit its hints.
    appearance: AppearanceModel,
    /// The colours of the labels handed out: they sharpen the labels near the drawn tool (see
    /// [`Labelling::learn`] for why apart).
    sharpening: AppearanceModel,
    colours: Option<ColourLut>,
    /// The colours compiled to decide only where sure ([`SHARPEN_LOG_RATIO`]): the fit's hints.
    sure: Option<Arc<ColourLut>>,
    /// The sharpening colours where sure and their class also explains them
    /// ([`SURE_MAHALANOBIS2`]): they sharpen the labels near the drawn tool.
    explained: Option<Arc<ColourLut>>,
    /// The drawn blade's pixels on the frame sets learned from, and those of them the sure colours
    /// call the hand's (with forgetting): whether the fit gets hand hints ([`TOOL_AS_HAND_MAX`]).
    tool_as_hand: (f64, f64),
    /// The last frame set's fit, where the tracker refused it but it agreed with the silhouettes:
    /// its tip and blade normal ([`BOOTSTRAP_STEP_M`]).
    last_agreeing: Option<(nalgebra::Point3<f64>, nalgebra::Vector3<f64>)>,
    /// The last frame set's possible shadows given back to the table (`None`: none were asked).
    shadow_on_table: Option<u64>,
    /// What the last frame set's segmentation tested ([`Labelling::segmented`]).
    segmented: Segmented,
    /// Weak foreground pixels confirmed in the last frame set (with the weak test only).
    weak_confirmed: Option<u64>,
    /// The pixels the last frame set's untrusted but agreeing fit taught the colours, over its
    /// views (`None`: it taught nothing; [`BOOTSTRAP_FRAMES`]).
    taught: Option<u64>,
    /// Fitted frame sets whose labels were drawn ([`LabellingReport::drawn`]).
    drawn: u64,
    /// Whether the label masks wanted but not needed to teach the colours are left to be drawn
    /// later ([`Labelling::defer_drawing`]).
    defer: bool,
    /// Fitted frame sets whose labels were left to be drawn later ([`LabellingReport::deferred`]).
    deferred: u64,
    /// Whether lessons are taken [`LESSON_DELAY`] frame sets later, not waited for at once
    /// ([`Labelling::learn_beside`]).
    beside: bool,
    /// The thread lessons run on, once one was given ([`crate::lesson`]).
    learner: Option<rayon::ThreadPool>,
    /// The lesson on that thread, until its colours are taken.
    lesson: Option<InFlight>,
    /// Lessons given ([`LabellingReport::lessons`]), and those waited for.
    lessons: u64,
    lessons_waited: u64,
    /// What the lesson whose colours were taken at the start of the last frame set's labelling
    /// took on its thread, ms.
    lesson_ms: Option<f64>,
    /// Frame sets labelled since the colours last learned (what they forget when they next do, and
    /// whether a trusted frame set may teach them: [`LEARN_EVERY`]).
    since_learned: u32,
    /// ... and since they were last compiled ([`REFRESH_EVERY`]).
    since_compiled: u32,
    /// Frame sets since a trusted frame set's colours were refused ([`Labelling::learn_trusted`]):
    /// none teaches them again for [`LEARN_EVERY`] frame sets.
    since_refused: Option<u32>,
    hull: HullParams,
    rig: Arc<hullcut_rig::Rig>,
    label_frames: Vec<u64>,
    counters: LabelCounters,
    /// The foreground masks, handed back to the segmenter frame set after frame set
    /// ([`Segmenter::keep_masks`]: nothing below writes foreground outside a view's window).
    masks: Vec<Option<GrayImage>>,
    /// The foreground masks before the hull resolved their possible shadows (for
    /// [`TableShadows`]), kept from frame set to frame set so that copying them allocates nothing.
    unresolved: Vec<Option<GrayImage>>,
    /// Per view, the rows of `unresolved` that may hold foreground ([`copy_within`]).
    unresolved_rows: Vec<Rows>,
    /// Per view, the fit's hints within its window ([`fit_hints`]), kept from frame set to frame
    /// set so that they allocate nothing.
    hints: Vec<Vec<u8>>,
    /// Per view, the foreground with the fit's hints ([`apply_hints`]), kept likewise.
    hinted: Vec<Option<GrayImage>>,
    /// Per view, the rows of `hinted` that may hold foreground ([`copy_within`]).
    hinted_rows: Vec<Rows>,
    /// Per camera, its usual foreground pixel count over the last frame sets (a degraded frame
    /// set repeats the last usual count), each with how many degraded frame sets in a row led to
    /// it.
    history: Vec<std::collections::VecDeque<(usize, usize)>>,
}

impl std::fmt::Debug for Labelling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Labelling")
            .field("method", &self.method)
            .field("tool", &self.tool.is_some())
            .field("label_frames", &self.label_frames)
            .field("counters", &self.counters)
            .finish_non_exhaustive()
    }
}

impl Labelling {
    /// Sets up the foreground models, the tool's labeller and the colours of `label_frames`' masks,
    /// for `method`. Without a tool and without masked frames there is nothing to tell hand from
    /// tool: an error that says what a lab must provide.
    pub fn new(
        ds: &Dataset,
        tool: Option<&ToolGeometry>,
        hull: HullParams,
        label_frames: &[u64],
        method: LabelMethod,
    ) -> Result<Self, Error> {
        let tool = if method == LabelMethod::Colour { None } else { tool };
        if method == LabelMethod::Geometry && tool.is_none() {
            fail!("{}: --labels geometry needs the scalpel's tool.json", ds.root().display());
        }
        if method == LabelMethod::Colour && label_frames.is_empty() {
            fail!(
                "{}: --labels colour learns the colours from masks/: name a few frames with --label-frames",
                ds.root().display()
            );
        }
        // A pixel with one foreground neighbour stays: a blade a pixel or two wide, partly of its
        // background's colour, breaks into short runs that two neighbours would erase, and the
        // tool's fit needs them (the hull and the fit ignore lone noise).
        let params = SegmentParams { shadow_depth: SHADOW_DEPTH, min_neighbors: 1, ..SegmentParams::default() };
        let mut segmenter = Segmenter::from_dataset(ds, params).context("setting up segmentation")?;
        // The foreground masks are kept from frame set to frame set (`masks`), and the passes
        // over them below change only foreground, which lies in each view's window.
        segmenter.keep_masks(true);
        let mut appearance = AppearanceModel::default();
        for &frame in label_frames {
            if !ds.has_masks() {
                fail!("--label-frames: {} has no masks/ to learn the colours from", ds.root().display());
            }
            let set = ds.read_frame_set(frame, true).with_context(|| format!("--label-frames: frame {frame}"))?;
            for view in set.views.iter().flatten() {
                let Some(mask) = &view.mask else { continue };
                appearance.learn(&view.image, mask, false);
                appearance.sources.mask_views += 1;
            }
        }
        let sharpening = appearance.clone();
        let (colours, sure) = compile(appearance.classes());
        let explained = compile_explained(sharpening.classes()).map(Arc::new);
        let tool = tool
            .map(|t| {
                ToolLabeller::new(
                    t,
                    TrackerParams { agreement: GEOMETRY_AGREEMENT, outline_offset: false, ..TrackerParams::default() },
                    LabelParams::default(),
                )
            })
            .transpose()
            .context("tool.json cannot serve to label the tool")?;
        if tool.is_none() && colours.is_none() {
            fail!(
                "{}: nothing tells the hand from the scalpel: add the scalpel's tool.json (its mesh, tip and cutting \
                 edge; README, \"From your rig to hullcut run\"), or draw masks/ for a few frames and name them with \
                 --label-frames (both labels must appear)",
                ds.root().display()
            );
        }
        Ok(Labelling {
            method,
            segmenter,
            weak: None,
            weak_when: WeakWhen::Always,
            lost: LostTrack::default(),
            weak_region: None,
            windows: Vec::new(),
            stretches: Vec::new(),
            last_blocks: None,
            full_workspace: hull.workspace,
            weak_pixels: Vec::new(),
            loose: Vec::new(),
            tool,
            appearance,
            sharpening,
            colours,
            sure,
            explained,
            tool_as_hand: (0.0, 0.0),
            last_agreeing: None,
            shadow_on_table: None,
            segmented: Segmented::default(),
            taught: None,
            drawn: 0,
            defer: false,
            deferred: 0,
            beside: false,
            learner: None,
            lesson: None,
            lessons: 0,
            lessons_waited: 0,
            lesson_ms: None,
            since_learned: 0,
            since_refused: None,
            since_compiled: 0,
            weak_confirmed: None,
            hull,
            rig: Arc::new(ds.rig().clone()),
            label_frames: label_frames.to_vec(),
            counters: LabelCounters { hand_hints: true, ..LabelCounters::default() },
            masks: Vec::new(),
            unresolved: Vec::new(),
            unresolved_rows: Vec::new(),
            hints: Vec::new(),
            hinted: Vec::new(),
            hinted_rows: Vec::new(),
            history: Vec::new(),
        })
    }

    /// Carves the foreground's hull in `workspace` from now on (a box within the working volume
    /// it was made with, on its leaf grid: [`crate::region::CarveRegion`]), and segments each
    /// view only where that box can be seen ([`crate::region::window`], grown by carving's
    /// footprint margin and the clean-up's reach): the rest of its mask is background. In the main job's loop the
    /// box around the last hull covers 8-23% of each view of the built-in scene. A box smaller
    /// than the working volume is the last hull's grown by the motion allowed for
    /// ([`crate::region::PAD_M`]); within its rectangle each view is then segmented only where the
    /// last hull's blocks, grown as much, can be seen, row by row ([`crate::region::stretches`]),
    /// unless that hull's foreground reached past the stretches it was segmented in (or the weak
    /// foreground is confirmed: [`Labelling::confirm_weak_foreground`]).
    pub fn set_workspace(&mut self, workspace: hullcut_hull::Aabb) {
        self.hull.workspace = workspace;
        let pad = self.window_pad();
        self.windows = self.rig.cameras.iter().map(|c| crate::region::window(c, &workspace, pad)).collect();
        self.stretches.clear();
        // The weak test, which sees the whole rectangle, would take what the stretches leave out
        // for weak foreground.
        let near_hull = workspace != self.full_workspace && !self.weak_runs();
        if let Some(blocks) = self.last_blocks.as_ref().filter(|_| near_hull) {
            let reach = 0.5 * BLOCK_M * 3f64.sqrt() + PAD_M;
            // A camera on the MOG2 fallback tests its whole image (its model learns from every
            // pixel): it needs no stretches.
            self.stretches = (self.rig.cameras.iter().zip(&self.windows))
                .enumerate()
                .map(|(k, (c, w))| {
                    let window = w.unwrap_or(Window::whole(c.width, c.height));
                    (self.segmenter.method(k) != Some(Method::Mog2))
                        .then(|| crate::region::stretches(c, blocks, reach, pad, window))
                        .flatten()
                })
                .collect();
        }
    }

    /// The hull of the views' foreground, and whether it was carved finer near the tool: where the
    /// tool's track predicts it, the hull is carved at twice the leaf, then again at the leaf
    /// within [`FINE_NEAR_TOOL_M`] of the predicted tool ([`hullcut_hull::refine_cells`]). There
    /// it holds the cells a carving at the leaf would (carving is conservative); away from the
    /// tool (the hand's bulk, the wrist) its leaves are twice as large, which the labels do not
    /// need finer: a hand cell matters to them where it lies in front of the tool or beside it.
    /// Without a prediction, where it reaches farther than [`MAX_PREDICTED_SHIFT_M`] or
    /// [`MAX_PREDICTED_AHEAD_S`], or with sliver trimming or blade refinement asked for, the whole
    /// hull is carved at the leaf.
    fn carve_foreground(
        &self,
        carver: &mut Carver,
        views: &[Option<Silhouette>],
        timestamp_ns: i64,
    ) -> Result<(Occupancy, bool), HullError> {
        let adaptive = !self.hull.trim_slivers && self.hull.blade_levels == 0;
        let steady = |t: &&ToolLabeller| {
            t.tracker()
                .prediction_reach(timestamp_ns)
                .is_some_and(|(shift, ahead)| shift <= MAX_PREDICTED_SHIFT_M && ahead <= MAX_PREDICTED_AHEAD_S)
        };
        let coarse = HullParams { leaf_size: 2.0 * self.hull.leaf_size, ..self.hull.clone() };
        // The coarse carving's leaves must be cells of the fine octree (one level up): not so where
        // the box is a leaf or less wide.
        let nested = matches!((self.hull.depth(), coarse.depth()), (Ok(f), Ok(c)) if f == c + 1);
        let Some(tool) = self.tool.as_ref().filter(|t| adaptive && nested && steady(t)) else {
            return Ok((carver.carve(views, &self.hull)?, false));
        };
        let occ = carver.carve(views, &coarse)?;
        match tool.near_predicted(timestamp_ns, &occ, FINE_NEAR_TOOL_M) {
            Some(near) => Ok((refine_cells(views, &self.hull, occ, 1, |k, _| near.get(k) == Some(&true))?, true)),
            None => Ok((carver.carve(views, &self.hull)?, false)),
        }
    }

    /// Pixels around a box's projection that segmentation tests too: the footprint margin of
    /// carving, the clean-up's reach (opening, closing, the neighbour test) and two more.
    fn window_pad(&self) -> f64 {
        let p = self.segmenter.params();
        self.hull.margin_px.ceil() + f64::from(p.open_radius + p.close_radius) + 3.0
    }

    /// Turns on the other views' confirmation of weak foreground: a pixel that the foreground
    /// test calls background but that differs from the background by half of its
    /// tolerances becomes foreground where the hull of the other views' foreground covers it;
    /// foreground to the tool's fit too, but never evidence of its outline.
    /// One more foreground test per view and one more carving, every frame
    /// set: for offline segmentation of a recording whose hand or glove is of the table's or the
    /// backdrop's colour (docs/benchmarks.md, "Weak foreground the other views confirm").
    pub fn confirm_weak_foreground(&mut self, ds: &Dataset) -> Result<(), Error> {
        self.confirm_weak_foreground_when(ds, WeakWhen::Always)
    }

    /// Whether the weak foreground test runs on the next frame set: set up, and always or once
    /// the track is lost.
    fn weak_runs(&self) -> bool {
        self.weak.is_some() && (self.weak_when == WeakWhen::Always || self.lost.since.is_some())
    }

    /// [`Labelling::confirm_weak_foreground`], on every frame set (`WeakWhen::Always`) or from
    /// the frame set after the tool's track was refused in [`LOST_REFUSED`] of the last
    /// [`LOST_WINDOW`] frame sets on (`WeakWhen::TrackLost`; without tool.json, never): the
    /// second test and its carving are paid where the foreground alone loses the tool (a grey
    /// blade over a grey table), not on every recording.
    pub fn confirm_weak_foreground_when(&mut self, ds: &Dataset, when: WeakWhen) -> Result<(), Error> {
        self.weak_when = when;
        let p = self.segmenter.params();
        let weak = SegmentParams {
            brightness_tolerance: p.brightness_tolerance * WEAK_SCALE,
            shadow_tolerance: p.shadow_tolerance * WEAK_SCALE,
            chroma_tolerance: p.chroma_tolerance * WEAK_SCALE,
            chroma_noise: p.chroma_noise * WEAK_SCALE,
            // Every pixel of the scaled test, joined to the foreground or not: the hull confirms.
            weak_share: 1.0,
            ..p.clone()
        };
        self.weak = Some(Segmenter::from_dataset(ds, weak).context("setting up the weak foreground test")?);
        self.weak_region = Some(CarveRegion::new(self.hull.workspace, self.hull.leaf_size));
        Ok(())
    }

    /// Where the other views confirm it, makes weak foreground of `fg` foreground (see
    /// [`Labelling::confirm_weak_foreground`]); counts the pixels.
    ///
    /// One carving with `carve_votes` 2 holds the hull of every view's silhouette but one's: a
    /// cell that view `k` alone refuted (or that no view refuted) lies in the hull of the views
    /// other than `k` ([`hullcut_hull::Cell::refuted_by`]), so each view's weak pixels are
    /// confirmed by the cells with no refuter or with that view as refuter.
    fn fill_weak(&mut self, set: &FrameSet, carver: &mut Carver, fg: &mut [Option<GrayImage>]) -> Result<(), Error> {
        self.weak_confirmed = None;
        self.weak_pixels.iter_mut().for_each(Vec::clear);
        if !self.weak_runs() {
            return Ok(());
        }
        let Some(weak) = &mut self.weak else { return Ok(()) };
        self.weak_confirmed = Some(0);
        let mut loose = std::mem::take(&mut self.loose);
        let tested = weak.segment_frame_set_within(set, &mut loose, &self.windows).context("the weak foreground test");
        let confirmed = tested.and_then(|()| self.confirm(set, carver, fg, &loose));
        self.loose = loose;
        confirmed
    }

    /// [`Labelling::fill_weak`] with the weak test's masks `loose`.
    fn confirm(
        &mut self,
        set: &FrameSet,
        carver: &mut Carver,
        fg: &mut [Option<GrayImage>],
        loose: &[Option<GrayImage>],
    ) -> Result<(), Error> {
        // Weak: foreground to the loose test, background to the foreground test.
        let candidates: Vec<Option<GrayImage>> = fg
            .par_iter()
            .zip(loose.par_iter())
            .map(|(mask, loose)| {
                let (mask, loose) = (mask.as_ref()?, loose.as_ref()?);
                let mut candidates = GrayImage::new(mask.width(), mask.height());
                let mut any = false;
                for ((c, &l), &m) in candidates.iter_mut().zip(loose.iter()).zip(mask.iter()) {
                    if l != label::BACKGROUND && m == label::BACKGROUND {
                        *c = WEAK;
                        any = true;
                    }
                }
                any.then_some(candidates)
            })
            .collect();
        if candidates.iter().all(Option::is_none) {
            return Ok(());
        }
        let refs: Vec<Option<&GrayImage>> = fg.iter().map(Option::as_ref).collect();
        let views = silhouettes(&self.rig, &refs).context("the views' silhouettes")?;
        if views.iter().flatten().count() < 2 {
            // No other view to confirm anything.
            return Ok(());
        }
        // Within the box around the last hull (and within the box the main job's loop carves in).
        let region = self.weak_region.as_mut().map_or(self.hull.workspace, CarveRegion::next_box);
        let Some(workspace) = intersection(&region, &self.hull.workspace) else { return Ok(()) };
        let but_one = HullParams { workspace, carve_votes: 2, blade_levels: 0, ..self.hull.clone() };
        let hull = carver.carve(&views, &but_one).context("the hull of all views but one")?;
        let margin = self.hull.margin_px;
        // Where the track expects the tool in each view: the drawn tool and the band around it.
        let expected: Vec<Option<(ToolRegion, ToolRegion)>> = match &self.tool {
            Some(tool) => self
                .rig
                .cameras
                .iter()
                .map(|c| {
                    let drawn = tool.predicted_region(set.timestamp_ns, c)?;
                    Some((drawn.dilated(WEAK_TOOL_BAND_PX, c.width as usize, c.height as usize), drawn))
                })
                .collect(),
            None => Vec::new(),
        };
        let confirmed: Vec<Option<GrayImage>> = candidates
            .into_par_iter()
            .zip(views.par_iter())
            .enumerate()
            .map(|(k, (candidates, view))| {
                let (mut candidates, view) = (candidates?, view.as_ref()?);
                let others = |i: usize| hull.cells[i].refuted_by.is_none_or(|r| usize::from(r) == k);
                cover_split(&hull, view, &mut candidates, WEAK, margin, others, [label::UNKNOWN, COVERED]);
                if let Some((band, drawn)) = expected.get(k).and_then(Option::as_ref) {
                    let w = candidates.width() as usize;
                    for y in band.y0..band.y0 + band.height {
                        for x in band.x0..band.x0 + band.width {
                            let p = &mut candidates.as_mut()[y * w + x];
                            if *p == label::UNKNOWN && band.covers(x, y) && !drawn.covers(x, y) {
                                *p = label::BACKGROUND;
                            }
                        }
                    }
                }
                Some(candidates)
            })
            .collect();
        self.weak_pixels.resize_with(fg.len(), Vec::new);
        for ((mask, confirmed), pixels) in fg.iter_mut().zip(&confirmed).zip(&mut self.weak_pixels) {
            if let (Some(mask), Some(confirmed)) = (mask, confirmed) {
                let mut n = 0;
                for (i, (p, _)) in
                    mask.iter_mut().zip(confirmed.iter()).enumerate().filter(|(_, (_, c))| **c == label::UNKNOWN)
                {
                    *p = label::UNKNOWN;
                    pixels.push(i);
                    n += 1;
                }
                self.counters.weak_confirmed += n;
                self.weak_confirmed = self.weak_confirmed.map(|w| w + n);
            }
        }
        Ok(())
    }

    /// The foreground settings in use.
    pub fn params(&self) -> &SegmentParams {
        self.segmenter.params()
    }

    /// Labels one frame set, its label masks drawn (at once, whatever
    /// [`Labelling::defer_drawing`] says).
    pub fn label(&mut self, set: &FrameSet, carver: &mut Carver) -> Result<Labelled, Error> {
        let defer = std::mem::replace(&mut self.defer, false);
        let labelled = self.label_with(set, carver, true);
        self.defer = defer;
        labelled
    }

    /// Labels one frame set; without `masks_wanted`, a frame set the tool's fit labels (trusted
    /// or not) gets no label masks (`None` for every view) unless its untrusted fit may teach the
    /// colours (one that agrees with the silhouettes while no trusted one has taught them): its
    /// hull and pose are the same either way, and so is every frame set after it (the masks of a
    /// frame set that does not teach feed nothing that follows; a trusted one that teaches, at
    /// most every fifteenth frame set, hands its lesson to a thread of its own, which draws them
    /// there: [`crate::lesson`]). With `masks_wanted` and [`Labelling::defer_drawing`], such a
    /// frame set's masks are handed out to be drawn later ([`Labelled::pending`]). A frame set the
    /// learned colours label gets its masks either way.
    pub fn label_with(&mut self, set: &FrameSet, carver: &mut Carver, masks_wanted: bool) -> Result<Labelled, Error> {
        let frame = set.frame;
        let clock = Instant::now();
        self.taught = None;
        self.lesson_ms = None;
        self.take_due_lesson(false)?;
        let mut fg = std::mem::take(&mut self.masks);
        let tested = self
            .segmenter
            .segment_frame_set_stretches(set, &mut fg, &self.windows, &self.stretches)
            .with_context(|| format!("segmenting frame {frame}"))?;
        let near_hull = self.stretches.iter().any(Option::is_some);
        let reached = tested.iter().any(|t| t.reached_past);
        self.segmented = Segmented {
            near_hull,
            pixels: tested.iter().map(|t| t.pixels).sum(),
            weak_joined: tested.iter().map(|t| t.joined).sum(),
            holes_filled: tested.iter().map(|t| t.filled).sum(),
        };
        self.counters.segmented_near_hull += u64::from(near_hull);
        self.counters.reached_past_hull += u64::from(near_hull && reached);
        self.counters.pixels_tested += self.segmented.pixels;
        self.counters.weak_joined += self.segmented.weak_joined;
        self.counters.holes_filled += self.segmented.holes_filled;
        // Set again once this frame set's hull is carved.
        self.last_blocks = None;
        self.fill_weak(set, carver, &mut fg).with_context(|| format!("confirming weak foreground in frame {frame}"))?;
        let foreground_ms = clock.elapsed().as_secs_f64() * 1e3;
        // Outside its window a view's mask is background: the passes over masks below look inside.
        let windows: Vec<Window> = set
            .views
            .iter()
            .enumerate()
            .map(|(k, v)| {
                v.as_ref().map_or(Window::whole(0, 0), |v| {
                    let (w, h) = v.image.dimensions();
                    Window::of_view(&self.windows, k, w, h)
                })
            })
            .collect();
        // One pass over each mask: its foreground and possible shadow pixels.
        let counts: Vec<Option<MaskCounts>> =
            fg.par_iter().zip(&windows).map(|(m, &win)| m.as_ref().map(|m| MaskCounts::within(m, win))).collect();
        let shadow_pixels: u64 = counts.iter().flatten().map(|c| c.shadow).sum();
        self.counters.shadow_pixels += shadow_pixels;
        let degraded = self.degraded_views(&counts);
        self.counters.degraded_views += degraded.iter().filter(|&&d| d).count() as u64;
        if self.tool.is_none() && shadow_pixels == 0 && !degraded.contains(&true) {
            // No tool: the colours learned from the masked frames.
            let mut masks = fg.clone();
            self.colour(set, &mut masks);
            self.counters.colour += 1;
            self.masks = fg;
            return Ok(Labelled {
                masks,
                occupancy: None,
                estimate: None,
                source: LabelSource::Colour,
                foreground_ms,
                carve_ms: 0.0,
                stats: None,
                drawn: false,
                pending: None,
                lesson_ms: self.lesson_ms,
            });
        }
        // The fit's hints (the learned colours', the possible shadows) are taken before possible
        // shadows become foreground or background.
        let sure = self.sure.as_deref().filter(|_| self.method == LabelMethod::Both);
        let hand_hints = self.hand_hints();
        // The weak foreground the other views confirmed is foreground to the fit, never evidence of
        // the tool's outline (as a shadow on the table, [`TABLE_SHADOW`]): the fat hull near the
        // blade confirms the blade's blended edge and the soft rim of its shadow beside it.
        let weak_hints = self.weak_pixels.iter().any(|p| !p.is_empty());
        // Window by window, in buffers kept from frame set to frame set.
        let mut hints = std::mem::take(&mut self.hints);
        let hinting = self.tool.is_some() && (sure.is_some() || shadow_pixels > 0 || weak_hints);
        if hinting {
            hints.resize_with(fg.len(), Vec::new);
            hints.par_iter_mut().zip(fg.par_iter()).zip(set.views.par_iter()).zip(windows.par_iter()).for_each(
                |(((out, m), view), &win)| match (m, view) {
                    (Some(m), Some(view)) => fit_hints(sure, hand_hints, &view.image, m, win, out),
                    _ => out.clear(),
                },
            );
        }
        let clock = Instant::now();
        let refs: Vec<Option<&GrayImage>> = fg.iter().map(Option::as_ref).collect();
        let views = silhouettes(&self.rig, &refs).with_context(|| format!("frame {frame}"))?;
        let (mut occ, near_tool) =
            self.carve_foreground(carver, &views, set.timestamp_ns).with_context(|| format!("frame {frame}"))?;
        self.counters.hull_fine_near_tool += u64::from(near_tool);
        let mut marked_only = Vec::new();
        // The possible shadows as the views saw them, before the hull resolved them: where a ray
        // meets the table, the other views tell a shadow from a dull tool ([`TableShadows`]).
        let table_shadows = shadow_pixels > 0 && self.tool.is_some() && self.rig.world_frame.is_table();
        if table_shadows {
            copy_masks(&fg, &windows, &mut self.unresolved, &mut self.unresolved_rows);
        }
        let mut given_back: Vec<Vec<usize>> = Vec::new();
        self.shadow_on_table = None;
        if shadow_pixels > 0 {
            let resolved = self
                .resolve_shadows(occ, &views, &mut fg, set, table_shadows)
                .with_context(|| format!("frame {frame}"))?;
            (occ, marked_only, given_back) = (resolved.occupancy, resolved.marked_only, resolved.given_back);
            self.shadow_on_table = table_shadows.then(|| given_back.iter().map(|b| b.len() as u64).sum());
        }
        if let Some(region) = &mut self.weak_region {
            region.update(&self.hull.workspace, &occ);
        }
        self.last_blocks = (!reached).then(|| crate::region::blocks(&occ, BLOCK_M)).filter(|b| !b.is_empty());
        for ((view, mask), _) in views.iter().zip(fg.iter_mut()).zip(&degraded).filter(|(_, d)| **d) {
            if let (Some(view), Some(mask)) = (view, mask) {
                // What the hull does not explain in this view is not in the working volume.
                cover(&occ, view, mask, label::UNKNOWN, EXPLAINED, self.hull.margin_px);
                mask.iter_mut().filter(|p| **p == EXPLAINED).for_each(|p| *p = label::UNKNOWN);
            }
        }
        let carve_ms = clock.elapsed().as_secs_f64() * 1e3;
        if self.tool.is_none() {
            let mut masks = fg.clone();
            self.colour(set, &mut masks);
            self.counters.colour += 1;
            self.masks = fg;
            return Ok(Labelled {
                masks,
                occupancy: None,
                estimate: None,
                source: LabelSource::Colour,
                foreground_ms,
                carve_ms,
                stats: None,
                drawn: false,
                pending: None,
                lesson_ms: self.lesson_ms,
            });
        }
        // The hints for the tool's fit, on the foreground as the hull left it. The shadows the other
        // views put on the table stay foreground to the fit where the track expects the tool, a
        // pixel inside its drawn outline (a dull blade over the hand's shadow near the table is as
        // dark as the shadow behind it), but never evidence of it ([`TABLE_SHADOW`]); elsewhere
        // they are background, which keeps a thin blade from rolling into them.
        let expected: Vec<Option<ToolRegion>> = match &self.tool {
            Some(tool) if given_back.iter().any(|b| !b.is_empty()) => self
                .rig
                .cameras
                .par_iter()
                .map(|camera| tool.predicted_region(set.timestamp_ns, camera).map(|r| r.eroded(1)))
                .collect(),
            _ => Vec::new(),
        };
        // The hinted masks, in buffers kept from frame set to frame set.
        let mut hinted_store = std::mem::take(&mut self.hinted);
        let mut hinted_rows = std::mem::take(&mut self.hinted_rows);
        let hinted: Option<&[Option<GrayImage>]> = hinting.then(|| {
            hinted_store.resize(fg.len(), None);
            hinted_rows.resize(fg.len(), Rows::NONE);
            let outs = hinted_store.par_iter_mut().zip(hinted_rows.par_iter_mut());
            outs.zip(fg.par_iter()).zip(hints.par_iter()).enumerate().for_each(|(k, (((out, held), m), hint))| {
                let Some(m) = m else {
                    *out = None;
                    return;
                };
                let m = copy_within(m, out, windows[k], held);
                let (w, h) = m.dimensions();
                apply_hints(m, windows[k].clipped(w, h), hint);
                if weak_hints {
                    for &i in self.weak_pixels.get(k).into_iter().flatten() {
                        if m.as_raw()[i] != label::BACKGROUND {
                            m.as_mut()[i] = TABLE_SHADOW;
                        }
                    }
                }
                if let Some(region) = expected.get(k).and_then(Option::as_ref) {
                    let w = m.width() as usize;
                    for &i in given_back.get(k).into_iter().flatten().filter(|&&i| region.covers(i % w, i / w)) {
                        m.as_mut()[i] = TABLE_SHADOW;
                    }
                }
            });
            &hinted_store[..]
        });
        let inputs: Vec<Option<ViewInput>> = self
            .rig
            .cameras
            .iter()
            .zip(hinted.unwrap_or(&fg))
            .zip(&set.views)
            .map(|((camera, m), v)| {
                m.as_ref().map(|mask| ViewInput { camera, mask, image: v.as_ref().map(|v| &v.image) })
            })
            .collect();
        let bootstrapping = self.bootstrapping();
        let colours = self.method == LabelMethod::Both;
        self.since_learned = self.since_learned.saturating_add(1);
        self.since_refused = self.since_refused.map(|n| n.saturating_add(1));
        let learn_due = colours
            && (self.counters.learned == 0 || u64::from(self.since_learned) >= LEARN_EVERY)
            && self.since_refused.is_none_or(|n| u64::from(n) >= LEARN_EVERY)
            && self.lesson.is_none();
        self.since_compiled = self.since_compiled.saturating_add(1);
        let Some(labeller) = &mut self.tool else { fail!("no tool to label frame {frame} with") };
        let table = table_shadows.then(|| table_shadows_of(&self.rig, &self.unresolved, set, &self.segmenter));
        // Only a frame set after an agreeing one may teach ([`BOOTSTRAP_STEP_M`]): the unoccluded
        // pixels cost a splat per view, and a recording never trusted would pay it every frame set.
        labeller.list_unoccluded(bootstrapping && self.last_agreeing.is_some());
        // The masks are drawn where an untrusted fit may teach (the colours label the other
        // untrusted frame sets, or nothing does), and where they are wanted, unless they are
        // left to be drawn later. A trusted frame set's lesson draws them where they are not.
        let teach = bootstrapping && self.last_agreeing.is_some();
        let defer = masks_wanted && self.defer && !teach;
        let draw = teach || masks_wanted && !defer;
        labeller.draw_labels(draw);
        let mut labelled = labeller.label(frame, set.timestamp_ns, &occ, &marked_only, &inputs, table.as_ref());
        let drawer = (defer || learn_due).then(|| labeller.drawer());
        drop(inputs);
        (self.hints, self.hinted, self.hinted_rows) = (hints, hinted_store, hinted_rows);
        self.counters.searches += u64::from(labelled.stats.from_thin_parts);
        self.counters.searches_paused += u64::from(labelled.stats.search_paused);
        let drawn = draw && labelled.estimate.fitted.is_some();
        self.drawn += u64::from(drawn);
        // The shadows given back to the table are background, unless the tool is drawn there;
        // neither the labels handed out nor the colours learned take them for the hand.
        to_background(&mut labelled.masks, &given_back, true);
        let estimate = labelled.estimate;
        let trusted = estimate.valid && estimate.fitted.is_some();
        if self.weak.is_some() && self.weak_when == WeakWhen::TrackLost {
            self.lost.record(frame, trusted);
        }
        let few_views = set.views.iter().flatten().count() < MANY_VIEWS;
        let learns =
            learn_due && trusted && (estimate.confidence >= LEARN_CONFIDENCE || (few_views && !self.taught_by_trust()));
        let agreement = estimate.diagnostics.explained.min(estimate.diagnostics.covered);
        // An untrusted fit that agrees with the silhouettes, and whether the one of the frame set
        // before agreed too, at nearly the same pose.
        let agreeing = estimate.fitted.as_ref().filter(|_| !trusted && agreement >= GEOMETRY_AGREEMENT.1);
        let steady = match (agreeing, &self.last_agreeing) {
            (Some(f), Some((tip, normal))) => {
                (f.tip - tip).norm() <= BOOTSTRAP_STEP_M
                    && f.plane_normal.angle(normal) <= BOOTSTRAP_TURN_DEG.to_radians()
            }
            _ => false,
        };
        self.last_agreeing = agreeing.map(|f| (f.tip, f.plane_normal));
        let taught = (bootstrapping
            && steady
            && labelled.unoccluded.iter().map(Vec::len).sum::<usize>() >= BOOTSTRAP_MIN_PIXELS)
            .then(|| bootstrap_labels(&labelled.masks, &labelled.tool_regions, &labelled.unoccluded));
        let mut drawn_lesson = None;
        let mut sharpen_later = None;
        let (mut masks, source) = if trusted {
            // The labels drawn at once teach as drawn, before any colour sharpened them.
            drawn_lesson = (learns && drawn).then(|| LessonLabels::Drawn {
                masks: labelled.masks.clone(),
                tool_regions: labelled.tool_regions.clone(),
            });
            let mut masks = labelled.masks;
            if let Some(lut) = self.explained.as_deref().filter(|_| colours) {
                sharpen_views(lut, &images_of(set), &mut masks, &labelled.tool_regions);
            }
            sharpen_later = self.explained.clone().filter(|_| colours);
            (masks, LabelSource::Geometry)
        } else if colours && self.colours_label() {
            let mut masks = fg.clone();
            self.colour(set, &mut masks);
            to_background(&mut masks, &given_back, false);
            (masks, LabelSource::Colour)
        } else if estimate.fitted.is_some() {
            (labelled.masks, LabelSource::UntrustedGeometry)
        } else {
            (labelled.masks, LabelSource::Unknown)
        };
        match source {
            LabelSource::Geometry => self.counters.geometry += 1,
            LabelSource::Colour => self.counters.colour += 1,
            LabelSource::UntrustedGeometry => self.counters.untrusted += 1,
            LabelSource::Unknown => self.counters.unknown += 1,
        }
        if let (true, Some(fitted)) = (learns, &estimate.fitted) {
            // Only a trusted fit's labels teach, beside the labelling: drawn here or there.
            let labels = match (drawn_lesson, &drawer) {
                (Some(drawn), _) => drawn,
                (None, Some(drawer)) => LessonLabels::ToDraw {
                    pending: Box::new(PendingLabels {
                        drawer: drawer.clone(),
                        rig: Arc::clone(&self.rig),
                        pose: fitted.tool_to_world,
                        masks: if hinting { self.hinted.clone() } else { fg.clone() },
                        given_back: given_back.clone(),
                        sharpen: None,
                    }),
                    occupancy: labelled.occupancy.clone(),
                },
                (None, None) => {
                    fail!("frame {frame}: a trusted fit to learn the colours from, neither drawn nor to draw")
                }
            };
            self.start_lesson(set, labels, &fitted.tool_to_world)?;
            if !self.beside {
                // Taken at once: the next frame set labels by what this one taught.
                self.take_due_lesson(true)?;
            }
        } else if let Some(taught) = taught {
            // Or, until one has, what an agreeing fit alone decides.
            let outline = self.blade_regions(&taught, estimate.fitted.as_ref());
            self.bootstrap(set, &taught, &outline);
        }
        // Left to be drawn later: the foreground the fit saw (its hints in, as `inputs` had it).
        let pending = match (drawer.filter(|_| defer), &estimate.fitted, source) {
            (Some(drawer), Some(fitted), LabelSource::Geometry | LabelSource::UntrustedGeometry) => {
                self.deferred += 1;
                Some(PendingLabels {
                    drawer,
                    rig: Arc::clone(&self.rig),
                    pose: fitted.tool_to_world,
                    masks: if hinting { self.hinted.clone() } else { fg.clone() },
                    given_back,
                    sharpen: sharpen_later,
                })
            }
            _ => None,
        };
        // The colour-labelled masks need their own hull; the geometric ones come with theirs.
        let occupancy = (source != LabelSource::Colour).then_some(labelled.occupancy);
        masks.resize(set.views.len(), None);
        self.masks = fg;
        Ok(Labelled {
            masks,
            occupancy,
            estimate: Some(estimate),
            source,
            foreground_ms,
            carve_ms,
            stats: Some(labelled.stats),
            drawn,
            pending,
            lesson_ms: self.lesson_ms,
        })
    }

    /// Searches the foreground's hull for a lost tool on one frame set in at most `gap` while the
    /// searches before found no trusted fit (1: on every frame set;
    /// [`hullcut_pose::LabelParams::max_search_gap`]). Without tool.json, nothing changes.
    pub fn set_search_gap(&mut self, gap: u32) {
        if let Some(tool) = &mut self.tool {
            tool.set_max_search_gap(gap);
        }
    }

    /// Whether the label masks of a frame set the tool's fit labels are left to be drawn later
    /// when they are wanted only to be shown (off by default): [`Labelling::label_with`] then
    /// hands them out as [`Labelled::pending`], which draws the same masks, on any thread. A
    /// frame set whose untrusted fit may teach the colours is drawn at once (the colours learn
    /// from its masks).
    pub fn defer_drawing(&mut self, on: bool) {
        self.defer = on;
    }

    /// Whether a trusted frame set's colours are learned beside the labelling and taken
    /// [`LESSON_DELAY`] frame sets later, for a loop that should not wait for them (the main
    /// job's: [`crate::lesson`]), or waited for before its labelling returns (off by default:
    /// the commands that label a recording offline, whose next frame set then labels by them).
    /// The lesson runs on its own thread either way; its results do not depend on the threads'
    /// timing.
    pub fn learn_beside(&mut self, on: bool) {
        self.beside = on;
    }

    /// Labels `set` again by the learned colours alone (`None` while none are learned, and with
    /// any method but [`LabelMethod::Both`]), for a frame set that the tool could not label with
    /// trust before later frames taught the colours.
    /// The counters count it as `relabelled`, nothing else.
    pub fn relabel_by_colour(&mut self, set: &FrameSet, carver: &mut Carver) -> Result<Option<Labelled>, Error> {
        if self.method != LabelMethod::Both || !self.colours_label() {
            return Ok(None);
        }
        // Without the tool, and with no history of usual foregrounds (this frame set is an old
        // one: the views' usual has moved on since).
        let (tool, counters, history) = (self.tool.take(), self.counters.clone(), std::mem::take(&mut self.history));
        let labelled = self.label(set, carver);
        (self.tool, self.history) = (tool, history);
        self.counters = LabelCounters { relabelled: counters.relabelled + 1, ..counters };
        labelled.map(Some)
    }

    /// Which views' foreground jumped far above its usual ([`DEGRADED_JUMP`] times the median of
    /// the view's last [`DEGRADED_HISTORY`] frame sets, that median taken as at least
    /// [`DEGRADED_MIN_FRACTION`] of the image): someone walking behind the table, a light switched
    /// on. A degraded frame set does not count towards the usual, until the change has lasted
    /// half the history: then it is the scene's new usual (a person who stays, a light left on).
    fn degraded_views(&mut self, counts: &[Option<MaskCounts>]) -> Vec<bool> {
        self.history.resize_with(counts.len(), std::collections::VecDeque::new);
        counts
            .iter()
            .zip(&mut self.history)
            .map(|(counts, history)| {
                let Some(MaskCounts { foreground: count, pixels, .. }) = *counts else { return false };
                let floor = DEGRADED_MIN_FRACTION * pixels as f64;
                let mut usual: Vec<usize> = history.iter().map(|&(c, _)| c).collect();
                usual.sort_unstable();
                let degraded = usual.len() >= DEGRADED_HISTORY / 2
                    && count as f64 > DEGRADED_JUMP * (usual[usual.len() / 2] as f64).max(floor);
                // A change that lasts half the history is the scene's new usual.
                let run = history.back().map_or(0, |&(_, r)| r);
                if degraded && run + 1 >= DEGRADED_HISTORY / 2 {
                    history.clear();
                    history.push_back((count, 0));
                    return false;
                }
                if history.len() == DEGRADED_HISTORY {
                    history.pop_front();
                }
                // Degraded counts stay out of the usual (kept with the run they extend).
                let usual_count = if degraded { history.back().map_or(count, |&(c, _)| c) } else { count };
                history.push_back((usual_count, if degraded { run + 1 } else { 0 }));
                degraded
            })
            .collect()
    }

    /// Keeps the hull's cells some view sees as sure foreground, and makes the views' possible
    /// shadows foreground where those cells cover them, background elsewhere; the cells near the
    /// tool where its track predicts it at `set`'s time are kept as objects. With `on_table`
    /// (`unresolved` holds this frame set's masks as the segmenter gave them), a possible shadow
    /// that a cell less than [`SHADOW_HULL_HEIGHT`] above the table covers is asked of the
    /// other views ([`TableShadows`]): where they see the table behind it darkened as much, it
    /// goes back to the background, and the low cells no longer seen in that view go too (the
    /// hand's hull over its own shadow near the table: kept, it hid the blade from the fit as
    /// the hand's, and its pixels beside the blade became the tool's). Returns the kept cells,
    /// which of them only that prediction kept (the tool's, or its shadow beside it: never the
    /// hand), and the pixels given back to the background.
    fn resolve_shadows(
        &mut self,
        occ: Occupancy,
        views: &[Option<Silhouette>],
        fg: &mut [Option<GrayImage>],
        set: &FrameSet,
        on_table: bool,
    ) -> Result<Resolved, Error> {
        // The views in parallel, each pixel without a branch (a filtered loop over six whole
        // masks, one view after the other, took some 0.5 ms a frame set on the built-in scene).
        let sure: Vec<Option<GrayImage>> = fg
            .par_iter()
            .map(|m| {
                m.as_ref().and_then(|m| {
                    let raw =
                        m.as_raw().iter().map(|&p| if p == SHADOW_LIKE { label::BACKGROUND } else { p }).collect();
                    GrayImage::from_raw(m.width(), m.height(), raw)
                })
            })
            .collect();
        // Few cells are judged on the sure foreground (most settle on their height or the first
        // views): its masks are counted pixel by pixel, not tabled.
        let sure = direct_silhouettes(&self.rig, sure).context("the sure foreground's silhouettes")?;
        // Where the tool's track predicts it, the hull is the tool's: a dull blade's tip over a table
        // of its shade looks like a shadow to most views.
        let tool = self.tool.as_ref().and_then(|t| t.near_predicted(set.timestamp_ns, &occ, TOOL_OBJECT_MARGIN));
        let kept = keep_supported(
            &occ,
            views,
            &sure,
            self.hull.margin_px,
            self.rig.world_frame.is_table(),
            tool.as_deref().unwrap_or_default(),
        );
        let mut occ = kept.occupancy;
        let mut marked_only = kept.marked_only;
        self.counters.shadow_cells_dropped += kept.dropped as u64;
        self.counters.shadow_cells_seen_through += kept.seen_through as u64;
        let margin = self.hull.margin_px;
        if !on_table {
            self.counters.shadow_foreground += views
                .par_iter()
                .zip(fg.par_iter_mut())
                .map(|(view, mask)| match (view, mask) {
                    (Some(view), Some(mask)) => cover(&occ, view, mask, SHADOW_LIKE, label::UNKNOWN, margin),
                    _ => 0,
                })
                .sum::<u64>();
            return Ok(Resolved { occupancy: occ, marked_only, given_back: Vec::new() });
        }
        // A possible shadow that a cell low over the table covers is asked, even where a cell above
        // covers it too (the footprint of a fingertip's cell reaches the shadow beside it).
        let low = |k: usize| occ.cells[k].min.z <= SHADOW_HULL_HEIGHT;
        let covered: Vec<[u64; 2]> = views
            .par_iter()
            .zip(fg.par_iter_mut())
            .map(|(view, mask)| match (view, mask) {
                (Some(view), Some(mask)) => {
                    let covered = cover_split(&occ, view, mask, SHADOW_LIKE, margin, low, [ASK_TABLE, COVERED]);
                    if covered[1] > 0 {
                        mask.iter_mut().filter(|p| **p == COVERED).for_each(|p| *p = label::UNKNOWN);
                    }
                    covered
                }
                _ => [0, 0],
            })
            .collect();
        self.counters.shadow_foreground += covered.iter().map(|c| c[0] + c[1]).sum::<u64>();
        if !covered.iter().any(|c| c[0] > 0) {
            return Ok(Resolved { occupancy: occ, marked_only, given_back: Vec::new() });
        }
        let table = table_shadows_of(&self.rig, &self.unresolved, set, &self.segmenter);
        let back = shadows_to_table(&table, fg);
        self.counters.shadow_on_table += back.iter().map(|b| b.len() as u64).sum::<u64>();
        let changed: Vec<Option<&GrayImage>> =
            fg.iter().zip(&back).map(|(m, b)| m.as_ref().filter(|_| !b.is_empty())).collect();
        if back.iter().any(|b| !b.is_empty()) {
            let seen = still_seen(&occ, views, &changed, margin);
            let marks = marked_only.iter().copied().chain(std::iter::repeat(false));
            (occ.cells, marked_only) =
                occ.cells.iter().zip(marks).zip(&seen).filter(|(_, seen)| **seen).map(|((c, m), _)| (*c, m)).unzip();
        }
        Ok(Resolved { occupancy: occ, marked_only, given_back: back })
    }

    /// Labels the foreground of `masks` by colour (unknown where no colours are learned yet).
    fn colour(&self, set: &FrameSet, masks: &mut [Option<GrayImage>]) {
        let Some(lut) = &self.colours else { return };
        for (view, mask) in set.views.iter().zip(masks) {
            if let (Some(view), Some(mask)) = (view, mask) {
                lut.label_foreground(&view.image, mask);
            }
        }
    }

    /// Learns a trusted frame set's colours: those that label and hint from `likelier` (its labels
    /// sharpened wherever a colour is surely the likelier), the sharpening colours from
    /// `handed_out` (the labels handed out); recompiles the classes now and then.
    ///
    /// Two models, because one failed either way. Learned from the likelier colours' labels
    /// alone, a shadow kept beside the blade (dark green on a green mat, of neither class) went
    /// to the broader class, the tool's, was learned as the tool and then sharpened to it
    /// (random:89 in random:131: scalpel IoU 0.758). Learned from the labels handed out alone,
    /// the hints those colours gave lost random:59 in random:101's track from frame set 93 to 120
    /// (129 -> 104 of 150 frame sets trusted), and the frame sets labelled by colour alone lost
    /// (random:97 in random:137, where the fit is trusted in 34 of 150: scalpel 0.588 -> 0.458).
    fn learn(
        &mut self,
        set: &FrameSet,
        likelier: &[Option<GrayImage>],
        handed_out: &[Option<GrayImage>],
        blade: &[Vec<usize>],
    ) {
        // What was learned is forgotten by the frame sets passed since ([`LEARN_EVERY`]); the
        // labels are background outside each view's window.
        let passed = std::mem::take(&mut self.since_learned);
        let images = images_of(set);
        let models = (&mut self.appearance, &mut self.sharpening);
        learn_models(models, &images, &self.windows, (likelier, handed_out), blade, passed);
        self.counters.learned += 1;
        let (refresh, colours, explained) = self.compiling(self.counters.learned == 1);
        if refresh {
            self.since_compiled = 0;
        }
        if colours {
            (self.colours, self.sure) = compile(self.appearance.classes());
        }
        if explained {
            self.explained = compile_explained(self.sharpening.classes()).map(Arc::new);
        }
    }

    /// Whether the colours learned next are compiled again: both models now and then
    /// ([`REFRESH_EVERY`]), and each while it has none compiled (one not learned yet, no class,
    /// does not make the other compile every frame set); the colours that label and hint, and
    /// the sharpening colours; `first` where the colours learn for the first time.
    fn compiling(&self, first: bool) -> (bool, bool, bool) {
        let refresh = first || self.since_compiled >= REFRESH_EVERY;
        (refresh, refresh || self.colours.is_none(), refresh || self.explained.is_none())
    }

    /// Per view of `masks`, the indices of the pixels inside the blade's outline with the tool at
    /// `fitted` (ascending; none without a tool, a fit or a mask).
    fn blade_regions(&self, masks: &[Option<GrayImage>], fitted: Option<&hullcut_pose::BladePose>) -> Vec<Vec<usize>> {
        let (Some(labeller), Some(fitted)) = (&self.tool, fitted) else { return Vec::new() };
        self.rig
            .cameras
            .par_iter()
            .zip(masks.par_iter())
            .map(|(camera, mask)| {
                mask.as_ref().map_or_else(Vec::new, |m| {
                    inside_outline(m.width(), m.height(), &labeller.blade_outline(camera, &fitted.tool_to_world))
                })
            })
            .collect()
    }

    /// Tallies a learned frame set's drawn blade: its `pixels` (its scalpel pixels within the
    /// blade's outline, taken before any colour sharpened the labels) and those of them the sure
    /// colours, as just learned, call the `hand`'s. What was tallied before is kept as for the
    /// `passed` frame sets since it was.
    fn tally_blade(&mut self, (pixels, hand): (u64, u64), passed: u32) {
        let (b, h) = self.tool_as_hand;
        let keep = TOOL_AS_HAND_KEEP.powi(passed.clamp(1, i32::MAX as u32) as i32);
        self.tool_as_hand = (b * keep + pixels as f64, h * keep + hand as f64);
        self.counters.tool_as_hand = self.tool_as_hand_share();
        self.counters.hand_hints = self.hand_hints();
    }

    /// The last labelled frame set's weak foreground pixels that the other views' hull confirmed,
    /// over its views (`None` without [`Labelling::confirm_weak_foreground`]).
    pub fn weak_confirmed(&self) -> Option<u64> {
        self.weak_confirmed
    }

    /// The pixels the last labelled frame set's untrusted fit taught the colours, over its views,
    /// where it agreed with the silhouettes and taught them (before any trusted fit did; `None`
    /// where it taught nothing).
    pub fn taught(&self) -> Option<u64> {
        self.taught
    }

    /// What labelled `labelled`, the frame set this labelling labelled last, and the colours
    /// learned by then.
    pub fn trace(&self, labelled: &Labelled) -> LabelTrace {
        LabelTrace {
            source: labelled.source,
            learned: self.learned(),
            blade_as_hand: self.blade_as_hand(),
            shadow_on_table: self.shadow_on_table(),
            weak_confirmed: self.weak_confirmed(),
            taught: self.taught(),
            segmented: self.segmented(),
            hull_search: labelled.hull_search(),
            lesson_ms: labelled.lesson_ms,
        }
    }

    /// What the last labelled frame set's segmentation tested: whether only near the last hull,
    /// and the pixels.
    pub fn segmented(&self) -> Segmented {
        self.segmented
    }

    /// The last labelled frame set's possible shadows given back to the table as the other views
    /// saw them, over its views (`None` where none were asked: no possible shadows, no tool, or a
    /// world frame that is not a table).
    pub fn shadow_on_table(&self) -> Option<u64> {
        self.shadow_on_table
    }

    /// The share of the drawn blade the sure colours call the hand's, on the frame sets learned
    /// from (recent ones weighing more); `None` before any blade pixel was drawn on one. Above 0.1
    /// the fit gets no hand hints.
    pub fn blade_as_hand(&self) -> Option<f64> {
        (self.tool_as_hand.0 > 0.0).then(|| self.tool_as_hand_share())
    }

    /// The share of the drawn blade the sure colours call the hand's (0 before any was drawn).
    fn tool_as_hand_share(&self) -> f64 {
        let (tool, hand) = self.tool_as_hand;
        if tool > 0.0 { hand / tool } else { 0.0 }
    }

    /// Whether the colours were taught by a trusted frame set or by masked frames (not only by
    /// untrusted fits that agreed with the silhouettes, or not at all).
    fn taught_by_trust(&self) -> bool {
        self.counters.learned > self.counters.bootstrapped || self.appearance.sources.mask_views > 0
    }

    /// Whether an untrusted fit that agrees with the silhouettes may teach the colours
    /// ([`BOOTSTRAP_FRAMES`]): with colours to learn, none seeded by masked frames, no trusted
    /// frame set learned from yet, and fewer than that many taught so.
    fn bootstrapping(&self) -> bool {
        self.method == LabelMethod::Both
            && self.appearance.sources.mask_views == 0
            && self.counters.learned == self.counters.bootstrapped
            && self.counters.bootstrapped < BOOTSTRAP_FRAMES
            && self.lesson.is_none()
    }

    /// Learns `taught` (what an untrusted fit alone decides: [`bootstrap_labels`]) as the colours,
    /// unless the hand's class then learned explains the tool's colour ([`tool_apart_from_hand`]):
    /// a hand and a tool of one colour (a blue glove holding a blue handle) teach nothing the fit
    /// could use, and their hints moved the fits (random:257 in random:263's hand IoU 0.959 ->
    /// 0.925, scalpel 0.373 -> 0.099; squared distance of the tool's mean from the hand 1.26 on its
    /// first such frame set, random:71 in random:109's 1.09): then the colours stay as they were.
    fn bootstrap(&mut self, set: &FrameSet, taught: &[Option<GrayImage>], blade: &[Vec<usize>]) {
        let before = self.colour_state();
        self.learn(set, taught, taught, blade);
        if tool_apart_from_hand(self.appearance.classes().as_ref()) {
            self.counters.bootstrapped += 1;
            let labelled = |m: &Option<GrayImage>| m.as_ref().map_or(0, |m| m.iter().filter(|&&l| l != 0).count());
            self.taught = Some(taught.iter().map(labelled).sum::<usize>() as u64);
        } else {
            self.roll_back(before);
            self.counters.bootstrap_refused += 1;
        }
    }

    /// Takes what a trusted frame set's lesson taught ([`crate::lesson`]), `since` frame sets
    /// after it (those labelled in between left out), unless, both labels learned, the tool's
    /// classes then have the hand's colours ([`tool_taught_the_hand`]): a fit laid over the hand,
    /// trusted all the same, teaches the tool the hand's colours, and from then on the colours
    /// call the hand the tool. Then the colours stay as they were, no trusted frame set teaches
    /// them for [`LEARN_EVERY`] frame sets from the one refused (counted as `learn_refused`). On
    /// random:1523 in random:1531 two such fits (34° and 84° off) were the first trusted and
    /// taught the glove's blue as the blade's: 2 frame sets of 150 trusted instead of 49 (53 with
    /// the rule). On random:1993 in random:1953 (a bare hand, every trusted fit off) the colours
    /// so learned took the hand's pooled IoU from 0.94 to 0.61.
    fn take_lesson(&mut self, lesson: &InFlight, learned: Learned, since: u32) {
        self.lesson_ms = Some(learned.ms);
        if learned.refused {
            self.counters.learn_refused += 1;
            self.since_refused = Some(since);
            return;
        }
        self.appearance = learned.appearance;
        self.sharpening = learned.sharpening;
        self.counters.learned += 1;
        self.since_learned = since;
        if lesson.refresh {
            self.since_compiled = since;
        }
        if let Some((colours, sure)) = learned.colours {
            (self.colours, self.sure) = (colours, sure);
        }
        if let Some(explained) = learned.explained {
            self.explained = explained;
        }
        if let Some(blade) = learned.blade {
            self.tally_blade(blade, lesson.passed);
        }
    }

    /// Takes the lesson in flight when it is due ([`LESSON_DELAY`]), at the start of a frame
    /// set's labelling, or now with `now`.
    fn take_due_lesson(&mut self, now: bool) -> Result<(), Error> {
        let Some(lesson) = self.lesson.as_mut() else { return Ok(()) };
        if !now {
            lesson.since += 1;
        }
        if !now && lesson.since < LESSON_DELAY {
            return Ok(());
        }
        let Some(lesson) = self.lesson.take() else { return Ok(()) };
        let (learned, waited) = lesson.wait()?;
        // Waited for when due, beside the labelling (taken at once, it is always waited for).
        self.lessons_waited += u64::from(waited && !now);
        // Those labelled in between, the one now starting left out.
        let since = if now { lesson.since } else { lesson.since - 1 };
        self.take_lesson(&lesson, learned, since);
        Ok(())
    }

    /// Hands a trusted frame set's lesson (its `labels`, the tool at `pose`) to the learning
    /// thread: the colours as they are now, and the frame sets passed since they last learned.
    fn start_lesson(
        &mut self,
        set: &FrameSet,
        labels: LessonLabels,
        pose: &nalgebra::Isometry3<f64>,
    ) -> Result<(), Error> {
        let Some(labeller) = &self.tool else { fail!("frame {}: no tool to learn the colours with", set.frame) };
        let (refresh, colours, explained) = self.compiling(self.counters.learned == 0);
        let lesson = Lesson {
            labels,
            images: set.views.iter().map(|v| v.as_ref().map(|v| v.image.clone())).collect(),
            outlines: self.rig.cameras.iter().map(|c| labeller.blade_outline(c, pose)).collect(),
            windows: self.windows.clone(),
            sure: self.sure.clone(),
            explained: self.explained.clone(),
            appearance: self.appearance.clone(),
            sharpening: self.sharpening.clone(),
            passed: self.since_learned,
            compile: (colours, explained),
        };
        let pool = match &self.learner {
            Some(pool) => pool,
            None => self.learner.insert(crate::lesson::pool()?),
        };
        self.lesson = Some(InFlight::start(pool, set.frame, refresh, lesson));
        self.lessons += 1;
        Ok(())
    }

    /// Takes what the lesson in flight taught, waiting for it (the labelling takes it
    /// [`LESSON_DELAY`] frame sets after the frame set that taught it, or here): before a report,
    /// or relabelling by colour, at the end of a recording. An error where its thread failed.
    pub fn settle(&mut self) -> Result<(), Error> {
        self.take_due_lesson(true)
    }

    /// What [`Labelling::learn`] changes, to roll it back ([`Labelling::roll_back`]).
    fn colour_state(&self) -> ColourState {
        ColourState {
            appearance: self.appearance.clone(),
            sharpening: self.sharpening.clone(),
            colours: self.colours.clone(),
            sure: self.sure.clone(),
            explained: self.explained.clone(),
            learned: self.counters.learned,
            since: (self.since_learned, self.since_compiled),
        }
    }

    /// Puts back the colours as they were when `state` was taken.
    fn roll_back(&mut self, state: ColourState) {
        ColourState {
            appearance: self.appearance,
            sharpening: self.sharpening,
            colours: self.colours,
            sure: self.sure,
            explained: self.explained,
            learned: self.counters.learned,
            since: (self.since_learned, self.since_compiled),
        } = state;
    }

    /// Whether the learned colours may label a frame set alone: once a trusted frame set or a
    /// masked frame taught them. The colours an untrusted fit taught ([`BOOTSTRAP_FRAMES`]) only
    /// hint the fit: where the hand and the tool share a colour (a blue glove holding a blue
    /// handle) they label nothing right, and labelling by them alone took random:257 in
    /// random:263's hand IoU from 0.959 to 0.575 and random:71 in random:109's from 0.640 to 0.009.
    fn colours_label(&self) -> bool {
        self.colours.is_some()
            && (self.counters.learned > self.counters.bootstrapped || self.appearance.sources.mask_views > 0)
    }

    /// Whether the fit gets hand hints: while the sure colours call little of the drawn blade the
    /// hand's ([`TOOL_AS_HAND_MAX`]).
    fn hand_hints(&self) -> bool {
        self.tool_as_hand_share() <= TOOL_AS_HAND_MAX
    }

    /// What the labelling did so far.
    pub fn report(&self) -> LabellingReport {
        LabellingReport {
            foreground: (0..self.segmenter.cameras()).map(|c| self.segmenter.method(c)).collect(),
            method: self.method,
            tool: self.tool.is_some(),
            label_frames: self.label_frames.clone(),
            confirm_weak_foreground: self.weak.is_some(),
            weak_foreground_when: self.weak.as_ref().map(|_| self.weak_when),
            weak_foreground_from: match self.weak_when {
                WeakWhen::Always => None,
                WeakWhen::TrackLost => self.lost.since,
            },
            counters: self.counters.clone(),
            appearance: self.appearance.summary(),
            sharpening_appearance: self.sharpening.summary(),
            appearance_sources: self.appearance.sources,
            drawn: self.drawn,
            deferred: self.deferred,
            lessons: self.lessons,
            lessons_waited: self.lessons_waited,
        }
    }

    /// The colours learned so far that label by colour and give the fit its hints (those of the
    /// report's `appearance`), one per label.
    pub fn learned(&self) -> Vec<LearnedColour> {
        self.appearance.summary()
    }
}

/// The box two boxes share (`None` when they share no volume).
fn intersection(a: &hullcut_hull::Aabb, b: &hullcut_hull::Aabb) -> Option<hullcut_hull::Aabb> {
    let min = a.min.sup(&b.min);
    let max = a.max.inf(&b.max);
    (0..3).all(|k| max[k] > min[k]).then_some(hullcut_hull::Aabb { min, max })
}

/// Copies `from` into `to`, reusing the images already there where their sizes match.
fn copy_masks(from: &[Option<GrayImage>], windows: &[Window], to: &mut Vec<Option<GrayImage>>, held: &mut Vec<Rows>) {
    to.resize(from.len(), None);
    held.resize(from.len(), Rows::NONE);
    for (((src, dst), held), win) in from.iter().zip(to.iter_mut()).zip(held.iter_mut()).zip(windows) {
        match src {
            Some(src) => {
                copy_within(src, dst, *win, held);
            }
            None => *dst = None,
        }
    }
}

/// A range of image rows (empty where `start >= end`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Rows {
    start: usize,
    end: usize,
}

impl Rows {
    /// No row.
    const NONE: Rows = Rows { start: 0, end: 0 };

    /// The rows from the first of either to the last of either.
    fn span(self, other: Rows) -> Rows {
        match (self.start < self.end, other.start < other.end) {
            (false, _) => other,
            (_, false) => self,
            _ => Rows { start: self.start.min(other.start), end: self.end.max(other.end) },
        }
    }
}

/// Copies `src` into `dst`, where `src` is background outside `win` and `dst` outside the rows
/// `held` (what an earlier copy left there): only the rows of either are copied, and `held`
/// becomes `win`'s rows. A `dst` of another size, or none, becomes a clone of `src`. The views'
/// windows cover 8-23% of the built-in scene's views: the masks the labelling keeps copies of
/// from frame set to frame set were copied whole before.
fn copy_within<'a>(src: &GrayImage, dst: &'a mut Option<GrayImage>, win: Window, held: &mut Rows) -> &'a mut GrayImage {
    let win = win.clipped(src.width(), src.height());
    let rows = Rows { start: win.y0 as usize, end: win.y1 as usize };
    match dst.as_mut() {
        Some(d) if d.dimensions() == src.dimensions() => {
            let copied = rows.span(*held);
            let w = src.width() as usize;
            let range = copied.start * w..copied.end * w;
            d.as_mut()[range.clone()].copy_from_slice(&src.as_raw()[range]);
        }
        _ => *dst = Some(src.clone()),
    }
    *held = rows;
    dst.get_or_insert_with(|| src.clone())
}

/// What resolving a frame set's possible shadows kept ([`Labelling::resolve_shadows`]).
struct Resolved {
    /// The hull's kept cells.
    occupancy: Occupancy,
    /// Per kept cell: kept only because the track predicts the tool there.
    marked_only: Vec<bool>,
    /// Per view, the possible shadows given back to the background as shadows on the table
    /// (pixel indices).
    given_back: Vec<Vec<usize>>,
}

/// The views' possible shadows before the hull resolved them (`unresolved`), with each view's
/// image, background and exposure gain where its background is one image ([`TableShadows`]).
fn table_shadows_of<'a>(
    rig: &'a hullcut_rig::Rig,
    unresolved: &'a [Option<GrayImage>],
    set: &'a FrameSet,
    segmenter: &'a Segmenter,
) -> TableShadows<'a> {
    let views = rig.cameras.iter().zip(unresolved).map(|(camera, mask)| mask.as_ref().map(|m| (camera, m))).collect();
    let shading = (0..rig.cameras.len())
        .map(|k| {
            let view = set.views.get(k)?.as_ref()?;
            Some(Shading {
                image: &view.image,
                background: segmenter.background_mean(k)?,
                gain: segmenter.last_exposure_gain(k)?,
            })
        })
        .collect();
    TableShadows::new(views).with_shading(shading)
}

/// Gives back to the background the possible shadows marked [`ASK_TABLE`] in `fg` where `table`
/// finds them a shadow on the table, the rest becoming unknown foreground; returns those given
/// back (pixel indices), per view.
fn shadows_to_table(table: &TableShadows, fg: &mut [Option<GrayImage>]) -> Vec<Vec<usize>> {
    fg.par_iter_mut()
        .enumerate()
        .map(|(view, mask)| {
            let Some(mask) = mask.as_mut() else { return Vec::new() };
            let w = mask.width() as usize;
            let mut back = Vec::new();
            for (k, p) in mask.iter_mut().enumerate().filter(|(_, p)| **p == ASK_TABLE) {
                *p = if table.on_table(view, k % w, k / w) {
                    back.push(k);
                    label::BACKGROUND
                } else {
                    label::UNKNOWN
                };
            }
            back
        })
        .collect()
}

/// Sets the pixels `given_back` lists (indices, per view) to the background in `masks`, those
/// labelled the scalpel too unless `keep_scalpel` (where the fitted tool is drawn over them).
pub(crate) fn to_background(masks: &mut [Option<GrayImage>], given_back: &[Vec<usize>], keep_scalpel: bool) {
    for (mask, back) in masks.iter_mut().zip(given_back) {
        let Some(mask) = mask.as_mut() else { continue };
        let raw: &mut [u8] = mask;
        for &i in back {
            if let Some(p) = raw.get_mut(i).filter(|p| !keep_scalpel || **p != label::SCALPEL) {
                *p = label::BACKGROUND;
            }
        }
    }
}

/// The colours as [`Labelling::learn`] left them, and its counts ([`Labelling::colour_state`]).
struct ColourState {
    appearance: AppearanceModel,
    sharpening: AppearanceModel,
    colours: Option<ColourLut>,
    sure: Option<Arc<ColourLut>>,
    explained: Option<Arc<ColourLut>>,
    learned: u64,
    since: (u32, u32),
}

/// Whether the learned tool's mean colours (its body's and its blade's, where learned apart) lie
/// outside the hand's 99% ellipsoid (squared Mahalanobis distance above [`SURE_MAHALANOBIS2`]):
/// the hand's class explains none of the tool's usual colours; `false` without both labels'
/// classes. The tool's class may well explain the hand's mean: a blue handle, a grey blade and
/// their blends make a broad class beside a bare hand's narrow one (random:503 in random:509: 8-11
/// one way, 104-152 the other), and the likelier class still tells them apart.
fn tool_apart_from_hand(classes: Option<&ColourClasses>) -> bool {
    let Some(classes) = classes else { return false };
    let Some(hand) = classes.classes.iter().find(|c| c.label == label::HAND) else { return false };
    let mut tool = classes.classes.iter().filter(|c| c.label == label::SCALPEL).peekable();
    tool.peek().is_some() && tool.all(|t| hand.mahalanobis2(&t.mean).is_some_and(|m| m > SURE_MAHALANOBIS2))
}

/// Whether every learned class of the tool (its body's, its blade's where learned apart) has its
/// mean within [`HAND_SPREAD_MAHALANOBIS2`] of the hand's: closer to it than the hand's own
/// pixels lie on average, the tool's pixels were the hand's. `false` without a class of the hand
/// or of the tool. A tool merely near the hand's colours is not taught the hand: a latex glove
/// and a steel scalpel, both near grey (random:1951 in random:1927: the tool's body 5.7-8, its
/// blade 1.9-2.1 in the hand's metric; the colours so learned took the scalpel's pooled IoU from
/// 0.39 to 0.79), while a fit laid over the hand taught classes within 0.1-1.4 of it (random:1523
/// in random:1531, random:1993 in random:1953).
pub(crate) fn tool_taught_the_hand(classes: &ColourClasses) -> bool {
    let Some(hand) = classes.classes.iter().find(|c| c.label == label::HAND) else { return false };
    let mut tool = classes.classes.iter().filter(|c| c.label == label::SCALPEL).peekable();
    tool.peek().is_some() && tool.all(|t| hand.mahalanobis2(&t.mean).is_some_and(|m| m <= HAND_SPREAD_MAHALANOBIS2))
}

/// The mean squared Mahalanobis distance of a class's own samples from its mean (the features'
/// dimension): [`tool_taught_the_hand`]'s bound.
const HAND_SPREAD_MAHALANOBIS2: f64 = 3.0;

/// The learned classes compiled two ways: every colour labelled; labelled only where sure
/// ([`SHARPEN_LOG_RATIO`]).
pub(crate) fn compile(classes: Option<ColourClasses>) -> (Option<ColourLut>, Option<Arc<ColourLut>>) {
    let Some(classes) = classes else { return (None, None) };
    let (all, sure) = ColourLut::new_and_confident(&classes, 2.0 * SHARPEN_LOG_RATIO);
    (Some(all), Some(Arc::new(sure)))
}

/// The learned classes compiled to label only where sure ([`SHARPEN_LOG_RATIO`]) and explained by
/// the label's class ([`SURE_MAHALANOBIS2`]).
pub(crate) fn compile_explained(classes: Option<ColourClasses>) -> Option<ColourLut> {
    let explained = ColourClasses { reject_mahalanobis2: Some(SURE_MAHALANOBIS2), ..classes? };
    Some(ColourLut::confident(&explained, 2.0 * SHARPEN_LOG_RATIO))
}

/// What an untrusted fit alone decides, per view: scalpel at its `unoccluded` pixels (the drawn
/// tool with no hull cell in front), hand where `masks` (its labels) call the foreground the hand's
/// farther than [`SHARPEN_PX`] from the drawn tool (`regions`), background elsewhere (not learned).
fn bootstrap_labels(
    masks: &[Option<GrayImage>],
    regions: &[Option<ToolRegion>],
    unoccluded: &[Vec<usize>],
) -> Vec<Option<GrayImage>> {
    masks
        .par_iter()
        .enumerate()
        .map(|(k, mask)| {
            let mask = mask.as_ref()?;
            let (w, h) = (mask.width() as usize, mask.height() as usize);
            let near = regions.get(k).and_then(Option::as_ref).map(|r| r.dilated(SHARPEN_PX, w, h));
            let mut out = GrayImage::new(mask.width(), mask.height());
            for ((k, o), &l) in out.as_mut().iter_mut().enumerate().zip(mask.as_raw()) {
                if l == label::HAND && !near.as_ref().is_some_and(|r| r.covers(k % w, k / w)) {
                    *o = label::HAND;
                }
            }
            for &i in unoccluded.get(k).into_iter().flatten() {
                if let Some(o) = out.as_mut().get_mut(i) {
                    *o = label::SCALPEL;
                }
            }
            Some(out)
        })
        .collect()
}

/// The fit's hints ([`ToolLabeller::label`]) in the window `win` of `mask` (outside it the mask
/// is background), into `out`, row by row (`out` is emptied when the image and mask sizes
/// differ): each foreground pixel's colour's label where `sure` decides ([`label::UNKNOWN`]
/// where it does not, or without colours), and a possible shadow ([`SHADOW_LIKE`])
/// [`POSSIBLE_SHADOW`], or [`label::HAND`] where its colour is surely the hand's: its colour is
/// the background's darkened, so it may speak against the tool, never for it (where it is surely
/// the tool's, [`TOOL_COLOURED_SHADOW`]: a possible shadow still, but one the hand's hull does not
/// take from the drawn tool on a small rig); background elsewhere. Without `hand_hints`
/// ([`TOOL_AS_HAND_MAX`]) a foreground pixel surely of the hand's colour is [`label::UNKNOWN`] (a
/// possible shadow of that colour stays the hand's: it is no shadow, and the hint only keeps it
/// from the tool's shadows).
fn fit_hints(
    sure: Option<&ColourLut>,
    hand_hints: bool,
    image: &image::RgbImage,
    mask: &GrayImage,
    win: Window,
    out: &mut Vec<u8>,
) {
    out.clear();
    if image.dimensions() != mask.dimensions() {
        return;
    }
    let colour = |p: &[u8]| sure.map_or(label::UNKNOWN, |s| s.get([p[0], p[1], p[2]]));
    let hint = |m: u8, p: &[u8]| match m {
        SHADOW_LIKE => match colour(p) {
            label::HAND => label::HAND,
            label::SCALPEL => TOOL_COLOURED_SHADOW,
            _ => POSSIBLE_SHADOW,
        },
        _ => match colour(p) {
            label::HAND if !hand_hints => label::UNKNOWN,
            c => c,
        },
    };
    let (w, h) = mask.dimensions();
    out.resize(win.clipped(w, h).area() as usize, label::BACKGROUND);
    let rows = win.spans(w, h).zip(out.chunks_mut(win.clipped(w, h).width().max(1) as usize));
    for (span, row) in rows {
        let (pixels, mask) = (&image.as_raw()[3 * span.start..3 * span.end], &mask.as_raw()[span]);
        // Most of a window is background: eight of its pixels are passed over at a time.
        let mut i = 0;
        while i < mask.len() {
            if let Some(eight) = mask.get(i..i + 8).and_then(|e| <[u8; 8]>::try_from(e).ok()) {
                // Background is 0.
                if u64::from_ne_bytes(eight) == 0 {
                    i += 8;
                    continue;
                }
            }
            let m = mask[i];
            if m != label::BACKGROUND {
                row[i] = hint(m, &pixels[3 * i..3 * i + 3]);
            }
            i += 1;
        }
    }
}

/// Gives each foreground pixel of `mask` in `win` (clipped to the mask) its hint from `hints`
/// ([`fit_hints`] over the same window; empty: no hints) where the hint decides something:
/// [`label::HAND`], [`label::SCALPEL`], [`POSSIBLE_SHADOW`] or [`TOOL_COLOURED_SHADOW`].
/// Background stays background. Every pixel is stored, without a branch, so the pass vectorizes.
fn apply_hints(mask: &mut GrayImage, win: Window, hints: &[u8]) {
    let (w, h) = mask.dimensions();
    let win = win.clipped(w, h);
    if hints.len() != win.area() as usize || hints.is_empty() {
        return;
    }
    let rows = win.spans(w, h).zip(hints.chunks_exact(win.width().max(1) as usize));
    for (span, row) in rows {
        for (p, &h) in mask.as_mut()[span].iter_mut().zip(row) {
            let decides = h == label::HAND || h == label::SCALPEL || h == POSSIBLE_SHADOW || h == TOOL_COLOURED_SHADOW;
            *p = if *p != label::BACKGROUND && decides { h } else { *p };
        }
    }
}

/// Per view, its image (`None` for a missing view).
pub(crate) fn images_of(set: &FrameSet) -> Vec<Option<&image::RgbImage>> {
    set.views.iter().map(|v| v.as_ref().map(|v| &v.image)).collect()
}

/// [`sharpen`] in every view that has an image, a mask and a drawn tool (`regions`), in parallel.
pub(crate) fn sharpen_views(
    lut: &ColourLut,
    images: &[Option<&image::RgbImage>],
    masks: &mut [Option<GrayImage>],
    regions: &[Option<ToolRegion>],
) {
    masks.par_iter_mut().zip(images).zip(regions).for_each(|((mask, image), region)| {
        if let (Some(mask), Some(image), Some(region)) = (mask, image, region) {
            sharpen(lut, image, mask, region);
        }
    });
}

/// Gives the foreground near the drawn tool (`region`, grown by [`SHARPEN_PX`]) the label of its
/// colour where `sure` decides; the geometry's label stays elsewhere.
pub(crate) fn sharpen(sure: &ColourLut, image: &image::RgbImage, mask: &mut GrayImage, region: &ToolRegion) {
    if image.dimensions() != mask.dimensions() {
        return;
    }
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let near = region.dilated(SHARPEN_PX, w, h);
    let (px, raw) = (image.as_raw(), mask.as_mut());
    for (x, y) in near.pixels() {
        let k = y * w + x;
        if raw[k] == label::BACKGROUND {
            continue;
        }
        let colour = sure.get([px[3 * k], px[3 * k + 1], px[3 * k + 2]]);
        if colour != label::UNKNOWN {
            raw[k] = colour;
        }
    }
}

#[cfg(test)]
mod tests {
    use hullcut_capture::segment::{BackgroundSource, ColourClass};
    use image::{Rgb, RgbImage};

    use super::*;
    use crate::lesson::{blade_as_hand, scalpel_among};

    /// Near the last hull each view is tested in its rows' stretches, but a camera on the MOG2
    /// fallback tests its whole image (its model learns from every pixel): it gets none.
    #[test]
    fn a_camera_on_mog2_gets_no_stretches_near_the_last_hull() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
        let ds = Dataset::open(root).expect("the dataset opens");
        let tool = ds.tool().expect("tool.json reads");
        let volume = hullcut_hull::WorkingVolume::from_rig(ds.rig(), 3, true).expect("a working volume");
        let hull = HullParams::new(volume.aabb, 0.008);
        let mut labelling =
            Labelling::new(&ds, tool.as_ref(), hull, &[], LabelMethod::Both).expect("the labelling sets up");
        // Camera 0 on MOG2; the others with the first frame set as their empty scene.
        let set = ds.read_frame_set(0, false).expect("frame set 0 reads");
        let sources = set
            .views
            .iter()
            .enumerate()
            .map(|(k, v)| match v {
                Some(v) if k > 0 => BackgroundSource::EmptyScene(vec![v.image.clone()]),
                _ => BackgroundSource::Stream,
            })
            .collect();
        labelling.segmenter = Segmenter::with_sources(SegmentParams::default(), sources).expect("the segmenter");
        assert_eq!(labelling.segmenter.method(0), Some(Method::Mog2));
        // The last hull: one block amid the working volume, and a box around it.
        let centre = nalgebra::center(&volume.aabb.min, &volume.aabb.max);
        labelling.last_blocks = Some(vec![centre]);
        let grown = nalgebra::Vector3::repeat(0.1);
        labelling.set_workspace(hullcut_hull::Aabb { min: centre - grown, max: centre + grown });
        assert_eq!(labelling.stretches.len(), set.views.len());
        assert!(labelling.stretches[0].is_none(), "the MOG2 camera has stretches");
        assert!(labelling.stretches[1..].iter().all(Option::is_some), "a camera without stretches");
    }

    #[test]
    fn the_track_counts_as_lost_from_the_frame_set_after_a_fifth_of_the_last_thirty_were_refused() {
        // Refusals further apart than the window never add up.
        let mut lost = LostTrack::default();
        for frame in 0..300u64 {
            lost.record(frame, frame % (LOST_WINDOW as u64 / (LOST_REFUSED as u64 - 1) + 1) != 0);
        }
        assert_eq!(lost.since, None);
        // The sixth refusal within thirty frame sets loses it, from the next one on, for good.
        let mut lost = LostTrack::default();
        for frame in 0..40u64 {
            lost.record(frame, !(10..10 + LOST_REFUSED as u64).contains(&frame));
        }
        assert_eq!(lost.since, Some(10 + LOST_REFUSED as u64));
        lost.record(40, true);
        assert_eq!(lost.since, Some(10 + LOST_REFUSED as u64));
    }

    #[test]
    fn two_boxes_share_their_overlap_and_nothing_when_they_only_touch() {
        let b = |min: [f64; 3], max: [f64; 3]| hullcut_hull::Aabb { min: min.into(), max: max.into() };
        let shared = intersection(&b([0.0, 0.0, 0.0], [2.0, 2.0, 2.0]), &b([1.0, -1.0, 0.5], [3.0, 1.0, 1.5]));
        assert_eq!(shared, Some(b([1.0, 0.0, 0.5], [2.0, 1.0, 1.5])));
        assert_eq!(intersection(&b([0.0; 3], [1.0; 3]), &b([1.0, 0.0, 0.0], [2.0, 1.0, 1.0])), None);
        assert_eq!(intersection(&b([0.0; 3], [1.0; 3]), &b([5.0; 3], [6.0; 3])), None);
    }

    #[test]
    fn mask_counts_equal_counting_pixel_by_pixel_at_any_size() {
        let mut rng = 7u64;
        for (w, h) in [(1, 1), (17, 15), (255, 1), (256, 3), (640, 480)] {
            let mask = GrayImage::from_fn(w, h, |_, _| {
                rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                image::Luma([[label::BACKGROUND, label::HAND, SHADOW_LIKE, label::UNKNOWN][(rng >> 62) as usize]])
            });
            let counts = MaskCounts::within(&mask, Window::whole(w, h));
            assert_eq!(counts.foreground, mask.iter().filter(|&&p| p != label::BACKGROUND).count(), "{w}x{h}");
            assert_eq!(counts.shadow, mask.iter().filter(|&&p| p == SHADOW_LIKE).count() as u64, "{w}x{h}");
            assert_eq!(counts.pixels, (w * h) as usize);
        }
        let all = GrayImage::from_pixel(640, 480, [SHADOW_LIKE].into());
        let counts = MaskCounts::within(&all, Window::whole(640, 480));
        assert_eq!((counts.foreground, counts.shadow), (640 * 480, 640 * 480));
        // In a window, the pixels in it.
        let win = Window { x0: 3, y0: 400, x1: 300, y1: 900 };
        assert_eq!(MaskCounts::within(&all, win).foreground, 297 * 80);
    }

    #[test]
    fn copied_masks_equal_their_source_whatever_was_there() {
        let a = GrayImage::from_fn(4, 3, |x, y| image::Luma([(x + 4 * y) as u8]));
        let b = GrayImage::from_pixel(2, 2, image::Luma([7]));
        let mut to = vec![Some(GrayImage::new(4, 3)), Some(GrayImage::new(5, 5)), None, Some(b.clone())];
        let mut held = Vec::new();
        let from = vec![Some(a.clone()), Some(b.clone()), Some(a.clone())];
        let whole = [Window::whole(4, 3), Window::whole(2, 2), Window::whole(4, 3)];
        copy_masks(&from, &whole, &mut to, &mut held);
        assert_eq!(to, from);
        copy_masks(&[None, Some(b.clone())], &whole[..2], &mut to, &mut held);
        assert_eq!(to, vec![None, Some(b)]);
    }

    /// Masks background outside random windows, copied one after the other into one buffer by
    /// their windows' rows only, come out equal to their source every time.
    #[test]
    fn masks_copied_by_their_windows_rows_equal_their_source() {
        let mut state = 2861u64;
        let mut below = |n: u32| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) % u64::from(n.max(1))) as u32
        };
        let (w, h) = (23u32, 17u32);
        let (mut dst, mut held) = (None, Rows::NONE);
        for round in 0..300 {
            let (x0, y0) = (below(w), below(h));
            let win = Window { x0, y0, x1: x0 + below(w + 4 - x0), y1: y0 + below(h + 4 - y0) };
            let inside = win.clipped(w, h);
            let src = GrayImage::from_fn(w, h, |x, y| {
                let within = (inside.x0..inside.x1).contains(&x) && (inside.y0..inside.y1).contains(&y);
                image::Luma([if within { below(4) as u8 } else { label::BACKGROUND }])
            });
            let copied = copy_within(&src, &mut dst, win, &mut held).clone();
            assert_eq!(copied, src, "round {round}, {win:?}");
        }
    }

    #[test]
    fn only_colours_their_class_explains_sharpen_the_labels_near_the_tool() {
        // A skin-toned hand and a tool of steel and brass (one broad class), learned; the drawn
        // tool covers the middle column of a 3x1 view.
        let classes = ColourClasses {
            classes: vec![
                ColourClass::from_albedo(label::HAND, [200.0, 140.0, 110.0], (0.5, 1.0), 0.015),
                ColourClass::from_albedo(label::SCALPEL, [150.0, 140.0, 110.0], (0.2, 1.0), 0.05),
            ],
            reject_mahalanobis2: None,
        };
        let (steel, skin, green_shadow) = ([90, 90, 95], [190, 132, 104], [20, 60, 35]);
        let image = RgbImage::from_fn(3, 1, |x, _| Rgb([steel, skin, green_shadow][x as usize]));
        let region = ToolRegion { x0: 1, y0: 0, width: 1, height: 1, covered: vec![true] };
        let mut mask = GrayImage::from_raw(3, 1, vec![label::HAND, label::SCALPEL, label::HAND]).expect("mask");
        let (likelier, explained) = (compile(Some(classes.clone())).1, compile_explained(Some(classes)));
        sharpen(&explained.expect("compiled"), &image, &mut mask, &region);
        // The steel beside the drawn tool is the tool's, the skin on it the hand's; the green
        // shadow kept beside the blade is neither: the geometry's label stays.
        assert_eq!(mask.as_raw(), &vec![label::SCALPEL, label::HAND, label::HAND]);
        // Without the test of explanation the broader class would take the shadow.
        assert_eq!(likelier.expect("compiled").get(green_shadow), label::SCALPEL);
    }

    /// A skin-toned hand and a dark blue handle, learned (the thin steel blade was not).
    fn skin_and_blue() -> Arc<ColourLut> {
        let classes = ColourClasses {
            classes: vec![
                ColourClass::from_albedo(label::HAND, [200.0, 150.0, 120.0], (0.3, 1.0), 0.05),
                ColourClass::from_albedo(label::SCALPEL, [40.0, 60.0, 200.0], (0.3, 1.0), 0.03),
            ],
            reject_mahalanobis2: None,
        };
        compile(Some(classes)).1.expect("compiled")
    }

    #[test]
    fn the_blade_the_sure_colours_call_the_hand_is_counted_inside_its_outline_only() {
        let sure = skin_and_blue();
        let (steel, skin, blue) = ([128, 128, 128], [190, 142, 114], [38, 58, 190]);
        assert_eq!((sure.get(steel), sure.get(skin), sure.get(blue)), (label::HAND, label::HAND, label::SCALPEL));
        // A 12x8 view: the drawn tool fills rows 2..6 of columns 0..12; steel in columns 6..12,
        // the blue handle left of it; a finger (hand label) at column 8 on row 3. The blade's
        // outline is the square from (6, 1) to (10, 6): columns 6..=10.
        let image = RgbImage::from_fn(12, 8, |x, _| Rgb(if x >= 6 { steel } else { blue }));
        let mask = GrayImage::from_fn(12, 8, |x, y| {
            image::Luma([match (x, y) {
                (8, 3) => label::HAND,
                (_, 2..6) => label::SCALPEL,
                _ => label::BACKGROUND,
            }])
        });
        let counted = |outline: &[nalgebra::Point2<f64>]| {
            let pixels = scalpel_among(&mask, &inside_outline(mask.width(), mask.height(), outline));
            (pixels.len() as u64, blade_as_hand(&sure, &image, &pixels))
        };
        let outline = [(6.0, 1.0), (10.0, 1.0), (10.0, 6.0), (6.0, 6.0)].map(|(x, y)| nalgebra::Point2::new(x, y));
        // 5 columns by 4 rows of drawn tool, less the finger; every one of them steel.
        assert_eq!(counted(&outline), (19, 19));
        // Fewer than three points outline nothing.
        assert_eq!(counted(&outline[..2]), (0, 0));
        // An outline over the handle counts blade pixels the colours call the tool's.
        let handle = [(0.0, 2.0), (3.0, 2.0), (3.0, 5.0), (0.0, 5.0)].map(|(x, y)| nalgebra::Point2::new(x, y));
        assert_eq!(counted(&handle), (16, 0));
        // An outline beyond the image counts the part inside it.
        let wide = [(-5.0, -5.0), (40.0, -5.0), (40.0, 40.0), (-5.0, 40.0)].map(|(x, y)| nalgebra::Point2::new(x, y));
        assert_eq!(counted(&wide), (47, 23));
    }

    #[test]
    fn without_hand_hints_the_hands_colour_decides_nothing_but_a_shadow() {
        let sure = skin_and_blue();
        let (steel, blue, grey) = ([128, 128, 128], [38, 58, 190], [60, 62, 64]);
        let image = RgbImage::from_fn(4, 1, |x, _| Rgb([steel, blue, steel, grey][x as usize]));
        let mask = GrayImage::from_raw(4, 1, vec![label::UNKNOWN, label::UNKNOWN, SHADOW_LIKE, label::BACKGROUND])
            .expect("mask");
        let whole = Window::whole(4, 1);
        let hints = |hand_hints| {
            let mut out = Vec::new();
            fit_hints(Some(&sure), hand_hints, &image, &mask, whole, &mut out);
            out
        };
        assert_eq!(hints(true), vec![label::HAND, label::SCALPEL, label::HAND, label::BACKGROUND]);
        assert_eq!(hints(false), vec![label::UNKNOWN, label::SCALPEL, label::HAND, label::BACKGROUND]);
    }

    #[test]
    fn fit_hints_pass_background_over_eight_at_a_time_and_hint_every_foreground_pixel_as_one_by_one() {
        // Pixel by pixel, as the hints are defined.
        let one_by_one =
            |sure: Option<&ColourLut>, hand_hints: bool, image: &image::RgbImage, mask: &GrayImage, win: Window| {
                let (w, h) = mask.dimensions();
                let win = win.clipped(w, h);
                let mut out = Vec::new();
                for y in win.y0..win.y1 {
                    for x in win.x0..win.x1 {
                        let p = image.get_pixel(x, y).0;
                        let colour = sure.map_or(label::UNKNOWN, |s| s.get(p));
                        out.push(match mask.get_pixel(x, y).0[0] {
                            label::BACKGROUND => label::BACKGROUND,
                            SHADOW_LIKE => match colour {
                                label::HAND => label::HAND,
                                label::SCALPEL => TOOL_COLOURED_SHADOW,
                                _ => POSSIBLE_SHADOW,
                            },
                            _ if colour == label::HAND && !hand_hints => label::UNKNOWN,
                            _ => colour,
                        });
                    }
                }
                out
            };
        let lut = skin_and_blue();
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 33) % n.max(1)
        };
        for round in 0..300 {
            let (w, h) = (1 + next(37) as u32, 1 + next(9) as u32);
            // Foreground in runs, long stretches of background between them.
            let mut raw = vec![label::BACKGROUND; (w * h) as usize];
            let mut i = next(12) as usize;
            while i < raw.len() {
                let run = 1 + next(5) as usize;
                let value = [label::HAND, label::SCALPEL, label::UNKNOWN, SHADOW_LIKE][next(4) as usize];
                let end = (i + run).min(raw.len());
                raw[i..end].fill(value);
                i += run + next(20) as usize;
            }
            let mask = GrayImage::from_raw(w, h, raw).expect("mask");
            let image = image::RgbImage::from_fn(w, h, |_, _| {
                let c = [[200, 150, 120], [40, 60, 200], [120, 120, 120]][next(3) as usize];
                image::Rgb(c.map(|v: u8| v.saturating_add(next(9) as u8)))
            });
            let (x0, y0) = (next(u64::from(w)) as u32, next(u64::from(h)) as u32);
            let win = Window { x0, y0, x1: x0 + next(u64::from(w) + 3) as u32, y1: y0 + 1 + next(u64::from(h)) as u32 };
            for (sure, hand_hints) in [(Some(&*lut), true), (Some(&*lut), false), (None, true)] {
                let mut out = vec![7; 3];
                fit_hints(sure, hand_hints, &image, &mask, win, &mut out);
                assert_eq!(out, one_by_one(sure, hand_hints, &image, &mask, win), "round {round}, {w}x{h}, {win:?}");
            }
        }
    }

    #[test]
    fn hints_take_only_foreground_pixels_in_their_window_and_only_where_they_decide() {
        // A 4x3 mask, its window the middle two columns of the last two rows.
        let fg = label::UNKNOWN;
        let mut mask = GrayImage::from_raw(
            4,
            3,
            vec![fg, fg, fg, fg, label::BACKGROUND, fg, fg, SHADOW_LIKE, fg, label::HAND, fg, fg],
        )
        .expect("mask");
        let before = mask.clone();
        let win = Window { x0: 1, y0: 1, x1: 3, y1: 3 };
        let hints = [label::SCALPEL, POSSIBLE_SHADOW, TOOL_COLOURED_SHADOW, label::UNKNOWN];
        apply_hints(&mut mask, win, &hints);
        let expected = vec![fg, fg, fg, fg, label::BACKGROUND, label::SCALPEL, POSSIBLE_SHADOW, SHADOW_LIKE, fg];
        assert_eq!(&mask.as_raw()[..9], &expected[..]);
        // A deciding hint takes a labelled pixel too; an undecided one keeps the label; outside
        // the window nothing changes.
        assert_eq!(&mask.as_raw()[9..], &[TOOL_COLOURED_SHADOW, fg, fg]);
        assert_eq!((mask.as_raw()[8], mask.as_raw()[11]), (before.as_raw()[8], before.as_raw()[11]));
        // A background pixel takes no hint; hints of the wrong size, or none, change nothing.
        let mut empty = GrayImage::from_raw(2, 1, vec![label::BACKGROUND, fg]).expect("mask");
        apply_hints(&mut empty, Window::whole(2, 1), &[label::HAND, label::HAND]);
        assert_eq!(empty.as_raw(), &vec![label::BACKGROUND, label::HAND]);
        for wrong in [&[][..], &[label::SCALPEL][..]] {
            apply_hints(&mut empty, Window::whole(2, 1), wrong);
            assert_eq!(empty.as_raw(), &vec![label::BACKGROUND, label::HAND]);
        }
    }

    #[test]
    fn a_possible_shadow_is_hinted_by_its_sure_colour() {
        let sure = skin_and_blue();
        let (steel, blue) = ([128, 128, 128], [38, 58, 190]);
        let image = RgbImage::from_fn(2, 1, |x, _| Rgb([steel, blue][x as usize]));
        let mask = GrayImage::from_raw(2, 1, vec![SHADOW_LIKE; 2]).expect("mask");
        let whole = Window::whole(2, 1);
        // Surely the hand's: the hand; surely the tool's: a possible shadow no hand cell takes from
        // the drawn tool; with no colours learned, a possible shadow.
        let mut hints = Vec::new();
        for hand_hints in [true, false] {
            fit_hints(Some(&sure), hand_hints, &image, &mask, whole, &mut hints);
            assert_eq!(hints, vec![label::HAND, TOOL_COLOURED_SHADOW]);
        }
        fit_hints(None, true, &image, &mask, whole, &mut hints);
        assert_eq!(hints, vec![POSSIBLE_SHADOW; 2]);
    }

    #[test]
    fn an_untrusted_fit_teaches_only_a_tool_whose_colour_the_hand_does_not_explain() {
        let skin = ColourClass::from_albedo(label::HAND, [200.0, 150.0, 120.0], (0.3, 1.0), 0.02);
        let classes = |hand: &ColourClass, tool: ColourClass| ColourClasses {
            classes: vec![hand.clone(), tool],
            reject_mahalanobis2: None,
        };
        // A blue handle beside a bare hand: apart.
        let blue = ColourClass::from_albedo(label::SCALPEL, [40.0, 60.0, 200.0], (0.3, 1.0), 0.03);
        assert!(tool_apart_from_hand(Some(&classes(&skin, blue))));
        // A broad tool class (handle, blade and their blends) explains the hand's mean, but the
        // hand's class does not explain the tool's: apart.
        let broad = ColourClass::from_albedo(label::SCALPEL, [110.0, 120.0, 150.0], (0.1, 1.0), 0.08);
        assert!(broad.mahalanobis2(&skin.mean).is_some_and(|m| m < SURE_MAHALANOBIS2));
        assert!(tool_apart_from_hand(Some(&classes(&skin, broad))));
        // A tool of the hand's colour (a blue glove holding a blue handle): not apart.
        let glove = ColourClass::from_albedo(label::HAND, [40.0, 60.0, 200.0], (0.2, 1.0), 0.04);
        let handle = ColourClass::from_albedo(label::SCALPEL, [42.0, 58.0, 205.0], (0.3, 0.8), 0.02);
        assert!(!tool_apart_from_hand(Some(&classes(&glove, handle))));
        // Without both classes: nothing to tell apart.
        assert!(!tool_apart_from_hand(None));
        let one = ColourClasses { classes: vec![skin], reject_mahalanobis2: None };
        assert!(!tool_apart_from_hand(Some(&one)));
    }

    #[test]
    fn a_trusted_fit_teaches_a_tool_unless_its_every_class_has_the_hands_colour() {
        let glove = ColourClass::from_albedo(label::HAND, [40.0, 60.0, 200.0], (0.2, 1.0), 0.04);
        let handle = ColourClass::from_albedo(label::SCALPEL, [42.0, 58.0, 205.0], (0.3, 0.8), 0.02);
        let steel = ColourClass::from_albedo(label::SCALPEL, [128.0, 128.0, 132.0], (0.3, 1.0), 0.02);
        let classes = |tool: &[&ColourClass]| ColourClasses {
            classes: std::iter::once(&glove).chain(tool.iter().copied()).cloned().collect(),
            reject_mahalanobis2: None,
        };
        assert!(glove.mahalanobis2(&handle.mean).is_some_and(|m| m <= HAND_SPREAD_MAHALANOBIS2));
        // A handle of the glove's colour beside a steel blade: taught (an untrusted fit's would
        // not be: every class must be apart there).
        assert!(!tool_taught_the_hand(&classes(&[&handle, &steel])));
        assert!(!tool_apart_from_hand(Some(&classes(&[&handle, &steel]))));
        // Body and blade both of the glove's colour (a fit laid over the hand): not taught.
        let blade_as_glove = ColourClass { label: label::SCALPEL, ..glove.clone() };
        assert!(tool_taught_the_hand(&classes(&[&handle, &blade_as_glove])));
        assert!(tool_taught_the_hand(&classes(&[&handle])));
        // A tool near the hand's colours, not of them: a grey latex glove, a bluish steel handle
        // within the glove's 99% ellipsoid, but farther from its mean than its own pixels lie on
        // average. Taught.
        let latex = ColourClass::from_albedo(label::HAND, [132.0, 130.0, 122.0], (0.2, 1.0), 0.02);
        let bluish = ColourClass::from_albedo(label::SCALPEL, [121.0, 124.0, 139.0], (0.3, 0.9), 0.01);
        let m = latex.mahalanobis2(&bluish.mean).expect("invertible");
        assert!(m > HAND_SPREAD_MAHALANOBIS2 && m <= SURE_MAHALANOBIS2, "{m}");
        let near = ColourClasses { classes: vec![latex, bluish], reject_mahalanobis2: None };
        assert!(!tool_taught_the_hand(&near));
        // No class of the hand, or none of the tool: nothing taught the hand.
        let tools_only = ColourClasses { classes: vec![handle.clone(), steel.clone()], reject_mahalanobis2: None };
        assert!(!tool_taught_the_hand(&tools_only));
        assert!(!tool_taught_the_hand(&classes(&[])));
    }

    #[test]
    fn an_untrusted_fit_teaches_its_unoccluded_tool_and_the_hand_far_from_it() {
        // A 60x10 view, all hand but a background column and a scalpel-labelled pixel far from the
        // tool; the tool drawn over columns 50..=52 of rows 4..=6, two of its pixels unoccluded.
        let (w, h) = (60usize, 10usize);
        let mask = GrayImage::from_fn(w as u32, h as u32, |x, y| {
            image::Luma([match (x, y) {
                (5, _) => label::BACKGROUND,
                (7, 7) => label::SCALPEL,
                _ => label::HAND,
            }])
        });
        let region = ToolRegion { x0: 50, y0: 4, width: 3, height: 3, covered: vec![true; 9] };
        let unoccluded = vec![5 * w + 51, 6 * w + 52];
        let taught =
            bootstrap_labels(&[Some(mask.clone()), None], &[Some(region), None], std::slice::from_ref(&unoccluded));
        assert_eq!(taught.len(), 2);
        assert!(taught[1].is_none(), "a view without a mask teaches nothing");
        let view = taught[0].as_ref().expect("the first view's labels");
        for (k, &l) in view.as_raw().iter().enumerate() {
            let (x, y) = (k % w, k / w);
            let expected = if unoccluded.contains(&k) {
                label::SCALPEL
            } else if x + SHARPEN_PX >= 50 || mask.as_raw()[k] != label::HAND {
                // Near the drawn tool, and where the fit's labels are not the hand's: not taught.
                label::BACKGROUND
            } else {
                label::HAND
            };
            assert_eq!(l, expected, "pixel ({x}, {y})");
        }
        // Without a drawn tool in the view, all of the hand is far from it.
        let taught = bootstrap_labels(std::slice::from_ref(&Some(mask.clone())), &[None], &[]);
        let hand = taught[0].as_ref().expect("labels").as_raw().iter().filter(|&&l| l == label::HAND).count();
        assert_eq!(hand, w * h - h - 1);
    }
}
