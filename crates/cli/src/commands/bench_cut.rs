//! `hullcut bench cut`: cutting where it fails (the stress cases of `hullcut_sim::stress`).

use std::path::Path;

use anyhow::bail;
use hullcut_sim::stress::{CaseResult, cases, run as run_case};
use rayon::prelude::*;

use super::bench::Table;
use crate::chart::{Scale, Series, scatter_chart};

/// Runs every stress case (all cores, one case each), writes `cut_stress.csv`,
/// `cut_stress_cost.png` and `cut_stress_pieces.png` into `out`, and fails when a case was
/// unstable or did not come apart as expected (the table is written first). `quick` runs one
/// case of each family.
pub fn run(out: &Path, quick: bool) -> anyhow::Result<()> {
    let mut all = cases();
    if quick {
        let mut seen = Vec::new();
        all.retain(|c| {
            let first = !seen.contains(&c.family);
            seen.push(c.family);
            first
        });
    }
    let bar = crate::progress::bar(all.len() as u64, "cutting stress cases");
    let results: Vec<CaseResult> = all
        .par_iter()
        .map(|c| {
            let r = run_case(c);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let mut table = Table::new(&[
        "case",
        "family",
        "frames",
        "pieces",
        "expected_pieces",
        "separated",
        "stable",
        "failure",
        "kinetic_max_ratio",
        "inverted_max",
        "inverted_end",
        "edges_cut",
        "copies",
        "virtual_nodes",
        "torn_merged",
        "torn_bridged",
        "torn_holes",
        "frame_ms_mean",
        "frame_ms_max",
        "cut_ms_mean",
    ]);
    for r in &results {
        table.row([
            r.name.clone(),
            r.family.clone(),
            r.frames.to_string(),
            r.pieces.to_string(),
            r.expected_pieces.to_string(),
            (r.pieces == r.expected_pieces).to_string(),
            r.stable().to_string(),
            r.failure.clone().unwrap_or_default(),
            format!("{:.3e}", r.kinetic_max_ratio),
            r.inverted_max.to_string(),
            r.inverted_end.to_string(),
            r.edges_cut.to_string(),
            r.copies.to_string(),
            r.virtual_nodes.to_string(),
            r.torn_merged.to_string(),
            r.torn_bridged.to_string(),
            r.torn_holes.to_string(),
            format!("{:.3}", r.frame_ms_mean),
            format!("{:.3}", r.frame_ms_max),
            format!("{:.3}", r.cut_ms_mean),
        ]);
        println!(
            "{:<44} {:>2} of {:>2} pieces, {}, KE {:.1e} m g H, {:.2} ms/frame ({:.2} max), cut {:.2} ms",
            r.name,
            r.pieces,
            r.expected_pieces,
            r.failure.as_deref().map_or_else(
                || if r.stable() { "stable".to_owned() } else { "UNSTABLE".to_owned() },
                |f| format!("FAILED: {f}")
            ),
            r.kinetic_max_ratio,
            r.frame_ms_mean,
            r.frame_ms_max,
            r.cut_ms_mean
        );
    }
    table.write(&out.join("cut_stress.csv"))?;
    let mut families: Vec<&str> = results.iter().map(|r| r.family.as_str()).collect();
    families.dedup();
    let series = |point: &dyn Fn(&CaseResult) -> (f64, f64)| -> Vec<Series> {
        families
            .iter()
            .map(|f| Series {
                label: (*f).to_owned(),
                points: results.iter().filter(|r| r.family == *f).map(point).collect(),
            })
            .collect()
    };
    scatter_chart(
        &out.join("cut_stress_cost.png"),
        "Cutting stress cases: cost of a frame against peak kinetic energy",
        "peak kinetic energy / (m g H) of the block",
        "ms per frame (cut + advance 33 ms), mean",
        (Scale::Log, Scale::Linear),
        &series(&|r| (r.kinetic_max_ratio.max(1e-6), r.frame_ms_mean)),
    )?;
    scatter_chart(
        &out.join("cut_stress_pieces.png"),
        "Cutting stress cases: pieces found against pieces expected",
        "pieces expected",
        "pieces found",
        (Scale::Linear, Scale::Linear),
        &series(&|r| (r.expected_pieces as f64, r.pieces as f64)),
    )?;
    let failed: Vec<&str> = results.iter().filter(|r| !r.passed()).map(|r| r.name.as_str()).collect();
    if !failed.is_empty() {
        bail!("{} stress case(s) unstable or not in the pieces expected: {}", failed.len(), failed.join(", "));
    }
    println!("{} stress cases: all stable, all in the pieces expected", results.len());
    Ok(())
}
