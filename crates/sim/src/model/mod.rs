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
