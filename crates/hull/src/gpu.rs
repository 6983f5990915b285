//! Octree carving on the GPU (wgpu, WGSL): one dispatch per octree level tests every cell of
//! that level against every view's summed-area table, with the rules of [`crate::carve`]
//! (footprint with a margin, k-of-N refutation, occlusion-aware labels with `min_support`,
//! exclusive labels, uniform cells kept whole). Cells to split append their eight children to
//! the next level's list, kept cells to the output, both through an integer atomic counter (no
//! float atomics); the CPU reads back only the counters and the kept cells of each level.
//!
//! Differences from the CPU carver, by construction:
//! - corners are projected in f32 instead of f64, so a footprint bound within rounding of a
//!   pixel edge may round the other way: such cells are counted ([`GpuCarveStats::near_threshold`])
//!   and are the only ones whose verdict can differ. "Within rounding" is 2e-3 px: a pixel
//!   coordinate of up to 10³ carries about 10³ · 2⁻²⁴ ≈ 6e-5 px per f32 operation, and a
//!   projection is some thirty dependent ones;
//! - every view is tested for every cell (no early exit), so `footprint_tests` is cells × views;
//! - the kept cells come level by level, not depth first (the same set).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use hullcut_gpu::Gpu;
use nalgebra::{Point3, Vector3};

use crate::{CarveStats, Cell, HullError, HullParams, Occupancy, Silhouette};

/// Invocations per workgroup.
const WORKGROUP: u32 = 64;
/// Most views the counters have room for.
pub const MAX_VIEWS: usize = 16;

/// Counter slots: next-level cells, kept cells, kept against a refutation, unused, near
/// threshold, unseen (too few views), then lone refutations per view.
const COUNTERS: usize = 6 + MAX_VIEWS;

/// Per-dispatch constants (64 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Params {
    origin: [f32; 3],
    extent: f32,
    margin: f32,
    views: u32,
    votes: u32,
    min_support: u32,
    exclusive: u32,
    leaf_level: u32,
    count: u32,
    level: u32,
    /// The working volume's upper corner in leaves from the origin (`carve::box_in_leaves`).
    box_hi: [f32; 3],
    min_views: u32,
}

/// A view's camera and the place of its table (112 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct View {
    /// Rows of R, with t's component in w.
    r: [[f32; 4]; 3],
    /// fx, fy, cx, cy.
    k: [f32; 4],
    /// k1, k2, p1, p2.
    d: [f32; 4],
    /// k3, the lens' invertible radius, width, height.
    e: [f32; 4],
    /// Offset of the table (in entries of three counts), its row stride, 1 where points beyond the
    /// radius in `e` are clamped to it (the field's radius) rather than unknown, and the bits of
    /// the f32 distortion curvature bound (`Silhouette::curvature`).
    table: [u32; 4],
}

const CARVE_WGSL: &str = "
struct Params {
    origin: vec3<f32>,
    extent: f32,
    margin: f32,
    views: u32,
    votes: u32,
    min_support: u32,
    exclusive: u32,
    leaf_level: u32,
    count: u32,
    level: u32,
    box_hi: vec3<f32>,
    min_views: u32,
}
struct View {
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    k: vec4<f32>,
    d: vec4<f32>,
    e: vec4<f32>,
    table: vec4<u32>,
}
@group(0) @binding(0) var<uniform> c: Params;
@group(0) @binding(1) var<storage, read> views: array<View>;
@group(0) @binding(2) var<storage, read> tables: array<u32>;
@group(0) @binding(3) var<storage, read> cells: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read_write> next: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> kept: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>>;

// A footprint bound closer than 2e-3 px to a pixel edge counts as within rounding (near_edge).
// Pixel of world point p (w = 1), or w = -2 behind the camera, w = -1 beyond the lens' invertible
// radius of a camera whose image reaches it (points beyond the field's radius are clamped to it).
fn project(v: View, p: vec3<f32>) -> vec3<f32> {
    let pc = vec3<f32>(dot(v.r0.xyz, p) + v.r0.w, dot(v.r1.xyz, p) + v.r1.w, dot(v.r2.xyz, p) + v.r2.w);
    if (pc.z <= 1e-3) {
        return vec3<f32>(0.0, 0.0, -2.0);
    }
    var x = pc.x / pc.z;
    var y = pc.y / pc.z;
    var r2 = x * x + y * y;
    let r = sqrt(r2);
    if (r >= v.e.y) {
        if (v.table.z == 0u) {
            return vec3<f32>(0.0, 0.0, -1.0);
        }
        x = x * (v.e.y / r);
        y = y * (v.e.y / r);
        r2 = x * x + y * y;
    }
    let radial = 1.0 + r2 * (v.d.x + r2 * (v.d.y + r2 * v.e.x));
    let xd = x * radial + 2.0 * v.d.z * x * y + v.d.w * (r2 + 2.0 * x * x);
    let yd = y * radial + v.d.z * (r2 + 2.0 * y * y) + 2.0 * v.d.w * x * y;
    return vec3<f32>(v.k.x * xd + v.k.z, v.k.y * yd + v.k.w, 1.0);
}

fn near_edge(x: f32) -> bool {
    let f = x - floor(x);
    return f < 2e-3 || f > 1.0 - 2e-3;
}

fn entry(v: View, i: u32, j: u32) -> vec3<u32> {
    let o = 3u * (v.table.x + j * v.table.y + i);
    return vec3<u32>(tables[o], tables[o + 1u], tables[o + 2u]);
}

@compute @workgroup_size(64)
fn judge(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x;
    if (idx >= c.count) {
        return;
    }
    let cell = cells[idx];
    let size = c.extent / f32(1u << c.level);
    let lo_corner = c.origin + vec3<f32>(cell.xyz) * size;
    // The cell against the volume's box, in whole leaves (as the CPU carver does).
    let n = f32(1u << (c.leaf_level - c.level));
    let lo_leaf = vec3<f32>(cell.xyz) * n;
    if (any(lo_leaf >= c.box_hi)) {
        return;
    }
    let inside_box = all(lo_leaf + vec3<f32>(n) <= c.box_hi);
    if (!inside_box && n <= 1.0 && any(lo_leaf + vec3<f32>(0.5) > c.box_hi)) {
        return;
    }
    var covered = 0u;
    var reach = 0u;
    var unknown = 0u;
    var refutes = 0u;
    var sees = 0u;
    var refuter = 0u;
    var hand = 0u;
    var scalpel = 0u;
    var hand_share = 0.0;
    var scalpel_share = 0.0;
    var uniform_cell = inside_box || n <= 1.0;
    var uniform_label = 0u;
    var near = false;
    for (var v = 0u; v < c.views; v++) {
        let view = views[v];
        var lo = vec2<f32>(3.0e38);
        var hi = vec2<f32>(-3.0e38);
        var seen = true;
        var behind = 0u;
        for (var k = 0u; k < 8u; k++) {
            let offset = vec3<f32>(f32(k & 1u), f32((k >> 1u) & 1u), f32((k >> 2u) & 1u));
            let uv = project(view, lo_corner + offset * size);
            if (uv.z < 0.0) {
                seen = false;
                behind += select(0u, 1u, uv.z < -1.5);
                continue;
            }
            lo = min(lo, uv.xy);
            hi = max(hi, uv.xy);
        }
        // 0: abstains, 1: refutes, 2: sees.
        var verdict = 0u;
        var counts = vec3<u32>(0u);
        var total = 0u;
        var footprint_inside = false;
        // An unprojectable corner: part of the cell may be in view, unless the whole cell lies
        // behind the camera.
        let all_behind = behind == 8u;
        var reaches = !seen && !all_behind;
        if (seen) {
            let extent = max(hi.x - lo.x, hi.y - lo.y);
            let margin = c.margin + bitcast<f32>(view.table.w) * extent * extent;
            let a = lo - vec2<f32>(margin);
            let b = hi + vec2<f32>(margin);
            near = near || near_edge(a.x) || near_edge(a.y) || near_edge(b.x) || near_edge(b.y);
            // No pixel centre inside: the two whose centres bracket the rectangle.
            let i0 = min(ceil(a.x), floor(b.x));
            let j0 = min(ceil(a.y), floor(b.y));
            let i1 = max(ceil(a.x), floor(b.x));
            let j1 = max(ceil(a.y), floor(b.y));
            let w = view.e.z;
            let h = view.e.w;
            let inside = i0 >= 0.0 && j0 >= 0.0 && i1 <= w - 1.0 && j1 <= h - 1.0;
            let ci0 = max(i0, 0.0);
            let cj0 = max(j0, 0.0);
            let ci1 = min(i1, w - 1.0);
            let cj1 = min(j1, h - 1.0);
            if (ci0 <= ci1 && cj0 <= cj1) {
                let x0 = u32(ci0);
                let y0 = u32(cj0);
                let x1 = u32(ci1);
                let y1 = u32(cj1);
                counts = entry(view, x1 + 1u, y1 + 1u) + entry(view, x0, y0) - entry(view, x1 + 1u, y0)
                    - entry(view, x0, y1 + 1u);
                total = (x1 - x0 + 1u) * (y1 - y0 + 1u);
                reaches = true;
                footprint_inside = inside;
                if (counts.x + counts.y + counts.z == 0u) {
                    verdict = select(0u, 1u, inside);
                } else {
                    verdict = 2u;
                }
            }
        }
        reach += select(0u, 1u, reaches);
        unknown += select(0u, 1u, !seen && !all_behind);
        covered += select(0u, 1u, footprint_inside && verdict != 0u);
        if (verdict == 1u) {
            refutes += 1u;
            refuter = v;
            uniform_cell = false;
        } else if (verdict == 0u) {
            uniform_cell = false;
        } else {
            sees += 1u;
            hand += select(0u, 1u, counts.x > 0u);
            scalpel += select(0u, 1u, counts.y > 0u);
            hand_share += f32(counts.x) / f32(total);
            scalpel_share += f32(counts.y) / f32(total);
            var single = 0u;
            if (counts.x == total) {
                single = 1u;
            } else if (counts.y == total) {
                single = 2u;
            }
            if (single != 0u && (uniform_label == 0u || uniform_label == single)) {
                uniform_label = single;
            } else {
                uniform_cell = false;
            }
        }
    }
    if (near) {
        atomicAdd(&counters[4], 1u);
    }
    if (refutes == 1u && sees + 1u == c.views && sees > 0u) {
        atomicAdd(&counters[6u + refuter], 1u);
    }
    if (refutes >= c.votes) {
        return;
    }
    if (reach < c.min_views || sees + unknown + c.votes - 1u < c.min_views) {
        atomicAdd(&counters[5], 1u);
        return;
    }
    if (c.level < c.leaf_level && (!uniform_cell || covered < c.min_views)) {
        let base = atomicAdd(&counters[0], 8u);
        for (var k = 0u; k < 8u; k++) {
            next[base + k] = vec4<u32>(2u * cell.x + (k & 1u), 2u * cell.y + ((k >> 1u) & 1u), 2u * cell.z + ((k >> 2u) & 1u), 0u);
        }
        return;
    }
    if (covered < c.min_views) {
        atomicAdd(&counters[5], 1u);
        return;
    }
    if (refutes > 0u) {
        atomicAdd(&counters[2], 1u);
    }
    // A leaf is solid when fewer than `votes` views see background at the pixel nearest its
    // centre's projection, and then takes its labels from those pixels; larger kept cells are
    // uniform (solid), and slivers take their labels from their footprints.
    var solid = true;
    var label_hand = hand;
    var label_scalpel = scalpel;
    if (c.level >= c.leaf_level) {
        let centre = lo_corner + vec3<f32>(0.5 * size);
        var refuting = 0u;
        var centre_hand = 0u;
        var centre_scalpel = 0u;
        for (var v = 0u; v < c.views; v++) {
            let view = views[v];
            let uv = project(view, centre);
            if (uv.z < 0.0) {
                continue;
            }
            let i = floor(uv.x + 0.5);
            let j = floor(uv.y + 0.5);
            if (i >= 0.0 && j >= 0.0 && i < view.e.z && j < view.e.w) {
                let n = entry(view, u32(i) + 1u, u32(j) + 1u) + entry(view, u32(i), u32(j))
                    - entry(view, u32(i) + 1u, u32(j)) - entry(view, u32(i), u32(j) + 1u);
                refuting += select(0u, 1u, n.x + n.y + n.z == 0u);
                centre_hand += n.x;
                centre_scalpel += n.y;
            }
        }
        solid = refuting < c.votes;
        if (solid) {
            label_hand = centre_hand;
            label_scalpel = centre_scalpel;
        }
    }
    var has_hand = label_hand >= c.min_support;
    var has_scalpel = label_scalpel >= c.min_support;
    if (c.exclusive != 0u && has_hand && has_scalpel) {
        if (label_hand == label_scalpel) {
            has_hand = hand_share >= scalpel_share;
        } else {
            has_hand = label_hand > label_scalpel;
        }
        has_scalpel = !has_hand;
    }
    let out = atomicAdd(&counters[1], 1u);
    kept[out] = vec4<u32>(cell.xyz, c.level | select(0u, 256u, has_hand) | select(0u, 512u, has_scalpel)
        | select(0u, 1024u, solid) | select(0u, (refuter + 1u) << 11u, refutes > 0u));
}
";

/// Counters the GPU carver adds to [`CarveStats`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GpuCarveStats {
    /// Cells (of any level) with a footprint bound within rounding of a pixel edge in some view:
    /// the only cells whose verdict may differ from the CPU's f64 carver.
    pub near_threshold: u64,
    /// Dispatches (octree levels) run.
    pub levels: u32,
}

/// A storage buffer that grows as needed and is otherwise reused.
#[derive(Debug, Default)]
struct Growing {
    buffer: Option<wgpu::Buffer>,
    bytes: u64,
}

impl Growing {
    fn with_room(&mut self, gpu: &Gpu, label: &str, bytes: u64) -> Result<&wgpu::Buffer, HullError> {
        let bytes = bytes.max(16);
        if self.buffer.is_none() || self.bytes < bytes {
            let bytes = bytes.next_power_of_two();
            gpu.check_storage(label, bytes).map_err(|e| HullError::Gpu(e.to_string()))?;
            self.buffer = Some(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
            self.bytes = bytes;
        }
        self.buffer.as_ref().ok_or_else(|| HullError::Gpu(format!("{label}: no buffer")))
    }
}

/// Carving on a GPU; keeps its buffers from frame to frame.
#[derive(Debug)]
pub struct GpuCarver {
    gpu: Arc<Gpu>,
    pipeline: wgpu::ComputePipeline,
    tables: Growing,
    views: Growing,
    lists: [Growing; 2],
    kept: Growing,
    counters: wgpu::Buffer,
    /// Counters of the last carve.
    pub last: GpuCarveStats,
}

fn gpu_err(e: hullcut_gpu::GpuError) -> HullError {
    HullError::Gpu(e.to_string())
}

impl GpuCarver {
    /// Compiles the carving kernel on `gpu`.
    pub fn new(gpu: Arc<Gpu>) -> Result<Self, HullError> {
        let have = gpu.summary.limits.max_storage_buffers_per_shader_stage;
        if have < 6 {
            return Err(HullError::Gpu(format!(
                "{} allows {have} storage buffers per shader stage; carving needs 6",
                gpu.summary.info.name
            )));
        }
        let pipeline = gpu.pipeline("hull carving", CARVE_WGSL, "judge");
        let counters = gpu.storage("carving counters", &[0u32; COUNTERS]).map_err(gpu_err)?;
        Ok(Self {
            gpu,
            pipeline,
            tables: Growing::default(),
            views: Growing::default(),
            lists: [Growing::default(), Growing::default()],
            kept: Growing::default(),
            counters,
            last: GpuCarveStats::default(),
        })
    }

    /// Carves the hull of the views' silhouettes, as [`crate::carve`] does on the CPU (the blade's
    /// refinement, [`HullParams::blade_levels`], runs on the CPU afterwards).
    pub fn carve(&mut self, views: &[Option<Silhouette>], params: &HullParams) -> Result<Occupancy, HullError> {
        let (leaf_level, extent) = crate::carve::check(views, params)?;
        crate::carve::check_refine(params, leaf_level)?;
        let present: Vec<&Silhouette> = views.iter().flatten().collect();
        if present.len() > MAX_VIEWS {
            return Err(HullError::Gpu(format!("{} views; the GPU carver takes at most {MAX_VIEWS}", present.len())));
        }
        let gpu = &*self.gpu;
        // Views and their tables, concatenated.
        let mut table: Vec<u32> = Vec::new();
        let mut cams = Vec::with_capacity(present.len());
        for s in &present {
            let offset = table.len() / 3;
            let Some(stride) = s.extend_whole_table(&mut table) else {
                return Err(HullError::Gpu(
                    "a silhouette without summed-area tables cannot be carved on the GPU".into(),
                ));
            };
            let cam = s.camera();
            let r = cam.rotation.matrix();
            let t = cam.translation;
            let row = |i: usize| [r[(i, 0)] as f32, r[(i, 1)] as f32, r[(i, 2)] as f32, t[i] as f32];
            let d = &cam.distortion;
            cams.push(View {
                r: [row(0), row(1), row(2)],
                k: [cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32],
                d: [d.k1 as f32, d.k2 as f32, d.p1 as f32, d.p2 as f32],
                e: [
                    d.k3 as f32,
                    s.field_radius().unwrap_or(s.monotonic_radius()).min(f64::from(f32::MAX)) as f32,
                    cam.width as f32,
                    cam.height as f32,
                ],
                table: [
                    offset as u32,
                    stride as u32,
                    u32::from(s.field_radius().is_some()),
                    (s.curvature() as f32).to_bits(),
                ],
            });
        }
        let tables = self.tables.with_room(gpu, "silhouette tables", 4 * table.len() as u64)?;
        gpu.queue.write_buffer(tables, 0, bytemuck::cast_slice(&table));
        let view_buf = self.views.with_room(gpu, "views", size_of_val(&cams[..]) as u64)?;
        gpu.queue.write_buffer(view_buf, 0, bytemuck::cast_slice(&cams));

        let start = params.start_level.min(leaf_level);
        let n = 1u32 << start;
        let origin = params.workspace.min;
        // Only the roots that reach into the volume's box.
        let size0 = extent / f64::from(n);
        let reach = |a: usize| ((params.workspace.max[a] - origin[a]) / size0).ceil().clamp(1.0, f64::from(n)) as u32;
        let dims = [reach(0), reach(1), reach(2)];
        let roots: Vec<[u32; 4]> = (0..dims[0] * dims[1] * dims[2])
            .map(|k| [k % dims[0], (k / dims[0]) % dims[1], k / (dims[0] * dims[1]), 0])
            .collect();
        let box_hi = crate::carve::box_in_leaves(params);
        let min_views = params.min_views.min(present.len()).max(1) as u32;
        let mut p = Params {
            origin: origin.coords.cast::<f32>().into(),
            extent: extent as f32,
            margin: params.margin_px as f32,
            views: present.len() as u32,
            votes: params.carve_votes as u32,
            min_support: params.min_support as u32,
            exclusive: u32::from(params.exclusive_labels),
            leaf_level,
            count: roots.len() as u32,
            level: start,
            box_hi: [box_hi.x as f32, box_hi.y as f32, box_hi.z as f32],
            min_views,
        };
        let list = self.lists[0].with_room(gpu, "octree cells", 16 * roots.len() as u64)?;
        gpu.queue.write_buffer(list, 0, bytemuck::cast_slice(&roots));
        let mut stats = CarveStats {
            views_used: present.len(),
            views_missing: views.len() - present.len(),
            lone_refutations: vec![0; views.len()],
            ..CarveStats::default()
        };
        let mut last = GpuCarveStats::default();
        // Present view n is entry rig_index[n] of `views`.
        let rig_index: Vec<usize> = views.iter().enumerate().filter(|(_, v)| v.is_some()).map(|(k, _)| k).collect();
        let mut counters = [0u32; COUNTERS];
        let mut cells = Vec::new();
        let mut current = 0;
        while p.count > 0 {
            let count = u64::from(p.count);
            // Room for every cell's children in the next list and for every cell in the output.
            let [a, b] = &mut self.lists;
            let (from, to) = if current == 0 { (a, b) } else { (b, a) };
            let to = to.with_room(gpu, "octree cells", 16 * 8 * count)?;
            let from = from.with_room(gpu, "octree cells", 16 * count)?;
            let kept = self.kept.with_room(gpu, "kept cells", 16 * count)?;
            let uniform = gpu.uniform("carving params", &p);
            gpu.queue.write_buffer(&self.counters, 0, bytemuck::cast_slice(&[0u32; COUNTERS]));
            let bind = gpu.bind(
                &self.pipeline,
                &[&uniform, view_buf_of(&self.views)?, tables_of(&self.tables)?, from, to, kept, &self.counters],
            );
            gpu.dispatch(&self.pipeline, &bind, p.count, WORKGROUP);
            let c: Vec<u32> = gpu.read("carving counters", &self.counters, COUNTERS).map_err(gpu_err)?;
            counters.copy_from_slice(&c);
            let kept_cells: Vec<[u32; 4]> = gpu.read("kept cells", kept, counters[1] as usize).map_err(gpu_err)?;
            let size = extent / f64::from(1u32 << p.level);
            for k in &kept_cells {
                let min = origin + Vector3::new(f64::from(k[0]), f64::from(k[1]), f64::from(k[2])) * size;
                cells.push(Cell {
                    min: Point3::from(min.coords),
                    size,
                    hand: k[3] & 256 != 0,
                    scalpel: k[3] & 512 != 0,
                    solid: k[3] & 1024 != 0,
                    // Bits 11 and up: the refuting present view + 1, or 0.
                    refuted_by: (k[3] >> 11).checked_sub(1).and_then(|v| rig_index.get(v as usize)).map(|&r| r as u16),
                });
            }
            stats.cells_visited += count;
            stats.footprint_tests += count * present.len() as u64;
            stats.kept_against_refutation += u64::from(counters[2]);
            stats.unseen_cells += u64::from(counters[5]);
            last.near_threshold += u64::from(counters[4]);
            last.levels += 1;
            for (&k, n) in rig_index.iter().zip(&counters[6..]) {
                stats.lone_refutations[k] += u64::from(*n);
            }
            p.count = counters[0];
            p.level += 1;
            current = 1 - current;
        }
        self.last = last;
        let occ = crate::carve::finish(cells, stats, params, leaf_level, extent);
        crate::carve::refine_label(views, params, occ, hullcut_dataset::label::SCALPEL, params.blade_levels)
    }
}

fn view_buf_of(g: &Growing) -> Result<&wgpu::Buffer, HullError> {
    g.buffer.as_ref().ok_or_else(|| HullError::Gpu("views: no buffer".into()))
}

fn tables_of(g: &Growing) -> Result<&wgpu::Buffer, HullError> {
    g.buffer.as_ref().ok_or_else(|| HullError::Gpu("tables: no buffer".into()))
}
