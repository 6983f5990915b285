//! TLED against numbers anyone can compute: the NiftySim single-hexahedron case, the patch test,
//! rigid motions and the computed stability limit.

use hullcut_sim::dynamics::{Integrator, Prescribed};
use hullcut_sim::stability;
use hullcut_sim::{Integration, Lattice, Material, Tled, TledParams};
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};

fn params(integration: Integration) -> TledParams {
    TledParams { integration, ..TledParams::default() }
}

/// The closed-form x-reaction of a block stretched to F = diag(1 + e, 1, 1): P_xx × area.
fn uniaxial_reaction(m: &Material, e: f64, area: f64) -> f64 {
    let s = 1.0 + e;
    let (l, mu) = (m.lambda, m.mu);
    // S_xx = μ (1 − 1/s²) + λ J (J − 1) / s² with J = s; P_xx = s S_xx.
    s * (mu * (1.0 - 1.0 / (s * s)) + l * s * (s - 1.0) / (s * s)) * area
}

#[test]
fn single_hexahedron_reaction_matches_closed_form() {
    // NiftySim's user-guide case: a 0.1 m cube, x+ face displaced 0.03 m, y and z held everywhere.
    let lattice = Lattice::block(Point3::origin(), 0.1, [1, 1, 1]);
    let material = Material::default();
    let expected = uniaxial_reaction(&material, 0.3, 0.01);
    for integration in [Integration::OnePoint, Integration::Gauss8] {
        let mut tled = Tled::new(&lattice, None, &material, params(integration)).expect("tled");
        let u: Vec<Vector3<f32>> =
            lattice.rest.iter().map(|p| Vector3::new(if p.x > 0.05 { 0.03 } else { 0.0 }, 0.0, 0.0)).collect();
        let mut f = vec![Vector3::zeros(); 8];
        tled.internal_forces(&u, &mut f);
        let reaction: f64 = (0..8).filter(|&n| lattice.rest[n].x > 0.05).map(|n| f64::from(f[n].x)).sum();
        // f32 arithmetic on O(1) numbers: 1e-5 relative is a few ulps times the operation count.
        assert!((reaction - expected).abs() < 1e-5 * expected, "{integration:?}: {reaction} N vs {expected} N");
        // Equal and opposite on the x- face; no net force.
        let total: Vector3<f32> = f.iter().sum();
        assert!(total.norm() < 1e-5 * expected as f32);
        // Hourglass forces are exactly zero for this homogeneous deformation.
        if integration == Integration::OnePoint {
            let mut no_hg = Tled::new(&lattice, None, &material, TledParams { hourglass: 0.0, ..params(integration) })
                .expect("tled");
            let mut g = vec![Vector3::zeros(); 8];
            no_hg.internal_forces(&u, &mut g);
            assert_eq!(f, g, "hourglass forces must vanish");
        }
    }
}

#[test]
fn single_hexahedron_reaction_through_the_integrator() {
    // The same case driven by prescribed displacements with a smooth ramp: once the ramp ends the
    // reaction the constraints report is the static closed form.
    let lattice = Lattice::block(Point3::origin(), 0.1, [1, 1, 1]);
    let material = Material::default();
    let mut tled = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
    let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
    let mut prescribed = Vec::new();
    for n in 0..8u32 {
        let plus = lattice.rest[n as usize].x > 0.05;
        prescribed.push(Prescribed {
            node: n,
            axis: 0,
            target: if plus { 0.03 } else { 0.0 },
            ramp: 0.05,
            groups: u32::from(plus),
        });
        for axis in 1..3 {
            prescribed.push(Prescribed { node: n, axis, target: 0.0, ramp: 0.0, groups: 0 });
        }
    }
    let mut it = Integrator::new(mass, prescribed, 1, 0.0, 1e-4, 1e3);
    let mut f = vec![Vector3::zeros(); 8];
    let zero = vec![Vector3::zeros(); 8];
    for _ in 0..600 {
        tled.internal_forces(&it.u, &mut f);
        it.advance(&f, &zero).expect("stable");
    }
    let expected = uniaxial_reaction(&material, 0.3, 0.01);
    let got = it.reactions[0].x;
    assert!((got - expected).abs() < 1e-4 * expected, "{got} vs {expected}");
}

fn affine(a: &Matrix3<f64>, p: &Point3<f64>) -> Vector3<f32> {
    (a * p.coords).cast::<f32>()
}

#[test]
fn patch_test_reproduces_affine_field() {
    // 4x4x4 block, boundary nodes prescribed u = A X, interior nodes free; dynamic relaxation
    // (damped explicit dynamics) must settle the interior on the same affine field.
    let h = 0.01;
    let lattice = Lattice::block(Point3::origin(), h, [4, 4, 4]);
    let material = Material::default();
    let a = Matrix3::new(0.04, 0.02, -0.01, 0.0, -0.03, 0.015, 0.01, 0.0, 0.05);
    for integration in [Integration::OnePoint, Integration::Gauss8] {
        let mut tled = Tled::new(&lattice, None, &material, params(integration)).expect("tled");
        // Consistency first: at the exact affine state every interior node is in equilibrium.
        let exact: Vec<Vector3<f32>> = lattice.rest.iter().map(|p| affine(&a, p)).collect();
        let mut f = vec![Vector3::zeros(); lattice.node_count()];
        tled.internal_forces(&exact, &mut f);
        let boundary = |ijk: [u32; 3]| ijk.iter().any(|&c| c == 0 || c == 4);
        let scale = material.mu as f32 * (h * h) as f32 * 0.05;
        for (n, ijk) in lattice.node_ijk.iter().enumerate() {
            if !boundary(*ijk) {
                assert!(f[n].norm() < 1e-4 * scale, "{integration:?}: interior force {:?}", f[n]);
            }
        }
        // Then reproduction from rest.
        let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
        let mut prescribed = Vec::new();
        for (n, ijk) in lattice.node_ijk.iter().enumerate() {
            if boundary(*ijk) {
                for axis in 0..3u8 {
                    prescribed.push(Prescribed {
                        node: n as u32,
                        axis,
                        target: exact[n][axis as usize],
                        ramp: 0.0,
                        groups: 0,
                    });
                }
            }
        }
        let free: Vec<[bool; 3]> = lattice.node_ijk.iter().map(|ijk| [!boundary(*ijk); 3]).collect();
        let zero = vec![Vector3::zeros(); lattice.node_count()];
        let limit = stability::estimate(&mut tled, &mass, &free, &zero, h, 300, 1e-6);
        // Critical damping of the lowest mode of this small block is a few hundred 1/s.
        let mut it = Integrator::new(mass, prescribed, 0, 400.0, (0.8 * limit.dt_critical) as f32, 1e3);
        for _ in 0..20_000 {
            tled.internal_forces(&it.u, &mut f);
            it.advance(&f, &zero).expect("stable");
        }
        let worst = (0..lattice.node_count()).map(|n| (it.u[n] - exact[n]).norm()).fold(0.0f32, f32::max);
        // f32 displacements of ~5e-4 m: 1e-8 m is ~2e-5 relative, a few ulps after settling.
        assert!(worst < 1e-8, "{integration:?}: worst interior error {worst} m");
    }
}

#[test]
fn rigid_motion_gives_zero_internal_force() {
    let h = 0.01;
    let lattice = Lattice::block(Point3::new(-0.02, 0.01, 0.0), h, [3, 4, 2]);
    let material = Material::default();
    let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8)), 1.1);
    let t = Vector3::new(0.02, -0.01, 0.03);
    let u: Vec<Vector3<f32>> = lattice.rest.iter().map(|p| (r * p.coords + t - p.coords).cast::<f32>()).collect();
    // The force a strain of 1e-4 would produce on a node: the yardstick for "zero" in f32.
    let yardstick = 1e-4 * (material.lambda + 2.0 * material.mu) as f32 * (h * h) as f32;
    for integration in [Integration::OnePoint, Integration::Gauss8] {
        let mut tled = Tled::new(&lattice, None, &material, params(integration)).expect("tled");
        let mut f = vec![Vector3::zeros(); lattice.node_count()];
        tled.internal_forces(&u, &mut f);
        let worst = f.iter().map(|x| x.norm()).fold(0.0f32, f32::max);
        assert!(worst < 1e-2 * yardstick, "{integration:?}: {worst} N");
    }
}

/// Runs a free block from a small perturbation; returns whether it stayed stable.
fn stays_stable(lattice: &Lattice, material: &Material, dt: f64, steps: usize) -> bool {
    stability::free_run_stays_stable(lattice, material, dt, steps).expect("valid material")
}

#[test]
fn computed_stability_limit_separates_stable_from_unstable() {
    for (nu, e) in [(0.25, 60_000.0), (0.45, 30_000.0), (0.49, 10_000.0)] {
        for (h, n) in [(0.01, [3, 3, 3]), (0.005, [6, 4, 3])] {
            let material = Material::from_young_poisson(e, nu, 1000.0);
            let lattice = Lattice::block(Point3::origin(), h, n);
            let mut tled = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
            let mass: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
            let free = vec![[true; 3]; lattice.node_count()];
            let zero = vec![Vector3::zeros(); lattice.node_count()];
            let limit = stability::estimate(&mut tled, &mass, &free, &zero, h, 500, 1e-8);
            let l_over_c = h / material.wave_speed();
            eprintln!("nu {nu} h {h}: dt_crit {:.3e} s = {:.3} L/c", limit.dt_critical, limit.dt_critical / l_over_c);
            assert!(
                stays_stable(&lattice, &material, 0.9 * limit.dt_critical, 3000),
                "0.9x limit unstable (nu {nu}, h {h})"
            );
            assert!(
                !stays_stable(&lattice, &material, 1.5 * limit.dt_critical, 3000),
                "1.5x limit stable (nu {nu}, h {h})"
            );
            // L/c is not a conservative bound here: the computed limit lies below it.
            assert!(limit.dt_critical < l_over_c, "nu {nu}: {} vs L/c {l_over_c}", limit.dt_critical);
        }
    }
}

/// Throughput probe (not a test of behaviour): `cargo test -p hullcut-sim --test integration -- --ignored --nocapture throughput`.
#[test]
#[ignore = "timing probe; run by hand"]
fn throughput_probe() {
    let side: usize = std::env::var("PROBE_SIDE").ok().and_then(|s| s.parse().ok()).unwrap_or(30);
    let lattice = Lattice::block(Point3::origin(), 0.005, [side; 3]);
    let material = Material::default();
    let mut tled = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
    let u: Vec<Vector3<f32>> =
        lattice.rest.iter().map(|p| Vector3::new(0.01 * p.y as f32, 0.0, 0.02 * p.x as f32)).collect();
    let mut f = vec![Vector3::zeros(); lattice.node_count()];
    let reps = (8e6 / lattice.cells.len() as f64).ceil() as usize;
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            tled.internal_forces(&u, &mut f);
            let t = std::time::Instant::now();
            for _ in 0..reps {
                tled.internal_forces(&u, &mut f);
            }
            let s = t.elapsed().as_secs_f64();
            eprintln!(
                "{side}^3 cells, {threads} threads: {:.1} M element-steps/s",
                (lattice.cells.len() * reps) as f64 / s / 1e6
            );
        });
    }
}
