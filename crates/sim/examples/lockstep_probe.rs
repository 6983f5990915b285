//! Runs two cut scenarios (the same body and blade, two models) in lockstep and prints, every 6
//! frames, the RMS difference of the lattice nodes' positions, split by the piece each node is in
//! (all-TLED's piece numbering) and for nodes near the blade's edge: where a model's error lives.
//! `lockstep_probe REFERENCE.toml MODEL.toml`.
use hullcut_sim::{Scenario, ScriptedCut};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let load = |p: &str| -> Result<ScriptedCut, Box<dyn std::error::Error>> {
        Ok(ScriptedCut::from_scenario(&Scenario::load(std::path::Path::new(p))?)?)
    };
    let (mut a, mut b) = (load(&args[1])?, load(&args[2])?);
    let frames = a.frames_for(Scenario::load(std::path::Path::new(&args[1]))?.run.duration);
    for k in 0..frames {
        a.frame()?;
        b.frame()?;
        if k % 6 != 5 {
            continue;
        }
        let nodes = a.sim.lattice().node_count();
        let (pa, pb) = (a.sim.node_positions(), b.sim.node_positions());
        let edge = a.blade.edge_at(a.sim.time());
        let (x0, y0) = (edge[0].x as f32, edge[0].y as f32);
        let mut sums = [(0.0f64, 0usize); 3];
        for n in 0..nodes {
            let d2 = f64::from((pa[n] - pb[n]).norm_squared());
            // Beyond the cut plane (the lobe's tip), near the edge (2 cm in plan), the rest.
            let near = ((pa[n].x - x0).powi(2) + (pa[n].y - y0).powi(2)).sqrt() < 0.02;
            let g = if a.sim.lattice().rest[n].x > edge[0].x {
                0
            } else if near {
                1
            } else {
                2
            };
            sums[g].0 += d2;
            sums[g].1 += 1;
        }
        let rms = |g: usize| (sums[g].0 / sums[g].1.max(1) as f64).sqrt() * 1e3;
        println!(
            "frame {k:3}: RMS mm beyond the cut plane {:.3} ({} nodes), near the edge {:.3} ({}), the rest {:.3}; awake {} / {}",
            rms(0),
            sums[0].1,
            rms(1),
            sums[1].1,
            rms(2),
            b.sim.tled_cells(),
            a.sim.tled_cells()
        );
    }
    Ok(())
}
