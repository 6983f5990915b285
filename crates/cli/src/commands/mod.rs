//! One module per subcommand, and the value parsers their flags share.

pub mod bench;
pub mod bench_cut;
pub mod bench_hull;
pub mod bench_loop;
pub mod bench_pipeline;
pub mod bench_pose;
pub mod bench_segment;
pub mod bench_tissue;
pub mod calibrate;
pub mod gpu_info;
pub mod import;
pub mod reconstruct;
pub mod rig;
pub mod run;
pub mod segment;
pub mod sim;
pub mod sim_cut;
pub mod synth;

/// Value parser of a flag that takes a positive, finite number (a length, a rate, a scale):
/// anything else is bad usage (exit 2), and clap's message names the flag and the value.
pub(crate) fn positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err("expected a positive, finite number".to_owned()),
        Err(e) => Err(format!("expected a positive number ({e})")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_out_of_range_are_refused() {
        assert_eq!(positive("0.25"), Ok(0.25));
        for bad in ["0", "-1", "NaN", "inf", "", "x"] {
            assert!(positive(bad).is_err(), "{bad}");
        }
    }
}
