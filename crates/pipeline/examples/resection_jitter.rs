//! Diagnostic: whether the built-in resection cuts the lobe off the organ's 5 mm lattice when its
//! true poses are disturbed as a pose stage's are.
//! `resection_jitter RIG TOOL MM DEG SEEDS [DX_MM DZ_MM DRIFT_MM REFUSED_PCT]`: each seed adds to every
//! frame's true pose a translation uniform in a ball of MM millimetres, a turn of up to DEG
//! degrees about the tip, a fixed shift (DX_MM across the blade's plane, DZ_MM up) and a drift
//! across the plane of DRIFT_MM amplitude over two seconds, refuses REFUSED_PCT percent of the
//! frame sets at random (their poses do not cut), and prints the pieces. With
//! `HC_PLANE=1` it also maps the node plane x = 55 mm the blade's plane lies on: per node, which
//! of its x-edges is cut (`L` toward lower x, `H` higher, `B` both, `.` neither), `|` an in-plane
//! edge cut toward the next node along y and `-` one toward the node below.
use std::collections::{BTreeMap, BTreeSet};

use hullcut_pipeline::tissue::{self, Sweeper};
use hullcut_pipeline::{StageTimes, no_tool_estimate};
use hullcut_pose::{BladePose, Template, rigid_from_matrix};
use hullcut_rig::RigPreset;
use hullcut_sim::CutSim;
use hullcut_synth::{Scene, SceneConfig, SceneKind, ToolKind};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn ball(&mut self) -> Vector3<f64> {
        loop {
            let v = Vector3::new(2.0 * self.next() - 1.0, 2.0 * self.next() - 1.0, 2.0 * self.next() - 1.0);
            if v.norm_squared() <= 1.0 {
                return v;
            }
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        return Err("usage: resection_jitter RIG TOOL MM DEG SEEDS [DX_MM DZ_MM DRIFT_MM REFUSED_PCT]".into());
    }
    let rig = RigPreset::parse(&args[1]).ok_or("rig")?;
    let tool = ToolKind::from_name(&args[2]).ok_or("tool")?;
    let (mm, deg): (f64, f64) = (args[3].parse()?, args[4].parse()?);
    let seeds: u64 = args[5].parse()?;
    let extra = |k: usize| args.get(k).map_or(Ok(0.0), |v| v.parse::<f64>());
    let (dx, dz, drift, refused) = (extra(6)?, extra(7)?, extra(8)?, extra(9)?);
    let mut config = SceneConfig::new(SceneKind::Resect, 1, 150);
    config.rig = rig.rig();
    config.tool = tool;
    config.stroke_depth = [0.018, 0.035];
    let scene = Scene::new(config)?;
    let template = Template::new(&scene.scalpel().geometry)?;
    for seed in 0..seeds {
        let mut rng = Rng(seed.wrapping_mul(0x2545_f491_4f6c_dd1d) ^ 7);
        let mut organ = tissue::build("organ", 0.005, None, None)?;
        let (mut sweeper, mut times, mut last) = (Sweeper::default(), StageTimes::default(), None);
        for frame in 0..150 {
            let truth = scene.truth_pose(frame);
            let seconds = last.map_or(0.0, |t: i64| (truth.timestamp_ns - t) as f64 * 1e-9);
            last = Some(truth.timestamp_ns);
            let pose = rigid_from_matrix(&truth.tool_to_world)?;
            let wave = (frame as f64 / 30.0 * std::f64::consts::PI + seed as f64 * 1.7).sin();
            let shift = rng.ball() * mm + Vector3::new(dx + drift * wave, 0.0, dz);
            let turn = UnitQuaternion::from_scaled_axis(rng.ball().normalize() * (rng.next() * deg).to_radians());
            let tip = pose * template.tip;
            let about_tip = Translation3::from(tip.coords) * turn * Translation3::from(-tip.coords);
            let moved: Isometry3<f64> = Translation3::from(shift * 1e-3) * about_tip * pose;
            let mut estimate = no_tool_estimate(frame, truth.timestamp_ns);
            estimate.valid = rng.next() * 100.0 >= refused;
            estimate.pose = Some(BladePose::new(&template, moved));
            let mut step = sweeper.next(Some(&estimate), Some(&template), organ.cell);
            organ.step(&mut step, seconds, None, &mut times)?;
        }
        let ml: Vec<String> = organ.sim.piece_states().iter().map(|p| format!("{:.2}", p.volume_m3 * 1e6)).collect();
        println!(
            "seed {seed}: {} piece(s), ml {}, {} edges cut",
            ml.len(),
            ml.join(" "),
            organ.sim.topology().cut.len()
        );
        if std::env::var_os("HC_PLANE").is_some() {
            print_plane(&organ.sim);
        }
    }
    Ok(())
}

/// The map of the node plane x = 55 mm described in the module's documentation.
fn print_plane(sim: &CutSim) {
    let (lattice, topology) = (sim.lattice(), sim.topology());
    let cut = |a: u32, b: u32| topology.cut.contains_key(&(a.min(b), a.max(b)));
    let step = |n: u32, axis: usize, by: i64| {
        let mut ijk = lattice.node_ijk[n as usize].map(i64::from);
        ijk[axis] += by;
        (ijk[axis] >= 0).then(|| lattice.node_at(ijk.map(|v| v as usize))).flatten()
    };
    let mm = |v: f64| (v * 1e3).round() as i64;
    let mut rows: BTreeMap<i64, BTreeMap<i64, u32>> = BTreeMap::new();
    for n in 0..lattice.node_count() as u32 {
        let p = lattice.rest[n as usize];
        if (p.x - 0.055).abs() < 1e-6 {
            rows.entry(-mm(p.z)).or_default().insert(mm(p.y), n);
        }
    }
    let ys: BTreeSet<i64> = rows.values().flat_map(|r| r.keys().copied()).collect();
    println!("y {:?} mm", ys.iter().collect::<Vec<_>>());
    for (minus_z, row) in &rows {
        let (mut nodes, mut below) = (format!("z {:>3}: ", -minus_z), String::from("        "));
        for y in &ys {
            let Some(&n) = row.get(y) else {
                nodes.push_str("  ");
                below.push_str("  ");
                continue;
            };
            let low = step(n, 0, -1).is_some_and(|m| cut(n, m));
            let high = step(n, 0, 1).is_some_and(|m| cut(n, m));
            nodes.push(match (low, high) {
                (true, true) => 'B',
                (true, false) => 'L',
                (false, true) => 'H',
                (false, false) => '.',
            });
            nodes.push(if step(n, 1, 1).is_some_and(|m| cut(n, m)) { '|' } else { ' ' });
            below.push(if step(n, 2, -1).is_some_and(|m| cut(n, m)) { '-' } else { ' ' });
            below.push(' ');
        }
        println!("{nodes}\n{below}");
    }
}
