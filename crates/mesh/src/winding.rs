//! Generalized winding numbers: exact ([`TriMesh::winding_number`]) and fast ([`WindingTree`]).
//!
//! The winding number of a point is the signed solid angle the mesh subtends there, over 4π (Jacobson
//! et al. 2013, "Robust inside-outside segmentation using generalized winding numbers"): 1 inside and
//! 0 outside a closed, outward-oriented mesh, and a smooth value between that still separates inside
//! from outside at 0.5 where the mesh has holes. [`WindingTree`] answers many queries fast with a
//! bounding volume hierarchy whose far clusters are replaced by their dipole and quadrupole moments
//! (Barill et al. 2018, "Fast winding numbers for soups and clouds").

use nalgebra::{Matrix3, Point3, Vector3};

use crate::TriMesh;

impl TriMesh {
    /// Generalized winding number at `p`, summing every triangle exactly: O(triangles) per query;
    /// use [`WindingTree`] for many queries. A point on a triangle's plane inside it gets no
    /// contribution from that triangle, so a point on a closed mesh's face reads 0.5.
    pub fn winding_number(&self, p: &Point3<f64>) -> f64 {
        self.triangles.iter().map(|t| solid_angle(&t.map(|i| self.vertices[i as usize]), p)).sum::<f64>()
            / (4.0 * std::f64::consts::PI)
    }
}

/// Signed solid angle of triangle `t` seen from `p` (Van Oosterom and Strackee 1983): positive
/// when `p` is behind the triangle (on the side its normal points away from).
fn solid_angle(t: &[Point3<f64>; 3], p: &Point3<f64>) -> f64 {
    let a = t[0] - p;
    let b = t[1] - p;
    let c = t[2] - p;
    let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
    let det = a.dot(&b.cross(&c));
    // Coplanar with the triangle (or on a vertex): the limit is ±2π or 0 depending on the side, so
    // contribute nothing; the rest of a closed mesh then sums to half a turn.
    if det.abs() <= 1e-14 * la * lb * lc {
        return 0.0;
    }
    let den = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
    2.0 * det.atan2(den)
}

/// Default of [`WindingTree::with_far_ratio`]: as in Barill et al. 2018.
pub const FAR_RATIO: f64 = 2.0;
/// Triangles per BVH leaf.
const LEAF_SIZE: usize = 8;

#[derive(Debug, Clone)]
struct WindingNode {
    /// Area-weighted centroid of the cluster.
    center: Point3<f64>,
    /// Largest distance from `center` to a vertex of the cluster.
    radius: f64,
    /// Sum of area-weighted normals (the dipole moment).
    normal: Vector3<f64>,
    /// First moment: sum over triangles of `(centroid - center) (area normal)ᵀ`.
    moment: Matrix3<f64>,
    /// Second moment, one symmetric matrix per normal component i: the sum over triangles of
    /// `(area normal)_i ∫ (x - center)(x - center)ᵀ dA / area`.
    second: [Matrix3<f64>; 3],
    /// Leaf: `(first triangle, count)`; inner node: `(left child, 0)`, the right child follows the
    /// left subtree.
    first: u32,
    count: u32,
    right: u32,
}

impl WindingNode {
    /// The cluster's solid angle seen from the point at `r = center - p` (`d2 = |r|²`): the kernel
    /// F(r) = r / |r|³ integrated against the area normals, Taylor-expanded about the centre to second
    /// order (Barill et al. 2018, eq. 11-13): N·F + ∂F : M + ½ ∂²F ⋮ T.
    fn far_field(&self, r: &Vector3<f64>, d2: f64) -> f64 {
        let d = d2.sqrt();
        let inv3 = 1.0 / (d2 * d);
        let inv5 = inv3 / d2;
        let dipole = r.dot(&self.normal) * inv3;
        // ∂F_i/∂r_j = δ_ij / |r|³ - 3 r_i r_j / |r|⁵.
        let first = self.moment.trace() * inv3 - 3.0 * r.dot(&(self.moment * r)) * inv5;
        // ∂²F_i/∂r_j∂r_k = -3 (δ_ij r_k + δ_ik r_j + δ_jk r_i) / |r|⁵ + 15 r_i r_j r_k / |r|⁷.
        let mut a = Vector3::zeros();
        let mut b = Vector3::zeros();
        let mut rrr = 0.0;
        for i in 0..3 {
            a += self.second[i].row(i).transpose();
            b[i] = self.second[i].trace();
            rrr += r[i] * r.dot(&(self.second[i] * r));
        }
        let second = 0.5 * (-3.0 * (2.0 * a.dot(r) + b.dot(r)) * inv5 + 15.0 * rrr * inv5 / d2);
        dipole + first + second
    }
}

/// A bounding volume hierarchy over a mesh's triangles for fast generalized winding numbers
/// (Barill et al. 2018): clusters far from the query point contribute their dipole and quadrupole
/// moments, near ones are summed exactly. Queries are read-only and can run in parallel.
#[derive(Debug, Clone)]
pub struct WindingTree {
    far_ratio: f64,
    nodes: Vec<WindingNode>,
    triangles: Vec<[Point3<f64>; 3]>,
}

impl WindingTree {
    /// Builds the hierarchy (O(n log n)) with the default [`FAR_RATIO`].
    pub fn new(mesh: &TriMesh) -> Self {
        Self::with_far_ratio(mesh, FAR_RATIO)
    }

    /// Builds the hierarchy; clusters farther from a query point than `far_ratio` times their radius
    /// contribute their moment expansion instead of their triangles (larger: slower and more exact).
    pub fn with_far_ratio(mesh: &TriMesh, far_ratio: f64) -> Self {
        let triangles: Vec<[Point3<f64>; 3]> =
            mesh.triangles.iter().map(|t| t.map(|i| mesh.vertices[i as usize])).collect();
        let mut order: Vec<usize> = (0..triangles.len()).collect();
        let centroids: Vec<Point3<f64>> =
            triangles.iter().map(|t| Point3::from((t[0].coords + t[1].coords + t[2].coords) / 3.0)).collect();
        let mut nodes = Vec::new();
        if !triangles.is_empty() {
            build(&triangles, &centroids, &mut order, 0, &mut nodes);
        }
        let triangles = order.iter().map(|&i| triangles[i]).collect();
        Self { far_ratio, nodes, triangles }
    }

    /// Generalized winding number at `p` (see the module docs). At the default [`FAR_RATIO`] it is
    /// within about 5e-3 of [`TriMesh::winding_number`] (largest error over 5000 random points around
    /// the Stanford bunny: 5.2e-3; 1.7e-3 at a ratio of 2.5, 0.9e-3 at 3).
    pub fn winding_number(&self, p: &Point3<f64>) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut sum = 0.0;
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            let r = node.center - p;
            let d2 = r.norm_squared();
            if d2 > (self.far_ratio * node.radius).powi(2) {
                sum += node.far_field(&r, d2);
                continue;
            }
            if node.count > 0 {
                let range = node.first as usize..(node.first + node.count) as usize;
                sum += self.triangles[range].iter().map(|t| solid_angle(t, p)).sum::<f64>();
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.right;
                top += 2;
            } else {
                // Deeper than the stack (a degenerate hierarchy): sum the subtree exactly.
                sum += self.subtree_exact(node, p);
            }
        }
        sum / (4.0 * std::f64::consts::PI)
    }

    fn subtree_exact(&self, node: &WindingNode, p: &Point3<f64>) -> f64 {
        if node.count > 0 {
            let range = node.first as usize..(node.first + node.count) as usize;
            return self.triangles[range].iter().map(|t| solid_angle(t, p)).sum();
        }
        self.subtree_exact(&self.nodes[node.first as usize], p)
            + self.subtree_exact(&self.nodes[node.right as usize], p)
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether the tree holds no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }
}

/// Builds the subtree over `order[..]` (indices into `tris`) starting at `offset` in the final
/// triangle order; returns its node index.
fn build(
    tris: &[[Point3<f64>; 3]],
    centroids: &[Point3<f64>],
    order: &mut [usize],
    offset: usize,
    nodes: &mut Vec<WindingNode>,
) -> u32 {
    let mut area_sum = 0.0;
    let mut weighted = Vector3::zeros();
    let mut normal = Vector3::zeros();
    let mut mean = Vector3::zeros();
    for &i in order.iter() {
        let t = &tris[i];
        let n = (t[1] - t[0]).cross(&(t[2] - t[0])) * 0.5;
        let a = n.norm();
        area_sum += a;
        weighted += centroids[i].coords * a;
        normal += n;
        mean += centroids[i].coords;
    }
    let center = Point3::from(if area_sum > 0.0 { weighted / area_sum } else { mean / order.len().max(1) as f64 });
    let mut radius: f64 = 0.0;
    let mut moment = Matrix3::zeros();
    let mut second = [Matrix3::zeros(); 3];
    for &i in order.iter() {
        let t = &tris[i];
        let v = t.map(|v| v - center);
        for v in &v {
            radius = radius.max(v.norm());
        }
        let n = (t[1] - t[0]).cross(&(t[2] - t[0])) * 0.5;
        moment += (centroids[i] - center) * n.transpose();
        // Mean of x xᵀ over a triangle with vertices v: (Σ v vᵀ + s sᵀ) / 12, s = Σ v.
        let s = v[0] + v[1] + v[2];
        let mean =
            (v[0] * v[0].transpose() + v[1] * v[1].transpose() + v[2] * v[2].transpose() + s * s.transpose()) / 12.0;
        for k in 0..3 {
            second[k] += mean * n[k];
        }
    }
    let index = nodes.len() as u32;
    nodes.push(WindingNode {
        center,
        radius,
        normal,
        moment,
        second,
        first: offset as u32,
        count: order.len() as u32,
        right: 0,
    });
    if order.len() <= LEAF_SIZE {
        return index;
    }
    let (lo, hi) =
        order.iter().fold((Point3::from([f64::INFINITY; 3]), Point3::from([f64::NEG_INFINITY; 3])), |(lo, hi), &i| {
            (lo.inf(&centroids[i]), hi.sup(&centroids[i]))
        });
    let extent = hi - lo;
    let axis = extent.imax();
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| centroids[a][axis].total_cmp(&centroids[b][axis]));
    let (left, right) = order.split_at_mut(mid);
    let l = build(tris, centroids, left, offset, nodes);
    let r = build(tris, centroids, right, offset + mid, nodes);
    let node = &mut nodes[index as usize];
    node.first = l;
    node.count = 0;
    node.right = r;
    index
}
