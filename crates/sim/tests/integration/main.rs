//! Integration tests of hullcut-sim.

mod body;
mod cut_faces;
mod flsm;
mod layering;
mod mechanics;
mod scenario;
mod stress;
mod tled;
