//! Small 2-D geometry: convex hulls and distances to convex polygons.

use nalgebra::Point2;

/// Convex hull of points (Andrew's monotone chain), counter-clockwise, without repeated or
/// collinear points. Fewer than three distinct points give what there is.
pub(crate) fn convex_hull(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let mut p: Vec<Point2<f64>> = points.iter().copied().filter(|q| q.x.is_finite() && q.y.is_finite()).collect();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| (a - o).perp(&(b - o));
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * p.len());
    // Lower chain left to right, then upper chain right to left; the upper chain never pops the
    // lower one's points.
    for (pass, chain) in [p.clone(), p.iter().rev().skip(1).copied().collect()].iter().enumerate() {
        let floor = if pass == 0 { 2 } else { hull.len() + 1 };
        for q in chain {
            while hull.len() >= floor && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(*q);
        }
    }
    hull.pop();
    hull
}

/// Signed distance from `q` to a convex polygon given counter-clockwise: the distance outside,
/// minus the depth inside. A polygon of one or two points is a point or a segment (never inside).
pub(crate) fn signed_distance_convex(polygon: &[Point2<f64>], q: &Point2<f64>) -> f64 {
    let n = polygon.len();
    if n == 0 {
        return f64::INFINITY;
    }
    if n == 1 {
        return (q - polygon[0]).norm();
    }
    let mut inside = n >= 3;
    let mut outside_distance = f64::INFINITY;
    let mut depth = f64::INFINITY;
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        let ab = b - a;
        let aq = q - a;
        let len2 = ab.norm_squared();
        if len2 == 0.0 {
            continue;
        }
        let side = ab.perp(&aq) / len2.sqrt();
        if side < 0.0 {
            inside = false;
        }
        depth = depth.min(side);
        let t = (aq.dot(&ab) / len2).clamp(0.0, 1.0);
        outside_distance = outside_distance.min((aq - ab * t).norm());
    }
    if inside { -depth } else { outside_distance }
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
        assert!((signed_distance_convex(&h, &Point2::new(0.5, 0.4)) + 0.4).abs() < 1e-12);
        assert!((signed_distance_convex(&h, &Point2::new(2.0, 0.5)) - 1.0).abs() < 1e-12);
        assert!((signed_distance_convex(&h, &Point2::new(2.0, 2.0)) - 2f64.sqrt()).abs() < 1e-12);
    }
}
