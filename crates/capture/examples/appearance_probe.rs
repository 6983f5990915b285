//! Diagnostic: the appearance model learned from a dataset's truth masks (frames 0-2), its
//! confident colour table scored on frames 5-7. `appearance_probe DATASET [LOG_RATIO_MARGIN]`.
use hullcut_capture::segment::AppearanceModel;
use hullcut_dataset::{Dataset, label};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ds = Dataset::open(&args[1]).expect("dataset");
    let margin: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3.0);
    let mut model = AppearanceModel::default();
    for f in 0..3 {
        let set = ds.read_frame_set(f, true).expect("frame");
        model.age();
        for v in set.views.iter().flatten() {
            model.learn(&v.image, v.mask.as_ref().expect("mask"), true);
        }
    }
    let classes = model.classes().expect("classes");
    let lut = hullcut_capture::segment::ColourLut::confident(&classes, 2.0 * margin);
    {
        let mut confusion = [[0u64; 3]; 2];
        for f in 5..8 {
            let set = ds.read_frame_set(f, true).expect("frame");
            for v in set.views.iter().flatten() {
                for (p, &t) in v.image.pixels().zip(v.mask.as_ref().expect("mask").as_raw()) {
                    let row = match t {
                        label::HAND => 0,
                        label::SCALPEL => 1,
                        _ => continue,
                    };
                    let col = match lut.get(p.0) {
                        label::HAND => 0,
                        label::SCALPEL => 1,
                        _ => 2,
                    };
                    confusion[row][col] += 1;
                }
            }
        }
        println!("truth hand -> [hand, scalpel, unknown] {:?}; truth scalpel -> {:?}", confusion[0], confusion[1]);
    }
}
