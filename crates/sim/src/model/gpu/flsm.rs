//! The hybrid model's FLSM step on the GPU, before each group of TLED sub-steps: region fits
//! (centroid, moment, rotation by the same safeguarded Newton iteration as
//! [`crate::flsm::Flsm`], warm-started per region), goals, the goal pull and region damping of
//! the FLSM nodes, and the interface nodes' pull toward their goals as TLED's external force.
//!
//! Region sums are direct sums over each region's `(2w + 1)³` grid points, around the region's
//! own centroid (f32 keeps the deformation that way), not the CPU's separable box sums: on a GPU
//! the direct sums are cheap for the small `w` the hybrid uses, and their cost grows as `w³`.

use bytemuck::{Pod, Zeroable};
use hullcut_gpu::Gpu;
use nalgebra::Vector3;

use super::{WORKGROUP, gpu_err};
use crate::SimError;
use crate::flsm::FlsmLayout;

/// The FLSM passes' constants (48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FlsmUniform {
    grid: [u32; 3],
    w: u32,
    alpha: f32,
    damping: f32,
    /// FLSM step, s.
    h: f32,
    /// TLED step, s.
    dt: f32,
    substeps: u32,
    nodes: u32,
    pad: [u32; 2],
}

const FLSM_COMMON_WGSL: &str = "
struct Flsm {
    grid: vec3<u32>,
    w: u32,
    alpha: f32,
    damping: f32,
    h: f32,
    dt: f32,
    substeps: u32,
    nodes: u32,
    pad0: u32,
    pad1: u32,
}
struct FlsmNode {
    x0: vec3<f32>,
    weight: f32,
    grid: u32,
    inv_count: f32,
    inv_mass: f32,
    moves: u32,
}
struct Region {
    c0: vec3<f32>,
    mass: f32,
    floor: f32,
    pad0: f32,
    pad1: f32,
    pad2: f32,
}
@group(0) @binding(0) var<uniform> f: Flsm;

// Grid point of `g`, and whether `at + d` is inside the grid (then its index in `out`).
fn grid_of(g: u32) -> vec3<i32> {
    return vec3<i32>(i32(g % f.grid.x), i32((g / f.grid.x) % f.grid.y), i32(g / (f.grid.x * f.grid.y)));
}
fn inside(p: vec3<i32>) -> bool {
    return all(p >= vec3<i32>(0)) && all(p < vec3<i32>(f.grid));
}
fn index_of(p: vec3<i32>) -> u32 {
    return u32(p.x) + f.grid.x * (u32(p.y) + f.grid.y * u32(p.z));
}
";

/// A region's grid points, for the passes that sum over them (`grid_node` at binding 1).
const NEIGHBOURS_WGSL: &str = "
@group(0) @binding(1) var<storage, read> grid_node: array<u32>;

// Grid points in a region of half-width w: (2w + 1)^3.
fn neighbourhood() -> u32 {
    let side = 2u * f.w + 1u;
    return side * side * side;
}

// The node at grid point t of the region around `at` (x fastest, then y, then z), or
// 0xffffffff outside the grid or where there is none.
fn neighbour(at: vec3<i32>, t: u32) -> u32 {
    let side = 2u * f.w + 1u;
    let d = vec3<i32>(i32(t % side), i32((t / side) % side), i32(t / (side * side))) - vec3<i32>(i32(f.w));
    let p = at + d;
    if (!inside(p)) {
        return 0xffffffffu;
    }
    return grid_node[index_of(p)];
}
";

/// Region fit: centroid, moment and rotation of the region centred at each node.
const FIT_WGSL: &str = "
@group(0) @binding(2) var<storage, read> fnodes: array<FlsmNode>;
@group(0) @binding(3) var<storage, read> regions: array<Region>;
@group(0) @binding(4) var<storage, read_write> u_now: array<f32>;
@group(0) @binding(5) var<storage, read_write> quat: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> frame: array<vec4<f32>>;

fn disp(n: u32) -> vec3<f32> {
    return vec3<f32>(u_now[3u * n], u_now[3u * n + 1u], u_now[3u * n + 2u]);
}

fn quat_mat(q: vec4<f32>) -> mat3x3<f32> {
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// q (x) (1, d / 2), renormalised: a turn by about |d| in q's frame.
fn turn(q: vec4<f32>, d: vec3<f32>) -> vec4<f32> {
    let h = d * 0.5;
    let v = q.xyz;
    return normalize(vec4<f32>(q.w * h + v + cross(v, h), q.w - dot(v, h)));
}

// h x = g by L D L^T (lower triangle of the symmetric h); w = 0 when a pivot is below min_pivot.
fn ldlt(h: mat3x3<f32>, g: vec3<f32>, min_pivot: f32) -> vec4<f32> {
    let d0 = h[0][0];
    if (!(d0 > 0.0 && d0 >= min_pivot)) {
        return vec4<f32>(0.0);
    }
    let l10 = h[0][1] / d0;
    let l20 = h[0][2] / d0;
    let d1 = h[1][1] - l10 * h[0][1];
    if (!(d1 > 0.0 && d1 >= min_pivot)) {
        return vec4<f32>(0.0);
    }
    let l21 = (h[1][2] - l20 * h[0][1]) / d1;
    let d2 = h[2][2] - l20 * h[0][2] - l21 * l21 * d1;
    if (!(d2 > 0.0 && d2 >= min_pivot)) {
        return vec4<f32>(0.0);
    }
    let z0 = g.x;
    let z1 = g.y - l10 * z0;
    let z2 = g.z - l20 * z0 - l21 * z1;
    let x2 = z2 / d2;
    let x1 = z1 / d1 - l21 * x2;
    let x0 = z0 / d0 - l10 * x1 - l20 * x2;
    return vec4<f32>(x0, x1, x2, 1.0);
}

// The rotation maximising tr(R^T a), from q (crate::flsm::extract_rotation in f32).
fn polar(a_in: mat3x3<f32>, floor_norm: f32, q_in: vec4<f32>) -> vec4<f32> {
    let norm = sqrt(dot(a_in[0], a_in[0]) + dot(a_in[1], a_in[1]) + dot(a_in[2], a_in[2]));
    if (!(norm > floor_norm && norm < 3.0e38)) {
        return q_in;
    }
    let a = a_in * (1.0 / norm);
    var q = q_in;
    var qm = transpose(quat_mat(q)) * a;
    for (var it = 0u; it < 12u; it++) {
        let grad = vec3<f32>(qm[1][2] - qm[2][1], qm[2][0] - qm[0][2], qm[0][1] - qm[1][0]);
        let fv = qm[0][0] + qm[1][1] + qm[2][2];
        let sym = (qm + transpose(qm)) * 0.5;
        let hess = mat3x3<f32>(vec3<f32>(fv, 0.0, 0.0), vec3<f32>(0.0, fv, 0.0), vec3<f32>(0.0, 0.0, fv)) - sym;
        var step = ldlt(hess, grad, 0.05);
        let newton = step.w != 0.0;
        if (!newton) {
            var gersh = 3.0e38;
            for (var i = 0u; i < 3u; i++) {
                var off = 0.0;
                for (var j = 0u; j < 3u; j++) {
                    if (j != i) {
                        off += abs(hess[j][i]);
                    }
                }
                gersh = min(gersh, hess[i][i] - off);
            }
            let mu = max(0.05 - gersh, 0.0);
            let shifted = hess + mat3x3<f32>(vec3<f32>(mu, 0.0, 0.0), vec3<f32>(0.0, mu, 0.0), vec3<f32>(0.0, 0.0, mu));
            step = ldlt(shifted, grad, 0.0);
            if (step.w == 0.0) {
                step = vec4<f32>(grad / max(0.05, abs(hess[0][0] + hess[1][1] + hess[2][2])), 0.0);
            }
        }
        var delta = step.xyz;
        let size = length(delta);
        if (size < 1e-6 || (newton && size < 1e-3)) {
            return turn(q, delta);
        }
        var improved = false;
        for (var b = 0u; b < 8u; b++) {
            let cand = turn(q, delta);
            let cq = transpose(quat_mat(cand)) * a;
            if (cq[0][0] + cq[1][1] + cq[2][2] >= fv - 1e-6) {
                q = cand;
                qm = cq;
                improved = true;
                break;
            }
            delta = delta * 0.5;
        }
        if (!improved) {
            return q;
        }
    }
    return q;
}

@compute @workgroup_size(64)
fn fit(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = gid.x;
    if (r >= f.nodes) {
        return;
    }
    let at = grid_of(fnodes[r].grid);
    let region = regions[r];
    var sx = vec3<f32>(0.0);
    for (var t = 0u; t < neighbourhood(); t++) {
        let m = neighbour(at, t);
        if (m != 0xffffffffu) {
            let node = fnodes[m];
            sx += (node.x0 + disp(m)) * node.weight;
        }
    }
    let c = sx / region.mass;
    var a = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var t = 0u; t < neighbourhood(); t++) {
        let m = neighbour(at, t);
        if (m != 0xffffffffu) {
            let node = fnodes[m];
            let x = (node.x0 + disp(m) - c) * node.weight;
            let y = node.x0 - region.c0;
            a += mat3x3<f32>(x * y.x, x * y.y, x * y.z);
        }
    }
    let q = polar(a, region.floor, quat[r]);
    quat[r] = q;
    let rot = quat_mat(q);
    let shift = c - rot * region.c0;
    frame[3u * r] = vec4<f32>(rot[0], shift.x);
    frame[3u * r + 1u] = vec4<f32>(rot[1], shift.y);
    frame[3u * r + 2u] = vec4<f32>(rot[2], shift.z);
}
";

/// Goals: each node's mean over the regions containing it, as a displacement from rest.
const GOALS_WGSL: &str = "
@group(0) @binding(2) var<storage, read> fnodes: array<FlsmNode>;
@group(0) @binding(6) var<storage, read> frame: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> goal: array<vec4<f32>>;

@compute @workgroup_size(64)
fn goals(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= f.nodes) {
        return;
    }
    let node = fnodes[n];
    let at = grid_of(node.grid);
    var g = vec3<f32>(0.0);
    for (var t = 0u; t < neighbourhood(); t++) {
        let r = neighbour(at, t);
        if (r != 0xffffffffu) {
            let c0 = frame[3u * r];
            let c1 = frame[3u * r + 1u];
            let c2 = frame[3u * r + 2u];
            g += c0.xyz * node.x0.x + c1.xyz * node.x0.y + c2.xyz * node.x0.z + vec3<f32>(c0.w, c1.w, c2.w);
        }
    }
    goal[n] = vec4<f32>(g * node.inv_count - node.x0, 0.0);
}
";

/// The goal pull and external force on the FLSM nodes' velocities.
const VELOCITY_WGSL: &str = "
@group(0) @binding(2) var<storage, read> fnodes: array<FlsmNode>;
@group(0) @binding(4) var<storage, read_write> u_now: array<f32>;
@group(0) @binding(7) var<storage, read> goal: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read> node_data: array<NodeData>;
@group(0) @binding(13) var<storage, read_write> status: array<atomic<u32>>;

fn disp(n: u32) -> vec3<f32> {
    return vec3<f32>(u_now[3u * n], u_now[3u * n + 1u], u_now[3u * n + 2u]);
}

@compute @workgroup_size(64)
fn velocity(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= f.nodes || fnodes[n].moves == 0u || atomicLoad(&status[1]) != 0u) {
        return;
    }
    let pull = (goal[n].xyz - disp(n)) * (f.alpha / f.h);
    vel[n] = vec4<f32>(vel[n].xyz + pull + node_data[n].f_ext * (f.h * fnodes[n].inv_mass), 0.0);
}
";

/// Mean velocity of each region (for region damping).
const REGION_VELOCITY_WGSL: &str = "
@group(0) @binding(2) var<storage, read> fnodes: array<FlsmNode>;
@group(0) @binding(3) var<storage, read> regions: array<Region>;
@group(0) @binding(8) var<storage, read> vel: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> vbar: array<vec4<f32>>;

@compute @workgroup_size(64)
fn region_velocity(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = gid.x;
    if (r >= f.nodes) {
        return;
    }
    let at = grid_of(fnodes[r].grid);
    var s = vec3<f32>(0.0);
    for (var t = 0u; t < neighbourhood(); t++) {
        let m = neighbour(at, t);
        if (m != 0xffffffffu) {
            s += vel[m].xyz * fnodes[m].weight;
        }
    }
    vbar[r] = vec4<f32>(s / regions[r].mass, 0.0);
}
";

/// Region damping, the move, the FLSM nodes' prescribed components, and their displacements
/// handed to TLED's buffers (current and previous).
const MOVE_WGSL: &str = "
@group(0) @binding(2) var<storage, read> fnodes: array<FlsmNode>;
@group(0) @binding(4) var<storage, read_write> u_now: array<f32>;
@group(0) @binding(8) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read> node_data: array<NodeData>;
@group(0) @binding(10) var<storage, read> vbar: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> u_before: array<f32>;
@group(0) @binding(13) var<storage, read_write> status: array<atomic<u32>>;

fn disp(n: u32) -> vec3<f32> {
    return vec3<f32>(u_now[3u * n], u_now[3u * n + 1u], u_now[3u * n + 2u]);
}

@compute @workgroup_size(64)
fn move_nodes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= f.nodes || fnodes[n].moves == 0u || atomicLoad(&status[1]) != 0u) {
        return;
    }
    let node = fnodes[n];
    var v = vel[n].xyz;
    if (f.damping > 0.0) {
        let at = grid_of(node.grid);
            var s = vec3<f32>(0.0);
        for (var t = 0u; t < neighbourhood(); t++) {
            let r = neighbour(at, t);
            if (r != 0xffffffffu) {
                s += vbar[r].xyz;
            }
        }
        v = v + (s * node.inv_count - v) * f.damping;
    }
    var u = disp(n) + v * f.h;
    let d = node_data[n];
    let t_end = f32(atomicLoad(&status[0]) + f.substeps) * f.dt;
    for (var k = 0u; k < 3u; k++) {
        if ((d.fixed & (1u << k)) != 0u) {
            u[k] = d.goal[k] * ramp(t_end, d.ramp[k]);
            v[k] = 0.0;
        }
    }
    vel[n] = vec4<f32>(v, 0.0);
    let before = u - v * f.dt;
    for (var k = 0u; k < 3u; k++) {
        u_now[3u * n + k] = u[k];
        u_before[3u * n + k] = before[k];
    }
}
";

/// The interface nodes' pull toward their goals, `f_ext = f_applied + β (g − rest)`.
const INTERFACE_WGSL: &str = "
@group(0) @binding(7) var<storage, read> goal: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> node_data: array<NodeData>;
@group(0) @binding(12) var<storage, read> applied: array<vec4<f32>>;

@compute @workgroup_size(64)
fn pull(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= f.nodes) {
        return;
    }
    let k = node_data[n].k;
    if (k > 0.0) {
        node_data[n].f_ext = applied[n].xyz + goal[n].xyz * k;
    }
}
";

/// Buffers of the FLSM passes that the stepper's bind groups share.
#[derive(Debug)]
pub(crate) struct FlsmBuffers {
    uniform: wgpu::Buffer,
    grid_node: wgpu::Buffer,
    nodes: wgpu::Buffer,
    regions: wgpu::Buffer,
    quat: wgpu::Buffer,
    frame: wgpu::Buffer,
    /// Goal displacements (vec4 per node).
    pub(crate) goal: wgpu::Buffer,
    /// FLSM velocities (vec4 per node).
    pub(crate) vel: wgpu::Buffer,
    vbar: wgpu::Buffer,
    applied: wgpu::Buffer,
    pub(crate) substeps: u32,
    damping: bool,
}

/// The FLSM passes: pipelines and, per rotation of the displacement buffers, bind groups.
#[derive(Debug)]
pub(crate) struct FlsmPasses {
    pub(crate) buffers: FlsmBuffers,
    /// (pipeline, bind group per rotation) in dispatch order.
    passes: Vec<(wgpu::ComputePipeline, [wgpu::BindGroup; 3])>,
    nodes: u32,
}

/// What the hybrid's FLSM part is: its layout, which nodes it moves, its step and the TLED
/// step, the external forces without the interface pull.
pub(crate) struct FlsmSetup<'a> {
    pub layout: FlsmLayout,
    pub active: &'a [bool],
    pub substeps: u32,
    pub dt: f32,
    pub applied: &'a [Vector3<f32>],
}

impl FlsmPasses {
    /// Uploads the FLSM constants and builds the passes over the stepper's `status`, `node_data`
    /// and displacement buffers `u` (with rotation `r` the passes read and write `u[(r + 1) % 3]`
    /// as the current displacements and write `u[r]` as the previous ones, as the stepper's
    /// rotation `r`).
    pub(crate) fn new(
        gpu: &Gpu,
        setup: FlsmSetup,
        status: &wgpu::Buffer,
        node_data: &wgpu::Buffer,
        u: &[wgpu::Buffer; 3],
    ) -> Result<Self, SimError> {
        let FlsmSetup { layout, active, substeps, dt, applied } = setup;
        let n = layout.nodes.len();
        let have = gpu.summary.limits.max_storage_buffers_per_shader_stage;
        if have < 8 {
            return Err(SimError::Gpu(format!(
                "{} allows {have} storage buffers per shader stage; the FLSM step needs 8",
                gpu.summary.info.name
            )));
        }
        let uniform = FlsmUniform {
            grid: layout.grid,
            w: layout.w,
            alpha: layout.alpha,
            damping: layout.region_damping,
            h: dt * substeps as f32,
            dt,
            substeps,
            nodes: n as u32,
            pad: [0; 2],
        };
        let mut nodes = layout.nodes.clone();
        for (node, &a) in nodes.iter_mut().zip(active) {
            node[7] = f32::from_bits(u32::from(a));
        }
        let applied: Vec<[f32; 4]> = applied.iter().map(|f| [f.x, f.y, f.z, 0.0]).collect();
        let quat: Vec<[f32; 4]> = vec![[0.0, 0.0, 0.0, 1.0]; n];
        let zeros4 = vec![[0.0f32; 4]; n];
        let buffers = FlsmBuffers {
            uniform: gpu.uniform("flsm params", &uniform),
            grid_node: gpu.storage("flsm grid", &layout.grid_node).map_err(gpu_err)?,
            nodes: gpu.storage("flsm nodes", &nodes).map_err(gpu_err)?,
            regions: gpu.storage("flsm regions", &layout.regions).map_err(gpu_err)?,
            quat: gpu.storage("flsm rotations", &quat).map_err(gpu_err)?,
            frame: gpu.storage("flsm frames", &vec![[0.0f32; 4]; 3 * n]).map_err(gpu_err)?,
            goal: gpu.storage("flsm goals", &zeros4).map_err(gpu_err)?,
            vel: gpu.storage("flsm velocities", &zeros4).map_err(gpu_err)?,
            vbar: gpu.storage("flsm region velocities", &zeros4).map_err(gpu_err)?,
            applied: gpu.storage("applied forces", &applied).map_err(gpu_err)?,
            substeps,
            damping: layout.region_damping > 0.0,
        };
        let b = &buffers;
        let module = |src: &str| {
            // The passes over regions read the grid; `move_nodes` also ramps prescribed components.
            let neighbours = if src.contains("neighbour(") { NEIGHBOURS_WGSL } else { "" };
            format!("{FLSM_COMMON_WGSL}{neighbours}{}{}{src}", super::step::NODE_DATA_WGSL, super::step::RAMP_WGSL)
        };
        let all: [(u32, &wgpu::Buffer); 11] = [
            (0, &b.uniform),
            (1, &b.grid_node),
            (2, &b.nodes),
            (3, &b.regions),
            (5, &b.quat),
            (6, &b.frame),
            (7, &b.goal),
            (8, &b.vel),
            (9, node_data),
            (10, &b.vbar),
            (12, &b.applied),
        ];
        let mut passes = Vec::new();
        let mut add = |label: &str, src: &str, entry: &str, wanted: &[u32]| {
            let pipeline = gpu.pipeline(label, &module(src), entry);
            let groups = [0, 1, 2].map(|r| {
                let rotating = [(4, &u[(r + 1) % 3]), (11, &u[r]), (13, status)];
                let entries: Vec<(u32, &wgpu::Buffer)> =
                    all.iter().chain(&rotating).filter(|(k, _)| wanted.contains(k)).copied().collect();
                gpu.bind_numbered(&pipeline, &entries)
            });
            passes.push((pipeline, groups));
        };
        add("flsm fit", FIT_WGSL, "fit", &[0, 1, 2, 3, 4, 5, 6]);
        add("flsm goals", GOALS_WGSL, "goals", &[0, 1, 2, 6, 7]);
        add("flsm velocity", VELOCITY_WGSL, "velocity", &[0, 2, 4, 7, 8, 9, 13]);
        if buffers.damping {
            add("flsm region velocity", REGION_VELOCITY_WGSL, "region_velocity", &[0, 1, 2, 3, 8, 10]);
        }
        add("flsm move", MOVE_WGSL, "move_nodes", &[0, 1, 2, 4, 8, 9, 10, 11, 13]);
        add("flsm interface", INTERFACE_WGSL, "pull", &[0, 7, 9, 12]);
        Ok(Self { buffers, passes, nodes: n as u32 })
    }
}

impl FlsmPasses {
    /// Records one FLSM step into `pass` for the stepper's rotation `r`.
    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>, r: usize) {
        for (pipeline, groups) in &self.passes {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &groups[r], &[]);
            pass.dispatch_workgroups(self.nodes.div_ceil(WORKGROUP), 1, 1);
        }
    }
}
