//! `hullcut bench hull`: carving time against resolution (octree and dense grid) and accuracy
//! against the exact visual hull, on a rendered frame of the `cut` scene.

use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use hullcut_dataset::label;
use hullcut_hull::accuracy::grid_iou;
use hullcut_hull::{DenseGrid, HullParams, Occupancy, carve, silhouettes};
use hullcut_synth::{Scene, SceneConfig, SceneKind};

use crate::chart::{Scale, Series, line_chart};

/// The frame of the `cut` scene (seed 2, 30 fps) used: the blade is in the organ, mid-stroke.
const FRAME: u64 = 48;

fn timed_carve(
    views: &[Option<hullcut_hull::Silhouette>],
    params: &HullParams,
    repeats: usize,
) -> anyhow::Result<(Occupancy, f64)> {
    let mut best = f64::INFINITY;
    let mut occ = None;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let o = carve(views, params)?;
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
    let extent = HullParams::default().workspace.extent();
    let reference_n = if quick { 128 } else { 512 };
    let exact = carve(&views, &HullParams { leaf_size: extent / reference_n as f64, ..HullParams::default() })?;
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
    let mut accuracy: Vec<Series> =
        label::NAMED.iter().map(|&(_, n)| Series { label: format!("{n} (octree)"), points: Vec::new() }).collect();
    for &n in resolutions {
        let leaf = extent / n as f64;
        let depth = n.trailing_zeros();
        for (method, start_level) in [("octree", 3), ("dense", depth)] {
            if method == "dense" && n > dense_limit {
                continue;
            }
            let params = HullParams { leaf_size: leaf, start_level, ..HullParams::default() };
            let (occ, ms) = timed_carve(&views, &params, repeats)?;
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
            let k = usize::from(method == "dense");
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
    Ok(())
}
