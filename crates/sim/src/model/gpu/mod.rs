//! TLED on the GPU (wgpu, WGSL): the same one-point hexahedra with Flanagan–Belytschko hourglass
//! control as [`crate::Tled`], in passes without float atomics: an element pass (one invocation
//! per cell, writing its eight nodal forces) and a node pass (one invocation per node, gathering
//! through the node → (cell, corner) list).
//!
//! - [`GpuTled`]: internal forces alone, for parity tests against the CPU kernel;
//! - [`GpuStepper`]: whole central-difference steps (forces, update, prescribed components,
//!   divergence flag, contacts with an obstacle), many per submission, the CPU reading back only
//!   the state at the end; with the hybrid model, the FLSM step (region fits, polar
//!   decompositions, goals, goal pull, region damping) and the interface pull before every
//!   `substeps` TLED steps (`flsm` module).
//!
//! A cell whose det F falls below [`crate::tled::INVERSION_J`] is counted; unlike the CPU kernel
//! the GPU does not regularize it (its force is the neo-Hookean force of the unregularized F), so
//! callers treat a nonzero count as a reason to redo the work on the CPU
//! ([`crate::Simulation::use_gpu`] does, and counts it).

mod flsm;
mod run;
mod step;

use bytemuck::{Pod, Zeroable};
use hullcut_gpu::Gpu;
use nalgebra::Vector3;

use crate::SimError;
use crate::tled::{INVERSION_J, Integration, Tled};

pub(crate) use flsm::FlsmSetup;
pub use run::GpuStats;
pub(crate) use run::{GpuRun, Ran};
pub use step::{ContactShapes, GpuStepper, PushGrid, StepBatch};

/// Invocations per workgroup of the element and node passes.
const WORKGROUP: u32 = 64;

/// Entries of the status buffer the kernels share (atomic `u32`s).
mod status {
    /// Steps completed (the integrator's step count).
    pub const STEP: usize = 0;
    /// Nonzero once a node moved faster than the limit or became non-finite.
    pub const DIVERGED: usize = 1;
    /// The lowest-numbered node that did (`u32::MAX`: none).
    pub const NODE: usize = 2;
    /// Cells found inverted, summed over the steps run.
    pub const INVERTED: usize = 3;
    /// Nodes pushed out of the obstacle in the last completed step.
    pub const CONTACTS: usize = 4;
    /// Nodes put back on the table in the last completed step.
    pub const TABLE_CONTACTS: usize = 6;
    /// Length of the buffer; entries 5 and 7 count the contacts of the step under way, which the
    /// tick moves to `CONTACTS` and `TABLE_CONTACTS`.
    pub const LEN: usize = 8;
}

/// The kernels' shared constants (a uniform buffer; 48 bytes).
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
    /// Time step, s.
    dt: f32,
    /// 1 / (1 + α dt / 2).
    a: f32,
    /// 1 − α dt / 2.
    b: f32,
    /// dt².
    dt2: f32,
    /// Largest squared speed before the run counts as divergent, m²/s².
    speed_limit2: f32,
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
    dt: f32,
    a: f32,
    b: f32,
    dt2: f32,
    speed_limit2: f32,
}
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> status: array<atomic<u32>>;
";

/// Element pass: cell `c`'s eight nodal forces to `cell_forces[24 c + 3 a ..]`; inverted cells
/// counted in `status[3]`. Does nothing once the run has diverged.
const ELEMENT_WGSL: &str = "
@group(0) @binding(2) var<storage, read> cell_nodes: array<u32>;
@group(0) @binding(3) var<storage, read> volume: array<f32>;
@group(0) @binding(4) var<storage, read> u: array<f32>;
@group(0) @binding(5) var<storage, read_write> cell_forces: array<f32>;

fn sign(a: u32, bit: u32) -> f32 {
    return select(-1.0, 1.0, (a & bit) != 0u);
}

@compute @workgroup_size(64)
fn element(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = gid.x;
    if (c >= p.cells || atomicLoad(&status[1]) != 0u) {
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
    if (j < p.inversion_j || j != j) {
        atomicAdd(&status[3], 1u);
    }
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

/// A node's internal force: the sum of its cells' corner forces, through `gather_list` (the
/// first `nodes + 1` entries are offsets into the same array, then `cell * 8 + corner` entries).
const GATHER_FN_WGSL: &str = "
@group(0) @binding(2) var<storage, read> gather_list: array<u32>;
@group(0) @binding(3) var<storage, read> cell_forces: array<f32>;

fn gathered(n: u32) -> vec3<f32> {
    var f = vec3<f32>(0.0);
    for (var e = gather_list[n]; e < gather_list[n + 1u]; e++) {
        let o = 3u * gather_list[e];
        f += vec3<f32>(cell_forces[o], cell_forces[o + 1u], cell_forces[o + 2u]);
    }
    return f;
}
";

/// Node pass of [`GpuTled`]: writes each node's force.
const FORCES_WGSL: &str = "
@group(0) @binding(4) var<storage, read_write> forces: array<f32>;

@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= p.nodes) {
        return;
    }
    let f = gathered(n);
    forces[3u * n] = f.x;
    forces[3u * n + 1u] = f.y;
    forces[3u * n + 2u] = f.z;
}
";

/// The GPU side of a [`Tled`]: constants, cells, the gather list, the corner forces and the
/// status buffer, with the element pass's pipeline.
#[derive(Debug)]
struct CellBuffers {
    params: Params,
    uniform: wgpu::Buffer,
    status: wgpu::Buffer,
    cell_nodes: wgpu::Buffer,
    volume: wgpu::Buffer,
    gather_list: wgpu::Buffer,
    cell_forces: wgpu::Buffer,
    element: wgpu::ComputePipeline,
}

fn gpu_err(e: hullcut_gpu::GpuError) -> SimError {
    SimError::Gpu(e.to_string())
}

impl CellBuffers {
    /// Uploads `tled`'s cells; `params` carries the stepping constants (zero for forces alone).
    fn new(gpu: &Gpu, tled: &Tled, mut params: Params) -> Result<Self, SimError> {
        if tled.params.integration != Integration::OnePoint {
            return Err(SimError::Gpu("only one-point integration runs on the GPU (tled.integration)".into()));
        }
        let (cells, nodes) = (tled.cell_nodes.len(), tled.node_count);
        let k = tled.one_point_constants();
        params.cells = u32::try_from(cells).map_err(|_| SimError::Gpu(format!("{cells} cells: too many")))?;
        params.nodes = u32::try_from(nodes).map_err(|_| SimError::Gpu(format!("{nodes} nodes: too many")))?;
        params.inv4h = k.inv4h;
        params.lambda = k.lambda;
        params.mu = k.mu;
        params.kappa_per_volume = k.kappa_per_volume;
        params.inversion_j = INVERSION_J;
        let uniform = gpu.uniform("tled params", &params);
        let status = gpu.storage("status", &status_init(0)).map_err(gpu_err)?;
        let cell_nodes = gpu.storage("cell nodes", tled.cell_nodes.as_flattened()).map_err(gpu_err)?;
        let volume = gpu.storage("cell volumes", &tled.volume).map_err(gpu_err)?;
        let gather_list = gpu.storage("gather list", &gather_list(&tled.cell_nodes, nodes)).map_err(gpu_err)?;
        let cell_forces = gpu.storage("cell forces", &vec![0.0f32; 24 * cells]).map_err(gpu_err)?;
        let element = gpu.pipeline("tled element pass", &format!("{PARAMS_WGSL}{ELEMENT_WGSL}"), "element");
        Ok(Self { params, uniform, status, cell_nodes, volume, gather_list, cell_forces, element })
    }

    /// The element pass's bind group with displacements `u`.
    fn element_bind(&self, gpu: &Gpu, u: &wgpu::Buffer) -> wgpu::BindGroup {
        gpu.bind(&self.element, &[&self.uniform, &self.status, &self.cell_nodes, &self.volume, u, &self.cell_forces])
    }

    /// Reads the status buffer.
    fn read_status(&self, gpu: &Gpu) -> Result<[u32; status::LEN], SimError> {
        let v: Vec<u32> = gpu.read("status", &self.status, status::LEN).map_err(gpu_err)?;
        let mut out = [0; status::LEN];
        out.copy_from_slice(&v);
        Ok(out)
    }
}

/// The status buffer at the start of a run from step `step`.
fn status_init(step: u32) -> [u32; status::LEN] {
    let mut s = [0; status::LEN];
    s[status::STEP] = step;
    s[status::NODE] = u32::MAX;
    s
}

/// The node → (cell, corner) list: `nodes + 1` offsets (into this same array), then the entries
/// `cell * 8 + corner` of each node in turn.
fn gather_list(cell_nodes: &[[u32; 8]], nodes: usize) -> Vec<u32> {
    let mut counts = vec![0u32; nodes + 1];
    for c in cell_nodes {
        for &n in c {
            counts[n as usize + 1] += 1;
        }
    }
    let mut list = vec![0u32; nodes + 1 + 8 * cell_nodes.len()];
    list[0] = (nodes + 1) as u32;
    for i in 1..=nodes {
        list[i] = list[i - 1] + counts[i];
    }
    let mut fill: Vec<u32> = list[..nodes].to_vec();
    for (c, corners) in cell_nodes.iter().enumerate() {
        for (a, &n) in corners.iter().enumerate() {
            list[fill[n as usize] as usize] = (8 * c + a) as u32;
            fill[n as usize] += 1;
        }
    }
    list
}

/// Flattens vectors for upload.
fn flatten(v: &[Vector3<f32>]) -> Vec<f32> {
    v.iter().flat_map(|x| [x.x, x.y, x.z]).collect()
}

/// Vectors from a read-back.
fn unflatten(v: &[f32]) -> Vec<Vector3<f32>> {
    v.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect()
}

/// TLED's internal forces on a GPU, for the cells of a CPU [`Tled`].
#[derive(Debug)]
pub struct GpuTled<'g> {
    gpu: &'g Gpu,
    cells: CellBuffers,
    u: wgpu::Buffer,
    forces: wgpu::Buffer,
    element_bind: wgpu::BindGroup,
    gather: (wgpu::ComputePipeline, wgpu::BindGroup),
}

impl<'g> GpuTled<'g> {
    /// Uploads `tled`'s cells (node lists, volumes, constants) and its gather list to `gpu`.
    /// Only one-point integration runs on the GPU.
    pub fn new(gpu: &'g Gpu, tled: &Tled) -> Result<Self, SimError> {
        let cells = CellBuffers::new(gpu, tled, Params::zeroed())?;
        let nodes = tled.node_count;
        let u = gpu.storage("displacements", &vec![0.0f32; 3 * nodes]).map_err(gpu_err)?;
        let forces = gpu.storage("nodal forces", &vec![0.0f32; 3 * nodes]).map_err(gpu_err)?;
        let element_bind = cells.element_bind(gpu, &u);
        let pipeline = gpu.pipeline("tled node pass", &format!("{PARAMS_WGSL}{GATHER_FN_WGSL}{FORCES_WGSL}"), "gather");
        let bind = gpu.bind_numbered(
            &pipeline,
            &[(0, &cells.uniform), (2, &cells.gather_list), (3, &cells.cell_forces), (4, &forces)],
        );
        Ok(Self { gpu, cells, u, forces, element_bind, gather: (pipeline, bind) })
    }

    /// Internal nodal forces for displacements `u` into `out` (one per node); returns the number
    /// of cells flagged as inverted (det F below [`INVERSION_J`]).
    pub fn internal_forces(&mut self, u: &[Vector3<f32>], out: &mut [Vector3<f32>]) -> Result<usize, SimError> {
        let n = self.cells.params.nodes as usize;
        if u.len() != n || out.len() != n {
            return Err(SimError::Gpu(format!("{} displacements and {} forces for {n} nodes", u.len(), out.len())));
        }
        let queue = &self.gpu.queue;
        queue.write_buffer(&self.cells.status, 0, bytemuck::cast_slice(&status_init(0)));
        queue.write_buffer(&self.u, 0, bytemuck::cast_slice(&flatten(u)));
        self.gpu.dispatch(&self.cells.element, &self.element_bind, self.cells.params.cells, WORKGROUP);
        self.gpu.dispatch(&self.gather.0, &self.gather.1, self.cells.params.nodes, WORKGROUP);
        let forces: Vec<f32> = self.gpu.read("nodal forces", &self.forces, 3 * n).map_err(gpu_err)?;
        out.copy_from_slice(&unflatten(&forces));
        Ok(self.cells.read_status(self.gpu)?[status::INVERTED] as usize)
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
