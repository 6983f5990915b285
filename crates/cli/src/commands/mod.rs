//! One module per subcommand.

pub mod calibrate;
pub mod rig;
pub mod sim;
