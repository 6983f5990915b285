//! Integration tests of hullcut-sim.

mod body;
mod flsm;
mod mechanics;
mod scenario;
mod stress;
mod tled;
