//! The scalpel: a flat handle and a No. 10-style blade, with the geometry `tool.json` describes.
//!
//! Tool frame: origin where the blade meets the handle, on the handle's axis; x along the tool
//! toward the tip, y across the blade toward its spine (the blunt back), z the blade normal. The
//! handle runs along −x; the blade lies in the xy plane, its mid-plane at z = 0.

use hullcut_dataset::ToolGeometry;
use nalgebra::{Point2, Point3, Vector3};

use crate::TriMesh;

/// Handle length, metres.
pub const HANDLE_LENGTH: f64 = 0.130;
/// Handle width (in the blade plane), metres.
pub const HANDLE_WIDTH: f64 = 0.010;
/// Handle thickness (along the blade normal), metres.
pub const HANDLE_THICKNESS: f64 = 0.006;
/// Blade length from the handle to the tip, metres.
pub const BLADE_LENGTH: f64 = 0.038;
/// Blade width, metres.
pub const BLADE_WIDTH: f64 = 0.009;
/// Blade thickness, metres.
pub const BLADE_THICKNESS: f64 = 0.0004;

/// Points along the curved cutting edge (tip and heel included).
const EDGE_POINTS: usize = 17;

/// The scalpel's parts and its described geometry.
#[derive(Debug, Clone)]
pub struct Scalpel {
    /// The handle, a closed box in the tool frame.
    pub handle: TriMesh,
    /// The blade, a closed thin prism in the tool frame.
    pub blade: TriMesh,
    /// What `tool.json` states (mesh = handle and blade together).
    pub geometry: ToolGeometry,
}

impl Default for Scalpel {
    fn default() -> Self {
        Self::new()
    }
}

impl Scalpel {
    /// The standard scalpel of the synthetic scenes.
    pub fn new() -> Self {
        let half_w = BLADE_WIDTH / 2.0;
        let heel_x = 0.004;
        // The belly rises as a cubic from the heel (flat, at the bottom of the blade) to the tip,
        // which sits 1.5 mm below the spine; the spine is straight, then slopes down to the tip.
        let tip = Point2::new(BLADE_LENGTH, half_w - 0.0015);
        let edge: Vec<Point2<f64>> = (0..EDGE_POINTS)
            .map(|k| {
                let s = k as f64 / (EDGE_POINTS - 1) as f64;
                if k == EDGE_POINTS - 1 {
                    return tip;
                }
                Point2::new(heel_x + (tip.x - heel_x) * s, -half_w + (tip.y + half_w) * s.powi(3))
            })
            .collect();
        // Counter-clockwise outline seen from +z: heel corner, along the edge to the tip, the spine.
        let mut outline = vec![Point2::new(0.0, -half_w)];
        outline.extend_from_slice(&edge);
        outline.push(Point2::new(0.030, half_w));
        outline.push(Point2::new(0.0, half_w));
        let blade = TriMesh::convex_prism(&outline, -BLADE_THICKNESS / 2.0, BLADE_THICKNESS / 2.0);
        let handle = TriMesh::cuboid(
            Point3::new(-HANDLE_LENGTH, -HANDLE_WIDTH / 2.0, -HANDLE_THICKNESS / 2.0),
            Point3::new(0.0, HANDLE_WIDTH / 2.0, HANDLE_THICKNESS / 2.0),
        );
        let mut mesh = handle.clone();
        mesh.append(&blade);
        let lift = |p: &Point2<f64>| Point3::new(p.x, p.y, 0.0);
        let geometry = ToolGeometry {
            mesh: mesh.to_dataset(),
            tip: lift(&tip),
            cutting_edge: edge.iter().rev().map(lift).collect(),
            blade_normal: Vector3::z(),
            blade_thickness: BLADE_THICKNESS,
            blade_outline: Some(outline.iter().map(lift).collect()),
        };
        Scalpel { handle, blade, geometry }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blade_and_handle_have_the_stated_size() {
        let s = Scalpel::new();
        assert!(s.blade.is_closed() && s.handle.is_closed());
        let area = s.blade.volume() / BLADE_THICKNESS;
        // A No. 10 blade's face is about 2.5 to 3.5 cm².
        assert!((2.5e-4..3.5e-4).contains(&area), "blade area {area} m²");
        assert!((s.handle.volume() - HANDLE_LENGTH * HANDLE_WIDTH * HANDLE_THICKNESS).abs() < 1e-15);
        assert_eq!(s.geometry.cutting_edge.first(), Some(&s.geometry.tip));
        assert!(s.geometry.cutting_edge.len() >= 2);
    }
}
