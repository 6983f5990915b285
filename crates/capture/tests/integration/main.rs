//! Integration tests of hullcut-capture: synchronization policy (pure), the OpenCV decode path
//! (videos and image sequences written here, read back as cameras), error handling, segmentation
//! on procedural images with known masks, and MOG2 on real footage (`vtest.avi`).

mod common;
mod decode;
mod errors;
mod segment;
mod sync;
mod vtest;
