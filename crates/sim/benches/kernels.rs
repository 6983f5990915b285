//! Criterion benchmarks of the simulator's kernels on the 30 x 30 x 30-cell block of the seed's
//! liver material at 5 mm cells (29,791 nodes): the TLED element pass, the element pass with the
//! node gather, one whole TLED step (element pass, then the gather fused into the central-difference
//! update), and one FLSM step (w = 1).
//!
//! `cargo bench -p hullcut-sim --bench kernels`. Each measurement runs on a rayon worker, as
//! `hullcut sim` steps, so the parallel passes start on the measuring thread.

use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use hullcut_sim::dynamics::Integrator;
use hullcut_sim::{Flsm, FlsmParams, Lattice, Material, Tled, TledParams};
use nalgebra::{Point3, Vector3};

const SIDE: usize = 30;
const CELL: f64 = 0.005;

fn block() -> Lattice {
    Lattice::block(Point3::origin(), CELL, [SIDE; 3])
}

/// A smooth shear and bend of the block: every cell deformed, none inverted.
fn deformation(lattice: &Lattice) -> Vec<Vector3<f32>> {
    lattice
        .rest
        .iter()
        .map(|p| Vector3::new(0.05 * p.y, 0.02 * p.z, 0.04 * p.x * p.x / (SIDE as f64 * CELL)).cast::<f32>())
        .collect()
}

/// Times `iters` calls of `op` on a rayon worker.
fn on_worker(iters: u64, mut op: impl FnMut() + Send) -> Duration {
    rayon::scope(|_| {
        let start = Instant::now();
        for _ in 0..iters {
            op();
        }
        start.elapsed()
    })
}

fn tled(c: &mut Criterion) {
    let lattice = block();
    let material = Material::default();
    let u = deformation(&lattice);
    let mut group = c.benchmark_group("tled");
    group.throughput(Throughput::Elements(lattice.cells.len() as u64));

    let mut model = Tled::new(&lattice, None, &material, TledParams::default()).expect("tled");
    group.bench_function("element_pass", |b| b.iter_custom(|iters| on_worker(iters, || model.element_pass(&u))));

    let mut forces = vec![Vector3::zeros(); lattice.node_count()];
    group.bench_function("internal_forces", |b| {
        b.iter_custom(|iters| on_worker(iters, || model.internal_forces(&u, &mut forces)))
    });

    // A whole explicit step: masses lumped, no damping, a step well inside the stable range.
    let masses: Vec<f32> = lattice.lumped_masses(material.density).iter().map(|&m| m as f32).collect();
    let mut integrator = Integrator::new(masses, Vec::new(), 0, 0.0, 1e-5, f32::INFINITY);
    integrator.u.clone_from(&u);
    integrator.u_prev.clone_from(&u);
    let f_ext = vec![Vector3::zeros(); lattice.node_count()];
    group.bench_function("step", |b| {
        b.iter_custom(|iters| {
            on_worker(iters, || {
                model.element_pass(&integrator.u);
                let model = &model;
                integrator.advance_with(|i| model.node_force(i), &f_ext).expect("a stable step");
            })
        })
    });
    group.finish();
}

fn flsm(c: &mut Criterion) {
    let lattice = block();
    let masses = lattice.lumped_masses(Material::default().density);
    let mut model = Flsm::new(&lattice, &masses, FlsmParams::default()).expect("flsm");
    let mut x: Vec<Vector3<f32>> =
        lattice.rest.iter().zip(deformation(&lattice)).map(|(p, u)| p.coords.cast::<f32>() + u).collect();
    let mut v = vec![Vector3::zeros(); x.len()];
    let f_ext = vec![Vector3::zeros(); x.len()];
    let mut group = c.benchmark_group("flsm");
    group.throughput(Throughput::Elements(x.len() as u64));
    group.bench_function("step_w1", |b| {
        b.iter_custom(|iters| on_worker(iters, || model.step(&mut x, &mut v, &f_ext, 5e-4, None)))
    });
    group.finish();
}

criterion_group!(kernels, tled, flsm);
criterion_main!(kernels);
