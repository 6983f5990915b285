//! The cutting stress test: every case stays stable and comes apart as expected.

use hullcut_sim::stress::{cases, run};
use rayon::prelude::*;

#[test]
fn every_stress_case_stays_stable_and_separates_into_the_pieces_expected() {
    let cases = cases();
    assert!(cases.len() >= 30, "{} cases", cases.len());
    let results: Vec<_> = cases.par_iter().map(run).collect();
    for r in &results {
        eprintln!(
            "{:<44} {:>2} of {:>2} pieces, KE {:.2e} m g H, inverted {} (max {}), {:.2} ms/frame, {}",
            r.name,
            r.pieces,
            r.expected_pieces,
            r.kinetic_max_ratio,
            r.inverted_end,
            r.inverted_max,
            r.frame_ms_mean,
            r.failure.as_deref().unwrap_or("ok")
        );
    }
    let failed: Vec<_> = results.iter().filter(|r| !r.passed()).map(|r| r.name.as_str()).collect();
    assert!(failed.is_empty(), "failed: {failed:?}");
    // The fast strokes cut in one frame what the slow ones cut over many.
    let frames = |name: &str| results.iter().find(|r| r.name == name).map(|r| r.frames).expect(name);
    assert!(frames("speed 0.05 m/s") > frames("speed 2 m/s") + 10);
}
