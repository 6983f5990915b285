//! The surface a blade's cutting edge sweeps between two trusted poses.
//!
//! The edge (a polyline in the tool frame, tip to heel) is carried from one pose to the next along
//! the rigid motion between them: translation interpolated linearly, rotation by slerp. Rows of
//! the edge at intermediate times, as many as it takes for no point of the edge to move more than
//! `max_chord` between rows and the rotation to turn by no more than `max_angle`, are joined into a
//! triangulated ruled surface. However fast the stroke, the surface spans the whole motion
//! between the two frames: nothing between them is skipped (no tunnelling). A pose that was not
//! trusted is never given to it: the caller sweeps only between trusted poses.

use nalgebra::{Isometry3, Point3, Translation3};

/// Largest number of rows a sweep is divided into (a safety bound for absurd inputs).
const MAX_ROWS: usize = 1024;

/// A triangulated swept surface.
#[derive(Debug, Clone, PartialEq)]
pub struct SweptSurface {
    /// Vertices: `rows` copies of the edge, row by row (row 0 at the first pose).
    pub vertices: Vec<Point3<f64>>,
    /// Triangles (vertex indices), two per quad between consecutive rows and edge points.
    pub triangles: Vec<[u32; 3]>,
    /// Rows of the edge (at least 2).
    pub rows: usize,
}

impl SweptSurface {
    /// The surface `edge` (tool frame, at least two points) sweeps from pose `from` to pose `to`,
    /// divided so that no edge point moves more than `max_chord` metres and the tool turns no more
    /// than `max_angle` radians between rows. `None` for an edge of fewer than two points, a
    /// non-finite pose or non-positive limits.
    pub fn between(
        edge: &[Point3<f64>],
        from: &Isometry3<f64>,
        to: &Isometry3<f64>,
        max_chord: f64,
        max_angle: f64,
    ) -> Option<Self> {
        Self::through(edge, &[*from, *to], max_chord, max_angle)
    }

    /// The surface `edge` sweeps along the path through `poses` (at least two), each leg divided
    /// as [`SweptSurface::between`] divides it; its rows run from the first pose to the last.
    /// `None` as for `between`, or for fewer than two poses or 1024 legs and more (a sweep has
    /// at most 1024 rows).
    ///
    /// A caller that cuts a moving body starts each sweep a little back along the leg before
    /// ([`reach_back`]): each sweep is tested against the body where it is now, so an edge of the
    /// body that moved across the seam between two sweeps (behind the row where the last sweep
    /// ended, ahead of the row where this one starts) would be crossed by neither.
    pub fn through(edge: &[Point3<f64>], poses: &[Isometry3<f64>], max_chord: f64, max_angle: f64) -> Option<Self> {
        let finite = |p: &Isometry3<f64>| p.to_homogeneous().iter().all(|c| c.is_finite());
        if !(edge.len() >= 2 && poses.len() >= 2 && poses.iter().all(finite) && max_chord > 0.0 && max_angle > 0.0) {
            return None;
        }
        let legs = poses.len() - 1;
        if legs >= MAX_ROWS {
            return None;
        }
        let per_leg = (MAX_ROWS - 1) / legs;
        let mut vertices = Vec::new();
        let mut rows = 0;
        for (k, leg) in poses.windows(2).enumerate() {
            let (from, to) = (&leg[0], &leg[1]);
            let travel = edge.iter().map(|p| (to * p - from * p).norm()).fold(0.0, f64::max);
            let angle = from.rotation.angle_to(&to.rotation);
            let steps = ((travel / max_chord).ceil().max((angle / max_angle).ceil()) as usize).clamp(1, per_leg);
            // Every leg but the first starts where the one before ended.
            for r in usize::from(k > 0)..=steps {
                let pose = interpolate(from, to, r as f64 / steps as f64);
                vertices.extend(edge.iter().map(|p| pose * p));
                rows += 1;
            }
        }
        let n = edge.len() as u32;
        let mut triangles = Vec::with_capacity(2 * (rows - 1) * (edge.len() - 1));
        for r in 0..(rows - 1) as u32 {
            for k in 0..n - 1 {
                let (a, b, c, d) = (r * n + k, r * n + k + 1, (r + 1) * n + k, (r + 1) * n + k + 1);
                triangles.push([a, b, d]);
                triangles.push([a, d, c]);
            }
        }
        Some(SweptSurface { vertices, triangles, rows })
    }

    /// The corners of triangle `t`.
    pub fn triangle(&self, t: usize) -> [Point3<f64>; 3] {
        self.triangles[t].map(|i| self.vertices[i as usize])
    }
}

/// Where a sweep from `before` should start so that it overlaps the leg from `earlier` to
/// `before` by `back` metres of the edge's travel (its farthest-moving point), or `earlier` when
/// that leg is shorter.
///
/// The overlap closes the seam between consecutive sweeps of a moving body (see
/// [`SweptSurface::through`]) and is kept short: material that moved into the blade's earlier
/// path after the blade had left it would be cut again, at another place in the material. Half a
/// lattice cell is more than the tissue moves in a frame, and two cuts that close are one
/// ([`crate::sliver`]).
pub fn reach_back(
    edge: &[Point3<f64>],
    earlier: &Isometry3<f64>,
    before: &Isometry3<f64>,
    back: f64,
) -> Isometry3<f64> {
    let travel = edge.iter().map(|p| (before * p - earlier * p).norm()).fold(0.0, f64::max);
    if travel <= back || !travel.is_finite() {
        return *earlier;
    }
    interpolate(earlier, before, 1.0 - back / travel)
}

/// The pose a fraction `s` of the way from `a` to `b` (translation lerp, rotation slerp).
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let t = a.translation.vector.lerp(&b.translation.vector, s);
    let r = a.rotation.try_slerp(&b.rotation, s, 1e-12).unwrap_or(if s < 0.5 { a.rotation } else { b.rotation });
    Isometry3::from_parts(Translation3::from(t), r)
}

#[cfg(test)]
mod tests {
    use nalgebra::{UnitQuaternion, Vector3};

    use super::*;

    fn edge() -> Vec<Point3<f64>> {
        (0..5).map(|k| Point3::new(0.01 * k as f64, 0.0, 0.0)).collect()
    }

    #[test]
    fn a_straight_stroke_is_one_strip_and_a_fast_one_is_divided() {
        let from = Isometry3::translation(0.0, 0.0, 0.1);
        let to = Isometry3::translation(0.0, 0.0, 0.05);
        let slow = SweptSurface::between(&edge(), &from, &to, 0.1, 0.5).expect("surface");
        assert_eq!((slow.rows, slow.triangles.len()), (2, 8));
        let fast = SweptSurface::between(&edge(), &from, &to, 0.004, 0.5).expect("surface");
        assert_eq!(fast.rows, 14, "5 cm in steps of at most 4 mm");
        // The rows lie on the path: the last row is the edge at the second pose.
        assert!((fast.vertices[13 * 5 + 4] - to * edge()[4]).norm() < 1e-15);
    }

    #[test]
    fn a_turn_is_followed_by_slerp() {
        let from = Isometry3::identity();
        let to =
            Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.0));
        let s = SweptSurface::between(&edge(), &from, &to, 1.0, 0.1).expect("surface");
        assert_eq!(s.rows, 11);
        // Every vertex stays at its distance from the axis of rotation.
        for (k, v) in s.vertices.iter().enumerate() {
            assert!((v.coords.norm() - edge()[k % 5].coords.norm()).abs() < 1e-12);
        }
        assert!(SweptSurface::between(&edge()[..1], &from, &to, 1.0, 0.1).is_none());
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
        assert!(SweptSurface::between(&edge(), &from, &nan, 1.0, 0.1).is_none());
    }

    #[test]
    fn a_path_through_three_poses_is_its_two_legs_joined_at_the_middle_pose() {
        let poses = [
            Isometry3::translation(0.0, 0.0, 0.1),
            Isometry3::translation(0.0, 0.0, 0.08),
            Isometry3::translation(0.0, 0.01, 0.07),
        ];
        let path = SweptSurface::through(&edge(), &poses, 0.004, 0.5).expect("surface");
        let first = SweptSurface::between(&edge(), &poses[0], &poses[1], 0.004, 0.5).expect("surface");
        let second = SweptSurface::between(&edge(), &poses[1], &poses[2], 0.004, 0.5).expect("surface");
        assert_eq!(path.rows, first.rows + second.rows - 1);
        assert_eq!(&path.vertices[..first.vertices.len()], &first.vertices[..]);
        assert_eq!(&path.vertices[first.vertices.len() - 5..], &second.vertices[..]);
        assert_eq!(path.triangles.len(), first.triangles.len() + second.triangles.len());
        assert!(SweptSurface::through(&edge(), &poses[..1], 0.004, 0.5).is_none());
    }

    #[test]
    fn a_sweep_reaches_back_half_a_cell_along_a_long_leg_and_over_a_short_one() {
        let (earlier, before) = (Isometry3::translation(0.0, 0.0, 0.1), Isometry3::translation(0.0, 0.0, 0.05));
        let start = reach_back(&edge(), &earlier, &before, 0.0025);
        assert!((start.translation.vector.z - 0.0525).abs() < 1e-12);
        assert_eq!(reach_back(&edge(), &earlier, &before, 0.06), earlier);
    }
}
