//! The table the tissue rests on: a half-space (parry's [`HalfSpace`]) below a horizontal plane,
//! with Coulomb friction.
//!
//! Contact is resolved by projection after every time step (as the hand's obstacle is, see
//! [`crate::Obstacle`]): a node found below the plane is put back on it and its normal velocity
//! is removed (inelastic contact). Friction acts on the step's tangential motion with the
//! position-based form of Coulomb's law: the normal correction `d` is the normal impulse over
//! the node's mass times the step, so friction may take away tangential motion up to `μ d`; a
//! node whose tangential step is smaller sticks where it was (static friction), a faster one
//! slides with its step shortened by `μ d` (kinetic friction). A piece resting on the table then
//! stays put under gravity, and a piece falling onto it lands, slides a little and stops.
//!
//! The plane is horizontal (z up, as in the world frame); the table's height is its top.

use nalgebra::{Point3, Vector3};
use parry3d_f64::math::{Pose, Vector as PVector};
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::HalfSpace;

use crate::SimError;

/// Largest friction coefficient a table takes (rubber on dry rubber is about 1-2).
pub const MAX_FRICTION: f64 = 10.0;

/// A horizontal table top under the tissue.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Table {
    /// Height of the table top, metres (world z).
    pub height: f64,
    /// Coulomb friction coefficient between tissue and table (static and kinetic alike).
    pub friction: f64,
}

impl Table {
    /// Checks the height is finite and the friction within `[0, MAX_FRICTION]`.
    pub fn validate(&self) -> Result<(), SimError> {
        let invalid = |message: String| SimError::Invalid { key: "table".to_owned(), message };
        if !(self.height.is_finite() && self.height.abs() <= 1e3) {
            return Err(invalid(format!("the height must be finite and within 1 km, got {}", self.height)));
        }
        if !(0.0..=MAX_FRICTION).contains(&self.friction) {
            return Err(invalid(format!("the friction must lie in [0, {MAX_FRICTION}], got {}", self.friction)));
        }
        Ok(())
    }

    /// The half-space below the table top and where it lies.
    fn shape(&self) -> (HalfSpace, Pose) {
        (HalfSpace::new(PVector::Z), Pose::translation(0.0, 0.0, self.height))
    }

    /// Puts the nodes below the table back on it with friction (see the module's text); `rest`
    /// and `u` give positions now, `u_prev` a step before; nodes for which `skip` holds are left
    /// alone. Returns how many were in contact.
    pub fn resolve(
        &self,
        rest: &[Point3<f32>],
        u: &mut [Vector3<f32>],
        u_prev: &mut [Vector3<f32>],
        skip: &[bool],
    ) -> usize {
        self.resolve_nodes(rest, u, u_prev, skip, 0..u.len())
    }

    /// As [`Table::resolve`], for `nodes` only (the others are left as they are).
    pub fn resolve_nodes(
        &self,
        rest: &[Point3<f32>],
        u: &mut [Vector3<f32>],
        u_prev: &mut [Vector3<f32>],
        skip: &[bool],
        nodes: impl Iterator<Item = usize>,
    ) -> usize {
        let (half_space, pose) = self.shape();
        let top = self.height as f32;
        let mut contacts = 0;
        for n in nodes {
            let x = rest[n] + u[n];
            // The broad phase: only nodes at or below the top can be in the half-space.
            if skip[n] || x.z > top {
                continue;
            }
            let point = PVector::new(f64::from(x.x), f64::from(x.y), f64::from(x.z));
            let projection = half_space.project_point(&pose, point, false);
            if !projection.is_inside {
                continue;
            }
            contacts += 1;
            let depth = (projection.point.z - point.z) as f32;
            u[n].z += depth;
            u_prev[n].z = u[n].z;
            let slip = Vector3::new(u[n].x - u_prev[n].x, u[n].y - u_prev[n].y, 0.0);
            let length = slip.norm();
            let grip = self.friction as f32 * depth;
            let removed = if length <= grip { slip } else { slip * (grip / length) };
            u[n].x -= removed.x;
            u[n].y -= removed.y;
        }
        contacts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        Table { height: 0.01, friction: 0.5 }
    }

    #[test]
    fn a_node_below_the_top_is_put_back_and_stopped_and_one_above_is_left_alone() {
        let rest = [Point3::new(0.0, 0.0, 0.0f32), Point3::new(0.0, 0.0, 0.02)];
        let mut u = [Vector3::new(0.0, 0.0, 0.005f32), Vector3::new(0.0, 0.0, -0.005)];
        let mut u_prev = [Vector3::new(0.0, 0.0, 0.007f32), Vector3::new(0.0, 0.0, -0.004)];
        assert_eq!(table().resolve(&rest, &mut u, &mut u_prev, &[false, false]), 1);
        assert!((u[0].z - 0.01).abs() < 1e-7 && u_prev[0].z == u[0].z, "on the top, at rest: {:?}", u[0]);
        assert_eq!(u[1], Vector3::new(0.0, 0.0, -0.005), "above the top: unchanged");
        // A held node is skipped.
        let mut u = [Vector3::new(0.0, 0.0, 0.005f32)];
        let mut prev = u;
        assert_eq!(table().resolve(&rest[..1], &mut u, &mut prev, &[true]), 0);
    }

    #[test]
    fn friction_holds_a_slow_node_and_shortens_a_fast_ones_slide_by_mu_times_the_correction() {
        let rest = [Point3::new(0.0, 0.0, 0.0f32)];
        // 1 mm below the top: the grip is 0.5 mm of tangential motion.
        let slow = Vector3::new(0.0003f32, 0.0, 0.009);
        let mut u = [slow];
        let mut u_prev = [Vector3::new(0.0, 0.0, 0.01)];
        table().resolve(&rest, &mut u, &mut u_prev, &[false]);
        assert!(u[0].x.abs() < 1e-9, "static friction: {:?}", u[0]);
        let mut u = [Vector3::new(0.0020f32, 0.0, 0.009)];
        let mut u_prev = [Vector3::new(0.0, 0.0, 0.01)];
        table().resolve(&rest, &mut u, &mut u_prev, &[false]);
        assert!((u[0].x - 0.0015).abs() < 1e-6, "kinetic friction: {:?}", u[0]);
        // Without friction it slides freely.
        let mut u = [Vector3::new(0.0020f32, 0.0, 0.009)];
        let mut u_prev = [Vector3::new(0.0, 0.0, 0.01)];
        Table { friction: 0.0, ..table() }.resolve(&rest, &mut u, &mut u_prev, &[false]);
        assert!((u[0].x - 0.0020).abs() < 1e-9);
    }

    #[test]
    fn bad_tables_are_refused_naming_the_key() {
        for bad in [Table { height: f64::NAN, friction: 0.5 }, Table { height: 0.0, friction: -0.1 }] {
            let e = bad.validate().expect_err("refused").to_string();
            assert!(e.contains("table"), "{e}");
        }
        assert!(table().validate().is_ok());
    }
}
