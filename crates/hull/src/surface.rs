//! Surfaces of the carved hull: the kept cells of one label rasterized onto the leaf grid (over
//! their bounding box only), then surface nets: one vertex per grid cube that straddles the
//! boundary, at the mean of its crossing edges' midpoints, and one quad per boundary edge, wound so
//! that normals point out. The mesh is closed (each boundary edge of the occupancy gives exactly
//! one quad and every quad edge is shared) and consistently oriented.

use hullcut_dataset::Mesh;
use nalgebra::{Point3, Vector3};

use crate::Occupancy;

/// Whether every directed edge of a mesh is matched by as many opposite ones: the mesh is
/// watertight and consistently oriented. Surface nets of voxels that touch only along an edge give
/// edges with four triangles (non-manifold but still closed); this check accepts them, where a
/// strict two-triangles-per-edge check would not.
pub fn is_watertight(mesh: &Mesh) -> bool {
    let mut edges: std::collections::HashMap<(u32, u32), i64> = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a == b {
                return false;
            }
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += if a < b { 1 } else { -1 };
        }
    }
    edges.values().all(|&v| v == 0)
}

/// Occupancy of one label on the leaf grid, over a padded bounding box.
#[derive(Debug, Clone)]
pub struct DenseGrid {
    /// World position of sample (0, 0, 0): the centre of that leaf.
    pub origin: Point3<f64>,
    /// Leaf size, metres.
    pub leaf: f64,
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Occupied samples, x fastest.
    pub occupied: Vec<bool>,
}

impl DenseGrid {
    /// Rasterizes the cells carrying `l` (every kept cell for `None`), with one empty sample of
    /// padding on every side.
    pub fn from_occupancy(occ: &Occupancy, l: Option<u8>) -> Option<DenseGrid> {
        let cells: Vec<_> = occ.cells.iter().filter(|c| l.is_none_or(|l| c.has(l))).collect();
        if cells.is_empty() {
            return None;
        }
        let leaf = occ.leaf_size;
        let index = |x: f64, a: usize| ((x - occ.origin[a]) / leaf).round() as i64;
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        for c in &cells {
            for a in 0..3 {
                lo[a] = lo[a].min(index(c.min[a], a));
                hi[a] = hi[a].max(index(c.min[a] + c.size, a));
            }
        }
        let dims = [0, 1, 2].map(|a| (hi[a] - lo[a]) as usize + 2);
        let mut occupied = vec![false; dims[0] * dims[1] * dims[2]];
        for c in &cells {
            let start = [0, 1, 2].map(|a| (index(c.min[a], a) - lo[a] + 1) as usize);
            let n = (c.size / leaf).round() as usize;
            for z in start[2]..start[2] + n {
                for y in start[1]..start[1] + n {
                    let row = (z * dims[1] + y) * dims[0];
                    occupied[row + start[0]..row + start[0] + n].fill(true);
                }
            }
        }
        let origin = occ.origin + Vector3::new(lo[0] as f64 - 0.5, lo[1] as f64 - 0.5, lo[2] as f64 - 0.5) * leaf;
        Some(DenseGrid { origin, leaf, dims, occupied })
    }

    /// Whether a world point falls in an occupied leaf.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        let idx = [0, 1, 2].map(|a| ((p[a] - self.origin[a]) / self.leaf).round());
        if idx.iter().zip(self.dims).any(|(&x, n)| x < 0.0 || x >= n as f64) {
            return false;
        }
        self.at(idx[0] as usize, idx[1] as usize, idx[2] as usize)
    }

    /// The box the occupied leaves span (their outer faces), if any.
    pub fn bounds(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let [nx, ny, _] = self.dims;
        let mut out: Option<(Point3<f64>, Point3<f64>)> = None;
        for (n, &o) in self.occupied.iter().enumerate() {
            if !o {
                continue;
            }
            let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
            let c = self.origin + Vector3::new(i as f64, j as f64, k as f64) * self.leaf;
            let (lo, hi) = (c - Vector3::repeat(self.leaf / 2.0), c + Vector3::repeat(self.leaf / 2.0));
            out = Some(match out {
                None => (lo, hi),
                Some((a, b)) => (a.inf(&lo), b.sup(&hi)),
            });
        }
        out
    }

    fn at(&self, i: usize, j: usize, k: usize) -> bool {
        self.occupied[(k * self.dims[1] + j) * self.dims[0] + i]
    }

    /// Occupied samples.
    pub fn count(&self) -> usize {
        self.occupied.iter().filter(|&&o| o).count()
    }

    /// The closed boundary surface (surface nets), world metres.
    pub fn surface(&self) -> Mesh {
        let [nx, ny, nz] = self.dims;
        // Dual cubes span samples (i..=i+1, j..=j+1, k..=k+1).
        let (cx, cy) = (nx - 1, ny - 1);
        let mut vertex_of = vec![u32::MAX; cx * cy * (nz - 1)];
        let mut mesh = Mesh::default();
        for k in 0..nz - 1 {
            for j in 0..ny - 1 {
                for i in 0..nx - 1 {
                    let mut inside = 0;
                    let mut sum = Vector3::zeros();
                    let mut crossings = 0;
                    let corner = |c: usize| (i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                    for c in 0..8 {
                        let (a, b, d) = corner(c);
                        inside += usize::from(self.at(a, b, d));
                    }
                    if inside == 0 || inside == 8 {
                        continue;
                    }
                    for c in 0..8 {
                        for axis in 0..3 {
                            if c & (1 << axis) != 0 {
                                continue;
                            }
                            let (p, q) = (corner(c), corner(c | (1 << axis)));
                            if self.at(p.0, p.1, p.2) != self.at(q.0, q.1, q.2) {
                                sum += Vector3::new(
                                    (p.0 + q.0) as f64 / 2.0,
                                    (p.1 + q.1) as f64 / 2.0,
                                    (p.2 + q.2) as f64 / 2.0,
                                );
                                crossings += 1;
                            }
                        }
                    }
                    vertex_of[(k * cy + j) * cx + i] = mesh.vertices.len() as u32;
                    mesh.vertices.push(self.origin + sum / crossings as f64 * self.leaf);
                }
            }
        }
        let v = |i: usize, j: usize, k: usize| vertex_of[(k * cy + j) * cx + i];
        let mut quad = |q: [u32; 4], flip: bool| {
            let [a, b, c, d] = if flip { [q[0], q[3], q[2], q[1]] } else { q };
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([a, c, d]);
        };
        // Sample edges along each axis. The padding keeps the border samples empty, so an edge
        // with a sign change always has its four dual cubes.
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let here = self.at(i, j, k);
                    if i + 1 < nx && j > 0 && k > 0 && here != self.at(i + 1, j, k) {
                        quad([v(i, j - 1, k - 1), v(i, j, k - 1), v(i, j, k), v(i, j - 1, k)], !here);
                    }
                    if j + 1 < ny && i > 0 && k > 0 && here != self.at(i, j + 1, k) {
                        quad([v(i - 1, j, k - 1), v(i - 1, j, k), v(i, j, k), v(i, j, k - 1)], !here);
                    }
                    if k + 1 < nz && i > 0 && j > 0 && here != self.at(i, j, k + 1) {
                        quad([v(i - 1, j - 1, k), v(i, j - 1, k), v(i, j, k), v(i - 1, j, k)], !here);
                    }
                }
            }
        }
        mesh
    }
}
