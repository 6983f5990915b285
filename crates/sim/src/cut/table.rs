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

/// How close above the table a cutting edge plunging onto it cuts down through it, metres
/// ([`Table::pressed_through`]).
pub const TABLE_REACH_M: f64 = 0.002;

/// How steeply the cutting edge must rise from a vertex near the table, or that vertex must have
/// come down, for it to count as pressed onto the table: rise over run (0.5: 27° from the
/// horizontal; the resection holds the blade at 60-70°).
pub const PLUNGE_SLOPE: f64 = 0.5;

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

    /// `surface` with its cutting edge carried down through the table where the edge plunges
    /// onto it: every vertex less than [`TABLE_REACH_M`] above the top where the edge rises
    /// from it steeper than [`PLUNGE_SLOPE`], or where the edge came down onto it that steeply
    /// (a blade pressed down to the table, not one laid flat and slid along it), is moved to
    /// [`TABLE_REACH_M`] / 2 below it. `None` when no vertex moves.
    ///
    /// The organ's lowest nodes rest on the table, and a pose is a millimetre or so off: a blade
    /// that stops a hair above the table (0.1 mm in `examples/resection_jitter.rs`) left
    /// everything resting on it joined, where a scalpel pressed onto the table cuts through the
    /// thin layer under it.
    pub fn pressed_through(&self, surface: &crate::sweep::SweptSurface) -> Option<crate::sweep::SweptSurface> {
        let edge = surface.vertices.len() / surface.rows.max(1);
        if edge < 2 || edge * surface.rows != surface.vertices.len() {
            return None;
        }
        let (near, below) = (self.height + TABLE_REACH_M, self.height - TABLE_REACH_M / 2.0);
        let v = &surface.vertices;
        let steep = |a: usize, b: usize| {
            let (p, q) = (v[a], v[b]);
            (q.z - p.z) > PLUNGE_SLOPE * ((q.x - p.x).powi(2) + (q.y - p.y).powi(2)).sqrt()
        };
        // Steep along the edge (a blade held pitched down), or come down steeply from the row
        // before or to the row after (a blade brought down onto the table).
        let moved: Vec<usize> = (0..v.len())
            .filter(|&i| v[i].z < near && v[i].z > below)
            .filter(|&i| {
                let k = i % edge;
                let along = (k > 0 && steep(i, i - 1)) || (k + 1 < edge && steep(i, i + 1));
                let down = (i >= edge && steep(i, i - edge)) || (i + edge < v.len() && steep(i, i + edge));
                along || down
            })
            .collect();
        if moved.is_empty() {
            return None;
        }
        let mut pressed = surface.clone();
        for i in moved {
            pressed.vertices[i].z = below;
        }
        Some(pressed)
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
    fn a_blade_pressed_onto_the_table_cuts_through_to_it_and_one_slid_flat_along_it_does_not() {
        use crate::sweep::SweptSurface;
        use nalgebra::{Isometry3, Translation3, UnitQuaternion};
        let t = table();
        // A 3 cm edge from its tip along +x, pitched 60° down toward the tip.
        let edge: Vec<Point3<f64>> = (0..7).map(|k| Point3::new(0.005 * k as f64, 0.0, 0.0)).collect();
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -60f64.to_radians());
        let at = |y: f64, tip_above: f64, r: UnitQuaternion<f64>| {
            Isometry3::from_parts(Translation3::new(0.0, y, t.height + tip_above), r)
        };
        let sweep = |tip_above: f64, r: UnitQuaternion<f64>| {
            SweptSurface::between(&edge, &at(0.0, tip_above, r), &at(0.02, tip_above, r), 0.0025, 0.1).expect("a sweep")
        };
        // Pitched, its tip 1 mm above the table, slid along it: the tip's row goes through the
        // table, the rest of the edge (4.3 mm up at its second point) stays.
        let pitched = sweep(0.001, pitch);
        let pressed = t.pressed_through(&pitched).expect("pressed");
        for (before, after) in pitched.vertices.iter().zip(&pressed.vertices) {
            if before.z < t.height + TABLE_REACH_M {
                assert!((after.z - (t.height - TABLE_REACH_M / 2.0)).abs() < 1e-12, "{before} -> {after}");
            } else {
                assert_eq!(before, after);
            }
        }
        // Its tip 3 mm above: nothing moves.
        assert!(t.pressed_through(&sweep(0.003, pitch)).is_none());
        // Laid flat 1 mm above the table and slid along it: nothing moves either.
        assert!(t.pressed_through(&sweep(0.001, UnitQuaternion::identity())).is_none());
        // Laid flat and brought straight down to 1 mm above it (a cleaver): pressed through.
        let down = SweptSurface::between(
            &edge,
            &at(0.0, 0.02, UnitQuaternion::identity()),
            &at(0.0, 0.001, UnitQuaternion::identity()),
            0.0025,
            0.1,
        )
        .expect("a sweep");
        let pressed = t.pressed_through(&down).expect("pressed");
        assert!(pressed.vertices.iter().filter(|v| v.z < t.height).count() == edge.len());
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
