//! Diagnostic: the scalpel's hull against the exact one on a rendered cut-scene frame, for
//! carving variants. `scalpel_probe RIG TOOL LEAF_M` (RIG default|lab8|random:N, TOOL
//! standard|pointed).
use hullcut_dataset::label;
use hullcut_hull::accuracy::grid_iou;
use hullcut_hull::{Aabb, DenseGrid, HullParams, carve, carve_within, silhouettes};
use hullcut_rig::RigPreset;
use hullcut_synth::{Scene, SceneConfig, SceneKind, ToolKind};
use nalgebra::{Point3, Vector3};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let rig = RigPreset::parse(&args[1]).ok_or("rig")?;
    let tool = ToolKind::from_name(&args[2]).ok_or("tool")?;
    let leaf: f64 = args[3].parse()?;
    let frame = 48;
    let mut config = SceneConfig::new(SceneKind::Cut, 2, frame + 1);
    config.rig = rig.rig();
    config.tool = tool;
    let scene = Scene::new(config)?;
    let rig = scene.config().rig.clone();
    let masks: Vec<_> = (0..rig.len()).map(|c| scene.render_view(frame, c).map(|v| v.mask)).collect();
    let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Option::as_ref).collect();
    let views = silhouettes(&rig, &refs)?;
    let (mut lo, mut hi) = (Point3::from(Vector3::repeat(f64::MAX)), Point3::from(Vector3::repeat(f64::MIN)));
    for (_, mesh) in scene.truth_meshes(frame) {
        for v in &mesh.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
    }
    let tight = Aabb { min: lo - Vector3::repeat(0.02), max: hi + Vector3::repeat(0.02) };
    let base = HullParams { min_views: 3, ..HullParams::new(tight, leaf) };
    let occ = carve(&views, &base)?;
    let exact = carve_within(&views, &HullParams { leaf_size: leaf / 4.0, ..base.clone() }, &occ.cells)?;
    let eg = DenseGrid::from_occupancy(&exact, Some(label::SCALPEL)).ok_or("no exact scalpel")?;
    let vol = |o: &hullcut_hull::Occupancy| o.cells.iter().filter(|c| c.scalpel).map(|c| c.size.powi(3)).sum::<f64>();
    println!("exact scalpel volume {:.3} cm3", vol(&exact) * 1e6);
    for (name, p) in [
        ("base", base.clone()),
        ("min_support 1", HullParams { min_support: 1, ..base.clone() }),
        ("min_support 3", HullParams { min_support: 3, ..base.clone() }),
        ("exclusive", HullParams { exclusive_labels: true, ..base.clone() }),
        ("trim", HullParams { trim_slivers: true, ..base.clone() }),
        ("margin 0", HullParams { margin_px: 0.0, ..base.clone() }),
    ] {
        let o = carve(&views, &p)?;
        let g = DenseGrid::from_occupancy(&o, Some(label::SCALPEL)).ok_or("no scalpel")?;
        println!(
            "{name:14} scalpel volume {:.3} cm3 ({:.2}x), IoU {:.4}",
            vol(&o) * 1e6,
            vol(&o) / vol(&exact),
            grid_iou(&g, &eg, 200_000).unwrap_or(f64::NAN)
        );
    }
    for levels in [1u32, 2] {
        let fine = HullParams { leaf_size: leaf / f64::from(1u32 << levels), ..base.clone() };
        let seeds: Vec<_> = occ.cells.iter().filter(|c| c.scalpel).copied().collect();
        let t = std::time::Instant::now();
        let refined = carve_within(&views, &fine, &seeds)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let g = DenseGrid::from_occupancy(&refined, Some(label::SCALPEL)).ok_or("no scalpel")?;
        println!(
            "refined {levels}      scalpel volume {:.3} cm3 ({:.2}x), IoU {:.4}, {} seeds, {:.1} ms",
            vol(&refined) * 1e6,
            vol(&refined) / vol(&exact),
            grid_iou(&g, &eg, 200_000).unwrap_or(f64::NAN),
            seeds.len(),
            ms
        );
    }
    Ok(())
}
