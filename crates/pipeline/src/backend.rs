//! Where the compute runs (`--backend`), and the hull's carver on it.

#[cfg(feature = "gpu")]
use std::sync::Arc;

#[cfg(feature = "gpu")]
use hullcut_hull::gpu::GpuCarver;
use hullcut_hull::{HullError, HullParams, Occupancy, Silhouette, carve};
use serde::{Deserialize, Serialize};

#[cfg(feature = "gpu")]
use crate::error::Context as _;
use crate::error::Error;

/// Where the compute runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// The CPU, on rayon's threads.
    Cpu,
    /// A GPU through wgpu (the adapter as `hullcut gpu-info` shows; HULLCUT_GPU_ADAPTER chooses).
    Gpu,
}

/// An opened GPU (with the `gpu` feature; without it there is none to hold).
#[cfg(feature = "gpu")]
pub type GpuHandle = Arc<hullcut_gpu::Gpu>;

/// An opened GPU: none can be opened without the `gpu` feature.
#[cfg(not(feature = "gpu"))]
#[derive(Debug, Clone)]
pub enum GpuHandle {}

impl Backend {
    /// Opens the GPU for `Backend::Gpu` (a clear error naming the flag when there is none, or
    /// when this build has no GPU support).
    pub fn open(self) -> Result<Option<GpuHandle>, Error> {
        match self {
            Backend::Cpu => Ok(None),
            #[cfg(feature = "gpu")]
            Backend::Gpu => {
                let gpu = hullcut_gpu::Gpu::new(&hullcut_gpu::AdapterChoice::from_env()).context("--backend gpu")?;
                tracing::info!(adapter = %gpu.summary.info.name, "GPU backend");
                Ok(Some(Arc::new(gpu)))
            }
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => Err(Error::msg("--backend gpu: hullcut-pipeline was built without its `gpu` feature")),
        }
    }
}

/// Where the visual hull is carved.
#[derive(Debug)]
pub enum Carver {
    /// [`hullcut_hull::carve`] on rayon.
    Cpu,
    /// The GPU's octree carver.
    #[cfg(feature = "gpu")]
    Gpu(Box<GpuCarver>),
}

impl Carver {
    /// The carver for an opened backend.
    pub fn new(gpu: Option<&GpuHandle>) -> Result<Self, Error> {
        Ok(match gpu {
            #[cfg(feature = "gpu")]
            Some(g) => Carver::Gpu(Box::new(GpuCarver::new(Arc::clone(g)).context("--backend gpu: the hull")?)),
            #[cfg(not(feature = "gpu"))]
            Some(never) => match *never {},
            None => Carver::Cpu,
        })
    }

    /// Carves, as [`hullcut_hull::carve`].
    pub fn carve(&mut self, views: &[Option<Silhouette>], params: &HullParams) -> Result<Occupancy, HullError> {
        match self {
            Carver::Cpu => carve(views, params),
            #[cfg(feature = "gpu")]
            Carver::Gpu(g) => g.carve(views, params),
        }
    }
}
