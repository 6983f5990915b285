//! Times carving on a dataset's mask files: `cargo run --release -p hullcut-hull --example
//! carve_probe -- DATASET LEAF_M [REPEATS] [MINX,MINY,MINZ,MAXX,MAXY,MAXZ]` (the working volume
//! from the rig without the last argument). Prints the best and mean milliseconds per frame set
//! and the counters, for profiling the carver.

use std::time::Instant;

use hullcut_dataset::Dataset;
use hullcut_hull::{Aabb, HullParams, WorkingVolume, carve, silhouettes};
use nalgebra::Point3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let ds = Dataset::open(args.get(1).ok_or("usage: carve_probe DATASET LEAF_M [REPEATS] [BOX]")?)?;
    let leaf: f64 = args.get(2).ok_or("leaf size")?.parse()?;
    let repeats: usize = args.get(3).map_or(Ok(5), |s| s.parse())?;
    let volume = match args.get(4) {
        Some(b) => {
            let v: Vec<f64> = b.split(',').map(str::parse).collect::<Result<_, _>>()?;
            Aabb { min: Point3::new(v[0], v[1], v[2]), max: Point3::new(v[3], v[4], v[5]) }
        }
        None => WorkingVolume::from_rig(ds.rig(), 3, ds.rig().world_frame.is_table())?.aabb,
    };
    let params = HullParams::new(volume, leaf);
    let mut times = Vec::new();
    let mut last = None;
    for frame in ds.frame_numbers() {
        let set = ds.read_frame_set(frame, true)?;
        let masks: Vec<Option<&image::GrayImage>> =
            set.views.iter().map(|v| v.as_ref().and_then(|v| v.mask.as_ref())).collect();
        let views = silhouettes(ds.rig(), &masks)?;
        for _ in 0..repeats {
            let t = Instant::now();
            let occ = carve(&views, &params)?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
            last = Some(occ.stats);
        }
    }
    let best = times.iter().copied().fold(f64::INFINITY, f64::min);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!("best {best:.2} ms, mean {mean:.2} ms per frame set; last {:?}", last);
    Ok(())
}
