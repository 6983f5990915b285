//! A [`Simulation`] stepped on the GPU ([`GpuStepper`]), with counted falls back to the CPU.

use std::sync::Arc;

use hullcut_gpu::Gpu;

use nalgebra::Vector3;

use super::Simulation;
use crate::SimError;
use crate::dynamics::Divergence;
use crate::gpu::{FlsmSetup, GpuRun, GpuStats, GpuStepper, Ran};

/// The GPU side of a simulation.
pub(super) type GpuPart = GpuRun;

impl Simulation {
    /// Steps this simulation on `gpu` from now on: TLED, and with the hybrid model its FLSM part
    /// and the interface pull. Refused (with the reason) for Gauss quadrature.
    pub fn use_gpu(&mut self, gpu: Arc<Gpu>) -> Result<(), SimError> {
        let flsm = self.flsm.as_ref().map(|part| FlsmSetup {
            layout: part.flsm.gpu_layout(),
            active: &part.active,
            substeps: part.steps.substeps as u32,
            dt: self.integrator.dt,
            applied: &self.f_applied,
        });
        let stepper =
            GpuStepper::with_flsm(gpu.clone(), &self.tled, &self.integrator, &self.f_applied, &self.rest, flsm)?;
        let mut run = GpuRun::new(gpu);
        run.install(stepper);
        self.gpu = Some(run);
        Ok(())
    }

    /// The GPU backend's counts, when it is in use.
    pub fn gpu_stats(&self) -> Option<&GpuStats> {
        self.gpu.as_ref().map(|g| &g.stats)
    }

    /// `advances` calls' worth of [`Simulation::advance`] on the GPU, or on the CPU where
    /// [`GpuRun`] says so (counted).
    pub(super) fn gpu_steps(&mut self, advances: u64) -> Result<(), Divergence> {
        let Some(run) = self.gpu.as_mut() else {
            return self.cpu_steps(advances);
        };
        let steps = advances * self.flsm.as_ref().map_or(1, |p| p.steps.substeps as u64);
        let flsm_v = self.flsm.as_ref().map(|p| &p.v[..]);
        let Ran::Gpu { u_older, flsm, .. } = run.advance(&mut self.integrator, flsm_v, steps)? else {
            return self.cpu_steps(advances);
        };
        let goals = match (self.flsm.as_mut(), flsm) {
            (Some(part), Some(state)) => {
                part.v = state.v;
                Some(state.goals)
            }
            _ => None,
        };
        // Reactions of the last step, from the internal forces at the state before it.
        if self.integrator.prescribed.iter().any(|p| p.groups != 0) {
            // The external forces of that step: the applied ones, and the interface pull toward
            // the goals of the last FLSM step.
            let mut f_ext = self.f_applied.clone();
            if let (Some(part), Some(goals)) = (&self.flsm, &goals) {
                for &i in &part.interface {
                    f_ext[i as usize] += goals[i as usize] * part.steps.beta;
                }
            }
            let it = &self.integrator;
            self.tled.element_pass(&it.u_prev);
            let tled = &self.tled;
            let mut reactions = vec![Vector3::zeros(); it.reactions.len()];
            it.reactions_into(
                |i| tled.node_force(i),
                &f_ext,
                [&u_older[..], &it.u_prev[..], &it.u[..]],
                &mut reactions,
            );
            self.integrator.reactions = reactions;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{NodeRole, Scenario};
    use nalgebra::Vector3;

    /// A clamped block pulled sideways at its x+ face (a ramp), under gravity and a point load:
    /// 12 x 8 x 6 cells of 5 mm.
    const BLOCK: &str = r#"
        [body]
        shape = "box"
        size = [0.06, 0.04, 0.03]
        cell = 0.005
        [[boundary]]
        faces = ["z-"]
        fix = ["x", "y", "z"]
        [[boundary]]
        box = { min = [0.06, 0.0, 0.005], max = [0.06, 0.04, 0.03] }
        displace = [0.004, 0.0, 0.002]
        ramp = 0.02
        [run]
        damping = 30.0
        gravity = [0.0, 0.0, -9.81]
        [[load]]
        box = { min = [0.0, 0.0, 0.03], max = [0.01, 0.04, 0.03] }
        force = [0.0, 0.3, -0.5]
        [report]
        reaction = ["z-", "x+"]
    "#;

    fn sim(text: &str) -> Simulation {
        Simulation::from_scenario(&Scenario::parse(text, "test.toml").expect("scenario")).expect("simulation")
    }

    fn largest(v: &[Vector3<f32>]) -> f32 {
        v.iter().map(|x| x.norm()).fold(0.0, f32::max)
    }

    #[test]
    fn gpu_steps_match_the_cpu_within_f32_rounding() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let gpu = Arc::new(gpu);
        let mut cpu = sim(BLOCK);
        let mut on_gpu = sim(BLOCK);
        on_gpu.use_gpu(gpu.clone()).expect("use_gpu");
        // Batches of 1, 300 (two submissions) and 99 steps: the buffers' rotation carries over.
        let steps = 400;
        cpu.advance_by(steps).expect("cpu");
        for n in [1, 300, 99] {
            on_gpu.advance_by(n).expect("gpu");
        }
        assert_eq!(on_gpu.integrator.step, steps);
        let stats = on_gpu.gpu_stats().expect("stats");
        assert_eq!((stats.batches, stats.steps, stats.cpu_batches), (3, steps, 0), "{stats:?}");
        let (a, b) = (&cpu.integrator.u, &on_gpu.integrator.u);
        let scale = largest(a);
        let worst = a.iter().zip(b).map(|(x, y)| (x - y).norm()).fold(0.0f32, f32::max);
        // Each step rounds a node's new displacement (about four operations) and its force (about
        // 150 dependent operations in each of up to 8 cells), and the force's error enters
        // through dt²/m: at the auto step (ω dt ≤ 1.6) a force error of ε|f| moves a node by at
        // most ε (ω dt)² ≈ 2.6 ε of its displacement, and a stable, damped central-difference step
        // does not amplify it. Worst case, every rounding adds up: N (4 + 2.6 · 1200) · 2⁻²⁴ ≈ 0.07
        // of the largest displacement for N = 400. Roundings are independent, so sums of them grow
        // as square roots: √N (2 + 2.6 √1200) · 6e-8 ≈ 1.1e-4; the bound is ten times that. A wrong
        // index, sign or ramp gives differences of order 1.
        let per_step = (2.0 + 2.6 * 1200f32.sqrt()) * f32::EPSILON / 2.0;
        let bound = 10.0 * (steps as f32).sqrt() * per_step;
        eprintln!(
            "GPU ({}) against CPU after {steps} steps: largest difference {:.2e} of {scale:.3e} m (bound {bound:.1e})",
            gpu.summary.info.name,
            worst / scale
        );
        assert!(worst <= bound * scale, "difference {worst} m against displacements up to {scale} m");
        for (r_cpu, r_gpu) in cpu.integrator.reactions.iter().zip(&on_gpu.integrator.reactions) {
            assert!((r_cpu - r_gpu).norm() <= 1e-3 * r_cpu.norm().max(1e-3), "reaction {r_gpu:?} against {r_cpu:?}");
        }
        assert!(cpu.integrator.reactions[1].x > 0.0, "the pulled face's reaction must be reported");
    }

    #[test]
    fn the_single_hexahedron_reaction_matches_the_closed_form_on_the_gpu() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/scenarios/hex-stretch.toml"))
                .expect("hex-stretch.toml");
        let mut s = sim(&text);
        s.use_gpu(Arc::new(gpu)).expect("use_gpu");
        let steps = (0.3 / s.dt()).ceil() as u64;
        s.advance_by(steps).expect("stable");
        // P_xx = 1.3 (μ (1 − 1/1.69) + λ 1.3 · 0.3 / 1.69) on 0.01 m²; the face is held at rest
        // after the ramp, and damping has settled the body by t = 0.3 s.
        let expected = 1.3 * (20_000.0 * (1.0 - 1.0 / 1.69) + 20_000.0 * 1.3 * 0.3 / 1.69) * 0.01;
        let got = s.integrator.reactions[0].x;
        assert!((got - expected).abs() < 0.01 * expected, "reaction {got} N, closed form {expected} N");
    }

    #[test]
    fn a_step_above_the_limit_is_reported_with_its_step_not_nan() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let mut s = sim(BLOCK);
        let dt = 1.5 * s.stability.dt_critical;
        let text = BLOCK.replace("damping = 30.0", &format!("damping = 30.0\ndt = {dt:e}"));
        let mut s2 = sim(&text);
        assert!(s2.dt_above_critical);
        s2.use_gpu(Arc::new(gpu)).expect("use_gpu");
        let err = s2.advance_by(5000).expect_err("unstable");
        assert!(err.step > 1 && err.step <= 5000, "{err:?}");
        assert_eq!(s2.integrator.step + 1, err.step);
        assert!(
            s2.integrator.u.iter().all(|u| u.iter().all(|x| x.is_finite())),
            "the state before the failure is finite"
        );
        assert!(err.reason.contains(&format!("node {}", err.node)), "{}", err.reason);
        // The CPU fails at the same step: the same arithmetic, up to rounding.
        s.integrator.dt = dt as f32;
        let cpu = s.advance_by(5000).expect_err("unstable on the cpu");
        assert!(cpu.step.abs_diff(err.step) <= 2, "cpu {} gpu {}", cpu.step, err.step);
    }

    #[test]
    fn a_batch_with_an_inverted_cell_is_redone_on_the_cpu_and_counted() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        // A 3 cm cube at rest, one interior node pushed through its neighbours to start with:
        // the cells around it are inverted, which the GPU counts and the CPU regularizes.
        let text = r#"
            [body]
            shape = "box"
            size = [0.03, 0.03, 0.03]
            cell = 0.01
            [[boundary]]
            faces = ["z-"]
            fix = ["x", "y", "z"]
            [run]
            damping = 200.0
        "#;
        let mut cpu = sim(text);
        let centre = cpu.lattice.node_at([1, 1, 1]).expect("node") as usize;
        cpu.integrator.u[centre] = Vector3::new(0.015, 0.015, 0.015);
        cpu.integrator.u_prev[centre] = cpu.integrator.u[centre];
        let mut s = sim(text);
        s.integrator.u.clone_from(&cpu.integrator.u);
        s.integrator.u_prev.clone_from(&cpu.integrator.u_prev);
        s.use_gpu(Arc::new(gpu)).expect("use_gpu");
        // The first batch inverts and is redone on the CPU, from the same state as the CPU run:
        // the same arithmetic, so the same numbers.
        cpu.advance_by(20).expect("stable on the cpu");
        s.advance_by(20).expect("stable");
        let stats = s.gpu_stats().expect("stats").clone();
        assert_eq!((stats.batches, stats.cpu_batches, stats.cpu_steps), (0, 1, 20), "{stats:?}");
        assert!(cpu.inverted_cells_max() > 0 && s.inverted_cells_max() > 0);
        assert_eq!(s.integrator.u, cpu.integrator.u);
        // Once the cells have recovered, batches run on the GPU again.
        for _ in 0..20 {
            s.advance_by(100).expect("stable");
        }
        let stats = s.gpu_stats().expect("stats");
        assert!(stats.batches >= 1, "{stats:?}");
        assert!(s.integrator.u.iter().all(|u| u.iter().all(|x| x.is_finite())));
        eprintln!("{stats:?}");
    }

    #[test]
    fn the_hybrid_on_the_gpu_moves_as_on_the_cpu() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let gpu = Arc::new(gpu);
        // FLSM matched to the material (a step per TLED step), and the seed's settings (an FLSM
        // step every 4 TLED steps, a weak interface pull: FLSM lags and swings).
        for hybrid in ["ratio = 0.5", "ratio = 0.4\nsubsteps = 4\nbeta = 200.0"] {
            let text = format!("{BLOCK}\n[hybrid]\n{hybrid}\n");
            let (mut cpu, mut on_gpu) = (sim(&text), sim(&text));
            assert!(cpu.hybrid_steps().is_some(), "a hybrid");
            on_gpu.use_gpu(gpu.clone()).expect("use_gpu");
            cpu.advance_by(200).expect("cpu");
            for n in [1, 120, 79] {
                on_gpu.advance_by(n).expect("gpu");
            }
            assert_eq!(on_gpu.integrator.step, cpu.integrator.step);
            let stats = on_gpu.gpu_stats().expect("stats");
            assert_eq!((stats.batches, stats.cpu_batches), (3, 0), "{stats:?}");
            let (a, b) = (&cpu.integrator.u, &on_gpu.integrator.u);
            let scale = largest(a);
            let worst = a.iter().zip(b).map(|(x, y)| (x - y).norm()).fold(0.0f32, f32::max);
            // The TLED part's rounding (see the all-TLED parity test) plus FLSM's: sums in f32
            // instead of f64, and rotations that stop within 1e-3 rad Newton steps on both
            // sides (leaving about 1e-6 rad), each FLSM step pulling nodes to goals that differ by
            // that much of a region's size.
            eprintln!(
                "hybrid ({hybrid:?}) after {} steps: GPU against CPU {:.2e} of {scale:.3e} m",
                cpu.integrator.step,
                worst / scale
            );
            assert!(worst <= 1e-3 * scale, "difference {worst} m against displacements up to {scale} m");
            for (r_cpu, r_gpu) in cpu.integrator.reactions.iter().zip(&on_gpu.integrator.reactions) {
                assert!(
                    (r_cpu - r_gpu).norm() <= 1e-2 * r_cpu.norm().max(1e-3),
                    "reaction {r_gpu:?} against {r_cpu:?}"
                );
            }
            // FLSM moved its nodes: they sag under gravity on both sides alike.
            let flsm_sag = |s: &Simulation| {
                s.roles
                    .iter()
                    .zip(&s.integrator.u)
                    .filter(|(r, _)| **r == NodeRole::Flsm)
                    .map(|(_, u)| u.z)
                    .fold(0.0f32, f32::min)
            };
            assert!(flsm_sag(&cpu) < -1e-5, "FLSM nodes sag: {}", flsm_sag(&cpu));
            assert!((flsm_sag(&cpu) - flsm_sag(&on_gpu)).abs() <= 1e-3 * scale);
        }
    }

    #[test]
    fn gauss_quadrature_is_refused_with_its_key() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let mut gauss = sim(&format!("{BLOCK}\n[tled]\nintegration = \"gauss8\"\n"));
        let err = gauss.use_gpu(Arc::new(gpu)).expect_err("gauss8");
        assert!(err.to_string().contains("tled.integration"), "{err}");
    }
}
