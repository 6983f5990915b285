//! The pose stage's outputs: `poses.jsonl` lines (DESIGN's contract), accuracy against truth for
//! the report, and the rerun entities `world/tool/{estimate,truth}`.

use std::io::Write as _;
use std::path::Path;

use anyhow::Context as _;
use hullcut_pose::{BladePose, MANY_VIEWS, PoseError, PoseEstimate, Sight};
use hullcut_viz::RecordingStream;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Errors above these count as wrong in the report (the refusal line), degrees and mm.
pub const WRONG_DEG: f64 = 5.0;
/// See [`WRONG_DEG`].
pub const WRONG_MM: f64 = 5.0;

fn array(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

fn vector(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// One line of `poses.jsonl`.
#[derive(Debug, Serialize, Deserialize)]
pub struct PoseLine {
    frame: u64,
    timestamp_ns: i64,
    valid: bool,
    held: bool,
    confidence: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    plane_point: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    plane_normal: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    edge: Option<Vec<[f64; 3]>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tip: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
}

impl PoseLine {
    /// The line of an estimate. A pose with a non-finite number is never written: the line then
    /// carries no pose fields and says why.
    pub fn new(e: &PoseEstimate) -> Self {
        let pose = e.pose.as_ref().filter(|p| p.is_finite());
        let reason = match (&e.reason, e.pose.is_some() && pose.is_none()) {
            (_, true) => Some("the pose had a non-finite number and is not written".to_owned()),
            (r, false) => r.clone(),
        };
        PoseLine {
            frame: e.frame,
            timestamp_ns: e.timestamp_ns,
            valid: e.valid && pose.is_some(),
            held: e.held && pose.is_some(),
            confidence: if e.confidence.is_finite() { e.confidence } else { 0.0 },
            plane_point: pose.map(|p| array(&p.plane_point)),
            plane_normal: pose.map(|p| vector(&p.plane_normal)),
            edge: pose.map(|p| p.edge.iter().map(array).collect()),
            tip: pose.map(|p| array(&p.tip)),
            reason,
        }
    }
}

/// Writes `poses.jsonl` line by line.
pub struct PoseWriter {
    out: std::io::BufWriter<std::fs::File>,
    path: std::path::PathBuf,
}

impl PoseWriter {
    /// Creates (truncates) the file.
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(PoseWriter { out: std::io::BufWriter::new(file), path: path.to_owned() })
    }

    /// Appends one frame's line.
    pub fn write(&mut self, e: &PoseEstimate) -> anyhow::Result<()> {
        let line = serde_json::to_string(&PoseLine::new(e)).context("serializing a pose")?;
        writeln!(self.out, "{line}").with_context(|| format!("writing {}", self.path.display()))
    }

    /// Flushes the file.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.out.flush().with_context(|| format!("writing {}", self.path.display()))
    }
}

/// One frame's pose errors in the report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FrameError {
    frame: u64,
    valid: bool,
    confidence: f64,
    /// Errors of the pose handed out (trusted), or of the refused frame's own fit.
    normal_deg: Option<f64>,
    edge_mm: Option<f64>,
    tip_mm: Option<f64>,
    /// Errors of the frame's own fit before the pose filter, trusted or not (a trusted frame's
    /// error beside it tells the fit's error from the filter's lag).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fit_normal_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fit_tip_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    /// Fit agreement: outline points explained, interior points on foreground (fractions), RMS px.
    explained: f64,
    covered: f64,
    fit_rms_px: f64,
    /// How much fatter (px, negative: thinner) than the fitted tool the scalpel silhouettes are.
    fit_offset_px: f64,
    /// Views seeing the blade's face, edge-on, hidden by the hand, with it on background, with
    /// it on the handle's colour.
    views_seen: usize,
    views_edge_on: usize,
    views_hidden: usize,
    views_on_background: usize,
    views_handle_coloured: usize,
    scalpel_leaves: usize,
    from_hull: bool,
    iterations: usize,
    /// Where two views saw the blade's face and views edge-on could stand in for a third: the
    /// span of turns about its long axis that fit as well, degrees (45: its plane is not fixed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    roll_span_deg: Option<f64>,
    /// How well the silhouettes hold the fit's turn about the blade's long axis: its standard
    /// deviation for a pixel of noise on every residual, degrees ([`hullcut_pose::Diagnostics::roll_sd_deg`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    roll_sd_deg: Option<f64>,
    /// The camera set aside before the fit was judged: its residuals made up half the fit's cost
    /// or more, and the tool was fitted again without it ([`hullcut_pose::Diagnostics::view_set_aside`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    set_aside: Option<String>,
}

/// Mean, 95th percentile (nearest rank) and maximum.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
pub struct Spread {
    mean: f64,
    p95: f64,
    max: f64,
}

impl Spread {
    fn of(values: &[f64]) -> Option<Spread> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let p95 = v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1];
        Some(Spread { mean: v.iter().sum::<f64>() / v.len() as f64, p95, max: v[v.len() - 1] })
    }
}

/// How often one camera saw the fitted blade, over the frames whose fit it judged (it had a mask
/// and the tool in view): what a lab moving a camera wants to know.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CameraSight {
    /// The camera's name.
    pub camera: String,
    /// Frames whose fit it judged.
    pub judged: usize,
    /// Of them, those where it saw the blade's face ...
    pub seen: usize,
    /// ... saw it within 10° of edge-on ...
    pub edge_on: usize,
    /// ... had it hidden by the hand ...
    pub hidden: usize,
    /// ... had most of it on background ...
    pub on_background: usize,
    /// ... had it on the handle's learned colours.
    pub handle_coloured: usize,
    /// Of the frames it judged, those trusted.
    pub trusted: usize,
    /// Of those, the ones where it saw the blade's face.
    pub seen_trusted: usize,
    /// Of the frames it judged, those whose fit set it aside (its residuals half the fit's cost
    /// or more, its mask within the fit without it: it lost the blade's pixels in patches where
    /// the other views agree on it; [`hullcut_pose::Diagnostics::view_set_aside`]).
    #[serde(default)]
    pub set_aside: usize,
}

impl CameraSight {
    /// Counts one frame's sight.
    fn count(&mut self, sight: Sight, trusted: bool) {
        self.judged += 1;
        let n = match sight {
            Sight::Seen => &mut self.seen,
            Sight::EdgeOn => &mut self.edge_on,
            Sight::Hidden => &mut self.hidden,
            Sight::OnBackground => &mut self.on_background,
            Sight::HandleColoured => &mut self.handle_coloured,
        };
        *n += 1;
        self.trusted += usize::from(trusted);
        self.seen_trusted += usize::from(trusted && sight == Sight::Seen);
    }

    /// The share of its judged fits in which it saw the blade's face (0 where it judged none).
    fn seen_share(&self) -> f64 {
        if self.judged == 0 { 0.0 } else { self.seen as f64 / self.judged as f64 }
    }

    /// Its commonest way of not seeing the blade's face, in words, with its share.
    fn commonest_miss(&self) -> Option<(&'static str, f64)> {
        [
            (self.edge_on, "edge-on"),
            (self.hidden, "hidden by the hand"),
            (self.on_background, "on background"),
            (self.handle_coloured, "on the handle's colour"),
        ]
        .into_iter()
        .filter(|&(n, _)| n > 0)
        .max_by_key(|&(n, _)| n)
        .map(|(n, words)| (words, n as f64 / self.judged.max(1) as f64))
    }
}

/// Fits a camera must have judged before [`PoseReport::rig_hint`] names it.
pub const EDGE_ON_HINT_FITS: usize = 10;

/// The pose section of the report.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct PoseReport {
    /// Whether the dataset has a tool.json (without one every frame is refused).
    pub tool: bool,
    frames: usize,
    valid_frames: usize,
    held_frames: usize,
    invalid_rate: f64,
    /// Refusal reasons and how often each came.
    reasons: Vec<(String, usize)>,
    /// Over trusted frames with truth.
    normal_deg: Option<Spread>,
    edge_mm: Option<Spread>,
    tip_mm: Option<Spread>,
    /// Trusted frames whose error exceeds 5° or 5 mm (should be 0).
    trusted_wrong: usize,
    /// Refused frames whose own fit was within 5° and 5 mm (refused needlessly).
    refused_right: usize,
    /// Frames whose fit was judged with the colours of the tool's blade and handle told apart.
    #[serde(default)]
    parts_told_apart_frames: usize,
    /// Frames where some view found the fitted blade on the handle's colours.
    #[serde(default)]
    handle_coloured_frames: usize,
    /// Frames refused where, on a rig of four or five cameras, two views saw the blade's face and
    /// the views edge-on left it free to turn about its long axis (its plane not fixed).
    #[serde(default)]
    unfixed_plane_frames: usize,
    /// Frames whose fit set a view aside ([`CameraSight::set_aside`]).
    #[serde(default)]
    set_aside_frames: usize,
    /// Per camera (rig order), how often it saw the fitted blade.
    #[serde(default)]
    per_camera: Vec<CameraSight>,
    per_frame: Vec<FrameError>,
}

impl PoseReport {
    /// An empty report; `tool` says whether the dataset has a tool.json.
    pub fn new(tool: bool) -> Self {
        PoseReport { tool, ..PoseReport::default() }
    }

    /// Names the rig's cameras (rig order) for [`PoseReport`]'s per-camera counts; a view beyond
    /// them is named by its index.
    pub fn with_cameras(mut self, names: impl IntoIterator<Item = String>) -> Self {
        self.per_camera = names.into_iter().map(|camera| CameraSight { camera, ..CameraSight::default() }).collect();
        self
    }

    /// Adds a frame; `error` is the trusted pose's error, `fitted_error` the frame's own fit's.
    pub fn push(&mut self, e: &PoseEstimate, error: Option<PoseError>, fitted_error: Option<PoseError>) {
        self.frames += 1;
        self.valid_frames += usize::from(e.valid);
        self.held_frames += usize::from(e.held);
        self.parts_told_apart_frames += usize::from(e.diagnostics.parts_told_apart);
        self.handle_coloured_frames += usize::from(e.diagnostics.views_handle_coloured > 0);
        self.unfixed_plane_frames += usize::from(!e.valid && e.diagnostics.plane_unfixed());
        self.set_aside_frames += usize::from(e.diagnostics.view_set_aside.is_some());
        let aside = e.diagnostics.view_set_aside;
        for (k, sight) in e.diagnostics.sight.iter().enumerate() {
            let Some(sight) = sight else { continue };
            self.name_views(k + 1);
            self.per_camera[k].count(*sight, e.valid);
            self.per_camera[k].set_aside += usize::from(aside == Some(k));
        }
        let set_aside = aside.map(|k| {
            self.name_views(k + 1);
            self.per_camera[k].camera.clone()
        });
        if let Some(r) = &e.reason {
            let key = reason_kind(r).to_owned();
            match self.reasons.iter_mut().find(|(k, _)| *k == key) {
                Some((_, n)) => *n += 1,
                None => self.reasons.push((key, 1)),
            }
        }
        let shown = if e.valid { error } else { fitted_error };
        if e.valid && error.is_some_and(|x| x.exceeds(WRONG_DEG, WRONG_MM)) {
            self.trusted_wrong += 1;
        }
        if !e.valid && fitted_error.is_some_and(|x| !x.exceeds(WRONG_DEG, WRONG_MM)) {
            self.refused_right += 1;
        }
        self.per_frame.push(FrameError {
            frame: e.frame,
            valid: e.valid,
            confidence: e.confidence,
            normal_deg: shown.map(|x| x.normal_deg),
            edge_mm: shown.map(|x| x.edge_mm),
            tip_mm: shown.map(|x| x.tip_mm),
            fit_normal_deg: fitted_error.map(|x| x.normal_deg),
            fit_tip_mm: fitted_error.map(|x| x.tip_mm),
            reason: e.reason.clone(),
            explained: e.diagnostics.explained,
            covered: e.diagnostics.covered,
            fit_rms_px: e.diagnostics.fit_rms_px,
            fit_offset_px: e.diagnostics.fit_offset_px,
            views_seen: e.diagnostics.views_seen,
            views_edge_on: e.diagnostics.views_edge_on,
            views_hidden: e.diagnostics.views_hidden,
            views_on_background: e.diagnostics.views_on_background,
            views_handle_coloured: e.diagnostics.views_handle_coloured,
            scalpel_leaves: e.diagnostics.scalpel_leaves,
            from_hull: e.diagnostics.from_hull,
            iterations: e.diagnostics.iterations,
            roll_span_deg: e.diagnostics.roll_span_deg,
            roll_sd_deg: e.diagnostics.roll_sd_deg,
            set_aside,
        });
    }

    /// Names views up to `n` (a view beyond the rig's cameras is named by its index).
    fn name_views(&mut self, n: usize) {
        while self.per_camera.len() < n {
            let camera = format!("view {}", self.per_camera.len());
            self.per_camera.push(CameraSight { camera, ..CameraSight::default() });
        }
    }

    /// Computes the aggregates.
    pub fn finish(&mut self) {
        self.invalid_rate =
            if self.frames == 0 { 0.0 } else { (self.frames - self.valid_frames) as f64 / self.frames as f64 };
        let trusted: Vec<&FrameError> = self.per_frame.iter().filter(|f| f.valid).collect();
        let collect = |f: fn(&FrameError) -> Option<f64>| trusted.iter().filter_map(|x| f(x)).collect::<Vec<_>>();
        self.normal_deg = Spread::of(&collect(|x| x.normal_deg));
        self.edge_mm = Spread::of(&collect(|x| x.edge_mm));
        self.tip_mm = Spread::of(&collect(|x| x.tip_mm));
    }

    /// A line for the terminal on how often each camera saw the fitted blade's face, the one
    /// that saw it least named with its commonest miss (`None` where no camera judged a fit).
    pub fn sight_summary(&self) -> Option<String> {
        let judged: Vec<&CameraSight> = self.per_camera.iter().filter(|c| c.judged > 0).collect();
        let least = judged.iter().min_by(|a, b| a.seen_share().total_cmp(&b.seen_share()))?;
        let shares: Vec<String> =
            judged.iter().map(|c| format!("{} {:.0}%", c.camera, 100.0 * c.seen_share())).collect();
        let mut s = format!("views: the fitted blade's face seen by {}", shares.join(", "));
        if let Some((words, share)) = least.commonest_miss() {
            s += &format!("; least by {} ({} in {:.0}% of its fits)", least.camera, words, 100.0 * share);
        }
        if let Some(aside) = judged.iter().filter(|c| c.set_aside > 0).max_by_key(|c| c.set_aside) {
            s += &format!(
                "; {} set aside in {} of its {} fits (its mask lost the blade in patches where the others agree on it)",
                aside.camera, aside.set_aside, aside.judged
            );
        }
        Some(s)
    }

    /// On a rig of fewer than [`MANY_VIEWS`] cameras, where a fit is trusted only if three views
    /// see the blade's face (or two do and two more, edge-on, fix its turn about its long axis),
    /// and where a fifth of the frames or more were refused: a line naming the camera that saw
    /// the fitted blade edge-on in the largest share (half or more) of the fits it judged
    /// ([`EDGE_ON_HINT_FITS`] or more), for the lab to move or add a camera, with the frames
    /// refused for a plane the views left free (a four-camera rig whose cameras see the blade
    /// edge-on by turns trusts it in few frames even with perfect masks: random:1021 in
    /// random:1051). On larger rigs a camera edge-on to the blade is common and costs little
    /// (the others see it), so none is named.
    pub fn rig_hint(&self) -> Option<String> {
        let (refused, frames) = self.refused_of();
        if frames == 0 || 5 * refused < frames || self.per_camera.len() >= MANY_VIEWS {
            return None;
        }
        let edge_on = |c: &CameraSight| c.edge_on as f64 / c.judged.max(1) as f64;
        let worst = self
            .per_camera
            .iter()
            .filter(|c| c.judged >= EDGE_ON_HINT_FITS && 2 * c.edge_on >= c.judged)
            .max_by(|a, b| edge_on(a).total_cmp(&edge_on(b)))?;
        let unfixed = match self.unfixed_plane_frames {
            0 => String::new(),
            n => format!(" ({n} frame sets refused where they did not)"),
        };
        Some(format!(
            "hint: {} saw the fitted blade edge-on in {:.0}% of its fits; on a rig of {} cameras a fit is trusted \
             only where three views see the blade's face, or two do and two more, edge-on, fix its turn about its \
             long axis{unfixed}: a camera placed across the blade's usual plane, or one more, would see it",
            worst.camera,
            100.0 * edge_on(worst),
            self.per_camera.len()
        ))
    }

    /// Frames refused (not trusted) and frames judged.
    pub(crate) fn refused_of(&self) -> (usize, usize) {
        (self.frames.saturating_sub(self.valid_frames), self.frames)
    }

    /// A line for the terminal.
    pub fn summary(&self) -> String {
        let mut s =
            format!("pose: {} of {} frames trusted ({} held)", self.valid_frames, self.frames, self.held_frames);
        if let (Some(n), Some(t)) = (self.normal_deg, self.tip_mm) {
            s += &format!(
                "; normal {:.2}° mean, {:.2}° p95; tip {:.2} mm mean, {:.2} mm p95; {} trusted frames off by more than 5° or 5 mm",
                n.mean, n.p95, t.mean, t.p95, self.trusted_wrong
            );
        }
        if let Some((reason, n)) = self.reasons.iter().max_by_key(|(_, n)| *n) {
            s += &format!("; most common refusal ({n}x): {reason}");
        }
        s
    }
}

/// The kind of a refusal's reason: its words before the first parenthesis or number (the numbers
/// vary frame to frame: "the blade's face is seen by 1 view(s): 2 edge-on, ..." and "... by 2
/// view(s): ..." are one kind).
fn reason_kind(reason: &str) -> &str {
    let end = reason
        .char_indices()
        .find(|&(i, c)| c.is_ascii_digit() || reason[i..].starts_with(" ("))
        .map_or(reason.len(), |(i, _)| i);
    reason[..end].trim_end_matches([' ', ':', ','])
}

/// Logs a blade pose under `world/tool/<which>`: the plane as a small quad, the cutting edge as a
/// line strip, the tip as a point.
pub fn log_blade(rec: &RecordingStream, which: &str, pose: &BladePose) -> anyhow::Result<()> {
    let f = |p: Point3<f64>| [p.x as f32, p.y as f32, p.z as f32];
    let colour = if which == "truth" { [80, 220, 120, 255] } else { [255, 120, 40, 255] };
    let base = format!("world/tool/{which}");
    let along = pose.edge.first().zip(pose.edge.last()).map(|(a, b)| a - b).unwrap_or_else(Vector3::x);
    let u = (along - pose.plane_normal * along.dot(&pose.plane_normal)).try_normalize(1e-12).unwrap_or_else(Vector3::x);
    let w = pose.plane_normal.cross(&u);
    let (hu, hw) = (0.02, 0.0075);
    let c = pose.plane_point;
    let quad = [c - u * hu - w * hw, c + u * hu - w * hw, c + u * hu + w * hw, c - u * hu + w * hw].map(f);
    hullcut_viz::log_mesh3d(
        rec,
        &format!("{base}/plane"),
        &quad,
        &[[0, 1, 2], [0, 2, 3]],
        [colour[0], colour[1], colour[2], 110],
    )?;
    let edge: Vec<[f32; 3]> = pose.edge.iter().copied().map(f).collect();
    hullcut_viz::log_line_strips3d(rec, &format!("{base}/edge"), &[edge], colour, 0.0005)?;
    hullcut_viz::log_points3d(rec, &format!("{base}/tip"), &[f(pose.tip)], colour, 0.0015)?;
    Ok(())
}

pub use hullcut_pipeline::no_tool_estimate;

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame's estimate with nothing fitted: `valid`, its refusal's `reason`, its `diagnostics`.
    fn estimate(
        frame: u64,
        valid: bool,
        reason: Option<String>,
        diagnostics: hullcut_pose::Diagnostics,
    ) -> PoseEstimate {
        PoseEstimate {
            frame,
            timestamp_ns: 0,
            valid,
            held: false,
            confidence: 0.0,
            pose: None,
            fitted: None,
            reason,
            diagnostics,
        }
    }

    #[test]
    fn reasons_are_counted_by_their_words_before_any_number_or_parenthesis() {
        let seen = |n: usize| {
            format!(
                "the blade's face is seen by {n} view(s): 1 edge-on, 2 hidden by the hand, 0 on background, 0 on the handle's colour, of 5"
            )
        };
        assert_eq!(reason_kind(&seen(1)), "the blade's face is seen by");
        assert_eq!(reason_kind(&seen(1)), reason_kind(&seen(2)));
        for (reason, kind) in [
            (
                "the fitted tool disagrees with the silhouettes (explains 54% of the scalpel pixels, 81% of it lands on foreground)",
                "the fitted tool disagrees with the silhouettes",
            ),
            (
                "the blade is hidden by the hand from more views (4) than see it (3) or see it edge-on (0)",
                "the blade is hidden by the hand from more views",
            ),
            (
                "the hull is searched for the tool on one frame set in 4: the last 3 searches found no trusted fit",
                "the hull is searched for the tool on one frame set in",
            ),
            ("no view sees the scalpel's region", "no view sees the scalpel's region"),
            ("", ""),
        ] {
            assert_eq!(reason_kind(reason), kind, "{reason}");
        }
    }

    #[test]
    fn a_reports_refusals_of_one_kind_are_counted_together() {
        let mut report = PoseReport::new(true);
        for (frame, seen) in [(0, 1), (1, 2), (2, 1)] {
            let reason = format!("the blade's face is seen by {seen} view(s): 0 edge-on, of 5");
            report.push(&estimate(frame, false, Some(reason), hullcut_pose::Diagnostics::default()), None, None);
        }
        assert_eq!(report.reasons, vec![("the blade's face is seen by".to_owned(), 3)]);
        assert_eq!((report.parts_told_apart_frames, report.handle_coloured_frames), (0, 0));
    }

    #[test]
    fn frames_judged_with_the_parts_told_apart_and_those_on_the_handles_colours_are_counted() {
        let mut report = PoseReport::new(true);
        for (frame, told, handle) in [(0, false, 0), (1, true, 0), (2, true, 2), (3, true, 1)] {
            let diagnostics = hullcut_pose::Diagnostics {
                parts_told_apart: told,
                views_handle_coloured: handle,
                ..hullcut_pose::Diagnostics::default()
            };
            report.push(&estimate(frame, handle == 0, None, diagnostics), None, None);
        }
        assert_eq!((report.parts_told_apart_frames, report.handle_coloured_frames), (3, 2));
        let json = serde_json::to_value(&report).expect("serializes");
        assert_eq!(json["parts_told_apart_frames"], 3);
        assert_eq!(json["handle_coloured_frames"], 2);
    }

    #[test]
    fn each_cameras_sight_of_the_blade_is_counted_by_kind_and_the_least_seeing_one_named() {
        let mut report = PoseReport::new(true).with_cameras(["left".to_owned(), "right".to_owned()]);
        assert_eq!(report.sight_summary(), None, "no fit judged yet");
        // Three views: the third is beyond the names given; `None`: no evidence from that view.
        let frames = [
            (true, vec![Some(Sight::Seen), Some(Sight::EdgeOn), None]),
            (true, vec![Some(Sight::Seen), Some(Sight::Seen), Some(Sight::Hidden)]),
            (false, vec![Some(Sight::OnBackground), Some(Sight::EdgeOn), Some(Sight::Hidden)]),
            (false, vec![None, Some(Sight::HandleColoured), Some(Sight::Seen)]),
        ];
        for (frame, (valid, sight)) in frames.into_iter().enumerate() {
            let diagnostics = hullcut_pose::Diagnostics { sight, ..hullcut_pose::Diagnostics::default() };
            report.push(&estimate(frame as u64, valid, None, diagnostics), None, None);
        }
        let left = CameraSight {
            camera: "left".to_owned(),
            judged: 3,
            seen: 2,
            on_background: 1,
            trusted: 2,
            seen_trusted: 2,
            ..CameraSight::default()
        };
        let right = CameraSight {
            camera: "right".to_owned(),
            judged: 4,
            seen: 1,
            edge_on: 2,
            handle_coloured: 1,
            trusted: 2,
            seen_trusted: 1,
            ..CameraSight::default()
        };
        let third = CameraSight {
            camera: "view 2".to_owned(),
            judged: 3,
            seen: 1,
            hidden: 2,
            trusted: 1,
            ..CameraSight::default()
        };
        assert_eq!(report.per_camera, vec![left, right, third]);
        assert_eq!(
            report.sight_summary().as_deref(),
            Some(
                "views: the fitted blade's face seen by left 67%, right 25%, view 2 33%; least by right (edge-on in 50% of its fits)"
            )
        );
        let json = serde_json::to_value(&report).expect("serializes");
        assert_eq!(json["per_camera"][1]["edge_on"], 2);
        assert_eq!(report.rig_hint(), None, "too few fits judged to name a camera");
    }

    #[test]
    fn a_camera_set_aside_is_counted_named_in_its_frames_and_in_the_views_line() {
        // Three frames of two cameras: the second set aside in the first two, none in the third.
        let mut report = PoseReport::new(true).with_cameras(["left".to_owned(), "right".to_owned()]);
        for (frame, aside) in [Some(1), Some(1), None].into_iter().enumerate() {
            let sight = vec![Some(Sight::Seen), Some(Sight::OnBackground)];
            let diagnostics =
                hullcut_pose::Diagnostics { sight, view_set_aside: aside, ..hullcut_pose::Diagnostics::default() };
            report.push(&estimate(frame as u64, true, None, diagnostics), None, None);
        }
        assert_eq!(report.set_aside_frames, 2);
        assert_eq!((report.per_camera[0].set_aside, report.per_camera[1].set_aside), (0, 2));
        let json = serde_json::to_value(&report).expect("serializes");
        let named: Vec<&serde_json::Value> =
            json["per_frame"].as_array().expect("frames").iter().map(|f| &f["set_aside"]).collect();
        assert_eq!(named, [&serde_json::json!("right"), &serde_json::json!("right"), &serde_json::Value::Null]);
        assert_eq!(json["set_aside_frames"], 2);
        let line = report.sight_summary().expect("fits judged");
        assert!(
            line.ends_with(
                "; right set aside in 2 of its 3 fits (its mask lost the blade in patches where the others agree on it)"
            ),
            "{line}"
        );
    }

    #[test]
    fn a_camera_that_sees_the_blade_edge_on_in_half_its_fits_is_hinted_where_a_fifth_were_refused() {
        // `edge_on` of ten fits by the second camera, the first always seeing the face; frames
        // refused from `refused_from` on.
        let report = |edge_on: usize, refused_from: usize| {
            let mut report = PoseReport::new(true).with_cameras(["a".to_owned(), "b".to_owned()]);
            for frame in 0..EDGE_ON_HINT_FITS {
                let second = if frame < edge_on { Sight::EdgeOn } else { Sight::Seen };
                let sight = vec![Some(Sight::Seen), Some(second)];
                let diagnostics = hullcut_pose::Diagnostics { sight, ..hullcut_pose::Diagnostics::default() };
                report.push(&estimate(frame as u64, frame < refused_from, None, diagnostics), None, None);
            }
            report
        };
        let hint = report(5, 8).rig_hint().expect("half edge-on, a fifth refused");
        assert!(
            hint.starts_with("hint: b saw the fitted blade edge-on in 50% of its fits; on a rig of 2 cameras"),
            "{hint}"
        );
        assert!(!hint.contains("frame sets refused where"), "{hint}");
        // Refusals for a plane the edge-on views left free are counted and named.
        let mut unfixed = report(5, 8);
        for frame in 10..13 {
            let sight = vec![Some(Sight::Seen), Some(Sight::EdgeOn)];
            let diagnostics = hullcut_pose::Diagnostics {
                sight,
                roll_span_deg: Some(45.0),
                roll_sd_deg: (frame == 12).then_some(7.5),
                ..hullcut_pose::Diagnostics::default()
            };
            unfixed.push(&estimate(frame, false, None, diagnostics), None, None);
        }
        let json = serde_json::to_value(&unfixed).expect("serializes");
        assert_eq!(json["unfixed_plane_frames"], 3);
        // The turn's deviation is reported where the fit gave one.
        let frames = json["per_frame"].as_array().expect("per frame");
        let of = |frame: u64| frames.iter().find(|f| f["frame"] == frame).expect("the frame");
        assert_eq!(of(12)["roll_sd_deg"], 7.5);
        assert!(of(11).get("roll_sd_deg").is_none(), "{}", of(11));
        let hint = unfixed.rig_hint().expect("more than half edge-on, a fifth refused");
        assert!(hint.contains("fix its turn about its long axis (3 frame sets refused where they did not)"), "{hint}");
        assert_eq!(report(4, 8).rig_hint(), None, "under half edge-on");
        assert_eq!(report(10, 9).rig_hint(), None, "under a fifth refused");
        let mut large = report(5, 8);
        large
            .per_camera
            .extend((2..MANY_VIEWS).map(|k| CameraSight { camera: format!("c{k}"), ..CameraSight::default() }));
        assert_eq!(large.rig_hint(), None, "a rig of six cameras or more");
    }
}
