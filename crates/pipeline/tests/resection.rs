//! The built-in resection's blade plane (x = 55 mm) lies on a plane of the organ's 5 mm lattice
//! nodes, so which edges a sweep crosses is decided by rounding: the true poses, and poses a hair
//! to either side of them, must cut the lobe's tip off at the loop's lattice all the same.

use hullcut_pipeline::tissue::{self, Sweeper};
use hullcut_pipeline::{StageTimes, no_tool_estimate};
use hullcut_pose::{BladePose, Template, rigid_from_matrix};
use hullcut_rig::RigPreset;
use hullcut_synth::{Scene, SceneConfig, SceneKind, ToolKind};
use nalgebra::{Isometry3, Translation3};

/// The pieces' volumes (ml, smallest first) after the resection's 150 frame sets with every true
/// pose moved by `shift` (metres, world).
fn resect(rig: &str, tool: ToolKind, shift: [f64; 3]) -> Vec<f64> {
    let mut config = SceneConfig::new(SceneKind::Resect, 1, 150);
    config.rig = RigPreset::parse(rig).expect("a rig").rig();
    config.tool = tool;
    config.stroke_depth = [0.018, 0.035];
    let scene = Scene::new(config).expect("the scene");
    let template = Template::new(&scene.scalpel().geometry).expect("a template");
    let mut organ = tissue::build("organ", 0.005, None, None).expect("the organ");
    let (mut sweeper, mut times, mut last) = (Sweeper::default(), StageTimes::default(), None);
    for frame in 0..150 {
        let truth = scene.truth_pose(frame);
        let seconds = last.map_or(0.0, |t: i64| (truth.timestamp_ns - t) as f64 * 1e-9);
        last = Some(truth.timestamp_ns);
        let pose: Isometry3<f64> = Translation3::from(nalgebra::Vector3::from(shift))
            * rigid_from_matrix(&truth.tool_to_world).expect("rigid");
        let mut estimate = no_tool_estimate(frame, truth.timestamp_ns);
        estimate.valid = true;
        estimate.pose = Some(BladePose::new(&template, pose));
        let mut step = sweeper.next(Some(&estimate), Some(&template), organ.cell);
        organ.step(&mut step, seconds, None, &mut times).expect("a step");
    }
    let mut ml: Vec<f64> = organ.sim.piece_states().iter().map(|p| p.volume_m3 * 1e6).collect();
    ml.sort_by(f64::total_cmp);
    ml
}

#[test]
fn the_resection_cuts_the_tip_off_with_its_blade_on_a_node_plane_or_a_hair_beside_it() {
    // The true poses of both tools' resections (before the cut's boxes had slack, the standard
    // blade's left the lobe joined by the nodes on the table), and the standard blade's moved a
    // hundredth of a millimetre to either side of the node plane or up.
    for (rig, tool, shift) in [
        ("default", ToolKind::Standard, [0.0, 0.0, 0.0]),
        ("default", ToolKind::Pointed, [0.0, 0.0, 0.0]),
        ("default", ToolKind::Standard, [-1e-5, 0.0, 0.0]),
        ("default", ToolKind::Standard, [1e-5, 0.0, 0.0]),
        ("default", ToolKind::Standard, [0.0, 0.0, 1e-5]),
    ] {
        let ml = resect(rig, tool, shift);
        assert_eq!(ml.len(), 2, "{rig}, {tool:?}, shift {shift:?}: pieces {ml:?}");
        assert!((18.0..20.5).contains(&ml[0]), "{rig}, {tool:?}, shift {shift:?}: tip {} ml", ml[0]);
    }
}
