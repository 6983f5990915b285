//! The triangle mesh type: construction, rigid and scale transforms, topology (holes, open edges,
//! orientation), volume and area.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Vector3};

/// An indexed triangle mesh in metres. Triangles are counter-clockwise seen from outside (outward
/// normals). Meshes read from files ([`TriMesh::load`]) have finite vertices and valid indices;
/// meshes built in memory can be checked with [`TriMesh::validate`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Point3<f64>>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh built in memory.
    pub fn new(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> Self {
        Self { vertices, triangles }
    }

    /// The surface of the box `[min, max]` with each face split into a grid of `n` cells per axis
    /// (at least 1), as a closed, outward-oriented mesh: `4 (nx ny + ny nz + nz nx)` triangles.
    pub fn cuboid_grid(min: Point3<f64>, max: Point3<f64>, n: [usize; 3]) -> Self {
        let n = n.map(|v| v.max(1));
        let mut index = BTreeMap::new();
        let mut vertices = Vec::new();
        let mut vertex = |g: [usize; 3]| -> u32 {
            *index.entry(g).or_insert_with(|| {
                let p = Point3::from(Vector3::from_fn(|a, _| min[a] + (max[a] - min[a]) * g[a] as f64 / n[a] as f64));
                vertices.push(p);
                (vertices.len() - 1) as u32
            })
        };
        let mut triangles = Vec::new();
        for axis in 0..3 {
            // The face's grid runs along u and v with u x v = +axis.
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in [0, n[axis]] {
                for i in 0..n[u] {
                    for j in 0..n[v] {
                        let at = |di: usize, dj: usize| {
                            let mut g = [0; 3];
                            g[axis] = side;
                            g[u] = i + di;
                            g[v] = j + dj;
                            g
                        };
                        let q = [vertex(at(0, 0)), vertex(at(1, 0)), vertex(at(1, 1)), vertex(at(0, 1))];
                        if side == 0 {
                            triangles.push([q[0], q[2], q[1]]);
                            triangles.push([q[0], q[3], q[2]]);
                        } else {
                            triangles.push([q[0], q[1], q[2]]);
                            triangles.push([q[0], q[2], q[3]]);
                        }
                    }
                }
            }
        }
        Self::new(vertices, triangles)
    }

    /// Multiplies every coordinate by `factor` (e.g. 0.001 for a mesh in millimetres).
    pub fn scale(&mut self, factor: f64) {
        for v in &mut self.vertices {
            v.coords *= factor;
        }
    }

    /// Moves every vertex by `offset`.
    pub fn translate(&mut self, offset: &Vector3<f64>) {
        for v in &mut self.vertices {
            *v += offset;
        }
    }

    /// Reverses every triangle's orientation.
    pub fn flip(&mut self) {
        for t in &mut self.triangles {
            t.swap(1, 2);
        }
    }

    /// Axis-aligned bounds `(min, max)` of the vertices; `None` for a mesh without vertices.
    pub fn bounds(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let first = *self.vertices.first()?;
        Some(self.vertices.iter().fold((first, first), |(lo, hi), v| (lo.inf(v), hi.sup(v))))
    }

    /// Enclosed volume by the divergence theorem: the sum of signed tetrahedra from the bounds centre
    /// to each triangle. Positive for an outward-oriented closed mesh. Holes are first closed by a fan
    /// from the centroid of each [`TriMesh::holes`] component, so the result does not depend on the
    /// reference point for open meshes either.
    pub fn volume(&self) -> f64 {
        let Some((lo, hi)) = self.bounds() else { return 0.0 };
        let c = nalgebra::center(&lo, &hi);
        let det = |a: &Point3<f64>, b: &Point3<f64>, d: &Point3<f64>| (a - c).dot(&(b - c).cross(&(d - c)));
        let v = |i: u32| &self.vertices[i as usize];
        let mut sum: f64 = self.triangles.iter().map(|t| det(v(t[0]), v(t[1]), v(t[2]))).sum();
        for hole in self.holes() {
            let mut centroid = Vector3::zeros();
            for (a, b) in &hole {
                centroid += v(*a).coords + v(*b).coords;
            }
            let centroid = Point3::from(centroid / (2 * hole.len()) as f64);
            // Each border edge a -> b is closed by the cap triangle (b, a, centroid).
            sum += hole.iter().map(|(a, b)| det(v(*b), v(*a), &centroid)).sum::<f64>();
        }
        sum / 6.0
    }

    /// The border edges of the holes, grouped into connected components: each edge `(a, b)` in the
    /// direction the mesh's triangles traverse it, once per unmatched use. An edge is a border edge
    /// when its triangles do not pair up in opposite directions (so a duplicated pair of faces or a
    /// non-manifold edge with balanced uses is not a hole). Components are sorted by their lowest
    /// vertex.
    pub fn holes(&self) -> Vec<Vec<(u32, u32)>> {
        let mut border = Vec::new();
        for ((a, b), count, forward) in self.edge_uses() {
            let backward = count - forward;
            for _ in backward..forward {
                border.push((a, b));
            }
            for _ in forward..backward {
                border.push((b, a));
            }
        }
        // Union-find over the border vertices.
        let mut parent: BTreeMap<u32, u32> = BTreeMap::new();
        fn find(parent: &mut BTreeMap<u32, u32>, x: u32) -> u32 {
            let mut root = x;
            while let Some(&p) = parent.get(&root).filter(|&&p| p != root) {
                root = p;
            }
            let mut y = x;
            while y != root {
                let next = parent.get(&y).copied().unwrap_or(root);
                parent.insert(y, root);
                y = next;
            }
            root
        }
        for &(a, b) in &border {
            parent.entry(a).or_insert(a);
            parent.entry(b).or_insert(b);
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra != rb {
                parent.insert(ra.max(rb), ra.min(rb));
            }
        }
        let mut groups: BTreeMap<u32, Vec<(u32, u32)>> = BTreeMap::new();
        for &(a, b) in &border {
            let root = find(&mut parent, a);
            groups.entry(root).or_default().push((a, b));
        }
        groups.into_values().collect()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| self.triangle_normal(t).norm() * 0.5).sum()
    }

    fn triangle_normal(&self, t: &[u32; 3]) -> Vector3<f64> {
        let [a, b, c] = t.map(|i| self.vertices[i as usize]);
        (b - a).cross(&(c - a))
    }

    /// Undirected edges with their triangle counts and how many of those traverse the edge from its
    /// lower to its higher vertex index, sorted by edge.
    fn edge_uses(&self) -> Vec<((u32, u32), u32, u32)> {
        let mut edges: Vec<(u32, u32, bool)> = Vec::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                edges.push((a.min(b), a.max(b), a < b));
            }
        }
        edges.sort_unstable();
        let mut out: Vec<((u32, u32), u32, u32)> = Vec::new();
        for (a, b, forward) in edges {
            match out.last_mut() {
                Some((key, count, fwd)) if *key == (a, b) => {
                    *count += 1;
                    *fwd += u32::from(forward);
                }
                _ => out.push(((a, b), 1, u32::from(forward))),
            }
        }
        out
    }

    /// Number of edges not shared by exactly two triangles (border edges of holes, and non-manifold
    /// edges).
    pub fn open_edges(&self) -> usize {
        self.edge_uses().iter().filter(|(_, n, _)| *n != 2).count()
    }

    /// Whether every edge is shared by exactly two triangles.
    pub fn is_closed(&self) -> bool {
        self.open_edges() == 0
    }

    /// Number of edges shared by two triangles that traverse it in the same direction: 0 for a
    /// consistently oriented mesh.
    pub fn orientation_conflicts(&self) -> usize {
        self.edge_uses().iter().filter(|(_, n, fwd)| *n == 2 && *fwd != 1).count()
    }

    /// Whether every edge is used exactly twice, once in each direction, and no triangle repeats a
    /// vertex: closed and consistently oriented. Stricter than [`TriMesh::is_closed`]; an empty mesh
    /// is not closed.
    pub fn is_closed_oriented(&self) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let mut directed: BTreeMap<(u32, u32), u32> = BTreeMap::new();
        for t in &self.triangles {
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                return false;
            }
            for k in 0..3 {
                let count = directed.entry((t[k], t[(k + 1) % 3])).or_insert(0);
                *count += 1;
                if *count > 1 {
                    return false;
                }
            }
        }
        directed.keys().all(|&(a, b)| directed.contains_key(&(b, a)))
    }

    /// Checks that every vertex is finite and every triangle index refers to a vertex; the message
    /// names the first offending vertex or triangle.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(i) = self.vertices.iter().position(|v| !v.coords.iter().all(|c| c.is_finite())) {
            return Err(format!("vertex {i} is not finite"));
        }
        let n = self.vertices.len();
        if let Some(i) = self.triangles.iter().position(|t| t.iter().any(|&v| v as usize >= n)) {
            return Err(format!("triangle {i} refers to a vertex beyond the {n} vertices"));
        }
        Ok(())
    }

    /// Appends another mesh (a union of meshes, overlaps allowed).
    pub fn append(&mut self, other: &TriMesh) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles.extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
    }

    /// The mesh moved by a rigid transform.
    pub fn transformed(&self, iso: &Isometry3<f64>) -> TriMesh {
        TriMesh { vertices: self.vertices.iter().map(|p| iso * p).collect(), triangles: self.triangles.clone() }
    }
}
