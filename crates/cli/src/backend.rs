//! The `--backend` choice of `reconstruct`, `sim` and `run`, and where each stage then runs.

use std::sync::Arc;

use anyhow::Context as _;
use hullcut_gpu::{AdapterChoice, Gpu};
use hullcut_hull::gpu::GpuCarver;
use hullcut_hull::{HullError, HullParams, Occupancy, Silhouette, carve};
use serde::{Deserialize, Serialize};

/// Where the compute runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// The CPU, on rayon's threads.
    Cpu,
    /// A GPU through wgpu (the adapter as `hullcut gpu-info` shows; HULLCUT_GPU_ADAPTER chooses).
    Gpu,
}

impl Backend {
    /// Opens the GPU for `Backend::Gpu` (a clear error naming the flag when there is none).
    pub fn open(self) -> anyhow::Result<Option<Arc<Gpu>>> {
        match self {
            Backend::Cpu => Ok(None),
            Backend::Gpu => {
                let gpu = Gpu::new(&AdapterChoice::from_env()).context("--backend gpu")?;
                tracing::info!(adapter = %gpu.summary.info.name, "GPU backend");
                Ok(Some(Arc::new(gpu)))
            }
        }
    }
}

/// Where the visual hull is carved.
#[derive(Debug)]
pub enum Carver {
    /// [`hullcut_hull::carve`] on rayon.
    Cpu,
    /// [`GpuCarver`].
    Gpu(Box<GpuCarver>),
}

impl Carver {
    /// The carver for an opened backend.
    pub fn new(gpu: Option<&Arc<Gpu>>) -> anyhow::Result<Self> {
        Ok(match gpu {
            Some(g) => Carver::Gpu(Box::new(GpuCarver::new(Arc::clone(g)).context("--backend gpu: the hull")?)),
            None => Carver::Cpu,
        })
    }

    /// Carves, as [`hullcut_hull::carve`].
    pub fn carve(&mut self, views: &[Option<Silhouette>], params: &HullParams) -> Result<Occupancy, HullError> {
        match self {
            Carver::Cpu => carve(views, params),
            Carver::Gpu(g) => g.carve(views, params),
        }
    }
}
