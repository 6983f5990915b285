//! Small 2-D geometry: convex hulls and distances to convex polygons.

use nalgebra::{Point2, Vector2};

/// Iterations a symmetric eigendecomposition (a 3x3 covariance) may take: far more than a finite
/// matrix needs, and a bound where rounding or a huge entry would keep it from converging.
pub(crate) const MAX_EIGEN_ITERATIONS: usize = 1000;

/// Convex hull of points (Andrew's monotone chain), counter-clockwise, without repeated or
/// collinear points. Fewer than three distinct points give what there is.
pub(crate) fn convex_hull(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let mut order = Vec::new();
    convex_hull_indices(points, &mut order);
    order.iter().map(|&i| points[i]).collect()
}

/// Point sets at least this large are first rid of the points deep inside the polygon of their
/// extremes ([`Extremes`]): a projected handle's vertices, hundreds of them, were sorted whole
/// for every pose the tool's fit tried.
const PREFILTER_MIN: usize = 24;

/// [`convex_hull`] as indices into `points`, written into `hull` (reused between calls).
pub(crate) fn convex_hull_indices(points: &[Point2<f64>], hull: &mut Vec<usize>) {
    let mut idx: Vec<usize> =
        (0..points.len()).filter(|&i| points[i].x.is_finite() && points[i].y.is_finite()).collect();
    if idx.len() >= PREFILTER_MIN
        && let Some(extremes) = Extremes::of(points, &idx)
    {
        idx.retain(|&i| !extremes.holds_deep(&points[i]));
    }
    monotone_chain(points, idx, hull);
}

/// The polygon of a point set's extremes in eight directions (least and greatest x, y, x + y and
/// x − y), as its edges: its corners are points of the set, so a point inside it by more than a
/// rounding error's margin is inside their convex hull and never one of its corners (Akl and
/// Toussaint's filter). Kept on the stack: it is made for every outline the tool's fit projects.
struct Extremes {
    /// Each edge's start and unit direction, counter-clockwise; the first `edges` are used.
    edges: [(Point2<f64>, Vector2<f64>); 8],
    len: usize,
    /// Far more than the rounding of a cross product of the points' coordinates, far less than
    /// a pixel.
    margin: f64,
}

impl Extremes {
    /// The extremes' polygon of the points `idx` names (finite ones); `None` where it spans no
    /// area.
    fn of(points: &[Point2<f64>], idx: &[usize]) -> Option<Self> {
        // Outward directions in counter-clockwise order: their extremes are the polygon's corners
        // in that order.
        const DIRECTIONS: [(f64, f64); 8] =
            [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0), (-1.0, -1.0), (0.0, -1.0), (1.0, -1.0)];
        let mut best = [(f64::NEG_INFINITY, Point2::origin()); 8];
        let mut extent = 0.0f64;
        for &i in idx {
            let p = points[i];
            extent = extent.max(p.x.abs()).max(p.y.abs());
            for (b, (dx, dy)) in best.iter_mut().zip(DIRECTIONS) {
                let v = dx * p.x + dy * p.y;
                if v > b.0 {
                    *b = (v, p);
                }
            }
        }
        let mut corners = [Point2::origin(); 8];
        let mut n = 0;
        for &(v, p) in &best {
            if v.is_finite() && (n == 0 || (corners[n - 1] != p && corners[0] != p)) {
                corners[n] = p;
                n += 1;
            }
        }
        let mut edges = [(Point2::origin(), Vector2::zeros()); 8];
        let mut len = 0;
        for k in 0..n {
            let (a, b) = (corners[k], corners[(k + 1) % n]);
            let ab = b - a;
            let l = ab.norm();
            if l > 0.0 {
                edges[len] = (a, ab / l);
                len += 1;
            }
        }
        (n >= 3 && len >= 3).then_some(Extremes { edges, len, margin: 1e-9 * (1.0 + extent) })
    }

    /// Whether `p` lies inside the polygon by more than the margin.
    fn holds_deep(&self, p: &Point2<f64>) -> bool {
        self.edges[..self.len].iter().all(|(a, u)| u.perp(&(p - a)) > self.margin)
    }
}

/// Andrew's monotone chain over the points `idx` names (finite ones), into `hull`.
fn monotone_chain(points: &[Point2<f64>], mut idx: Vec<usize>, hull: &mut Vec<usize>) {
    hull.clear();
    // Ties broken by index: the order a stable sort of the ascending indices gives.
    idx.sort_unstable_by(|&a, &b| {
        points[a].x.total_cmp(&points[b].x).then(points[a].y.total_cmp(&points[b].y)).then(a.cmp(&b))
    });
    idx.dedup_by(|a, b| points[*a] == points[*b]);
    if idx.len() < 3 {
        hull.extend_from_slice(&idx);
        return;
    }
    let cross = |o: usize, a: usize, b: usize| (points[a] - points[o]).perp(&(points[b] - points[o]));
    // Lower chain left to right, then upper chain right to left; the upper chain never pops the
    // lower one's points.
    for pass in 0..2 {
        let floor = if pass == 0 { 2 } else { hull.len() + 1 };
        let chain: Box<dyn Iterator<Item = &usize>> =
            if pass == 0 { Box::new(idx.iter()) } else { Box::new(idx.iter().rev().skip(1)) };
        for &q in chain {
            while hull.len() >= floor && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
    }
    hull.pop();
}

/// The nearest boundary feature of a convex polygon to a point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Nearest {
    /// Signed distance: outside positive, inside the negative depth.
    pub sd: f64,
    /// Edge from polygon vertex `edge` to `edge + 1` (cyclic).
    pub edge: usize,
    /// Position of the nearest point along that edge, 0 at its start, 1 at its end.
    pub t: f64,
    /// Unit direction in which `sd` grows fastest as the point moves (the outward normal of the
    /// edge inside, the direction from the nearest point outside).
    pub normal: Vector2<f64>,
}

/// One edge of a [`Convex`] polygon, from vertex `index` to the next.
#[derive(Debug, Clone, Copy)]
struct Edge {
    index: usize,
    a: Point2<f64>,
    ab: Vector2<f64>,
    len2: f64,
    len: f64,
    /// Outward unit normal (the polygon is counter-clockwise).
    normal: Vector2<f64>,
}

/// A convex polygon (counter-clockwise) prepared for many nearest-feature queries: its edges'
/// vectors, lengths and normals are computed once.
#[derive(Debug, Clone, Default)]
pub(crate) struct Convex {
    vertices: usize,
    edges: Vec<Edge>,
}

impl Convex {
    /// The polygon through `polygon`'s points in order (a repeated point makes no edge); the
    /// library reuses one polygon's storage ([`Convex::set`]).
    #[cfg(test)]
    pub(crate) fn new(polygon: &[Point2<f64>]) -> Self {
        let mut convex = Convex::default();
        convex.set(polygon);
        convex
    }

    /// Makes this the polygon through `polygon`'s points, reusing its storage.
    pub(crate) fn set(&mut self, polygon: &[Point2<f64>]) {
        let n = polygon.len();
        self.vertices = n;
        self.edges.clear();
        for i in 0..n {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            let ab = b - a;
            let len2 = ab.norm_squared();
            if len2 == 0.0 {
                continue;
            }
            let len = len2.sqrt();
            self.edges.push(Edge { index: i, a, ab, len2, len, normal: Vector2::new(ab.y, -ab.x) / len });
        }
    }

    /// Number of vertices.
    pub(crate) fn len(&self) -> usize {
        self.vertices
    }

    /// The nearest feature to `q` (`None` for fewer than two points).
    pub(crate) fn nearest(&self, q: &Point2<f64>) -> Option<Nearest> {
        if self.vertices < 2 {
            return None;
        }
        let mut inside = self.vertices >= 3;
        let mut depth = Nearest { sd: f64::INFINITY, edge: 0, t: 0.0, normal: Vector2::x() };
        // The nearest point outside, compared by squared distance: (squared distance, edge, t,
        // offset from the edge's nearest point).
        let mut out: Option<(f64, &Edge, f64, Vector2<f64>)> = None;
        // A segment (two points) has no inside: every edge's distance counts.
        let segment = self.vertices < 3;
        for e in &self.edges {
            let aq = q - e.a;
            let side = e.ab.perp(&aq) / e.len;
            let deeper = side < depth.sd;
            // Outside a polygon, the nearest boundary point lies on an edge that `q` is outside
            // of (at a vertex, on one of the two edges that meet there): the distance to the
            // others is not needed.
            if side >= 0.0 && !deeper && !segment {
                continue;
            }
            let t = (aq.dot(&e.ab) / e.len2).clamp(0.0, 1.0);
            if deeper {
                depth = Nearest { sd: side, edge: e.index, t, normal: e.normal };
            }
            if side < 0.0 || segment {
                inside &= side >= 0.0;
                let d = aq - e.ab * t;
                let dist2 = d.norm_squared();
                if out.is_none_or(|(best, ..)| dist2 < best) {
                    out = Some((dist2, e, t, d));
                }
            }
        }
        if inside {
            return Some(Nearest { sd: -depth.sd, ..depth });
        }
        Some(match out {
            Some((dist2, e, t, d)) => {
                let dist = dist2.sqrt();
                let normal = if dist > 1e-12 { d / dist } else { e.normal };
                Nearest { sd: dist, edge: e.index, t, normal }
            }
            None => Nearest { sd: f64::INFINITY, edge: 0, t: 0.0, normal: Vector2::x() },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_of_a_square_with_inner_points_is_the_square() {
        let pts = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.5, 0.5), (0.2, 0.8), (0.5, 0.0)]
            .map(|(x, y)| Point2::new(x, y));
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4);
        assert!(crate::template::polygon_area(&h) > 0.99);
        let h = Convex::new(&h);
        let sd = |x: f64, y: f64| h.nearest(&Point2::new(x, y)).expect("a polygon");
        let inside = sd(0.5, 0.4);
        assert!((inside.sd + 0.4).abs() < 1e-12 && (inside.normal - Vector2::new(0.0, -1.0)).norm() < 1e-12);
        let beside = sd(2.0, 0.5);
        assert!((beside.sd - 1.0).abs() < 1e-12 && (beside.t - 0.5).abs() < 1e-12);
        assert!((sd(2.0, 2.0).sd - 2f64.sqrt()).abs() < 1e-12);
    }

    /// The hull with the points deep inside the extremes' polygon left out is the hull of every
    /// point, corner for corner: random clouds in discs, rings and rectangles (a projected
    /// handle's outline and inside), with repeated points, points on the extremes' edges and
    /// collinear runs, from the prefilter's threshold up.
    #[test]
    fn leaving_out_the_points_inside_the_extremes_keeps_the_hull() {
        let mut seed = 17u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut filtered = 0;
        for round in 0..400 {
            let n = PREFILTER_MIN + round % 300;
            let shape = round % 4;
            let (cx, cy, s) = (next() * 600.0, next() * 400.0, 1.0 + next() * 200.0);
            let mut points: Vec<Point2<f64>> = (0..n)
                .map(|_| {
                    let (a, r) = (next() * std::f64::consts::TAU, next());
                    let (x, y) = match shape {
                        0 => (r.sqrt() * a.cos(), r.sqrt() * a.sin()),
                        1 => (a.cos(), a.sin()),
                        2 => (2.0 * r - 1.0, 0.2 * (2.0 * next() - 1.0)),
                        _ => ((4.0 * r).round() / 4.0, (4.0 * next()).round() / 4.0),
                    };
                    Point2::new(cx + s * x, cy + s * y)
                })
                .collect();
            // Repeats, and a point on the segment between two others.
            points.push(points[0]);
            points.push(points[1]);
            let mid = Point2::from((points[2].coords + points[3].coords) * 0.5);
            points.push(mid);
            let mut hull = Vec::new();
            convex_hull_indices(&points, &mut hull);
            let mut every = Vec::new();
            monotone_chain(&points, (0..points.len()).collect(), &mut every);
            assert_eq!(hull, every, "round {round}, shape {shape}");
            let extremes = Extremes::of(&points, &(0..points.len()).collect::<Vec<_>>()).expect("an area");
            filtered += points.iter().filter(|p| extremes.holds_deep(p)).count();
        }
        assert!(filtered > 10_000, "{filtered} points left out over the rounds");
        // Collinear points: no area, nothing left out.
        let line: Vec<Point2<f64>> = (0..40).map(|k| Point2::new(f64::from(k), 2.0 * f64::from(k))).collect();
        assert!(Extremes::of(&line, &(0..40).collect::<Vec<_>>()).is_none());
        let mut hull = Vec::new();
        convex_hull_indices(&line, &mut hull);
        assert_eq!(hull, vec![0, 39]);
    }

    #[test]
    fn nearest_agrees_with_the_distance_to_every_edge() {
        let mut seed = 3u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
        };
        for _ in 0..200 {
            let points: Vec<Point2<f64>> = (0..8).map(|_| Point2::new(next(), next())).collect();
            let hull = convex_hull(&points);
            let polygon = Convex::new(&hull);
            let q = Point2::new(next(), next());
            let n = hull.len();
            // The distance to the boundary: the nearest of its edges as segments.
            let boundary = (0..n)
                .map(|i| {
                    let (a, b) = (hull[i], hull[(i + 1) % n]);
                    let t = ((q - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
                    (q - (a + (b - a) * t)).norm()
                })
                .fold(f64::INFINITY, f64::min);
            let inside = (0..n).all(|i| (hull[(i + 1) % n] - hull[i]).perp(&(q - hull[i])) >= 0.0);
            let near = polygon.nearest(&q).expect("a polygon");
            assert!((near.sd.abs() - boundary).abs() < 1e-9, "{} against {boundary}", near.sd);
            assert_eq!(near.sd <= 0.0, inside, "{q:?} in {hull:?}");
            // A segment has no inside: the distance to it, also from a point on its line.
            let (a, b) = (hull[0], hull[1]);
            let segment = Convex::new(&[a, b]);
            for q in [q, a + (b - a) * 1.5] {
                let t = ((q - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
                let expected = (q - (a + (b - a) * t)).norm();
                let near = segment.nearest(&q).expect("a segment");
                assert!((near.sd - expected).abs() < 1e-9, "{} against {expected}", near.sd);
            }
        }
    }
}
