//! Errors of an estimate against the true pose, as the report gives them.

use nalgebra::{Isometry3, Point3};

use crate::{BladePose, Template};

/// Errors of one frame's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// Angle between the estimated and the true blade normal (unsigned), degrees.
    pub normal_deg: f64,
    /// Mean distance from the true cutting edge's points to the estimated edge polyline, mm.
    pub edge_mm: f64,
    /// Distance between the estimated and the true tip, mm.
    pub tip_mm: f64,
}

impl PoseError {
    /// Whether the error exceeds `deg` degrees or `mm` millimetres (tip or edge).
    pub fn exceeds(&self, deg: f64, mm: f64) -> bool {
        self.normal_deg > deg || self.tip_mm > mm || self.edge_mm > mm
    }
}

/// Distance from a point to a polyline.
fn to_polyline(p: &Point3<f64>, line: &[Point3<f64>]) -> f64 {
    match line {
        [] => f64::INFINITY,
        [a] => (p - a).norm(),
        _ => line
            .windows(2)
            .map(|w| {
                let (a, b) = (w[0], w[1]);
                let ab = b - a;
                let t =
                    if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
                (p - (a + ab * t)).norm()
            })
            .fold(f64::INFINITY, f64::min),
    }
}

/// Errors of `estimate` against the template placed at the true `truth` pose.
pub fn pose_error(estimate: &BladePose, template: &Template, truth: &Isometry3<f64>) -> PoseError {
    let t = BladePose::new(template, *truth);
    let cos = estimate.plane_normal.normalize().dot(&t.plane_normal.normalize()).abs().min(1.0);
    let edge = t.edge.iter().map(|p| to_polyline(p, &estimate.edge)).sum::<f64>() / t.edge.len().max(1) as f64;
    PoseError { normal_deg: cos.acos().to_degrees(), edge_mm: edge * 1e3, tip_mm: (estimate.tip - t.tip).norm() * 1e3 }
}
