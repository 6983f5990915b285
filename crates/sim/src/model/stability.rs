//! The stable time step of the explicit central-difference scheme, computed rather than guessed.
//!
//! Central differences are stable for `dt < 2 / ω_max`, with ω_max the highest natural frequency of
//! the lumped-mass system. `L / c` (edge over dilatational wave speed) is not conservative for a
//! lattice: its exact limit is 0.6–0.95 L/c, lower for nearly incompressible material. So ω_max² is
//! estimated as the largest eigenvalue of M⁻¹K by power iteration, with K applied matrix-free as the
//! directional derivative of the internal forces at the current state, over the free degrees of
//! freedom only (held components do not vibrate).

use nalgebra::Vector3;

use crate::tled::Tled;

/// Result of the eigenvalue estimate.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StabilityLimit {
    /// Estimated highest angular frequency, rad/s.
    pub omega_max: f64,
    /// Critical time step `2 / ω_max`, seconds.
    pub dt_critical: f64,
    /// Power iterations run.
    pub iterations: usize,
    /// Relative change of the eigenvalue estimate in the last iteration.
    pub residual: f64,
}

/// Estimates ω_max of `M⁻¹K` linearized about displacements `u0`.
///
/// `free[n][k]` says whether component k of node n may move; nodes with zero mass are ignored.
/// Power iteration from a checkerboard start (close to the highest lattice mode), stopping when the
/// Rayleigh quotient changes by less than `tolerance` or after `max_iterations`. Its estimate
/// approaches ω_max from below, so callers step below `dt_critical` with a safety factor.
pub fn estimate(
    tled: &mut Tled,
    mass: &[f32],
    free: &[[bool; 3]],
    u0: &[Vector3<f32>],
    h: f64,
    max_iterations: usize,
    tolerance: f64,
) -> StabilityLimit {
    let n = mass.len();
    let mut v: Vec<Vector3<f64>> = (0..n)
        .map(|i| {
            // Checkerboard by node index parity of a hash of the index, with a little variation
            // so the start is not orthogonal to the top mode on symmetric lattices.
            let s = if (i * 2_654_435_761usize) % 7 < 4 { 1.0 } else { -1.0 };
            let jitter = 1.0 + 0.1 * (((i * 40_503) % 97) as f64 / 97.0);
            Vector3::new(s * jitter, -s, s * 0.7)
        })
        .collect();
    let project = |v: &mut [Vector3<f64>]| {
        for i in 0..n {
            for k in 0..3 {
                if !free[i][k] || mass[i] <= 0.0 {
                    v[i][k] = 0.0;
                }
            }
        }
    };
    project(&mut v);
    let mut up = vec![Vector3::zeros(); n];
    let mut um = vec![Vector3::zeros(); n];
    let mut fp = vec![Vector3::zeros(); n];
    let mut fm = vec![Vector3::zeros(); n];
    let mut lambda = 0.0;
    let mut residual = f64::INFINITY;
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        // Scale so the probe strain is ~1e-4: linear, yet far above f32 rounding.
        let vmax = v.iter().map(|x| x.amax()).fold(0.0, f64::max);
        if vmax == 0.0 {
            break;
        }
        let eps = 1e-4 * h / vmax;
        for i in 0..n {
            up[i] = u0[i] + (v[i] * eps).cast::<f32>();
            um[i] = u0[i] - (v[i] * eps).cast::<f32>();
        }
        tled.internal_forces(&up, &mut fp);
        tled.internal_forces(&um, &mut fm);
        // K v and the Rayleigh quotient vᵀKv / vᵀMv.
        let mut num = 0.0;
        let mut den = 0.0;
        let mut w = vec![Vector3::zeros(); n];
        for i in 0..n {
            if mass[i] <= 0.0 {
                continue;
            }
            let kv = (fp[i] - fm[i]).cast::<f64>() / (2.0 * eps);
            let m = f64::from(mass[i]);
            num += v[i].dot(&kv);
            den += m * v[i].norm_squared();
            w[i] = kv / m;
        }
        project(&mut w);
        let new_lambda = if den > 0.0 { num / den } else { 0.0 };
        residual = ((new_lambda - lambda) / new_lambda.abs().max(f64::MIN_POSITIVE)).abs();
        lambda = new_lambda;
        // Normalize (the probe scale above depends only on the direction).
        let wmax = w.iter().map(|x| x.amax()).fold(0.0, f64::max);
        if wmax > 0.0 {
            for x in &mut w {
                *x /= wmax;
            }
        }
        v = w;
        if residual < tolerance {
            break;
        }
    }
    let omega_max = lambda.max(0.0).sqrt();
    StabilityLimit {
        omega_max,
        dt_critical: if omega_max > 0.0 { 2.0 / omega_max } else { f64::INFINITY },
        iterations,
        residual,
    }
}

/// Measures stability directly: runs a free, undamped block perturbed by 1e-4 of a cell for
/// `steps` steps of `dt` and returns whether it stayed stable (no node faster than ten wave speeds,
/// nothing non-finite). Used to find the true edge that [`estimate`] predicts.
pub fn free_run_stays_stable(
    lattice: &crate::Lattice,
    material: &crate::Material,
    dt: f64,
    steps: usize,
) -> Result<bool, crate::SimError> {
    let mut tled = Tled::new(lattice, None, material, crate::TledParams::default())?;
    let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
    let mut it =
        crate::dynamics::Integrator::new(mass, Vec::new(), 0, 0.0, dt as f32, 10.0 * material.wave_speed() as f32);
    for (n, u) in it.u.iter_mut().enumerate() {
        let s = ((n * 7919) % 13) as f32 / 13.0 - 0.5;
        *u = Vector3::new(s, -0.5 * s, 0.25 * s) * (1e-4 * lattice.cell as f32);
    }
    it.u_prev.clone_from(&it.u);
    let mut f = vec![Vector3::zeros(); lattice.node_count()];
    let zero = vec![Vector3::zeros(); lattice.node_count()];
    for _ in 0..steps {
        tled.internal_forces(&it.u, &mut f);
        if it.advance(&f, &zero).is_err() {
            return Ok(false);
        }
    }
    Ok(it.u.iter().all(|u| u.iter().all(|x| x.is_finite())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Lattice, Material, TledParams};
    use nalgebra::Point3;

    #[test]
    fn single_free_cube_limit_is_below_l_over_c() {
        let lattice = Lattice::block(Point3::origin(), 0.01, [1, 1, 1]);
        let material = Material::default();
        let mut tled = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
        let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
        let r = estimate(&mut tled, &mass, &[[true; 3]; 8], &[Vector3::zeros(); 8], 0.01, 500, 1e-10);
        let l_over_c = 0.01 / material.wave_speed();
        assert!(r.dt_critical.is_finite() && r.dt_critical < l_over_c, "{r:?} vs L/c {l_over_c}");
        assert!(r.dt_critical > 0.3 * l_over_c, "{r:?}");
    }
}
