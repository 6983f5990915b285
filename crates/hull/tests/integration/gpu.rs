//! The GPU carver against the CPU's on rendered silhouettes: the same kept leaves with the same
//! labels, except where a footprint bound lies within f32 rounding of a pixel edge.

use std::collections::HashMap;
use std::sync::Arc;

use hullcut_dataset::label;
use hullcut_hull::gpu::GpuCarver;
use hullcut_hull::{HullParams, Occupancy, carve};
use hullcut_rig::default_rig;
use hullcut_synth::{Part, TriMesh};
use nalgebra::{Isometry3, Point3, Vector3};

use super::{render, views};

/// Every leaf a kept cell covers, with its labels (bit 0 kept, 1 hand, 2 scalpel) and the view
/// that refuted it (bits 3 and up: the view + 1, or 0).
fn leaves(occ: &Occupancy) -> HashMap<[i64; 3], u16> {
    let mut out = HashMap::new();
    for c in &occ.cells {
        let at = |a: usize| ((c.min[a] - occ.origin[a]) / occ.leaf_size).round() as i64;
        let n = (c.size / occ.leaf_size).round() as i64;
        let refuter = c.refuted_by.map_or(0, |v| v + 1);
        let bits = 1 | (u16::from(c.hand) << 1) | (u16::from(c.scalpel) << 2) | (refuter << 3);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    out.insert([at(0) + i, at(1) + j, at(2) + k], bits);
                }
            }
        }
    }
    out
}

#[test]
fn the_gpu_carves_what_the_cpu_carves_up_to_rounding() {
    let Some(gpu) = hullcut_gpu::for_tests() else { return };
    let hand = TriMesh::ellipsoid(&Isometry3::translation(-0.03, 0.0, 0.12), Vector3::repeat(0.04), 64);
    let bar = TriMesh::cuboid(Point3::new(0.0, -0.005, 0.117), Point3::new(0.09, 0.005, 0.123));
    let parts = [
        Part { label: label::HAND, albedo: [0.3, 0.4, 0.8], mesh: hand },
        Part { label: label::SCALPEL, albedo: [0.6; 3], mesh: bar },
    ];
    let mut carver = GpuCarver::new(Arc::new(gpu)).expect("carver");
    // Both rigs with their own working volume: the default rule, two votes, and a missing view.
    for (name, rig) in [("default", default_rig()), ("lab8", hullcut_rig::lab8_rig())] {
        let masks = render(&rig, &parts);
        let mut all = views(&rig, &masks);
        // The blade refined a level finer (on the CPU after the GPU's carving) before the missing
        // view, which stays missing.
        for (case, votes, drop, blade_levels) in [
            ("default", 1, None, 0),
            ("two votes", 2, None, 0),
            ("blade refined", 1, None, 1),
            ("camera 2 missing", 1, Some(2), 0),
        ] {
            let case = format!("{name}, {case}");
            if let Some(k) = drop {
                all[k] = None;
            }
            let params = HullParams { carve_votes: votes, blade_levels, ..super::params(&rig, super::LEAF) };
            let cpu = carve(&all, &params).expect("cpu");
            let on_gpu = carver.carve(&all, &params).expect("gpu");
            let (a, b) = (leaves(&cpu), leaves(&on_gpu));
            let differ = a.iter().filter(|(k, v)| b.get(*k) != Some(v)).count()
                + b.keys().filter(|k| !a.contains_key(*k)).count();
            let near = carver.last.near_threshold;
            eprintln!(
                "{case}: {} leaves on the CPU, {} on the GPU, {differ} differ; {near} of {} cells tested within rounding",
                a.len(),
                b.len(),
                on_gpu.stats.cells_visited
            );
            assert!(a.len() > 1000, "{case}: a hull to compare");
            assert!((differ as f64) <= 1e-3 * a.len() as f64, "{case}: {differ} of {} leaves differ", a.len());
            assert!(differ == 0 || near > 0, "{case}: differences without a cell near a pixel edge");
            assert_eq!(on_gpu.stats.views_used, cpu.stats.views_used);
            assert_eq!(on_gpu.stats.views_missing, cpu.stats.views_missing);
            assert_eq!((on_gpu.resolution, on_gpu.leaf_size), (cpu.resolution, cpu.leaf_size));
            // The same cells visited, so the same counters (but footprint tests: the GPU tests every
            // view of every cell, the CPU stops at the first refutation). A cell within rounding of
            // a pixel edge may be uniform on one side and split into the same leaves on the other:
            // then the visits differ by a few cells.
            let s = (&cpu.stats, &on_gpu.stats);
            let visits = s.0.cells_visited.abs_diff(s.1.cells_visited);
            assert!(visits as f64 <= 1e-3 * s.0.cells_visited as f64, "{case}: visits {visits}");
            if differ == 0 && visits == 0 {
                assert_eq!(s.0.lone_refutations, s.1.lone_refutations, "{case}");
                assert_eq!(s.0.kept_against_refutation, s.1.kept_against_refutation, "{case}");
                assert_eq!(s.0.unlabelled_cells, s.1.unlabelled_cells, "{case}");
                assert_eq!(s.0.unseen_cells, s.1.unseen_cells, "{case}");
            }
        }
    }
}
