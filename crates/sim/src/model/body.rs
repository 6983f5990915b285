//! Bodies to simulate and their voxelization into a [`Lattice`].
//!
//! A [`Body`] is a box, a triangle mesh read from a file, or the built-in liver-like organ.
//! [`voxelize`] covers the body's bounds with a grid of cubic cells and gives each cell the share of
//! its volume inside the body, from `samples³` sub-cell samples (exactly for the box). Mesh insides
//! are decided by generalized winding numbers, so meshes with small holes still voxelize (with a
//! warning).

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::lattice::Lattice;
use crate::mesh::{MeshError, TriMesh, WindingTree, push_quad};

/// A body to simulate, in metres.
#[derive(Debug, Clone, PartialEq)]
pub enum Body {
    /// The box spanning `[0, size]`.
    Box {
        /// Edge lengths along x, y, z.
        size: Vector3<f64>,
    },
    /// A triangle mesh, ideally closed and outward-oriented, and the file it was read from (for
    /// messages; `None` for a mesh built in memory).
    Mesh(TriMesh, Option<PathBuf>),
    /// The built-in liver-like organ (see [`organ_sdf`]), its size multiplied by `scale` about
    /// the origin (it stays centred on the table): 1 is the built-in organ (0.435 l),
    /// [`LARGE_ORGAN_SCALE`] an adult liver's size.
    Organ {
        /// Size factor, 1 for the built-in organ.
        scale: f64,
    },
}

/// Size factor of the large built-in organ (`--tissue organ-large`, `body.scale` of an organ
/// scenario): 1.2 makes it 18 x 12 x 7.2 cm, 0.75 litres, a small adult liver, with more than
/// 100,000 lattice nodes at 2 mm cells.
pub const LARGE_ORGAN_SCALE: f64 = 1.2;

/// Vertex spacing of the organ's surface mesh and the finest spacing of a box's surface, metres.
pub const SURFACE_SPACING: f64 = 0.0025;

impl Body {
    /// Reads a mesh body from a `.ply` or `.obj` file, multiplying coordinates by `scale` to get
    /// metres (1 for a file in metres, 0.001 for millimetres).
    pub fn load_mesh(path: impl AsRef<Path>, scale: f64) -> Result<Self, MeshError> {
        let path = path.as_ref();
        let mut mesh = TriMesh::load(path)?;
        if scale != 1.0 {
            mesh.scale(scale);
        }
        Ok(Self::Mesh(mesh, Some(path.to_owned())))
    }

    /// Axis-aligned bounds `(min, max)`; for the organ, those of its analytic shape.
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        match self {
            Self::Box { size } => (Point3::origin(), Point3::from(*size)),
            Self::Mesh(m, _) => m.bounds().unwrap_or((Point3::origin(), Point3::origin())),
            Self::Organ { scale } => (Point3::from(ORGAN_MIN) * *scale, Point3::from(ORGAN_MAX) * *scale),
        }
    }

    /// Whether `p` is inside: for a mesh, |winding number| > 0.5 (either orientation), summed exactly,
    /// O(triangles) per call.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        match self {
            Self::Box { size } => (0..3).all(|a| p[a] >= 0.0 && p[a] <= size[a]),
            Self::Mesh(m, _) => m.winding_number(p).abs() > 0.5,
            Self::Organ { scale } => scaled_organ_sdf(p, *scale) < 0.0,
        }
    }

    /// The body's surface as a triangle mesh, for embedding in the lattice and display: the box's
    /// faces split into squares of at most [`SURFACE_SPACING`] (at most 64 per edge), the mesh itself,
    /// or [`Body::organ_mesh`] at the organ's scale.
    pub fn surface(&self) -> TriMesh {
        match self {
            Self::Box { size } => {
                let n = [0, 1, 2].map(|a| ((size[a] / SURFACE_SPACING).ceil().max(1.0) as usize).min(64));
                TriMesh::cuboid_grid(Point3::origin(), Point3::from(*size), n)
            }
            Self::Mesh(m, _) => m.clone(),
            Self::Organ { scale } => Self::organ_mesh(*scale),
        }
    }

    /// The surface of the organ at size factor `scale`: the zero set of [`organ_sdf`] extracted by
    /// surface nets on a [`SURFACE_SPACING`] grid, vertices projected onto the zero set. Closed and
    /// outward-oriented (about 14 000 triangles at scale 1).
    pub fn organ_mesh(scale: f64) -> TriMesh {
        let h = SURFACE_SPACING;
        // Start 2.5 spacings below the bounds so that no grid node lies on the flat underside z = 0 and
        // the outermost nodes are all outside.
        let (lo, hi) = (Point3::from(ORGAN_MIN) * scale, Point3::from(ORGAN_MAX) * scale);
        let start = lo - Vector3::repeat(2.5 * h);
        let n = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / h).ceil() as usize + 6);
        surface_nets(&|p| scaled_organ_sdf(p, scale), start, h, n)
    }
}

impl fmt::Display for Body {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Box { size } => write!(f, "box {} x {} x {} m", size.x, size.y, size.z),
            Self::Mesh(_, Some(path)) => write!(f, "mesh {}", path.display()),
            Self::Mesh(m, None) => write!(f, "mesh ({} triangles)", m.triangles.len()),
            Self::Organ { scale } if *scale == 1.0 => write!(f, "built-in organ"),
            Self::Organ { scale } => write!(f, "built-in organ at {scale} times its size"),
        }
    }
}

/// One lobe of the organ: an ellipsoid.
struct Lobe {
    center: [f64; 3],
    radii: [f64; 3],
}

/// The right lobe (patient's right, at -x), the larger and thicker one.
const RIGHT_LOBE: Lobe = Lobe { center: [-0.025, 0.0, 0.015], radii: [0.05, 0.05, 0.045] };
/// The left lobe, smaller and thinner.
const LEFT_LOBE: Lobe = Lobe { center: [0.035, 0.01, 0.005], radii: [0.04, 0.035, 0.03] };
/// Width of the smooth union between the lobes, metres.
const LOBE_BLEND: f64 = 0.012;
/// Bounds of the organ: the lobes' extents, cut at the table z = 0.
const ORGAN_MIN: [f64; 3] = [-0.075, -0.05, 0.0];
const ORGAN_MAX: [f64; 3] = [0.075, 0.05, 0.06];

impl Lobe {
    /// Signed distance estimate to the ellipsoid (Quílez's first-order bound form): exact zero set,
    /// negative inside, close to the distance near the surface.
    fn sdf(&self, p: &Point3<f64>) -> f64 {
        let q = Vector3::from_fn(|a, _| p[a] - self.center[a]);
        let r = Vector3::from(self.radii);
        let k0 = q.component_div(&r).norm();
        let k1 = q.component_div(&r.component_mul(&r)).norm();
        if k1 < 1e-12 {
            return -r.min();
        }
        k0 * (k0 - 1.0) / k1
    }
}

/// Polynomial smooth minimum of width `k` (Quílez): equals `min(a, b)` where they differ by more
/// than `k`, and rounds the crease between them.
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

/// Exact signed distance of the box `[0, size]`, metres (negative inside).
pub fn box_sdf(size: Vector3<f64>) -> impl Fn(&Point3<f64>) -> f64 + Sync {
    move |p: &Point3<f64>| {
        let q = (p.coords - size / 2.0).abs() - size / 2.0;
        q.map(|x| x.max(0.0)).norm() + q.max().min(0.0)
    }
}

/// Signed distance estimate of the built-in liver-like organ, metres (negative inside).
///
/// Two ellipsoidal lobes joined by a smooth union and cut flat by the table at z = 0: a right lobe
/// (patient's right, -x) 10 x 10 cm across and 6 cm high, centred at (-2.5, 0) cm, and a thinner left
/// lobe 8 x 7 cm across and 3.5 cm high, centred at (3.5, 1) cm. Overall 15 x 10 x 6 cm, centred on the
/// origin in x and y, resting on z = 0. Volume about 0.435 litres (see the organ test).
pub fn organ_sdf(p: &Point3<f64>) -> f64 {
    let lobes = smooth_min(RIGHT_LOBE.sdf(p), LEFT_LOBE.sdf(p), LOBE_BLEND);
    lobes.max(-p.z)
}

/// [`organ_sdf`] of the organ made `scale` times larger about the origin (still on z = 0).
pub fn scaled_organ_sdf(p: &Point3<f64>, scale: f64) -> f64 {
    if scale == 1.0 { organ_sdf(p) } else { scale * organ_sdf(&(p / scale)) }
}

/// Extracts the zero set of `f` (negative inside) by naive surface nets over the grid of `n` nodes
/// per axis from `start` with spacing `h`: one vertex per cell the surface crosses, at the mean of
/// the edge crossings projected onto the zero set, and a quad (two triangles) across each grid edge
/// with a sign change, oriented so that normals point from negative to positive. `f` must be
/// positive on the grid's outermost nodes; the result is then closed.
fn surface_nets(f: &(dyn Fn(&Point3<f64>) -> f64 + Sync), start: Point3<f64>, h: f64, n: [usize; 3]) -> TriMesh {
    let node = |i: usize, j: usize, k: usize| i + n[0] * (j + n[1] * k);
    let position = |g: [usize; 3]| start + Vector3::new(g[0] as f64, g[1] as f64, g[2] as f64) * h;
    let values: Vec<f64> = (0..n[0] * n[1] * n[2])
        .into_par_iter()
        .map(|g| f(&position([g % n[0], (g / n[0]) % n[1], g / (n[0] * n[1])])))
        .collect();
    let inside = |g: usize| values[g] < 0.0;

    let cn = [n[0] - 1, n[1] - 1, n[2] - 1];
    let cell_id = |c: [usize; 3]| c[0] + cn[0] * (c[1] + cn[1] * c[2]);
    let mut cell_vertex = vec![u32::MAX; cn[0] * cn[1] * cn[2]];
    let mut vertices = Vec::new();
    for k in 0..cn[2] {
        for j in 0..cn[1] {
            for i in 0..cn[0] {
                let corner = |c: usize| [i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)];
                let v: [f64; 8] = std::array::from_fn(|c| {
                    let g = corner(c);
                    values[node(g[0], g[1], g[2])]
                });
                let signs = v.iter().filter(|&&x| x < 0.0).count();
                if signs == 0 || signs == 8 {
                    continue;
                }
                let mut sum = Vector3::zeros();
                let mut crossings = 0.0;
                for c in 0..8 {
                    for bit in [1, 2, 4] {
                        let d = c | bit;
                        if c & bit != 0 || (v[c] < 0.0) == (v[d] < 0.0) {
                            continue;
                        }
                        let t = v[c] / (v[c] - v[d]);
                        let (a, b) = (position(corner(c)), position(corner(d)));
                        sum += a.coords + (b - a) * t;
                        crossings += 1.0;
                    }
                }
                let lo = position([i, j, k]);
                let p = project_to_zero(f, Point3::from(sum / crossings), &lo, h);
                cell_vertex[cell_id([i, j, k])] = vertices.len() as u32;
                vertices.push(p);
            }
        }
    }

    let mut triangles = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let g = [i, j, k];
                    if g[axis] + 1 >= n[axis] {
                        continue;
                    }
                    let mut g2 = g;
                    g2[axis] += 1;
                    let (a, b) = (inside(node(i, j, k)), inside(node(g2[0], g2[1], g2[2])));
                    if a == b {
                        continue;
                    }
                    // Edges on the grid's outer faces have no four surrounding cells; `f` is positive
                    // there by contract, so they never change sign.
                    if g[u] == 0 || g[v] == 0 || g[u] >= cn[u] || g[v] >= cn[v] {
                        continue;
                    }
                    let cell = |du: usize, dv: usize| {
                        let mut c = g;
                        c[u] = g[u] + du - 1;
                        c[v] = g[v] + dv - 1;
                        cell_vertex[cell_id(c)]
                    };
                    // Counter-clockwise about +axis (u x v = axis).
                    let mut q = [cell(0, 0), cell(1, 0), cell(1, 1), cell(0, 1)];
                    if !a {
                        q.reverse();
                    }
                    push_quad(&mut triangles, &vertices, q);
                }
            }
        }
    }
    TriMesh::new(vertices, triangles)
}

/// A few Newton steps moving `p` onto the zero set of `f` along its numerical gradient, kept inside
/// the grid cell `[lo, lo + h]`.
fn project_to_zero(
    f: &(dyn Fn(&Point3<f64>) -> f64 + Sync),
    mut p: Point3<f64>,
    lo: &Point3<f64>,
    h: f64,
) -> Point3<f64> {
    let eps = h * 1e-4;
    for _ in 0..3 {
        let v = f(&p);
        let g = Vector3::from_fn(|a, _| {
            let mut e = Vector3::zeros();
            e[a] = eps;
            (f(&(p + e)) - f(&(p - e))) / (2.0 * eps)
        });
        let g2 = g.norm_squared();
        if !g2.is_finite() || g2 <= 1e-12 || v.abs() < 1e-9 * h {
            break;
        }
        p -= g * (v / g2);
        for a in 0..3 {
            p[a] = p[a].clamp(lo[a], lo[a] + h);
        }
    }
    p
}

/// Parameters of [`voxelize`].
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelizeParams {
    /// Sub-samples per axis and cell for the material fraction (`samples³` per cell). Default 4,
    /// which resolves fractions to 1/64. The box's fractions are exact whatever this is.
    pub samples: usize,
    /// Cells holding less than this share of material are dropped. Default 0.05: such a cell adds at
    /// most 5 % of a cell's volume, but its corner nodes, where no fuller cell shares them, carry
    /// almost no mass, and an explicit integrator's stable time step shrinks with the smallest
    /// mass-to-stiffness ratio; dropping them costs little volume and keeps the step usable.
    pub min_fraction: f32,
    /// Grid nodes lie at `anchor + cell * (i, j, k)` for integers i, j, k. Default: the world origin,
    /// so a box `[0, size]` with sizes divisible by the cell is covered exactly.
    pub anchor: Point3<f64>,
    /// Refuse grids with more cells than this (a mesh in the wrong units would otherwise exhaust
    /// memory). Default 20 million.
    pub max_cells: usize,
}

impl Default for VoxelizeParams {
    fn default() -> Self {
        Self { samples: 4, min_fraction: 0.05, anchor: Point3::origin(), max_cells: 20_000_000 }
    }
}

/// What can go wrong voxelizing a body.
#[derive(Debug, thiserror::Error)]
pub enum VoxelizeError {
    /// A parameter is out of range.
    #[error("voxelize: {message}")]
    InvalidParams {
        /// What is wrong.
        message: String,
    },
    /// The body is degenerate (zero or non-finite size, non-finite vertices).
    #[error("{body}: {message}")]
    InvalidBody {
        /// The body (names the file for meshes).
        body: String,
        /// What is wrong.
        message: String,
    },
    /// The grid would exceed [`VoxelizeParams::max_cells`].
    #[error(
        "{body}: a grid of {dims:?} cells of {cell} m exceeds the limit of {max} cells (check the units and scale)"
    )]
    TooLarge {
        /// The body.
        body: String,
        /// Cells per axis.
        dims: [usize; 3],
        /// Cell size, metres.
        cell: f64,
        /// The limit.
        max: usize,
    },
    /// No cell holds enough material.
    #[error("{body}: no lattice cell holds at least {min_fraction} material (is the mesh closed, outward, in metres?)")]
    NoMaterial {
        /// The body (names the file for meshes).
        body: String,
        /// The threshold used.
        min_fraction: f32,
    },
}

/// The result of [`voxelize`].
#[derive(Debug, Clone)]
pub struct Voxelized {
    /// The lattice of cells holding material.
    pub lattice: Lattice,
    /// Problems worked around, for the CLI to report: a mesh that is not closed (inside decided by
    /// winding number) or faces inward (orientation reversed). Each names the body's file.
    pub warnings: Vec<String>,
    /// Cells with material dropped for holding less than `min_fraction`.
    pub dropped_cells: usize,
    /// Material volume in the dropped cells, cubic metres.
    pub dropped_volume: f64,
}

/// Covers `body` with a grid of cubic cells of side `cell` (aligned to `params.anchor`) and keeps the
/// cells holding at least `params.min_fraction` material.
///
/// Fractions: exact overlap for the box; `samples³` samples of `organ_sdf < 0` for the organ; for a
/// mesh, winding number > 0.5 at `samples³` points: within one cell of a hole every point is
/// evaluated ([`WindingTree`]); in cells that some triangle's bounding box overlaps, the first point
/// is evaluated and the others follow from the ±1 jumps across the triangles their segment from it
/// crosses; every other cell lies wholly on one side, and each face-connected region of such cells
/// takes the value at the centre of its first cell.
pub fn voxelize(body: &Body, cell: f64, params: &VoxelizeParams) -> Result<Voxelized, VoxelizeError> {
    let started = Instant::now();
    if !(cell.is_finite() && cell > 0.0) {
        return Err(VoxelizeError::InvalidParams { message: format!("cell must be a positive length, got {cell}") });
    }
    if !(1..=64).contains(&params.samples) {
        return Err(VoxelizeError::InvalidParams {
            message: format!("samples must be 1 to 64 per axis, got {}", params.samples),
        });
    }
    if !(0.0..=1.0).contains(&params.min_fraction) {
        return Err(VoxelizeError::InvalidParams {
            message: format!("min_fraction must be in [0, 1], got {}", params.min_fraction),
        });
    }
    let invalid = |message: String| VoxelizeError::InvalidBody { body: body.to_string(), message };
    let mut warnings = Vec::new();
    match body {
        Body::Box { size } if !size.iter().all(|&s| s.is_finite() && s > 0.0) => {
            return Err(invalid(format!("box size must be positive, got {:?}", size.as_slice())));
        }
        Body::Mesh(m, _) => {
            if m.triangles.is_empty() {
                return Err(invalid("mesh has no triangles".into()));
            }
            if m.vertices.iter().any(|v| !v.iter().all(|c| c.is_finite())) {
                return Err(invalid("mesh has non-finite vertex coordinates".into()));
            }
            if m.triangles.iter().flatten().any(|&i| i as usize >= m.vertices.len()) {
                return Err(invalid("mesh has a triangle index out of range".into()));
            }
        }
        _ => {}
    }

    let (lo, hi) = body.bounds();
    let a = params.anchor;
    // A bound within 1e-9 cells of a grid plane counts as on it, so rounding in `size / cell` does not
    // add an empty layer.
    let first = [0, 1, 2].map(|i| ((lo[i] - a[i]) / cell + 1e-9).floor());
    let last = [0, 1, 2].map(|i| ((hi[i] - a[i]) / cell - 1e-9).ceil());
    let dims = [0, 1, 2].map(|i| (last[i] - first[i]).max(1.0) as usize);
    let origin = Point3::new(a.x + first[0] * cell, a.y + first[1] * cell, a.z + first[2] * cell);
    let total = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)).unwrap_or(usize::MAX);
    if total > params.max_cells {
        return Err(VoxelizeError::TooLarge { body: body.to_string(), dims, cell, max: params.max_cells });
    }

    let n = params.samples;
    let offsets: Vec<f64> = (0..n).map(|s| (s as f64 + 0.5) / n as f64).collect();
    let cell_min = |idx: usize| {
        let ijk = [idx % dims[0], (idx / dims[0]) % dims[1], idx / (dims[0] * dims[1])];
        origin + Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) * cell
    };
    // Share of the cell starting at `c` (any body) whose sub-samples satisfy `inside`.
    let sampled = |c: Point3<f64>, inside: &dyn Fn(&Point3<f64>) -> bool| {
        let mut count = 0usize;
        for &oz in &offsets {
            for &oy in &offsets {
                for &ox in &offsets {
                    count += usize::from(inside(&(c + Vector3::new(ox, oy, oz) * cell)));
                }
            }
        }
        count as f32 / (n * n * n) as f32
    };

    let fractions: Vec<f32> = match body {
        Body::Box { size } => (0..total)
            .into_par_iter()
            .map(|idx| {
                let c = cell_min(idx);
                (0..3).map(|a| ((c[a] + cell).min(size[a]) - c[a].max(0.0)).max(0.0) / cell).product::<f64>() as f32
            })
            .collect(),
        Body::Organ { scale } => (0..total)
            .into_par_iter()
            .map(|idx| sampled(cell_min(idx), &|p| scaled_organ_sdf(p, *scale) < 0.0))
            .collect(),
        Body::Mesh(mesh, _) => {
            let open_edges = mesh.open_edges();
            if open_edges > 0 {
                warnings.push(format!(
                    "{body} is not closed ({open_edges} edges not shared by exactly two triangles); inside \
                     decided by generalized winding number"
                ));
            }
            let sign = if mesh.volume() < 0.0 {
                warnings.push(format!("{body} has inward-facing triangles (negative volume); orientation reversed"));
                -1.0
            } else {
                1.0
            };
            let bins = CellBins::new(mesh, origin, cell, dims);
            let tree = WindingTree::new(mesh);
            let inside = |p: &Point3<f64>| sign * tree.winding_number(p) > 0.5;
            // Cells that no triangle's bounding box overlaps and no hole is near lie wholly on one side,
            // and so does each face-connected region of them: one winding number per region.
            let regions = free_regions(&bins, dims);
            let region_inside: Vec<bool> = regions
                .first_cell
                .par_iter()
                .map(|&idx| inside(&(cell_min(idx) + Vector3::repeat(0.5 * cell))))
                .collect();
            (0..total)
                .into_par_iter()
                .map(|idx| {
                    let c = cell_min(idx);
                    if let Some(&r) = regions.label.get(idx).filter(|&&r| r != u32::MAX) {
                        return if region_inside[r as usize] { 1.0 } else { 0.0 };
                    }
                    if bins.hole[idx] {
                        return sampled(c, &inside);
                    }
                    let local = bins.local(idx);
                    // One winding number, then the ±1 jumps across the cell's triangles along straight
                    // segments to the other samples (exact for a closed mesh; away from holes the part
                    // of an open mesh's winding number that varies smoothly barely changes in a cell).
                    let mut points = Vec::with_capacity(n * n * n);
                    for &oz in &offsets {
                        for &oy in &offsets {
                            for &ox in &offsets {
                                points.push(c + Vector3::new(ox, oy, oz) * cell);
                            }
                        }
                    }
                    let w0 = sign * tree.winding_number(&points[0]);
                    let count = points
                        .iter()
                        .skip(1)
                        .filter(|q| match crossings(mesh, local, &points[0], q) {
                            Some(jumps) => w0 + sign * f64::from(jumps) > 0.5,
                            None => inside(q),
                        })
                        .count()
                        + usize::from(w0 > 0.5);
                    count as f32 / points.len() as f32
                })
                .collect()
        }
    };

    let (mut dropped_cells, mut dropped_volume) = (0, 0.0);
    for &f in &fractions {
        if f > 0.0 && f < params.min_fraction {
            dropped_cells += 1;
            dropped_volume += f64::from(f) * cell.powi(3);
        }
    }
    let lattice = Lattice::from_fractions(origin, cell, dims, &fractions, params.min_fraction);
    if lattice.cells.is_empty() {
        return Err(VoxelizeError::NoMaterial { body: body.to_string(), min_fraction: params.min_fraction });
    }
    tracing::debug!(
        body = %body,
        cells = lattice.cells.len(),
        nodes = lattice.node_count(),
        grid = ?dims,
        volume = lattice.volume(),
        seconds = started.elapsed().as_secs_f64(),
        "voxelized"
    );
    Ok(Voxelized { lattice, warnings, dropped_cells, dropped_volume })
}

/// The triangles whose bounding box overlaps each grid cell, and the cells near a hole.
struct CellBins {
    /// `(cell, triangle)` pairs sorted by cell.
    pairs: Vec<(usize, u32)>,
    /// Cells within one cell of a hole's bounding box ([`TriMesh::holes`]): near a hole the winding
    /// number varies smoothly through 0.5, so every sample there is evaluated.
    hole: Vec<bool>,
}

impl CellBins {
    fn new(mesh: &TriMesh, origin: Point3<f64>, cell: f64, dims: [usize; 3]) -> Self {
        let index =
            |x: f64, a: usize| -> usize { (((x - origin[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1) };
        let range = |lo: Point3<f64>, hi: Point3<f64>| {
            let from = [0, 1, 2].map(|a| index(lo[a], a));
            let to = [0, 1, 2].map(|a| index(hi[a], a));
            (from[2]..=to[2]).flat_map(move |k| {
                (from[1]..=to[1]).flat_map(move |j| (from[0]..=to[0]).map(move |i| i + dims[0] * (j + dims[1] * k)))
            })
        };
        let mut pairs = Vec::new();
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let [p, q, r] = t.map(|i| mesh.vertices[i as usize]);
            pairs.extend(range(p.inf(&q).inf(&r), p.sup(&q).sup(&r)).map(|c| (c, ti as u32)));
        }
        pairs.sort_unstable();
        let mut hole = vec![false; dims[0] * dims[1] * dims[2]];
        for edges in mesh.holes() {
            let v = |i: u32| mesh.vertices[i as usize];
            let (lo, hi) = edges.iter().fold((v(edges[0].0), v(edges[0].0)), |(lo, hi), &(a, b)| {
                (lo.inf(&v(a)).inf(&v(b)), hi.sup(&v(a)).sup(&v(b)))
            });
            for c in range(lo - Vector3::repeat(cell), hi + Vector3::repeat(cell)) {
                hole[c] = true;
            }
        }
        Self { pairs, hole }
    }

    /// The `(cell, triangle)` pairs of grid cell `idx`.
    fn local(&self, idx: usize) -> &[(usize, u32)] {
        let lo = self.pairs.partition_point(|p| p.0 < idx);
        let hi = lo + self.pairs[lo..].partition_point(|p| p.0 <= idx);
        &self.pairs[lo..hi]
    }
}

/// Face-connected regions of the cells with no triangle and no hole near ([`CellBins`]).
struct Regions {
    /// Region of each cell, `u32::MAX` for the other cells.
    label: Vec<u32>,
    /// The lowest cell of each region.
    first_cell: Vec<usize>,
}

fn free_regions(bins: &CellBins, dims: [usize; 3]) -> Regions {
    let total = dims[0] * dims[1] * dims[2];
    let mut free = vec![true; total];
    for &(c, _) in &bins.pairs {
        free[c] = false;
    }
    for (f, &h) in free.iter_mut().zip(&bins.hole) {
        *f &= !h;
    }
    let mut label = vec![u32::MAX; total];
    let mut first_cell = Vec::new();
    let mut stack = Vec::new();
    for start in 0..total {
        if !free[start] || label[start] != u32::MAX {
            continue;
        }
        let r = first_cell.len() as u32;
        first_cell.push(start);
        label[start] = r;
        stack.push(start);
        while let Some(idx) = stack.pop() {
            let ijk = [idx % dims[0], (idx / dims[0]) % dims[1], idx / (dims[0] * dims[1])];
            let stride = [1, dims[0], dims[0] * dims[1]];
            for a in 0..3 {
                let mut visit = |n: usize| {
                    if free[n] && label[n] == u32::MAX {
                        label[n] = r;
                        stack.push(n);
                    }
                };
                if ijk[a] > 0 {
                    visit(idx - stride[a]);
                }
                if ijk[a] + 1 < dims[a] {
                    visit(idx + stride[a]);
                }
            }
        }
    }
    Regions { label, first_cell }
}

/// The change of `mesh`'s winding number from `p` to `q` from the triangles of `local` that the
/// segment crosses: -1 for each crossing from behind a triangle to its front, +1 the other way.
/// Whether the line passes through a triangle is decided by the signs of its three edge functions,
/// each evaluated with the edge's vertices in index order, so that two triangles sharing an edge
/// see exactly opposite values and a line near the edge passes through exactly one of them
/// (Woop et al. 2013, "Watertight ray/triangle intersection"). `None` when the segment touches an
/// edge, a vertex or has an end on a triangle: the caller then evaluates the winding number.
fn crossings(mesh: &TriMesh, local: &[(usize, u32)], p: &Point3<f64>, q: &Point3<f64>) -> Option<i32> {
    let d = q - p;
    let v = |i: u32| mesh.vertices[i as usize];
    let edge = |a: u32, b: u32| {
        let (lo, hi, s) = if a < b { (a, b, 1.0) } else { (b, a, -1.0) };
        s * (v(lo) - p).dot(&(v(hi) - p).cross(&d))
    };
    let mut jumps = 0;
    for &(_, t) in local {
        let [i0, i1, i2] = mesh.triangles[t as usize];
        let (a, b, c) = (v(i0), v(i1), v(i2));
        let n = (b - a).cross(&(c - a));
        let (sp, sq) = ((p - a).dot(&n), (q - a).dot(&n));
        if (sp > 0.0 && sq > 0.0) || (sp < 0.0 && sq < 0.0) {
            continue;
        }
        let e = [edge(i0, i1), edge(i1, i2), edge(i2, i0)];
        let positive = e.iter().all(|&x| x >= 0.0);
        let negative = e.iter().all(|&x| x <= 0.0);
        if !(positive || negative) {
            continue;
        }
        if e.contains(&0.0) || sp == 0.0 || sq == 0.0 {
            return None;
        }
        jumps += if sp < 0.0 { -1 } else { 1 };
    }
    Some(jumps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_min_is_min_far_apart() {
        assert_eq!(smooth_min(1.0, 3.0, 0.5), 1.0);
        assert!(smooth_min(1.0, 1.0, 0.5) < 1.0);
    }

    #[test]
    fn box_surface_is_closed() {
        let b = Body::Box { size: Vector3::new(0.05, 0.02, 0.01) };
        let s = b.surface();
        assert!(s.is_closed());
        assert_eq!(s.orientation_conflicts(), 0);
        assert!((s.volume() - 1e-5).abs() < 1e-15);
        assert_eq!(s.triangles.len(), 4 * (20 * 8 + 8 * 4 + 4 * 20));
    }

    #[test]
    fn invalid_inputs() {
        let b = Body::Box { size: Vector3::new(0.05, 0.0, 0.01) };
        assert!(matches!(voxelize(&b, 0.01, &VoxelizeParams::default()), Err(VoxelizeError::InvalidBody { .. })));
        let b = Body::Box { size: Vector3::new(1.0, 1.0, 1.0) };
        assert!(matches!(voxelize(&b, 0.0, &VoxelizeParams::default()), Err(VoxelizeError::InvalidParams { .. })));
        assert!(matches!(voxelize(&b, 1e-4, &VoxelizeParams::default()), Err(VoxelizeError::TooLarge { .. })));
    }
}
