//! Measures a far-field model against all-TLED on the built-in organ cut by the true poses of the
//! built-in resection scene: ms of tissue work per frame set for each, and the RMS difference of
//! the lattice nodes' positions near the blade (within 2 cm of its cutting edge) and everywhere.
//! `far_field_probe CELL_M RADIUS_M MODEL [FRAMES]` (MODEL flsm|frozen).
use std::time::Instant;

use hullcut_pipeline::tissue::{self, Sweeper, Tissue};
use hullcut_pipeline::{StageTimes, no_tool_estimate};
use hullcut_pose::{BladePose, Template, rigid_from_matrix};
use hullcut_sim::{FarField, HybridParams};
use hullcut_synth::{Scene, SceneConfig, SceneKind};
use nalgebra::Point3;

/// Near the blade: within this distance of a point of its cutting edge, metres.
const NEAR_M: f32 = 0.02;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let cell: f64 = args[1].parse()?;
    let radius: f64 = args[2].parse()?;
    let far_field = match args[3].as_str() {
        "flsm" => FarField::Flsm,
        "frozen" => FarField::Frozen,
        other => return Err(format!("unknown model {other}").into()),
    };
    let frames: u64 = args.get(4).map_or(Ok(180), |f| f.parse())?;
    // Profiling the model alone: FAR_FIELD_PROBE_MODEL_ONLY=1 skips the all-TLED reference.
    let skip_reference = std::env::var_os("FAR_FIELD_PROBE_MODEL_ONLY").is_some();
    let mut config = SceneConfig::new(SceneKind::Resect, 1, frames);
    config.stroke_depth = [0.018, 0.035];
    let scene = Scene::new(config)?;
    let geometry = &scene.scalpel().geometry;
    let template = Template::new(geometry)?;
    let hybrid = HybridParams { radius, far_field, ..HybridParams::default() };
    let clock = Instant::now();
    let mut reference = tissue::build("organ", cell, None, None)?;
    let mut model = tissue::build("organ", cell, Some(hybrid), None)?;
    let nodes = reference.sim.lattice().node_count();
    println!(
        "{nodes} lattice nodes, {} cells at {:.1} mm; set up both in {:.1} s",
        reference.sim.lattice().cells.len(),
        cell * 1e3,
        clock.elapsed().as_secs_f64()
    );
    let (mut sweep_ref, mut sweep_model) = (Sweeper::default(), Sweeper::default());
    let (mut times_ref, mut times_model, mut last) = (StageTimes::default(), StageTimes::default(), None);
    let (mut ms_ref, mut ms_model) = (0.0, 0.0);
    let (mut worst_near, mut worst_all, mut awake) = (0.0f64, 0.0f64, 0usize);
    for frame in 0..frames {
        let truth = scene.truth_pose(frame);
        let seconds = last.map_or(0.0, |t: i64| ((truth.timestamp_ns - t) as f64 * 1e-9).clamp(0.0, 0.2));
        last = Some(truth.timestamp_ns);
        let pose = rigid_from_matrix(&truth.tool_to_world)?;
        let mut estimate = no_tool_estimate(frame, truth.timestamp_ns);
        estimate.valid = true;
        estimate.pose = Some(BladePose::new(&template, pose));
        let step = |organ: &mut Tissue,
                    sweeper: &mut Sweeper,
                    times: &mut StageTimes|
         -> Result<f64, Box<dyn std::error::Error>> {
            let clock = Instant::now();
            let mut step = sweeper.next(Some(&estimate), Some(&template), organ.cell);
            organ.step(&mut step, seconds, None, times)?;
            Ok(clock.elapsed().as_secs_f64() * 1e3)
        };
        if !skip_reference {
            ms_ref += step(&mut reference, &mut sweep_ref, &mut times_ref)?;
        }
        ms_model += step(&mut model, &mut sweep_model, &mut times_model)?;
        awake += model.sim.tled_cells();
        let edge: Vec<Point3<f32>> = geometry.cutting_edge.iter().map(|p| (pose * p).cast::<f32>()).collect();
        let (a, b) = (reference.sim.node_positions(), model.sim.node_positions());
        let (mut near, mut n_near, mut all) = (0.0f64, 0usize, 0.0f64);
        for n in 0..nodes {
            let d2 = f64::from((a[n] - b[n]).norm_squared());
            all += d2;
            if edge.iter().any(|e| (a[n] - e).norm() < NEAR_M) {
                near += d2;
                n_near += 1;
            }
        }
        let rms_all = (all / nodes as f64).sqrt() * 1e3;
        let rms_near = if n_near > 0 { (near / n_near as f64).sqrt() * 1e3 } else { 0.0 };
        worst_all = worst_all.max(rms_all);
        worst_near = worst_near.max(rms_near);
        if frame % 30 == 29 || frame + 1 == frames {
            println!(
                "frame {frame}: RMS {rms_near:.3} mm near the blade ({n_near} nodes), {rms_all:.3} mm everywhere; {} of {} cells awake; pieces {} / {}",
                model.sim.tled_cells(),
                model.sim.lattice().cells.len(),
                reference.sim.pieces(),
                model.sim.pieces()
            );
        }
    }
    let f = frames as f64;
    let mean = |v: &[std::time::Duration]| v.iter().map(|d| d.as_secs_f64() * 1e3).sum::<f64>() / f;
    for (name, t) in [("all-TLED", &times_ref), ("far field", &times_model)] {
        println!(
            "{name}: ms per frame set: collide {:.2}, cut topology {:.2}, cut surface {:.2}, contact {:.2}, deform {:.2}, tissue surface {:.2}",
            mean(&t.collide),
            mean(&t.cut_topology),
            mean(&t.cut_surface),
            mean(&t.contact),
            mean(&t.deform),
            mean(&t.tissue_surface)
        );
    }
    println!(
        "{far_field:?} at {:.0} mm: {:.2} ms per frame set against {:.2} all-TLED ({:.2}x); worst RMS {worst_near:.3} mm near the blade, {worst_all:.3} mm everywhere; {:.0} cells awake on average",
        radius * 1e3,
        ms_model / f,
        ms_ref / f,
        ms_ref / ms_model,
        awake as f64 / f
    );
    Ok(())
}
