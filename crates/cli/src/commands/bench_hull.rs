//! `hullcut bench hull`: carving time against resolution (octree and dense grid) and accuracy
//! against the exact visual hull, on a rendered frame of the `cut` scene; and where carving
//! breaks: IoU with the clean hull against silhouette noise and against the number of cameras.

use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use hullcut_dataset::label;
use hullcut_hull::accuracy::{grid_iou, occupancy_iou};
use hullcut_hull::gpu::GpuCarver;
use hullcut_hull::{DenseGrid, HullParams, Occupancy, carve, silhouettes};
use hullcut_synth::texture::mix64;
use hullcut_synth::{Scene, SceneConfig, SceneKind};

use crate::chart::{Scale, Series, line_chart};

/// The frame of the `cut` scene (seed 2, 30 fps) used: the blade is in the organ, mid-stroke.
const FRAME: u64 = 48;

fn timed_carve(
    views: &[Option<hullcut_hull::Silhouette>],
    params: &HullParams,
    repeats: usize,
    gpu: Option<&mut GpuCarver>,
) -> anyhow::Result<(Occupancy, f64)> {
    let mut best = f64::INFINITY;
    let mut occ = None;
    let mut gpu = gpu;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let o = match gpu.as_deref_mut() {
            Some(g) => g.carve(views, params)?,
            None => carve(views, params)?,
        };
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        occ = Some(o);
    }
    Ok((occ.context("no carving run")?, best))
}

/// Runs the hull benchmark into `out`.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 2, FRAME + 1))?;
    let rig = &scene.config().rig;
    let masks: Vec<image::GrayImage> = (0..rig.len())
        .map(|c| scene.render_view(FRAME, c).map(|v| v.mask).context("the cut scene drops no frames"))
        .collect::<anyhow::Result<_>>()?;
    let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Some).collect();
    let views = silhouettes(rig, &refs)?;
    let extent = crate::volume::BENCH_SIDE_M;
    let base = crate::volume::hull_params(rig, extent / 128.0)?;
    let reference_n = if quick { 128 } else { 512 };
    let exact = carve(&views, &HullParams { leaf_size: extent / reference_n as f64, ..base.clone() })?;
    let exact_grids: Vec<Option<DenseGrid>> =
        label::NAMED.iter().map(|&(l, _)| DenseGrid::from_occupancy(&exact, Some(l))).collect();
    let resolutions: &[usize] = if quick { &[16, 32, 64] } else { &[32, 64, 128, 256] };
    let dense_limit = if quick { 32 } else { 128 };
    let repeats = if quick { 1 } else { 5 };
    let mut csv = String::from(
        "method,resolution,leaf_mm,carve_ms,footprint_tests,cells_kept,hand_iou_vs_exact_hull,scalpel_iou_vs_exact_hull\n",
    );
    let mut speed = vec![
        Series { label: "octree".into(), points: Vec::new() },
        Series { label: "dense grid (every leaf tested)".into(), points: Vec::new() },
    ];
    let mut gpu = match hullcut_gpu::Gpu::new(&hullcut_gpu::AdapterChoice::from_env()) {
        Ok(g) => {
            speed.push(Series { label: format!("octree on the GPU ({})", g.summary.info.name), points: Vec::new() });
            Some(GpuCarver::new(std::sync::Arc::new(g))?)
        }
        Err(e) => {
            tracing::warn!("hull.csv without the GPU rows: {e}");
            None
        }
    };
    let mut accuracy: Vec<Series> =
        label::NAMED.iter().map(|&(_, n)| Series { label: format!("{n} (octree)"), points: Vec::new() }).collect();
    for &n in resolutions {
        let leaf = extent / n as f64;
        let depth = n.trailing_zeros();
        for (method, start_level) in [("octree", 3), ("dense", depth), ("gpu", 3)] {
            if method == "dense" && n > dense_limit || method == "gpu" && gpu.is_none() {
                continue;
            }
            let params = HullParams { leaf_size: leaf, start_level, ..base.clone() };
            let on_gpu = if method == "gpu" { gpu.as_mut() } else { None };
            let (occ, ms) = timed_carve(&views, &params, repeats, on_gpu)?;
            let ious: Vec<Option<f64>> = label::NAMED
                .iter()
                .zip(&exact_grids)
                .map(|(&(l, _), e)| {
                    let g = DenseGrid::from_occupancy(&occ, Some(l));
                    match (g.as_ref(), e.as_ref()) {
                        (Some(g), Some(e)) => grid_iou(g, e, 200_000),
                        _ => None,
                    }
                })
                .collect();
            let fmt = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.4}"));
            csv.push_str(&format!(
                "{method},{n},{:.3},{ms:.3},{},{},{},{}\n",
                leaf * 1e3,
                occ.stats.footprint_tests,
                occ.cells.len(),
                fmt(ious[0]),
                fmt(ious[1])
            ));
            let k = match method {
                "octree" => 0,
                "dense" => 1,
                _ => 2,
            };
            speed[k].points.push((n as f64, ms));
            if method == "octree" {
                for (s, iou) in accuracy.iter_mut().zip(&ious) {
                    if let Some(iou) = iou {
                        s.points.push((ms, *iou));
                    }
                }
            }
            tracing::info!(method, resolution = n, ms, "carved");
        }
    }
    std::fs::write(out.join("hull.csv"), &csv)
        .with_context(|| format!("writing {}", out.join("hull.csv").display()))?;
    line_chart(
        &out.join("hull_speed.png"),
        "Carving time against resolution (6 views at 640x480, one cut-scene frame)",
        "leaves per side of the 0.4 m workspace",
        "carve ms (best of runs)",
        (Scale::Log, Scale::Log),
        &speed,
    )?;
    line_chart(
        &out.join("hull_accuracy.png"),
        &format!("IoU with the exact visual hull ({reference_n}³ from truth masks) against carve time"),
        "carve ms",
        "IoU",
        (Scale::Log, Scale::Linear),
        &accuracy,
    )?;
    println!("wrote {} and the charts hull_speed.png, hull_accuracy.png", out.join("hull.csv").display());
    robustness(out, quick, rig, &masks, &exact_grids)
}

/// Flips `fraction` of a mask's pixels (deterministic for a seed): background becomes hand, any
/// foreground becomes background.
pub(crate) fn salt_and_pepper(mask: &image::GrayImage, fraction: f64, seed: u64) -> image::GrayImage {
    let mut out = mask.clone();
    for (n, p) in out.pixels_mut().enumerate() {
        let u = (mix64(seed.wrapping_mul(0x1000_0000_01b3) ^ n as u64) >> 11) as f64 / (1u64 << 53) as f64;
        if u < fraction {
            p.0[0] = if p.0[0] == label::BACKGROUND { label::HAND } else { label::BACKGROUND };
        }
    }
    out
}

/// Salt-and-pepper noise in every view, and fewer cameras (the first N of the rig), for
/// carve_votes 1 and 2: IoU of all kept cells with the clean six-view classic hull at the same
/// resolution, and per label with the exact hull.
fn robustness(
    out: &Path,
    quick: bool,
    rig: &hullcut_rig::Rig,
    masks: &[image::GrayImage],
    exact_grids: &[Option<DenseGrid>],
) -> anyhow::Result<()> {
    let n = if quick { 64 } else { 128 };
    let base = crate::volume::hull_params(rig, crate::volume::BENCH_SIDE_M / n as f64)?;
    let params = |votes: usize| HullParams { carve_votes: votes, ..base.clone() };
    let carve_masks = |masks: &[Option<image::GrayImage>], votes: usize| -> anyhow::Result<(Occupancy, f64)> {
        let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Option::as_ref).collect();
        let t = Instant::now();
        let occ = carve(&silhouettes(rig, &refs)?, &params(votes))?;
        Ok((occ, t.elapsed().as_secs_f64() * 1e3))
    };
    let all: Vec<Option<image::GrayImage>> = masks.iter().cloned().map(Some).collect();
    let (clean, _) = carve_masks(&all, 1)?;
    let mut csv = String::from(
        "experiment,carve_votes,noise,cameras,carve_ms,cells_kept,iou_vs_clean_hull,hand_iou_vs_exact_hull,\
         scalpel_iou_vs_exact_hull,disagreed_most\n",
    );
    let mut row = |experiment: &str, votes: usize, noise: f64, cameras: usize, occ: &Occupancy, ms: f64| {
        let iou = occupancy_iou(occ, &clean, None).unwrap_or(0.0);
        let label_iou: Vec<String> = label::NAMED
            .iter()
            .zip(exact_grids)
            .map(|(&(l, _), e)| match (DenseGrid::from_occupancy(occ, Some(l)), e) {
                (Some(g), Some(e)) => grid_iou(&g, e, 200_000).map_or(String::new(), |v| format!("{v:.4}")),
                _ => String::new(),
            })
            .collect();
        let most = occ.stats.most_disagreeing_view().map_or("", |k| rig.cameras[k].name.as_str());
        csv.push_str(&format!(
            "{experiment},{votes},{noise},{cameras},{ms:.3},{},{iou:.4},{},{},{most}\n",
            occ.cells.len(),
            label_iou[0],
            label_iou[1]
        ));
        tracing::info!(experiment, votes, noise, cameras, iou, "robustness");
        iou
    };
    let mut noise_series = Vec::new();
    let mut camera_series = Vec::new();
    for votes in [1, 2] {
        let mut points = Vec::new();
        for fraction in [0.0, 0.005, 0.01, 0.02, 0.05] {
            let noisy: Vec<Option<image::GrayImage>> =
                masks.iter().enumerate().map(|(k, m)| Some(salt_and_pepper(m, fraction, k as u64 + 1))).collect();
            let (occ, ms) = carve_masks(&noisy, votes)?;
            points.push((fraction * 100.0, row("noise", votes, fraction, masks.len(), &occ, ms)));
        }
        noise_series.push(Series { label: format!("carve_votes {votes}"), points });
        let mut points = Vec::new();
        for cameras in 2..=masks.len() {
            let some: Vec<Option<image::GrayImage>> =
                masks.iter().enumerate().map(|(k, m)| (k < cameras).then(|| m.clone())).collect();
            let (occ, ms) = carve_masks(&some, votes)?;
            points.push((cameras as f64, row("cameras", votes, 0.0, cameras, &occ, ms)));
        }
        camera_series.push(Series { label: format!("carve_votes {votes}"), points });
    }
    let path = out.join("hull_robustness.csv");
    std::fs::write(&path, &csv).with_context(|| format!("writing {}", path.display()))?;
    line_chart(
        &out.join("hull_robustness_noise.png"),
        &format!("IoU with the clean classic hull ({n}³) against salt-and-pepper noise in all 6 views"),
        "pixels flipped, %",
        "IoU with the clean hull (carve_votes 1)",
        (Scale::Linear, Scale::Linear),
        &noise_series,
    )?;
    line_chart(
        &out.join("hull_robustness_cameras.png"),
        &format!("IoU with the six-view hull ({n}³) against the number of cameras (the first N)"),
        "cameras",
        "IoU with the six-view hull (carve_votes 1)",
        (Scale::Linear, Scale::Linear),
        &camera_series,
    )?;
    println!("wrote {} and the charts hull_robustness_noise.png, hull_robustness_cameras.png", path.display());
    Ok(())
}
