//! Drives the pipeline from a few lines of Rust: replays a recorded dataset (masks from its
//! files), cuts the built-in organ with the blade it sees, and prints each frame set's result.
//!
//! ```sh
//! cargo run -p hullcut-pipeline --example replay -- datasets/cut-small
//! ```

use std::sync::Arc;

use hullcut_dataset::Dataset;
use hullcut_hull::{HullParams, WorkingVolume};
use hullcut_pipeline::{Carver, FrameSource, Setup, spawn, tissue};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = std::env::args().nth(1).unwrap_or_else(|| "datasets/cut-small".to_owned());
    let ds = Arc::new(Dataset::open(&root)?);
    // The space at least three cameras see, above the table; 4 mm leaves; the organ at 6 mm.
    let volume = WorkingVolume::from_rig(ds.rig(), 3, ds.rig().world_frame.is_table())?;
    let hull = HullParams { min_views: 3, ..HullParams::new(volume.aabb, 0.004) };
    let organ = tissue::build("organ", 0.006, None, None)?;
    let frames = ds.frame_numbers();
    let pipeline = spawn(Setup::new(FrameSource::Dataset(Arc::clone(&ds)), frames, true, hull, Carver::Cpu, organ))?;
    for work in pipeline.output.iter() {
        let trusted = work.estimate.as_ref().is_some_and(|e| e.valid);
        let (pieces, cut) = work.tissue.as_ref().map_or((0, 0), |t| (t.pieces, t.cut.map_or(0, |c| c.new_edges)));
        println!(
            "frame {:4}: blade {}, {cut} edges cut, {pieces} piece(s), {:.1} ms from capture to cut surface",
            work.frame,
            if trusted { "trusted" } else { "refused" },
            work.latency().as_secs_f64() * 1e3
        );
    }
    let outcome = pipeline.join();
    if let Some(e) = outcome.error {
        return Err(e.into());
    }
    println!("{} frame sets read, {} dropped", outcome.read.read, outcome.read.dropped);
    Ok(())
}
