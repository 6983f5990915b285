//! FLSM: rigid motions are goals, a resting body rests, a squashed body recovers its shape, momentum
//! is conserved, large steps stay stable, and the parameters are checked by key.

use std::time::Instant;

use hullcut_sim::{Flsm, FlsmParams, Lattice};
use nalgebra::{Point3, Rotation3, Vector3};

type V = Vector3<f32>;

/// Deterministic pseudo-random numbers in [-1, 1).
fn noise(seed: u64) -> impl FnMut() -> f32 {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

/// A 6 x 5 x 4 block of 5 mm cells with an L-shaped notch and a few cells missing inside.
fn l_block() -> Lattice {
    let dims = [6, 5, 4];
    let mut fraction = vec![1.0f32; 6 * 5 * 4];
    for k in 0..4 {
        for j in 0..5 {
            for i in 0..6 {
                if (i >= 3 && j >= 2) || (i * 7 + j * 3 + k * 5) % 13 == 0 {
                    fraction[i + 6 * (j + 5 * k)] = 0.0;
                }
            }
        }
    }
    Lattice::from_fractions(Point3::new(0.0, 0.0, 0.0), 0.005, dims, &fraction, 0.0)
}

fn rest(lattice: &Lattice) -> Vec<V> {
    lattice.rest.iter().map(|p| p.coords.cast::<f32>()).collect()
}

fn setup(lattice: &Lattice, params: FlsmParams) -> (Flsm, Vec<f64>) {
    let masses = lattice.lumped_masses(1000.0);
    (Flsm::new(lattice, &masses, params).expect("valid FLSM setup"), masses)
}

/// RMS relative length change of the lattice's axis-aligned edges: zero for any rigid motion.
fn edge_strain(lattice: &Lattice, x: &[V]) -> f64 {
    let mut sum = 0.0;
    let mut count = 0;
    for (n, ijk) in lattice.node_ijk.iter().enumerate() {
        for axis in 0..3 {
            let mut next = ijk.map(|a| a as usize);
            next[axis] += 1;
            if let Some(m) = lattice.node_at(next) {
                let len = f64::from((x[m as usize] - x[n]).norm());
                sum += (len / lattice.cell - 1.0).powi(2);
                count += 1;
            }
        }
    }
    (sum / f64::from(count)).sqrt()
}

fn momentum(masses: &[f64], x: &[V], v: &[V]) -> (Vector3<f64>, Vector3<f64>) {
    let mut p = Vector3::zeros();
    let mut l = Vector3::zeros();
    for ((m, x), v) in masses.iter().zip(x).zip(v) {
        let mv = v.cast::<f64>() * *m;
        p += mv;
        l += x.cast::<f64>().cross(&mv);
    }
    (p, l)
}

fn kinetic_energy(masses: &[f64], v: &[V]) -> f64 {
    masses.iter().zip(v).map(|(m, v)| 0.5 * m * f64::from(v.norm_squared())).sum()
}

#[test]
fn rigid_motions_are_their_own_goals() {
    let lattice = l_block();
    for w in [1, 2, 3] {
        let (mut flsm, _) = setup(&lattice, FlsmParams { w, ..FlsmParams::default() });
        for (axis, angle, shift) in [
            (Vector3::x(), 0.0, Vector3::new(0.3, -1.0, 0.02)),
            (Vector3::new(1.0, 2.0, -0.5), 1.0, Vector3::new(0.01, 0.2, -0.1)),
            (Vector3::new(-0.3, 0.1, 1.0), 2.5, Vector3::zeros()),
        ] {
            let rot = Rotation3::from_scaled_axis(axis.normalize() * angle);
            let x: Vec<V> = lattice.rest.iter().map(|p| (rot * p.coords + shift).cast::<f32>()).collect();
            let mut goals = vec![V::zeros(); x.len()];
            // A fresh solver: the rotation of every region comes from a cold start (identity).
            flsm.reset_rotations();
            flsm.compute_goals(&x, &mut goals);
            let worst = x.iter().zip(&goals).map(|(a, b)| (a - b).norm()).fold(0.0, f32::max);
            // 1e-5 m is the brief's bound (0.2 % of a 5 mm cell); f32 rounding of these positions is ~1e-7 m.
            assert!(worst < 1e-5, "w {w}, rotation {angle} rad: goal off the rigid position by {worst} m");
        }
    }
}

#[test]
fn a_body_at_rest_or_in_uniform_motion_stays_so() {
    let lattice = l_block();
    let (mut flsm, _) = setup(&lattice, FlsmParams::default());
    let x0 = rest(&lattice);
    let f = vec![V::zeros(); x0.len()];
    let dt = 0.01;
    for drift in [V::zeros(), V::new(0.02, -0.01, 0.005)] {
        let mut x = x0.clone();
        let mut v = vec![drift; x0.len()];
        for _ in 0..200 {
            flsm.step(&mut x, &mut v, &f, dt, None);
        }
        let t = 200.0 * dt;
        let off = x.iter().zip(&x0).map(|(x, r)| (x - (r + drift * t)).norm()).fold(0.0, f32::max);
        let dv = v.iter().map(|v| (v - drift).norm()).fold(0.0, f32::max);
        // Only f32 rounding of positions near 0.03 m (~2e-9 m per step, 200 steps) may move it.
        assert!(off < 1e-6, "drift {drift:?}: moved {off} m off the rigid path");
        assert!(dv < 1e-4, "drift {drift:?}: velocity changed by {dv} m/s");
    }
}

#[test]
fn a_squashed_body_recovers_its_shape() {
    let lattice = Lattice::block(Point3::origin(), 0.005, [6, 6, 6]);
    for w in [1, 2] {
        let (mut flsm, _) = setup(&lattice, FlsmParams { w, ..FlsmParams::default() });
        // Squash to 60 % height, bulging sideways as if volume were kept.
        let mut x: Vec<V> = lattice
            .rest
            .iter()
            .map(|p| {
                let c = p.coords - Vector3::repeat(0.015);
                (Vector3::new(c.x * 1.29, c.y * 1.29, c.z * 0.6) + Vector3::repeat(0.015)).cast::<f32>()
            })
            .collect();
        let mut v = vec![V::zeros(); x.len()];
        let f = vec![V::zeros(); x.len()];
        let initial = edge_strain(&lattice, &x);
        for _ in 0..300 {
            flsm.step(&mut x, &mut v, &f, 1.0 / 60.0, None);
        }
        let last = edge_strain(&lattice, &x);
        // The rest shape is the only shape with every region at its goal; with damping 0.1 per
        // step the oscillation about it decays to well under a tenth in 300 steps.
        assert!(last < 0.1 * initial, "w {w}: strain {initial} → {last}");
    }
}

#[test]
fn goal_pull_and_damping_conserve_momentum() {
    let lattice = l_block();
    let mut rnd = noise(21);
    let x0 = rest(&lattice);
    let x_start: Vec<V> = x0.iter().map(|p| p + V::new(rnd(), rnd(), rnd()) * 0.001).collect();
    let v_start: Vec<V> = x0.iter().map(|_| V::new(rnd(), rnd(), rnd()) * 0.05).collect();
    for damping in [0.0, 0.3] {
        let (mut flsm, masses) = setup(&lattice, FlsmParams { region_damping: damping, ..FlsmParams::default() });
        let (mut x, mut v) = (x_start.clone(), v_start.clone());
        let f = vec![V::zeros(); x.len()];
        let (p0, l0) = momentum(&masses, &x, &v);
        for _ in 0..100 {
            flsm.step(&mut x, &mut v, &f, 0.01, None);
        }
        let (p1, l1) = momentum(&masses, &x, &v);
        // Scale: the momentum the nodes carry in total, Σ m |v|.
        let scale: f64 = masses.iter().zip(&v_start).map(|(m, v)| m * f64::from(v.norm())).sum();
        // Linear momentum: exact up to f32 rounding of velocities (~1e-7 relative per step).
        assert!((p1 - p0).norm() < 1e-4 * scale, "damping {damping}: p {p0:?} → {p1:?}");
        if damping == 0.0 {
            // Angular momentum about the origin (within ~0.03 m of every node): exact for a converged
            // polar decomposition; damping towards the regions' mean linear velocity does not keep it.
            assert!((l1 - l0).norm() < 1e-4 * scale * 0.03, "L {l0:?} → {l1:?}");
        }
    }
}

#[test]
fn huge_time_steps_stay_stable() {
    let lattice = Lattice::block(Point3::origin(), 0.005, [6, 6, 6]);
    let mut rnd = noise(9);
    let x0 = rest(&lattice);
    // 0.05 s is ~10^4 times the explicit FEM limit of 5 mm cells of 20 kPa tissue (~5 µs).
    let dt = 0.05;
    for params in [
        FlsmParams { alpha: 1.0, region_damping: 0.0, ..FlsmParams::default() },
        FlsmParams::default(),
        FlsmParams { w: 3, alpha: 1.0, region_damping: 0.0 },
    ] {
        let (mut flsm, masses) = setup(&lattice, params);
        // Each node thrown half a cell off and moving a cell per step.
        let mut x: Vec<V> = x0.iter().map(|p| p + V::new(rnd(), rnd(), rnd()) * 0.0025).collect();
        let mut v: Vec<V> = x0.iter().map(|_| V::new(rnd(), rnd(), rnd()) * (0.005 / dt)).collect();
        let f = vec![V::zeros(); x.len()];
        let e0 = kinetic_energy(&masses, &v);
        let mut e_max: f64 = 0.0;
        let (mut strain_first, mut strain_max) = (0.0, 0.0f64);
        for step in 0..1000 {
            flsm.step(&mut x, &mut v, &f, dt, None);
            e_max = e_max.max(kinetic_energy(&masses, &v));
            strain_max = strain_max.max(edge_strain(&lattice, &x));
            if step == 0 {
                strain_first = strain_max;
            }
        }
        assert!(x.iter().chain(&v).all(|a| a.iter().all(|c| c.is_finite())), "{params:?}: not finite");
        // Per deformation mode the undamped update has determinant 1 (no growth) for any dt; the
        // energy moves between kinetic and goal-distance but stays within a small factor.
        assert!(e_max < 4.0 * e0, "{params:?}: kinetic energy {e0} rose to {e_max}");
        // The first step scrambles the lattice (strain ~0.9, regions inverted); undamped it keeps
        // sloshing at that level (0.5-1.0 seen) but must not grow.
        assert!(strain_max < 2.0 * strain_first, "{params:?}: strain {strain_first} grew to {strain_max}");
        if params.region_damping > 0.0 {
            let (p, _) = momentum(&masses, &x, &v);
            let total: f64 = masses.iter().sum();
            let drift = 0.5 * p.norm_squared() / total;
            let e_end = kinetic_energy(&masses, &v);
            // Damped: everything but the drift of the centre of mass has died out.
            assert!(e_end - drift < 1e-3 * e0, "{params:?}: kinetic energy {e0} → {e_end} (drift {drift})");
        }
    }
}

#[test]
fn a_held_bar_sags_under_gravity_and_keeps_its_shape() {
    // Held at x = 0 (those nodes inactive); 4 cm long, 1 cm thick; 1 s in steps of 1 ms.
    let lattice = Lattice::block(Point3::origin(), 0.005, [8, 2, 2]);
    let (mut flsm, masses) = setup(&lattice, FlsmParams { w: 2, ..FlsmParams::default() });
    let held: Vec<bool> = lattice.node_ijk.iter().map(|ijk| ijk[0] == 0).collect();
    let active: Vec<bool> = held.iter().map(|h| !h).collect();
    let x0 = rest(&lattice);
    let mut x = x0.clone();
    let mut v = vec![V::zeros(); x.len()];
    let f: Vec<V> = masses.iter().map(|m| V::new(0.0, 0.0, -9.81 * *m as f32)).collect();
    for _ in 0..1000 {
        flsm.step(&mut x, &mut v, &f, 1e-3, Some(&active));
    }
    for (i, h) in held.iter().enumerate() {
        if *h {
            assert_eq!(x[i], x0[i], "inactive node {i} moved");
            assert_eq!(v[i], V::zeros(), "inactive node {i} got a velocity");
        }
    }
    assert!(x.iter().chain(&v).all(|p| p.iter().all(|c| c.is_finite())));
    // FLSM's stiffness is set by the step, not a material: about α m / dt² = 0.1 N/m per node
    // here, so the free end drops by ~1 cm; it must drop, and the bar must bend, not stretch.
    let tip = x.iter().map(|p| p.z).fold(f32::INFINITY, f32::min);
    let strain = edge_strain(&lattice, &x);
    assert!(tip < -0.002 && tip > -0.04, "free end at z = {tip} m");
    assert!(strain < 0.1, "edge strain {strain}");
}

#[test]
fn inactive_nodes_are_untouched_and_results_do_not_depend_on_threads() {
    let lattice = l_block();
    let mut rnd = noise(4);
    let x0 = rest(&lattice);
    let x_start: Vec<V> = x0.iter().map(|p| p + V::new(rnd(), rnd(), rnd()) * 0.001).collect();
    let v_start: Vec<V> = x0.iter().map(|_| V::new(rnd(), rnd(), rnd()) * 0.05).collect();
    let active: Vec<bool> = (0..x0.len()).map(|i| i % 3 != 0).collect();
    let f: Vec<V> = x0.iter().map(|_| V::new(0.0, 0.0, -1e-4)).collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            let (mut flsm, _) = setup(&lattice, FlsmParams { w: 2, ..FlsmParams::default() });
            let (mut x, mut v) = (x_start.clone(), v_start.clone());
            for _ in 0..20 {
                flsm.step(&mut x, &mut v, &f, 0.01, Some(&active));
            }
            (x, v)
        })
    };
    let (x1, v1) = run(1);
    let (x3, v3) = run(3);
    assert_eq!(x1, x3);
    assert_eq!(v1, v3);
    for i in (0..x0.len()).filter(|&i| !active[i]) {
        assert_eq!(x1[i], x_start[i]);
        assert_eq!(v1[i], v_start[i]);
    }
    assert!((0..x0.len()).filter(|&i| active[i]).any(|i| x1[i] != x_start[i]));
}

#[test]
fn parameter_errors_name_the_key() {
    let lattice = l_block();
    let masses = lattice.lumped_masses(1000.0);
    for (params, key) in [
        (FlsmParams { w: 0, ..FlsmParams::default() }, "flsm.w"),
        (FlsmParams { w: usize::MAX, ..FlsmParams::default() }, "flsm.w"),
        (FlsmParams { alpha: 0.0, ..FlsmParams::default() }, "flsm.alpha"),
        (FlsmParams { alpha: 1.5, ..FlsmParams::default() }, "flsm.alpha"),
        (FlsmParams { alpha: f32::NAN, ..FlsmParams::default() }, "flsm.alpha"),
        (FlsmParams { region_damping: -0.1, ..FlsmParams::default() }, "flsm.region_damping"),
        (FlsmParams { region_damping: 1.01, ..FlsmParams::default() }, "flsm.region_damping"),
    ] {
        let err = Flsm::new(&lattice, &masses, params).expect_err("invalid parameters");
        assert!(err.to_string().contains(key), "{params:?}: `{err}` does not name {key}");
        assert!(params.validate().is_err());
    }
    assert!(FlsmParams::default().validate().is_ok());
    assert!(FlsmParams { w: 4, alpha: 1.0, region_damping: 0.0 }.validate().is_ok());
}

/// Throughput on a 30 x 30 x 30-cell block (29,791 nodes; `PROBE_SIDE` sets the side) for w = 1, 2, 4;
/// prints, asserts nothing.
/// `cargo test --release -p hullcut-sim --test integration flsm_throughput -- --ignored --nocapture`
#[test]
#[ignore = "timing, run by hand in release"]
fn flsm_throughput() {
    let side: usize = std::env::var("PROBE_SIDE").ok().and_then(|s| s.parse().ok()).unwrap_or(30);
    let lattice = Lattice::block(Point3::origin(), 0.005, [side; 3]);
    let mut rnd = noise(1);
    let x0 = rest(&lattice);
    let f = vec![V::zeros(); x0.len()];
    println!("threads: {}", rayon::current_num_threads());
    // On a rayon worker, as `hullcut sim` steps: parallel passes start on the stepping thread.
    rayon::scope(|_| flsm_throughput_on(&lattice, &x0, &f, &mut rnd));
}

fn flsm_throughput_on(lattice: &Lattice, x0: &[V], f: &[V], rnd: &mut impl FnMut() -> f32) {
    for w in [1, 2, 4] {
        let (mut flsm, _) = setup(lattice, FlsmParams { w, ..FlsmParams::default() });
        let mut x: Vec<V> = x0.iter().map(|p| p + V::new(rnd(), rnd(), rnd()) * 0.0005).collect();
        let mut v = vec![V::zeros(); x.len()];
        for _ in 0..5 {
            flsm.step(&mut x, &mut v, f, 0.01, None);
        }
        let steps = 100;
        let start = Instant::now();
        let mut iterations = 0;
        for _ in 0..steps {
            flsm.step(&mut x, &mut v, f, 0.01, None);
            iterations += flsm.polar_iterations();
        }
        let secs = start.elapsed().as_secs_f64();
        let rate = (steps * x.len()) as f64 / secs;
        println!(
            "w {w}: {:.2} ms/step, {:.2e} particle-steps/s, {:.2} polar iterations per region",
            1e3 * secs / steps as f64,
            rate,
            iterations as f64 / (steps * x.len()) as f64
        );
    }
}
