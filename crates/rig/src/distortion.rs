//! OpenCV's five-coefficient lens distortion (Brown–Conrady: radial k1, k2, k3; tangential p1, p2).

use nalgebra::{Matrix2, Vector2};

/// Largest number of Newton iterations [`Distortion::undistort`] takes.
pub const UNDISTORT_MAX_ITERATIONS: usize = 50;

/// Convergence bound of [`Distortion::undistort`]: iteration stops once re-distorting the estimate
/// reproduces the input within this distance in normalized image coordinates (for a 600 px focal
/// length this is 6e-12 px, far below the 1e-6 px the tests demand).
pub const UNDISTORT_TOLERANCE: f64 = 1e-14;

/// OpenCV's distortion coefficients `(k1, k2, p1, p2, k3)`, acting on normalized image coordinates.
///
/// With `r² = x² + y²` the distorted point is
/// `x' = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)` and
/// `y' = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
    /// First tangential coefficient.
    pub p1: f64,
    /// Second tangential coefficient.
    pub p2: f64,
    /// Radial coefficient of r⁶.
    pub k3: f64,
}

impl Distortion {
    /// No distortion.
    pub const NONE: Self = Self { k1: 0.0, k2: 0.0, p1: 0.0, p2: 0.0, k3: 0.0 };

    /// The coefficients in OpenCV's order `[k1, k2, p1, p2, k3]`.
    pub fn to_array(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// Coefficients from OpenCV's order `[k1, k2, p1, p2, k3]`.
    pub fn from_array(c: [f64; 5]) -> Self {
        Self { k1: c[0], k2: c[1], p1: c[2], p2: c[3], k3: c[4] }
    }

    /// Whether every coefficient is zero.
    #[inline]
    pub fn is_none(&self) -> bool {
        self.to_array().iter().all(|&c| c == 0.0)
    }

    /// Applies the distortion to a normalized image point.
    #[inline]
    pub fn distort(&self, p: Vector2<f64>) -> Vector2<f64> {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        Vector2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// The distorted point and the 2x2 Jacobian of the distortion at `p`.
    #[inline]
    pub fn distort_with_jacobian(&self, p: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r2)
        let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let d = self.distort(p);
        let dxdx = radial + x * dradial * 2.0 * x + 2.0 * self.p1 * y + self.p2 * 6.0 * x;
        let dxdy = x * dradial * 2.0 * y + 2.0 * self.p1 * x + self.p2 * 2.0 * y;
        let dydx = y * dradial * 2.0 * x + self.p1 * 2.0 * x + 2.0 * self.p2 * y;
        let dydy = radial + y * dradial * 2.0 * y + self.p1 * 6.0 * y + 2.0 * self.p2 * x;
        (d, Matrix2::new(dxdx, dxdy, dydx, dydy))
    }

    /// An upper bound of how much the distortion stretches distances among normalized points within
    /// radius `r` of the centre: the operator norm of its Jacobian there is at most
    /// `1 + 3|k1| r² + 5|k2| r⁴ + 7|k3| r⁶ + 12 (|p1| + |p2|) r`. The radial part's Jacobian is
    /// symmetric with eigenvalues `1 + k1 r² + k2 r⁴ + k3 r⁶` and `1 + 3 k1 r² + 5 k2 r⁴ + 7 k3 r⁶`;
    /// the tangential part's four entries sum, in absolute value, to at most `12 (|p1| + |p2|) r`.
    #[inline]
    pub fn stretch_bound(&self, r: f64) -> f64 {
        let r2 = r * r;
        1.0 + r2 * (3.0 * self.k1.abs() + r2 * (5.0 * self.k2.abs() + r2 * 7.0 * self.k3.abs()))
            + 12.0 * (self.p1.abs() + self.p2.abs()) * r
    }

    /// The radius (in normalized coordinates) up to which the radial map `r ↦ r (1 + k1 r² + k2 r⁴ +
    /// k3 r⁶)` is increasing, i.e. where the distortion can be inverted without ambiguity.
    ///
    /// Returns `f64::INFINITY` when the map increases for every radius. Points beyond this radius
    /// fold back onto points inside it: a projection there is reported as not visible.
    pub fn monotonic_radius(&self) -> f64 {
        // d/dr [r + k1 r³ + k2 r⁵ + k3 r⁷] = 1 + 3 k1 s + 5 k2 s² + 7 k3 s³ with s = r².
        let g = |s: f64| 1.0 + s * (3.0 * self.k1 + s * (5.0 * self.k2 + s * 7.0 * self.k3));
        // No negative coefficient: g ≥ 1 for every s ≥ 0 (no distortion, pincushion). Callers
        // ask per projected point, so this is worth the test.
        if self.k1 >= 0.0 && self.k2 >= 0.0 && self.k3 >= 0.0 {
            return f64::INFINITY;
        }
        // Scan s geometrically for the first sign change, then bisect until the bounds are
        // neighbouring numbers (about 50 halvings; at most 200).
        let mut lo = 0.0;
        let mut hi = 1e-4;
        while hi < 1e6 {
            if g(hi) <= 0.0 {
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if mid == lo || mid == hi {
                        break;
                    }
                    if g(mid) > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                return lo.sqrt();
            }
            lo = hi;
            hi *= 1.1;
        }
        f64::INFINITY
    }

    /// Inverts the distortion: the normalized point whose distortion is `pd`.
    ///
    /// Newton's method started at `pd`, with step halving when a step does not reduce the residual.
    /// It stops when `|distort(p) - pd| < UNDISTORT_TOLERANCE` and returns `None` when that is not
    /// reached within [`UNDISTORT_MAX_ITERATIONS`] (a point outside the invertible range).
    pub fn undistort(&self, pd: Vector2<f64>) -> Option<Vector2<f64>> {
        if self.is_none() {
            return Some(pd);
        }
        let mut p = pd;
        let (mut d, mut jac) = self.distort_with_jacobian(p);
        let mut residual = d - pd;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let err = residual.norm();
            if err < UNDISTORT_TOLERANCE {
                return Some(p);
            }
            let step = jac.try_inverse()? * residual;
            let mut scale = 1.0;
            loop {
                let candidate = p - step * scale;
                let (d2, jac2) = self.distort_with_jacobian(candidate);
                let r2 = d2 - pd;
                if r2.norm() < err || scale < 1e-6 {
                    p = candidate;
                    d = d2;
                    jac = jac2;
                    residual = r2;
                    break;
                }
                scale *= 0.5;
            }
        }
        ((d - pd).norm() < UNDISTORT_TOLERANCE * 1e3).then_some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_finite_differences() {
        let d = Distortion { k1: -0.2, k2: 0.05, p1: 1e-3, p2: -2e-3, k3: 0.01 };
        let p = Vector2::new(0.3, -0.2);
        let (_, j) = d.distort_with_jacobian(p);
        let h = 1e-6;
        for c in 0..2 {
            let mut e = Vector2::zeros();
            e[c] = h;
            let fd = (d.distort(p + e) - d.distort(p - e)) / (2.0 * h);
            for r in 0..2 {
                assert!((fd[r] - j[(r, c)]).abs() < 1e-8, "J[{r},{c}] {} vs {}", j[(r, c)], fd[r]);
            }
        }
    }

    #[test]
    fn monotonic_radius_of_barrel_distortion() {
        // 1 + 3 k1 r² = 0  =>  r = sqrt(-1 / (3 k1)) for k2 = k3 = 0.
        let d = Distortion { k1: -0.3, ..Distortion::NONE };
        let expected = (1.0f64 / 0.9).sqrt();
        assert!((d.monotonic_radius() - expected).abs() < 1e-9);
        assert!(Distortion { k1: 0.1, ..Distortion::NONE }.monotonic_radius().is_infinite());
        assert!(Distortion { k1: 0.1, k2: 0.2, k3: 0.0, ..Distortion::NONE }.monotonic_radius().is_infinite());
        // A positive k1 with a negative k2 still folds, farther out: the slope vanishes there.
        let d = Distortion { k1: 0.1, k2: -0.05, ..Distortion::NONE };
        let r = d.monotonic_radius();
        let slope = |r: f64| 1.0 + 3.0 * d.k1 * r * r + 5.0 * d.k2 * r.powi(4);
        assert!(r.is_finite() && slope(r) > 0.0 && slope(r) < 1e-9 && slope(r * (1.0 + 1e-9)) < 0.0, "{r}");
    }

    #[test]
    fn undistort_inverts_distort() {
        let d = Distortion { k1: -0.25, k2: 0.08, p1: 5e-4, p2: -3e-4, k3: -0.01 };
        for &(x, y) in &[(0.0, 0.0), (0.4, 0.3), (-0.5, 0.1), (0.05, -0.6)] {
            let p = Vector2::new(x, y);
            let back = d.undistort(d.distort(p)).expect("converges");
            assert!((back - p).norm() < 1e-12, "{p:?} -> {back:?}");
        }
    }
}
