//! `hullcut bench pose`: the blade pose's error against leaf size and time per frame, and its
//! error and refusal rate against the number of cameras and against silhouette noise, on rendered
//! scenes with exact truth (truth masks, so that the pose stage is measured on its own).

use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use hullcut_hull::{carve, silhouettes};
use hullcut_pose::{PoseError, Template, Tracker, TrackerParams, ViewInput, isometry_from_matrix, pose_error};
use hullcut_synth::{Scene, SceneConfig, SceneKind};
use image::GrayImage;

use super::bench::Table;
use super::bench_hull::salt_and_pepper;
use crate::chart::{Scale, Series, line_chart};
use crate::progress::bar;

/// The frames of a scene that the bench tracks: masks per frame and camera, and the truth.
struct Clip {
    name: &'static str,
    scene: Scene,
    frames: Vec<u64>,
    masks: Vec<Vec<Option<GrayImage>>>,
}

impl Clip {
    fn render(name: &'static str, kind: SceneKind, seed: u64, first: u64, count: u64) -> anyhow::Result<Clip> {
        let scene = Scene::new(SceneConfig::new(kind, seed, first + count))?;
        let frames: Vec<u64> = (first..first + count).collect();
        let pb = bar(count, &format!("rendering {name}"));
        let masks = frames
            .iter()
            .map(|&f| {
                pb.inc(1);
                (0..scene.config().rig.len()).map(|c| scene.render_view(f, c).map(|v| v.mask)).collect()
            })
            .collect();
        pb.finish_and_clear();
        Ok(Clip { name, scene, frames, masks })
    }
}

/// A chart to draw: file, title, axis labels, scales, series.
type Chart = (&'static str, String, &'static str, &'static str, (Scale, Scale), Vec<Series>);

/// What one tracking run measured.
#[derive(Debug, Default)]
struct Run {
    frames: usize,
    valid: usize,
    /// Trusted frames off by more than 5° or 5 mm.
    wrong: usize,
    normal: Vec<f64>,
    tip: Vec<f64>,
    pose_ms: Vec<f64>,
    /// Summed-area tables and carving, ms.
    hull_ms: Vec<f64>,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
}

fn p95(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() as f64 * 0.95).ceil() as usize).clamp(1, s.len()) - 1]
}

impl Run {
    fn invalid_rate(&self) -> f64 {
        (self.frames - self.valid) as f64 / self.frames.max(1) as f64
    }
}

/// Tracks a clip with `cameras` of its views (the first ones), masks passed through `edit`.
fn track(clip: &Clip, leaf: f64, cameras: usize, edit: impl Fn(usize, &GrayImage) -> GrayImage) -> anyhow::Result<Run> {
    let rig = &clip.scene.config().rig;
    let template = Template::new(&clip.scene.scalpel().geometry)?;
    let mut tracker = Tracker::new(template.clone(), TrackerParams::default());
    let params = crate::volume::hull_params(&clip.scene.config().rig, leaf)?;
    let mut run = Run::default();
    for (&f, views) in clip.frames.iter().zip(&clip.masks) {
        let masks: Vec<Option<GrayImage>> =
            views.iter().enumerate().map(|(c, m)| m.as_ref().filter(|_| c < cameras).map(|m| edit(c, m))).collect();
        let refs: Vec<Option<&GrayImage>> = masks.iter().map(Option::as_ref).collect();
        let clock = Instant::now();
        let occ = carve(&silhouettes(rig, &refs)?, &params)?;
        run.hull_ms.push(clock.elapsed().as_secs_f64() * 1e3);
        let inputs: Vec<Option<ViewInput>> = rig
            .cameras
            .iter()
            .zip(&masks)
            .map(|(camera, m)| m.as_ref().map(|mask| ViewInput { camera, mask, image: None }))
            .collect();
        let clock = Instant::now();
        let e = tracker.update(f, clip.scene.frame_timestamp(f), &occ, &inputs);
        run.pose_ms.push(clock.elapsed().as_secs_f64() * 1e3);
        run.frames += 1;
        let truth = isometry_from_matrix(&clip.scene.truth_pose(f).tool_to_world).context("a true pose")?;
        if let (true, Some(p)) = (e.valid, &e.pose) {
            let err: PoseError = pose_error(p, &template, &truth);
            run.valid += 1;
            run.wrong += usize::from(err.exceeds(5.0, 5.0));
            run.normal.push(err.normal_deg);
            run.tip.push(err.tip_mm);
        }
    }
    Ok(run)
}

/// Runs the pose benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let count = if quick { 4 } else { 30 };
    let clips = [
        Clip::render("static", SceneKind::Static, 1, 0, count)?,
        Clip::render("cut", SceneKind::Cut, 2, 30, count)?,
        Clip::render("hard", SceneKind::Hard, 3, 20, count)?,
    ];
    let extent = crate::volume::BENCH_SIDE_M;
    let default_leaf = extent / 128.0;
    let mut table = Table::new(&[
        "experiment",
        "scene",
        "leaf_mm",
        "cameras",
        "noise",
        "frames",
        "invalid_rate",
        "trusted_wrong",
        "normal_deg_mean",
        "normal_deg_p95",
        "tip_mm_mean",
        "tip_mm_p95",
        "pose_ms_mean",
        "pose_ms_p50",
        "hull_ms_mean",
    ]);
    let mut row = |experiment: &str, clip: &Clip, leaf: f64, cameras: usize, noise: f64, r: &Run| {
        let mut sorted = r.pose_ms.clone();
        sorted.sort_by(f64::total_cmp);
        let p50 = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
        table.row([
            experiment.to_owned(),
            clip.name.to_owned(),
            format!("{:.3}", leaf * 1e3),
            cameras.to_string(),
            noise.to_string(),
            r.frames.to_string(),
            format!("{:.4}", r.invalid_rate()),
            r.wrong.to_string(),
            format!("{:.4}", mean(&r.normal)),
            format!("{:.4}", p95(&r.normal)),
            format!("{:.4}", mean(&r.tip)),
            format!("{:.4}", p95(&r.tip)),
            format!("{:.3}", mean(&r.pose_ms)),
            format!("{p50:.3}"),
            format!("{:.3}", mean(&r.hull_ms)),
        ]);
        tracing::info!(experiment, scene = clip.name, leaf, cameras, noise, "pose bench");
    };
    let keep = |_: usize, m: &GrayImage| m.clone();

    // Error against leaf size, and against the time per frame (carve + pose).
    let resolutions: &[usize] = if quick { &[64, 128] } else { &[64, 128, 256] };
    let mut by_leaf = Vec::new();
    let mut by_time = Vec::new();
    for clip in &clips {
        let mut normal = Series { label: format!("{} normal error, deg", clip.name), points: Vec::new() };
        let mut tip = Series { label: format!("{} tip error, mm", clip.name), points: Vec::new() };
        let mut timed = Series { label: format!("{} tip error, mm", clip.name), points: Vec::new() };
        for &n in resolutions {
            let leaf = extent / n as f64;
            let r = track(clip, leaf, 6, keep)?;
            row("leaf", clip, leaf, 6, 0.0, &r);
            normal.points.push((leaf * 1e3, mean(&r.normal)));
            tip.points.push((leaf * 1e3, mean(&r.tip)));
            timed.points.push((mean(&r.hull_ms) + mean(&r.pose_ms), mean(&r.tip)));
        }
        by_leaf.extend([normal, tip]);
        by_time.push(timed);
    }

    // Error and refusals against the number of cameras and against salt-and-pepper noise (cut).
    let cut = &clips[1];
    let camera_counts: Vec<usize> = if quick { vec![3, 6] } else { (2..=6).collect() };
    let noise_levels: &[f64] = if quick { &[0.0, 0.01] } else { &[0.0, 0.001, 0.002, 0.005, 0.01, 0.02] };
    let mut cam_err = vec![
        Series { label: "normal error, deg".into(), points: Vec::new() },
        Series { label: "tip error, mm".into(), points: Vec::new() },
    ];
    let mut noise_err = cam_err.clone();
    let mut invalid = vec![
        Series { label: "invalid rate against cameras (x: cameras)".into(), points: Vec::new() },
        Series { label: "invalid rate against noise (x: % flipped)".into(), points: Vec::new() },
    ];
    for &k in &camera_counts {
        let r = track(cut, default_leaf, k, keep)?;
        row("cameras", cut, default_leaf, k, 0.0, &r);
        cam_err[0].points.push((k as f64, mean(&r.normal)));
        cam_err[1].points.push((k as f64, mean(&r.tip)));
        invalid[0].points.push((k as f64, r.invalid_rate()));
    }
    for &fraction in noise_levels {
        let r = track(cut, default_leaf, 6, |c, m| salt_and_pepper(m, fraction, c as u64 + 1))?;
        row("noise", cut, default_leaf, 6, fraction, &r);
        noise_err[0].points.push((fraction * 100.0, mean(&r.normal)));
        noise_err[1].points.push((fraction * 100.0, mean(&r.tip)));
        invalid[1].points.push((fraction * 100.0, r.invalid_rate()));
    }
    let finite = |series: Vec<Series>| -> Vec<Series> {
        series
            .into_iter()
            .map(|s| Series { points: s.points.into_iter().filter(|p| p.1.is_finite()).collect(), ..s })
            .collect()
    };
    let path = out.join("pose.csv");
    table.write(&path)?;
    let charts: [Chart; 5] = [
        (
            "pose_leaf.png",
            "Blade pose error (trusted frames, mean) against leaf size, 6 views at 640x480".into(),
            "leaf, mm",
            "error",
            (Scale::Linear, Scale::Linear),
            by_leaf,
        ),
        (
            "pose_time.png",
            "Tip error against time per frame (silhouettes, carve, pose), leaves 6.3 / 3.1 / 1.6 mm".into(),
            "ms per frame",
            "tip error, mm",
            (Scale::Log, Scale::Linear),
            by_time,
        ),
        (
            "pose_cameras.png",
            "Blade pose error against the number of cameras (the first N), cut scene".into(),
            "cameras",
            "error (trusted frames, mean)",
            (Scale::Linear, Scale::Linear),
            cam_err,
        ),
        (
            "pose_noise.png",
            "Blade pose error against salt-and-pepper noise in all views, cut scene".into(),
            "pixels flipped, %",
            "error (trusted frames, mean)",
            (Scale::Linear, Scale::Linear),
            noise_err,
        ),
        (
            "pose_invalid.png",
            "Refused frames against cameras and against noise, cut scene".into(),
            "cameras, or % of pixels flipped",
            "fraction of frames refused",
            (Scale::Linear, Scale::Linear),
            invalid,
        ),
    ];
    for (file, title, x, y, scales, series) in charts {
        let series = finite(series);
        if series.iter().any(|s| !s.points.is_empty()) {
            line_chart(&out.join(file), &title, x, y, scales, &series)?;
        }
    }
    println!(
        "wrote {} and the charts pose_leaf.png, pose_time.png, pose_cameras.png, pose_noise.png, pose_invalid.png",
        path.display()
    );
    Ok(())
}
