//! Closed surfaces of the pieces of a cut body.
//!
//! The body is sampled on a grid finer than the lattice (in the rest configuration), every sample
//! strictly inside one lattice cell. A sample belongs to the copy of its cell that owns its side of
//! the cut ([`crate::vna::CellSplit::component_at`]), and so to that copy's piece. For each piece, a signed
//! function is negative where the piece has material: the body's signed distance, bounded by the
//! distance to the cut plane in split cells, and positive in every sample that belongs to another
//! piece. Surface nets over it give one closed, consistently oriented mesh per piece whose cut
//! faces lie where the blade passed (planar within each cell) and whose outside follows the body.
//!
//! Adjacent samples of one piece whose copies share no node lie on opposite faces of a cut that
//! has not (yet) separated the piece, a slit: the surface passes between them too, as two faces
//! with their own vertices, one per side, so the slit opens as its sides move apart.
//!
//! Each vertex is bound to the copy that holds it: its trilinear weights in that copy's cube, so
//! it moves with the copy's nodes (real or virtual) and the pieces come apart as their nodes do.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::lattice::Lattice;
use crate::mesh::{TriMesh, push_quad};
use crate::vna::{CellSplit, CutTopology};

/// A sample's copy: none outside the lattice.
const NO_COPY: u32 = u32::MAX;

/// The rest-configuration sampling of a body over a lattice: computed once, reused after every cut.
#[derive(Debug, Clone)]
pub struct BodySamples {
    /// Samples per lattice cell along each axis.
    pub per_cell: usize,
    /// Sample spacing, metres.
    pub h: f64,
    /// Samples along x, y, z, including one empty layer on every side.
    pub dims: [usize; 3],
    /// Position of sample (0, 0, 0), metres.
    pub start: Point3<f64>,
    /// Signed distance (or a signed estimate) of the body at each sample, negative inside.
    pub body: Vec<f64>,
    /// The lattice cell each sample lies in (`u32::MAX` for none).
    pub cell: Vec<u32>,
}

impl BodySamples {
    /// Samples `per_cell`³ points per lattice cell (at least 1), with `signed` the body's signed
    /// distance (negative inside).
    pub fn new(lattice: &Lattice, per_cell: usize, signed: &(dyn Fn(&Point3<f64>) -> f64 + Sync)) -> Self {
        let per_cell = per_cell.max(1);
        let h = lattice.cell / per_cell as f64;
        let dims = lattice.dims.map(|d| d * per_cell + 2);
        // Sample (1, 1, 1) is the centre of the first sub-cube of cell (0, 0, 0).
        let start = lattice.origin - Vector3::repeat(0.5 * h);
        let count = dims[0] * dims[1] * dims[2];
        let (body, cell): (Vec<f64>, Vec<u32>) = (0..count)
            .into_par_iter()
            .map(|g| {
                let ijk = [g % dims[0], (g / dims[0]) % dims[1], g / (dims[0] * dims[1])];
                let interior = (0..3).all(|a| ijk[a] >= 1 && ijk[a] + 1 < dims[a]);
                let c = interior
                    .then(|| lattice.cell_index(ijk.map(|v| (v - 1) / per_cell)))
                    .flatten()
                    .map_or(NO_COPY, |c| c as u32);
                let p = start + Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) * h;
                (signed(&p), c)
            })
            .unzip();
        BodySamples { per_cell, h, dims, start, body, cell }
    }

    fn position(&self, g: usize) -> Point3<f64> {
        let d = self.dims;
        self.start + Vector3::new((g % d[0]) as f64, ((g / d[0]) % d[1]) as f64, (g / (d[0] * d[1])) as f64) * self.h
    }
}

/// Where a surface vertex sits in the cut lattice: eight nodes and their trilinear weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Binding {
    /// The nodes of the copy holding the vertex (lattice or virtual).
    pub nodes: [u32; 8],
    /// Trilinear weights of the vertex's rest position in that copy's cube (they may extrapolate a
    /// little for vertices just outside it).
    pub weights: [f32; 8],
}

/// One piece's surface.
#[derive(Debug, Clone)]
pub struct PieceSurface {
    /// The closed mesh at rest.
    pub rest: TriMesh,
    /// One binding per vertex.
    pub bindings: Vec<Binding>,
}

impl PieceSurface {
    /// Vertex positions given node displacements (indexed like the cut lattice's nodes).
    pub fn deformed(&self, u: &[Vector3<f32>]) -> Vec<Point3<f32>> {
        self.rest
            .vertices
            .iter()
            .zip(&self.bindings)
            .map(|(p, b)| {
                let d: Vector3<f32> = b.nodes.iter().zip(&b.weights).map(|(&n, &w)| u[n as usize] * w).sum();
                p.cast::<f32>() + d
            })
            .collect()
    }
}

/// The surfaces of every piece of a cut body.
pub fn piece_surfaces(lattice: &Lattice, topology: &CutTopology, samples: &BodySamples) -> Vec<PieceSurface> {
    surfaces_of_pieces(lattice, topology, samples, true)
}

/// [`piece_surfaces`], visiting only the samples near the surface (`skip_interior`) or all.
fn surfaces_of_pieces(
    lattice: &Lattice,
    topology: &CutTopology,
    samples: &BodySamples,
    skip_interior: bool,
) -> Vec<PieceSurface> {
    // How each split cell's material is divided, once per cell (not once per sample).
    let splits: Vec<Option<CellSplit>> = (0..lattice.cells.len())
        .into_par_iter()
        .map(|c| (topology.copies_of(c).len() > 1).then(|| topology.split(lattice, c)))
        .collect();
    // Copy and cut distance (metres, negative on the copy's side) of every sample.
    let owner: Vec<(u32, f64)> = (0..samples.body.len())
        .into_par_iter()
        .map(|g| {
            let c = samples.cell[g];
            if c == NO_COPY {
                return (NO_COPY, f64::INFINITY);
            }
            let range = topology.copies_of(c as usize);
            let Some(split) = &splits[c as usize] else {
                return (range.start as u32, f64::NEG_INFINITY);
            };
            let p = samples.position(g);
            let ijk = lattice.cells[c as usize].ijk;
            let local = (p - lattice.origin) / lattice.cell - Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64);
            let (k, d) = split.component_at(&local);
            ((range.start + k) as u32, d * lattice.cell)
        })
        .collect();
    let piece_of = |copy: u32| if copy == NO_COPY { u32::MAX } else { topology.piece_of[copy as usize] };
    // Copies of split cells: only those can be cut apart from a neighbour.
    let split: Vec<bool> = topology.copies.iter().map(|c| topology.copies_of(c.parent as usize).len() > 1).collect();
    let joined = |a: u32, b: u32| {
        a == b || !(split[a as usize] || split[b as usize]) || {
            let (na, nb) = (&topology.copies[a as usize].nodes, &topology.copies[b as usize].nodes);
            na.iter().any(|n| nb.contains(n))
        }
    };
    let near = if skip_interior {
        near_surface(samples, &owner, |copy, cell| {
            split[copy as usize] || topology.copies[copy as usize].parent != cell
        })
    } else {
        vec![true; owner.len()]
    };
    (0..topology.pieces as u32)
        .into_par_iter()
        .map(|piece| {
            let values: Vec<f64> = owner
                .par_iter()
                .zip(&samples.body)
                .map(|(&(copy, cut), &body)| {
                    if copy == NO_COPY {
                        body.max(1e-6 * samples.h)
                    } else if piece_of(copy) == piece {
                        body.max(cut)
                    } else if cut.is_finite() {
                        (-cut).max(1e-6 * samples.h)
                    } else {
                        0.5 * samples.h
                    }
                })
                .collect();
            let field = Field {
                values: &values,
                near: &near,
                owner: &owner,
                samples,
                joined: &joined,
                lattice,
                splits: &splits,
                first_copy: &topology.first_copy,
            };
            let (mesh, held_by) = field.surface_nets();
            let bindings =
                mesh.vertices.iter().zip(held_by).map(|(p, copy)| bind(lattice, topology, copy, p)).collect();
            PieceSurface { rest: mesh, bindings }
        })
        .collect()
}

/// Which samples lie within one sample (along every axis) of a sample the surface can pass
/// beside: outside the body, in no copy, or in a copy `special(copy, cell)` says can be cut apart
/// from its neighbours (a copy of a split cell, or one the sample's cell does not hold).
///
/// A grid cube whose eight samples are all inside the body and held by whole cells of one piece
/// (whole cells that touch share lattice nodes, so they are one piece) has no surface through it;
/// every cube the surface crosses has a special corner, so all its corners are near one. Surface
/// nets visit only the samples near one: the same cubes in the same order, the organ's interior
/// skipped (the built-in organ at 2 mm: most of its 1.6 million samples).
fn near_surface(samples: &BodySamples, owner: &[(u32, f64)], special: impl Fn(u32, u32) -> bool + Sync) -> Vec<bool> {
    let n = samples.dims;
    let marked: Vec<bool> = (0..owner.len())
        .into_par_iter()
        .map(|g| {
            let copy = owner[g].0;
            samples.body[g] >= 0.0 || copy == NO_COPY || special(copy, samples.cell[g])
        })
        .collect();
    // Dilate by one sample along x, then y, then z (a 3 x 3 x 3 neighbourhood in all).
    let stride = [1, n[0], n[0] * n[1]];
    let mut near = marked;
    let mut before = near.clone();
    for axis in 0..3 {
        if axis > 0 {
            before.copy_from_slice(&near);
        }
        near.par_iter_mut().enumerate().for_each(|(g, out)| {
            if *out {
                return;
            }
            let i = (g / stride[axis]) % n[axis];
            *out = (i > 0 && before[g - stride[axis]]) || (i + 1 < n[axis] && before[g + stride[axis]]);
        });
    }
    near
}

/// The trilinear weights of `p` in the cube of `copy`.
fn bind(lattice: &Lattice, topology: &CutTopology, copy: u32, p: &Point3<f64>) -> Binding {
    let copy = &topology.copies[copy as usize];
    let ijk = lattice.cells[copy.parent as usize].ijk;
    let local = (p - lattice.origin) / lattice.cell - Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64);
    let weights = std::array::from_fn(|k| {
        let o = crate::lattice::CORNERS[k];
        (0..3).map(|a| if o[a] == 1 { local[a] } else { 1.0 - local[a] }).product::<f64>() as f32
    });
    Binding { nodes: copy.nodes, weights }
}

/// One piece's signed samples with who owns them.
struct Field<'a> {
    /// Negative where the piece has material.
    values: &'a [f64],
    /// Samples near one the surface can pass beside ([`near_surface`]); the others are skipped.
    near: &'a [bool],
    /// Each sample's copy and signed distance to its cell's cut (metres; infinite in whole cells).
    owner: &'a [(u32, f64)],
    samples: &'a BodySamples,
    /// Whether two copies hold together (share a node): samples of copies that do not are on
    /// opposite faces of a cut, even inside one piece.
    joined: &'a (dyn Fn(u32, u32) -> bool + Sync),
    lattice: &'a Lattice,
    /// How each split cell is divided (`None` for whole cells).
    splits: &'a [Option<CellSplit>],
    /// Each lattice cell's first copy ([`CutTopology::first_copy`]).
    first_copy: &'a [u32],
}

impl Field<'_> {
    fn inside(&self, g: usize) -> bool {
        self.values[g] < 0.0
    }

    /// Whether the surface passes between adjacent samples `a` (inside) and `b`: `b` is outside,
    /// or across a cut (a slit within the piece shows as two faces, one per side).
    fn boundary(&self, a: usize, b: usize) -> bool {
        !self.inside(b) || !(self.joined)(self.owner[a].0, self.owner[b].0)
    }

    /// Where the surface crosses the grid edge from `a` (inside) to `b`, as a fraction of it.
    ///
    /// Where a cut passes between them (`b` is across a slit, or holds another piece's material),
    /// at the cut plane of `a`'s cell or `b`'s: the plane's signed distance is affine, so the
    /// crossing is exact for a planar cut even where the other sample's cell is whole (its
    /// distance measured from the split cell's plane, extended).
    fn crossing(&self, a: usize, b: usize) -> f64 {
        let (va, vb) = (self.values[a], self.values[b]);
        let other_piece = !self.inside(b) && self.samples.body[b] < 0.0 && self.owner[b].0 != NO_COPY;
        if !self.inside(b) && !other_piece {
            return (va / (va - vb)).clamp(0.0, 1.0);
        }
        if let Some(t) = self.plane_crossing(a, b) {
            return t;
        }
        if !self.inside(b) {
            return (va / (va - vb)).clamp(0.0, 1.0);
        }
        // Across a cut, no plane to measure from (crossing cuts): as seen from either side's cell.
        let h = self.samples.h;
        let (ca, cb) = (self.owner[a].1.abs(), self.owner[b].1.abs());
        match (ca.is_finite(), cb.is_finite()) {
            (true, true) => ca / (ca + cb).max(1e-12),
            (true, false) => (ca / h).min(1.0),
            (false, true) => (1.0 - cb / h).max(0.0),
            (false, false) => 0.5,
        }
    }

    /// Where the cut plane of `a`'s cell, or else of `b`'s, crosses the grid edge from `a` to
    /// `b`, when one of them has a plane that puts them on opposite sides.
    fn plane_crossing(&self, a: usize, b: usize) -> Option<f64> {
        for (of, sign) in [(a, 1.0), (b, -1.0)] {
            let (Some(fa), Some(fb)) = (self.plane_side(a, of), self.plane_side(b, of)) else { continue };
            let (fa, fb) = (sign * fa, sign * fb);
            if fa <= 0.0 && fb > 0.0 {
                return Some((-fa / (fb - fa)).clamp(0.0, 1.0));
            }
        }
        None
    }

    /// Signed distance (cell units) of sample `g` from the cut plane of sample `of`'s cell,
    /// negative on the side of `of`'s copy; `None` when that cell is whole or has no plane.
    fn plane_side(&self, g: usize, of: usize) -> Option<f64> {
        let cell = self.samples.cell[of];
        let split = self.splits.get(cell as usize)?.as_ref()?;
        let (centroid, normal) = split.plane?;
        let ijk = self.lattice.cells[cell as usize].ijk;
        let local = (self.samples.position(g) - self.lattice.origin) / self.lattice.cell
            - Vector3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64);
        let d = (local - centroid).dot(&normal);
        // The plane's normal points away from component 0.
        let first = self.lattice_copy_index(of) == 0;
        Some(if first { d } else { -d })
    }

    /// Which of its cell's copies sample `g` belongs to (0 for the first).
    fn lattice_copy_index(&self, g: usize) -> u32 {
        self.owner[g].0 - self.first_copy[self.samples.cell[g] as usize]
    }

    /// Naive surface nets with cut walls: in each grid cube the surface crosses, the inside samples
    /// fall into groups that hold together (cube edges between samples whose copies are joined);
    /// each group has its own vertex, at the mean of the crossings on its boundary edges (at a
    /// slit's front, where both sides hold together, one group holds both faces' edges). One
    /// quad per boundary grid edge, on the inside sample's side, oriented from inside to outside.
    /// A whole body gives one group per cube (plain surface nets); a slit gives one group on
    /// each side, so its two faces have their own vertices and can open. Returns the mesh and, per
    /// vertex, the copy that holds it (the group's deepest sample's).
    fn surface_nets(&self) -> (TriMesh, Vec<u32>) {
        let n = self.samples.dims;
        let node = |g: [usize; 3]| g[0] + n[0] * (g[1] + n[1] * g[2]);
        let cn = [n[0] - 1, n[1] - 1, n[2] - 1];
        let cube = |c: [usize; 3]| c[0] + cn[0] * (c[1] + cn[1] * c[2]);
        // Per cube: UNSEEN, PLAIN (no surface through it) or an index into `groups`, which holds for
        // each crossed cube the vertex of each corner's group (u32::MAX for outside corners).
        const UNSEEN: u32 = u32::MAX;
        const PLAIN: u32 = u32::MAX - 1;
        let mut cube_state = vec![UNSEEN; cn[0] * cn[1] * cn[2]];
        let mut groups: Vec<[u32; 8]> = Vec::new();
        let mut vertices = Vec::new();
        let mut held_by = Vec::new();
        for g in (0..self.values.len()).filter(|&g| self.near[g] && self.inside(g)) {
            let gi = [g % n[0], (g / n[0]) % n[1], g / (n[0] * n[1])];
            for c in 0..8 {
                let lo =
                    [gi[0].wrapping_sub(c & 1), gi[1].wrapping_sub((c >> 1) & 1), gi[2].wrapping_sub((c >> 2) & 1)];
                if (0..3).any(|a| lo[a] >= cn[a]) || cube_state[cube(lo)] != UNSEEN {
                    continue;
                }
                let corner = |k: usize| node([lo[0] + (k & 1), lo[1] + ((k >> 1) & 1), lo[2] + ((k >> 2) & 1)]);
                let idx: [usize; 8] = std::array::from_fn(corner);
                // Groups: union of inside corners along cube edges that are not boundaries.
                let mut group: [usize; 8] = std::array::from_fn(|k| k);
                let find = |group: &[usize; 8], mut k: usize| {
                    while group[k] != k {
                        k = group[k];
                    }
                    k
                };
                let mut crossed = false;
                for a in 0..8 {
                    for bit in [1, 2, 4] {
                        let b = a | bit;
                        if a & bit != 0 {
                            continue;
                        }
                        let (ia, ib) = (idx[a], idx[b]);
                        match (self.inside(ia), self.inside(ib)) {
                            (true, true) if !self.boundary(ia, ib) => {
                                let (ra, rb) = (find(&group, a), find(&group, b));
                                group[ra.max(rb)] = ra.min(rb);
                            }
                            (false, false) => {}
                            _ => crossed = true,
                        }
                    }
                }
                if !crossed {
                    cube_state[cube(lo)] = PLAIN;
                    continue;
                }
                let mut ids = [u32::MAX; 8];
                for root in 0..8 {
                    if !self.inside(idx[root]) || find(&group, root) != root {
                        continue;
                    }
                    let members: Vec<usize> =
                        (0..8).filter(|&k| self.inside(idx[k]) && find(&group, k) == root).collect();
                    let mut sum = Vector3::zeros();
                    let mut count = 0.0;
                    for &a in &members {
                        for bit in [1, 2, 4] {
                            let b = a ^ bit;
                            if !self.boundary(idx[a], idx[b]) {
                                continue;
                            }
                            let t = self.crossing(idx[a], idx[b]);
                            let (pa, pb) = (self.samples.position(idx[a]), self.samples.position(idx[b]));
                            sum += pa.coords + (pb - pa) * t;
                            count += 1.0;
                        }
                    }
                    let deepest = members
                        .iter()
                        .map(|&k| idx[k])
                        .min_by(|&x, &y| self.values[x].total_cmp(&self.values[y]))
                        .unwrap_or(idx[root]);
                    let id = vertices.len() as u32;
                    vertices.push(Point3::from(sum / f64::max(count, 1.0)));
                    held_by.push(self.owner[deepest].0);
                    for &k in &members {
                        ids[k] = id;
                    }
                }
                cube_state[cube(lo)] = groups.len() as u32;
                groups.push(ids);
            }
        }
        let mut triangles = Vec::new();
        for g in (0..self.values.len()).filter(|&g| self.near[g] && self.inside(g)) {
            let gi = [g % n[0], (g / n[0]) % n[1], g / (n[0] * n[1])];
            for axis in 0..3 {
                let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
                for dir in [-1i64, 1] {
                    let mut other = gi;
                    other[axis] = (gi[axis] as i64 + dir) as usize;
                    if !self.boundary(g, node(other)) {
                        continue;
                    }
                    let low = if dir > 0 { gi } else { other };
                    // The vertex of g's group in the cube with lower corner c.
                    let quad_vertex = |du: usize, dw: usize| {
                        let mut c = low;
                        c[u] = low[u] + du - 1;
                        c[w] = low[w] + dw - 1;
                        let k = (0..3).map(|a| (gi[a] - c[a]) << a).sum::<usize>();
                        groups[cube_state[cube(c)] as usize][k]
                    };
                    let mut q = [quad_vertex(0, 0), quad_vertex(1, 0), quad_vertex(1, 1), quad_vertex(0, 1)];
                    if dir < 0 {
                        q.reverse();
                    }
                    push_quad(&mut triangles, &vertices, q);
                }
            }
        }
        (TriMesh::new(vertices, triangles), held_by)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;

    use super::*;
    use crate::body::box_sdf;
    use crate::collide::{SpatialHash, cut_edges};
    use crate::sweep::SweptSurface;

    #[test]
    fn skipping_the_interior_gives_the_same_surfaces_vertex_for_vertex() {
        // A block cut by two crossing strokes and a third that parts a corner, on the organ-like
        // margin case too (a box not aligned with the lattice): the skipped samples change nothing.
        let l = Lattice::block(Point3::origin(), 0.01, [6, 5, 4]);
        let size = Vector3::new(0.057, 0.046, 0.037);
        let samples = BodySamples::new(&l, 3, &box_sdf(size));
        let hash = SpatialHash::new(&l, &l.rest, l.cell);
        let stroke = |edge: Vec<Point3<f64>>, from: Vector3<f64>, to: Vector3<f64>| {
            let s = SweptSurface::between(
                &edge,
                &Isometry3::translation(from.x, from.y, from.z),
                &Isometry3::translation(to.x, to.y, to.z),
                0.004,
                0.1,
            )
            .expect("surface");
            cut_edges(&l, &l.rest, &hash, &s).edges
        };
        let along_x: Vec<Point3<f64>> = (0..9).map(|k| Point3::new(-0.01 + 0.01 * k as f64, 0.0, 0.0)).collect();
        let along_y: Vec<Point3<f64>> = (0..9).map(|k| Point3::new(0.0, -0.01 + 0.01 * k as f64, 0.0)).collect();
        let mut edges = stroke(along_x, Vector3::new(0.0, 0.023, 0.06), Vector3::new(0.0, 0.023, 0.012));
        edges.extend(stroke(along_y.clone(), Vector3::new(0.031, 0.0, 0.06), Vector3::new(0.031, 0.0, -0.01)));
        edges.extend(stroke(along_y, Vector3::new(0.049, 0.0, 0.06), Vector3::new(0.049, 0.0, -0.01)));
        let cut = CutTopology::rebuild(&l, edges);
        assert!(cut.pieces >= 2, "{} pieces", cut.pieces);
        let (fast, all) = (surfaces_of_pieces(&l, &cut, &samples, true), surfaces_of_pieces(&l, &cut, &samples, false));
        assert_eq!(fast.len(), all.len());
        for (a, b) in fast.iter().zip(&all) {
            assert!(!a.rest.triangles.is_empty());
            assert_eq!(a.rest.vertices, b.rest.vertices);
            assert_eq!(a.rest.triangles, b.rest.triangles);
            assert_eq!(a.bindings.len(), b.bindings.len());
        }
    }

    #[test]
    fn a_slit_within_one_piece_shows_as_two_faces_that_open_with_their_sides() {
        let l = Lattice::block(Point3::origin(), 0.01, [6, 6, 6]);
        let size = Vector3::repeat(0.06);
        let samples = BodySamples::new(&l, 4, &box_sdf(size));
        let whole = &piece_surfaces(&l, &CutTopology::rebuild(&l, []), &samples)[0].rest;
        // The blade goes in from the top, 3.3 cm deep, across the whole block at y = 0.023.
        let edge: Vec<Point3<f64>> = (0..9).map(|k| Point3::new(-0.01 + 0.01 * k as f64, 0.0, 0.0)).collect();
        let hash = SpatialHash::new(&l, &l.rest, l.cell);
        let s = SweptSurface::between(
            &edge,
            &Isometry3::translation(0.0, 0.023, 0.08),
            &Isometry3::translation(0.0, 0.023, 0.027),
            0.005,
            0.1,
        )
        .expect("surface");
        let cut = CutTopology::rebuild(&l, cut_edges(&l, &l.rest, &hash, &s).edges);
        assert_eq!(cut.pieces, 1, "a slit does not separate");
        let surfaces = piece_surfaces(&l, &cut, &samples);
        let slit = &surfaces[0].rest;
        assert!(slit.is_closed(), "closed with the slit's faces");
        assert_eq!(slit.orientation_conflicts(), 0);
        assert!((slit.volume() - whole.volume()).abs() < 0.01 * whole.volume(), "no material lost");
        // Two faces, each as wide as the block and as deep as the split cells (3 of 6 layers),
        // folded into each other at the slit's front.
        let added = slit.area() - whole.area();
        let expected = 2.0 * 0.06 * 0.03;
        assert!((added - expected).abs() < 0.15 * expected, "added {added} m² vs {expected}");
        // Pull the side y < 0.023 of the split cells away: the faces part, no vertex is torn from
        // its side (vertices bound to copies whose nodes did not move stay put).
        let mut u = vec![Vector3::zeros(); cut.node_count(&l)];
        let base = l.node_count();
        for (v, &real) in cut.virtual_of.iter().enumerate() {
            if l.rest[real as usize].y > 0.023 {
                u[base + v] = Vector3::new(0.0, -0.004, 0.0);
            }
        }
        for n in 0..base {
            if l.rest[n].y < 0.023 && l.rest[n].z > 0.025 {
                u[n] = Vector3::new(0.0, -0.004, 0.0);
            }
        }
        let moved = surfaces[0].deformed(&u);
        let opened = moved.iter().zip(&slit.vertices).filter(|(q, p)| (q.y - p.y as f32) < -0.003).count();
        assert!(opened > 0, "the side that moved carries its face along");
    }

    #[test]
    fn a_straight_cut_gives_two_closed_pieces_with_the_volume_kept() {
        let l = Lattice::block(Point3::origin(), 0.01, [6, 6, 6]);
        let size = Vector3::repeat(0.06);
        let samples = BodySamples::new(&l, 4, &box_sdf(size));
        let whole = CutTopology::rebuild(&l, []);
        let surfaces = piece_surfaces(&l, &whole, &samples);
        assert_eq!(surfaces.len(), 1);
        assert!(surfaces[0].rest.is_closed() && surfaces[0].rest.orientation_conflicts() == 0);
        let v0 = surfaces[0].rest.volume();
        // Surface nets cut the box's edges and corners by about half a sample: within 2%.
        assert!((v0 - 0.06f64.powi(3)).abs() < 0.02 * 0.06f64.powi(3), "{v0}");

        let edge: Vec<Point3<f64>> = (0..9).map(|k| Point3::new(-0.01 + 0.01 * k as f64, 0.0, 0.0)).collect();
        let hash = SpatialHash::new(&l, &l.rest, l.cell);
        let s = SweptSurface::between(
            &edge,
            &Isometry3::translation(0.0, 0.023, 0.08),
            &Isometry3::translation(0.0, 0.023, -0.01),
            0.005,
            0.1,
        )
        .expect("surface");
        let cut = CutTopology::rebuild(&l, cut_edges(&l, &l.rest, &hash, &s).edges);
        let surfaces = piece_surfaces(&l, &cut, &samples);
        assert_eq!(surfaces.len(), 2);
        let mut volumes = Vec::new();
        for s in &surfaces {
            assert!(s.rest.is_closed(), "each piece is closed");
            assert_eq!(s.rest.orientation_conflicts(), 0);
            assert!(s.rest.volume() > 0.0, "outward normals");
            volumes.push(s.rest.volume());
        }
        let total: f64 = volumes.iter().sum();
        assert!((total - v0).abs() < 0.01 * v0, "volume kept within 1%: {total} vs {v0}");
        volumes.sort_by(f64::total_cmp);
        // The cut plane y = 2.3 cm: 2.3 / 6 of the box on one side.
        let expected = 0.023 / 0.06 * v0;
        assert!((volumes[0] - expected).abs() < 0.02 * v0, "{volumes:?} vs {expected}");
        // At rest, the bound vertices stay where they are.
        let u = vec![Vector3::zeros(); cut.node_count(&l)];
        for s in &surfaces {
            for (p, q) in s.rest.vertices.iter().zip(s.deformed(&u)) {
                assert!((p.cast::<f32>() - q).norm() < 1e-6);
            }
        }
        // Moving piece 0's nodes moves its surface rigidly; piece 1's stays.
        let mut u = u;
        for (copy, &piece) in cut.copies.iter().zip(&cut.piece_of) {
            if piece == 0 {
                for &n in &copy.nodes {
                    u[n as usize] = Vector3::new(0.0, 0.0, -0.01);
                }
            }
        }
        for (k, s) in surfaces.iter().enumerate() {
            let moved = s.deformed(&u);
            let expected = if k == 0 { -0.01 } else { 0.0 };
            for (p, q) in s.rest.vertices.iter().zip(&moved) {
                assert!((q.z - p.z as f32 - expected).abs() < 1e-5, "piece {k}: {p} -> {q}");
            }
        }
    }
}
