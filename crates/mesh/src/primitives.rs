//! Closed meshes built from primitives: boxes, solids of revolution (capsules, ellipsoids) and
//! prisms over convex outlines. Every builder returns a closed mesh with triangles
//! counter-clockwise seen from outside.

use nalgebra::{Isometry3, Point2, Point3, Rotation3, Vector3};

use crate::TriMesh;

impl TriMesh {
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
}
