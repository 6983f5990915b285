//! Soft-tissue simulation for hullcut: lattice, TLED, FLSM and their hybrid.
//!
//! Entry points: [`Scenario`] (the TOML scenario) and [`Simulation::from_scenario`] /
//! [`Simulation::advance`]; every value a scenario gives is checked against documented limits
//! ([`scenario`]'s constants, [`MAX_STEPS`], [`MAX_SUBSTEPS`], [`MAX_LATTICE_CELLS`]). The building
//! blocks: [`Lattice`], [`body::voxelize`], [`Tled`], [`flsm::Flsm`], [`stability::estimate`],
//! [`dynamics::Integrator`] and [`embed::Embedding`].
//!
//! Cutting: [`SweptSurface`] (the blade edge's sweep between two trusted poses), [`cut_edges`] with
//! a [`CellTree`] (the lattice edges it crosses), [`CutTopology`] (the virtual node algorithm's
//! cell copies and virtual nodes, and the cut lattice that TLED runs on),
//! [`cut_surface::piece_surfaces`] (a closed surface per piece, cut faces included) and
//! [`CutSim`], which puts them together under gravity: TLED everywhere, or the hybrid model with
//! an operational region that follows the tool ([`operational`]). The scenario-driven
//! [`Simulation`] (hybrid TLED/FLSM with a fixed operational region) does not cut; a scenario
//! with `[cut]` runs as a [`ScriptedCut`] (a blade moved along keys, cut frame by frame).
//!
//! The crate's folders are its architecture: [`model`] is the deformation model, [`cut`] cutting
//! and contact on top of it (never the reverse), [`scenario`] the TOML scenarios at the edge.
//!
//! Feature `gpu`: TLED on wgpu ([`gpu`]: internal forces and whole steps) and
//! `Simulation::use_gpu` (TLED, and the hybrid's FLSM step and interface pull) and
//! `CutSim::use_gpu` (all-TLED, with contacts).
#![warn(missing_docs)]

pub mod cut;
mod error;
pub mod mesh;
pub mod model;
pub mod scenario;

// The modules at the crate's root as before the split into `model` and `cut`.
pub use cut::{collide, cut_surface, cutting, obstacle, piece_contact, scripted, sliver, stress, sweep, table, vna};
#[cfg(feature = "gpu")]
pub use model::gpu;
pub use model::{body, dynamics, embed, flsm, lattice, material, operational, simulation, stability, tled};

pub use body::{
    Body, LARGE_ORGAN_SCALE, VoxelizeError, VoxelizeParams, Voxelized, organ_sdf, scaled_organ_sdf, voxelize,
};
pub use collide::{CELL_EDGES, CellIndex, CellTree, Cuts, EdgeCut, SpatialHash, cut_edges, segment_triangle};
pub use cutting::{CutOutcome, CutSim, CutSimParams, PieceState};
pub use embed::{EmbedError, Embedding};
pub use error::SimError;
pub use flsm::{Flsm, FlsmParams};
#[cfg(feature = "gpu")]
pub use gpu::GpuStats;
pub use lattice::{CORNERS, Cell, Lattice};
pub use material::Material;
pub use mesh::{MeshError, TriMesh, WindingTree};
pub use obstacle::Obstacle;
pub use operational::{FarField, HybridParams, HybridSteps, MAX_SUBSTEPS, match_flsm};
pub use scenario::{MAX_LATTICE_CELLS, Scenario};
pub use scripted::{BladePath, ScriptedCut};
pub use simulation::{MAX_STEPS, NodeRole, Simulation};
pub use sliver::{TEAR_CELLS, Torn};
pub use sweep::{SweptSurface, interpolate, reach_back};
pub use table::Table;
pub use tled::{Integration, Tled, TledParams};
pub use vna::{CellCopy, CellSplit, CutTopology};
