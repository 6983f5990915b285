//! Diagnostic: the piece the true poses of the built-in resection scene cut off the built-in
//! organ, per rig, tool and lattice cell. `resection_probe RIG TOOL CELL_M [FRAMES]`.
use hullcut_pipeline::tissue::{self, Sweeper};
use hullcut_pipeline::{StageTimes, no_tool_estimate};
use hullcut_pose::{BladePose, Template, rigid_from_matrix};
use hullcut_rig::RigPreset;
use hullcut_synth::{Scene, SceneConfig, SceneKind, ToolKind};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let rig = RigPreset::parse(&args[1]).ok_or("rig")?;
    let tool = ToolKind::from_name(&args[2]).ok_or("tool")?;
    let cell: f64 = args[3].parse()?;
    let frames: u64 = args.get(4).map_or(Ok(150), |f| f.parse())?;
    let mut config = SceneConfig::new(SceneKind::Resect, 1, frames);
    config.rig = rig.rig();
    config.tool = tool;
    config.stroke_depth = [0.018, 0.035];
    let scene = Scene::new(config)?;
    let template = Template::new(&scene.scalpel().geometry)?;
    let mut organ = tissue::build("organ", cell, None, None)?;
    let (mut sweeper, mut times, mut last) = (Sweeper::default(), StageTimes::default(), None);
    for frame in 0..frames {
        let truth = scene.truth_pose(frame);
        let seconds = last.map_or(0.0, |t: i64| ((truth.timestamp_ns - t) as f64 * 1e-9).clamp(0.0, 0.2));
        last = Some(truth.timestamp_ns);
        let mut estimate = no_tool_estimate(frame, truth.timestamp_ns);
        estimate.valid = true;
        estimate.pose = Some(BladePose::new(&template, rigid_from_matrix(&truth.tool_to_world)?));
        let mut step = sweeper.next(Some(&estimate), Some(&template), organ.cell);
        organ.step(&mut step, seconds, None, &mut times)?;
    }
    let pieces = organ.sim.piece_states();
    let ml: Vec<String> = pieces.iter().map(|p| format!("{:.2}", p.volume_m3 * 1e6)).collect();
    println!("{} {} {:.1} mm: {} pieces, ml {}", args[1], args[2], cell * 1e3, pieces.len(), ml.join(" "));
    Ok(())
}
