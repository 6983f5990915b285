//! What the loop must fit in to keep up with a real hand: 60 frame sets a second, 50 ms from a
//! frame set's capture to its cut surface, and each stage's share of the frame, measured inside
//! the loop. [`check`] says which stage misses, and by how much.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::stages::StageTimes;

/// Frame sets a second the loop must sustain.
pub const FPS: f64 = 60.0;
/// Latency from capture to cut surface the loop must keep under, p95, milliseconds.
pub const LATENCY_P95_MS: f64 = 50.0;

/// Each stage's budget per frame set, milliseconds, and whether it holds for the mean or the p95:
/// segmentation 3 (six 640x480 views), carving 3 (a 128³ working volume), surfaces 1, pose 1,
/// cutting 3 at p95 (collision, topology and surfaces of a sweep), contact and deformation 6 at
/// the paper's organ size. Together 17 ms: one 60 Hz frame on the stages' path.
pub const STAGES: [(&str, f64, Statistic); 6] = [
    ("segment", 3.0, Statistic::Mean),
    ("carve", 3.0, Statistic::Mean),
    ("surface", 1.0, Statistic::Mean),
    ("pose", 1.0, Statistic::Mean),
    ("cut", 3.0, Statistic::P95),
    ("contact+deform", 6.0, Statistic::Mean),
];

/// Which figure of a stage's times a budget holds for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Statistic {
    /// The mean over the frame sets.
    Mean,
    /// The 95th percentile.
    P95,
}

/// One stage against its budget.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Line {
    /// The stage.
    pub stage: String,
    /// Its budget, milliseconds.
    pub budget_ms: f64,
    /// Which figure the budget holds for.
    pub statistic: Statistic,
    /// That figure, measured inside the loop, milliseconds.
    pub measured_ms: f64,
    /// How far over budget, milliseconds (negative: under).
    pub over_ms: f64,
}

impl Line {
    /// Whether the stage keeps to its budget.
    pub fn met(&self) -> bool {
        self.over_ms <= 0.0
    }
}

/// Each stage that ran against its budget (`segment` only when the masks were segmented).
pub fn check(times: &StageTimes) -> Vec<Line> {
    // Per frame set: a frame set whose sweep cut nothing spent nothing cutting.
    let frames = times.carve.len().max(1);
    let summed = |parts: &[&Vec<Duration>]| -> Vec<f64> {
        (0..frames).map(|k| parts.iter().map(|d| d.get(k).map_or(0.0, |d| d.as_secs_f64() * 1e3)).sum()).collect()
    };
    let ms = |d: &Vec<Duration>| d.iter().map(|d| d.as_secs_f64() * 1e3).collect::<Vec<f64>>();
    let mut lines = Vec::new();
    for (stage, budget_ms, statistic) in STAGES {
        let values = match stage {
            "segment" => ms(&times.segment),
            "carve" => ms(&times.carve),
            "surface" => ms(&times.surface),
            "pose" => ms(&times.pose),
            "cut" => summed(&[&times.collide, &times.cut_topology, &times.cut_surface]),
            _ => summed(&[&times.contact, &times.deform]),
        };
        if values.is_empty() || (stage == "segment" && times.segment.is_empty()) {
            continue;
        }
        let measured_ms = match statistic {
            Statistic::Mean => values.iter().sum::<f64>() / values.len() as f64,
            Statistic::P95 => p95(values),
        };
        lines.push(Line {
            stage: stage.to_owned(),
            budget_ms,
            statistic,
            measured_ms,
            over_ms: measured_ms - budget_ms,
        });
    }
    lines
}

/// The 95th percentile (nearest rank) of `values`.
fn p95(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let rank = ((0.95 * values.len() as f64).ceil() as usize).clamp(1, values.len().max(1));
    values.get(rank - 1).copied().unwrap_or(0.0)
}

/// One line for people: the stages over budget and by how much, or that all keep to it.
pub fn summary(lines: &[Line]) -> String {
    let over: Vec<String> = lines
        .iter()
        .filter(|l| !l.met())
        .map(|l| {
            let what = if l.statistic == Statistic::P95 { " p95" } else { "" };
            format!("{}{what} {:.1} ms of {:.0} (+{:.1})", l.stage, l.measured_ms, l.budget_ms, l.over_ms)
        })
        .collect();
    if over.is_empty() {
        format!("every stage within its budget for {FPS:.0} fps")
    } else {
        format!("over the {FPS:.0} fps budget: {}", over.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_over_budget_is_named_with_its_excess_and_cutting_counts_per_frame_set() {
        let ms = |v: f64| Duration::from_secs_f64(v * 1e-3);
        let mut times = StageTimes::default();
        for _ in 0..20 {
            times.carve.push(ms(5.0));
            times.surface.push(ms(0.5));
            times.pose.push(ms(0.8));
            times.contact.push(ms(1.0));
            times.deform.push(ms(4.0));
        }
        // One sweep in twenty frame sets costs 10 ms: its p95 over the frame sets is 0.
        times.collide.push(ms(10.0));
        let lines = check(&times);
        let carve = lines.iter().find(|l| l.stage == "carve").expect("carve");
        assert!((carve.over_ms - 2.0).abs() < 1e-9 && !carve.met());
        assert!(lines.iter().filter(|l| l.stage != "carve").all(Line::met), "{lines:?}");
        assert!(lines.iter().all(|l| l.stage != "segment"), "no segmentation ran");
        assert_eq!(summary(&lines), "over the 60 fps budget: carve 5.0 ms of 3 (+2.0)");
    }
}
