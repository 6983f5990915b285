//! What the scalpel hull says before any fit: its connected components, its main axis and
//! extent, and the starting poses tried when there is no track to follow.

use std::collections::HashMap;

use hullcut_dataset::label;
use hullcut_hull::Occupancy;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::geometry::MAX_EIGEN_ITERATIONS;
use crate::template::Template;

/// Leaves expanded from the hull at most (a larger scalpel hull is not a scalpel).
const MAX_LEAVES: usize = 400_000;
/// Slots of the dense grid over the leaves' bounding box at most (leaves spread that thin are not
/// one tool either).
const MAX_GRID_SLOTS: usize = 1 << 26;
/// Roll angles tried about the hull's axis when starting from nothing.
const ROLLS: usize = 12;

/// The scalpel hull, summarized.
#[derive(Debug, Clone)]
pub(crate) struct HullSummary {
    /// Leaves in the largest connected component.
    pub leaves: usize,
    /// Connected components (26-connected leaves).
    pub components: usize,
    /// Leaves of the second-largest component over those of the largest (0 with one component).
    pub second_fraction: f64,
    /// Centroid of the largest component.
    pub centroid: Point3<f64>,
    /// Its principal axis (unit, sign arbitrary).
    pub axis: Vector3<f64>,
    /// Its extent along the axis, relative to the centroid: (lowest, highest), metres.
    pub span: (f64, f64),
    /// Centroid of the hand cells within the tool's reach, if any: the hand holds the handle, so
    /// the blade points away from it.
    pub hand_centroid: Option<Point3<f64>>,
    /// Bounding box (corners) of the scalpel's leaves (the components taken as the tool), for
    /// the views' regions of interest.
    pub bounds: (Point3<f64>, Point3<f64>),
}

/// Summarizes the scalpel cells of a hull; `None` when there are none (or absurdly many). `reach`
/// is the tool's length: cells farther than that from the scalpel's centroid cannot hold it.
pub(crate) fn summarize(occ: &Occupancy, reach: f64) -> Option<HullSummary> {
    let leaf = occ.leaf_size;
    let key = |p: &Point3<f64>| {
        let q = (p - occ.origin) / leaf;
        [q.x.floor() as i32, q.y.floor() as i32, q.z.floor() as i32]
    };
    let mut leaves: Vec<[i32; 3]> = Vec::new();
    for c in occ.cells.iter().filter(|c| c.has(label::SCALPEL)) {
        // Counted in floating point: a cell many leaves wide must not overflow the count.
        let m = (c.size / leaf).round().max(1.0);
        if !(m.is_finite() && leaves.len() as f64 + m * m * m <= MAX_LEAVES as f64) {
            return None;
        }
        let m = m as i32;
        let k0 = key(&(c.min + Vector3::repeat(leaf / 2.0)));
        for i in 0..m {
            for j in 0..m {
                for k in 0..m {
                    leaves.push([k0[0] + i, k0[1] + j, k0[2] + k]);
                }
            }
        }
    }
    if leaves.is_empty() {
        return None;
    }
    // Leaf indices on a dense grid over the leaves' bounding box (one slot per leaf position,
    // u32::MAX where empty): neighbour lookups are array reads.
    let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
    for k in &leaves {
        for a in 0..3 {
            lo[a] = lo[a].min(k[a]);
            hi[a] = hi[a].max(k[a]);
        }
    }
    let dims = [0, 1, 2].map(|a| (i64::from(hi[a]) - i64::from(lo[a]) + 1) as usize);
    if dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).is_none_or(|n| n > MAX_GRID_SLOTS) {
        return None;
    }
    let slot = |k: &[i32; 3]| {
        ((k[2] - lo[2]) as usize * dims[1] + (k[1] - lo[1]) as usize) * dims[0] + (k[0] - lo[0]) as usize
    };
    let mut grid = vec![u32::MAX; dims[0] * dims[1] * dims[2]];
    for (i, k) in leaves.iter().enumerate() {
        grid[slot(k)] = i as u32;
    }
    let mut parent: Vec<usize> = (0..leaves.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (i, k) in leaves.iter().enumerate() {
        // Half of the 26 neighbours suffice: each pair is met from one side.
        for d in 14..27 {
            let n = [k[0] + d % 3 - 1, k[1] + (d / 3) % 3 - 1, k[2] + d / 9 - 1];
            if (0..3).any(|a| n[a] < lo[a] || n[a] > hi[a]) {
                continue;
            }
            let j = grid[slot(&n)];
            if j != u32::MAX {
                let (a, b) = (find(&mut parent, i), find(&mut parent, j as usize));
                if a != b {
                    parent[a] = b;
                }
            }
        }
    }
    let mut sizes: HashMap<usize, usize> = HashMap::new();
    for i in 0..leaves.len() {
        *sizes.entry(find(&mut parent, i)).or_default() += 1;
    }
    let mut by_size: Vec<(usize, usize)> = sizes.into_iter().map(|(root, n)| (n, root)).collect();
    by_size.sort_unstable_by(|a, b| b.cmp(a));
    let (largest, root) = by_size[0];
    let centre =
        |k: &[i32; 3]| occ.origin + Vector3::new(k[0] as f64 + 0.5, k[1] as f64 + 0.5, k[2] as f64 + 0.5) * leaf;
    let roots: Vec<usize> = (0..leaves.len()).map(|i| find(&mut parent, i)).collect();
    let component = |r: usize| -> Vec<Point3<f64>> {
        (0..leaves.len()).filter(|&i| roots[i] == r).map(|i| centre(&leaves[i])).collect()
    };
    let mut points = component(root);
    let mut line = principal_line(&points)?;
    // A hand holding the scalpel in its middle splits the scalpel's hull in two; two components
    // that together still form one thin tool no longer than it are one tool.
    let mut second_fraction = 0.0;
    if let Some(&(n2, r2)) = by_size.get(1) {
        let mut both = points.clone();
        both.extend(component(r2));
        if let Some(joint) = principal_line(&both)
            && joint.thickness <= MAX_TOOL_THICKNESS
            && joint.span.1 - joint.span.0 <= reach * 1.2
        {
            points = both;
            line = joint;
            second_fraction = by_size.get(2).map_or(0.0, |s| s.0 as f64 / (largest + n2) as f64);
        } else {
            second_fraction = n2 as f64 / largest as f64;
        }
    }
    let Line { centroid, axis, span: (lo, hi), .. } = line;
    let (mut bmin, mut bmax) = (centroid, centroid);
    for p in &points {
        bmin = bmin.inf(p);
        bmax = bmax.sup(p);
    }
    let half = Vector3::repeat(leaf / 2.0);
    let (mut hand_sum, mut hand_volume) = (Vector3::zeros(), 0.0);
    for c in occ.cells.iter().filter(|c| (c.centre() - centroid).norm() <= reach + c.size) {
        if c.has(label::HAND) {
            let v = c.size.powi(3);
            hand_sum += c.centre().coords * v;
            hand_volume += v;
        }
    }
    let hand_centroid = (hand_volume > 0.0).then(|| Point3::from(hand_sum / hand_volume));
    Some(HullSummary {
        leaves: points.len(),
        components: by_size.len(),
        second_fraction,
        centroid,
        axis,
        span: (lo - leaf / 2.0, hi + leaf / 2.0),
        hand_centroid,
        bounds: (bmin - half, bmax + half),
    })
}

/// Thickest a set of leaves may be (RMS distance from its principal line) and still be one tool.
const MAX_TOOL_THICKNESS: f64 = 0.015;

/// A point set's principal line.
struct Line {
    centroid: Point3<f64>,
    axis: Vector3<f64>,
    /// Extent along the axis relative to the centroid.
    span: (f64, f64),
    /// RMS distance from the line.
    thickness: f64,
}

/// A point set's principal line; `None` where the eigendecomposition does not converge within
/// [`MAX_EIGEN_ITERATIONS`].
fn principal_line(points: &[Point3<f64>]) -> Option<Line> {
    let n = points.len().max(1) as f64;
    let centroid = Point3::from(points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n);
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p - centroid;
        cov += d * d.transpose();
    }
    let eig = nalgebra::SymmetricEigen::try_new(cov, f64::EPSILON, MAX_EIGEN_ITERATIONS)?;
    let k = eig.eigenvalues.imax();
    let axis = eig.eigenvectors.column(k).into_owned().normalize();
    let off_axis = (eig.eigenvalues.sum() - eig.eigenvalues[k]).max(0.0) / n;
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for p in points {
        let s = (p - centroid).dot(&axis);
        lo = lo.min(s);
        hi = hi.max(s);
    }
    Some(Line { centroid, axis, span: (lo, hi), thickness: off_axis.sqrt() })
}

/// The template's own frame of reference: its long axis (toward the tip) and the blade normal
/// made perpendicular to it, as a rotation from (x, y, z) to (axis, normal, axis × normal).
fn template_frame(t: &Template) -> Option<(Rotation3<f64>, f64, f64)> {
    let axis = (t.tip - t.body_or_blade_centre()).try_normalize(1e-9)?;
    let n = (t.normal - axis * t.normal.dot(&axis)).try_normalize(1e-9)?;
    let frame = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[axis, n, axis.cross(&n)]));
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for p in t.blade.iter().chain(&t.body) {
        let s = (p - t.tip).dot(&axis);
        lo = lo.min(s);
        hi = hi.max(s);
    }
    // Offsets of the tool's two ends from the tip along its axis (hi is about 0: the tip leads).
    Some((frame, lo, hi))
}

/// Starting poses from the hull alone: the template's axis along the hull's (pointing away from
/// the hand, or both ways without one), rolled
/// about it in [`ROLLS`] steps, its tip at the hull's far end or its back at the near end.
pub(crate) fn candidates(t: &Template, hull: &HullSummary) -> Vec<Isometry3<f64>> {
    let Some((frame_t, back, front)) = template_frame(t) else { return Vec::new() };
    let mut out = Vec::with_capacity(4 * ROLLS);
    // The blade points away from the hand that holds the handle (the hull's end farther from the
    // hand's centroid is the tip's); with no hand, both ways.
    let end = |s: f64| hull.centroid + hull.axis * s;
    let signs: &[f64] = match hull.hand_centroid {
        Some(h) if (end(hull.span.1) - h).norm() > (end(hull.span.0) - h).norm() => &[1.0],
        Some(_) => &[-1.0],
        None => &[1.0, -1.0],
    };
    for &sign in signs {
        let a = hull.axis * sign;
        let (lo, hi) = if sign > 0.0 { hull.span } else { (-hull.span.1, -hull.span.0) };
        let e1 = a.cross(&if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() }).normalize();
        let e2 = a.cross(&e1);
        for r in 0..ROLLS {
            let theta = r as f64 * std::f64::consts::TAU / ROLLS as f64;
            let b = e1 * theta.cos() + e2 * theta.sin();
            let frame_w = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[a, b, a.cross(&b)]));
            let rot = UnitQuaternion::from_rotation_matrix(&(frame_w * frame_t.inverse()));
            // Tip at the hull's far end, or the tool's back at its near end.
            for tip_at in [hi - front, lo - back] {
                let tip_world = hull.centroid + a * tip_at;
                let translation = tip_world.coords - rot * t.tip.coords;
                out.push(Isometry3::from_parts(Translation3::from(translation), rot));
            }
        }
    }
    out
}
