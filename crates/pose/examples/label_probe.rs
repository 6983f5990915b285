//! Diagnostic: the geometric labeller on a dataset's truth foreground (labels dropped).
//!
//! `label_probe DATASET [FRAMES] [SEGMENT_OUT]`: masks from `hullcut segment --out SEGMENT_OUT`
//! when given; `PROBE_VOTES=K` carves the hull k-of-N (`HullParams::carve_votes`, 1 by default).
use hullcut_dataset::{Dataset, label};
use hullcut_hull::{Aabb, HullParams, carve, silhouettes};
use hullcut_pose::labels::thin_parts;
use hullcut_pose::{LabelParams, ToolLabeller, TrackerParams, ViewInput};
use nalgebra::{Point3, Vector3};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ds = Dataset::open(&args[1]).expect("dataset");
    let frames: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let tool = ds.tool().expect("tool").expect("tool.json");
    let truth = ds.truth_poses().expect("truth").expect("poses");
    let mut labeller = ToolLabeller::new(
        &tool,
        TrackerParams { agreement: (0.82, 0.92), outline_offset: false, ..TrackerParams::default() },
        LabelParams::default(),
    )
    .expect("labeller");
    for f in 0..frames {
        let set = ds.read_frame_set(f, true).expect("frame");
        // Masks from OUT/masks/camK/NNNNNN.png (a `segment --out`) when a third argument names OUT.
        let masks: Vec<Option<image::GrayImage>> = set
            .views
            .iter()
            .enumerate()
            .map(|(c, v)| match args.get(3) {
                Some(dir) => image::open(format!("{dir}/masks/cam{c}/{f:06}.png")).ok().map(|i| i.to_luma8()),
                None => v.as_ref().and_then(|v| v.mask.clone()),
            })
            .map(|m| {
                m.map(|mut m| {
                    m.iter_mut().filter(|p| **p != 0).for_each(|p| *p = label::UNKNOWN);
                    m
                })
            })
            .collect();
        let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Option::as_ref).collect();
        let views = silhouettes(ds.rig(), &refs).expect("sil");
        let t = truth.iter().find(|t| t.frame == f).expect("truth frame");
        let centre = Point3::from(t.tool_to_world.fixed_view::<3, 1>(0, 3).into_owned());
        let bx = Aabb { min: centre - Vector3::new(0.25, 0.25, 0.25), max: centre + Vector3::new(0.25, 0.25, 0.25) };
        let votes = std::env::var("PROBE_VOTES").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
        let occ = carve(&views, &HullParams { carve_votes: votes, ..HullParams::new(bx, 0.003125) }).expect("carve");
        let (_, comps) = thin_parts(&occ, 0.007);
        let axis = t.tool_to_world.fixed_view::<3, 1>(0, 0).into_owned();
        for (k, c) in comps.iter().take(5).enumerate() {
            let mean = c.iter().map(|&n| occ.cells[n].centre().coords).sum::<Vector3<f64>>() / c.len() as f64;
            let d = mean - centre.coords;
            let off_axis = (d - axis * axis.dot(&d)).norm();
            println!(
                "frame {f} comp {k}: {} leaves, centroid {:.3?}, off tool axis {:.1} mm, along {:.1} mm",
                c.len(),
                mean.as_slice(),
                off_axis * 1e3,
                axis.dot(&d) * 1e3
            );
        }
        let inputs: Vec<Option<ViewInput>> = ds
            .rig()
            .cameras
            .iter()
            .zip(&masks)
            .map(|(camera, m)| m.as_ref().map(|mask| ViewInput { camera, mask, image: None }))
            .collect();
        let out = labeller.label(f, set.timestamp_ns, &occ, &[], &inputs, None);
        let e = &out.estimate;
        let fit = e.fitted.as_ref().map(|p| p.tool_to_world);
        let err = fit.map(|p| {
            let tr = hullcut_pose::isometry_from_matrix(&t.tool_to_world).expect("iso");
            let d = p.rotation.inverse() * tr.rotation;
            let axis = d.axis().map(|a| a.into_inner()).unwrap_or_else(Vector3::x);
            (d.angle().to_degrees(), (p.translation.vector - tr.translation.vector).norm() * 1e3, axis)
        });
        println!(
            "frame {f}: valid {} conf {:.2} reason {:?} err (deg, mm) {:?} stats {:?}",
            e.valid, e.confidence, e.reason, err, out.stats
        );
    }
}
