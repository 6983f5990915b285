//! Cutting and contact, built on the deformation model ([`crate::model`]): the blade's swept
//! surface, the lattice edges it crosses (parry's BVH of the cells), the virtual node algorithm's
//! topology with torn slivers, the pieces' closed surfaces, the body that is cut while it deforms
//! ([`cutting::CutSim`], its GPU steps beside it), the hand's obstacle, the table, pieces kept
//! out of each other, a blade scripted by a scenario's `[cut]`, and the stress test of cutting where it fails.

pub mod collide;
pub mod cut_surface;
pub mod cutting;
pub mod obstacle;
pub mod piece_contact;
pub mod scripted;
pub mod sliver;
pub mod stress;
pub mod sweep;
pub mod table;
pub mod vna;
