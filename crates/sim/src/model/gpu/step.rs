//! Whole TLED steps on the GPU: per step an element pass, a node pass (gather, central-difference
//! update, prescribed components, divergence flag) and a one-invocation tick that counts the
//! step, all recorded into one compute pass per submission. The displacements live in three
//! buffers whose roles (previous, current, next) rotate each step, so nothing is copied; the CPU
//! reads back the state only at the end of a batch. With an obstacle set, a contact pass after
//! each step pushes the free nodes inside it out, as [`crate::CutSim`] does on the CPU.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use hullcut_gpu::Gpu;
use nalgebra::Vector3;

use super::flsm::{FlsmPasses, FlsmSetup};
use super::{
    CellBuffers, GATHER_FN_WGSL, PARAMS_WGSL, Params, WORKGROUP, flatten, gpu_err, status, status_init, unflatten,
};
use crate::SimError;
use crate::dynamics::Integrator;
use crate::tled::Tled;

/// Steps recorded into one submission; the CPU waits (bounded) between submissions, so a slow
/// device never holds one wait for long.
const STEPS_PER_SUBMIT: u32 = 256;

/// Per-node constants of the update (48 bytes, WGSL's layout of the struct below).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct NodeData {
    f_ext: [f32; 3],
    mass: f32,
    /// Prescribed displacement at the end of the ramp, per component.
    target: [f32; 3],
    /// Bit k set: component k is prescribed.
    fixed: u32,
    /// Ramp duration per component, s.
    ramp: [f32; 3],
    /// Spring stiffness integrated implicitly (the hybrid's interface pull), N/m.
    k: f32,
}

/// The per-node constants, as [`NodeData`]: `fixed` bits 0–2 prescribed components, bit 3 a
/// node frozen during TLED steps (moved by FLSM).
pub(super) const NODE_DATA_WGSL: &str = "
struct NodeData {
    f_ext: vec3<f32>,
    mass: f32,
    goal: vec3<f32>,
    fixed: u32,
    ramp: vec3<f32>,
    k: f32,
}
";

/// An obstacle as the contact pass takes it: per voxel of a regular grid, the push out of it.
#[derive(Debug, Clone, PartialEq)]
pub struct PushGrid {
    /// Centre of voxel 0, metres.
    pub origin: [f32; 3],
    /// Voxel side, metres.
    pub h: f32,
    /// Voxels per axis.
    pub dims: [u32; 3],
    /// Per voxel, x fastest: the push out of it (metres) and 1 where it is occupied (0 elsewhere).
    pub voxels: Vec<[f32; 4]>,
}

/// What the contact pass resolves after every step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ContactShapes {
    /// An obstacle free nodes are pushed out of.
    pub grid: Option<PushGrid>,
    /// A table below: its top's height (metres) and the friction coefficient.
    pub table: Option<(f32, f32)>,
}

/// The obstacle's grid and the table (a uniform; 48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ContactParams {
    origin: [f32; 3],
    h: f32,
    /// Voxels per axis (zeros: no obstacle).
    dims: [u32; 3],
    /// Longest push per step, m.
    max_push: f32,
    /// The table: height (m), friction coefficient, 1 when there is one (else 0), unused.
    table: [f32; 4],
}

/// Contact pass: a free node inside the obstacle moves toward its outside by at most
/// `max_push` and stops (its previous displacement set to the new one); then a node below the
/// table is put back on it, its normal velocity removed and its tangential step shortened by
/// friction, as the CPU's table contact does (`crate::cut::table`).
const CONTACT_WGSL: &str = "
struct Contact {
    origin: vec3<f32>,
    h: f32,
    dims: vec3<u32>,
    max_push: f32,
    table: vec4<f32>,
}
@group(0) @binding(2) var<uniform> obstacle: Contact;
@group(0) @binding(3) var<storage, read> push: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> rest: array<f32>;
@group(0) @binding(5) var<storage, read> node_data: array<NodeData>;
@group(0) @binding(6) var<storage, read_write> u_new: array<f32>;
@group(0) @binding(7) var<storage, read_write> u_old: array<f32>;

@compute @workgroup_size(64)
fn contact(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= p.nodes || atomicLoad(&status[1]) != 0u || (node_data[n].fixed & 7u) == 7u) {
        return;
    }
    let r = vec3<f32>(rest[3u * n], rest[3u * n + 1u], rest[3u * n + 2u]);
    var u = vec3<f32>(u_new[3u * n], u_new[3u * n + 1u], u_new[3u * n + 2u]);
    var prev = vec3<f32>(u_old[3u * n], u_old[3u * n + 1u], u_old[3u * n + 2u]);
    var touched = false;
    let q = round((r + u - obstacle.origin) / obstacle.h);
    if (all(q >= vec3<f32>(0.0)) && all(q < vec3<f32>(obstacle.dims))) {
        let g = u32(q.x) + obstacle.dims.x * (u32(q.y) + obstacle.dims.y * u32(q.z));
        let v = push[g];
        if (v.w != 0.0) {
            u = u + v.xyz * (obstacle.max_push / max(length(v.xyz), obstacle.max_push));
            prev = u;
            touched = true;
            atomicAdd(&status[5], 1u);
        }
    }
    let depth = obstacle.table.x - (r.z + u.z);
    if (obstacle.table.z != 0.0 && depth > 0.0) {
        u.z = u.z + depth;
        prev.z = u.z;
        let slip = u.xy - prev.xy;
        let grip = obstacle.table.y * depth;
        var removed = slip;
        if (length(slip) > grip) {
            removed = slip * (grip / length(slip));
        }
        u = vec3<f32>(u.xy - removed, u.z);
        touched = true;
        atomicAdd(&status[7], 1u);
    }
    if (touched) {
        for (var k = 0u; k < 3u; k++) {
            u_new[3u * n + k] = u[k];
            u_old[3u * n + k] = prev[k];
        }
    }
}
";

/// The smooth ramp `s³ (10 − 15 s + 6 s²)`, as [`crate::dynamics::ramp`].
pub(super) const RAMP_WGSL: &str = "
fn ramp(t: f32, duration: f32) -> f32 {
    if (duration <= 0.0) {
        return 1.0;
    }
    let s = clamp(t / duration, 0.0, 1.0);
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}
";

/// Node pass of a step: gather, update, prescribed components, divergence flag.
const NODE_WGSL: &str = "
@group(0) @binding(4) var<storage, read> node_data: array<NodeData>;
@group(0) @binding(5) var<storage, read> u_prev: array<f32>;
@group(0) @binding(6) var<storage, read> u_now: array<f32>;
@group(0) @binding(7) var<storage, read_write> u_next: array<f32>;

@compute @workgroup_size(64)
fn node(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = gid.x;
    if (n >= p.nodes || atomicLoad(&status[1]) != 0u) {
        return;
    }
    let d = node_data[n];
    let u = vec3<f32>(u_now[3u * n], u_now[3u * n + 1u], u_now[3u * n + 2u]);
    var x = u;
    if (d.mass > 0.0 && (d.fixed & 8u) == 0u) {
        let up = vec3<f32>(u_prev[3u * n], u_prev[3u * n + 1u], u_prev[3u * n + 2u]);
        let denom = select(p.a, 1.0 / (1.0 / p.a + d.k * p.dt2 / d.mass), d.k > 0.0);
        x = ((d.f_ext - gathered(n)) * (p.dt2 / d.mass) + u * 2.0 - up * p.b) * denom;
    }
    let step = x - u;
    let v2 = dot(step, step) / p.dt2;
    let t = f32(atomicLoad(&status[0]) + 1u) * p.dt;
    for (var k = 0u; k < 3u; k++) {
        if ((d.fixed & (1u << k)) != 0u) {
            x[k] = d.goal[k] * ramp(t, d.ramp[k]);
        }
    }
    u_next[3u * n] = x.x;
    u_next[3u * n + 1u] = x.y;
    u_next[3u * n + 2u] = x.z;
    // Also true for NaN: the comparison fails.
    if (!(v2 <= p.speed_limit2)) {
        atomicMax(&status[1], 1u);
        atomicMin(&status[2], n);
    }
}
";

/// Counts a completed step (unless the run diverged in it) and its contacts.
const TICK_WGSL: &str = "
@group(0) @binding(0) var<storage, read_write> status: array<atomic<u32>>;

@compute @workgroup_size(1)
fn tick() {
    if (atomicLoad(&status[1]) == 0u) {
        atomicAdd(&status[0], 1u);
        atomicStore(&status[4], atomicLoad(&status[5]));
        atomicStore(&status[5], 0u);
        atomicStore(&status[6], atomicLoad(&status[7]));
        atomicStore(&status[7], 0u);
    }
}
";

/// The hybrid's FLSM state read back after a batch.
#[derive(Debug, Clone)]
pub(crate) struct FlsmState {
    /// Velocities of the FLSM nodes (zero elsewhere).
    pub v: Vec<Vector3<f32>>,
    /// Every node's goal displacement (goal − rest) of the last FLSM step.
    pub goals: Vec<Vector3<f32>>,
}

/// What a batch of steps on the GPU ended with.
#[derive(Debug, Clone)]
pub struct StepBatch {
    /// Steps completed (all asked for, unless the run diverged).
    pub completed: u32,
    /// The lowest-numbered node that moved faster than the limit or became non-finite in the
    /// step after the completed ones.
    pub diverged_node: Option<u32>,
    /// Cells found inverted, summed over the steps run (the GPU does not regularize them).
    pub inverted_cell_steps: u32,
    /// Nodes the contact pass pushed out of the obstacle in the last completed step.
    pub contacts: u32,
    /// Nodes the contact pass put back on the table in the last completed step.
    pub table_contacts: u32,
    /// Device time of the batch's passes (timestamp queries; `None` where the adapter has none).
    pub device_ns: Option<f64>,
    /// Displacements after the completed steps.
    pub u: Vec<Vector3<f32>>,
    /// Displacements one step before.
    pub u_prev: Vec<Vector3<f32>>,
    /// Displacements two steps before (after a divergence: the failed step's displacements,
    /// where the node pass wrote them).
    pub u_older: Vec<Vector3<f32>>,
}

/// TLED steps on the GPU (with the hybrid's FLSM step where it has one): the cells of a [`Tled`], the masses, external
/// forces and prescribed components of an [`Integrator`].
#[derive(Debug)]
pub struct GpuStepper {
    gpu: Arc<Gpu>,
    cells: CellBuffers,
    /// The three displacement buffers; step `i` of a batch reads `u[(r + i) % 3]` (previous) and
    /// `u[(r + i + 1) % 3]` (current) and writes `u[(r + i + 2) % 3]`, with `r` = `rotation`.
    u: [wgpu::Buffer; 3],
    /// Element pass reading `u[i]`.
    element_binds: [wgpu::BindGroup; 3],
    node: wgpu::ComputePipeline,
    /// Node pass of rotation `r`.
    node_binds: [wgpu::BindGroup; 3],
    tick: (wgpu::ComputePipeline, wgpu::BindGroup),
    rotation: usize,
    rest: wgpu::Buffer,
    node_data: wgpu::Buffer,
    contact: wgpu::ComputePipeline,
    /// Contact pass of rotation `r`, while an obstacle is set.
    contact_binds: Option<[wgpu::BindGroup; 3]>,
    /// The hybrid's FLSM step, run before every `substeps` TLED steps.
    flsm: Option<FlsmPasses>,
    /// Times the passes on the device, where the adapter can.
    timer: Option<hullcut_gpu::PassTimer>,
    /// What the lattice's buffers hold, for [`GpuStepper::refit`].
    shadows: Shadows,
}

/// The bytes last written to the lattice's buffers.
#[derive(Debug, Default)]
struct Shadows {
    cell_nodes: Vec<u8>,
    volume: Vec<u8>,
    gather_list: Vec<u8>,
    node_data: Vec<u8>,
    rest: Vec<u8>,
}

/// Bytes compared and written together by [`refill`].
const BLOCK: usize = 4096;

/// A storage buffer of at least `bytes`, rounded up to a power of two.
fn grown_buffer(gpu: &Gpu, label: &str, bytes: u64) -> Result<wgpu::Buffer, SimError> {
    let size = bytes.max(16).next_power_of_two();
    gpu.check_storage(label, size).map_err(gpu_err)?;
    Ok(gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    }))
}

/// Makes `buffer` hold `data` (whose last write is `shadow`): a grown buffer written whole, or the
/// blocks that differ. Returns the bytes written and whether the buffer is new.
fn refill(
    gpu: &Gpu,
    label: &str,
    buffer: &mut wgpu::Buffer,
    shadow: &mut Vec<u8>,
    data: &[u8],
) -> Result<(u64, bool), SimError> {
    if (data.len() as u64) > buffer.size() {
        *buffer = grown_buffer(gpu, label, data.len() as u64)?;
        gpu.queue.write_buffer(buffer, 0, data);
        *shadow = data.to_vec();
        return Ok((data.len() as u64, true));
    }
    let mut written = 0;
    for (b, block) in data.chunks(BLOCK).enumerate() {
        let at = b * BLOCK;
        if shadow.get(at..at + block.len()) != Some(block) {
            gpu.queue.write_buffer(buffer, at as u64, block);
            written += block.len() as u64;
        }
    }
    shadow.clear();
    shadow.extend_from_slice(data);
    Ok((written, false))
}

/// The per-node constants of `integrator` with external forces `f_ext`.
fn node_data_of(integrator: &Integrator, f_ext: &[Vector3<f32>]) -> Vec<NodeData> {
    let mut data: Vec<NodeData> = integrator
        .mass
        .iter()
        .zip(f_ext)
        .zip(integrator.frozen.iter().zip(&integrator.implicit_stiffness))
        .map(|((&mass, f), (&frozen, &k))| NodeData {
            f_ext: [f.x, f.y, f.z],
            mass,
            fixed: if frozen { 8 } else { 0 },
            k,
            ..NodeData::zeroed()
        })
        .collect();
    for p in &integrator.prescribed {
        let (d, k) = (&mut data[p.node as usize], usize::from(p.axis));
        d.fixed |= 1 << k;
        d.target[k] = p.target;
        d.ramp[k] = p.ramp;
    }
    data
}

/// The node pass's bind group for rotation `r`.
fn node_bind(
    gpu: &Gpu,
    node: &wgpu::ComputePipeline,
    cells: &CellBuffers,
    node_data: &wgpu::Buffer,
    u: &[wgpu::Buffer; 3],
    r: usize,
) -> wgpu::BindGroup {
    gpu.bind_numbered(
        node,
        &[
            (0, &cells.uniform),
            (1, &cells.status),
            (2, &cells.gather_list),
            (3, &cells.cell_forces),
            (4, node_data),
            (5, &u[r]),
            (6, &u[(r + 1) % 3]),
            (7, &u[(r + 2) % 3]),
        ],
    )
}

impl GpuStepper {
    /// Uploads the cells of `tled`, the masses and the prescribed components of `integrator` (whose
    /// state [`GpuStepper::upload`] sends), the constant external forces `f_ext` and the nodes'
    /// rest positions `rest` (for contacts).
    ///
    /// Refuses what the GPU path does not model: Gauss quadrature, nodes frozen or pulled by
    /// another model without that model's FLSM part (the hybrid), and devices with too few
    /// storage bindings.
    pub fn new(
        gpu: Arc<Gpu>,
        tled: &Tled,
        integrator: &Integrator,
        f_ext: &[Vector3<f32>],
        rest: &[Vector3<f32>],
    ) -> Result<Self, SimError> {
        Self::with_flsm(gpu, tled, integrator, f_ext, rest, None)
    }

    /// As [`GpuStepper::new`], with the hybrid's FLSM part: `f_ext` are then the applied forces
    /// (the interface pull is added on the GPU), and a batch runs whole FLSM steps.
    pub(crate) fn with_flsm(
        gpu: Arc<Gpu>,
        tled: &Tled,
        integrator: &Integrator,
        f_ext: &[Vector3<f32>],
        rest: &[Vector3<f32>],
        flsm: Option<FlsmSetup>,
    ) -> Result<Self, SimError> {
        let nodes = integrator.u.len();
        if tled.node_count != nodes || f_ext.len() != nodes || rest.len() != nodes {
            return Err(SimError::Gpu(format!(
                "{} lattice nodes, {nodes} integrator nodes, {} external forces and {} rest positions",
                tled.node_count,
                f_ext.len(),
                rest.len()
            )));
        }
        if flsm.is_none()
            && (integrator.frozen.iter().any(|&f| f) || integrator.implicit_stiffness.iter().any(|&k| k != 0.0))
        {
            return Err(SimError::Gpu(
                "frozen or pulled nodes without the FLSM part that moves them (GpuStepper::with_flsm)".into(),
            ));
        }
        // The node pass binds six storage buffers (status, gather list, corner forces, node data
        // and two displacement buffers read, one written: seven in all).
        let have = gpu.summary.limits.max_storage_buffers_per_shader_stage;
        if have < 7 {
            return Err(SimError::Gpu(format!(
                "{} allows {have} storage buffers per shader stage; the TLED step needs 7",
                gpu.summary.info.name
            )));
        }
        let dt = integrator.dt;
        let params = Params {
            dt,
            a: 1.0 / (1.0 + 0.5 * integrator.damping * dt),
            b: 1.0 - 0.5 * integrator.damping * dt,
            dt2: dt * dt,
            speed_limit2: integrator.speed_limit * integrator.speed_limit,
            ..Params::zeroed()
        };
        let cells = CellBuffers::new(&gpu, tled, params)?;
        let data = node_data_of(integrator, f_ext);
        let node_data = gpu.storage("node data", &data).map_err(gpu_err)?;
        let shadows = Shadows {
            cell_nodes: bytemuck::cast_slice(tled.cell_nodes.as_flattened()).to_vec(),
            volume: bytemuck::cast_slice(&tled.volume).to_vec(),
            gather_list: bytemuck::cast_slice(&super::gather_list(&tled.cell_nodes, nodes)).to_vec(),
            node_data: bytemuck::cast_slice(&data).to_vec(),
            rest: bytemuck::cast_slice(&flatten(rest)).to_vec(),
        };
        let zeros = vec![0.0f32; 3 * nodes];
        let u = [
            gpu.storage("displacements 0", &zeros).map_err(gpu_err)?,
            gpu.storage("displacements 1", &zeros).map_err(gpu_err)?,
            gpu.storage("displacements 2", &zeros).map_err(gpu_err)?,
        ];
        let element_binds = [0, 1, 2].map(|i| cells.element_bind(&gpu, &u[i]));
        let node = gpu.pipeline(
            "tled step node pass",
            &format!("{PARAMS_WGSL}{GATHER_FN_WGSL}{NODE_DATA_WGSL}{RAMP_WGSL}{NODE_WGSL}"),
            "node",
        );
        let node_binds = [0, 1, 2].map(|r| node_bind(&gpu, &node, &cells, &node_data, &u, r));
        let tick = gpu.pipeline("tled step tick", TICK_WGSL, "tick");
        let tick_bind = gpu.bind(&tick, &[&cells.status]);
        let rest = gpu.storage("rest positions", &flatten(rest)).map_err(gpu_err)?;
        let contact =
            gpu.pipeline("tled contact pass", &format!("{PARAMS_WGSL}{NODE_DATA_WGSL}{CONTACT_WGSL}"), "contact");
        let flsm = flsm.map(|setup| FlsmPasses::new(&gpu, setup, &cells.status, &node_data, &u)).transpose()?;
        let timer = gpu.pass_timer();
        Ok(Self {
            gpu,
            cells,
            u,
            element_binds,
            node,
            node_binds,
            tick: (tick, tick_bind),
            rotation: 0,
            rest,
            node_data,
            contact,
            contact_binds: None,
            flsm,
            timer,
            shadows,
        })
    }

    /// Takes over a changed lattice (a cut) without building anew: the same pipelines, buffers
    /// grown where the new lattice needs more room (to the next power of two), and of the cells,
    /// gather list, node data and rest positions only the 4 KiB blocks that changed are written.
    /// Returns the bytes written and the bytes the lattice's data take. The state is sent by the
    /// next [`GpuStepper::upload`]; steppers with an FLSM part are not refitted.
    pub fn refit(
        &mut self,
        tled: &Tled,
        integrator: &Integrator,
        f_ext: &[Vector3<f32>],
        rest: &[Vector3<f32>],
    ) -> Result<(u64, u64), SimError> {
        let nodes = integrator.u.len();
        if self.flsm.is_some() {
            return Err(SimError::Gpu("a stepper with an FLSM part is built anew, not refitted".into()));
        }
        if tled.node_count != nodes || f_ext.len() != nodes || rest.len() != nodes {
            return Err(SimError::Gpu(format!(
                "{} lattice nodes, {nodes} integrator nodes, {} external forces and {} rest positions",
                tled.node_count,
                f_ext.len(),
                rest.len()
            )));
        }
        let gpu = Arc::clone(&self.gpu);
        let cells = tled.cell_nodes.len();
        self.cells.params.cells =
            u32::try_from(cells).map_err(|_| SimError::Gpu(format!("{cells} cells: too many")))?;
        self.cells.params.nodes =
            u32::try_from(nodes).map_err(|_| SimError::Gpu(format!("{nodes} nodes: too many")))?;
        gpu.queue.write_buffer(&self.cells.uniform, 0, bytemuck::bytes_of(&self.cells.params));
        let (mut written, mut total, mut grown) = (0u64, 0u64, false);
        let mut refill = |label: &str, buffer: &mut wgpu::Buffer, shadow: &mut Vec<u8>, data: &[u8]| {
            let (w, g) = refill(&gpu, label, buffer, shadow, data)?;
            written += w;
            total += data.len() as u64;
            grown |= g;
            Ok::<(), SimError>(())
        };
        let s = &mut self.shadows;
        refill(
            "cell nodes",
            &mut self.cells.cell_nodes,
            &mut s.cell_nodes,
            bytemuck::cast_slice(tled.cell_nodes.as_flattened()),
        )?;
        refill("cell volumes", &mut self.cells.volume, &mut s.volume, bytemuck::cast_slice(&tled.volume))?;
        let list = super::gather_list(&tled.cell_nodes, nodes);
        refill("gather list", &mut self.cells.gather_list, &mut s.gather_list, bytemuck::cast_slice(&list))?;
        let data = node_data_of(integrator, f_ext);
        refill("node data", &mut self.node_data, &mut s.node_data, bytemuck::cast_slice(&data))?;
        refill("rest positions", &mut self.rest, &mut s.rest, bytemuck::cast_slice(&flatten(rest)))?;
        let mut room = |label: &str, buffer: &mut wgpu::Buffer, bytes: u64| -> Result<(), SimError> {
            if buffer.size() < bytes {
                *buffer = grown_buffer(&gpu, label, bytes)?;
                grown = true;
            }
            Ok(())
        };
        room("cell forces", &mut self.cells.cell_forces, 96 * cells as u64)?;
        for (i, u) in self.u.iter_mut().enumerate() {
            room(["displacements 0", "displacements 1", "displacements 2"][i], u, 12 * nodes as u64)?;
        }
        if grown {
            self.bind();
        }
        self.contact_binds = None;
        Ok((written, total))
    }

    /// (Re)creates the bind groups of the element, node and tick passes over the current buffers.
    fn bind(&mut self) {
        let (gpu, cells, u) = (&*self.gpu, &self.cells, &self.u);
        self.element_binds = [0, 1, 2].map(|i| cells.element_bind(gpu, &u[i]));
        self.node_binds = [0, 1, 2].map(|r| node_bind(gpu, &self.node, cells, &self.node_data, u, r));
        self.tick.1 = gpu.bind(&self.tick.0, &[&cells.status]);
    }

    /// What the contact pass resolves from the next step on: free nodes inside the obstacle's grid
    /// move out by at most `max_push` metres per step and stop; nodes below the table are put
    /// back on it with friction (nothing when `shapes` holds neither).
    pub fn set_contacts(&mut self, shapes: &ContactShapes, max_push: f32) -> Result<(), SimError> {
        if shapes.grid.is_none() && shapes.table.is_none() {
            self.contact_binds = None;
            return Ok(());
        }
        let empty = [[0.0f32; 4]];
        let (origin, h, dims, grid) = match &shapes.grid {
            Some(g) => (g.origin, g.h, g.dims, g.voxels.as_slice()),
            None => ([0.0; 3], 1.0, [0; 3], &empty[..]),
        };
        let table = shapes.table.map_or([0.0; 4], |(height, friction)| [height, friction, 1.0, 0.0]);
        let params = ContactParams { origin, h, dims, max_push, table };
        let gpu = &*self.gpu;
        let uniform = gpu.uniform("contacts", &params);
        let grid = gpu.storage("obstacle grid", grid).map_err(gpu_err)?;
        self.contact_binds = Some([0, 1, 2].map(|r| {
            gpu.bind_numbered(
                &self.contact,
                &[
                    (0, &self.cells.uniform),
                    (1, &self.cells.status),
                    (2, &uniform),
                    (3, &grid),
                    (4, &self.rest),
                    (5, &self.node_data),
                    (6, &self.u[(r + 2) % 3]),
                    (7, &self.u[(r + 1) % 3]),
                ],
            )
        }));
        Ok(())
    }

    /// The device in use.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// Sends the FLSM nodes' velocities (the hybrid only).
    pub(crate) fn upload_flsm_velocities(&self, v: &[Vector3<f32>]) {
        if let Some(f) = &self.flsm {
            let v: Vec<[f32; 4]> = v.iter().map(|v| [v.x, v.y, v.z, 0.0]).collect();
            self.gpu.queue.write_buffer(&f.buffers.vel, 0, bytemuck::cast_slice(&v));
        }
    }

    /// The FLSM nodes' velocities and every node's goal displacement (goal − rest) of the last
    /// FLSM step (the hybrid only).
    pub(crate) fn read_flsm(&self) -> Result<Option<FlsmState>, SimError> {
        let Some(f) = &self.flsm else { return Ok(None) };
        let n = self.cells.params.nodes as usize;
        let read = |b: &wgpu::Buffer, what: &str| -> Result<Vec<Vector3<f32>>, SimError> {
            let raw: Vec<[f32; 4]> = self.gpu.read(what, b, n).map_err(gpu_err)?;
            Ok(raw.iter().map(|v| Vector3::new(v[0], v[1], v[2])).collect())
        };
        Ok(Some(FlsmState { v: read(&f.buffers.vel, "flsm velocities")?, goals: read(&f.buffers.goal, "flsm goals")? }))
    }

    /// Sends the integrator's state (current and previous displacements).
    pub fn upload(&mut self, integrator: &Integrator) {
        let r = self.rotation;
        let queue = &self.gpu.queue;
        queue.write_buffer(&self.u[r], 0, bytemuck::cast_slice(&flatten(&integrator.u_prev)));
        queue.write_buffer(&self.u[(r + 1) % 3], 0, bytemuck::cast_slice(&flatten(&integrator.u)));
    }

    /// Runs `steps` steps from the uploaded state, the first of them step `start + 1` (its time
    /// sets the prescribed ramps), and reads back the state they end in.
    pub fn run(&mut self, start: u64, steps: u32) -> Result<StepBatch, SimError> {
        let substeps = self.flsm.as_ref().map_or(1, |f| f.buffers.substeps);
        if !steps.is_multiple_of(substeps) {
            return Err(SimError::Gpu(format!("{steps} steps: not whole FLSM steps of {substeps}")));
        }
        let start32 = u32::try_from(start + u64::from(steps))
            .map_err(|_| SimError::Gpu(format!("step {start}: beyond the GPU's 32-bit step counter")))?
            - steps;
        let gpu = &*self.gpu;
        gpu.queue.write_buffer(&self.cells.status, 0, bytemuck::cast_slice(&status_init(start32)));
        let (cells, nodes) = (self.cells.params.cells, self.cells.params.nodes);
        let mut done = 0;
        let mut device_ns = None;
        while done < steps {
            let batch = (steps - done).min(STEPS_PER_SUBMIT.next_multiple_of(substeps));
            let mut encoder =
                gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("tled steps") });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("tled steps"),
                    timestamp_writes: self.timer.as_ref().map(hullcut_gpu::PassTimer::writes),
                });
                for i in done..done + batch {
                    let r = (self.rotation + i as usize) % 3;
                    if let Some(flsm) = &self.flsm
                        && i % substeps == 0
                    {
                        flsm.record(&mut pass, r);
                    }
                    pass.set_pipeline(&self.cells.element);
                    pass.set_bind_group(0, &self.element_binds[(r + 1) % 3], &[]);
                    pass.dispatch_workgroups(cells.div_ceil(WORKGROUP), 1, 1);
                    pass.set_pipeline(&self.node);
                    pass.set_bind_group(0, &self.node_binds[r], &[]);
                    pass.dispatch_workgroups(nodes.div_ceil(WORKGROUP), 1, 1);
                    if let Some(binds) = &self.contact_binds {
                        pass.set_pipeline(&self.contact);
                        pass.set_bind_group(0, &binds[r], &[]);
                        pass.dispatch_workgroups(nodes.div_ceil(WORKGROUP), 1, 1);
                    }
                    pass.set_pipeline(&self.tick.0);
                    pass.set_bind_group(0, &self.tick.1, &[]);
                    pass.dispatch_workgroups(1, 1, 1);
                }
            }
            if let Some(t) = &self.timer {
                t.resolve(&mut encoder);
            }
            gpu.queue.submit([encoder.finish()]);
            gpu.wait("TLED steps").map_err(gpu_err)?;
            if let Some(t) = &self.timer {
                *device_ns.get_or_insert(0.0) += t.elapsed_ns(gpu).map_err(gpu_err)?;
            }
            done += batch;
        }
        let s = self.cells.read_status(gpu)?;
        let completed = s[status::STEP] - start32;
        let r = (self.rotation + completed as usize) % 3;
        let n = 3 * nodes as usize;
        let read = |i: usize| -> Result<Vec<Vector3<f32>>, SimError> {
            Ok(unflatten(&gpu.read::<f32>("displacements", &self.u[i], n).map_err(gpu_err)?))
        };
        let batch = StepBatch {
            completed,
            diverged_node: (s[status::DIVERGED] != 0).then_some(s[status::NODE]),
            inverted_cell_steps: s[status::INVERTED],
            contacts: s[status::CONTACTS],
            table_contacts: s[status::TABLE_CONTACTS],
            device_ns,
            u: read((r + 1) % 3)?,
            u_prev: read(r)?,
            u_older: read((r + 2) % 3)?,
        };
        self.rotation = r;
        Ok(batch)
    }
}
