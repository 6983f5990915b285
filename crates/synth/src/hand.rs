//! A gloved hand holding the scalpel: a palm, a forearm stub and finger segments as capsules and
//! ellipsoids, placed in the tool frame, with a grip that changes over time.
//!
//! `grip` runs from 0 (fingers back on the handle) to 1 (index finger stretched onto the blade's
//! spine, hiding the blade's heel from cameras that look at its upper side).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::TriMesh;
use crate::scalpel::HandleFit;

/// Segments around each capsule and ellipsoid.
const SEGMENTS: usize = 20;

/// Finger radius, metres (a gloved adult finger).
const FINGER_RADIUS: f64 = 0.0085;

/// Builds the hand's closed meshes in the tool frame for a grip in [0, 1], holding the standard
/// scalpel's handle.
pub fn hand_mesh(grip: f64) -> TriMesh {
    hand_mesh_on(grip, &crate::Scalpel::new().fit)
}

/// Builds the hand's closed meshes in the tool frame for a grip in [0, 1], its fingers resting on a
/// handle of the given size.
pub fn hand_mesh_on(grip: f64, handle: &HandleFit) -> TriMesh {
    let g = grip.clamp(0.0, 1.0);
    let handle_top = handle.half_width;
    let p = Point3::new;
    let mut mesh = TriMesh::default();
    // Palm above and behind the handle, tilted along the tool.
    let palm_pose = Isometry3::from_parts(
        Translation3::new(-0.105, 0.032, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.25),
    );
    mesh.append(&TriMesh::ellipsoid(&palm_pose, Vector3::new(0.045, 0.018, 0.040), SEGMENTS));
    // Forearm stub behind the hand, about 20° above the horizontal at the scenes' tool pitches; it
    // covers the end of the handle, as a real palm does.
    mesh.append(&TriMesh::capsule(p(-0.122, 0.030, 0.0), p(-0.195, 0.002, 0.0), 0.027, SEGMENTS));
    // Index finger along the spine side of the handle; its tip slides toward the blade with grip.
    let index_tip = p(-0.040 + 0.048 * g, handle_top + FINGER_RADIUS * 0.9 + 0.002 * (1.0 - g), 0.0);
    let index_mid = p(-0.062 + 0.020 * g, handle_top + FINGER_RADIUS + 0.004, 0.0);
    mesh.append(&TriMesh::capsule(p(-0.085, 0.030, 0.0), index_mid, FINGER_RADIUS, SEGMENTS));
    mesh.append(&TriMesh::capsule(index_mid, index_tip, FINGER_RADIUS * 0.95, SEGMENTS));
    // Thumb on the +z face, middle finger on the −z face.
    let side = handle.half_thickness + FINGER_RADIUS;
    mesh.append(&TriMesh::capsule(p(-0.095, 0.020, 0.030), p(-0.058 + 0.010 * g, 0.0, side), FINGER_RADIUS, SEGMENTS));
    mesh.append(&TriMesh::capsule(
        p(-0.088, 0.018, -0.030),
        p(-0.062 + 0.008 * g, -0.001, -side),
        FINGER_RADIUS,
        SEGMENTS,
    ));
    // Ring and little fingers curled under the handle.
    mesh.append(&TriMesh::capsule(p(-0.100, 0.012, -0.026), p(-0.088, -0.016, -0.012), FINGER_RADIUS, SEGMENTS));
    mesh.append(&TriMesh::capsule(p(-0.112, 0.008, -0.020), p(-0.104, -0.014, -0.008), FINGER_RADIUS * 0.85, SEGMENTS));
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_finger_reaches_the_blade_only_at_full_grip() {
        let reach = |g: f64| hand_mesh(g).vertices.iter().map(|v| v.x).fold(f64::MIN, f64::max);
        assert!(reach(0.0) < -0.02, "{}", reach(0.0));
        assert!(reach(1.0) > 0.01, "{}", reach(1.0));
        assert!(hand_mesh(0.5).triangles.len() > 1000);
    }
}
