//! Closed triangle meshes built from primitives: cuboids, solids of revolution (capsules,
//! ellipsoids) and prisms over convex outlines. Every builder returns a closed mesh with triangles
//! counter-clockwise seen from outside.

use nalgebra::{Isometry3, Point2, Point3, Rotation3, Vector3};

/// A closed triangle mesh in double precision.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Appends another mesh (a union of closed meshes, overlaps allowed).
    pub fn append(&mut self, other: &TriMesh) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }

    /// The mesh moved by a rigid transform.
    pub fn transformed(&self, iso: &Isometry3<f64>) -> TriMesh {
        TriMesh { vertices: self.vertices.iter().map(|p| iso * p).collect(), triangles: self.triangles.clone() }
    }

    /// Enclosed volume (divergence theorem), cubic metres; positive for outward-oriented meshes.
    pub fn volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// An axis-aligned box between two corners.
    pub fn cuboid(min: Point3<f64>, max: Point3<f64>) -> TriMesh {
        let vertices = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        // Quads counter-clockwise from outside; corner index bits are (x, y, z).
        let quads: [[u32; 4]; 6] = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
        let triangles = quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
        TriMesh { vertices, triangles }
    }

    /// A solid of revolution about the z axis from a profile of `(z, radius)` pairs running from
    /// the top pole (radius 0) to the bottom pole (radius 0), with `segments` around.
    fn revolve(profile: &[(f64, f64)], segments: usize) -> TriMesh {
        let rings = &profile[1..profile.len() - 1];
        let mut vertices = vec![Point3::new(0.0, 0.0, profile[0].0)];
        for &(z, r) in rings {
            for j in 0..segments {
                let phi = std::f64::consts::TAU * j as f64 / segments as f64;
                vertices.push(Point3::new(r * phi.cos(), r * phi.sin(), z));
            }
        }
        let bottom = vertices.len() as u32;
        vertices.push(Point3::new(0.0, 0.0, profile[profile.len() - 1].0));
        let s = segments as u32;
        let ring = |i: usize, j: u32| 1 + i as u32 * s + j % s;
        let mut triangles = Vec::with_capacity(2 * segments * rings.len());
        for j in 0..s {
            triangles.push([0, ring(0, j), ring(0, j + 1)]);
        }
        for i in 0..rings.len() - 1 {
            for j in 0..s {
                triangles.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
                triangles.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
            }
        }
        let last = rings.len() - 1;
        for j in 0..s {
            triangles.push([bottom, ring(last, j + 1), ring(last, j)]);
        }
        TriMesh { vertices, triangles }
    }

    /// A capsule (cylinder with hemispherical caps) of radius `radius` around the segment `a`–`b`.
    pub fn capsule(a: Point3<f64>, b: Point3<f64>, radius: f64, segments: usize) -> TriMesh {
        let axis = b - a;
        let length = axis.norm();
        let cap_rings = (segments / 4).max(2);
        let mut profile = Vec::with_capacity(2 * cap_rings + 2);
        for k in 0..=cap_rings {
            let theta = std::f64::consts::FRAC_PI_2 * k as f64 / cap_rings as f64;
            profile.push((length + radius * theta.cos(), radius * theta.sin()));
        }
        for k in 0..=cap_rings {
            let theta = std::f64::consts::FRAC_PI_2 * (1.0 + k as f64 / cap_rings as f64);
            profile.push((radius * theta.cos(), radius * theta.sin().max(0.0)));
        }
        if let Some(last) = profile.last_mut() {
            last.1 = 0.0;
        }
        let local = Self::revolve(&profile, segments);
        let rotation = Rotation3::rotation_between(&Vector3::z(), &axis)
            .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
        let iso = Isometry3::from_parts(a.coords.into(), rotation.into());
        local.transformed(&iso)
    }

    /// An ellipsoid with semi-axes `radii` along the axes of `pose` (centre = pose translation).
    pub fn ellipsoid(pose: &Isometry3<f64>, radii: Vector3<f64>, segments: usize) -> TriMesh {
        let rings = (segments / 2).max(3);
        let profile: Vec<(f64, f64)> = (0..=rings)
            .map(|k| {
                let theta = std::f64::consts::PI * k as f64 / rings as f64;
                (theta.cos(), if k == 0 || k == rings { 0.0 } else { theta.sin() })
            })
            .collect();
        let mut mesh = Self::revolve(&profile, segments);
        for v in &mut mesh.vertices {
            *v = pose * Point3::new(v.x * radii.x, v.y * radii.y, v.z * radii.z);
        }
        mesh
    }

    /// A prism over a convex outline (counter-clockwise in the xy plane) between heights `z0 < z1`.
    pub fn convex_prism(outline: &[Point2<f64>], z0: f64, z1: f64) -> TriMesh {
        let n = outline.len() as u32;
        let mut vertices: Vec<Point3<f64>> = outline.iter().map(|p| Point3::new(p.x, p.y, z0)).collect();
        vertices.extend(outline.iter().map(|p| Point3::new(p.x, p.y, z1)));
        let mut triangles = Vec::with_capacity(4 * n as usize);
        for i in 1..n - 1 {
            triangles.push([0, i + 1, i]);
            triangles.push([n, n + i, n + i + 1]);
        }
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([i, j, n + j]);
            triangles.push([i, n + j, n + i]);
        }
        TriMesh { vertices, triangles }
    }

    /// True when every edge is used exactly twice, once in each direction (closed and consistently
    /// oriented).
    pub fn is_closed(&self) -> bool {
        let mut edges: std::collections::HashMap<(u32, u32), i32> = std::collections::HashMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a, b)).or_insert(0) += 1;
            }
        }
        edges.iter().all(|(&(a, b), &count)| count == 1 && edges.get(&(b, a)) == Some(&1))
    }

    /// The mesh in the dataset crate's type.
    pub fn to_dataset(&self) -> hullcut_dataset::Mesh {
        hullcut_dataset::Mesh { vertices: self.vertices.clone(), triangles: self.triangles.clone() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_closed_with_the_right_volume() {
        let cube = TriMesh::cuboid(Point3::new(0.0, 0.0, 0.0), Point3::new(0.1, 0.2, 0.3));
        assert!(cube.is_closed());
        assert!((cube.volume() - 0.006).abs() < 1e-15);

        let r = 0.01;
        let cap = TriMesh::capsule(Point3::new(0.1, 0.0, 0.0), Point3::new(0.1, 0.05, 0.02), r, 48);
        assert!(cap.is_closed());
        let exact = std::f64::consts::PI * r * r * (0.05f64.hypot(0.02) + 4.0 / 3.0 * r);
        assert!((cap.volume() - exact).abs() < 0.01 * exact, "{} vs {exact}", cap.volume());

        let radii = Vector3::new(0.03, 0.02, 0.01);
        let e = TriMesh::ellipsoid(&Isometry3::translation(0.0, 0.0, 0.5), radii, 64);
        assert!(e.is_closed());
        let exact = 4.0 / 3.0 * std::f64::consts::PI * radii.product();
        assert!((e.volume() - exact).abs() < 0.01 * exact);

        let tri = [Point2::new(0.0, 0.0), Point2::new(1.0, 0.0), Point2::new(0.0, 1.0)];
        let p = TriMesh::convex_prism(&tri, -0.5, 0.5);
        assert!(p.is_closed());
        assert!((p.volume() - 0.5).abs() < 1e-12);
    }
}
