//! A [`CutSim`] stepped on the GPU: TLED everywhere (the hybrid stays on the CPU), the stepper
//! built anew for each cut lattice, the hand's obstacle uploaded each advance.

use std::sync::Arc;

use hullcut_gpu::Gpu;

use super::{CutSim, MAX_PUSH_PER_STEP};
use crate::SimError;
use crate::dynamics::Divergence;
use crate::gpu::{ContactShapes, GpuRun, GpuStats, GpuStepper, Ran};

impl CutSim {
    /// Steps this body on `gpu` from now on (all TLED). Refused for the hybrid model, whose FLSM
    /// part runs on the CPU only.
    pub fn use_gpu(&mut self, gpu: Arc<Gpu>) -> Result<(), SimError> {
        if self.params.hybrid.is_some() {
            return Err(SimError::Gpu(
                "the GPU backend runs the tissue all-TLED; the hybrid model (--operational-radius) runs on the CPU only"
                    .into(),
            ));
        }
        self.gpu = Some(GpuRun::new(gpu));
        Ok(())
    }

    /// The GPU backend's counts, when it is in use.
    pub fn gpu_stats(&self) -> Option<&GpuStats> {
        self.gpu.as_ref().map(|g| &g.stats)
    }

    /// The hand's obstacle and the table, as the GPU's contact pass takes them.
    fn contact_shapes(&self) -> ContactShapes {
        ContactShapes {
            grid: self.obstacles.first().map(crate::Obstacle::push_grid),
            table: self.params.table.map(|t| (t.height as f32, t.friction as f32)),
        }
    }

    /// `steps` TLED steps on the GPU; `false` when the CPU must run them (no GPU, the hybrid
    /// model, more than one obstacle, a cell inverted, or a device error: the last two counted).
    pub(super) fn gpu_steps(&mut self, steps: usize) -> Result<bool, Divergence> {
        if self.params.hybrid.is_some() || self.obstacles.len() > 1 {
            return Ok(false);
        }
        if self.gpu.as_ref().is_none_or(|r| r.given_up) {
            return Ok(false);
        }
        let shapes = self.contact_shapes();
        let Some(run) = self.gpu.as_mut() else {
            return Ok(false);
        };
        if run.stepper.is_none() || run.stale {
            let rest: Vec<_> = self.rest.iter().map(|p| p.coords).collect();
            let done = match run.stepper.as_mut() {
                Some(stepper) => stepper
                    .refit(&self.tled, &self.integrator, &self.f_ext, &rest)
                    .map(|(written, total)| run.refitted(written, total)),
                None => GpuStepper::new(run.gpu.clone(), &self.tled, &self.integrator, &self.f_ext, &rest)
                    .map(|s| run.install(s)),
            };
            if let Err(e) = done {
                run.give_up(e.to_string());
                return Ok(false);
            }
        }
        let max_push = (MAX_PUSH_PER_STEP * self.lattice.cell) as f32;
        if let Some(stepper) = run.stepper.as_mut()
            && let Err(e) = stepper.set_contacts(&shapes, max_push)
        {
            run.give_up(e.to_string());
            return Ok(false);
        }
        match run.advance(&mut self.integrator, None, steps as u64)? {
            Ran::Gpu { contacts, table_contacts, .. } => {
                self.contacts = contacts as usize;
                self.table_contacts = table_contacts as usize;
                Ok(true)
            }
            Ran::Cpu => Ok(false),
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Point3, Vector3};

    use super::*;
    use crate::body::box_sdf;
    use crate::cutting::tests::{finger, l_shape, vertical_stroke};
    use crate::{CutSimParams, HybridParams, Lattice, Material};

    /// A 6 x 3 x 3 cm bar of 1 cm cells held at x = 0, under gravity (as the CPU's cutting test).
    fn bar() -> CutSim {
        let size = Vector3::new(0.06, 0.03, 0.03);
        let lattice = Lattice::block(Point3::origin(), 0.01, [6, 3, 3]);
        let material = Material::from_young_poisson(5.0e4, 0.45, 1000.0);
        let params = CutSimParams { samples_per_cell: 4, ..CutSimParams::default() };
        CutSim::new(lattice, &box_sdf(size), material, |p| p.x < 1e-9, params).expect("sim")
    }

    /// Largest node distance between two runs, relative to the largest displacement of the first.
    fn difference(a: &CutSim, b: &CutSim) -> f32 {
        let scale = a.displacements().iter().map(|u| u.norm()).fold(0.0f32, f32::max);
        let worst = a.displacements().iter().zip(b.displacements()).map(|(x, y)| (x - y).norm()).fold(0.0f32, f32::max);
        worst / scale
    }

    #[test]
    fn a_bar_cut_on_the_gpu_moves_as_on_the_cpu() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let (mut cpu, mut on_gpu) = (bar(), bar());
        on_gpu.use_gpu(Arc::new(gpu)).expect("use_gpu");
        for sim in [&mut cpu, &mut on_gpu] {
            sim.advance(0.1).expect("stable");
            let cut = sim.cut(&vertical_stroke(0.037, 0.05, -0.01)).expect("cut");
            assert_eq!(cut.pieces, 2);
            sim.advance(0.1).expect("stable after the cut");
        }
        let stats = on_gpu.gpu_stats().expect("stats").clone();
        assert_eq!(
            (stats.uploads, stats.refits, stats.cpu_batches),
            (1, 1, 0),
            "built once, refitted at the cut: {stats:?}"
        );
        assert!(stats.refit_bytes_written > 0 && stats.refit_bytes_written <= stats.refit_bytes_total, "{stats:?}");
        assert_eq!(stats.steps, on_gpu.integrator.step, "{stats:?}");
        // The cut-off end falls on both; the fields agree to f32 rounding over the steps run (the
        // derivation of the Simulation parity test: √N (2 + 2.6 √1200) 6e-8, ten times over).
        let steps = on_gpu.integrator.step as f32;
        let bound = 10.0 * steps.sqrt() * (2.0 + 2.6 * 1200f32.sqrt()) * f32::EPSILON / 2.0;
        let d = difference(&cpu, &on_gpu);
        eprintln!(
            "cut bar after {steps} steps: GPU against CPU {d:.2e} of the largest displacement (bound {bound:.1e})"
        );
        assert!(d <= bound, "{d} > {bound}");
        let lowest = |s: &CutSim| s.node_positions().iter().map(|p| p.z).fold(f32::MAX, f32::min);
        assert!(lowest(&on_gpu) < -0.01, "the free end falls: {}", lowest(&on_gpu));
    }

    #[test]
    fn a_finger_pushes_the_tissue_on_the_gpu_as_on_the_cpu() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let block = || {
            let lattice = Lattice::block(Point3::origin(), 0.005, [8, 8, 6]);
            let material = Material::from_young_poisson(3.0e3, 0.45, 1000.0);
            let size = Vector3::new(0.04, 0.04, 0.03);
            CutSim::new(lattice, &box_sdf(size), material, |p| p.z < 1e-9, CutSimParams::default()).expect("sim")
        };
        // The CPU test's finger, reaching 6 mm into the block's top.
        let (finger, h) = finger();
        let (mut cpu, mut on_gpu) = (block(), block());
        on_gpu.use_gpu(Arc::new(gpu)).expect("use_gpu");
        for sim in [&mut cpu, &mut on_gpu] {
            sim.advance(0.3).expect("stable");
            sim.set_obstacles(vec![finger.clone()]);
            sim.advance(0.3).expect("stable with contact");
        }
        assert!(on_gpu.contacts() > 0 && cpu.contacts() > 0);
        assert_eq!(on_gpu.gpu_stats().expect("stats").cpu_batches, 0);
        let centre = |s: &CutSim| {
            s.node_positions()
                .iter()
                .filter(|p| (p.x - 0.02).abs() < 1e-3 && (p.y - 0.02).abs() < 1e-3)
                .map(|p| p.z)
                .fold(f32::MIN, f32::max)
        };
        // Contact snaps positions to the finger's voxels, so a rounding at a voxel boundary may
        // move a node by one capped push (an eighth of a millimetre); the pressed top agrees to a
        // tenth of a voxel.
        let (c, g) = (centre(&cpu), centre(&on_gpu));
        assert!((c - g).abs() < 0.1 * h as f32, "pressed top: cpu {c} gpu {g}");
        let deepest =
            on_gpu.node_positions().iter().filter_map(|p| finger.push_at(p)).map(|d| d.norm()).fold(0.0, f32::max);
        assert!(deepest <= 1.01 * h as f32, "a node {deepest} m inside the finger");
    }

    #[test]
    fn a_piece_cut_off_falls_onto_the_table_and_rests_on_the_gpu_as_on_the_cpu() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let table = crate::Table { height: 0.0, friction: 0.5 };
        let (mut cpu, mut on_gpu) = (l_shape(Some(table)), l_shape(Some(table)));
        on_gpu.use_gpu(Arc::new(gpu)).expect("use_gpu");
        for sim in [&mut cpu, &mut on_gpu] {
            sim.advance(0.2).expect("stable");
            assert_eq!(sim.cut(&vertical_stroke(0.0455, 0.05, -0.02)).expect("cut").pieces, 2);
            sim.advance(0.6).expect("stable");
        }
        assert_eq!(on_gpu.gpu_stats().expect("stats").cpu_batches, 0);
        assert!(on_gpu.table_contacts() > 0 && cpu.table_contacts() > 0);
        // The cut-off end of the arm (x > 4.5 cm) rests on the table on both, where it fell.
        let far_end = |s: &CutSim| -> (f32, f32) {
            let far: Vec<_> = s
                .node_positions()
                .iter()
                .zip(0..)
                .filter(|(_, n)| s.topology().rest(s.lattice(), *n).x > 0.0455)
                .map(|(p, _)| *p)
                .collect();
            let lowest = far.iter().map(|p| p.z).fold(f32::MAX, f32::min);
            (lowest, far.iter().map(|p| p.x).sum::<f32>() / far.len() as f32)
        };
        let ((cpu_low, cpu_x), (gpu_low, gpu_x)) = (far_end(&cpu), far_end(&on_gpu));
        assert!(gpu_low.abs() < 2e-4 && cpu_low.abs() < 2e-4, "lowest: cpu {cpu_low} gpu {gpu_low}");
        // The pieces' contact (the falling end slides down the stub's cut face) is enforced after
        // every step on the CPU and after every 1/30 s batch on the GPU, so where the end comes to
        // rest differs by a little (1.5 mm measured); within half a cell.
        assert!((cpu_x - gpu_x).abs() < 2.5e-3, "where it rests: cpu x {cpu_x} gpu x {gpu_x}");
    }

    #[test]
    fn the_hybrid_stays_on_the_cpu_with_a_clear_error() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let lattice = Lattice::block(Point3::origin(), 0.01, [4, 3, 3]);
        let params = CutSimParams { hybrid: Some(HybridParams::default()), ..CutSimParams::default() };
        let size = Vector3::new(0.04, 0.03, 0.03);
        let mut sim = CutSim::new(lattice, &box_sdf(size), Material::default(), |p| p.x < 1e-9, params).expect("sim");
        let err = sim.use_gpu(Arc::new(gpu)).expect_err("hybrid");
        assert!(err.to_string().contains("--operational-radius"), "{err}");
    }
}
