//! Labels from geometry: which foreground pixels are the known tool, with no colour model.
//!
//! The foreground of every view (hand and tool together) carves one hull. The tool's template is
//! fitted into it by the [`Tracker`]: from the track's prediction when there is one, else from the
//! hull's thin parts (what an opening of the hull by [`LabelParams::thin_radius_m`] removes: a
//! handle and a blade, not a palm or a fist). The fit's evidence is the foreground's outline where
//! the tool should be: foreground pixels within [`LabelParams::band_px`] of the predicted tool's
//! silhouette (the tool as predicted and rolled a few degrees either way about its long axis,
//! [`LabelParams::roll_deg`]) are taken as scalpel for the fit, the rest as hand, so the outline of
//! the tool against the background is what pulls the fit, and the hand's outline elsewhere does
//! not. Small holes in that foreground near the tool (a grey handle over a grey table) are
//! foreground of no label to the fit, not outline, on rigs of six views or more.
//!
//! With the fitted pose, the tool's mesh is drawn into every view with a depth buffer; a
//! foreground pixel it covers is scalpel unless a hull cell of the hand (farther than
//! [`LabelParams::tool_margin_m`] from the tool) lies in front of it along that pixel's ray by more
//! than [`LabelParams::occlusion_margin_m`]: then the hand hides the tool there. Every other
//! foreground pixel is hand. The hull's cells are relabelled the same way: near the tool,
//! scalpel; the rest, hand. A frame whose tool cannot be fitted leaves its foreground unknown.

use std::sync::Arc;
use std::time::Instant;

use hullcut_dataset::{Mesh, ToolGeometry, label};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, Silhouette};
use hullcut_rig::Camera;
use image::GrayImage;
use nalgebra::{Isometry3, Point2, Point3, Vector2, Vector3};
use rayon::prelude::*;

use crate::ToolError;
use crate::evidence::{BATCH, ProjectedBatch, project, project_batch, project_camera_point};
use crate::geometry::convex_hull;
use crate::table_shadow::TableShadows;
use crate::template::Template;
use crate::track::{MANY_VIEWS, PoseEstimate, Tracker, TrackerParams, ViewInput};

/// A hint in a labeller's view mask: a foreground pixel that may be a cast shadow (the background's
/// colour darkened). It is evidence of the tool only where the predicted tool is drawn, or a pixel
/// from it (a blade's own shadow beside it, where it nears the table, is not its outline); the
/// pixel beside it only where the other views do not see the table behind it darkened too, when
/// the views' masks before the hull resolved the shadows are given ([`TableShadows`]): there it
/// is the hand's shadow on the table, not a dull tip over it.
pub const POSSIBLE_SHADOW: u8 = 128;

/// A hint in a labeller's view mask: a foreground pixel that the other views see as a shadow on
/// the table ([`TableShadows`]). The tool may cover it (a dull blade over the hand's shadow near
/// the table is as dark as the shadow behind it), but it is never evidence of the tool: a fit
/// drawn into a shadow beside the blade would otherwise explain it, and creep into it (roll the
/// blade about its long axis, frame set after frame set).
pub const TABLE_SHADOW: u8 = 129;

/// A hint in a labeller's view mask: a possible shadow ([`POSSIBLE_SHADOW`], and read as one
/// throughout) whose colour is surely the tool's rather than the hand's. On a rig of fewer than
/// six views with masks, where it is the tool's evidence (the tool drawn over it, or a pixel from
/// it), no cell of the hand's hull takes it from the tool: the hand does not look like it. A grey blade over a grey table looks like a shadow,
/// and with four cameras the hand's hull is fat enough about the held tool to lie in front of the
/// blade in half the views (random:503 in random:509: the right fit refused, seen by two views
/// of four, after 15 frame sets trusted). With more views the hull is tight, and the colour
/// would only keep the hand's grey shadow beside a steel blade for the tool where the track's
/// prediction draws it (the built-in scene: 29 -> 37 trusted frame sets off by over 5° or 5 mm).
pub const TOOL_COLOURED_SHADOW: u8 = 130;

/// Whether a hint marks a possible shadow ([`POSSIBLE_SHADOW`] or [`TOOL_COLOURED_SHADOW`]).
fn possible_shadow(hint: u8) -> bool {
    hint == POSSIBLE_SHADOW || hint == TOOL_COLOURED_SHADOW
}

/// A possible shadow is evidence of the tool within this many pixels of the drawn tool (the fit
/// puts the outline to a pixel or so).
const SHADOW_REACH_PX: usize = 1;
/// The holes of the fit's evidence filled before its outline is sampled: those of up to this share
/// of the view's pixels ([`crate::holes`]) ...
const HOLE_AREA: f64 = 1e-3;
/// ... within this many pixels of the box of its scalpel pixels.
const HOLE_MARGIN_PX: usize = 16;

/// The largest side of a tool a template or labeller is built for, metres (a scalpel is some
/// 15 cm long): see [`crate::check_tool`].
pub const MAX_TOOL_SIDE_M: f64 = 0.5;

/// Thin components tried as the tool when there is no track (largest first).
const INIT_COMPONENTS: usize = 3;

/// Settings of geometric labelling.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelParams {
    /// Radius of the opening that keeps the hand's bulk and removes thin parts, metres: parts of
    /// the hull narrower than twice this are taken as the tool when there is no track.
    pub thin_radius_m: f64,
    /// Foreground within this many pixels of the predicted tool's silhouette is the fit's
    /// evidence of the tool (unless its colour is surely the hand's).
    pub band_px: f64,
    /// The band is taken around the tool as predicted and as rolled this many degrees either way
    /// about its long axis (blade centre to tip), each part's three drawings in one convex
    /// outline. A thin blade's roll is what a prediction gets most wrong, and foreground beyond a
    /// band around a wrong roll went to the hand, out of the fit's sight, so the fit stayed at the
    /// prediction's roll frame set after frame set (random:1453 in random:1483: 44 trusted fits
    /// off by 8-12°; with the band around the true pose, 16; 34 with 6°). 0: the band around the
    /// prediction alone.
    pub roll_deg: f64,
    /// Hull cells whose centre lies this close to the tool's surface (plus half a cell's diagonal)
    /// are the tool's, metres.
    pub tool_margin_m: f64,
    /// A hand cell hides the tool where it lies this much nearer the camera than the tool's
    /// surface, metres (plus one cell).
    pub occlusion_margin_m: f64,
    /// While searches of the hull's thin parts for the tool (the track lost, or its prediction
    /// refused) keep finding no trusted fit, they run on fewer frame sets: after two failed in a
    /// row on every second, after three on every fourth, and so on up to one in this many (1, the
    /// default: on every frame set). A search costs 20 or more fits of the tool, 100-400 ms a
    /// frame set on two cores where the tool is not found (random:691 in random:701: the pose
    /// stage 200-265 ms a frame set, 2.4-3 fps; 5.6 fps with 4). Fewer searches find the tool
    /// fewer times where a search succeeds only now and then (random:769 in random:773, five
    /// cameras: 6 of 108 searches found it, its track then held it for 1-24 frame sets, 48
    /// trusted, 126 of the organ's edges cut; with 4, 2 of 75 found it, 2 trusted, none cut), so
    /// pacing is for live sessions that want a steady frame rate.
    pub max_search_gap: u32,
}

impl Default for LabelParams {
    fn default() -> Self {
        LabelParams {
            thin_radius_m: 0.007,
            band_px: 3.0,
            roll_deg: 6.0,
            tool_margin_m: 0.002,
            occlusion_margin_m: 0.003,
            max_search_gap: 1,
        }
    }
}

/// The frame sets from one search of the hull's thin parts to the next after `failed` searches in
/// a row found no trusted fit: 1 (every frame set) after none or one, doubling with each failure
/// after that, at most `max` (and at least 1).
pub(crate) fn search_gap(failed: u32, max: u32) -> u32 {
    let doubled = 1u32.checked_shl(failed.saturating_sub(1)).unwrap_or(u32::MAX);
    doubled.min(max).max(1)
}

/// What labelling one frame set found, and what it cost.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabelStats {
    /// The pose came from the hull's thin parts (no track to follow).
    pub from_thin_parts: bool,
    /// The hull's thin parts were not searched for the tool this frame set, though nothing was
    /// trusted from the track: the last searches found no trusted fit ([`LabelParams::max_search_gap`]).
    pub search_paused: bool,
    /// Hull leaves taken as thin parts (when starting from them).
    pub thin_leaves: usize,
    /// Foreground pixels labelled scalpel, over all views.
    pub scalpel_pixels: u64,
    /// Pixels the tool's mesh covers that the hand hides, over all views.
    pub hidden_pixels: u64,
    /// Foreground pixels left unknown (no fitted tool).
    pub unknown_pixels: u64,
    /// Time for the fit's evidence (thin parts, provisional labels, relabelled hull), ms.
    pub evidence_ms: f64,
    /// Time in the tracker (fit, confidence), ms.
    pub fit_ms: f64,
    /// Time drawing the final labels (tool mesh, hand depth), ms.
    pub draw_ms: f64,
}

/// One frame set labelled: the pose estimate, a label mask per view, the hull relabelled.
#[derive(Debug, Clone)]
pub struct LabelledFrame {
    /// The tracker's estimate for the frame.
    pub estimate: PoseEstimate,
    /// Per view (rig order): 0 background, 1 hand, 2 scalpel, 255 unknown; `None` for a missing
    /// view, and for every view of a fitted frame set whose labels were not drawn
    /// ([`ToolLabeller::draw_labels`]).
    pub masks: Vec<Option<GrayImage>>,
    /// The foreground's hull with tool cells labelled scalpel and the others hand.
    pub occupancy: Occupancy,
    /// Per view: where the fitted tool's mesh is drawn, hidden or not (`None` without a fit, a
    /// view, or the tool in it, and where the labels were not drawn).
    pub tool_regions: Vec<Option<ToolRegion>>,
    /// Per view (empty unless [`ToolLabeller::list_unoccluded`] asked for them, or without a
    /// fit): the indices of the foreground pixels where the tool is drawn and no cell of the
    /// hand's hull lies in front of it, phantom or not (those the fitted pose alone makes the
    /// tool's, whichever cells are real).
    pub unoccluded: Vec<Vec<usize>>,
    /// Counters and timings.
    pub stats: LabelStats,
}

/// The pixels a drawn tool covers in one view, in its bounding box.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ToolRegion {
    /// Left column of the box.
    pub x0: usize,
    /// Top row of the box.
    pub y0: usize,
    /// Width of the box.
    pub width: usize,
    /// Height of the box.
    pub height: usize,
    /// Row-major over the box: whether the tool covers the pixel.
    pub covered: Vec<bool>,
}

impl ToolRegion {
    /// The region grown by `r` pixels (a square neighbourhood), clipped to a `width`×`height`
    /// image.
    pub fn dilated(&self, r: usize, width: usize, height: usize) -> ToolRegion {
        let (x0, y0) = (self.x0.saturating_sub(r), self.y0.saturating_sub(r));
        let x1 = (self.x0 + self.width + r).min(width);
        let y1 = (self.y0 + self.height + r).min(height);
        let (w, h) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
        // Separable max: along rows into `rows`, then along columns, each a pass from either end
        // that tracks the distance to the last covered pixel (no cost per pixel of `r`).
        let mut rows = vec![false; w * h];
        for j in 0..self.height {
            let y = self.y0 + j - y0;
            if y >= h {
                continue;
            }
            let src = &self.covered[j * self.width..(j + 1) * self.width];
            let row = &mut rows[y * w..(y + 1) * w];
            let at = |x: usize| x.checked_sub(self.x0 - x0).and_then(|i| src.get(i)).copied().unwrap_or(false);
            let mut since = usize::MAX;
            for (x, out) in row.iter_mut().enumerate() {
                since = if at(x) { 0 } else { since.saturating_add(1) };
                *out = since <= r;
            }
            let mut until = usize::MAX;
            for (x, out) in row.iter_mut().enumerate().rev() {
                until = if at(x) { 0 } else { until.saturating_add(1) };
                *out |= until <= r;
            }
        }
        let mut covered = vec![false; w * h];
        let mut since = vec![usize::MAX; w];
        for y in 0..h {
            for (x, (out, s)) in covered[y * w..(y + 1) * w].iter_mut().zip(&mut since).enumerate() {
                *s = if rows[y * w + x] { 0 } else { s.saturating_add(1) };
                *out = *s <= r;
            }
        }
        let mut until = vec![usize::MAX; w];
        for y in (0..h).rev() {
            for (x, (out, u)) in covered[y * w..(y + 1) * w].iter_mut().zip(&mut until).enumerate() {
                *u = if rows[y * w + x] { 0 } else { u.saturating_add(1) };
                *out |= *u <= r;
            }
        }
        ToolRegion { x0, y0, width: w, height: h, covered }
    }

    /// The region shrunk by `r` pixels: the pixels whose whole square neighbourhood of radius `r`
    /// it covers.
    pub fn eroded(&self, r: usize) -> ToolRegion {
        let covered = (0..self.covered.len())
            .map(|k| {
                let (x, y) = (k % self.width.max(1), k / self.width.max(1));
                x >= r
                    && y >= r
                    && x + r < self.width
                    && y + r < self.height
                    && (y - r..=y + r).all(|yy| (x - r..=x + r).all(|xx| self.covered[yy * self.width + xx]))
            })
            .collect();
        ToolRegion { x0: self.x0, y0: self.y0, width: self.width, height: self.height, covered }
    }

    /// Whether the region covers pixel (`i`, `j`) of the image.
    pub fn covers(&self, i: usize, j: usize) -> bool {
        let (Some(x), Some(y)) = (i.checked_sub(self.x0), j.checked_sub(self.y0)) else { return false };
        x < self.width && y < self.height && self.covered.get(y * self.width + x).copied().unwrap_or(false)
    }

    /// The covered pixels, as image coordinates.
    pub fn pixels(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.covered
            .iter()
            .enumerate()
            .filter(|(_, c)| **c)
            .map(|(k, _)| (self.x0 + k % self.width.max(1), self.y0 + k / self.width.max(1)))
    }
}

/// Labels foreground with the known tool, frame after frame (it keeps the tool's track).
#[derive(Debug, Clone)]
pub struct ToolLabeller {
    tracker: Tracker,
    mesh: Arc<Mesh>,
    /// Distance to the tool, tool frame (for the hull's tool cells).
    field: ToolField,
    params: LabelParams,
    /// Whether [`ToolLabeller::label`] lists each view's [`LabelledFrame::unoccluded`] pixels.
    unoccluded: bool,
    /// Whether [`ToolLabeller::label`] draws the views' labels ([`ToolLabeller::draw_labels`]).
    draw: bool,
    /// Searches of the hull's thin parts in a row that found no trusted fit, since the first
    /// trusted one (before it, every frame set is searched).
    failed_searches: u32,
    /// Whether any frame set was trusted yet.
    trusted_once: bool,
    /// Frame sets labelled since the last search.
    since_search: u32,
}

impl ToolLabeller {
    /// A labeller for the tool of `tool.json`.
    pub fn new(tool: &ToolGeometry, tracker: TrackerParams, params: LabelParams) -> Result<Self, ToolError> {
        let template = Template::new(tool)?;
        if tool.mesh.triangles.is_empty() {
            return Err(ToolError::Template("the tool's mesh has no triangles to draw".to_owned()));
        }
        // The tool is filled and its distance field gridded at 1 mm: `Template::new` has bounded
        // its size and refused non-finite numbers ([`crate::template::check_tool`]).
        // Padded by 2 cm over the margin: a cell farther than that from the tool is not near it
        // unless it is over 2 cm large, and those are told by the grid's distance.
        let field = ToolField::new(&tool_points(&tool.mesh, 0.001), 0.001, params.tool_margin_m + 0.02);
        Ok(ToolLabeller {
            tracker: Tracker::new(template, tracker),
            mesh: Arc::new(tool.mesh.clone()),
            field,
            params,
            unoccluded: false,
            draw: true,
            failed_searches: 0,
            trusted_once: false,
            since_search: 0,
        })
    }

    /// Searches the hull's thin parts for a lost tool on one frame set in at most `gap` while the
    /// searches before found nothing ([`LabelParams::max_search_gap`]; 1: on every frame set).
    pub fn set_max_search_gap(&mut self, gap: u32) {
        self.params.max_search_gap = gap.max(1);
    }

    /// The tracker (its template and settings).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// Whether [`ToolLabeller::label`] also lists, per view, the drawn tool's foreground pixels
    /// that no cell of the hand's hull lies in front of ([`LabelledFrame::unoccluded`]; off by
    /// default: it splats every such cell once more per view).
    pub fn list_unoccluded(&mut self, on: bool) {
        self.unoccluded = on;
    }

    /// Whether [`ToolLabeller::label`] draws the fitted tool into the views and labels them (on
    /// by default). Off, a fitted frame set gets the hull's cells near the tool labelled and its
    /// pose, but no label masks ([`LabelledFrame::masks`] `None` for every view), no tool regions
    /// and no unoccluded pixels: for a loop that uses only the hull and the pose on most frame
    /// sets, the drawing is most of the labelling's time.
    pub fn draw_labels(&mut self, on: bool) {
        self.draw = on;
    }

    /// What draws the fitted tool into the views as [`ToolLabeller::label`] does, to draw a
    /// frame set's labels that it did not draw ([`ToolLabeller::draw_labels`]) later.
    pub fn drawer(&self) -> ToolDrawer {
        ToolDrawer { mesh: Arc::clone(&self.mesh), occlusion_margin_m: self.params.occlusion_margin_m }
    }

    /// The blade's outline in `camera` with the tool at `tool_to_world`: the convex hull of its
    /// projected outline (counter-clockwise pixels; fewer than three where it barely projects).
    pub fn blade_outline(&self, camera: &Camera, tool_to_world: &Isometry3<f64>) -> Vec<Point2<f64>> {
        let radius = camera.distortion.monotonic_radius();
        let pixels: Vec<Point2<f64>> = self
            .tracker
            .template()
            .blade
            .iter()
            .filter_map(|p| project(camera, radius, &(tool_to_world * p)))
            .collect();
        convex_hull(&pixels)
    }

    /// Which cells of `occ` come within `margin` metres of the tool where its track predicts it
    /// at `timestamp_ns` (`None` while the track predicts nothing): cells of an object, whatever
    /// their shading says.
    pub fn near_predicted(&self, timestamp_ns: i64, occ: &Occupancy, margin: f64) -> Option<Vec<bool>> {
        let pose = self.tracker.predicted(timestamp_ns)?;
        Some(near_tool(occ, &self.field, &pose, margin, &[]).cells.iter().map(|c| c.scalpel).collect())
    }

    /// The tool drawn in `camera` where its track predicts it at `timestamp_ns` (`None` while the
    /// track predicts nothing, or where it is out of the view).
    pub fn predicted_region(&self, timestamp_ns: i64, camera: &Camera) -> Option<ToolRegion> {
        let pose = self.tracker.predicted(timestamp_ns)?;
        ToolDepth::draw(camera, camera.distortion.monotonic_radius(), &self.mesh, &pose).map(|d| d.region())
    }

    /// Labels one frame set: `occ` is the hull of the views' foreground, `views` their foreground
    /// masks (any non-zero label is foreground), one entry per rig camera. A foreground pixel may
    /// carry a hint for the fit: [`label::HAND`] where its colour is surely the hand's,
    /// [`label::SCALPEL`] where surely the tool's, [`POSSIBLE_SHADOW`] where it may be a cast
    /// shadow; any other value decides nothing. `table`, where the world frame's z = 0 is the
    /// table top: the views' masks before their possible shadows were resolved, which tell the
    /// hand's shadow on the table beside the tool from a dull tool over it. `not_hand` marks (by
    /// index; shorter or empty marks none) cells of `occ` that are no evidence of the hand (kept
    /// only as possible parts of the tool, which may be its shadow): away from the fitted tool
    /// they hide nothing and are labelled neither hand nor scalpel.
    pub fn label(
        &mut self,
        frame: u64,
        timestamp_ns: i64,
        occ: &Occupancy,
        not_hand: &[bool],
        views: &[Option<ViewInput>],
        table: Option<&TableShadows>,
    ) -> LabelledFrame {
        let mut stats = LabelStats::default();
        let clock = Instant::now();
        let template = self.tracker.template().clone();
        let few_views = views.iter().flatten().count() < MANY_VIEWS;
        let provisional_for = |pose: &Isometry3<f64>| {
            let hull = near_tool(occ, &self.field, pose, self.params.tool_margin_m, not_hand);
            let hand = HandCells::new(
                hull.cells.iter().filter(|c| c.hand).copied().collect(),
                hull.cells.iter().filter(|c| !c.hand && !c.scalpel).copied().collect(),
            );
            let masks: Vec<Option<GrayImage>> = views
                .par_iter()
                .enumerate()
                .map(|(k, v)| {
                    v.map(|v| {
                        let radius = v.camera.distortion.monotonic_radius();
                        let depth = ToolDepth::draw(v.camera, radius, &self.mesh, pose);
                        let in_front = HandInFront {
                            hand: &hand,
                            tool: depth.as_ref(),
                            margin: self.params.occlusion_margin_m,
                            tool_colour_decides: few_views,
                        };
                        let band =
                            Band { px: self.params.band_px, roll_deg: self.params.roll_deg, fill_holes: !few_views };
                        band_labels(v, &template, pose, band, &in_front, table.map(|t| (t, k)))
                    })
                })
                .collect();
            (masks, hull)
        };
        // Each way to start is tried on a copy of the tracker; the best copy becomes the tracker.
        let score = |e: &PoseEstimate| {
            (e.fitted.is_some(), e.valid, e.confidence, e.diagnostics.explained * e.diagnostics.covered)
        };
        let mut best: Option<(Tracker, PoseEstimate)> = None;
        let consider = |probe: Tracker, e: PoseEstimate, best: &mut Option<(Tracker, PoseEstimate)>| {
            if best.as_ref().is_none_or(|(_, b)| score(&e).partial_cmp(&score(b)).is_some_and(|o| o.is_gt())) {
                *best = Some((probe, e));
            }
        };
        let fit_with = |tracker: &Tracker, (masks, hull): &(Vec<Option<GrayImage>>, Occupancy)| {
            let mut probe = tracker.clone();
            let e = probe.update(frame, timestamp_ns, hull, &inputs(views, masks));
            (probe, e)
        };
        let mut evidence_ms = 0.0;
        let mut timed_evidence = |f: &dyn Fn() -> (Vec<Option<GrayImage>>, Occupancy)| {
            let clock = Instant::now();
            let out = f();
            evidence_ms += clock.elapsed().as_secs_f64() * 1e3;
            out
        };
        // From the track's prediction.
        if let Some(pose) = self.tracker.predicted(timestamp_ns) {
            let evidence = timed_evidence(&|| provisional_for(&pose));
            let (probe, e) = fit_with(&self.tracker, &evidence);
            consider(probe, e, &mut best);
        }
        // From the hull's thin parts, when the track gave nothing trusted: each of the largest thin
        // components in turn as the tool, then the evidence around the best first fit; paced while
        // the searches before found nothing ([`LabelParams::max_search_gap`]).
        self.since_search = self.since_search.saturating_add(1);
        let tracked = best.as_ref().is_some_and(|(_, e)| e.valid);
        let gap = search_gap(self.failed_searches, self.params.max_search_gap);
        stats.search_paused = !tracked && self.since_search < gap;
        if tracked {
            self.failed_searches = 0;
        } else if !stats.search_paused {
            self.since_search = 0;
            stats.from_thin_parts = true;
            let (thin, components) = thin_parts(occ, self.params.thin_radius_m);
            stats.thin_leaves = components.iter().map(Vec::len).sum();
            let mut first: Option<PoseEstimate> = None;
            for component in components.iter().take(INIT_COMPONENTS).filter(|c| c.len() >= 3) {
                let evidence = timed_evidence(&|| {
                    let hull = only(&thin, component);
                    (views.iter().map(|v| v.map(|v| thin_labels(v, &hull))).collect(), hull)
                });
                let (_, e) = fit_with(&self.tracker, &evidence);
                if first.as_ref().is_none_or(|b| score(&e).partial_cmp(&score(b)).is_some_and(|o| o.is_gt())) {
                    first = Some(e);
                }
            }
            if let Some(pose) = first.and_then(|e| e.fitted).map(|p| p.tool_to_world) {
                let evidence = timed_evidence(&|| provisional_for(&pose));
                let (probe, e) = fit_with(&self.tracker, &evidence);
                consider(probe, e, &mut best);
            }
            let found = best.as_ref().is_some_and(|(_, e)| e.valid);
            self.failed_searches = if found || !self.trusted_once { 0 } else { self.failed_searches.saturating_add(1) };
        }
        stats.evidence_ms = evidence_ms;
        stats.fit_ms = clock.elapsed().as_secs_f64() * 1e3 - evidence_ms;
        let estimate = match best {
            Some((tracker, e)) => {
                self.tracker = tracker;
                e
            }
            None if stats.search_paused => self.tracker.refuse_unfitted(
                frame,
                timestamp_ns,
                views.iter().flatten().count(),
                format!(
                    "the hull is searched for the tool on one frame set in {gap}: the last {} searches found no trusted fit",
                    self.failed_searches
                ),
            ),
            None => {
                // Nothing to fit: the tracker's own refusal (and its held pose).
                self.tracker.update(frame, timestamp_ns, occ, &inputs(views, &[]))
            }
        };
        self.trusted_once |= estimate.valid;
        let clock = Instant::now();
        let (masks, occupancy, tool_regions, unoccluded) = match &estimate.fitted {
            Some(fitted) if !self.draw => {
                let occupancy = near_tool(occ, &self.field, &fitted.tool_to_world, self.params.tool_margin_m, not_hand);
                (vec![None; views.len()], occupancy, vec![None; views.len()], Vec::new())
            }
            Some(fitted) => {
                let pose = fitted.tool_to_world;
                let occupancy = near_tool(occ, &self.field, &pose, self.params.tool_margin_m, not_hand);
                let drawn =
                    draw_views(&self.mesh, self.params.occlusion_margin_m, views, &occupancy, &pose, self.unoccluded);
                stats.scalpel_pixels += drawn.scalpel_pixels;
                stats.hidden_pixels += drawn.hidden_pixels;
                (drawn.masks, occupancy, drawn.tool_regions, drawn.unoccluded)
            }
            None => {
                let masks = views
                    .iter()
                    .map(|v| {
                        v.map(|v| {
                            let mut m = v.mask.clone();
                            for p in m.iter_mut().filter(|p| **p != label::BACKGROUND) {
                                *p = label::UNKNOWN;
                                stats.unknown_pixels += 1;
                            }
                            m
                        })
                    })
                    .collect();
                (masks, occ.clone(), vec![None; views.len()], Vec::new())
            }
        };
        stats.draw_ms = clock.elapsed().as_secs_f64() * 1e3;
        LabelledFrame { estimate, masks, occupancy, tool_regions, unoccluded, stats }
    }
}

/// A fitted tool drawn into the views ([`ToolDrawer::draw`]).
#[derive(Debug)]
pub struct DrawnViews {
    /// Per view (rig order): 0 background, 1 hand, 2 scalpel, 255 unknown; `None` for a missing
    /// view.
    pub masks: Vec<Option<GrayImage>>,
    /// Per view: where the tool's mesh is drawn, hidden or not.
    pub tool_regions: Vec<Option<ToolRegion>>,
    /// Per view (empty unless asked for): the foreground pixels where the tool is drawn and no
    /// cell of the hand's hull lies in front of it ([`LabelledFrame::unoccluded`]).
    pub unoccluded: Vec<Vec<usize>>,
    /// Pixels labelled scalpel, over the views.
    pub scalpel_pixels: u64,
    /// Pixels of the drawn tool the hand hides, over the views.
    pub hidden_pixels: u64,
}

/// What draws a fitted tool into the views to label them ([`ToolLabeller::drawer`]): the tool's
/// mesh (shared, not copied) and the occlusion margin. It keeps no state from frame set to frame
/// set, so a fitted frame set's labels can be drawn later, on another thread, from what its
/// labelling saw (the views' foreground, the hull with the tool's cells labelled, the fitted
/// pose): the same labels as [`ToolLabeller::label`] draws.
#[derive(Debug, Clone)]
pub struct ToolDrawer {
    mesh: Arc<Mesh>,
    occlusion_margin_m: f64,
}

impl ToolDrawer {
    /// The tool at `pose` drawn into `views` and their foreground labelled, the hand's cells of
    /// `occupancy` (the foreground's hull, its cells near the tool labelled: [`LabelledFrame::occupancy`])
    /// hiding it where they lie in front of it; with `unoccluded`, the drawn tool's pixels no
    /// hand cell hides listed too.
    pub fn draw(
        &self,
        views: &[Option<ViewInput>],
        occupancy: &Occupancy,
        pose: &Isometry3<f64>,
        unoccluded: bool,
    ) -> DrawnViews {
        draw_views(&self.mesh, self.occlusion_margin_m, views, occupancy, pose, unoccluded)
    }
}

/// [`ToolDrawer::draw`]'s work.
fn draw_views(
    mesh: &Mesh,
    occlusion_margin_m: f64,
    views: &[Option<ViewInput>],
    occupancy: &Occupancy,
    pose: &Isometry3<f64>,
    unoccluded: bool,
) -> DrawnViews {
    // The tool drawn into every view, and the hull's cells labelled from those
    // drawings: a cell is the hand's only where views see foreground the tool does not
    // explain (the tool's own hull, fatter than the tool, hides nothing).
    // Per view, in one task each: the tool drawn into it; its labels with the hull's
    // cells judged against that drawing, for the occluders below: the hull's hand
    // cells (labelled from those drawings) whose footprint in that very view holds hand
    // pixels, i.e. cells that view can see as hand (a cell of the hand's hull that the
    // view sees only where the tool is drawn is the hull's fat, a phantom in front of
    // the tool, not what hides it; only the cells near the tool are judged, so the
    // drawings are counted pixel by pixel, not tabled); and the cells drawn over the
    // tool there: only cells drawn over the tool in some view can hide it, the others
    // are neither relabelled nor judged.
    let margin = occlusion_margin_m + occupancy.leaf_size;
    let runs = CellRun::split(&occupancy.cells);
    type PerView = (Option<ToolDepth>, Option<Silhouette>, Vec<(usize, DrawnBox)>);
    let per_view: Vec<PerView> = views
        .par_iter()
        .map(|v| {
            let Some(v) = v else { return (None, None, Vec::new()) };
            let d = ToolDepth::draw(v.camera, v.camera.distortion.monotonic_radius(), mesh, pose);
            let sil = Silhouette::direct(v.camera, labels_without_occlusion(*v, d.as_ref()));
            let over = d.as_ref().map_or_else(Vec::new, |d| d.cells_over(v.camera, &occupancy.cells, &runs, margin));
            (d, Some(sil), over)
        })
        .collect();
    let mut drawn = Vec::with_capacity(views.len());
    let mut sil = Vec::with_capacity(views.len());
    let mut over = Vec::with_capacity(views.len());
    for (d, s, o) in per_view {
        drawn.push(d);
        sil.push(s);
        over.push(o);
    }
    let mut wanted: Vec<usize> = over.iter().flatten().map(|(i, _)| *i).collect();
    wanted.sort_unstable();
    wanted.dedup();
    let params =
        HullParams::new(hullcut_hull::Aabb { min: occupancy.origin, max: occupancy.origin }, occupancy.leaf_size);
    let near = Occupancy {
        cells: wanted.iter().map(|&i| occupancy.cells[i]).collect(),
        stats: occupancy.stats.clone(),
        leaf_size: occupancy.leaf_size,
        origin: occupancy.origin,
        resolution: occupancy.resolution,
    };
    let mut hand = vec![false; occupancy.cells.len()];
    let (relabelled, hand_seen) = hullcut_hull::relabel(&near, &sil, &params);
    // Where each wanted cell sits in `wanted` (and in `hand_seen`'s rows).
    let mut row = vec![usize::MAX; occupancy.cells.len()];
    for (r, (&i, l)) in wanted.iter().zip(&relabelled.cells).enumerate() {
        hand[i] = l.hand && !l.scalpel;
        row[i] = r;
    }
    let n = sil.len();
    let occluders: Vec<Vec<DrawnBox>> = sil
        .iter()
        .zip(&over)
        .enumerate()
        .map(|(v, (s, over))| match s {
            Some(_) => over.iter().filter(|(i, _)| hand[*i] && hand_seen[row[*i] * n + v]).map(|(_, b)| *b).collect(),
            None => Vec::new(),
        })
        .collect();
    let labelled: Vec<Option<(GrayImage, u64, u64)>> = views
        .par_iter()
        .zip(drawn.par_iter())
        .zip(occluders.par_iter())
        .map(|((v, d), o)| v.map(|v| final_labels(v, d.as_ref(), o, margin)))
        .collect();
    let (mut scalpel_pixels, mut hidden_pixels) = (0, 0);
    let masks = labelled
        .into_iter()
        .map(|l| {
            l.map(|(mask, scalpel, hidden)| {
                scalpel_pixels += scalpel;
                hidden_pixels += hidden;
                mask
            })
        })
        .collect();
    let tool_regions = drawn.iter().map(|d| d.as_ref().map(ToolDepth::region)).collect();
    let unoccluded = if unoccluded {
        views
            .par_iter()
            .zip(drawn.par_iter())
            .zip(over.par_iter())
            .map(|((v, d), over)| match (v, d) {
                (Some(v), Some(d)) => d.unoccluded(v.mask, over.iter().map(|(_, b)| *b), margin),
                _ => Vec::new(),
            })
            .collect()
    } else {
        Vec::new()
    };
    DrawnViews { masks, tool_regions, unoccluded, scalpel_pixels, hidden_pixels }
}

/// A view's labels with the tool drawn (`tool`): scalpel where it covers foreground, unless a
/// hand cell (its [`drawn_box`] among `hand_cells`) lies in front of it there (within `margin`: the occlusion margin and the hull's leaf); the rest of the
/// foreground hand. With the pixels labelled scalpel and those the hand hides.
fn final_labels(
    view: ViewInput,
    tool: Option<&ToolDepth>,
    hand_cells: &[DrawnBox],
    margin: f64,
) -> (GrayImage, u64, u64) {
    let mut out = all_hand(view.mask);
    let Some(tool) = tool else { return (out, 0, 0) };
    let (mut scalpel, mut hidden_pixels) = (0, 0);
    let mut hand = vec![f32::INFINITY; tool.depth.len()];
    for &(lo, hi, z) in hand_cells {
        tool.splat_min(&mut hand, lo, hi, (z + margin) as f32);
    }
    let (w, raw) = (out.width() as usize, view.mask.as_raw());
    // 0 outside the tool or on background, 1 visible tool, 2 hidden by the hand.
    let state: Vec<u8> = tool
        .depth
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            let px = (tool.y0 + k / tool.w) * w + tool.x0 + k % tool.w;
            if !d.is_finite() || raw[px] == label::BACKGROUND {
                0
            } else if hand[k] < d {
                2
            } else {
                1
            }
        })
        .collect();
    // The hand's hull is coarser than the pixels: where a finger crosses the tool, slivers of
    // the tool's drawing slip past its cells. A visible pixel with more hidden than visible
    // tool pixels around it (5x5) is hidden too.
    let h = state.len() / tool.w.max(1);
    for (k, &st) in state.iter().enumerate() {
        if st == 0 {
            continue;
        }
        let (i, j) = (k % tool.w, k / tool.w);
        let mut hidden = st == 2;
        if !hidden {
            let (mut vis, mut hid) = (0, 0);
            for y in j.saturating_sub(2)..(j + 3).min(h) {
                for x in i.saturating_sub(2)..(i + 3).min(tool.w) {
                    match state[y * tool.w + x] {
                        1 => vis += 1,
                        2 => hid += 1,
                        _ => {}
                    }
                }
            }
            hidden = hid > vis;
        }
        let px = (tool.y0 + j) * w + tool.x0 + i;
        if hidden {
            hidden_pixels += 1;
        } else {
            out.as_mut()[px] = label::SCALPEL;
            scalpel += 1;
        }
    }
    (out, scalpel, hidden_pixels)
}

/// `mask` with all its foreground the hand's (every pixel stored, without a branch, so the pass
/// vectorizes).
fn all_hand(mask: &GrayImage) -> GrayImage {
    // One pass that writes the new image, not a copy and a pass over the copy.
    let raw = mask.as_raw().iter().map(|&p| if p == label::BACKGROUND { label::BACKGROUND } else { label::HAND });
    let (w, h) = mask.dimensions();
    // The sizes agree: a new image is never made.
    GrayImage::from_raw(w, h, raw.collect()).unwrap_or_else(|| GrayImage::new(w, h))
}

/// Foreground covered by the drawn tool: scalpel, whatever may hide it; other foreground: hand.
fn labels_without_occlusion(view: ViewInput, tool: Option<&ToolDepth>) -> GrayImage {
    let mut out = all_hand(view.mask);
    let w = out.width() as usize;
    let raw = out.as_mut();
    if let Some(tool) = tool {
        for (k, d) in tool.depth.iter().enumerate() {
            let px = (tool.y0 + k / tool.w) * w + tool.x0 + k % tool.w;
            if d.is_finite() && raw[px] == label::HAND {
                raw[px] = label::SCALPEL;
            }
        }
    }
    out
}

fn inputs<'a>(views: &[Option<ViewInput<'a>>], masks: &'a [Option<GrayImage>]) -> Vec<Option<ViewInput<'a>>> {
    views
        .iter()
        .zip(masks)
        .map(|(v, m)| v.zip(m.as_ref()).map(|(v, mask)| ViewInput { camera: v.camera, mask, image: v.image }))
        .collect()
}

/// The tool's silhouette in a view as the fit models it: the projected blade polygon and the
/// convex hull of the projected body.
fn silhouette(cam: &Camera, radius: f64, template: &Template, pose: &Isometry3<f64>) -> Vec<Vec<Point2<f64>>> {
    let part = |points: &[Point3<f64>]| {
        let pixels: Vec<Point2<f64>> = points.iter().filter_map(|p| project(cam, radius, &(pose * p))).collect();
        convex_hull(&pixels)
    };
    [part(&template.blade), part(&template.body)].into_iter().filter(|p| p.len() >= 3).collect()
}

/// Foreground within `band` pixels of the tool's modelled silhouette: scalpel, unless its colour
/// is surely the hand's (a [`label::HAND`] hint in the view's mask), or it may be a shadow
/// ([`POSSIBLE_SHADOW`]) away from the drawn tool, or a pixel from it that the other views see on
/// the table (`table`: the views' shadows and this view's index), or a cell of the hand's hull that is not behind
/// the tool projects onto it (a finger along the tool, or the hand in front of it: its outline is
/// not the tool's; see [`HandInFront`]) and its colour is not surely the tool's (a
/// [`label::SCALPEL`] hint); other foreground: hand.
fn band_labels(
    view: ViewInput,
    template: &Template,
    pose: &Isometry3<f64>,
    band: Band,
    hand: &HandInFront,
    table: Option<(&TableShadows, usize)>,
) -> GrayImage {
    let cam = view.camera;
    let radius = cam.distortion.monotonic_radius();
    let polygons = rolled_silhouette(cam, radius, template, pose, band.roll_deg);
    let Band { px: band, fill_holes, .. } = band;
    let hints = view.mask.as_raw();
    let mut out = all_hand(view.mask);
    let (w, h) = (out.width() as usize, out.height() as usize);
    let raw = out.as_mut();
    let mut scalpel = PixelBox::new(h);
    for poly in &polygons {
        for (j, a, b) in band_rows(poly, band, w, h) {
            for i in a..=b {
                let k = j * w + i;
                let hint = hints[k];
                let shadow_beside = possible_shadow(hint)
                    && match hand.tool {
                        Some(t) if t.at(i, j).is_some() => false,
                        Some(t) if t.near(i, j, SHADOW_REACH_PX) => {
                            table.is_some_and(|(t, view)| t.on_table(view, i, j))
                        }
                        _ => true,
                    };
                if raw[k] == label::HAND && hint != label::HAND && hint != TABLE_SHADOW && !shadow_beside {
                    raw[k] = label::SCALPEL;
                    scalpel.add(i, j);
                }
            }
        }
    }
    clear_hand(&mut out, view.camera, radius, hand, hints, &scalpel);
    if fill_holes {
        fill_evidence_holes(&mut out, &scalpel);
    }
    out
}

/// Fills the holes of the fit's evidence `labels` near its scalpel pixels (`scalpel`, their box
/// widened by [`HOLE_MARGIN_PX`]) of up to [`HOLE_AREA`] of the view's pixels with
/// [`label::UNKNOWN`]: foreground the tool may cover, and no outline of it.
///
/// Only on rigs of six views or more ([`MANY_VIEWS`]): on fewer, two views that see the blade
/// edge-on stand in for a third that sees its face only where the silhouettes fix its turn about
/// its long axis, and a gap between a finger and the blade seen edge-on, filled, let the blade
/// turn across it and fit as well (random:1307 in random:1193, four cameras, the first 30 frame
/// sets: 11 -> 8 trusted, right fits refused as free to turn). Filled only where the tool's own
/// pixels close a hole, they lost random:1733 in random:1787 its gain (135 -> 15 trusted): there
/// the hand's labels close most holes of the handle too.
fn fill_evidence_holes(labels: &mut GrayImage, scalpel: &PixelBox) {
    if scalpel.is_empty() {
        return;
    }
    let (w, h) = (labels.width() as usize, labels.height() as usize);
    let (x0, y0) = (scalpel.lo.0.saturating_sub(HOLE_MARGIN_PX), scalpel.lo.1.saturating_sub(HOLE_MARGIN_PX));
    let (x1, y1) = ((scalpel.hi.0 + HOLE_MARGIN_PX + 1).min(w), (scalpel.hi.1 + HOLE_MARGIN_PX + 1).min(h));
    let max_area = (HOLE_AREA * (w * h) as f64) as usize;
    crate::holes::fill_holes(labels.as_mut(), w, (x0, y0, x1 - x0, y1 - y0), (max_area, label::UNKNOWN));
}

/// Where [`band_labels`] takes the fit's evidence: within `px` pixels of the tool's outline, the
/// tool as predicted and as rolled `roll_deg` either way ([`LabelParams::roll_deg`]).
#[derive(Debug, Clone, Copy)]
struct Band {
    px: f64,
    roll_deg: f64,
    /// Whether the evidence's small holes near the tool are filled ([`fill_evidence_holes`]).
    fill_holes: bool,
}

/// The convex outline of each part of the tool (blade, body) in a view at `pose` and at `pose`
/// rolled by `roll_deg` either way about the blade's long axis (its centre to its tip): one
/// polygon per part holding its three drawings ([`silhouette`] at a roll of 0).
fn rolled_silhouette(
    cam: &Camera,
    radius: f64,
    template: &Template,
    pose: &Isometry3<f64>,
    roll_deg: f64,
) -> Vec<Vec<Point2<f64>>> {
    let axis = nalgebra::Unit::try_new(template.tip - template.blade_centre, 1e-9);
    let Some(axis) = axis.filter(|_| roll_deg > 0.0 && roll_deg.is_finite()) else {
        return silhouette(cam, radius, template, pose);
    };
    let c = template.blade_centre;
    let rolled = [-roll_deg, roll_deg].map(|deg| {
        let turn = nalgebra::UnitQuaternion::from_axis_angle(&axis, deg.to_radians());
        // About the axis through the blade's centre, in the tool's frame.
        pose * Isometry3::from_parts((c.coords - turn * c.coords).into(), turn)
    });
    let part = |points: &[Point3<f64>]| {
        let pixels: Vec<Point2<f64>> = std::iter::once(pose)
            .chain(&rolled)
            .flat_map(|at| points.iter().filter_map(move |p| project(cam, radius, &(at * p))))
            .collect();
        convex_hull(&pixels)
    };
    [part(&template.blade), part(&template.body)].into_iter().filter(|p| p.len() >= 3).collect()
}

/// The box of a view's scalpel pixels and each row's first and last of them (empty until one is
/// added).
#[derive(Debug, Clone, PartialEq)]
struct PixelBox {
    lo: (usize, usize),
    hi: (usize, usize),
    /// Per image row: its first and last column added (first > last: none).
    rows: Vec<(usize, usize)>,
}

impl PixelBox {
    /// No pixel yet, in an image `height` rows high.
    fn new(height: usize) -> Self {
        PixelBox { lo: (usize::MAX, usize::MAX), hi: (0, 0), rows: vec![(usize::MAX, 0); height] }
    }

    /// Adds pixel (`i`, `j`) (a row beyond the image's height is ignored).
    fn add(&mut self, i: usize, j: usize) {
        let Some(row) = self.rows.get_mut(j) else { return };
        *row = (row.0.min(i), row.1.max(i));
        self.lo = (self.lo.0.min(i), self.lo.1.min(j));
        self.hi = (self.hi.0.max(i), self.hi.1.max(j));
    }

    fn is_empty(&self) -> bool {
        self.lo.0 > self.hi.0
    }

    /// The box of the pixels of `labels` valued `value`.
    #[cfg(test)]
    fn of(labels: &GrayImage, value: u8) -> Self {
        let mut b = PixelBox::new(labels.height() as usize);
        for (i, j, p) in labels.enumerate_pixels() {
            if p.0[0] == value {
                b.add(i as usize, j as usize);
            }
        }
        b
    }
}

/// The hand's hull cells that may take pixels of the tool's band from it, with what tells a cell
/// behind the tool in a view: the tool drawn with its depth (`None`: no depth known, no cell
/// behind).
struct HandInFront<'a> {
    /// The hull's cells away from the tool.
    hand: &'a HandCells,
    /// The tool drawn into the view.
    tool: Option<&'a ToolDepth>,
    /// A cell is behind the tool at a pixel where its nearest point lies this much farther from
    /// the camera than the tool drawn there, metres.
    margin: f64,
    /// Whether a [`TOOL_COLOURED_SHADOW`] keeps its pixel from the cells (fewer than six views).
    tool_colour_decides: bool,
}

/// The hull's cells away from the tool, in runs ([`CellRun`]) that [`clear_hand`] rules out
/// together where none of their cells can reach the tool's band.
struct HandCells {
    /// The hand's cells.
    cells: Vec<hullcut_hull::Cell>,
    /// Cells that may be no object at all (a shadow kept beside the tool): they take band pixels
    /// beside the drawn tool, never one where it is drawn.
    doubtful: Vec<hullcut_hull::Cell>,
    /// `cells` in runs.
    runs: Vec<CellRun>,
    /// `doubtful` in runs.
    doubtful_runs: Vec<CellRun>,
}

impl HandCells {
    fn new(cells: Vec<hullcut_hull::Cell>, doubtful: Vec<hullcut_hull::Cell>) -> Self {
        let (runs, doubtful_runs) = (CellRun::split(&cells), CellRun::split(&doubtful));
        HandCells { cells, doubtful, runs, doubtful_runs }
    }
}

/// The pixels of a `w`×`h` image within `band` of the convex `polygon` (counter-clockwise, as
/// [`convex_hull`] gives it), as (row, first column, last column); a band that is negative or not
/// a number holds none.
fn band_rows(polygon: &[Point2<f64>], band: f64, w: usize, h: usize) -> Vec<(usize, usize, usize)> {
    let (mut lo, mut hi) = (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN));
    for q in polygon {
        lo = lo.inf(q);
        hi = hi.sup(q);
    }
    let (i0, j0) = ((lo.x - band).floor().max(0.0) as usize, (lo.y - band).floor().max(0.0) as usize);
    let (i1, j1) = ((hi.x + band).ceil().min(w as f64 - 1.0), (hi.y + band).ceil().min(h as f64 - 1.0));
    if i1 < i0 as f64 || j1 < j0 as f64 || polygon.len() < 2 || band.is_nan() || band < 0.0 {
        return Vec::new();
    }
    let grown = GrownPolygon::new(polygon, band);
    (j0..=j1 as usize)
        .filter_map(|j| {
            let (a, b) = grown.row(j as f64)?;
            let (a, b) = (a.ceil().max(i0 as f64), b.floor().min(i1));
            (a <= b).then_some((j, a as usize, b as usize))
        })
        .collect()
}

/// A convex polygon grown by a distance: the points within that distance of it (the polygon
/// swept by a disc), cut row by row in closed form.
struct GrownPolygon {
    /// The polygon's vertices (at least two).
    vertices: Vec<Point2<f64>>,
    /// Each edge's sides pushed out by the distance either way: a parallelogram per edge, as
    /// its four corners in order.
    slabs: Vec<[Point2<f64>; 4]>,
    /// The distance.
    band: f64,
}

impl GrownPolygon {
    fn new(polygon: &[Point2<f64>], band: f64) -> Self {
        let n = polygon.len();
        let slabs = (0..n)
            .filter_map(|i| {
                let (a, b) = (polygon[i], polygon[(i + 1) % n]);
                let ab = b - a;
                let len = ab.norm();
                (len > 0.0).then(|| {
                    let off = Vector2::new(ab.y, -ab.x) * (band / len);
                    [a + off, b + off, b - off, a - off]
                })
            })
            .collect();
        GrownPolygon { vertices: polygon.to_vec(), slabs, band }
    }

    /// The row `y`'s stretch of the grown polygon, as its lowest and highest x (`None` where it
    /// misses): the grown polygon is convex and the union of the polygon, a disc around each
    /// vertex and a slab along each edge, so the stretch runs from the least to the greatest end
    /// of theirs.
    fn row(&self, y: f64) -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut take = |x: f64| {
            lo = lo.min(x);
            hi = hi.max(x);
        };
        for v in &self.vertices {
            let dy = y - v.y;
            let r2 = self.band * self.band - dy * dy;
            if r2 >= 0.0 {
                let r = r2.sqrt();
                take(v.x - r);
                take(v.x + r);
            }
        }
        let mut crossings = |corners: &[Point2<f64>]| {
            for (k, p) in corners.iter().enumerate() {
                let q = corners[(k + 1) % corners.len()];
                if (p.y <= y && y <= q.y) || (q.y <= y && y <= p.y) {
                    if p.y == q.y {
                        take(p.x);
                        take(q.x);
                    } else {
                        take(p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y));
                    }
                }
            }
        };
        crossings(&self.vertices);
        for slab in &self.slabs {
            crossings(slab);
        }
        (lo <= hi).then_some((lo, hi))
    }
}

/// Gives the scalpel pixels of `labels` that a cell of `hand` projects onto back to the hand: the
/// cell is a disc around its centre's projection whose radius is its half-diagonal's (enough to
/// cover its footprint, which is what matters along the tool's outline), except pixels whose colour
/// is surely the tool's (`hints`, the view's mask) and pixels where the tool is drawn in front of
/// the cell (its nearest point farther than the drawn depth plus the margin): the view sees the
/// tool there (the hand's hull, fatter than the hand, would otherwise hide the blade from every
/// view that sees the hand behind it). A band pixel beside the drawn tool that a cell covers is
/// the hand's, wherever the cell lies; a doubtful cell ([`HandCells::doubtful`]) takes only
/// those.
fn clear_hand<'a>(
    labels: &mut GrayImage,
    cam: &Camera,
    radius: f64,
    hand: &HandInFront<'a>,
    hints: &[u8],
    scalpel: &PixelBox,
) {
    // Cells projecting outside the scalpel pixels' box are skipped after one projection, and
    // each cell looks only at the scalpel pixels' stretch of each row (pixels only leave the
    // scalpel below, so the stretches found before hold every pixel that may change).
    if scalpel.is_empty() {
        return;
    }
    // Compiled for the widest vector instructions the processor has (pulp's run-time dispatch):
    // the cells' projections and discs, a batch at a time, are the same IEEE operations in the
    // same order on any of them, so the same labels.
    pulp::Arch::new().dispatch(ClearHand { labels, cam, radius, hand, hints, scalpel });
}

/// [`clear_hand`]'s arguments, for pulp's dispatch.
struct ClearHand<'a, 'b> {
    labels: &'b mut GrayImage,
    cam: &'b Camera,
    radius: f64,
    hand: &'b HandInFront<'a>,
    hints: &'b [u8],
    scalpel: &'b PixelBox,
}

impl pulp::WithSimd for ClearHand<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let ClearHand { labels, cam, radius, hand, hints, scalpel } = self;
        let (w, h) = (labels.width() as usize, labels.height() as usize);
        let PixelBox { lo, hi, rows } = scalpel;
        let (lo, hi) = (*lo, *hi);
        let f = cam.fx.max(cam.fy);
        // A run's ball holds its cells' centres, so their projections lie in its projected disc, and
        // each cell's disc below is at most `1.005 b f / (z - ρ)` wide (0.87 of a cell's side is
        // within 1.005 of its bounding radius, at most the run's largest, `b`, and no cell is nearer
        // than z - ρ): a run whose disc, so widened, misses the box holds no cell that reaches it (a
        // micro-pixel of slack for rounding). Widened by the run's ρ instead of `b`, four in five of
        // the hand's runs reached the box on the built-in scene.
        let bounds = (lo.0 as f64, lo.1 as f64, hi.0 as f64, hi.1 as f64);
        let (lo_x, lo_y, hi_x, hi_y) = bounds;
        let run_reaches = |run: &CellRun| {
            let pc = cam.world_to_camera(&run.centre);
            let z = pc.z;
            cam.project_ball_in_camera(&pc, run.radius, NEAR_M, radius).is_none_or(|(uv, r)| {
                let reach = r + 1.005 * run.cell_radius * f / (z - run.radius) + 1e-6;
                let (ja, jb) = ((uv.y - reach).ceil().max(lo_y), (uv.y + reach).floor().min(hi_y));
                uv.x + reach >= lo_x
                    && uv.x - reach <= hi_x
                    && ja <= jb
                    && rows[ja as usize..=jb as usize]
                        .iter()
                        .any(|&(a, b)| a as f64 <= uv.x + reach && b as f64 >= uv.x - reach)
            })
        };
        let raw = labels.as_mut();
        let groups =
            [(&hand.hand.cells, &hand.hand.runs, false), (&hand.hand.doubtful, &hand.hand.doubtful_runs, true)];
        // The reaching runs' cells, their centres projected a run at a time ([`project_batch`]).
        for (cells, runs, doubtful) in groups {
            for run in runs.iter().filter(|run| run_reaches(run)) {
                let run = &cells[run.start..run.end];
                let at = project_batch(cam, radius, run.len(), |k| run[k].centre());
                let discs = CellDiscs::within(&at, run.len(), |k| run[k].size, f, bounds);
                for (k, c) in run.iter().enumerate().filter(|&(k, _)| discs.keep[k]) {
                    let (i0, i1) = (discs.i0[k] as usize, discs.i1[k] as usize);
                    let (j0, j1) = (discs.j0[k] as usize, discs.j1[k] as usize);
                    let nearest = at.z[k] - 0.87 * c.size;
                    for j in j0..=j1.min(h - 1) {
                        let (a, b) = rows[j];
                        for i in i0.max(a)..=i1.min(w - 1).min(b) {
                            let k = j * w + i;
                            if raw[k] != label::SCALPEL
                                || hints[k] == label::SCALPEL
                                || (hand.tool_colour_decides && hints[k] == TOOL_COLOURED_SHADOW)
                            {
                                continue;
                            }
                            // A doubtful cell keeps its hands off the drawn tool; any other cell takes the
                            // pixel unless it lies behind the tool there.
                            let takes = match hand.tool.and_then(|t| t.at(i, j)) {
                                Some(d) => !doubtful && nearest <= d + hand.margin,
                                None => true,
                            };
                            if takes {
                                raw[k] = label::HAND;
                            }
                        }
                    }
                }
            }
        }
    }
}

/// A batch of projected cells' discs ([`clear_hand`]: radius `0.87 · size · f / z` around the
/// centre's pixel) within the scalpel pixels' box, their pixel bounds (`i0..=i1` columns,
/// `j0..=j1` rows) and whether to visit them (`keep`: projected, its disc meets the box by a
/// whole pixel). Branch-free over the batch's lanes, written for the auto-vectorizer.
struct CellDiscs {
    i0: [u32; BATCH],
    i1: [u32; BATCH],
    j0: [u32; BATCH],
    j1: [u32; BATCH],
    keep: [bool; BATCH],
}

impl CellDiscs {
    /// The discs of the first `len` cells of `at` (their sizes `size(k)`), against the box
    /// `(lo_x, lo_y, hi_x, hi_y)`; each bound as [`ceil_within_u32`] or
    /// [`floor_within_u32`] gives it.
    #[inline(always)]
    // The misses are negated as written cell by cell (`!(a < b)` holds for NaN, `a >= b` not).
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn within(
        at: &ProjectedBatch,
        len: usize,
        size: impl Fn(usize) -> f64,
        f: f64,
        (lo_x, lo_y, hi_x, hi_y): (f64, f64, f64, f64),
    ) -> Self {
        let len = len.min(BATCH);
        let mut sizes = [0.0; BATCH];
        for (k, s) in sizes.iter_mut().enumerate().take(len) {
            *s = size(k);
        }
        let mut out =
            CellDiscs { i0: [0; BATCH], i1: [0; BATCH], j0: [0; BATCH], j1: [0; BATCH], keep: [false; BATCH] };
        for k in 0..BATCH {
            let (u, v) = (at.u[k], at.v[k]);
            let r = 0.87 * sizes[k] * f / at.z[k];
            // Missing the box by a whole stretch: nothing would be visited.
            let meets = !(u + r < lo_x) & !(u - r > hi_x) & !(v + r < lo_y) & !(v - r > hi_y);
            let (i0, j0) = (ceil_within_u32(u - r, lo_x, hi_x), ceil_within_u32(v - r, lo_y, hi_y));
            let (i1, j1) = (floor_within_u32(u + r, lo_x, hi_x), floor_within_u32(v + r, lo_y, hi_y));
            (out.i0[k], out.i1[k], out.j0[k], out.j1[k]) = (i0, i1, j0, j1);
            out.keep[k] = at.ok[k] & meets & (i0 <= i1) & (j0 <= j1);
        }
        out
    }
}

/// `x.ceil()` clamped to `[lo, hi]` (whole numbers from 0 to below 2³², pixel coordinates): the
/// least whole number in the range at or above `x`, or `hi + 1` where there is none (`lo` for
/// NaN), without the library call `ceil` is where the build does not assume SSE4.1, and in 32
/// bits, which vectorize (four roundings per hand cell in [`clear_hand`]).
#[inline(always)]
fn ceil_within_u32(x: f64, lo: f64, hi: f64) -> u32 {
    // Whole numbers in [lo, hi + 1] convert exactly, and truncation is the floor there.
    let v = x.max(lo).min(hi + 1.0);
    let t = v as u32;
    t + u32::from((t as f64) < v)
}

/// `x.floor()` clamped to `[lo, hi]` (whole numbers from 0 to below 2³²; `hi` for NaN): see
/// [`ceil_within_u32`].
#[inline(always)]
fn floor_within_u32(x: f64, lo: f64, hi: f64) -> u32 {
    x.min(hi).max(lo) as u32
}

/// `x.ceil()`, the same value for every `x` (infinities and NaN as they are; 0 where the library
/// gives -0), without a call into the library, which `f64::ceil` is on baseline x86-64: four
/// roundings per cell [`ToolDepth::span`] tests (one thread, the built-in scene: segmentation
/// 4.61 -> 4.52 ms a frame set). Only where the values are mostly positive: the branch on a
/// random fraction mispredicts, and in the fit and carving such helpers were slower than the
/// library's SSE4.1 rounding (docs/benchmarks.md, "Calls across crates inlined").
#[inline]
fn ceil(x: f64) -> f64 {
    // From 2^52 on every number is whole; below, truncation toward zero is exact, and is the
    // ceiling of a negative number.
    if x.abs() < TWO_52 {
        let t = x as i64 as f64;
        if t < x { t + 1.0 } else { t }
    } else {
        x
    }
}

/// `x.floor()` exactly: see [`ceil`].
#[inline]
fn floor(x: f64) -> f64 {
    if x.abs() < TWO_52 {
        let t = x as i64 as f64;
        if t > x { t - 1.0 } else { t }
    } else {
        x
    }
}

/// 2^52: every `f64` at least this large in magnitude is a whole number.
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// Foreground covered by the projected scalpel cells of `hull` (the thin parts): scalpel; other
/// foreground: hand.
fn thin_labels(view: ViewInput, hull: &Occupancy) -> GrayImage {
    let cam = view.camera;
    let radius = cam.distortion.monotonic_radius();
    let mut out = all_hand(view.mask);
    let (w, h) = (out.width() as f64, out.height() as f64);
    let stride = out.width() as usize;
    let raw = out.as_mut();
    for c in hull.cells.iter().filter(|c| c.scalpel) {
        let (mut lo, mut hi) = (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN));
        let mut all = true;
        for k in 0..8 {
            let p = c.min + Vector3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64) * c.size;
            match project(cam, radius, &p) {
                Some(uv) => {
                    lo = lo.inf(&uv);
                    hi = hi.sup(&uv);
                }
                None => all = false,
            }
        }
        if !all {
            continue;
        }
        let (i0, j0) = (lo.x.ceil().max(0.0), lo.y.ceil().max(0.0));
        let (i1, j1) = (hi.x.floor().min(w - 1.0), hi.y.floor().min(h - 1.0));
        if i0 > i1 || j0 > j1 {
            continue;
        }
        for j in j0 as usize..=j1 as usize {
            for px in &mut raw[j * stride + i0 as usize..=j * stride + i1 as usize] {
                if *px == label::HAND {
                    *px = label::SCALPEL;
                }
            }
        }
    }
    out
}

/// The nearest a projected point may lie to the camera's plane, metres (as [`project`]).
const NEAR_M: f64 = 1e-3;

/// A hand cell as it is splatted over the drawn tool: the box of its eight projected corners
/// (lowest, highest) and its nearest corner's depth.
type DrawnBox = (Point2<f64>, Point2<f64>, f64);

/// The box of a cell's eight projected corners and the nearest corner's depth, as the drawn
/// depth of a hand cell is splatted (`None` unless every corner projects).
fn drawn_box(cam: &Camera, radius: f64, c: &hullcut_hull::Cell) -> Option<DrawnBox> {
    let (mut lo, mut hi, mut z) = (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN), f64::MAX);
    for k in 0..8 {
        let p = c.min + Vector3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64) * c.size;
        let pc = cam.world_to_camera(&p);
        let uv = project_camera_point(cam, radius, &pc)?;
        lo = lo.inf(&uv);
        hi = hi.sup(&uv);
        z = z.min(pc.z);
    }
    Some((lo, hi, z))
}

/// Points filling the tool (its surface and its inside, about `spacing` apart), in the tool frame.
fn tool_points(mesh: &Mesh, spacing: f64) -> Vec<Point3<f64>> {
    let mut points = hullcut_hull::accuracy::sample_surface(mesh, spacing);
    points.extend_from_slice(&mesh.vertices);
    let solid = hullcut_hull::accuracy::Solid::new(mesh);
    let (mut lo, mut hi) = (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
    for v in &mesh.vertices {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    let steps = ((hi - lo) / spacing).map(|d| (d.ceil() as usize).clamp(1, 2000));
    for i in 0..steps.x {
        for j in 0..steps.y {
            for k in 0..steps.z {
                let p = lo + Vector3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * spacing;
                if solid.winding(&p) >= 1 {
                    points.push(p);
                }
            }
        }
    }
    points
}

/// Distance to the tool, tool frame: a grid of `spacing` around the tool (padded by `pad`) holding
/// each node's distance to the nearest point filling the tool; beyond the grid, farther than `pad`.
#[derive(Debug, Clone)]
struct ToolField {
    /// The box of the points filling the tool (a lower bound of the distance to the tool).
    bounds: (Point3<f64>, Point3<f64>),
    origin: Point3<f64>,
    dims: [usize; 3],
    spacing: f64,
    pad: f64,
    distance: Vec<f32>,
}

/// `v` rounded to the nearest integer (halves away from zero, as [`f64::round`]) when that is
/// in `0..n`, without a call to the library's rounding (the build assumes no SSE4.1): the
/// truncation toward zero is one instruction, and `v` less its integer part is exact. The
/// point-by-point definition [`ToolField::lookup_batch`] rounds by, lane by lane (tested).
#[cfg(test)]
fn round_below(v: f64, n: usize) -> Option<usize> {
    // Rounds to -1 or below, or is not a number; and at or past `n`.
    if v.is_nan() || v <= -0.5 || v >= n as f64 {
        return None;
    }
    let whole = v as usize;
    let rounded = whole + usize::from(v - whole as f64 >= 0.5);
    (rounded < n).then_some(rounded)
}

/// What [`ToolField::lookup`] tells of a point without reading the grid.
#[cfg(test)]
#[derive(Debug, Clone, Copy)]
enum Lookup {
    /// Within reach or not, from the tool's box alone (or the grid's bound beyond it).
    Decided(bool),
    /// The grid node that decides.
    Node(usize),
}

impl ToolField {
    /// The field of `points` (filling the tool, tool frame).
    fn new(points: &[Point3<f64>], spacing: f64, pad: f64) -> Self {
        let (mut lo, mut hi) = (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if points.is_empty() {
            (lo, hi) = (Point3::origin(), Point3::origin());
        }
        let origin = lo - Vector3::repeat(pad);
        let dims = ((hi - lo + Vector3::repeat(2.0 * pad)) / spacing).map(|d| (d.ceil() as usize + 1).clamp(1, 4096));
        let dims = [dims.x, dims.y, dims.z];
        let mut feature = vec![false; dims[0] * dims[1] * dims[2]];
        for p in points {
            let k = (p - origin) / spacing;
            let [x, y, z] = [k.x, k.y, k.z].map(|v| v.round().max(0.0) as usize);
            if x < dims[0] && y < dims[1] && z < dims[2] {
                feature[(z * dims[1] + y) * dims[0] + x] = true;
            }
        }
        let distance = squared_distance(&feature, dims).iter().map(|d| (d.sqrt() * spacing) as f32).collect();
        ToolField { bounds: (lo, hi), origin, dims, spacing, pad, distance }
    }

    /// Whether [`ToolField::at`]`(p) <= reach` ([`near_tool`] decides each cell so, a cell's
    /// grid read put off to a pass of its own), without reading the grid where the box of the
    /// points filling the tool is out of reach: inside the grid its distance is between grid
    /// nodes, each within half a diagonal of its point, so it is at least the distance to that
    /// box less √3 spacings (two of slack); most points far from a slender tool stop there.
    #[cfg(test)]
    fn within(&self, p: &Point3<f64>, reach: f64) -> bool {
        match self.lookup(p, reach) {
            Lookup::Decided(near) => near,
            Lookup::Node(index) => self.node_within(index, reach),
        }
    }

    /// [`ToolField::within`] as far as it goes without reading the grid: decided, or the grid
    /// node to read. The point-by-point definition of [`ToolField::lookup_batch`] (tested).
    #[cfg(test)]
    fn lookup(&self, p: &Point3<f64>, reach: f64) -> Lookup {
        let Some(index) = self.node(p) else { return Lookup::Decided(self.at(p) <= reach) };
        let (lo, hi) = &self.bounds;
        let gap = (lo - p).sup(&(p - hi)).sup(&Vector3::zeros());
        let slack = reach + 2.0 * self.spacing;
        // A point with a coordinate that is not a number has no grid node: it never gets here.
        if gap.norm_squared() > slack * slack { Lookup::Decided(false) } else { Lookup::Node(index) }
    }

    /// [`ToolField::lookup`] of a batch of points, branch-free over the batch's lanes (written
    /// for the auto-vectorizer): the same operations in the same order as point by point
    /// ([`round_below`] for each coordinate, the box's gap, and [`ToolField::at`] beyond the
    /// grid), so the same answers (test `a_batch_looks_the_grid_up_as_point_by_point`).
    #[inline(always)]
    // The refusals are negated as written point by point (`!(v <= -0.5)` holds for NaN).
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn lookup_batch(&self, p: &PointBatch) -> LookedUp {
        let (lo, hi) = &self.bounds;
        let [nx, ny, nz] = self.dims;
        let (fx, fy, fz) = (nx as f64, ny as f64, nz as f64);
        let mut out = LookedUp { near: [false; BATCH], read: [false; BATCH], node: [0; BATCH] };
        // As `round_below`: the nearest whole number when it is in `0..n`.
        // Lanes out of range are refused, their sums free to wrap (a saturated `usize::MAX`).
        let round = |v: f64, n: usize, nf: f64| {
            let whole = v as usize;
            let rounded = whole.wrapping_add(usize::from(v - whole as f64 >= 0.5));
            let inside = !v.is_nan() & !(v <= -0.5) & !(v >= nf) & (rounded < n);
            (rounded, inside)
        };
        for k in 0..BATCH {
            let (kx, ky, kz) = (
                (p.x[k] - self.origin.x) / self.spacing,
                (p.y[k] - self.origin.y) / self.spacing,
                (p.z[k] - self.origin.z) / self.spacing,
            );
            let ((x, in_x), (y, in_y), (z, in_z)) = (round(kx, nx, fx), round(ky, ny, fy), round(kz, nz, fz));
            let in_grid = in_x & in_y & in_z;
            let node = z.wrapping_mul(ny).wrapping_add(y).wrapping_mul(nx).wrapping_add(x);
            // Inside the grid: the gap to the box of the points filling the tool.
            let gap = |lo: f64, v: f64, hi: f64| (lo - v).max(v - hi).max(0.0);
            let (gx, gy, gz) = (gap(lo.x, p.x[k], hi.x), gap(lo.y, p.y[k], hi.y), gap(lo.z, p.z[k], hi.z));
            let slack = p.reach[k] + 2.0 * self.spacing;
            let far = gx * gx + gy * gy + gz * gz > slack * slack;
            // Beyond it: `pad` plus the distance to the grid.
            let outside = |v: f64, nf: f64| (-v).max(v - (nf - 1.0)).max(0.0);
            let (dx, dy, dz) = (outside(kx, fx), outside(ky, fy), outside(kz, fz));
            let at = self.pad + (dx * dx + dy * dy + dz * dz).sqrt() * self.spacing;
            out.read[k] = in_grid & !far;
            out.near[k] = !in_grid & (at <= p.reach[k]);
            out.node[k] = if in_grid { node } else { 0 };
        }
        out
    }

    /// How near the tool a cell's centre must lie for [`near_tool`] to call the cell near: the
    /// `margin`, plus the cell's half-diagonal, plus the grid's rounding.
    #[inline(always)]
    fn reach(&self, margin: f64, c: &hullcut_hull::Cell) -> f64 {
        margin + 0.87 * c.size + self.spacing
    }

    /// Whether grid node `index` (from [`ToolField::lookup`]) is within `reach` of the tool.
    fn node_within(&self, index: usize, reach: f64) -> bool {
        f64::from(self.distance[index]) <= reach
    }

    /// The index of the grid node nearest `p` (tool frame), `None` beyond the grid.
    #[cfg(test)]
    fn node(&self, p: &Point3<f64>) -> Option<usize> {
        let k = (p - self.origin) / self.spacing;
        let (x, y, z) =
            (round_below(k.x, self.dims[0])?, round_below(k.y, self.dims[1])?, round_below(k.z, self.dims[2])?);
        Some((z * self.dims[1] + y) * self.dims[0] + x)
    }

    /// Distance from `p` (tool frame) to the tool, to within the grid's spacing; beyond the grid,
    /// a lower bound (`pad` plus the distance to the grid).
    #[cfg(test)]
    fn at(&self, p: &Point3<f64>) -> f64 {
        if let Some(index) = self.node(p) {
            return f64::from(self.distance[index]);
        }
        let k = (p - self.origin) / self.spacing;
        let outside = |v: f64, n: usize| (-v).max(v - (n as f64 - 1.0)).max(0.0);
        let d = Vector3::new(outside(k.x, self.dims[0]), outside(k.y, self.dims[1]), outside(k.z, self.dims[2]));
        self.pad + d.norm() * self.spacing
    }
}

/// The hull with the cells near the tool at `pose` labelled scalpel and every other cell hand: a
/// cell is near when the tool comes within `margin` of it (its centre within `margin` plus its
/// half-diagonal, plus the field's rounding); a cell `not_hand` marks (by index) is not the hand
/// (no label) unless near. One transform and one lookup per cell.
fn near_tool(occ: &Occupancy, field: &ToolField, pose: &Isometry3<f64>, margin: f64, not_hand: &[bool]) -> Occupancy {
    let to_tool = pose.inverse();
    let mut out = occ.clone();
    out.cells.par_chunks_mut(NEAR_TOOL_CHUNK).enumerate().for_each(|(n, cells)| {
        // The cells the tool's box leaves in reach read the grid in a pass of their own, its
        // reads (scattered over a field of megabytes) in flight together; the chunk's list of
        // them lives on the stack (no allocation per chunk, frame set after frame set).
        let mut read = [(0usize, 0usize); NEAR_TOOL_CHUNK];
        let reads = pulp::Arch::new().dispatch(NearChunk { field, to_tool: &to_tool, margin, cells, read: &mut read });
        for &(k, index) in &read[..reads] {
            cells[k].scalpel = field.node_within(index, field.reach(margin, &cells[k]));
        }
        let first = n * NEAR_TOOL_CHUNK;
        for (k, c) in cells.iter_mut().enumerate() {
            c.hand = !c.scalpel && !not_hand.get(first + k).copied().unwrap_or(false);
        }
    });
    out
}

/// The first pass of one chunk of [`near_tool`]: each cell's centre taken to the tool's frame,
/// [`ToolField::lookup`] a batch of [`BATCH`] at a time ([`ToolField::lookup_batch`]), the
/// decided cells labelled, the others' grid nodes listed in `read` (returns how many). Compiled
/// for the widest vector instructions the processor has (pulp's run-time dispatch): the same
/// IEEE operations in the same order on any of them, so the same labels.
struct NearChunk<'a> {
    field: &'a ToolField,
    to_tool: &'a Isometry3<f64>,
    margin: f64,
    cells: &'a mut [hullcut_hull::Cell],
    read: &'a mut [(usize, usize); NEAR_TOOL_CHUNK],
}

impl pulp::WithSimd for NearChunk<'_> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> usize {
        let NearChunk { field, to_tool, margin, cells, read } = self;
        let mut reads = 0;
        for (b, batch) in cells.chunks_mut(BATCH).enumerate() {
            let mut points = PointBatch::default();
            for (k, c) in batch.iter().enumerate() {
                let p = to_tool * c.centre();
                (points.x[k], points.y[k], points.z[k]) = (p.x, p.y, p.z);
                points.reach[k] = field.reach(margin, c);
            }
            let looked = field.lookup_batch(&points);
            for (k, c) in batch.iter_mut().enumerate() {
                if looked.read[k] {
                    read[reads] = (b * BATCH + k, looked.node[k]);
                    reads += 1;
                } else {
                    c.scalpel = looked.near[k];
                }
            }
        }
        reads
    }
}

/// Up to [`BATCH`] points (tool frame) and their reaches, planar, for
/// [`ToolField::lookup_batch`]; past the batch's points, zeros.
#[derive(Debug, Clone, Copy, Default)]
struct PointBatch {
    x: [f64; BATCH],
    y: [f64; BATCH],
    z: [f64; BATCH],
    reach: [f64; BATCH],
}

/// [`ToolField::lookup_batch`]'s answers: point `k` is [`Lookup::Node`]`(node[k])` where
/// `read[k]`, else [`Lookup::Decided`]`(near[k])`.
#[derive(Debug, Clone, Copy)]
struct LookedUp {
    near: [bool; BATCH],
    read: [bool; BATCH],
    node: [usize; BATCH],
}

/// Cells per task of [`near_tool`].
const NEAR_TOOL_CHUNK: usize = 512;

/// The hull's thin parts: leaves an opening of the occupied leaves by a ball of `radius` removes,
/// labelled scalpel (every other cell hand), and their 26-connected components as lists of cell
/// indices, largest first.
pub fn thin_parts(occ: &Occupancy, radius: f64) -> (Occupancy, Vec<Vec<usize>>) {
    let mut out = occ.clone();
    let Some(grid) = DenseGrid::from_occupancy(occ, None) else { return (out, Vec::new()) };
    let opened = open_ball(&grid.occupied, grid.dims, (radius / occ.leaf_size).max(1.0));
    let index = |c: &hullcut_hull::Cell| {
        let centre = c.centre();
        [0, 1, 2].map(|a| ((centre[a] - grid.origin[a]) / grid.leaf).round() as usize)
    };
    let slot = |idx: [usize; 3]| (idx[2] * grid.dims[1] + idx[1]) * grid.dims[0] + idx[0];
    // Thin leaves by grid slot, for the components.
    let mut at_slot = vec![u32::MAX; grid.occupied.len()];
    let mut thin = Vec::new();
    for (n, c) in out.cells.iter_mut().enumerate() {
        // Cells larger than a leaf are uniform interior: never thin.
        let k = slot(index(c));
        let is_thin = c.size <= occ.leaf_size * 1.5
            && grid.occupied.get(k).copied().unwrap_or(false)
            && !opened.get(k).copied().unwrap_or(true);
        c.scalpel = is_thin;
        c.hand = !is_thin;
        if is_thin {
            at_slot[k] = thin.len() as u32;
            thin.push(n);
        }
    }
    // Union-find over the thin leaves' 26-neighbourhoods.
    let mut parent: Vec<usize> = (0..thin.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (t, &n) in thin.iter().enumerate() {
        let idx = index(&out.cells[n]);
        for d in 0..27usize {
            let q = [idx[0] + d % 3, idx[1] + (d / 3) % 3, idx[2] + d / 9];
            if q.contains(&0) || (0..3).any(|a| q[a] > grid.dims[a]) {
                continue;
            }
            let k = slot([q[0] - 1, q[1] - 1, q[2] - 1]);
            let other = at_slot[k];
            if other != u32::MAX {
                let (a, b) = (find(&mut parent, t), find(&mut parent, other as usize));
                if a != b {
                    parent[a] = b;
                }
            }
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = std::collections::BTreeMap::new();
    for (t, &n) in thin.iter().enumerate() {
        groups.entry(find(&mut parent, t)).or_default().push(n);
    }
    let mut components: Vec<Vec<usize>> = groups.into_values().collect();
    components.sort_by_key(|c| std::cmp::Reverse(c.len()));
    (out, components)
}

/// The hull with only the cells of one thin component labelled scalpel.
fn only(occ: &Occupancy, component: &[usize]) -> Occupancy {
    let mut out = occ.clone();
    for c in &mut out.cells {
        c.scalpel = false;
        c.hand = true;
    }
    for &n in component {
        out.cells[n].scalpel = true;
        out.cells[n].hand = false;
    }
    out
}

/// Opening by a ball of radius `r` leaves: the union of the balls that fit inside the occupied
/// leaves (erosion: leaves farther than `r` from any empty one; dilation: leaves within `r` of
/// those), from two Euclidean distance transforms. A ball, not a cube: a cube that fits a palm
/// does not fit a finger's round section, a ball of the same radius does.
fn open_ball(occupied: &[bool], dims: [usize; 3], r: f64) -> Vec<bool> {
    let r2 = r * r;
    // Squared distance to the nearest empty leaf (outside the grid counts as empty: the grid is
    // padded by one empty leaf on every side).
    let empty: Vec<bool> = occupied.iter().map(|&o| !o).collect();
    let to_empty = squared_distance(&empty, dims);
    let eroded: Vec<bool> = to_empty.iter().map(|&d| d > r2).collect();
    let to_core = squared_distance(&eroded, dims);
    to_core.iter().zip(occupied).map(|(&d, &o)| o && d <= r2).collect()
}

/// Squared Euclidean distance (in leaves) from every leaf to the nearest `feature` leaf, by
/// Felzenszwalb and Huttenlocher's separable lower-envelope transform; infinite without any.
fn squared_distance(feature: &[bool], dims: [usize; 3]) -> Vec<f64> {
    let mut d: Vec<f64> = feature.iter().map(|&f| if f { 0.0 } else { f64::INFINITY }).collect();
    let strides = [1, dims[0], dims[0] * dims[1]];
    let (mut line, mut out, mut v, mut z) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for axis in 0..3 {
        let n = dims[axis];
        for start in 0..d.len() {
            if !(start / strides[axis]).is_multiple_of(n) {
                continue;
            }
            line.clear();
            line.extend((0..n).map(|i| d[start + i * strides[axis]]));
            transform_1d(&line, &mut out, &mut v, &mut z);
            for (i, &x) in out.iter().enumerate() {
                d[start + i * strides[axis]] = x;
            }
        }
    }
    d
}

/// One dimension of [`squared_distance`]: `out[q] = min_p (q − p)² + f[p]`.
fn transform_1d(f: &[f64], out: &mut Vec<f64>, v: &mut Vec<usize>, z: &mut Vec<f64>) {
    let n = f.len();
    out.clear();
    out.resize(n, f64::INFINITY);
    v.clear();
    z.clear();
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        loop {
            let Some(&p) = v.last() else {
                v.push(q);
                z.push(f64::NEG_INFINITY);
                break;
            };
            // Where the parabolas of p and q cross.
            let s = ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
            if s <= *z.last().unwrap_or(&f64::NEG_INFINITY) {
                v.pop();
                z.pop();
                continue;
            }
            v.push(q);
            z.push(s);
            break;
        }
    }
    if v.is_empty() {
        return;
    }
    let mut k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while k + 1 < v.len() && z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        *o = (q as f64 - p as f64).powi(2) + f[p];
    }
}

/// The tool's mesh drawn into a region of a view: the depth (along the optical axis) of its
/// nearest surface per pixel, infinity where it is absent.
struct ToolDepth {
    x0: usize,
    y0: usize,
    w: usize,
    depth: Vec<f32>,
}

/// The depth of the projected triangle `[a, b, c]` (pixels with their depths; `area` its signed
/// doubled area) at the centre of pixel (`i`, `j`), where its barycentric weights are all
/// non-negative ([`ToolDepth::draw`]).
#[inline(always)]
fn triangle_depth([a, b, c]: [(Point2<f64>, f64); 3], area: f64, i: usize, j: usize) -> Option<f32> {
    let q = Point2::new(i as f64, j as f64);
    let (wa, wb) = ((c.0 - b.0).perp(&(q - b.0)) / area, (a.0 - c.0).perp(&(q - c.0)) / area);
    let wc = 1.0 - wa - wb;
    (wa >= 0.0 && wb >= 0.0 && wc >= 0.0).then_some((wa * a.1 + wb * b.1 + wc * c.1) as f32)
}

impl ToolDepth {
    fn draw(cam: &Camera, radius: f64, mesh: &Mesh, pose: &Isometry3<f64>) -> Option<Self> {
        let projected: Vec<Option<(Point2<f64>, f64)>> = mesh
            .vertices
            .iter()
            .map(|p| {
                let pc = cam.world_to_camera(&(pose * p));
                project_camera_point(cam, radius, &pc).map(|uv| (uv, pc.z))
            })
            .collect();
        let (mut lo, mut hi) = (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN));
        for (uv, _) in projected.iter().flatten() {
            lo = lo.inf(uv);
            hi = hi.sup(uv);
        }
        let (iw, ih) = (f64::from(cam.width), f64::from(cam.height));
        let (x0, y0) = (lo.x.floor().max(0.0), lo.y.floor().max(0.0));
        let (x1, y1) = (hi.x.ceil().min(iw - 1.0), hi.y.ceil().min(ih - 1.0));
        if !(x0 <= x1 && y0 <= y1) {
            return None;
        }
        let (x0, y0, w, h) = (x0 as usize, y0 as usize, (x1 - x0) as usize + 1, (y1 - y0) as usize + 1);
        let mut depth = vec![f32::INFINITY; w * h];
        for t in &mesh.triangles {
            let [Some(a), Some(b), Some(c)] = t.map(|i| projected[i as usize]) else { continue };
            let area = (b.0 - a.0).perp(&(c.0 - a.0));
            if area.abs() < 1e-12 {
                continue;
            }
            let (tlo, thi) = (a.0.inf(&b.0).inf(&c.0), a.0.sup(&b.0).sup(&c.0));
            let (i0, j0) = (tlo.x.ceil().max(x0 as f64) as usize, tlo.y.ceil().max(y0 as f64) as usize);
            let (i1, j1) = (thi.x.floor().min((x0 + w - 1) as f64), thi.y.floor().min((y0 + h - 1) as f64));
            if i1 < i0 as f64 || j1 < j0 as f64 {
                continue;
            }
            // Per row, only the columns near the triangle: each barycentric weight is linear
            // along the row, so its sign changes once; the test below still decides each pixel,
            // a pixel of slack on either side keeps rounding from losing one.
            let weights = [(b.0, c.0), (c.0, a.0), (a.0, b.0)];
            for j in j0..=j1 as usize {
                let y = j as f64;
                let (mut lo_x, mut hi_x) = (i0 as f64, i1);
                for (p, q) in weights {
                    // (q - p).perp(x - p) = (q.x - p.x)(y - p.y) - (q.y - p.y)(x - p.x), signed as `area`.
                    let slope = -(q.y - p.y) * area.signum();
                    let at_zero = ((q.x - p.x) * (y - p.y) + (q.y - p.y) * p.x) * area.signum();
                    if slope > 0.0 {
                        lo_x = lo_x.max(-at_zero / slope - 1.0);
                    } else if slope < 0.0 {
                        hi_x = hi_x.min(-at_zero / slope + 1.0);
                    } else if at_zero < -1e-9 * (1.0 + at_zero.abs()) {
                        hi_x = f64::MIN;
                    }
                }
                if lo_x.is_nan() || hi_x.is_nan() || lo_x > hi_x {
                    continue;
                }
                for i in lo_x.ceil() as usize..=hi_x.floor() as usize {
                    let Some(z) = triangle_depth([a, b, c], area, i, j) else { continue };
                    let k = (j - y0) * w + (i - x0);
                    if z < depth[k] {
                        depth[k] = z;
                    }
                }
            }
        }
        Some(ToolDepth { x0, y0, w, depth })
    }

    /// The pixels it covers.
    fn region(&self) -> ToolRegion {
        let height = self.depth.len() / self.w.max(1);
        ToolRegion {
            x0: self.x0,
            y0: self.y0,
            width: self.w,
            height,
            covered: self.depth.iter().map(|d| d.is_finite()).collect(),
        }
    }

    /// Whether the tool is drawn within `r` pixels of (`i`, `j`) (a square neighbourhood).
    fn near(&self, i: usize, j: usize, r: usize) -> bool {
        (j.saturating_sub(r)..=j + r).any(|y| (i.saturating_sub(r)..=i + r).any(|x| self.at(x, y).is_some()))
    }

    /// The depth drawn at pixel (`i`, `j`) of the view (`None` where the tool is not drawn).
    fn at(&self, i: usize, j: usize) -> Option<f64> {
        let (x, y) = (i.checked_sub(self.x0)?, j.checked_sub(self.y0)?);
        if x >= self.w {
            return None;
        }
        let d = *self.depth.get(y * self.w + x)?;
        d.is_finite().then_some(f64::from(d))
    }

    /// The pixel centres of the drawn box in `[lo, hi]`, as columns and rows of `depth` (first
    /// and last column, first and last row), or `None` where they miss it.
    fn span(&self, lo: Point2<f64>, hi: Point2<f64>) -> Option<(usize, usize, usize, usize)> {
        let h = self.depth.len() / self.w.max(1);
        let (i0, j0) = ((ceil(lo.x) - self.x0 as f64).max(0.0), (ceil(lo.y) - self.y0 as f64).max(0.0));
        let (i1, j1) = (
            (floor(hi.x) - self.x0 as f64).min(self.w as f64 - 1.0),
            (floor(hi.y) - self.y0 as f64).min(h as f64 - 1.0),
        );
        (i0 <= i1 && j0 <= j1).then_some((i0 as usize, i1 as usize, j0 as usize, j1 as usize))
    }

    /// The indices (in `mask`'s image) of the foreground pixels of `mask` where the tool is drawn
    /// and none of `cells` (the hand's, as [`drawn_box`]es) lies nearer than the tool's depth
    /// less `margin`: [`ToolLabeller::final_labels`] would call them visible whichever of the
    /// cells it took for occluders. A shadow the other views put on the table ([`TABLE_SHADOW`])
    /// is not foreground here, and a pixel whose colour is surely the hand's (a [`label::HAND`]
    /// hint) is left out.
    fn unoccluded(&self, mask: &GrayImage, cells: impl Iterator<Item = DrawnBox>, margin: f64) -> Vec<usize> {
        let mut hand = vec![f32::INFINITY; self.depth.len()];
        for (lo, hi, z) in cells {
            self.splat_min(&mut hand, lo, hi, (z + margin) as f32);
        }
        let (w, raw) = (mask.width() as usize, mask.as_raw());
        self.depth
            .iter()
            .zip(&hand)
            .enumerate()
            .filter(|(_, (d, h))| d.is_finite() && **h >= **d)
            .map(|(k, _)| (self.y0 + k / self.w) * w + self.x0 + k % self.w)
            .filter(|&px| raw.get(px).is_some_and(|&l| l != label::BACKGROUND && l != TABLE_SHADOW && l != label::HAND))
            .collect()
    }

    /// Lowers `buffer` (laid out as `depth`) to `z` over the pixel centres in `[lo, hi]`.
    fn splat_min(&self, buffer: &mut [f32], lo: Point2<f64>, hi: Point2<f64>, z: f32) {
        let Some((i0, i1, j0, j1)) = self.span(lo, hi) else { return };
        for j in j0..=j1 {
            for v in &mut buffer[j * self.w + i0..=j * self.w + i1] {
                if z < *v {
                    *v = z;
                }
            }
        }
    }

    /// The indices of the hand's `cells` (with their [`drawn_box`]) that can hide the drawn tool in
    /// [`ToolLabeller::final_labels`]: their [`drawn_box`] holds a pixel where the tool is drawn,
    /// and their nearest corner plus `margin` lies nearer than the farthest drawn depth. Each of
    /// `runs` (over `cells`: [`CellRun::split`]) is ruled out whole where its ball lies behind
    /// the tool or projects onto no drawn pixel; in the others, a cell's centre depth rules out
    /// those behind the tool, one projection of the centre with a disc around it
    /// ([`Camera::project_ball`], its half-diagonal's ball) most of the others; the rest are
    /// projected corner by corner. The drawn pixels in a box are counted from a summed-area table.
    fn cells_over(
        &self,
        cam: &Camera,
        cells: &[hullcut_hull::Cell],
        runs: &[CellRun],
        margin: f64,
    ) -> Vec<(usize, DrawnBox)> {
        let farthest = self.depth.iter().copied().filter(|d| d.is_finite()).fold(f32::NEG_INFINITY, f32::max);
        let (w, h) = (self.w, self.depth.len() / self.w.max(1));
        let mut sat = vec![0u32; (w + 1) * (h + 1)];
        for j in 0..h {
            let mut row = 0;
            for i in 0..w {
                row += u32::from(self.depth[j * w + i].is_finite());
                sat[(j + 1) * (w + 1) + i + 1] = sat[j * (w + 1) + i + 1] + row;
            }
        }
        let drawn_in = |lo: Point2<f64>, hi: Point2<f64>| {
            self.span(lo, hi).is_some_and(|(i0, i1, j0, j1)| {
                let at = |i: usize, j: usize| sat[j * (w + 1) + i];
                at(i1 + 1, j1 + 1) + at(i0, j0) > at(i0, j1 + 1) + at(i1 + 1, j0)
            })
        };
        let radius = cam.distortion.monotonic_radius();
        // A cell whose nearest point, plus the margin, lies beyond the farthest drawn depth hides
        // nothing (a micrometre of slack for rounding).
        let beyond = f64::from(farthest) + 1e-6 - margin;
        let reach = |c: &hullcut_hull::Cell| {
            if !c.hand {
                return None;
            }
            let pc = cam.world_to_camera(&c.centre());
            if pc.z - c.bounding_radius() > beyond {
                return None;
            }
            if let Some((uv, r)) = cam.project_ball_in_camera(&pc, c.bounding_radius(), NEAR_M, radius) {
                let pad = Vector2::new(r, r);
                if !drawn_in(uv - pad, uv + pad) {
                    return None;
                }
            }
            drawn_box(cam, radius, c).filter(|&(lo, hi, z)| ((z + margin) as f32) < farthest && drawn_in(lo, hi))
        };
        // A run's ball holds its cells' balls: behind the tool, or projected onto no drawn pixel,
        // so is each of them (a nanometre and a micro-pixel of slack for rounding).
        let run_reaches = |run: &CellRun| {
            let pc = cam.world_to_camera(&run.centre);
            if pc.z - run.radius - 1e-9 > beyond {
                return false;
            }
            cam.project_ball_in_camera(&pc, run.radius, NEAR_M, radius).is_none_or(|(uv, r)| {
                let pad = Vector2::new(r + 1e-6, r + 1e-6);
                drawn_in(uv - pad, uv + pad)
            })
        };
        runs.iter()
            .filter(|run| run_reaches(run))
            .flat_map(|run| (run.start..run.end).filter_map(|i| reach(&cells[i]).map(|b| (i, b))))
            .collect()
    }
}

/// Consecutive cells judged together ahead of their own tests in [`ToolDepth::cells_over`]: the
/// hull's cells come in octree order, so such a run is compact.
const RUN_CELLS: usize = crate::evidence::BATCH;

/// A run of consecutive cells (`start..end`) and a ball that holds each of their bounding balls.
#[derive(Debug, Clone, Copy)]
struct CellRun {
    start: usize,
    end: usize,
    centre: Point3<f64>,
    radius: f64,
    /// The largest of its cells' bounding radii (at most `radius`).
    cell_radius: f64,
}

impl CellRun {
    /// `cells` in runs of [`RUN_CELLS`], each with a ball around its cells' balls (centred on the
    /// middle of their centres' box).
    fn split(cells: &[hullcut_hull::Cell]) -> Vec<CellRun> {
        (0..cells.len())
            .step_by(RUN_CELLS)
            .map(|start| {
                let end = (start + RUN_CELLS).min(cells.len());
                let run = &cells[start..end];
                let (mut lo, mut hi) =
                    (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
                for c in run {
                    lo = lo.inf(&c.centre());
                    hi = hi.sup(&c.centre());
                }
                let centre = nalgebra::center(&lo, &hi);
                let radius = run.iter().map(|c| (c.centre() - centre).norm() + c.bounding_radius()).fold(0.0, f64::max);
                let cell_radius = run.iter().map(hullcut_hull::Cell::bounding_radius).fold(0.0, f64::max);
                CellRun { start, end, centre, radius, cell_radius }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reproducible stream of numbers in [0, 1).
    fn numbers(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The field of a slender tool: a blade-like strip of points 150 by 12 mm, a 1 mm grid
    /// padded by 22 mm.
    fn slender_tool_field() -> ToolField {
        let points: Vec<Point3<f64>> =
            (0..150).flat_map(|i| (0..12).map(move |j| Point3::new(i as f64 * 0.001, j as f64 * 0.001, 0.0))).collect();
        ToolField::new(&points, 0.001, 0.022)
    }

    #[test]
    fn rounding_without_the_library_is_the_library_s() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            TWO_52 - 0.5,
            -(TWO_52 - 0.5),
            TWO_52,
            -TWO_52,
            TWO_52 + 2.0,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
        ];
        let mut s = 88172645463325252u64;
        for _ in 0..10_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let unit = (s >> 11) as f64 / (1u64 << 53) as f64;
            values.push((unit - 0.5) * [2.0, 1e3, 1e7, 1e16][(s % 4) as usize]);
        }
        for v in values {
            assert_eq!(ceil(v), v.ceil(), "ceil({v:e})");
            assert_eq!(floor(v), v.floor(), "floor({v:e})");
        }
        assert!(ceil(f64::NAN).is_nan() && floor(f64::NAN).is_nan());
    }

    #[test]
    fn searches_pace_by_doubling_gaps_up_to_the_most_allowed() {
        let gaps: Vec<u32> = (0..7).map(|n| search_gap(n, 8)).collect();
        assert_eq!(gaps, vec![1, 1, 2, 4, 8, 8, 8]);
        assert_eq!(search_gap(3, 4), 4);
        // No overflow however many failed, and never a gap of 0.
        assert_eq!(search_gap(u32::MAX, 64), 64);
        assert_eq!(search_gap(40, 0), 1);
        assert!((0..100).all(|n| search_gap(n, 1) == 1));
    }

    #[test]
    fn distances_are_euclidean() {
        let dims = [7, 5, 3];
        let mut f = vec![false; 105];
        // The leaf (3, 2, 1).
        f[(5 + 2) * 7 + 3] = true;
        let d = squared_distance(&f, dims);
        for z in 0..3 {
            for y in 0..5 {
                for x in 0..7 {
                    let expected = (x as f64 - 3.0).powi(2) + (y as f64 - 2.0).powi(2) + (z as f64 - 1.0).powi(2);
                    assert_eq!(d[(z * 5 + y) * 7 + x], expected);
                }
            }
        }
    }

    #[test]
    fn opening_removes_what_is_thinner_than_the_ball() {
        // A 9x9x9 block with a 1x1x6 rod sticking out along x.
        let dims = [16, 11, 11];
        let mut grid = vec![false; dims[0] * dims[1] * dims[2]];
        let at = |x: usize, y: usize, z: usize| (z * dims[1] + y) * dims[0] + x;
        for z in 1..10 {
            for y in 1..10 {
                for x in 1..10 {
                    grid[at(x, y, z)] = true;
                }
            }
        }
        for x in 10..16 {
            grid[at(x, 5, 5)] = true;
        }
        let opened = open_ball(&grid, dims, 2.0);
        assert!(opened[at(5, 5, 5)] && opened[at(3, 3, 3)], "the block stays");
        assert!(
            (11..16).all(|x| !opened[at(x, 5, 5)]),
            "the rod goes (past the first leaf a ball at the block reaches)"
        );
        // A ball does not reach into the block's corners.
        assert!(!opened[at(1, 1, 1)]);
    }

    /// A camera at the origin looking along +z, a 10x10 block of scalpel pixels at its centre
    /// (the fit's band), the tool drawn 0.5 m away over its left half, and a 1 cm hand cell on the
    /// axis at `z`.
    fn band_scene(z: f64) -> (Camera, GrayImage, ToolDepth, hullcut_hull::Cell) {
        let camera = Camera::new("c", 100, 100, 100.0, 100.0, 50.0, 50.0);
        let mut labels = GrayImage::new(100, 100);
        for j in 45..55 {
            for i in 45..55 {
                labels.put_pixel(i, j, image::Luma([label::SCALPEL]));
            }
        }
        let depth = (0..100).map(|k| if k % 10 < 6 { 0.5 } else { f32::INFINITY }).collect();
        let tool = ToolDepth { x0: 45, y0: 45, w: 10, depth };
        let cell = hullcut_hull::Cell {
            min: Point3::new(-0.005, -0.005, z - 0.005),
            size: 0.01,
            hand: true,
            scalpel: false,
            solid: true,
            refuted_by: None,
        };
        (camera, labels, tool, cell)
    }

    #[test]
    fn the_hand_takes_band_pixels_from_the_tool_only_where_it_is_not_behind_it() {
        let at_centre = |l: &GrayImage| l.get_pixel(50, 50).0[0];
        for (z, expected) in [(0.7, label::SCALPEL), (0.4, label::HAND), (0.5, label::HAND)] {
            let (camera, mut labels, tool, cell) = band_scene(z);
            let hints = GrayImage::new(100, 100);
            let cells = HandCells::new(vec![cell], Vec::new());
            let hand = HandInFront { hand: &cells, tool: Some(&tool), margin: 0.003, tool_colour_decides: true };
            let scalpel = PixelBox::of(&labels, label::SCALPEL);
            clear_hand(&mut labels, &camera, 10.0, &hand, hints.as_raw(), &scalpel);
            assert_eq!(at_centre(&labels), expected, "a hand cell at {z} m, the tool at 0.5 m");
            assert_eq!(labels.get_pixel(51, 50).0[0], label::HAND, "beside the drawn tool the band is the hand's");
            assert_eq!(labels.get_pixel(45, 45).0[0], label::SCALPEL, "the cell's disc is a few pixels wide");
        }
        // A doubtful cell (maybe a shadow) in front of the tool hides nothing of it, and takes the
        // band beside it.
        let (camera, mut labels, tool, cell) = band_scene(0.4);
        let hints = GrayImage::new(100, 100);
        let cells = HandCells::new(Vec::new(), vec![cell]);
        let hand = HandInFront { hand: &cells, tool: Some(&tool), margin: 0.003, tool_colour_decides: true };
        let scalpel = PixelBox::of(&labels, label::SCALPEL);
        clear_hand(&mut labels, &camera, 10.0, &hand, hints.as_raw(), &scalpel);
        assert_eq!(at_centre(&labels), label::SCALPEL, "where the tool is drawn");
        assert_eq!(labels.get_pixel(51, 50).0[0], label::HAND, "beside the drawn tool");
        // Without the tool's depth every cell may be in front.
        let (camera, mut labels, _, cell) = band_scene(0.7);
        let hints = GrayImage::new(100, 100);
        let cells = HandCells::new(vec![cell], Vec::new());
        let hand = HandInFront { hand: &cells, tool: None, margin: 0.003, tool_colour_decides: true };
        let scalpel = PixelBox::of(&labels, label::SCALPEL);
        clear_hand(&mut labels, &camera, 10.0, &hand, hints.as_raw(), &scalpel);
        assert_eq!(at_centre(&labels), label::HAND);
        // A pixel whose colour is surely the tool's stays the tool's in front of any hull.
        let (camera, mut labels, tool, cell) = band_scene(0.4);
        let mut hints = GrayImage::new(100, 100);
        hints.put_pixel(50, 50, image::Luma([label::SCALPEL]));
        let cells = HandCells::new(vec![cell], Vec::new());
        let hand = HandInFront { hand: &cells, tool: Some(&tool), margin: 0.003, tool_colour_decides: true };
        let scalpel = PixelBox::of(&labels, label::SCALPEL);
        clear_hand(&mut labels, &camera, 10.0, &hand, hints.as_raw(), &scalpel);
        assert_eq!(at_centre(&labels), label::SCALPEL);
        assert_eq!(labels.get_pixel(51, 50).0[0], label::HAND);
        // So does a possible shadow of the tool's colour, where the tool's colour decides (a rig of
        // few views); one of no sure colour goes to the hand in front of it.
        for (hint, decides, expected) in [
            (TOOL_COLOURED_SHADOW, true, label::SCALPEL),
            (TOOL_COLOURED_SHADOW, false, label::HAND),
            (POSSIBLE_SHADOW, true, label::HAND),
        ] {
            let (camera, mut labels, tool, cell) = band_scene(0.4);
            let mut hints = GrayImage::new(100, 100);
            hints.put_pixel(50, 50, image::Luma([hint]));
            let cells = HandCells::new(vec![cell], Vec::new());
            let hand = HandInFront { hand: &cells, tool: Some(&tool), margin: 0.003, tool_colour_decides: decides };
            let scalpel = PixelBox::of(&labels, label::SCALPEL);
            clear_hand(&mut labels, &camera, 10.0, &hand, hints.as_raw(), &scalpel);
            assert_eq!(at_centre(&labels), expected, "hint {hint}, the tool's colour deciding: {decides}");
        }
    }

    #[test]
    fn the_unoccluded_tool_is_where_no_hand_cell_lies_in_front_of_its_drawing() {
        let (camera, tool) = diagonal_tool();
        let radius = camera.distortion.monotonic_radius();
        let (w, h) = (camera.width as usize, camera.height as usize);
        // Foreground everywhere but one drawn pixel (background) and one shadow on the table.
        let drawn: Vec<usize> = (0..tool.depth.len())
            .filter(|&k| tool.depth[k].is_finite())
            .map(|k| (tool.y0 + k / tool.w) * w + tool.x0 + k % tool.w)
            .collect();
        let mut mask = GrayImage::from_pixel(w as u32, h as u32, image::Luma([label::UNKNOWN]));
        let (off, on_table, hand) = (drawn[10], drawn[20], drawn[30]);
        mask.as_mut()[off] = label::BACKGROUND;
        mask.as_mut()[on_table] = TABLE_SHADOW;
        mask.as_mut()[hand] = label::HAND;
        // No cell: every drawn foreground pixel but the one surely of the hand's colour.
        let all = tool.unoccluded(&mask, std::iter::empty(), 0.004);
        assert_eq!(all.len(), drawn.len() - 3);
        assert!(!all.contains(&off) && !all.contains(&on_table) && !all.contains(&hand));
        assert!(all.iter().all(|&k| k < w * h && drawn.contains(&k)));
        // A 2 cm cell on the tool's line of sight in front of it hides what its box covers; the
        // same cell behind the tool (beyond the margin) hides nothing.
        let cell_at = |z: f64| {
            let ray = camera.pixel_ray(nalgebra::Point2::new(100.0, 80.0)).expect("a ray");
            let centre = ray.origin + ray.direction.into_inner() * z;
            hullcut_hull::Cell {
                min: centre - Vector3::repeat(0.01),
                size: 0.02,
                hand: true,
                scalpel: false,
                solid: true,
                refuted_by: None,
            }
        };
        let front = drawn_box(&camera, radius, &cell_at(0.3)).expect("the cell projects");
        let hidden = tool.unoccluded(&mask, std::iter::once(front), 0.004);
        assert!(!hidden.is_empty() && hidden.len() < all.len(), "{} of {}", hidden.len(), all.len());
        for &k in &all {
            let (x, y) = ((k % w) as f64, (k / w) as f64);
            let inside =
                x >= front.0.x.ceil() && x <= front.1.x.floor() && y >= front.0.y.ceil() && y <= front.1.y.floor();
            assert_eq!(hidden.contains(&k), !inside, "pixel ({x}, {y}) against the cell's box {front:?}");
        }
        let behind = drawn_box(&camera, radius, &cell_at(0.6)).expect("the cell projects");
        assert_eq!(tool.unoccluded(&mask, std::iter::once(behind), 0.004), all);
    }

    #[test]
    fn a_shadow_the_other_views_put_on_the_table_is_never_the_tool() {
        // The standard scalpel lying face-up under a camera 0.5 m above it.
        let scalpel = hullcut_synth::Scalpel::new();
        let template = Template::new(&scalpel.geometry).expect("the scalpel's template");
        let camera = Camera::new("top", 200, 200, 400.0, 400.0, 100.0, 100.0)
            .looking_at(Point3::new(0.0, 0.0, 0.5), Point3::origin(), Vector3::y())
            .expect("a camera looking down");
        let pose = Isometry3::identity();
        let radius = camera.distortion.monotonic_radius();
        let depth = ToolDepth::draw(&camera, radius, &scalpel.geometry.mesh, &pose);
        let cells = HandCells::new(Vec::new(), Vec::new());
        let hand = HandInFront { hand: &cells, tool: depth.as_ref(), margin: 0.003, tool_colour_decides: true };
        // A pixel in the middle of the blade's face.
        let uv = project(&camera, radius, &Point3::new(0.02, 0.0, 0.0)).expect("the blade in view");
        let (i, j) = (uv.x.round() as u32, uv.y.round() as u32);
        let label_with = |hint: u8| {
            let mut mask = GrayImage::from_pixel(200, 200, image::Luma([label::UNKNOWN]));
            mask.put_pixel(i, j, image::Luma([hint]));
            band_labels(
                ViewInput { camera: &camera, mask: &mask, image: None },
                &template,
                &pose,
                Band { px: 3.0, roll_deg: 0.0, fill_holes: true },
                &hand,
                None,
            )
            .get_pixel(i, j)
            .0[0]
        };
        assert_eq!(label_with(label::UNKNOWN), label::SCALPEL, "foreground where the tool is drawn");
        assert_eq!(label_with(POSSIBLE_SHADOW), label::SCALPEL, "a possible shadow where the tool is drawn");
        assert_eq!(label_with(TOOL_COLOURED_SHADOW), label::SCALPEL, "one of the tool's colour, alike");
        assert_eq!(label_with(TABLE_SHADOW), label::HAND, "a shadow on the table, even where the tool is drawn");
    }

    /// A hole in the tool's foreground (its colour the background's there) is foreground of no
    /// label to the fit, and its rim no outline; a notch open to the background stays outline.
    #[test]
    fn holes_in_the_tools_foreground_are_no_outline_and_notches_are() {
        // The standard scalpel lying face-up under a camera 0.5 m above it, its pixels the
        // foreground.
        let scalpel = hullcut_synth::Scalpel::new();
        let template = Template::new(&scalpel.geometry).expect("the scalpel's template");
        let camera = Camera::new("top", 400, 400, 1000.0, 1000.0, 200.0, 200.0)
            .looking_at(Point3::new(0.0, 0.0, 0.5), Point3::origin(), Vector3::y())
            .expect("a camera looking down");
        let pose = Isometry3::identity();
        let radius = camera.distortion.monotonic_radius();
        let depth = ToolDepth::draw(&camera, radius, &scalpel.geometry.mesh, &pose).expect("the tool in view");
        let mut mask = GrayImage::new(400, 400);
        for (k, d) in depth.depth.iter().enumerate() {
            if d.is_finite() {
                let (i, j) = ((depth.x0 + k % depth.w) as u32, (depth.y0 + k / depth.w) as u32);
                mask.put_pixel(i, j, image::Luma([label::UNKNOWN]));
            }
        }
        // A 3x3 hole in the middle of the blade's face; a notch cut from the body's edge inwards.
        let uv = project(&camera, radius, &Point3::new(0.02, 0.0, 0.0)).expect("the blade in view");
        let (hi, hj) = (uv.x.round() as u32, uv.y.round() as u32);
        let hole: Vec<(u32, u32)> = (hi - 1..=hi + 1).flat_map(|i| (hj - 1..=hj + 1).map(move |j| (i, j))).collect();
        let body = project(&camera, radius, &Point3::new(-0.04, 0.0, 0.0)).expect("the body in view");
        let (bi, bj) = (body.x.round() as u32, body.y.round() as u32);
        let top =
            (0..bj).rev().find(|&j| mask.get_pixel(bi, j).0[0] == label::BACKGROUND).expect("the body's edge") + 1;
        let notch: Vec<(u32, u32)> = (top..top + 3).map(|j| (bi, j)).collect();
        for &(i, j) in hole.iter().chain(&notch) {
            assert_eq!(mask.get_pixel(i, j).0[0], label::UNKNOWN, "({i}, {j}) on the tool");
            mask.put_pixel(i, j, image::Luma([label::BACKGROUND]));
        }
        let cells = HandCells::new(Vec::new(), Vec::new());
        let hand = HandInFront { hand: &cells, tool: Some(&depth), margin: 0.003, tool_colour_decides: true };
        let view = ViewInput { camera: &camera, mask: &mask, image: None };
        let band = |fill_holes| Band { px: 3.0, roll_deg: 0.0, fill_holes };
        let labels = band_labels(view, &template, &pose, band(true), &hand, None);
        assert!(hole.iter().all(|&(i, j)| labels.get_pixel(i, j).0[0] == label::UNKNOWN));
        assert!(notch.iter().all(|&(i, j)| labels.get_pixel(i, j).0[0] == label::BACKGROUND));
        // The outline the fit samples: scalpel pixels beside background ones (`ViewEvidence`).
        let outline_at = |labels: &GrayImage, pixels: &[(u32, u32)]| {
            pixels
                .iter()
                .flat_map(|&(i, j)| [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)])
                .filter(|&(i, j)| labels.get_pixel(i, j).0[0] == label::SCALPEL)
                .filter(|&(i, j)| {
                    [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)]
                        .iter()
                        .any(|&(a, b)| labels.get_pixel(a, b).0[0] == label::BACKGROUND)
                })
                .count()
        };
        assert_eq!(outline_at(&labels, &hole), 0, "no outline around the hole");
        assert!(outline_at(&labels, &notch) > 0, "the notch's sides are outline");
        // Not filled (a rig of fewer than six views), the hole's rim is outline.
        let unfilled = band_labels(view, &template, &pose, band(false), &hand, None);
        assert!(hole.iter().all(|&(i, j)| unfilled.get_pixel(i, j).0[0] == label::BACKGROUND));
        assert!(outline_at(&unfilled, &hole) >= 8);
    }

    #[test]
    fn a_blade_predicted_at_a_wrong_roll_keeps_its_pixels_in_the_band_of_the_rolled_outlines() {
        // The standard scalpel's blade seen 80° off its face, across its long axis, from 0.3 m:
        // a roll about that axis moves the blade's outline across its width by several pixels.
        let scalpel = hullcut_synth::Scalpel::new();
        let template = Template::new(&scalpel.geometry).expect("the scalpel's template");
        let (c, axis) = (template.blade_centre, (template.tip - template.blade_centre).normalize());
        let across = template.normal.cross(&axis).normalize();
        let (tilt, up) = (80f64.to_radians(), axis);
        let eye = c + 0.3 * (tilt.cos() * template.normal + tilt.sin() * across);
        let camera = Camera::new("side", 400, 400, 2000.0, 2000.0, 200.0, 200.0)
            .looking_at(eye, c, up)
            .expect("a camera looking at the blade");
        let radius = camera.distortion.monotonic_radius();
        let rolled = |deg: f64| {
            let turn =
                nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians());
            Isometry3::from_parts((c.coords - turn * c.coords).into(), turn)
        };
        // The true tool's pixels are the foreground; the prediction is rolled 5° off it.
        let truth =
            ToolDepth::draw(&camera, radius, &scalpel.geometry.mesh, &Isometry3::identity()).expect("the tool in view");
        let mut mask = GrayImage::new(400, 400);
        let mut tool_pixels = Vec::new();
        for (k, d) in truth.depth.iter().enumerate() {
            if d.is_finite() {
                let (i, j) = ((truth.x0 + k % truth.w) as u32, (truth.y0 + k / truth.w) as u32);
                mask.put_pixel(i, j, image::Luma([label::UNKNOWN]));
                tool_pixels.push((i, j));
            }
        }
        let cells = HandCells::new(Vec::new(), Vec::new());
        let hand = HandInFront { hand: &cells, tool: None, margin: 0.003, tool_colour_decides: true };
        let left_to_hand = |roll_deg: f64| {
            let band = Band { px: 3.0, roll_deg, fill_holes: true };
            let view = ViewInput { camera: &camera, mask: &mask, image: None };
            let labels = band_labels(view, &template, &rolled(5.0), band, &hand, None);
            tool_pixels.iter().filter(|&&(i, j)| labels.get_pixel(i, j).0[0] == label::HAND).count()
        };
        assert!(left_to_hand(0.0) > 20, "the band around the wrong roll alone leaves the blade's edge to the hand");
        assert_eq!(left_to_hand(6.0), 0, "rolled 6° either way, the band holds every pixel of the true tool");
        // Rolled by nothing, the outline is the prediction's.
        let pose = rolled(5.0);
        assert_eq!(
            rolled_silhouette(&camera, radius, &template, &pose, 0.0),
            silhouette(&camera, radius, &template, &pose)
        );
    }

    #[test]
    fn a_region_grows_by_the_square_of_its_radius_and_stops_at_the_image() {
        let mut rng = 3u64;
        let mut next = move |n: usize| {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((rng >> 33) % n as u64) as usize
        };
        for round in 0..40 {
            let (width, height) = (5 + next(30), 5 + next(30));
            let (iw, ih) = (width + 40, height + 40);
            let (x0, y0) = (next(iw - width + 1), next(ih - height + 1));
            let density = 1 + next(20);
            let covered: Vec<bool> = (0..width * height).map(|_| next(100) < density).collect();
            let region = ToolRegion { x0, y0, width, height, covered };
            for r in [0, 1, 2, 5, 12] {
                let grown = region.dilated(r, iw, ih);
                // Every pixel of the image: covered after growing exactly where a covered pixel
                // lies within r along both axes.
                for y in 0..ih {
                    for x in 0..iw {
                        let expect = (y.saturating_sub(r)..=y + r)
                            .any(|yy| (x.saturating_sub(r)..=x + r).any(|xx| region.covers(xx, yy)));
                        assert_eq!(grown.covers(x, y), expect, "round {round}, r {r}, ({x}, {y}) of {region:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_region_shrinks_to_the_pixels_whose_neighbours_it_all_covers() {
        // A 4x3 block at (11, 21) in a 6x5 box at (10, 20).
        let mut covered = vec![false; 30];
        for y in 1..4 {
            for x in 1..5 {
                covered[y * 6 + x] = true;
            }
        }
        let region = ToolRegion { x0: 10, y0: 20, width: 6, height: 5, covered };
        assert!(region.covers(11, 21) && region.covers(14, 23));
        assert!(!region.covers(10, 21) && !region.covers(15, 22) && !region.covers(9, 22) && !region.covers(12, 25));
        let eroded = region.eroded(1);
        let kept: Vec<(usize, usize)> = eroded.pixels().collect();
        assert_eq!(kept, vec![(12, 22), (13, 22)], "the block's inner row");
        assert!(region.eroded(2).pixels().next().is_none(), "three rows erode away");
        assert_eq!(region.eroded(0), region);
    }

    /// [`ToolDepth::draw`] as it was before it skipped the columns far from each triangle: every
    /// pixel of the drawing's box tested against every triangle.
    fn draw_every_pixel(cam: &Camera, mesh: &Mesh, pose: &Isometry3<f64>) -> Option<(usize, usize, usize, Vec<f32>)> {
        let radius = cam.distortion.monotonic_radius();
        let projected: Vec<Option<(Point2<f64>, f64)>> = mesh
            .vertices
            .iter()
            .map(|p| project(cam, radius, &(pose * p)).map(|uv| (uv, cam.world_to_camera(&(pose * p)).z)))
            .collect();
        let drawn = ToolDepth::draw(cam, radius, mesh, pose)?;
        let (x0, y0, w) = (drawn.x0, drawn.y0, drawn.w);
        let h = drawn.depth.len() / w;
        let mut depth = vec![f32::INFINITY; w * h];
        for t in &mesh.triangles {
            let [Some(a), Some(b), Some(c)] = t.map(|i| projected[i as usize]) else { continue };
            let area = (b.0 - a.0).perp(&(c.0 - a.0));
            if area.abs() < 1e-12 {
                continue;
            }
            for j in y0..y0 + h {
                for i in x0..x0 + w {
                    if let Some(z) = triangle_depth([a, b, c], area, i, j) {
                        let k = (j - y0) * w + (i - x0);
                        depth[k] = depth[k].min(z);
                    }
                }
            }
        }
        Some((x0, y0, w, depth))
    }

    #[test]
    fn the_tool_is_drawn_on_exactly_the_pixels_its_triangles_cover() {
        let camera = Camera::new("cam", 160, 120, 300.0, 300.0, 80.0, 60.0)
            .looking_at(Point3::new(0.05, -0.3, 0.25), Point3::new(0.0, 0.0, 0.02), Vector3::z())
            .expect("a camera looking at the tool");
        let scalpel = hullcut_synth::Scalpel::new().geometry.mesh;
        // Slivers and large triangles crossing the box's edges too.
        let mut rng = 11u64;
        let mut next = move || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let vertices: Vec<Point3<f64>> =
            (0..60).map(|_| Point3::new(next() * 0.3, next() * 0.3, next() * 0.1)).collect();
        let triangles: Vec<[u32; 3]> = (0..20).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
        let soup = Mesh { vertices, triangles };
        let mut drawn_pixels = 0;
        for (mesh, poses) in [(&scalpel, 6), (&soup, 3)] {
            for n in 0..poses {
                let pose = Isometry3::new(
                    Vector3::new(next() * 0.04, next() * 0.04, 0.03 + next() * 0.02),
                    Vector3::new(next(), next(), next() * 6.0),
                );
                let radius = camera.distortion.monotonic_radius();
                let drawn = ToolDepth::draw(&camera, radius, mesh, &pose).expect("in view");
                let (x0, y0, w, depth) = draw_every_pixel(&camera, mesh, &pose).expect("in view");
                assert_eq!((drawn.x0, drawn.y0, drawn.w), (x0, y0, w), "pose {n}");
                assert!(drawn.depth == depth, "pose {n}: the drawn depths differ");
                drawn_pixels += depth.iter().filter(|d| d.is_finite()).count();
            }
        }
        assert!(drawn_pixels > 2000, "{drawn_pixels} pixels drawn");
    }

    #[test]
    fn the_drawn_depth_is_read_only_where_the_tool_is_drawn() {
        let mut depth = vec![f32::INFINITY; 100];
        depth[3 * 10 + 4] = 0.25;
        let tool = ToolDepth { x0: 20, y0: 30, w: 10, depth };
        assert_eq!(tool.at(24, 33), Some(0.25));
        assert_eq!(tool.at(25, 33), None, "nothing drawn there");
        assert_eq!((tool.at(19, 33), tool.at(30, 33), tool.at(24, 29), tool.at(24, 40)), (None, None, None, None));
        assert!(tool.near(25, 34, 1) && tool.near(23, 32, 1) && tool.near(24, 33, 0));
        assert!(!tool.near(26, 33, 1) && !tool.near(25, 34, 0) && !tool.near(0, 0, 1));
    }

    #[test]
    fn band_rows_clip_to_the_image_and_are_empty_off_it() {
        let square =
            [Point2::new(10.0, 10.0), Point2::new(20.0, 10.0), Point2::new(20.0, 20.0), Point2::new(10.0, 20.0)];
        let rows = band_rows(&square, 2.0, 100, 100);
        assert_eq!(rows.first(), Some(&(8, 10, 20)));
        assert!(rows.contains(&(15, 8, 22)));
        assert_eq!(rows.len(), 15);
        let off: Vec<Point2<f64>> = square.iter().map(|p| p + Vector3::new(500.0, 0.0, 0.0).xy()).collect();
        assert!(band_rows(&off, 2.0, 100, 100).is_empty(), "right of the image");
        let above: Vec<Point2<f64>> = square.iter().map(|p| p - Vector3::new(0.0, 500.0, 0.0).xy()).collect();
        assert!(band_rows(&above, 2.0, 100, 100).is_empty(), "above the image");
        assert!(band_rows(&square, f64::NAN, 100, 100).is_empty() && band_rows(&square, -1.0, 100, 100).is_empty());
    }

    /// Points inside the grid, beyond it, far away, on its bounds and not numbers, in batches
    /// full and partial: every lane answers as [`ToolField::lookup`] does point by point.
    #[test]
    fn a_batch_looks_the_grid_up_as_point_by_point() {
        let field = slender_tool_field();
        let mut next = numbers(31);
        let (mut read, mut near, mut far) = (0, 0, 0);
        for round in 0..20_000 {
            let len = 1 + round % BATCH;
            let mut batch = PointBatch::default();
            for k in 0..len {
                let mut p = if next() < 0.5 {
                    [next() * 0.4 - 0.12, next() * 0.2 - 0.09, next() * 0.2 - 0.1]
                } else {
                    // About the tool.
                    [next() * 0.21 - 0.03, next() * 0.07 - 0.03, next() * 0.06 - 0.03]
                };
                match (next() * 40.0) as usize {
                    // On a grid node's rounding edge, or the grid's last half-spacing.
                    0 => p[0] = field.origin.x + ((next() * 200.0).floor() + 0.5) * field.spacing,
                    1 => p[1] = field.origin.y + (field.dims[1] as f64 - 0.5) * field.spacing,
                    2 => p[2] = f64::NAN,
                    3 => p[0] = 1e300,
                    _ => {}
                }
                (batch.x[k], batch.y[k], batch.z[k]) = (p[0], p[1], p[2]);
                batch.reach[k] = [0.004, 0.01, 0.03, 0.06][(next() * 4.0) as usize % 4];
            }
            let looked = field.lookup_batch(&batch);
            for k in 0..len {
                let p = Point3::new(batch.x[k], batch.y[k], batch.z[k]);
                match field.lookup(&p, batch.reach[k]) {
                    Lookup::Node(index) => {
                        assert!(looked.read[k] && looked.node[k] == index, "{p:?}: node {index}");
                        read += 1;
                    }
                    Lookup::Decided(is_near) => {
                        assert!(!looked.read[k] && looked.near[k] == is_near, "{p:?}: decided {is_near}");
                        if is_near { near += 1 } else { far += 1 }
                    }
                }
            }
        }
        assert!(read > 10_000 && near > 1_000 && far > 10_000, "{read} read, {near} near, {far} far");
    }

    #[test]
    fn the_tools_nearness_reads_the_grid_as_the_distance_does_wherever_the_point() {
        // A slender tool (a blade-like strip of points) and points inside the grid, beyond it
        // and far away, with reaches from a leaf's to a coarse octree cell's.
        let field = slender_tool_field();
        let mut next = numbers(5);
        let (mut near, mut far) = (0, 0);
        for _ in 0..200_000 {
            let p = Point3::new(next() * 0.4 - 0.12, next() * 0.2 - 0.09, next() * 0.2 - 0.1);
            let reach = [0.004, 0.01, 0.03, 0.06][(next() * 4.0) as usize % 4];
            let expected = field.at(&p) <= reach;
            assert_eq!(field.within(&p, reach), expected, "{p:?} at reach {reach}");
            if expected { near += 1 } else { far += 1 }
        }
        assert!(near > 10_000 && far > 10_000, "{near} near, {far} far");
        let nan = Point3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(field.within(&nan, 0.01), field.at(&nan) <= 0.01);
    }

    /// The hull's cells near the tool, labelled a chunk at a time with the grid read in a pass
    /// of its own, are those [`ToolField::within`] finds one cell at a time; every other cell is
    /// the hand's unless `not_hand` marks it.
    #[test]
    fn cells_near_the_tool_are_those_within_reach_one_by_one() {
        let field = slender_tool_field();
        let pose = Isometry3::new(Vector3::new(0.02, -0.01, 0.03), Vector3::new(0.3, -0.2, 0.9));
        let mut next = numbers(11);
        // More cells than one chunk holds, of a leaf's size and a coarse cell's, about the tool.
        let cells: Vec<hullcut_hull::Cell> = (0..3 * NEAR_TOOL_CHUNK + 77)
            .map(|_| {
                let size = if next() < 0.8 { 0.004 } else { 0.008 };
                let at = pose * Point3::new(next() * 0.2 - 0.025, next() * 0.06 - 0.024, next() * 0.05 - 0.025);
                hullcut_hull::Cell {
                    min: at - Vector3::repeat(size / 2.0),
                    size,
                    hand: false,
                    scalpel: false,
                    solid: true,
                    refuted_by: None,
                }
            })
            .collect();
        let not_hand: Vec<bool> = (0..cells.len()).map(|k| k % 3 == 0).collect();
        let occ = Occupancy {
            cells,
            leaf_size: 0.004,
            origin: Point3::new(-0.1, -0.1, -0.07),
            resolution: 128,
            stats: hullcut_hull::CarveStats::default(),
        };
        let margin = 0.002;
        let labelled = near_tool(&occ, &field, &pose, margin, &not_hand);
        let to_tool = pose.inverse();
        let mut near = 0;
        for (k, (c, l)) in occ.cells.iter().zip(&labelled.cells).enumerate() {
            let expected = field.within(&(to_tool * c.centre()), margin + 0.87 * c.size + field.spacing);
            assert_eq!(l.scalpel, expected, "cell {k}");
            assert_eq!(l.hand, !expected && !not_hand[k], "cell {k}");
            near += usize::from(expected);
        }
        assert!(near > 50 && near < occ.cells.len() - 500, "{near} of {} cells near the tool", occ.cells.len());
    }

    #[test]
    fn clamped_roundings_are_the_library_s() {
        let n = 40;
        let mut values = vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0, 0.0, 1e300, -1e300];
        for k in -3..=(2 * n as i64 + 3) {
            let half = k as f64 / 2.0 - 1.0;
            values.extend([half, half.next_up(), half.next_down(), half + 0.25]);
        }
        for v in values {
            let (lo, hi) = (3.0, 31.0);
            assert_eq!(ceil_within_u32(v, lo, hi), v.ceil().max(lo).min(hi + 1.0) as u32, "ceil {v:?}");
            assert_eq!(floor_within_u32(v, lo, hi), v.floor().min(hi).max(lo) as u32, "floor {v:?}");
            let r = v.round();
            let library = (r >= 0.0 && r < n as f64).then_some(r as usize);
            assert_eq!(round_below(v, n), library, "round {v:?}");
        }
    }

    #[test]
    fn a_batch_of_cell_discs_is_bounded_as_cell_by_cell() {
        // Centres scattered in and around a box, some unprojected, some at NaN; partial batches.
        let mut next = numbers(11);
        let bounds = (40.0, 30.0, 300.0, 200.0);
        let (lo_x, lo_y, hi_x, hi_y) = bounds;
        let (mut kept, mut missed) = (0, 0);
        for round in 0..400 {
            let len = 1 + round % BATCH;
            let mut at = ProjectedBatch { u: [0.0; BATCH], v: [0.0; BATCH], z: [0.0; BATCH], ok: [false; BATCH] };
            let mut sizes = [0.0; BATCH];
            for k in 0..len {
                at.u[k] = 400.0 * next() - 30.0;
                at.v[k] = 300.0 * next() - 30.0;
                at.z[k] = 0.2 + next();
                at.ok[k] = next() > 0.1;
                sizes[k] = 0.002 + 0.02 * next();
                if next() < 0.02 {
                    at.u[k] = f64::NAN;
                }
            }
            let f = 300.0 + 600.0 * next();
            let discs = CellDiscs::within(&at, len, |k| sizes[k], f, bounds);
            for k in 0..BATCH {
                let (u, v) = (at.u[k], at.v[k]);
                let r = 0.87 * sizes[k] * f / at.z[k];
                let misses = u + r < lo_x || u - r > hi_x || v + r < lo_y || v - r > hi_y;
                let i0 = (u - r).ceil().max(lo_x).min(hi_x + 1.0) as u32;
                let j0 = (v - r).ceil().max(lo_y).min(hi_y + 1.0) as u32;
                let i1 = (u + r).floor().min(hi_x).max(lo_x) as u32;
                let j1 = (v + r).floor().min(hi_y).max(lo_y) as u32;
                let keep = k < len && at.ok[k] && !misses && i0 <= i1 && j0 <= j1;
                assert_eq!(discs.keep[k], keep, "round {round}, cell {k}");
                if keep {
                    assert_eq!((discs.i0[k], discs.i1[k], discs.j0[k], discs.j1[k]), (i0, i1, j0, j1));
                    kept += 1;
                } else if k < len {
                    missed += 1;
                }
            }
        }
        assert!(kept > 500 && missed > 500, "{kept} discs kept, {missed} not");
    }

    #[test]
    fn band_rows_hold_exactly_the_pixels_within_the_band_of_the_polygon() {
        use crate::geometry::Convex;
        let mut seed = 11u64;
        let mut next = |scale: f64| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * scale
        };
        let (w, h) = (120, 90);
        let mut checked = 0;
        for round in 0..300 {
            // Slivers, triangles and many-sided polygons, some crossing the image's border.
            let (cx, cy, spread) = (next(140.0) - 10.0, next(110.0) - 10.0, 1.0 + next(40.0));
            let count = 3 + round % 12;
            let points: Vec<Point2<f64>> =
                (0..count).map(|_| Point2::new(cx + next(spread), cy + next(spread * 0.3))).collect();
            let polygon = convex_hull(&points);
            if polygon.len() < 3 {
                continue;
            }
            let band = [0.0, 0.5, 1.5, 3.0, 7.25][round % 5];
            let rows = band_rows(&polygon, band, w, h);
            let convex = Convex::new(&polygon);
            for j in 0..h {
                let row = rows.iter().find(|r| r.0 == j);
                for i in 0..w {
                    let sd = convex.nearest(&Point2::new(i as f64, j as f64)).expect("a polygon").sd;
                    // Pixels on the band's edge to rounding may fall either way.
                    if (sd - band).abs() < 1e-9 {
                        continue;
                    }
                    let listed = row.is_some_and(|&(_, a, b)| a <= i && i <= b);
                    assert_eq!(listed, sd <= band, "pixel ({i}, {j}), sd {sd}, band {band}, polygon {polygon:?}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 1_000_000, "{checked} pixels checked");
    }

    /// A distorted camera looking along +z and a thin diagonal tool drawn 0.5-0.57 m away.
    fn diagonal_tool() -> (Camera, ToolDepth) {
        let mut camera = Camera::new("c", 200, 160, 180.0, 175.0, 98.0, 83.0)
            .looking_at(Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 1.0), Vector3::y())
            .expect("a camera looking along +z");
        camera.distortion = hullcut_rig::Distortion { k1: -0.15, k2: 0.04, p1: 5e-4, p2: 2e-4, k3: 0.0 };
        let (x0, y0, w, h): (usize, usize, usize, usize) = (60, 40, 80, 70);
        let depth = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                if i.abs_diff(j) < 3 { 0.5 + 0.001 * j as f32 } else { f32::INFINITY }
            })
            .collect();
        (camera, ToolDepth { x0, y0, w, depth })
    }

    #[test]
    fn runs_of_cells_rule_out_only_cells_that_cannot_hide_the_tool() {
        // A block of 3 mm leaves in front of the diagonal tool, in octree-like order (z fastest
        // within 4x4x4 bricks), and one larger cell: judged in runs, the same cells and boxes
        // as judged one by one (one run whose ball holds everything rules nothing out).
        let (camera, tool) = diagonal_tool();
        let leaf = 0.003;
        let mut cells = Vec::new();
        for brick in 0..(12 * 10 * 4) {
            let (bx, by, bz) = (brick % 12, (brick / 12) % 10, brick / 120);
            for k in 0..64 {
                let (x, y, z) = (4 * bx + k % 4, 4 * by + (k / 4) % 4, 4 * bz + k / 16);
                let min = Point3::new(-0.07 + leaf * x as f64, -0.06 + leaf * y as f64, 0.38 + leaf * z as f64);
                cells.push(hullcut_hull::Cell {
                    min,
                    size: leaf,
                    hand: true,
                    scalpel: false,
                    solid: true,
                    refuted_by: None,
                });
            }
        }
        cells.push(hullcut_hull::Cell {
            min: Point3::new(-0.02, -0.02, 0.3),
            size: 0.024,
            hand: true,
            scalpel: false,
            solid: true,
            refuted_by: None,
        });
        let margin = 0.006;
        let all = [CellRun { start: 0, end: cells.len(), centre: Point3::origin(), radius: 1e9, cell_radius: 1e9 }];
        let one_by_one = tool.cells_over(&camera, &cells, &all, margin);
        let runs = CellRun::split(&cells);
        let by_runs = tool.cells_over(&camera, &cells, &runs, margin);
        assert!(
            !one_by_one.is_empty() && one_by_one.len() < cells.len() / 4,
            "{} of {}",
            one_by_one.len(),
            cells.len()
        );
        assert_eq!(by_runs, one_by_one);
        // The leaves' runs are compact (the last run is the large cell alone).
        let leaves = &runs[..runs.len() - 1];
        assert!(leaves.iter().all(|r| r.radius < 0.01), "{:?}", leaves.iter().map(|r| r.radius).fold(0.0, f64::max));
    }

    #[test]
    fn runs_of_hand_cells_take_the_same_band_pixels_as_cells_one_by_one_and_as_the_whole_box() {
        // The diagonal tool drawn into a distorted camera, its band labelled scalpel; cells of
        // many sizes in front of it, behind it, beside it and near the camera, each alone in its
        // run (where the bound on a run is tightest) and, half of them, doubtful: ruled out by
        // their run's ball, each takes the same pixels as when judged itself (one run whose ball
        // holds everything rules nothing out).
        let (camera, tool) = diagonal_tool();
        let mut labels = GrayImage::new(200, 160);
        for j in 0..tool.depth.len() / tool.w {
            for i in 0..tool.w {
                if tool.near(i + tool.x0, j + tool.y0, 2) {
                    labels.put_pixel((i + tool.x0) as u32, (j + tool.y0) as u32, image::Luma([label::SCALPEL]));
                }
            }
        }
        let scalpel = PixelBox::of(&labels, label::SCALPEL);
        // The same box with every row spanning it: no pixel ruled out by its row's stretch.
        let boxed = PixelBox {
            rows: (0..160)
                .map(|j| {
                    if (scalpel.lo.1..=scalpel.hi.1).contains(&j) {
                        (scalpel.lo.0, scalpel.hi.0)
                    } else {
                        (usize::MAX, 0)
                    }
                })
                .collect(),
            ..scalpel.clone()
        };
        let judged_within = |cells: &HandCells, scalpel: &PixelBox| {
            let mut out = labels.clone();
            let in_front = HandInFront { hand: cells, tool: Some(&tool), margin: 0.003, tool_colour_decides: true };
            clear_hand(&mut out, &camera, camera.distortion.monotonic_radius(), &in_front, &[0; 200 * 160], scalpel);
            out
        };
        let judged = |cells: &HandCells| judged_within(cells, &scalpel);
        let everything = [CellRun { start: 0, end: 1, centre: Point3::origin(), radius: 1e9, cell_radius: 1e9 }];
        let mut next = numbers(23);
        let (mut taking, mut idle) = (0, 0);
        for k in 0..3000 {
            let size = 0.002 + 0.01 * next();
            let min = Point3::new(next() * 0.6 - 0.3, next() * 0.5 - 0.25, next() * 0.7);
            let cell = hullcut_hull::Cell { min, size, hand: true, scalpel: false, solid: true, refuted_by: None };
            let (cells, doubtful) = if k % 2 == 0 { (vec![cell], Vec::new()) } else { (Vec::new(), vec![cell]) };
            let by_run = judged(&HandCells::new(cells.clone(), doubtful.clone()));
            let (runs, doubtful_runs) =
                if k % 2 == 0 { (everything.to_vec(), Vec::new()) } else { (Vec::new(), everything.to_vec()) };
            let alone = HandCells { cells, doubtful, runs, doubtful_runs };
            let itself = judged(&alone);
            assert!(by_run == itself, "cell {k} ({cell:?}) takes other pixels when judged by its run");
            assert!(
                judged_within(&alone, &boxed) == itself,
                "cell {k} ({cell:?}) takes other pixels when every row of the box is looked at"
            );
            if itself == labels { idle += 1 } else { taking += 1 }
        }
        assert!(taking > 50 && idle > 1000, "{taking} cells take band pixels, {idle} none");
        // Runs of 16 small cells spread over a few centimetres: the cells at a run's rim, whose
        // discs reach past the run's projected ball, are not ruled out either.
        for k in 0..400 {
            let centre = Point3::new(next() * 0.4 - 0.2, next() * 0.3 - 0.15, 0.1 + next() * 0.5);
            let cells: Vec<hullcut_hull::Cell> = (0..RUN_CELLS)
                .map(|_| {
                    let size = 0.002 + 0.003 * next();
                    let offset = Vector3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 0.04;
                    hullcut_hull::Cell {
                        min: centre + offset,
                        size,
                        hand: true,
                        scalpel: false,
                        solid: true,
                        refuted_by: None,
                    }
                })
                .collect();
            let by_run = judged(&HandCells::new(cells.clone(), Vec::new()));
            let all = [CellRun { start: 0, end: cells.len(), centre: Point3::origin(), radius: 1e9, cell_radius: 1e9 }];
            let itself =
                judged(&HandCells { cells, doubtful: Vec::new(), runs: all.to_vec(), doubtful_runs: Vec::new() });
            assert!(by_run == itself, "run {k} takes other pixels when judged as a run");
        }
    }

    #[test]
    fn a_cell_not_drawn_over_the_tool_cannot_hide_it() {
        // A distorted camera, a thin diagonal tool drawn 0.5 m away, and hull cells of many sizes
        // in front of it, behind it, beside it and near the camera.
        let (camera, tool) = diagonal_tool();
        let mut next = numbers(11);
        let cells: Vec<hullcut_hull::Cell> = (0..3000)
            .map(|_| {
                let size = 0.002 + 0.01 * next();
                let min = Point3::new(next() * 0.6 - 0.3, next() * 0.5 - 0.25, next() * 0.7);
                hullcut_hull::Cell { min, size, hand: true, scalpel: false, solid: true, refuted_by: None }
            })
            .collect();
        let margin = 0.006;
        let over = tool.cells_over(&camera, &cells, &CellRun::split(&cells), margin);
        assert!(
            !over.is_empty() && over.len() < cells.len() / 4,
            "{} of {} cells over the tool",
            over.len(),
            cells.len()
        );
        let radius = camera.distortion.monotonic_radius();
        let mut hides = 0;
        for (k, c) in cells.iter().enumerate() {
            let Some((lo, hi, z)) = drawn_box(&camera, radius, c) else { continue };
            let mut buffer = vec![f32::INFINITY; tool.depth.len()];
            tool.splat_min(&mut buffer, lo, hi, (z + margin) as f32);
            let hidden = buffer.iter().zip(&tool.depth).any(|(b, d)| d.is_finite() && b < d);
            hides += usize::from(hidden);
            let kept = over.iter().find(|(i, _)| *i == k);
            assert!(!hidden || kept.is_some(), "cell {k} ({c:?}) hides the tool but was left out");
            assert!(kept.is_none_or(|(_, b)| *b == (lo, hi, z)), "cell {k}: its box as splatted");
        }
        assert!(hides > 0, "some cells hide the tool");
    }
}
