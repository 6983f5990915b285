//! Whole-simulation checks against beam theory: convergence under refinement and the behaviour of
//! nearly incompressible tissue. Test names start with `slow_` (seconds each): skip with `--skip slow_`.

use hullcut_sim::{NodeRole, Scenario, Simulation};

/// Timoshenko tip deflection of a clamped square-section cantilever under its own weight:
/// `q L⁴ / (8 E I) + q L² / (2 k G A)` with q = ρ g A, I = b⁴/12, k = 5/6.
fn timoshenko_tip(e: f64, nu: f64, rho: f64, length: f64, side: f64) -> f64 {
    let (a, i) = (side * side, side.powi(4) / 12.0);
    let q = rho * 9.81 * a;
    let g = e / (2.0 * (1.0 + nu));
    q * length.powi(4) / (8.0 * e * i) + q * length * length / (2.0 * 5.0 / 6.0 * g * a)
}

/// Tip deflection (downwards, metres) of a 10 x 2 x 2 cm cantilever at lattice spacing `cell`.
fn cantilever_tip(cell: f64, e: f64, nu: f64, integration: &str) -> f64 {
    let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let mu = e / (2.0 * (1.0 + nu));
    let text = format!(
        "[body]\nshape = \"box\"\nsize = [0.1, 0.02, 0.02]\ncell = {cell}\n\
         [material]\nlambda = {lambda}\nmu = {mu}\ndensity = 1000.0\n\
         [tled]\nintegration = \"{integration}\"\n\
         [[boundary]]\nfaces = [\"x-\"]\nfix = [\"x\", \"y\", \"z\"]\n\
         [run]\nduration = 0.15\ndamping = 300.0\ngravity = [0.0, 0.0, -9.81]\n\
         [report]\nprobes = [[0.1, 0.01, 0.01]]\n"
    );
    let scenario = Scenario::parse(&text, "cantilever").expect("scenario");
    let mut sim = Simulation::from_scenario(&scenario).expect("setup");
    while sim.time() < scenario.run.duration {
        sim.advance().expect("stable");
    }
    let probes = sim.probe_displacements();
    -probes[0].1.expect("tip inside")[2]
}

#[test]
fn slow_cantilever_converges_to_beam_theory_under_refinement() {
    // E = 5 MPa, ν = 0.3: the sag is 0.8% of the length, so small-deflection theory applies.
    let (e, nu) = (5e6, 0.3);
    let reference = timoshenko_tip(e, nu, 1000.0, 0.1, 0.02);
    let cells = [0.01, 0.005, 0.0025];
    let errors: Vec<f64> = cells
        .iter()
        .map(|&h| {
            let tip = cantilever_tip(h, e, nu, "one-point");
            eprintln!(
                "cell {h} m: tip {tip:.6e} m, reference {reference:.6e} m, error {:+.2}%",
                100.0 * (tip / reference - 1.0)
            );
            (tip / reference - 1.0).abs()
        })
        .collect();
    // The error shrinks with every refinement, and the finest lattice (8 cells through the
    // thickness) is within 3% of Timoshenko theory (whose own shear correction is ~4% of the sag).
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "errors {errors:?} do not decrease");
    assert!(errors[2] < 0.03, "finest error {:.2}%", 100.0 * errors[2]);
}

#[test]
fn slow_nearly_incompressible_one_point_does_not_lock() {
    // Beam bending is governed by E (ν enters only the small shear term), so a discretisation that
    // does not lock gives nearly the same sag at ν = 0.45 and 0.49 as beam theory. Full 2x2x2 Gauss
    // integration locks: its sag collapses as ν → 0.5. That contrast is how we know.
    let e = 5e6;
    let results: Vec<(f64, f64, f64)> = [0.3, 0.45, 0.49]
        .iter()
        .map(|&nu| {
            let reference = timoshenko_tip(e, nu, 1000.0, 0.1, 0.02);
            let one_point = cantilever_tip(0.005, e, nu, "one-point") / reference;
            let gauss = cantilever_tip(0.005, e, nu, "gauss8") / reference;
            eprintln!("nu {nu}: one-point {one_point:.3} x theory, gauss8 {gauss:.3} x theory");
            (nu, one_point, gauss)
        })
        .collect();
    for &(nu, one_point, gauss) in &results[1..] {
        assert!((one_point - 1.0).abs() < 0.1, "nu {nu}: one-point sag {one_point:.3} x theory");
        assert!(gauss < one_point, "nu {nu}: gauss8 {gauss:.3} should be stiffer than one-point {one_point:.3}");
        if nu == 0.49 {
            assert!(gauss < 0.8, "gauss8 should lock at nu 0.49: {gauss:.3} x theory");
        }
    }
}

fn organ_scenario(ratio: f64, gravity: f64, extra: &str) -> Scenario {
    let text = format!(
        "[body]\nshape = \"organ\"\ncell = 0.01\n[hybrid]\nratio = {ratio}\n{extra}\
         [[boundary]]\nbox = {{ min = [-1.0, -1.0, -0.001], max = [1.0, 1.0, 0.004] }}\nfix = [\"x\", \"y\", \"z\"]\n\
         [run]\nduration = 0.1\ndamping = 30.0\ngravity = [0.0, 0.0, {gravity}]\n"
    );
    Scenario::parse(&text, "organ").expect("scenario")
}

fn run(s: &Scenario) -> Simulation {
    let mut sim = Simulation::from_scenario(s).expect("setup");
    while sim.time() < s.run.duration {
        sim.advance().expect("stable");
    }
    sim
}

#[test]
fn hybrid_at_rest_stays_at_rest() {
    // No load: the interface pull must not inject energy (an explicit β(g − x) on light boundary
    // nodes did, and diverged within a few steps).
    let sim = run(&organ_scenario(0.4, 0.0, ""));
    assert!(sim.roles.contains(&NodeRole::Interface), "the split has an interface");
    let worst = sim.integrator.u.iter().map(|u| u.norm()).fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "a body at rest moved {worst} m");
}

#[test]
fn hybrid_with_everything_operational_equals_tled() {
    let tled = run(&organ_scenario(1.0, -9.81, ""));
    let all = run(&organ_scenario(0.2, -9.81, "operational = { center = [0.0, 0.0, 0.03], radius = 1.0 }\n"));
    assert_eq!(all.tled_cells(), all.lattice.cells.len());
    let diff = tled.integrator.u.iter().zip(&all.integrator.u).map(|(a, b)| (a - b).norm()).fold(0.0f32, f32::max);
    assert!(diff < 1e-9, "{diff}");
    // And a true hybrid sags under gravity, stays stable, and keeps its fixed base in place.
    let hybrid = run(&organ_scenario(0.4, -9.81, ""));
    let base = hybrid
        .lattice
        .rest
        .iter()
        .zip(&hybrid.integrator.u)
        .filter(|(p, _)| p.z < 0.004)
        .map(|(_, u)| u.norm())
        .fold(0.0f32, f32::max);
    assert!(base == 0.0, "fixed base moved {base} m");
    let sag = hybrid.integrator.u.iter().map(|u| -u.z).fold(0.0f32, f32::max);
    assert!(sag > 0.0, "the hybrid does not sag");
}

/// RMS and largest node displacement difference between two runs of one lattice, metres.
fn displacement_difference(a: &Simulation, b: &Simulation) -> (f64, f64) {
    let d: Vec<f64> = a.integrator.u.iter().zip(&b.integrator.u).map(|(p, q)| f64::from((p - q).norm())).collect();
    ((d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt(), d.iter().copied().fold(0.0, f64::max))
}

#[test]
fn a_hybrid_with_flsm_matched_to_the_material_sags_like_tled() {
    // The organ sagging under gravity (0.3 s, nearly settled at damping 30/s). By default FLSM's
    // step and stiffness and the interface pull are matched to the material (`match_flsm`); the
    // seed's settings (an FLSM step every 10 TLED steps, β = 200 N/m) make FLSM hundreds of times
    // softer than the tissue, and its nodes sag far more.
    let scenario = |ratio: f64, extra: &str| {
        let text = format!(
            "[body]\nshape = \"organ\"\ncell = 0.01\n[hybrid]\nratio = {ratio}\n{extra}\
             [[boundary]]\nbox = {{ min = [-1.0, -1.0, -0.001], max = [1.0, 1.0, 0.004] }}\nfix = [\"x\", \"y\", \"z\"]\n\
             [run]\nduration = 0.3\ndamping = 30.0\ngravity = [0.0, 0.0, -9.81]\n"
        );
        Scenario::parse(&text, "organ").expect("scenario")
    };
    let tled = run(&scenario(1.0, ""));
    let sag = tled.integrator.u.iter().map(|u| f64::from(-u.z)).fold(0.0, f64::max);
    let matched = run(&scenario(0.4, ""));
    let steps = matched.hybrid_steps().expect("a hybrid");
    let seed = run(&scenario(0.4, "substeps = 10\nbeta = 200.0\n"));
    let (rms_matched, max_matched) = displacement_difference(&tled, &matched);
    let (rms_seed, max_seed) = displacement_difference(&tled, &seed);
    eprintln!(
        "sag {sag:.3e} m; matched ({steps:?}): rms {rms_matched:.3e} max {max_matched:.3e}; seed: rms {rms_seed:.3e} max {max_seed:.3e}"
    );
    assert!(rms_matched < 0.15 * sag, "matched hybrid: rms {rms_matched} m against a sag of {sag} m");
    assert!(rms_seed > 3.0 * rms_matched, "seed settings: rms {rms_seed} m, matched {rms_matched} m");
}

#[test]
fn a_node_on_two_reaction_faces_counts_toward_both() {
    // A 4 cm cube clamped at its base, settling under gravity: the base's reaction carries the
    // weight. Listing the base twice reports it twice; the x- face (held only along its bottom
    // edge, which it shares with the base) reports that edge's share, which used to go to the
    // first face only.
    let text = "[body]\nshape = \"box\"\nsize = [0.04, 0.04, 0.04]\ncell = 0.01\n\
                [[boundary]]\nfaces = [\"z-\"]\nfix = [\"x\", \"y\", \"z\"]\n\
                [run]\nduration = 0.4\ndamping = 60.0\ngravity = [0.0, 0.0, -9.81]\n\
                [report]\nreaction = [\"z-\", \"z-\", \"x-\"]\n";
    let scenario = Scenario::parse(text, "cube").expect("scenario");
    let sim = run(&scenario);
    let r = &sim.integrator.reactions;
    let weight = 1000.0 * 0.04f64.powi(3) * 9.81;
    assert_eq!(r[0], r[1], "the same face listed twice");
    assert!((r[0].z - weight).abs() < 0.01 * weight, "base reaction {} N, weight {weight} N", r[0].z);
    assert!(r[2].z > 0.0 && r[2].z < r[0].z, "the shared edge's share: {} N of {} N", r[2].z, r[0].z);
}

/// The free-lateral uniaxial stretch of the seed's neo-Hookean, `S = μ(I − C⁻¹) + λJ(J−1)C⁻¹`, to
/// `F = diag(s, t, t)`: the lateral stretch `t` makes `S_yy = 0`, that is
/// `μ(t² − 1) + λJ(J − 1) = 0` with `J = s t²` (bisection: the left side grows with `t`); the
/// reaction on the pulled face is `P_xx A = s S_xx A`. Returns `(t, reaction)`.
fn free_lateral_uniaxial(lambda: f64, mu: f64, s: f64, area: f64) -> (f64, f64) {
    let lateral = |t: f64| {
        let j = s * t * t;
        mu * (t * t - 1.0) + lambda * j * (j - 1.0)
    };
    let (mut lo, mut hi) = (0.1, 1.0);
    assert!(lateral(lo) < 0.0 && lateral(hi) > 0.0, "the root lies in (0.1, 1) for a stretch");
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if lateral(mid) > 0.0 { hi = mid } else { lo = mid }
    }
    let t = 0.5 * (lo + hi);
    let j = s * t * t;
    let s_xx = mu * (1.0 - 1.0 / (s * s)) + lambda * j * (j - 1.0) / (s * s);
    (t, s * s_xx * area)
}

#[test]
fn a_cube_stretched_with_free_sides_matches_the_closed_form_reaction_and_contraction() {
    // A 5 cm cube on rollers (x- held in x, y- in y, z- in z: free to contract sideways), its x+
    // face pulled 5 mm along x only (`components = ["x"]`), so y and z stay free there too. The
    // deformation is homogeneous, which trilinear cells represent exactly: what is left is the
    // dynamics, settled by damping after the ramp.
    let (lambda, mu, side, pull) = (30_000.0, 20_000.0, 0.05, 0.005);
    let text = format!(
        "[body]\nshape = \"box\"\nsize = [{side}, {side}, {side}]\ncell = 0.01\n\
         [material]\nlambda = {lambda}\nmu = {mu}\ndensity = 1000.0\n\
         [[boundary]]\nfaces = [\"x-\"]\nfix = [\"x\"]\n\
         [[boundary]]\nfaces = [\"y-\"]\nfix = [\"y\"]\n\
         [[boundary]]\nfaces = [\"z-\"]\nfix = [\"z\"]\n\
         [[boundary]]\nfaces = [\"x+\"]\ndisplace = [{pull}, 0.0, 0.0]\ncomponents = [\"x\"]\nramp = 0.5\n\
         [run]\nduration = 1.5\ndamping = 60.0\n\
         [report]\nreaction = [\"x+\"]\nprobes = [[{side}, {side}, {side}]]\n"
    );
    let scenario = Scenario::parse(&text, "free-lateral").expect("scenario");
    let sim = run(&scenario);
    let (t, expected) = free_lateral_uniaxial(lambda, mu, 1.0 + pull / side, side * side);
    let reaction = sim.integrator.reactions[0].x;
    // The closed form is exact for this mesh; 1% leaves room for the f32 state and the residual
    // motion after 1 s of damping (e^{-30} of the ramp's transient).
    assert!((reaction - expected).abs() < 0.01 * expected, "reaction {reaction} N, closed form {expected} N");
    let corner = sim.probe_displacements()[0].1.expect("the corner is in the body");
    let contraction = -corner[1] / side;
    let exact = 1.0 - t;
    eprintln!(
        "reaction {reaction:.6} N (closed form {expected:.6} N); lateral contraction {contraction:.6} ({exact:.6})"
    );
    assert!((contraction - exact).abs() < 0.02 * exact, "lateral contraction {contraction}, closed form {exact}");
    assert!((corner[1] - corner[2]).abs() < 1e-6, "y and z contract alike: {corner:?}");
    // Clamping the pulled face sideways (no `components`) is a different test: a stiffer reaction.
    let clamped = Scenario::parse(&text.replace("components = [\"x\"]\n", ""), "clamped").expect("scenario");
    let stiffer = run(&clamped).integrator.reactions[0].x;
    assert!(stiffer > 1.02 * reaction, "clamped {stiffer} N vs free {reaction} N");
}

#[test]
fn components_are_checked() {
    let base = "[body]\nshape = \"box\"\nsize = [0.02, 0.02, 0.02]\ncell = 0.01\n\
                [[boundary]]\nfaces = [\"x-\"]\nfix = [\"x\", \"y\", \"z\"]\n\
                [[boundary]]\nfaces = [\"x+\"]\nBOUNDARY\n";
    for (boundary, expected) in [
        ("fix = [\"y\"]\ncomponents = [\"x\"]", "needs `displace`"),
        ("displace = [0.001, 0.0, 0.0]\ncomponents = []", "lists no component"),
        ("displace = [0.001, 0.0, 0.0]\ncomponents = [\"x\", \"x\"]", "twice"),
        ("displace = [0.001, 0.0, 0.0]\ncomponents = [\"w\"]", "unknown component"),
        ("displace = [0.001, 0.0, 0.0]\ncomponents = [\"x\", \"y\", \"z\", \"x\"]", "boundary[1].components"),
    ] {
        let text = base.replace("BOUNDARY", boundary);
        let e = match Scenario::parse(&text, "components") {
            Err(e) => e.to_string(),
            Ok(s) => Simulation::from_scenario(&s).map(|_| ()).expect_err(boundary).to_string(),
        };
        assert!(e.contains(expected), "{boundary}: {e}");
    }
}
