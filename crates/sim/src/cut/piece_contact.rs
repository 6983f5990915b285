//! Pieces pressed against each other: a piece cut free must rest on the piece below it, not sink
//! through it onto the table.
//!
//! Every 1/30 s of simulated time the contacts are found: every piece's closed surface, deformed,
//! becomes a parry [`TriMesh`] of its triangles where other pieces' nodes come within reach of
//! it, and each lattice node that carries another piece's material (a real
//! node with mass, not held) within reach of it gets a contact plane: the nearest point of that
//! surface and the outward normal of its triangle (when the node is inside, or faces a triangle;
//! nearest a rim's edge or corner, a face's plane would catch a piece sliding past it). Then after every time step of the frame
//! ([`enforce`]) a node behind its plane is put back on it, its normal velocity removed and its
//! tangential step shortened by Coulomb friction, as on the table ([`crate::table`]). Virtual
//! nodes are left alone: they carry a copy's material across its cut and lie inside the other
//! piece by construction.
//!
//! The planes stay where they were found for the frame (the other piece's own motion within a
//! frame is not followed), which holds for pieces resting on or sliding along each other.

use nalgebra::{Point3, Vector3};
use parry3d_f64::math::Vector as PVector;
use parry3d_f64::query::PointQueryWithLocation;
use parry3d_f64::shape::{TriMesh, TrianglePointLocation};

use crate::cut_surface::PieceSurface;

/// A node held out of another piece for a frame: behind the plane through `point` with outward
/// unit `normal` it is inside that piece.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPlane {
    /// The node (of the cut lattice).
    pub node: u32,
    /// The nearest point of the other piece's surface, metres.
    pub point: Point3<f32>,
    /// That surface's outward normal there.
    pub normal: Vector3<f32>,
}

/// What [`detect`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PieceContacts {
    /// One plane per node within reach of another piece.
    pub planes: Vec<ContactPlane>,
    /// Of those, nodes found inside the other piece (before this frame's steps).
    pub inside: usize,
    /// Piece surfaces parry could not take: nothing is kept out of those.
    pub skipped_surfaces: usize,
}

fn to_parry(p: &Point3<f32>) -> PVector {
    PVector::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))
}

/// The contact planes of the nodes for which `piece_of_node` names a piece (`u32::MAX`: none)
/// within `reach` metres of another piece's surface (`surfaces`, one per piece, deformed by `u`).
pub fn detect(
    surfaces: &[PieceSurface],
    rest: &[Point3<f32>],
    u: &[Vector3<f32>],
    piece_of_node: &[u32],
    reach: f32,
) -> PieceContacts {
    let mut out = PieceContacts::default();
    if surfaces.len() < 2 {
        return out;
    }
    let deformed: Vec<Vec<Point3<f32>>> = surfaces.iter().map(|s| s.deformed(u)).collect();
    let boxes: Vec<(Point3<f32>, Point3<f32>)> = deformed
        .iter()
        .map(|v| {
            v.iter()
                .fold((Point3::from([f32::MAX; 3]), Point3::from([f32::MIN; 3])), |(lo, hi), p| (lo.inf(p), hi.sup(p)))
        })
        .collect();
    // Where other pieces' nodes come within reach of each piece's box: only its triangles there
    // are put in the BVH (a cut-off tip against the organ's whole surface would cost the organ's
    // triangles every frame).
    let mut near: Vec<(Point3<f32>, Point3<f32>)> =
        vec![(Point3::from([f32::MAX; 3]), Point3::from([f32::MIN; 3])); surfaces.len()];
    for n in 0..u.len() {
        let a = piece_of_node[n];
        if a == u32::MAX {
            continue;
        }
        let x = rest[n] + u[n];
        for (b, (lo, hi)) in boxes.iter().enumerate() {
            if b as u32 != a && (0..3).all(|k| x[k] >= lo[k] - reach && x[k] <= hi[k] + reach) {
                near[b] = (near[b].0.inf(&Point3::from(x.coords)), near[b].1.sup(&Point3::from(x.coords)));
            }
        }
    }
    let mut meshes: Vec<Option<Option<TriMesh>>> = vec![None; surfaces.len()];
    for n in 0..u.len() {
        let a = piece_of_node[n];
        if a == u32::MAX {
            continue;
        }
        let x = rest[n] + u[n];
        let mut best: Option<(f64, ContactPlane, bool)> = None;
        for (b, (lo, hi)) in boxes.iter().enumerate() {
            if b as u32 == a || (0..3).any(|k| x[k] < lo[k] - reach || x[k] > hi[k] + reach) {
                continue;
            }
            let mesh = meshes[b].get_or_insert_with(|| {
                let (lo, hi) = near[b];
                let v = &deformed[b];
                let triangles: Vec<[u32; 3]> = surfaces[b]
                    .rest
                    .triangles
                    .iter()
                    .filter(|t| {
                        (0..3).all(|k| {
                            let (tlo, thi) = t
                                .iter()
                                .map(|&i| v[i as usize][k])
                                .fold((f32::MAX, f32::MIN), |(a, b), c| (a.min(c), b.max(c)));
                            thi >= lo[k] - reach && tlo <= hi[k] + reach
                        })
                    })
                    .copied()
                    .collect();
                if triangles.is_empty() {
                    return None;
                }
                let built = TriMesh::new(v.iter().map(to_parry).collect(), triangles);
                out.skipped_surfaces += usize::from(built.is_err());
                built.ok()
            });
            let Some(mesh) = mesh else { continue };
            let point = to_parry(&Point3::from(x.coords));
            let Some((projection, (triangle, location))) =
                mesh.project_local_point_and_get_location_with_max_dist(point, false, f64::from(reach))
            else {
                continue;
            };
            let Some(normal) = mesh.triangle(triangle).normal() else { continue };
            let distance = (point - projection.point).length();
            let inside = (point - projection.point).dot(normal) < 0.0;
            // A node outside nearest an edge or a corner of the other piece (its rim) gets no plane:
            // a face's plane extended past the rim would catch a piece sliding past it.
            if !inside && !matches!(location, TrianglePointLocation::OnFace(..) | TrianglePointLocation::OnSolid) {
                continue;
            }
            if best.as_ref().is_none_or(|(d, _, _)| distance < *d) {
                let plane = ContactPlane {
                    node: n as u32,
                    point: Point3::new(projection.point.x as f32, projection.point.y as f32, projection.point.z as f32),
                    normal: Vector3::new(normal.x as f32, normal.y as f32, normal.z as f32),
                };
                best = Some((distance, plane, inside));
            }
        }
        if let Some((_, plane, inside)) = best {
            out.inside += usize::from(inside);
            out.planes.push(plane);
        }
    }
    out
}

/// Puts every node behind its contact plane back on it, by at most `max_move` metres, with its
/// normal velocity removed and its tangential step shortened by `friction` times the correction
/// (`u` now, `u_prev` a step before, as [`crate::Table::resolve`]). Returns how many.
pub fn enforce(
    planes: &[ContactPlane],
    rest: &[Point3<f32>],
    u: &mut [Vector3<f32>],
    u_prev: &mut [Vector3<f32>],
    friction: f32,
    max_move: f32,
) -> usize {
    let mut count = 0;
    for plane in planes {
        let n = plane.node as usize;
        let x = rest[n] + u[n];
        let depth = -(x - plane.point).dot(&plane.normal);
        if depth <= 0.0 {
            continue;
        }
        count += 1;
        let depth = depth.min(max_move);
        u[n] += plane.normal * depth;
        // Normal velocity removed; the tangential step shortened by μ × the correction.
        let step = u[n] - u_prev[n];
        let normal_step = plane.normal * step.dot(&plane.normal);
        let slip = step - normal_step;
        let grip = friction * depth;
        let removed = if slip.norm() <= grip { slip } else { slip * (grip / slip.norm()) };
        u[n] -= removed;
        u_prev[n] += normal_step;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_behind_its_plane_is_put_back_and_stopped_and_one_in_front_is_left_alone() {
        let plane = |node| ContactPlane { node, point: Point3::new(0.0, 0.0, 0.01), normal: Vector3::z() };
        let rest = [Point3::origin(), Point3::new(0.0, 0.0, 0.02)];
        let mut u = [Vector3::new(0.0003, 0.0, 0.009f32), Vector3::zeros()];
        let mut u_prev = [Vector3::new(0.0, 0.0, 0.0095f32), Vector3::zeros()];
        let planes = [plane(0), plane(1)];
        assert_eq!(enforce(&planes, &rest, &mut u, &mut u_prev, 0.5, 0.01), 1);
        // Back on the plane (1 mm up), stopped along the normal, and the 0.3 mm slip held by
        // friction (μ × 1 mm = 0.5 mm of grip).
        assert!((u[0].z - 0.01).abs() < 1e-7 && (u_prev[0].z - u[0].z).abs() < 1e-7, "{:?} {:?}", u[0], u_prev[0]);
        assert!(u[0].x.abs() < 1e-7, "{:?}", u[0]);
        assert_eq!(u[1], Vector3::zeros());
    }
}
