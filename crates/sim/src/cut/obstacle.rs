//! Rigid obstacles the tissue cannot enter: the reconstructed hand pressing on the organ.
//!
//! An obstacle is a voxel occupancy (the visual hull of one label, in world metres). For every
//! occupied voxel the way out is precomputed: the offset to the nearest free voxel, found by a
//! breadth-first sweep from the obstacle's boundary that carries each voxel's nearest boundary
//! voxel along (exact to within a voxel). A lattice node found inside is moved along it toward
//! the free voxel's centre (by at most a twentieth of a lattice cell per time step, see
//! [`crate::CutSim`]) and its velocity is set to zero: inelastic contact without friction
//! modelled, applied after every time step, so the tissue is pushed aside and never passes
//! through. Resolution is the obstacle's voxel: pressed against it, nodes rest within its
//! boundary voxels.

use std::collections::VecDeque;

use nalgebra::{Point3, Vector3};

/// A rigid obstacle sampled on a regular grid.
#[derive(Debug, Clone)]
pub struct Obstacle {
    origin: Point3<f64>,
    h: f64,
    dims: [usize; 3],
    /// For each sample: the offset that takes a point in it out of the obstacle (zero outside).
    push: Vec<Vector3<f32>>,
    occupied: Vec<bool>,
}

impl Obstacle {
    /// An obstacle from occupied samples: sample (i, j, k) is the voxel centred at
    /// `origin + h (i, j, k)`; `occupied` runs x fastest. `None` when the sizes disagree, `h` is not
    /// positive or nothing is occupied.
    pub fn from_occupancy(origin: Point3<f64>, h: f64, dims: [usize; 3], occupied: &[bool]) -> Option<Self> {
        let n = dims[0] * dims[1] * dims[2];
        if occupied.len() != n || h.is_nan() || h <= 0.0 || !occupied.iter().any(|&o| o) {
            return None;
        }
        let index = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        let ijk = |g: usize| [g % dims[0], (g / dims[0]) % dims[1], g / (dims[0] * dims[1])];
        // Breadth-first from the free samples next to the obstacle, each occupied sample taking
        // the nearest free sample of the neighbour that reached it first.
        let mut nearest: Vec<Option<usize>> = vec![None; n];
        let mut queue = VecDeque::new();
        let neighbours = |g: usize| {
            let [i, j, k] = ijk(g);
            let mut out = [None; 6];
            let steps = [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)];
            for (slot, (axis, d)) in out.iter_mut().zip(steps) {
                let mut c = [i as i64, j as i64, k as i64];
                c[axis] += d;
                if (0..3).all(|a| c[a] >= 0 && (c[a] as usize) < dims[a]) {
                    *slot = Some(index(c[0] as usize, c[1] as usize, c[2] as usize));
                }
            }
            out
        };
        for g in (0..n).filter(|&g| occupied[g]) {
            for m in neighbours(g).into_iter().flatten() {
                if !occupied[m] && nearest[g].is_none() {
                    nearest[g] = Some(m);
                    queue.push_back(g);
                }
            }
            // A sample on the grid's edge leaves through the edge.
            if nearest[g].is_none() && neighbours(g).iter().any(Option::is_none) {
                nearest[g] = Some(g);
                queue.push_back(g);
            }
        }
        let centre = |g: usize| {
            let [i, j, k] = ijk(g);
            origin + Vector3::new(i as f64, j as f64, k as f64) * h
        };
        while let Some(g) = queue.pop_front() {
            let Some(free) = nearest[g] else { continue };
            for m in neighbours(g).into_iter().flatten() {
                if !occupied[m] {
                    continue;
                }
                let better = match nearest[m] {
                    None => true,
                    Some(f) => {
                        (centre(free) - centre(m)).norm_squared() < (centre(f) - centre(m)).norm_squared() - 1e-18
                    }
                };
                if better {
                    nearest[m] = Some(free);
                    queue.push_back(m);
                }
            }
        }
        let push = (0..n)
            .map(|g| match (occupied[g], nearest[g]) {
                (true, Some(free)) => {
                    // To the free sample's centre: half a voxel past the surface between them.
                    let d = centre(free) - centre(g);
                    let d = if d.norm() > 0.0 { d } else { Vector3::z() * h };
                    d.cast::<f32>()
                }
                _ => Vector3::zeros(),
            })
            .collect();
        Some(Obstacle { origin, h, dims, push, occupied: occupied.to_vec() })
    }

    /// The grid as the GPU's contact pass takes it.
    #[cfg(feature = "gpu")]
    pub(crate) fn push_grid(&self) -> crate::gpu::PushGrid {
        crate::gpu::PushGrid {
            origin: self.origin.coords.cast::<f32>().into(),
            h: self.h as f32,
            dims: self.dims.map(|d| d as u32),
            voxels: self
                .push
                .iter()
                .zip(&self.occupied)
                .map(|(v, &o)| [v.x, v.y, v.z, if o { 1.0 } else { 0.0 }])
                .collect(),
        }
    }

    /// The offset that takes `p` out of the obstacle, or `None` when `p` is outside.
    pub fn push_at(&self, p: &Point3<f32>) -> Option<Vector3<f32>> {
        let q = (p.cast::<f64>() - self.origin) / self.h;
        let mut g = 0;
        let mut stride = 1;
        for a in 0..3 {
            let i = q[a].round();
            if !(i >= 0.0 && (i as usize) < self.dims[a]) {
                return None;
            }
            g += i as usize * stride;
            stride *= self.dims[a];
        }
        self.occupied[g].then(|| self.push[g])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_inside_leave_by_the_nearest_face_and_points_outside_stay() {
        // A 10 x 10 x 4 slab of 1 cm voxels inside a 12 x 12 x 6 grid.
        let dims = [12, 12, 6];
        let occupied: Vec<bool> = (0..12 * 12 * 6)
            .map(|g| {
                let (i, j, k) = (g % 12, (g / 12) % 12, g / 144);
                (1..11).contains(&i) && (1..11).contains(&j) && (1..5).contains(&k)
            })
            .collect();
        let o = Obstacle::from_occupancy(Point3::origin(), 0.01, dims, &occupied).expect("an obstacle");
        // Just under the top face (k = 4 is the top layer): pushed up one voxel, out of it.
        let p = Point3::new(0.055f32, 0.055, 0.04);
        let push = o.push_at(&p).expect("inside");
        assert!((push - Vector3::new(0.0, 0.0, 0.01)).norm() < 1e-6, "{push}");
        assert!(o.push_at(&(p + push)).is_none(), "out after the push");
        // Near the x- side: out through it.
        let push = o.push_at(&Point3::new(0.012, 0.055, 0.025)).expect("inside");
        assert!((push - Vector3::new(-0.01, 0.0, 0.0)).norm() < 1e-6, "{push}");
        // Deep in the middle of the slab: out through the nearest face (z, 2 voxels), not x or y.
        let push = o.push_at(&Point3::new(0.055, 0.055, 0.02)).expect("inside");
        assert!(push.x.abs() < 1e-6 && push.y.abs() < 1e-6 && push.z.abs() >= 0.02 - 1e-6, "{push}");
        assert!(o.push_at(&Point3::new(0.2, 0.0, 0.0)).is_none());
        assert!(o.push_at(&Point3::new(0.055, 0.055, 0.055)).is_none());
        assert!(Obstacle::from_occupancy(Point3::origin(), 0.01, dims, &vec![false; 12 * 12 * 6]).is_none());
    }
}
