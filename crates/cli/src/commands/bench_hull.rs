//! `hullcut bench hull`: carving speed and accuracy on three rigs (the default six cameras, the
//! lab's eight 1280x720 cameras with another scalpel, a seeded random rig), against Open3D's
//! carving of the same masks when a Python with Open3D is given; and where carving breaks (noise,
//! fewer cameras).

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use hullcut_dataset::label;
use hullcut_hull::accuracy::{grid_iou, occupancy_iou};
use hullcut_hull::gpu::GpuCarver;
use hullcut_hull::{Aabb, DenseGrid, HullParams, Occupancy, Silhouette, carve, carve_within, silhouettes};
use hullcut_rig::{Camera, Rig, RigPreset};
use hullcut_synth::texture::mix64;
use hullcut_synth::{Scene, SceneConfig, SceneKind, ToolKind};
use image::GrayImage;
use nalgebra::{Point3, Vector2, Vector3};

use crate::chart::{Scale, Series, line_chart};

/// Open3D's reference carving (shared/tools/vh_open3d.py) and the Python that runs it.
#[derive(Debug, Clone)]
pub struct Open3d {
    /// A Python with open3d, numpy and opencv-python installed (a virtual environment).
    pub python: PathBuf,
    /// The script.
    pub script: PathBuf,
}

/// One rig with its scene: the frame of the `cut` scene (seed 2, 30 fps) where the blade is in
/// the organ mid-stroke.
struct Setup {
    name: &'static str,
    rig: RigPreset,
    tool: ToolKind,
}

const SETUPS: [Setup; 3] = [
    Setup { name: "default", rig: RigPreset::Default, tool: ToolKind::Standard },
    Setup { name: "lab8", rig: RigPreset::Lab8, tool: ToolKind::Pointed },
    Setup { name: "random:7", rig: RigPreset::Random(7), tool: ToolKind::Standard },
];

const FRAME: u64 = 48;

/// A rendered frame: the rig, its truth masks and their summed-area tables, the box the hand and
/// tool occupy (padded by 2 cm: the volume a lab would give with --workspace) and the rig's own
/// volume.
struct Frame {
    rig: Rig,
    masks: Vec<GrayImage>,
    views: Vec<Option<Silhouette>>,
    tight: Aabb,
    rig_volume: Aabb,
}

fn render(setup: &Setup) -> anyhow::Result<Frame> {
    let mut config = SceneConfig::new(SceneKind::Cut, 2, FRAME + 1);
    config.rig = setup.rig.rig();
    config.tool = setup.tool;
    let scene = Scene::new(config)?;
    let rig = scene.config().rig.clone();
    let masks: Vec<GrayImage> = (0..rig.len())
        .map(|c| scene.render_view(FRAME, c).map(|v| v.mask).context("the cut scene drops no frames"))
        .collect::<anyhow::Result<_>>()?;
    let refs: Vec<Option<&GrayImage>> = masks.iter().map(Some).collect();
    let views = silhouettes(&rig, &refs)?;
    let (mut lo, mut hi) = (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
    for (_, mesh) in scene.truth_meshes(FRAME) {
        for v in &mesh.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
    }
    let pad = Vector3::repeat(0.02);
    let tight = Aabb { min: lo - pad, max: hi + pad };
    let rig_volume = crate::volume::of_rig(&rig)?.aabb;
    Ok(Frame { rig, masks, views, tight, rig_volume })
}

/// The method name of the rows whose scalpel leaves are carved a level finer.
const BLADE_REFINED: &str = "octree, blade refined a level";

fn params(volume: Aabb, leaf: f64, trim: bool) -> HullParams {
    HullParams { min_views: crate::volume::MIN_VIEWS, trim_slivers: trim, ..HullParams::new(volume, leaf) }
}

fn timed(repeats: usize, mut f: impl FnMut() -> anyhow::Result<Occupancy>) -> anyhow::Result<(Occupancy, f64)> {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let occ = f()?;
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        last = Some(occ);
    }
    Ok((last.context("no carving run")?, best))
}

/// Per-label IoU of a hull with the exact one, from 200,000 lattice samples.
fn label_ious(occ: &Occupancy, exact: &[Option<DenseGrid>]) -> [Option<f64>; 2] {
    let mut out = [None; 2];
    for (k, (&(l, _), e)) in label::NAMED.iter().zip(exact).enumerate() {
        if let (Some(g), Some(e)) = (DenseGrid::from_occupancy(occ, Some(l)), e) {
            out[k] = grid_iou(&g, e, 200_000);
        }
    }
    out
}

/// One row of hull.csv.
struct Row {
    rig: String,
    method: String,
    volume: &'static str,
    leaf_mm: f64,
    ms: f64,
    cells: usize,
    hand_iou: Option<f64>,
    scalpel_iou: Option<f64>,
}

/// Runs the hull benchmark into `out`.
pub fn run(out: &Path, quick: bool, open3d: Option<&Open3d>) -> anyhow::Result<()> {
    let leaves: &[f64] = if quick { &[0.004, 0.002] } else { &[0.002, 0.001] };
    let repeats = if quick { 1 } else { 5 };
    let mut gpu = match hullcut_gpu::Gpu::new(&hullcut_gpu::AdapterChoice::from_env()) {
        Ok(g) => Some(GpuCarver::new(std::sync::Arc::new(g))?),
        Err(e) => {
            tracing::warn!("hull.csv without the GPU rows: {e}");
            None
        }
    };
    let mut rows: Vec<Row> = Vec::new();
    let mut first = None;
    for setup in SETUPS.iter().take(if quick { 2 } else { 3 }) {
        let frame = render(setup)?;
        println!(
            "{}: {} cameras; volume from the rig {:.2} x {:.2} x {:.2} m, around the hand and tool {:.2} x {:.2} x {:.2} m",
            setup.name,
            frame.rig.len(),
            frame.rig_volume.max.x - frame.rig_volume.min.x,
            frame.rig_volume.max.y - frame.rig_volume.min.y,
            frame.rig_volume.max.z - frame.rig_volume.min.z,
            frame.tight.max.x - frame.tight.min.x,
            frame.tight.max.y - frame.tight.min.y,
            frame.tight.max.z - frame.tight.min.z,
        );
        for &leaf in leaves {
            let row = |rows: &mut Vec<Row>,
                       method: &str,
                       volume: &'static str,
                       ms: f64,
                       occ: &Occupancy,
                       exact: &[Option<DenseGrid>]| {
                let [hand_iou, scalpel_iou] = label_ious(occ, exact);
                tracing::info!(rig = setup.name, method, leaf, ms, "carved");
                rows.push(Row {
                    rig: setup.name.to_owned(),
                    method: method.to_owned(),
                    volume,
                    leaf_mm: leaf * 1e3,
                    ms,
                    cells: occ.cells.len(),
                    hand_iou,
                    scalpel_iou,
                });
            };
            for trim in [false, true] {
                let p = params(frame.tight, leaf, trim);
                let (occ, ms) = timed(repeats, || Ok(carve(&frame.views, &p)?))?;
                // The exact visual hull: the same rule at a quarter of the leaf, inside this hull.
                let fine = HullParams { leaf_size: leaf / 4.0, ..p.clone() };
                let seeds = if trim {
                    carve(&frame.views, &HullParams { trim_slivers: false, ..p.clone() })?
                } else {
                    occ.clone()
                };
                let exact = carve_within(&frame.views, &fine, &seeds.cells)?;
                let grids: Vec<Option<DenseGrid>> =
                    label::NAMED.iter().map(|&(l, _)| DenseGrid::from_occupancy(&exact, Some(l))).collect();
                let method = if trim { "octree, slivers trimmed" } else { "octree" };
                row(&mut rows, method, "tight", ms, &occ, &grids);
                if trim {
                    continue;
                }
                let pb = HullParams { blade_levels: 1, ..p.clone() };
                let (occ_blade, ms) = timed(repeats, || Ok(carve(&frame.views, &pb)?))?;
                row(&mut rows, BLADE_REFINED, "tight", ms, &occ_blade, &grids);
                let pr = params(frame.rig_volume, leaf, false);
                let (occ_rig, ms) = timed(repeats, || Ok(carve(&frame.views, &pr)?))?;
                row(&mut rows, "octree", "rig", ms, &occ_rig, &grids);
                if leaf >= 0.002 {
                    let depth = p.depth()?;
                    let pd = HullParams { start_level: depth, ..p.clone() };
                    let (occ_dense, ms) = timed(1, || Ok(carve(&frame.views, &pd)?))?;
                    row(&mut rows, "dense grid", "tight", ms, &occ_dense, &grids);
                }
                if let Some(g) = gpu.as_mut() {
                    let (occ_gpu, ms) = timed(repeats, || Ok(g.carve(&frame.views, &p)?))?;
                    row(&mut rows, "octree on the GPU", "tight", ms, &occ_gpu, &grids);
                }
                if let Some(o3d) = open3d {
                    let (ms, ious) = run_open3d(o3d, &frame, leaf, &exact, out)?;
                    rows.push(Row {
                        rig: setup.name.to_owned(),
                        method: "Open3D carve_silhouette".to_owned(),
                        volume: "tight",
                        leaf_mm: leaf * 1e3,
                        ms,
                        cells: 0,
                        hand_iou: ious,
                        scalpel_iou: None,
                    });
                }
            }
        }
        if first.is_none() {
            first = Some(frame);
        }
    }
    write_rows(out, &rows)?;
    charts(out, &rows)?;
    let Some(frame) = first else { bail!("no rig carved") };
    robustness(out, quick, &frame)
}

fn write_rows(out: &Path, rows: &[Row]) -> anyhow::Result<()> {
    let path = out.join("hull.csv");
    let mut w = csv::Writer::from_path(&path).with_context(|| format!("writing {}", path.display()))?;
    w.write_record([
        "rig",
        "method",
        "volume",
        "leaf_mm",
        "carve_ms",
        "cells_kept",
        "hand_iou_vs_exact_hull",
        "scalpel_iou_vs_exact_hull",
    ])?;
    let f = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.4}"));
    for r in rows {
        w.write_record([
            r.rig.clone(),
            r.method.clone(),
            r.volume.to_owned(),
            format!("{:.3}", r.leaf_mm),
            format!("{:.3}", r.ms),
            r.cells.to_string(),
            f(r.hand_iou),
            f(r.scalpel_iou),
        ])?;
    }
    w.flush().with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    for r in rows {
        println!(
            "  {:9} {:26} {:5} {:.1} mm: {:9.2} ms, hand IoU {}, scalpel IoU {}",
            r.rig,
            r.method,
            r.volume,
            r.leaf_mm,
            r.ms,
            f(r.hand_iou),
            f(r.scalpel_iou)
        );
    }
    Ok(())
}

/// hull_speed.png (carve ms against leaf, per rig and method) and hull_accuracy.png (IoU with the
/// exact hull against carve ms).
fn charts(out: &Path, rows: &[Row]) -> anyhow::Result<()> {
    let mut speed: Vec<Series> = Vec::new();
    let mut accuracy: Vec<Series> = Vec::new();
    let mut blade: Vec<Series> = Vec::new();
    for r in rows.iter().filter(|r| r.volume == "tight" && r.method != "dense grid") {
        let label = format!("{} {}", r.rig, r.method);
        match speed.iter_mut().find(|s| s.label == label) {
            Some(s) => s.points.push((r.leaf_mm, r.ms)),
            None => speed.push(Series { label: label.clone(), points: vec![(r.leaf_mm, r.ms)] }),
        }
        let add = |chart: &mut Vec<Series>, label: String, iou: Option<f64>| {
            let Some(iou) = iou else { return };
            match chart.iter_mut().find(|s| s.label == label) {
                Some(s) => s.points.push((r.ms, iou)),
                None => chart.push(Series { label, points: vec![(r.ms, iou)] }),
            }
        };
        if r.method == "octree" {
            add(&mut accuracy, format!("{} hand", r.rig), r.hand_iou);
            add(&mut accuracy, format!("{} scalpel", r.rig), r.scalpel_iou);
            add(&mut blade, format!("{} scalpel", r.rig), r.scalpel_iou);
        } else if r.method == BLADE_REFINED {
            add(&mut blade, format!("{} scalpel, refined a level", r.rig), r.scalpel_iou);
        }
    }
    // Eight colours: the three rigs' main lines first.
    speed.sort_by_key(|s| (s.label.contains("GPU"), s.label.contains("trimmed"), s.label.contains("refined")));
    speed.truncate(8);
    line_chart(
        &out.join("hull_speed.png"),
        "Carving time against leaf size, one cut-scene frame per rig, the box around hand and tool",
        "leaf, mm",
        "carve ms (best of runs)",
        (Scale::Log, Scale::Log),
        &speed,
    )?;
    accuracy.sort_by_key(|s| s.label.contains("scalpel"));
    line_chart(
        &out.join("hull_accuracy.png"),
        "IoU with the exact visual hull (a quarter leaf) against carve time, 2 mm and 1 mm leaves",
        "carve ms",
        "IoU",
        (Scale::Log, Scale::Linear),
        &accuracy,
    )?;
    blade.sort_by_key(|s| s.label.contains("refined"));
    line_chart(
        &out.join("hull_blade.png"),
        "The scalpel's IoU with the exact visual hull against carve time: leaves, and the blade a level finer",
        "carve ms",
        "scalpel IoU",
        (Scale::Log, Scale::Linear),
        &blade,
    )?;
    println!("wrote the charts hull_speed.png, hull_accuracy.png, hull_blade.png");
    Ok(())
}

/// A mask seen through the camera without its distortion (same K): what a pinhole-only tool such
/// as Open3D must be given for the comparison to be fair. Nearest-pixel lookup.
fn undistorted(camera: &Camera, mask: &GrayImage) -> GrayImage {
    let (w, h) = (camera.width, camera.height);
    GrayImage::from_fn(w, h, |i, j| {
        let xn = Vector2::new((f64::from(i) - camera.cx) / camera.fx, (f64::from(j) - camera.cy) / camera.fy);
        let uv = camera.normalized_to_pixel(camera.distortion.distort(xn));
        let (u, v) = ((uv.x + 0.5).floor(), (uv.y + 0.5).floor());
        if u >= 0.0 && v >= 0.0 && u < f64::from(w) && v < f64::from(h) {
            image::Luma([u8::from(mask.get_pixel(u as u32, v as u32).0[0] != label::BACKGROUND) * 255])
        } else {
            image::Luma([0])
        }
    })
}

/// Runs Open3D's carving on the frame's masks (undistorted) in the tight box; its carve seconds
/// and the IoU of its voxels (either label: Open3D carves one silhouette) with the exact hull.
fn run_open3d(
    o3d: &Open3d,
    frame: &Frame,
    leaf: f64,
    exact: &Occupancy,
    out: &Path,
) -> anyhow::Result<(f64, Option<f64>)> {
    let dir = out.join("open3d");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut cameras = Vec::new();
    for (k, (cam, mask)) in frame.rig.cameras.iter().zip(&frame.masks).enumerate() {
        let file = format!("cam{k:02}.png");
        undistorted(cam, mask)
            .save(dir.join(&file))
            .with_context(|| format!("writing {}", dir.join(&file).display()))?;
        let r = cam.rotation.matrix();
        let t = cam.translation;
        let e = [
            [r[(0, 0)], r[(0, 1)], r[(0, 2)], t.x],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)], t.y],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)], t.z],
            [0.0, 0.0, 0.0, 1.0],
        ];
        cameras.push(serde_json::json!({
            "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
            "width": cam.width, "height": cam.height, "extrinsic": e, "silhouette": file,
        }));
    }
    let rig_json = dir.join("rig.json");
    std::fs::write(&rig_json, serde_json::to_string(&serde_json::json!({ "cameras": cameras }))?)?;
    let npy = dir.join(format!("hull_{:.0}um.npy", leaf * 1e6));
    let (lo, hi) = (frame.tight.min, frame.tight.max);
    let output = std::process::Command::new(&o3d.python)
        .arg(&o3d.script)
        .args(["--rig", &rig_json.to_string_lossy(), "--sil-dir", &dir.to_string_lossy(), "--voxel", &leaf.to_string()])
        .args(["--bbox-min", &lo.x.to_string(), &lo.y.to_string(), &lo.z.to_string()])
        .args(["--bbox-max", &hi.x.to_string(), &hi.y.to_string(), &hi.z.to_string()])
        .args(["--out", &npy.to_string_lossy()])
        .output()
        .with_context(|| format!("running {} {}", o3d.python.display(), o3d.script.display()))?;
    if !output.status.success() {
        bail!("Open3D's carving failed: {}", String::from_utf8_lossy(&output.stderr));
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    let result: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .context("reading the result line of the Open3D script")?;
    let seconds = result["seconds_carve"].as_f64().context("no seconds_carve in Open3D's result")?
        + result["seconds_create_dense"].as_f64().unwrap_or(0.0);
    let centres = read_npy_points(&npy)?;
    // IoU of Open3D's voxels with the exact hull (either label), by samples over both boxes.
    let set: HashSet<[i64; 3]> =
        centres.iter().map(|c| [0, 1, 2].map(|a| ((c[a] - lo[a]) / leaf).floor() as i64)).collect();
    let in_o3d = |p: &Point3<f64>| set.contains(&[0, 1, 2].map(|a| ((p[a] - lo[a]) / leaf).floor() as i64));
    let exact_grid = DenseGrid::from_occupancy(exact, None);
    let iou = exact_grid.map(|g| {
        let n = 60usize;
        let (a, b) = (lo, hi);
        let (mut both, mut either) = (0u64, 0u64);
        for k in 0..n * n * n {
            let p = Point3::new(
                a.x + (b.x - a.x) * ((k % n) as f64 + 0.5) / n as f64,
                a.y + (b.y - a.y) * (((k / n) % n) as f64 + 0.5) / n as f64,
                a.z + (b.z - a.z) * ((k / (n * n)) as f64 + 0.5) / n as f64,
            );
            let (x, y) = (in_o3d(&p), g.contains(&p));
            both += u64::from(x && y);
            either += u64::from(x || y);
        }
        both as f64 / either.max(1) as f64
    });
    Ok((seconds * 1e3, iou))
}

/// The points of an (N, 3) float64 `.npy` file (NumPy's format, version 1 or 2).
fn read_npy_points(path: &Path) -> anyhow::Result<Vec<[f64; 3]>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let bad = |m: &str| anyhow::anyhow!("{}: {m}", path.display());
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("not a .npy file"));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        _ if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        _ => return Err(bad("truncated header")),
    };
    let header = std::str::from_utf8(bytes.get(start..start + header_len).ok_or_else(|| bad("truncated header"))?)?;
    if !header.contains("'<f8'") || header.contains("'fortran_order': True") {
        return Err(bad("expected little-endian float64 in C order"));
    }
    let data = &bytes[start + header_len..];
    Ok(data
        .chunks_exact(24)
        .map(|c| std::array::from_fn(|k| f64::from_le_bytes(c[8 * k..8 * k + 8].try_into().unwrap_or([0; 8]))))
        .collect())
}

/// Flips `fraction` of a mask's pixels (deterministic for a seed): background becomes hand, any
/// foreground becomes background.
pub(crate) fn salt_and_pepper(mask: &GrayImage, fraction: f64, seed: u64) -> GrayImage {
    let mut out = mask.clone();
    for (n, p) in out.pixels_mut().enumerate() {
        let u = (mix64(seed.wrapping_mul(0x1000_0000_01b3) ^ n as u64) >> 11) as f64 / (1u64 << 53) as f64;
        if u < fraction {
            p.0[0] = if p.0[0] == label::BACKGROUND { label::HAND } else { label::BACKGROUND };
        }
    }
    out
}

/// Salt-and-pepper noise in every view, and fewer cameras (the first N of the default rig), for
/// carve_votes 1 and 2: IoU of all kept cells with the clean hull at the same resolution.
fn robustness(out: &Path, quick: bool, frame: &Frame) -> anyhow::Result<()> {
    let leaf = if quick { 0.00625 } else { 0.003125 };
    let (rig, masks) = (&frame.rig, &frame.masks);
    let params = |votes: usize| HullParams { carve_votes: votes, ..params(frame.tight, leaf, false) };
    let carve_masks = |masks: &[Option<GrayImage>], votes: usize| -> anyhow::Result<(Occupancy, f64)> {
        let refs: Vec<Option<&GrayImage>> = masks.iter().map(Option::as_ref).collect();
        let t = Instant::now();
        let occ = carve(&silhouettes(rig, &refs)?, &params(votes))?;
        Ok((occ, t.elapsed().as_secs_f64() * 1e3))
    };
    let all: Vec<Option<GrayImage>> = masks.iter().cloned().map(Some).collect();
    let (clean, _) = carve_masks(&all, 1)?;
    let path = out.join("hull_robustness.csv");
    let mut w = csv::Writer::from_path(&path).with_context(|| format!("writing {}", path.display()))?;
    w.write_record([
        "experiment",
        "carve_votes",
        "noise",
        "cameras",
        "carve_ms",
        "cells_kept",
        "iou_vs_clean_hull",
        "disagreed_most",
    ])?;
    let mut noise_series = Vec::new();
    let mut camera_series = Vec::new();
    for votes in [1, 2] {
        let mut points = Vec::new();
        for fraction in [0.0, 0.005, 0.01, 0.02, 0.05] {
            let noisy: Vec<Option<GrayImage>> =
                masks.iter().enumerate().map(|(k, m)| Some(salt_and_pepper(m, fraction, k as u64 + 1))).collect();
            let (occ, ms) = carve_masks(&noisy, votes)?;
            let iou = occupancy_iou(&occ, &clean, None).unwrap_or(0.0);
            let most = occ.stats.most_disagreeing_view().map_or("", |k| rig.cameras[k].name.as_str());
            w.write_record([
                "noise".to_owned(),
                votes.to_string(),
                fraction.to_string(),
                masks.len().to_string(),
                format!("{ms:.3}"),
                occ.cells.len().to_string(),
                format!("{iou:.4}"),
                most.to_owned(),
            ])?;
            points.push((fraction * 100.0, iou));
        }
        noise_series.push(Series { label: format!("carve_votes {votes}"), points });
        let mut points = Vec::new();
        for cameras in 2..=masks.len() {
            let some: Vec<Option<GrayImage>> =
                masks.iter().enumerate().map(|(k, m)| (k < cameras).then(|| m.clone())).collect();
            let (occ, ms) = carve_masks(&some, votes)?;
            let iou = occupancy_iou(&occ, &clean, None).unwrap_or(0.0);
            w.write_record([
                "cameras".to_owned(),
                votes.to_string(),
                "0".to_owned(),
                cameras.to_string(),
                format!("{ms:.3}"),
                occ.cells.len().to_string(),
                format!("{iou:.4}"),
                String::new(),
            ])?;
            points.push((cameras as f64, iou));
        }
        camera_series.push(Series { label: format!("carve_votes {votes}"), points });
    }
    w.flush().with_context(|| format!("writing {}", path.display()))?;
    line_chart(
        &out.join("hull_robustness_noise.png"),
        &format!("IoU with the clean hull ({:.1} mm leaves) against salt-and-pepper noise in every view", leaf * 1e3),
        "pixels flipped, %",
        "IoU with the clean hull",
        (Scale::Linear, Scale::Linear),
        &noise_series,
    )?;
    line_chart(
        &out.join("hull_robustness_cameras.png"),
        &format!(
            "IoU with the all-camera hull ({:.1} mm leaves) against the number of cameras (the first N)",
            leaf * 1e3
        ),
        "cameras",
        "IoU with the all-camera hull",
        (Scale::Linear, Scale::Linear),
        &camera_series,
    )?;
    println!("wrote {} and the charts hull_robustness_noise.png, hull_robustness_cameras.png", path.display());
    Ok(())
}
