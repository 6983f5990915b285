//! Accuracy of a hull against ground truth: volumetric IoU (Monte Carlo over the union of the two
//! bounding boxes, inside-ness of the truth by generalized winding number, so unions of
//! overlapping closed parts count once), and Chamfer and Hausdorff distances between surfaces
//! (dense surface samples, nearest neighbours through a uniform hash grid).

use std::collections::HashMap;

use hullcut_dataset::Mesh;
use nalgebra::Point3;
use rayon::prelude::*;

use crate::DenseGrid;

/// Generalized winding number of a closed (or nearly closed) mesh at `p`: 1 inside, 0 outside,
/// n inside n overlapping parts.
pub fn winding_number(mesh: &Mesh, p: &Point3<f64>) -> f64 {
    let mut sum = 0.0;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize] - p);
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let det = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
        sum += 2.0 * det.atan2(den);
    }
    sum / (4.0 * std::f64::consts::PI)
}

/// A closed mesh prepared for inside tests: the integer winding number of a point is the signed
/// count of the mesh's triangles that a vertical ray from the point upward crosses (+1 where it
/// leaves through a triangle facing up, −1 where it enters through one facing down), so that
/// overlapping closed parts count once each. Triangles are binned on a grid over the mesh's xy
/// extent, so a test costs the few triangles above the point's cell instead of all of them (the
/// generalized winding number, [`winding_number`], sums over every triangle).
#[derive(Debug)]
pub struct Solid<'a> {
    mesh: &'a Mesh,
    lo: [f64; 2],
    cell: [f64; 2],
    dims: [usize; 2],
    /// Triangles of bin k: `ids[start[k]..start[k + 1]]`.
    start: Vec<u32>,
    ids: Vec<u32>,
}

impl<'a> Solid<'a> {
    /// Bins the mesh's triangles (about four per bin, at most 256 bins a side).
    pub fn new(mesh: &'a Mesh) -> Self {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for v in &mesh.vertices {
            for a in 0..2 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        let side = ((mesh.triangles.len() as f64 / 4.0).sqrt().ceil() as usize).clamp(1, 256);
        let dims = [side, side];
        let cell = [0, 1].map(|a| ((hi[a] - lo[a]) / side as f64).max(1e-12));
        let bin = |x: f64, a: usize| (((x - lo[a]) / cell[a]).floor().max(0.0) as usize).min(dims[a] - 1);
        let mut counts = vec![0u32; dims[0] * dims[1] + 1];
        let spans: Vec<[usize; 4]> = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                let (x0, x1) = (a.x.min(b.x).min(c.x), a.x.max(b.x).max(c.x));
                let (y0, y1) = (a.y.min(b.y).min(c.y), a.y.max(b.y).max(c.y));
                [bin(x0, 0), bin(x1, 0), bin(y0, 1), bin(y1, 1)]
            })
            .collect();
        for s in &spans {
            for j in s[2]..=s[3] {
                for i in s[0]..=s[1] {
                    counts[j * dims[0] + i + 1] += 1;
                }
            }
        }
        for k in 1..counts.len() {
            counts[k] += counts[k - 1];
        }
        let mut fill = counts.clone();
        let mut ids = vec![0u32; counts[counts.len() - 1] as usize];
        for (t, s) in spans.iter().enumerate() {
            for j in s[2]..=s[3] {
                for i in s[0]..=s[1] {
                    let k = j * dims[0] + i;
                    ids[fill[k] as usize] = t as u32;
                    fill[k] += 1;
                }
            }
        }
        Solid { mesh, lo, cell, dims, start: counts, ids }
    }

    /// The integer winding number at `p`: 1 inside one part, n inside n overlapping parts, 0
    /// outside (undefined on the surface itself).
    pub fn winding(&self, p: &Point3<f64>) -> i32 {
        let (fi, fj) = ((p.x - self.lo[0]) / self.cell[0], (p.y - self.lo[1]) / self.cell[1]);
        if !(fi >= 0.0 && fj >= 0.0 && fi < self.dims[0] as f64 && fj < self.dims[1] as f64) {
            return 0;
        }
        let k = fj as usize * self.dims[0] + fi as usize;
        let mut w = 0;
        for &t in &self.ids[self.start[k] as usize..self.start[k + 1] as usize] {
            let [a, b, c] = self.mesh.triangles[t as usize].map(|i| self.mesh.vertices[i as usize]);
            let edge = |u: &Point3<f64>, v: &Point3<f64>| (v.x - u.x) * (p.y - u.y) - (v.y - u.y) * (p.x - u.x);
            let (e0, e1, e2) = (edge(&a, &b), edge(&b, &c), edge(&c, &a));
            let area = e0 + e1 + e2;
            if area == 0.0 || !(e0 * area > 0.0 && e1 * area > 0.0 && e2 * area > 0.0) {
                continue;
            }
            // Height of the triangle's plane above (x, y), from the barycentric weights.
            let z = (e1 * a.z + e2 * b.z + e0 * c.z) / area;
            if z > p.z {
                // area > 0: counter-clockwise seen from above, so the triangle faces up.
                w += if area > 0.0 { 1 } else { -1 };
            }
        }
        w
    }
}

fn bounds(points: impl Iterator<Item = Point3<f64>>) -> Option<(Point3<f64>, Point3<f64>)> {
    points.fold(None, |acc, p| match acc {
        None => Some((p, p)),
        Some((lo, hi)) => Some((lo.inf(&p), hi.sup(&p))),
    })
}

/// A deterministic uniform number in [0, 1) from a counter.
fn unit(k: u64) -> f64 {
    let mut z = k.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Volumetric IoU between a hull (on its leaf grid) and the solid a truth mesh bounds, from
/// `samples` points spread uniformly over the union of their bounding boxes (deterministic).
/// None when both are empty, or when a bound is not finite (a truth vertex at infinity: nothing
/// can be measured).
pub fn volumetric_iou(hull: Option<&DenseGrid>, truth: &Mesh, samples: usize) -> Option<f64> {
    let truth_box = bounds(truth.vertices.iter().copied());
    let hull_box = hull.and_then(|g| g.bounds());
    let (lo, hi) = match (truth_box, hull_box) {
        (Some(a), Some(b)) => (a.0.inf(&b.0), a.1.sup(&b.1)),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => return None,
    };
    if !(lo.coords.iter().chain(hi.coords.iter()).all(|c| c.is_finite())) {
        return None;
    }
    let solid = Solid::new(truth);
    let (both, either) = (0..samples as u64)
        .into_par_iter()
        .map(|k| {
            let p = Point3::new(
                lo.x + (hi.x - lo.x) * unit(3 * k),
                lo.y + (hi.y - lo.y) * unit(3 * k + 1),
                lo.z + (hi.z - lo.z) * unit(3 * k + 2),
            );
            let in_hull = hull.is_some_and(|g| g.contains(&p));
            let in_truth = solid.winding(&p) >= 1;
            (u64::from(in_hull && in_truth), u64::from(in_hull || in_truth))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    (either > 0).then(|| both as f64 / either as f64)
}

/// Most points [`sample_surface`] and [`outer_surface_samples`] give: a larger surface (or a finer
/// spacing) is sampled more coarsely, so that a mesh spanning the whole working volume, or one
/// with a vertex far away, costs a bounded time and memory.
pub const MAX_SURFACE_SAMPLES: usize = 1 << 20;

/// Points on a mesh's surface about `spacing` apart (at least one per triangle's area share),
/// deterministic; at most about [`MAX_SURFACE_SAMPLES`] (the spacing widened to stay under it).
/// No points at all when the surface's area or the spacing is not a finite positive number.
pub fn sample_surface(mesh: &Mesh, spacing: f64) -> Vec<Point3<f64>> {
    sample_surface_with_triangles(mesh, spacing).into_iter().map(|(p, _)| p).collect()
}

/// [`sample_surface`] with the triangle each point lies on.
fn sample_surface_with_triangles(mesh: &Mesh, spacing: f64) -> Vec<(Point3<f64>, usize)> {
    let area_of = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        (b - a).cross(&(c - a)).norm() / 2.0
    };
    let total: f64 = mesh.triangles.iter().map(area_of).sum();
    if !(total.is_finite() && spacing > 0.0 && spacing.is_finite()) {
        return Vec::new();
    }
    let spacing = spacing.max((total / MAX_SURFACE_SAMPLES as f64).sqrt());
    let mut out = Vec::new();
    let mut counter = 0u64;
    let mut carry = 0.0;
    for (k, t) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        carry += area_of(t) / (spacing * spacing);
        while carry >= 1.0 {
            carry -= 1.0;
            let (mut r1, mut r2) = (unit(counter), unit(counter + 1));
            counter += 2;
            if r1 + r2 > 1.0 {
                (r1, r2) = (1.0 - r1, 1.0 - r2);
            }
            out.push((a + (b - a) * r1 + (c - a) * r2, k));
        }
    }
    out
}

/// Distances between two point sets standing for surfaces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceDistance {
    /// Mean of the two directed mean nearest-neighbour distances, metres.
    pub chamfer: f64,
    /// Largest nearest-neighbour distance in either direction, metres.
    pub hausdorff: f64,
}

struct HashGrid<'a> {
    cell: f64,
    map: HashMap<[i64; 3], Vec<usize>>,
    points: &'a [Point3<f64>],
}

impl<'a> HashGrid<'a> {
    fn new(points: &'a [Point3<f64>], cell: f64) -> Self {
        let mut map: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            map.entry(Self::key(p, cell)).or_default().push(i);
        }
        HashGrid { cell, map, points }
    }

    fn key(p: &Point3<f64>, cell: f64) -> [i64; 3] {
        [p.x, p.y, p.z].map(|x| (x / cell).floor() as i64)
    }

    /// Nearest distance, searching shells of cells outward until no closer point can exist. Once
    /// the cells searched outnumber the points, the rest is a scan of every point (exact, and no
    /// dearer than what was searched): a far point costs at most twice a scan, never a search
    /// through millions of empty cells.
    fn nearest(&self, p: &Point3<f64>) -> f64 {
        let k = Self::key(p, self.cell);
        let budget = self.points.len() as u64;
        let mut searched = 0u64;
        let mut best = f64::INFINITY;
        let mut r = 0i64;
        loop {
            for dz in -r..=r {
                for dy in -r..=r {
                    // Off the shell's faces in z and y, only its two x faces are on it (r >= 1 there).
                    let step = if dz.abs() == r || dy.abs() == r { 1 } else { 2 * r as usize };
                    for dx in (-r..=r).step_by(step) {
                        searched += 1;
                        let cell = [k[0].wrapping_add(dx), k[1].wrapping_add(dy), k[2].wrapping_add(dz)];
                        if let Some(ids) = self.map.get(&cell) {
                            for &i in ids {
                                best = best.min((self.points[i] - p).norm());
                            }
                        }
                    }
                }
            }
            if best <= r as f64 * self.cell {
                return best;
            }
            if searched > budget {
                return self.points.iter().map(|q| (q - p).norm()).fold(best, f64::min);
            }
            r += 1;
        }
    }
}

/// Chamfer and Hausdorff distances between two sampled surfaces; None if either is empty, if a
/// point is not finite or if `cell` (the hash grid's, metres) is not a positive length: nothing
/// is measured then. Every nearest-point query is bounded (see `HashGrid::nearest`), however far
/// apart the two surfaces lie.
pub fn surface_distance(a: &[Point3<f64>], b: &[Point3<f64>], cell: f64) -> Option<SurfaceDistance> {
    let finite = |s: &[Point3<f64>]| s.iter().all(|p| p.coords.iter().all(|c| c.is_finite()));
    if a.is_empty() || b.is_empty() || !(cell > 0.0 && cell.is_finite()) || !finite(a) || !finite(b) {
        return None;
    }
    let directed = |from: &[Point3<f64>], to: &[Point3<f64>]| {
        let grid = HashGrid::new(to, cell);
        let d: Vec<f64> = from.par_iter().map(|p| grid.nearest(p)).collect();
        (d.iter().sum::<f64>() / d.len() as f64, d.iter().copied().fold(0.0, f64::max))
    };
    let (ab, ab_max) = directed(a, b);
    let (ba, ba_max) = directed(b, a);
    Some(SurfaceDistance { chamfer: (ab + ba) / 2.0, hausdorff: ab_max.max(ba_max) })
}

/// Surface samples of a truth mesh made of overlapping closed parts, keeping only points on the
/// outer surface: moved a micrometre off their triangle, outward, a point on the outer surface
/// lies inside no part (a point of one part's surface that lies inside another does).
pub fn outer_surface_samples(truth: &Mesh, spacing: f64) -> Vec<Point3<f64>> {
    let solid = Solid::new(truth);
    sample_surface_with_triangles(truth, spacing)
        .into_par_iter()
        .filter(|(p, k)| {
            let [a, b, c] = truth.triangles[*k].map(|i| truth.vertices[i as usize]);
            let n = (b - a).cross(&(c - a)).try_normalize(1e-30).unwrap_or_default();
            solid.winding(&(p + n * 1e-6)) < 1
        })
        .map(|(p, _)| p)
        .collect()
}

/// IoU of two leaf grids, from a regular lattice of about `samples` points over their joint
/// bounding box. None when both are empty.
pub fn grid_iou(a: &DenseGrid, b: &DenseGrid, samples: usize) -> Option<f64> {
    let (lo, hi) = match (a.bounds(), b.bounds()) {
        (Some(x), Some(y)) => (x.0.inf(&y.0), x.1.sup(&y.1)),
        (Some(x), None) | (None, Some(x)) => x,
        (None, None) => return None,
    };
    let n = (samples as f64).cbrt().ceil() as usize;
    let f = |x: usize, axis: usize| lo[axis] + (hi[axis] - lo[axis]) * (x as f64 + 0.5) / n as f64;
    let (both, either) = (0..n * n * n)
        .into_par_iter()
        .map(|k| {
            let p = Point3::new(f(k % n, 0), f((k / n) % n, 1), f(k / (n * n), 2));
            let (x, y) = (a.contains(&p), b.contains(&p));
            (u64::from(x && y), u64::from(x || y))
        })
        .reduce(|| (0, 0), |s, t| (s.0 + t.0, s.1 + t.1));
    (either > 0).then(|| both as f64 / either as f64)
}

/// IoU of two carvings of the same cube at the same leaf size (same `origin` and `resolution`),
/// counted exactly leaf by leaf: the kept cells carrying the label (every kept cell for `None`),
/// larger cells as the leaves they cover. None when the grids differ or both are empty.
pub fn occupancy_iou(a: &crate::Occupancy, b: &crate::Occupancy, l: Option<u8>) -> Option<f64> {
    if a.resolution != b.resolution || a.origin != b.origin || a.leaf_size != b.leaf_size {
        return None;
    }
    let n = a.resolution;
    let leaves = |occ: &crate::Occupancy| {
        let mut bits = vec![0u64; (n * n * n).div_ceil(64)];
        for c in occ.cells.iter().filter(|c| l.is_none_or(|l| c.has(l))) {
            let lo = [0, 1, 2].map(|k| ((c.min[k] - occ.origin[k]) / occ.leaf_size).round() as usize);
            let span = (c.size / occ.leaf_size).round() as usize;
            for z in lo[2]..(lo[2] + span).min(n) {
                for y in lo[1]..(lo[1] + span).min(n) {
                    for x in lo[0]..(lo[0] + span).min(n) {
                        let i = x + n * (y + n * z);
                        bits[i / 64] |= 1 << (i % 64);
                    }
                }
            }
        }
        bits
    };
    let (x, y) = (leaves(a), leaves(b));
    let (both, either) = x.iter().zip(&y).fold((0u64, 0u64), |(i, u), (p, q)| {
        (i + u64::from((p & q).count_ones()), u + u64::from((p | q).count_ones()))
    });
    (either > 0).then(|| both as f64 / either as f64)
}

/// Silhouette consistency of one view: the hull's kept leaves re-projected into the camera
/// (each leaf as the pixel box around its eight projected corners) against the observed mask's
/// foreground, as an IoU over pixels. None when both are empty or the view is missing.
pub fn silhouette_consistency(occ: &crate::Occupancy, view: &crate::Silhouette) -> Option<f64> {
    let cam = view.camera();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut covered = vec![false; w * h];
    for cell in &occ.cells {
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        let mut ok = true;
        for k in 0..8 {
            let offset = nalgebra::Vector3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64);
            let pr = cam.project(&(cell.min + offset * cell.size));
            if pr.depth <= 0.0 || !pr.pixel.x.is_finite() {
                ok = false;
                break;
            }
            u0 = u0.min(pr.pixel.x);
            v0 = v0.min(pr.pixel.y);
            u1 = u1.max(pr.pixel.x);
            v1 = v1.max(pr.pixel.y);
        }
        if !ok {
            continue;
        }
        let (i0, j0) = (u0.ceil().max(0.0) as usize, v0.ceil().max(0.0) as usize);
        let (i1, j1) = (u1.floor().min(w as f64 - 1.0), v1.floor().min(h as f64 - 1.0));
        if i1 < 0.0 || j1 < 0.0 {
            continue;
        }
        for j in j0..=j1 as usize {
            for i in i0..=i1 as usize {
                covered[j * w + i] = true;
            }
        }
    }
    let (mut both, mut either) = (0u64, 0u64);
    for j in 0..h {
        for i in 0..w {
            let fg = view.counts(i, j, i, j).foreground() > 0;
            let c = covered[j * w + i];
            both += u64::from(fg && c);
            either += u64::from(fg || c);
        }
    }
    (either > 0).then(|| both as f64 / either as f64)
}
