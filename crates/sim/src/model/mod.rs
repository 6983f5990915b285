//! The deformation model: the body voxelized into a hexahedral lattice, its materials, TLED
//! (nonlinear FEM) and FLSM (lattice shape matching), their hybrid, the explicit integrator and
//! its computed stability limit, surfaces embedded in the lattice, the scenario-driven
//! [`simulation::Simulation`], and their GPU passes ([`gpu`]).
//!
//! Nothing here knows about cutting: [`crate::cut`] builds on this module, never the reverse.

pub mod body;
pub mod dynamics;
pub mod embed;
pub mod flsm;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod lattice;
pub mod material;
pub mod operational;
pub mod simulation;
pub mod stability;
pub mod tled;
mod tled_batch;
mod tled_slabs;

/// The vector instructions the model's passes are compiled for, found at run time: AVX2
/// (x86-64-v3) at most on x86-64, although the workspace lets pulp dispatch to AVX-512 (the
/// segmentation's foreground test gains from it). The TLED and integrator passes, written for
/// 8-wide f32 lanes, ran 40% slower with AVX-512 on the built-in scene (deformation 10.3 ->
/// 14.6 ms a frame set, measured 2026-12-01); the same arithmetic, so the same results, on any.
pub(crate) fn simd_arch() -> pulp::Arch {
    #[cfg(target_arch = "x86_64")]
    {
        pulp::x86::V3::try_new().map_or(pulp::Arch::Scalar, pulp::Arch::V3)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        pulp::Arch::new()
    }
}
