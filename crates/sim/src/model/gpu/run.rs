//! Batches of GPU steps for a simulation's integrator, with counted falls back to the CPU: a
//! batch in which a cell inverted is left to the CPU (which regularizes it), and a device error
//! gives the GPU up for the rest of the run. Shared by [`crate::Simulation`] and
//! [`crate::CutSim`].

use std::sync::Arc;

use hullcut_gpu::Gpu;
use nalgebra::Vector3;

use super::GpuStepper;
use super::step::FlsmState;
use crate::dynamics::{Divergence, Integrator};

/// How the GPU backend has done so far (in the reports of `hullcut sim` and `hullcut run` with
/// `--backend gpu`).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GpuStats {
    /// The adapter's name.
    pub adapter: String,
    /// Batches of steps run on the GPU and kept.
    pub batches: u64,
    /// Steps they held.
    pub steps: u64,
    /// Batches the CPU ran instead (a cell inverted: the GPU does not regularize it).
    pub cpu_batches: u64,
    /// Steps the CPU ran in their place.
    pub cpu_steps: u64,
    /// Steppers built (pipelines compiled, every buffer created and written).
    pub uploads: u64,
    /// Times a stepper took over a changed lattice (after a cut) by writing only what changed.
    pub refits: u64,
    /// Bytes those refits wrote, and the bytes of the lattices' data they kept up to date: their
    /// ratio is what writing only the changed blocks saves.
    pub refit_bytes_written: u64,
    /// See `refit_bytes_written`.
    pub refit_bytes_total: u64,
    /// Device time of the step passes kept, milliseconds, from timestamp queries (`None` where the
    /// adapter has none): against the wall time it tells the device's work from the transfers,
    /// waits and submissions around it.
    pub device_ms: Option<f64>,
    /// Why the GPU was given up for the rest of the run (a device error), if it was.
    pub abandoned: Option<String>,
}

/// What a batch came to.
#[derive(Debug)]
pub(crate) enum Ran {
    /// The GPU's steps stand; the integrator holds their state.
    Gpu {
        /// Displacements one step before the integrator's `u_prev` (for reactions).
        u_older: Vec<Vector3<f32>>,
        /// Nodes pushed out of the obstacle in the last step.
        contacts: u32,
        /// Nodes put back on the table in the last step.
        table_contacts: u32,
        /// The hybrid's FLSM velocities and goal displacements after the batch.
        flsm: Option<FlsmState>,
    },
    /// The CPU must run these steps (counted in the stats).
    Cpu,
}

/// A GPU, the stepper for the current lattice and the counts.
#[derive(Debug)]
pub(crate) struct GpuRun {
    pub(crate) gpu: Arc<Gpu>,
    /// `None` until built.
    pub(crate) stepper: Option<GpuStepper>,
    /// The lattice changed since the stepper took it (a cut): refit before the next batch.
    pub(crate) stale: bool,
    /// Whether the GPU holds the integrator's state (false after the CPU stepped).
    pub(crate) in_sync: bool,
    pub(crate) stats: GpuStats,
    /// Set after a device error: everything runs on the CPU from then on.
    pub(crate) given_up: bool,
}

impl GpuRun {
    pub(crate) fn new(gpu: Arc<Gpu>) -> Self {
        let stats = GpuStats { adapter: gpu.summary.info.name.clone(), ..GpuStats::default() };
        Self { gpu, stepper: None, stale: false, in_sync: false, stats, given_up: false }
    }

    /// Uses `stepper` for the lattice from now on.
    pub(crate) fn install(&mut self, stepper: GpuStepper) {
        self.stepper = Some(stepper);
        self.stale = false;
        self.in_sync = false;
        self.stats.uploads += 1;
    }

    /// Counts a refit that wrote `written` of `total` bytes; the state is sent again.
    pub(crate) fn refitted(&mut self, written: u64, total: u64) {
        self.stale = false;
        self.in_sync = false;
        self.stats.refits += 1;
        self.stats.refit_bytes_written += written;
        self.stats.refit_bytes_total += total;
    }

    /// Gives the GPU up after a device error (the CPU goes on).
    pub(crate) fn give_up(&mut self, why: String) {
        tracing::warn!("GPU backend given up, the CPU goes on: {why}");
        self.stats.abandoned = Some(why);
        self.given_up = true;
        self.stepper = None;
    }

    /// `steps` steps of `integrator` on the GPU (its stepper must be installed), with the hybrid's
    /// FLSM velocities `flsm_v` sent along when the GPU's state is stale. On success the
    /// integrator holds the new state; a divergence leaves it at the last completed step.
    pub(crate) fn advance(
        &mut self,
        integrator: &mut Integrator,
        flsm_v: Option<&[Vector3<f32>]>,
        steps: u64,
    ) -> Result<Ran, Divergence> {
        let Some(stepper) = self.stepper.as_mut().filter(|_| !self.given_up) else {
            return Ok(Ran::Cpu);
        };
        if !self.in_sync {
            stepper.upload(integrator);
            if let Some(v) = flsm_v {
                stepper.upload_flsm_velocities(v);
            }
            self.in_sync = true;
        }
        let start = integrator.step;
        let batch = match stepper.run(start, u32::try_from(steps).unwrap_or(u32::MAX)) {
            Ok(b) => b,
            Err(e) => {
                self.give_up(e.to_string());
                return Ok(Ran::Cpu);
            }
        };
        if batch.inverted_cell_steps > 0 {
            tracing::debug!(
                inverted = batch.inverted_cell_steps,
                step = start,
                "inverted cells: the CPU runs the batch"
            );
            self.stats.cpu_batches += 1;
            self.stats.cpu_steps += steps;
            self.in_sync = false;
            return Ok(Ran::Cpu);
        }
        self.stats.batches += 1;
        self.stats.steps += u64::from(batch.completed);
        if let Some(ns) = batch.device_ns {
            *self.stats.device_ms.get_or_insert(0.0) += ns * 1e-6;
        }
        integrator.step = start + u64::from(batch.completed);
        integrator.u = batch.u;
        integrator.u_prev = batch.u_prev;
        if let Some(node) = batch.diverged_node {
            // The failed step's values are in u_older, where the node pass wrote them.
            let node = node as usize;
            let speed = (batch.u_older[node] - integrator.u[node]).norm() / integrator.dt;
            return Err(Divergence {
                step: integrator.step + 1,
                time: (integrator.step + 1) as f64 * f64::from(integrator.dt),
                node,
                reason: if speed.is_finite() {
                    format!("node {node} reached {speed:.3e} m/s, above the {:.3e} m/s limit", integrator.speed_limit)
                } else {
                    format!("node {node} has a non-finite displacement")
                },
            });
        }
        let flsm = match stepper.read_flsm() {
            Ok(f) => f,
            Err(e) => {
                // The displacements are in; the FLSM velocities are not: the CPU goes on from here.
                self.give_up(e.to_string());
                return Ok(Ran::Gpu {
                    u_older: batch.u_older,
                    contacts: batch.contacts,
                    table_contacts: batch.table_contacts,
                    flsm: None,
                });
            }
        };
        Ok(Ran::Gpu { u_older: batch.u_older, contacts: batch.contacts, table_contacts: batch.table_contacts, flsm })
    }
}
