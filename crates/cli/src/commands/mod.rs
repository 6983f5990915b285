//! One module per subcommand.

pub mod bench;
pub mod bench_hull;
pub mod bench_pipeline;
pub mod bench_pose;
pub mod bench_segment;
pub mod calibrate;
pub mod gpu_info;
pub mod import;
pub mod reconstruct;
pub mod rig;
pub mod run;
pub mod segment;
pub mod sim;
pub mod synth;
