//! The scalpels of the synthetic scenes, with the geometry `tool.json` describes: the standard one
//! (a flat handle and a No. 10-style blade with a curved belly) and a pointed one (a round handle
//! and a No. 11-style blade with a straight edge), so that nothing is tuned to one tool.
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

/// Which scalpel a scene uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ToolKind {
    /// A flat 130 mm handle and a No. 10-style blade (curved belly, 38 mm).
    #[default]
    Standard,
    /// A round 154 mm handle (8.4 mm across) and a No. 11-style blade (straight edge rising to a
    /// point on the spine, 31 mm, 7 mm wide, 0.35 mm thick).
    Pointed,
}

impl ToolKind {
    /// Every tool with its command-line name.
    pub const ALL: [(ToolKind, &'static str); 2] = [(ToolKind::Standard, "standard"), (ToolKind::Pointed, "pointed")];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(k, _)| *k == self).map_or("standard", |(_, n)| n)
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<ToolKind> {
        Self::ALL.iter().find(|(_, n)| *n == name).map(|(k, _)| *k)
    }
}

/// Where the hand's fingers rest on a handle: its half extents across the tool frame's y and z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleFit {
    /// Half the handle's extent along y (the index finger lies on its +y side), metres.
    pub half_width: f64,
    /// Half its extent along z (thumb and middle finger on its ±z sides), metres.
    pub half_thickness: f64,
}

/// The scalpel's parts and its described geometry.
#[derive(Debug, Clone)]
pub struct Scalpel {
    /// Which scalpel.
    pub kind: ToolKind,
    /// The handle, a closed mesh in the tool frame.
    pub handle: TriMesh,
    /// The blade, a closed thin prism in the tool frame.
    pub blade: TriMesh,
    /// Where the hand holds the handle.
    pub fit: HandleFit,
    /// What `tool.json` states (mesh = handle and blade together).
    pub geometry: ToolGeometry,
}

impl Default for Scalpel {
    fn default() -> Self {
        Self::new()
    }
}

impl Scalpel {
    /// The scalpel of a kind.
    pub fn of(kind: ToolKind) -> Self {
        match kind {
            ToolKind::Standard => Self::new(),
            ToolKind::Pointed => Self::pointed(),
        }
    }

    /// The pointed scalpel ([`ToolKind::Pointed`]).
    pub fn pointed() -> Self {
        const HALF_W: f64 = 0.0035;
        const THICKNESS: f64 = 0.00035;
        const RADIUS: f64 = 0.0042;
        let heel = Point2::new(0.003, -HALF_W);
        let tip = Point2::new(0.031, HALF_W - 0.0005);
        // From the heel to exactly the tip (the interpolation's last point rounds off it).
        let edge: Vec<Point2<f64>> =
            (0..9).map(|k| if k == 8 { tip } else { heel + (tip - heel) * (k as f64 / 8.0) }).collect();
        let outline = vec![Point2::new(0.0, -HALF_W), heel, tip, Point2::new(0.030, HALF_W), Point2::new(0.0, HALF_W)];
        let blade = TriMesh::convex_prism(&outline, -THICKNESS / 2.0, THICKNESS / 2.0);
        // The round handle's cap ends where the blade begins.
        let handle = TriMesh::capsule(Point3::new(-0.150, 0.0, 0.0), Point3::new(-RADIUS, 0.0, 0.0), RADIUS, 24);
        Self::assemble(
            ToolKind::Pointed,
            handle,
            blade,
            HandleFit { half_width: RADIUS, half_thickness: RADIUS },
            &outline,
            &edge,
            tip,
            THICKNESS,
        )
    }

    /// Both parts and their `tool.json` description: mesh = handle and blade, cutting edge from
    /// the tip to the heel.
    #[allow(clippy::too_many_arguments)] // the parts of one tool, each named
    fn assemble(
        kind: ToolKind,
        handle: TriMesh,
        blade: TriMesh,
        fit: HandleFit,
        outline: &[Point2<f64>],
        edge: &[Point2<f64>],
        tip: Point2<f64>,
        thickness: f64,
    ) -> Self {
        let mut mesh = handle.clone();
        mesh.append(&blade);
        let lift = |p: &Point2<f64>| Point3::new(p.x, p.y, 0.0);
        let geometry = ToolGeometry {
            mesh,
            tip: lift(&tip),
            cutting_edge: edge.iter().rev().map(lift).collect(),
            blade_normal: Vector3::z(),
            blade_thickness: thickness,
            blade_outline: Some(outline.iter().map(lift).collect()),
        };
        Scalpel { kind, handle, blade, fit, geometry }
    }

    /// The standard scalpel of the synthetic scenes ([`ToolKind::Standard`]).
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
        let fit = HandleFit { half_width: HANDLE_WIDTH / 2.0, half_thickness: HANDLE_THICKNESS / 2.0 };
        Self::assemble(ToolKind::Standard, handle, blade, fit, &outline, &edge, tip, BLADE_THICKNESS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blade_and_handle_have_the_stated_size() {
        let s = Scalpel::new();
        assert!(s.blade.is_closed_oriented() && s.handle.is_closed_oriented());
        let area = s.blade.volume() / BLADE_THICKNESS;
        // A No. 10 blade's face is about 2.5 to 3.5 cm².
        assert!((2.5e-4..3.5e-4).contains(&area), "blade area {area} m²");
        assert!((s.handle.volume() - HANDLE_LENGTH * HANDLE_WIDTH * HANDLE_THICKNESS).abs() < 1e-15);
        assert_eq!(s.geometry.cutting_edge.first(), Some(&s.geometry.tip));
        assert!(s.geometry.cutting_edge.len() >= 2);
    }

    #[test]
    fn the_pointed_scalpel_is_another_tool() {
        let p = Scalpel::pointed();
        assert!(p.blade.is_closed_oriented() && p.handle.is_closed_oriented());
        let area = p.blade.volume() / 0.00035;
        // A No. 11 blade's face is a narrow triangle of 1 to 2 cm², smaller than the No. 10's.
        assert!((1.0e-4..2.0e-4).contains(&area), "blade area {area} m²");
        let length = |s: &Scalpel| {
            let xs = s.geometry.mesh.vertices.iter().map(|v| v.x);
            xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
        };
        assert!(length(&p) > length(&Scalpel::new()) + 0.01, "longer overall");
        assert_eq!(p.geometry.cutting_edge.first(), Some(&p.geometry.tip));
        assert_eq!(ToolKind::from_name(ToolKind::Pointed.name()), Some(ToolKind::Pointed));
    }
}
