//! The seed paper's compressible neo-Hookean material: `S = μ (I − C⁻¹) + λ J (J − 1) C⁻¹`.

use nalgebra::Matrix3;

use crate::SimError;

/// Lamé parameters and density.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Material {
    /// First Lamé parameter λ, pascals.
    pub lambda: f64,
    /// Shear modulus μ, pascals.
    pub mu: f64,
    /// Density, kg/m³.
    pub density: f64,
}

impl Default for Material {
    /// The seed paper's liver: λ = μ = 20 kPa, ρ = 1000 kg/m³.
    fn default() -> Self {
        Self { lambda: 20_000.0, mu: 20_000.0, density: 1000.0 }
    }
}

impl Material {
    /// From Young's modulus E and Poisson's ratio ν.
    pub fn from_young_poisson(e: f64, nu: f64, density: f64) -> Self {
        Self { lambda: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu: e / (2.0 * (1.0 + nu)), density }
    }

    /// Poisson's ratio ν = λ / (2 (λ + μ)).
    pub fn poisson(&self) -> f64 {
        self.lambda / (2.0 * (self.lambda + self.mu))
    }

    /// Young's modulus E = μ (3λ + 2μ) / (λ + μ), pascals.
    pub fn young_modulus(&self) -> f64 {
        self.mu * (3.0 * self.lambda + 2.0 * self.mu) / (self.lambda + self.mu)
    }

    /// Dilatational wave speed `c = √((λ + 2μ)/ρ)`, m/s.
    pub fn wave_speed(&self) -> f64 {
        ((self.lambda + 2.0 * self.mu) / self.density).sqrt()
    }

    /// Checks that the material is physical and within the documented ranges: all finite, the shear
    /// modulus μ from [`MIN_SHEAR_MODULUS_PA`] to [`MAX_MODULUS_PA`], |λ| at most [`MAX_MODULUS_PA`]
    /// with a positive bulk modulus λ + 2μ/3 (so Poisson's ratio lies in (−1, 0.5)), the density
    /// from [`MIN_DENSITY`] to [`MAX_DENSITY`]. Errors name the scenario key (`material.mu`, ...)
    /// and the allowed range.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |key: &str, msg: String| Err(SimError::Invalid { key: key.to_owned(), message: msg });
        for (key, v) in [("material.lambda", self.lambda), ("material.mu", self.mu), ("material.density", self.density)]
        {
            if !v.is_finite() {
                return bad(key, format!("{v} is not a finite number"));
            }
        }
        if !(MIN_SHEAR_MODULUS_PA..=MAX_MODULUS_PA).contains(&self.mu) {
            return bad(
                "material.mu",
                format!(
                    "the shear modulus must lie in [{MIN_SHEAR_MODULUS_PA}, {MAX_MODULUS_PA:e}] Pa, got {}",
                    self.mu
                ),
            );
        }
        if self.lambda.abs() > MAX_MODULUS_PA {
            return bad(
                "material.lambda",
                format!("must lie in [-{MAX_MODULUS_PA:e}, {MAX_MODULUS_PA:e}] Pa, got {}", self.lambda),
            );
        }
        if self.lambda + 2.0 * self.mu / 3.0 <= 0.0 {
            return bad(
                "material.lambda",
                format!(
                    "the bulk modulus λ + 2μ/3 must be positive (λ > {} Pa for μ = {} Pa), got λ = {}",
                    -2.0 * self.mu / 3.0,
                    self.mu,
                    self.lambda
                ),
            );
        }
        if !(MIN_DENSITY..=MAX_DENSITY).contains(&self.density) {
            return bad(
                "material.density",
                format!("must lie in [{MIN_DENSITY}, {MAX_DENSITY:e}] kg/m³, got {}", self.density),
            );
        }
        Ok(())
    }
}

/// Smallest shear modulus μ accepted, pascals (softer than any tissue; a softer body's stable step
/// and sag leave the ranges the simulator is checked in).
pub const MIN_SHEAR_MODULUS_PA: f64 = 1.0;
/// Largest μ and |λ| accepted, pascals (1 TPa, above any solid's shear modulus): TLED's stresses
/// and forces are `f32`.
pub const MAX_MODULUS_PA: f64 = 1e12;
/// Smallest density accepted, kg/m³ (about air's).
pub const MIN_DENSITY: f64 = 1.0;
/// Largest density accepted, kg/m³ (over four times osmium's): node masses stay well inside `f32`.
pub const MAX_DENSITY: f64 = 1e5;

/// First Piola–Kirchhoff stress `P = F S` of the neo-Hookean material for a deformation gradient
/// with `det F > 0`.
#[inline]
pub fn first_piola(f: &Matrix3<f32>, lambda: f32, mu: f32) -> Matrix3<f32> {
    let c = f.transpose() * f;
    let j = f.determinant();
    // C⁻¹ = adj(C) / det C, det C = J².
    let inv_det = 1.0 / (j * j);
    let ci = Matrix3::new(
        c[(1, 1)] * c[(2, 2)] - c[(1, 2)] * c[(2, 1)],
        c[(0, 2)] * c[(2, 1)] - c[(0, 1)] * c[(2, 2)],
        c[(0, 1)] * c[(1, 2)] - c[(0, 2)] * c[(1, 1)],
        c[(1, 2)] * c[(2, 0)] - c[(1, 0)] * c[(2, 2)],
        c[(0, 0)] * c[(2, 2)] - c[(0, 2)] * c[(2, 0)],
        c[(0, 2)] * c[(1, 0)] - c[(0, 0)] * c[(1, 2)],
        c[(1, 0)] * c[(2, 1)] - c[(1, 1)] * c[(2, 0)],
        c[(0, 1)] * c[(2, 0)] - c[(0, 0)] * c[(2, 1)],
        c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)],
    ) * inv_det;
    let s = (Matrix3::identity() - ci) * mu + ci * (lambda * j * (j - 1.0));
    f * s
}

/// `F` with its singular values clamped to at least `floor` and its orientation made proper, so that
/// an inverted or collapsed element (det F ≤ 0) gets a finite stress that pushes it back (in the
/// spirit of Irving et al. 2004, invertible finite elements).
pub fn regularize(f: &Matrix3<f32>, floor: f32) -> Matrix3<f32> {
    let svd = f.svd(true, true);
    let (Some(mut u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut s = svd.singular_values;
    // Make U and V proper rotations; the sign goes to the smallest singular value.
    let (umin, _) = s.argmin();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[umin] = -s[umin];
    }
    if u.determinant() < 0.0 {
        // Flip a column of U together with the sign already carried by s.
        u.column_mut(umin).neg_mut();
        s[umin] = -s[umin];
    }
    let clamped = s.map(|x| if x.is_finite() { x.max(floor) } else { floor });
    u * Matrix3::from_diagonal(&clamped) * v_t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stress_free_at_rest_and_uniaxial_closed_form() {
        let p = first_piola(&Matrix3::identity(), 20_000.0, 20_000.0);
        assert!(p.abs().max() < 1e-3);
        // F = diag(1.3, 1, 1): P_xx = 1.3 [μ (1 − 1/1.69) + λ 1.3 · 0.3 / 1.69].
        let (l, m) = (20_000.0f32, 20_000.0f32);
        let p = first_piola(&Matrix3::from_diagonal(&nalgebra::Vector3::new(1.3, 1.0, 1.0)), l, m);
        let expected = 1.3 * (m * (1.0 - 1.0 / 1.69) + l * 1.3 * 0.3 / 1.69);
        assert!((p[(0, 0)] - expected).abs() < 1e-2 * expected.abs() * 1e-2, "{} vs {expected}", p[(0, 0)]);
    }

    #[test]
    fn regularized_inversion_is_finite_and_proper() {
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, -0.5f32));
        let g = regularize(&f, 0.2);
        assert!(g.determinant() > 0.0);
        let p = first_piola(&g, 20_000.0, 20_000.0);
        assert!(p.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn validation_names_the_key() {
        let e = Material { mu: -1.0, ..Material::default() }.validate().expect_err("negative");
        assert!(e.to_string().contains("material.mu"));
        let e = Material { lambda: -20_000.0, ..Material::default() }.validate().expect_err("bulk");
        assert!(e.to_string().contains("material.lambda"));
        let e = Material { density: 1e308, ..Material::default() }.validate().expect_err("too dense");
        assert!(e.to_string().contains("material.density"), "{e}");
        let e = Material { lambda: 1e300, mu: 1e300, ..Material::default() }.validate().expect_err("too stiff");
        assert!(e.to_string().contains("material.mu"), "{e}");
    }
}
