//! TLED internal forces on the GPU (wgpu, WGSL): the same one-point hexahedra with
//! Flanagan–Belytschko hourglass control as [`crate::Tled`], in two passes without atomics: an
//! element pass (one invocation per cell, writing its eight nodal forces) and a node pass (one
//! invocation per node, gathering through the node → (cell, corner) list).
//!
//! A cell whose det F falls below [`crate::tled::INVERSION_J`] is flagged and counted; unlike the
//! CPU kernel the GPU pass does not regularize it (its force is the neo-Hookean force of the
//! unregularized F), so callers treat a nonzero count as a reason to fall back to the CPU.

use bytemuck::{Pod, Zeroable};
use hullcut_gpu::Gpu;
use nalgebra::Vector3;

use crate::SimError;
use crate::tled::{INVERSION_J, Integration, Tled};

/// Invocations per workgroup of both passes.
const WORKGROUP: u32 = 64;

/// The kernels' shared constants (a uniform buffer; 32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Params {
    cells: u32,
    nodes: u32,
    inv4h: f32,
    lambda: f32,
    mu: f32,
    kappa_per_volume: f32,
    inversion_j: f32,
    pad: u32,
}

const PARAMS_WGSL: &str = "
struct Params {
    cells: u32,
    nodes: u32,
    inv4h: f32,
    lambda: f32,
    mu: f32,
    kappa_per_volume: f32,
    inversion_j: f32,
    pad: u32,
}
@group(0) @binding(0) var<uniform> p: Params;
";

/// Element pass: cell `c`'s eight nodal forces to `cell_forces[24 c + 3 a ..]`.
const ELEMENT_WGSL: &str = "
@group(0) @binding(1) var<storage, read> cell_nodes: array<u32>;
@group(0) @binding(2) var<storage, read> volume: array<f32>;
@group(0) @binding(3) var<storage, read> u: array<f32>;
@group(0) @binding(4) var<storage, read_write> cell_forces: array<f32>;
@group(0) @binding(5) var<storage, read_write> inverted: array<u32>;

fn sign(a: u32, bit: u32) -> f32 {
    return select(-1.0, 1.0, (a & bit) != 0u);
}

@compute @workgroup_size(64)
fn element(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = gid.x;
    if (c >= p.cells) {
        return;
    }
    // Column sums d_k = sum_a u_a s_ak and hourglass sums q_m = sum_a h_am u_a.
    var d0 = vec3<f32>(0.0);
    var d1 = vec3<f32>(0.0);
    var d2 = vec3<f32>(0.0);
    var q0 = vec3<f32>(0.0);
    var q1 = vec3<f32>(0.0);
    var q2 = vec3<f32>(0.0);
    var q3 = vec3<f32>(0.0);
    for (var a = 0u; a < 8u; a++) {
        let n = cell_nodes[8u * c + a];
        let ua = vec3<f32>(u[3u * n], u[3u * n + 1u], u[3u * n + 2u]);
        let sx = sign(a, 1u);
        let sy = sign(a, 2u);
        let sz = sign(a, 4u);
        d0 += ua * sx;
        d1 += ua * sy;
        d2 += ua * sz;
        q0 += ua * (sy * sz);
        q1 += ua * (sx * sz);
        q2 += ua * (sx * sy);
        q3 += ua * (sx * sy * sz);
    }
    // F = I + (1/4h) [d0 d1 d2] (columns).
    let f = mat3x3<f32>(
        vec3<f32>(1.0, 0.0, 0.0) + d0 * p.inv4h,
        vec3<f32>(0.0, 1.0, 0.0) + d1 * p.inv4h,
        vec3<f32>(0.0, 0.0, 1.0) + d2 * p.inv4h,
    );
    let j = determinant(f);
    inverted[c] = select(0u, 1u, j < p.inversion_j || j != j);
    // C = F^T F; C^-1 = adj(C) / J^2.
    let cm = transpose(f) * f;
    let c00 = cm[0][0];
    let c01 = cm[1][0];
    let c02 = cm[2][0];
    let c11 = cm[1][1];
    let c12 = cm[2][1];
    let c22 = cm[2][2];
    let inv_det = 1.0 / (j * j);
    let i00 = (c11 * c22 - c12 * c12) * inv_det;
    let i01 = (c02 * c12 - c01 * c22) * inv_det;
    let i02 = (c01 * c12 - c02 * c11) * inv_det;
    let i11 = (c00 * c22 - c02 * c02) * inv_det;
    let i12 = (c01 * c02 - c00 * c12) * inv_det;
    let i22 = (c00 * c11 - c01 * c01) * inv_det;
    // S = mu I + (lambda J (J - 1) - mu) C^-1; P = F S, scaled by V / (4h).
    let w = p.lambda * j * (j - 1.0) - p.mu;
    let s = mat3x3<f32>(
        vec3<f32>(p.mu + w * i00, w * i01, w * i02),
        vec3<f32>(w * i01, p.mu + w * i11, w * i12),
        vec3<f32>(w * i02, w * i12, p.mu + w * i22),
    );
    let vol = volume[c];
    let pk = f * s * (vol * p.inv4h);
    let kappa = p.kappa_per_volume * vol;
    for (var a = 0u; a < 8u; a++) {
        let sx = sign(a, 1u);
        let sy = sign(a, 2u);
        let sz = sign(a, 4u);
        let fa = pk * vec3<f32>(sx, sy, sz)
            + kappa * (q0 * (sy * sz) + q1 * (sx * sz) + q2 * (sx * sy) + q3 * (sx * sy * sz));
        let o = 24u * c + 3u * a;
        cell_forces[o] = fa.x;
        cell_forces[o + 1u] = fa.y;
        cell_forces[o + 2u] = fa.z;
    }
}
";

/// Node pass: node `n`'s force, the sum of its cells' corner forces.
const GATHER_WGSL: &str = "
@group(0) @binding(1) var<storage, read> offsets: array<u32>;
@group(0) @binding(2) var<storage, read> entries: array<u32>;
@group(0) @binding(3) var<storage, read> cell_forces: array<f32>;
@group(0) @binding(4) var<storage, read_write> forces: array<f32>;

@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= p.nodes) {
        return;
    }
    var f = vec3<f32>(0.0);
    for (var e = offsets[n]; e < offsets[n + 1u]; e++) {
        let o = 3u * entries[e];
        f += vec3<f32>(cell_forces[o], cell_forces[o + 1u], cell_forces[o + 2u]);
    }
    forces[3u * n] = f.x;
    forces[3u * n + 1u] = f.y;
    forces[3u * n + 2u] = f.z;
}
";

/// TLED's internal forces on a GPU, for the cells of a CPU [`Tled`].
#[derive(Debug)]
pub struct GpuTled<'g> {
    gpu: &'g Gpu,
    cells: u32,
    nodes: u32,
    u: wgpu::Buffer,
    forces: wgpu::Buffer,
    inverted: wgpu::Buffer,
    element: (wgpu::ComputePipeline, wgpu::BindGroup),
    gather: (wgpu::ComputePipeline, wgpu::BindGroup),
}

impl<'g> GpuTled<'g> {
    /// Uploads `tled`'s cells (node lists, volumes, constants) and its gather list to `gpu`.
    /// Only one-point integration runs on the GPU.
    pub fn new(gpu: &'g Gpu, tled: &Tled) -> Result<Self, SimError> {
        if tled.params.integration != Integration::OnePoint {
            return Err(SimError::Gpu("only one-point integration runs on the GPU (tled.integration)".into()));
        }
        let gpu_err = |e: hullcut_gpu::GpuError| SimError::Gpu(e.to_string());
        let (cells, nodes) = (tled.cell_nodes.len(), tled.node_count);
        let k = tled.one_point_constants();
        let params = Params {
            cells: cells as u32,
            nodes: nodes as u32,
            inv4h: k.inv4h,
            lambda: k.lambda,
            mu: k.mu,
            kappa_per_volume: k.kappa_per_volume,
            inversion_j: INVERSION_J,
            pad: 0,
        };
        // The node → (cell, corner) list, as cell * 8 + corner.
        let mut offsets = vec![0u32; nodes + 1];
        for c in &tled.cell_nodes {
            for &n in c {
                offsets[n as usize + 1] += 1;
            }
        }
        for i in 1..=nodes {
            offsets[i] += offsets[i - 1];
        }
        let mut fill = offsets.clone();
        let mut entries = vec![0u32; offsets[nodes] as usize];
        for (c, corners) in tled.cell_nodes.iter().enumerate() {
            for (a, &n) in corners.iter().enumerate() {
                entries[fill[n as usize] as usize] = (8 * c + a) as u32;
                fill[n as usize] += 1;
            }
        }
        let uniform = gpu.uniform("tled params", &params);
        let cell_nodes = gpu.storage("cell nodes", tled.cell_nodes.as_flattened()).map_err(gpu_err)?;
        let volume = gpu.storage("cell volumes", &tled.volume).map_err(gpu_err)?;
        let u = gpu.storage("displacements", &vec![0.0f32; 3 * nodes]).map_err(gpu_err)?;
        let cell_forces = gpu.storage("cell forces", &vec![0.0f32; 24 * cells]).map_err(gpu_err)?;
        let inverted = gpu.storage("inverted cells", &vec![0u32; cells]).map_err(gpu_err)?;
        let offsets = gpu.storage("gather offsets", &offsets).map_err(gpu_err)?;
        let entries = gpu.storage("gather entries", &entries).map_err(gpu_err)?;
        let forces = gpu.storage("nodal forces", &vec![0.0f32; 3 * nodes]).map_err(gpu_err)?;
        let element_pipeline = gpu.pipeline("tled element pass", &format!("{PARAMS_WGSL}{ELEMENT_WGSL}"), "element");
        let element_bind = gpu.bind(&element_pipeline, &[&uniform, &cell_nodes, &volume, &u, &cell_forces, &inverted]);
        let gather_pipeline = gpu.pipeline("tled node pass", &format!("{PARAMS_WGSL}{GATHER_WGSL}"), "gather");
        let gather_bind = gpu.bind(&gather_pipeline, &[&uniform, &offsets, &entries, &cell_forces, &forces]);
        Ok(Self {
            gpu,
            cells: cells as u32,
            nodes: nodes as u32,
            u,
            forces,
            inverted,
            element: (element_pipeline, element_bind),
            gather: (gather_pipeline, gather_bind),
        })
    }

    /// Internal nodal forces for displacements `u` into `out` (one per node); returns the number
    /// of cells flagged as inverted (det F below [`INVERSION_J`]).
    pub fn internal_forces(&mut self, u: &[Vector3<f32>], out: &mut [Vector3<f32>]) -> Result<usize, SimError> {
        let n = self.nodes as usize;
        if u.len() != n || out.len() != n {
            return Err(SimError::Gpu(format!("{} displacements and {} forces for {n} nodes", u.len(), out.len())));
        }
        let flat: Vec<f32> = u.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
        self.gpu.queue.write_buffer(&self.u, 0, bytemuck::cast_slice(&flat));
        self.gpu.dispatch(&self.element.0, &self.element.1, self.cells, WORKGROUP);
        self.gpu.dispatch(&self.gather.0, &self.gather.1, self.nodes, WORKGROUP);
        let gpu_err = |e: hullcut_gpu::GpuError| SimError::Gpu(e.to_string());
        let forces: Vec<f32> = self.gpu.read("nodal forces", &self.forces, 3 * n).map_err(gpu_err)?;
        for (o, f) in out.iter_mut().zip(forces.chunks_exact(3)) {
            *o = Vector3::new(f[0], f[1], f[2]);
        }
        let flags: Vec<u32> = self.gpu.read("inverted cells", &self.inverted, self.cells as usize).map_err(gpu_err)?;
        Ok(flags.iter().filter(|&&f| f != 0).count())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Lattice, Material, TledParams};
    use nalgebra::Point3;

    /// A lattice with holes and partly filled cells, and a large smooth deformation with
    /// node-wise noise (so the hourglass terms are exercised).
    fn case() -> (Lattice, Vec<Vector3<f32>>) {
        let dims = [14, 9, 7];
        let fractions: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|c| {
                if c % 11 == 4 {
                    0.0
                } else if c % 7 == 2 {
                    0.5
                } else {
                    1.0
                }
            })
            .collect();
        let lattice = Lattice::from_fractions(Point3::origin(), 0.01, dims, &fractions, 0.0);
        let u = crate::tled::test_deformation(&lattice);
        (lattice, u)
    }

    #[test]
    fn gpu_forces_match_the_cpu_within_f32_rounding() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let (lattice, u) = case();
        let mut cpu = Tled::new(&lattice, None, &Material::default(), TledParams::default()).expect("tled");
        let mut expected = vec![Vector3::zeros(); lattice.node_count()];
        cpu.internal_forces(&u, &mut expected);
        assert_eq!(cpu.inverted_cells(), 0, "the case must not need regularization");
        let mut on_gpu = GpuTled::new(&gpu, &cpu).expect("gpu tled");
        let mut got = vec![Vector3::zeros(); lattice.node_count()];
        assert_eq!(on_gpu.internal_forces(&u, &mut got).expect("gpu forces"), 0);
        // Tolerance from f32 rounding: a node's force sums up to 8 cells' corner forces, each
        // about 150 dependent operations from the displacements (sums, F, C, C⁻¹, S, P, the corner
        // sum), each adding at most one unit roundoff 2⁻²⁴ ≈ 6e-8 of the largest intermediate,
        // which is of the size of the largest force: 8 · 150 · 6e-8 ≈ 7e-5 of it at worst. The CPU
        // sums in another order (Walsh–Hadamard sums, per-slab accumulators), so both sides carry
        // such errors.
        let scale = expected.iter().map(|f| f.norm()).fold(0.0f32, f32::max);
        assert!(scale > 0.0);
        let worst = expected.iter().zip(&got).map(|(e, g)| (e - g).norm()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-4 * scale, "largest difference {worst} N against forces up to {scale} N");
        eprintln!(
            "GPU ({}) against CPU: largest difference {:.2e} of {scale:.3e} N",
            gpu.summary.info.name,
            worst / scale
        );
    }

    #[test]
    fn an_inverted_cell_is_flagged() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let lattice = Lattice::block(Point3::origin(), 0.01, [3, 3, 3]);
        let cpu = Tled::new(&lattice, None, &Material::default(), TledParams::default()).expect("tled");
        let mut on_gpu = GpuTled::new(&gpu, &cpu).expect("gpu tled");
        let mut u = vec![Vector3::zeros(); lattice.node_count()];
        // Push one interior node 1.5 cells through its neighbours.
        let centre = lattice.node_at([1, 1, 1]).expect("node") as usize;
        u[centre] = Vector3::new(0.015, 0.015, 0.015);
        let mut f = vec![Vector3::zeros(); lattice.node_count()];
        let inverted = on_gpu.internal_forces(&u, &mut f).expect("forces");
        assert!((1..=8).contains(&inverted), "{inverted} cells flagged");
    }

    #[test]
    fn gauss_quadrature_is_refused_with_the_key() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let lattice = Lattice::block(Point3::origin(), 0.01, [2, 2, 2]);
        let params = TledParams { integration: Integration::Gauss8, ..TledParams::default() };
        let cpu = Tled::new(&lattice, None, &Material::default(), params).expect("tled");
        let err = GpuTled::new(&gpu, &cpu).expect_err("gauss8");
        assert!(err.to_string().contains("tled.integration"), "{err}");
    }

    /// Throughput on a 30³-cell block, upload and read-back included (not a test of behaviour):
    /// `cargo test -p hullcut-sim --features gpu --lib gpu_throughput_probe -- --ignored --nocapture`.
    #[test]
    #[ignore = "timing probe; run by hand"]
    fn gpu_throughput_probe() {
        let Some(gpu) = hullcut_gpu::for_tests() else { return };
        let lattice = Lattice::block(Point3::origin(), 0.005, [30, 30, 30]);
        let u: Vec<Vector3<f32>> =
            lattice.rest.iter().map(|p| Vector3::new(0.01 * p.y as f32, 0.0, 0.02 * p.x as f32)).collect();
        let cpu = Tled::new(&lattice, None, &Material::default(), TledParams::default()).expect("tled");
        let mut on_gpu = GpuTled::new(&gpu, &cpu).expect("gpu tled");
        let mut f = vec![Vector3::zeros(); lattice.node_count()];
        on_gpu.internal_forces(&u, &mut f).expect("forces");
        let reps = 10;
        let t = std::time::Instant::now();
        for _ in 0..reps {
            on_gpu.internal_forces(&u, &mut f).expect("forces");
        }
        let s = t.elapsed().as_secs_f64();
        eprintln!(
            "{}: {:.2} ms per call, {:.1} M element-steps/s",
            gpu.summary.info.name,
            1e3 * s / reps as f64,
            (lattice.cells.len() * reps) as f64 / s / 1e6
        );
    }
}
