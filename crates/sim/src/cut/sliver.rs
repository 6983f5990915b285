//! Slivers between two cuts that nearly coincide: torn through, so passes of a blade that follow
//! each other's groove separate what they cut between them.
//!
//! A blade stroked twice along the same line never sweeps the same surface twice: the hand
//! drifts, and the tissue moves between the passes, so in the material frame the second pass's
//! surface lies a little beside the first. Where the two surfaces overlap, the material between
//! them is a sliver joined to one side above the overlap and to the other below it; where they
//! merely abut, the seam between them leaves a bridge. Either way the body stays one piece,
//! exactly as a continuum cut by two zero-thickness surfaces would, and unlike tissue, which tears
//! a sliver far thinner than the blade's own width. On the lattice the sliver shows as lattice
//! nodes between two crossings of their edges along one axis (two surfaces on either side of a
//! node plane), and the bridge as neighbouring nodes in a node plane, one cut from the plane's
//! low side and the other from its high side.
//!
//! [`tear`] closes both, given [`TEAR_CELLS`]: a node cut on both sides along an axis, the two
//! crossings closer together than that, keeps only the crossing on its low side (the two
//! surfaces become one there; the same side at every node, so a sliver joins one side whole
//! instead of being split between them, which leaves cells of three components and flimsy
//! copies: the stress test's two passes 0.3 cells apart diverged that way); then an uncut edge between two neighbours cut from opposite sides along another
//! axis, with crossings closer than that across the plane, is cut half-way. A single surface never
//! triggers either rule (a continuous surface that passes on one side of a node and on the other
//! side of its neighbour crosses the edge between them), and two cuts at least [`TEAR_CELLS`]
//! apart are both kept, so a slice that thick comes off as its own piece.
//!
//! One more gap is closed: a hole of one node in a cut that runs along a node plane ([`holes`],
//! closed by [`crate::vna::CutTopology::rebuild`]). The plane's nodes are cut from one side or
//! the other by fractions of a millimetre, and a node the tissue carried across the plane while
//! the blade passed it, or one the blade's edge missed by a hair where it barely reached the
//! body's boundary, may be left uncut though every neighbour it has in the plane is cut from one
//! side: that node alone joins the two sides (the built-in resection's lobe stayed on by one node
//! at its top, on a recording whose blade was trusted in all 150 frame sets). Such a node is cut
//! from that side too. A surface that ends (a partial cut) leaves its frontier's
//! nodes uncut beside uncut neighbours, so it is not extended.
//!
//! And a bridge where the body ends at a node plane that the cut runs along: where the body is
//! stepped, a node of the plane on the step's face has no neighbour past the plane, so a blade
//! passing a hair beyond the plane crosses no edge there, while the nodes under it, where the
//! body goes on, are cut from the near side: the face's node joins the two sides through its edge
//! down (random:1361 in random:1187's resection kept its lobe so, with every frame set's blade
//! trusted). Where the cut runs along the plane (two nodes in a row cut from the same side
//! within [`PLANE_CELLS`]), [`tear`] carries it on to the face's node: that node's edge toward the
//! same side is cut as near it, leaving no more than that between the cut and the body's end.
//! (Cutting its edge down instead, tried first, left the face's nodes a flap joined to the other
//! side, which flapped 1.5 cm/s at rest at the end of the built-in main job.)

use std::collections::BTreeMap;

use crate::lattice::Lattice;

/// Two cuts closer together than this, in lattice cells along an axis, are one: the material
/// between them tears.
pub const TEAR_CELLS: f64 = 0.75;

/// A cut whose crossings are this near a node plane's nodes, in lattice cells, runs along the
/// plane: [`holes`] closes a node left uncut in it, and [`tear`] carries it on to where the body
/// ends at the plane.
pub const PLANE_CELLS: f64 = 0.5 * TEAR_CELLS;

/// A lattice edge's key in a map of crossings: its nodes, lower first.
fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// How far from `n` the crossing of edge `(n, m)` lies, as a fraction of the edge (`cut` holds
/// crossings from the lower node), if the edge is cut.
fn distance(cut: &BTreeMap<(u32, u32), f64>, n: u32, m: u32) -> Option<f64> {
    cut.get(&key(n, m)).map(|&t| if n < m { t } else { 1.0 - t })
}

/// The neighbour of node `n` one step along `axis` (`step` = -1 or +1), if there is one.
fn neighbour(lattice: &Lattice, n: u32, axis: usize, step: i64) -> Option<u32> {
    let mut ijk = lattice.node_ijk[n as usize].map(i64::from);
    ijk[axis] += step;
    if ijk[axis] < 0 {
        return None;
    }
    lattice.node_at(ijk.map(|v| v as usize))
}

/// Which side along `axis` node `n` is cut from, with the crossing's distance from it: `Some(-1,
/// d)` when only its edge toward lower `axis` is cut, `Some(+1, d)` when only the other one is,
/// `None` when neither or both are.
fn cut_side(lattice: &Lattice, cut: &BTreeMap<(u32, u32), f64>, n: u32, axis: usize) -> Option<(i8, f64)> {
    let low = neighbour(lattice, n, axis, -1).and_then(|m| distance(cut, n, m));
    let high = neighbour(lattice, n, axis, 1).and_then(|m| distance(cut, n, m));
    match (low, high) {
        (Some(d), None) => Some((-1, d)),
        (None, Some(d)) => Some((1, d)),
        _ => None,
    }
}

/// The nodes that end a crossed edge of `cut`, sorted, each once.
fn ends(cut: &BTreeMap<(u32, u32), f64>) -> Vec<u32> {
    let mut nodes: Vec<u32> = cut.keys().flat_map(|&(a, b)| [a, b]).collect();
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// What [`tear`] changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Torn {
    /// Crossings dropped because a nearer one on the node's other side stands for both.
    pub merged: usize,
    /// Edges cut across a bridge between neighbours cut from opposite sides, or to carry a cut
    /// along a node plane on to a node where the body ends at the plane.
    pub bridged: usize,
    /// Edges cut to close a hole of one node in a cut along a node plane ([`holes`]; counted by
    /// [`crate::vna::CutTopology::rebuild`], which closes them).
    pub holes: usize,
}

/// Tears the slivers and bridges between nearly coincident cuts in `cut` (crossed edges of
/// `lattice` by their nodes, the crossing's parameter from the lower node), in place.
pub fn tear(lattice: &Lattice, cut: &mut BTreeMap<(u32, u32), f64>) -> Torn {
    let mut torn = Torn::default();
    if cut.is_empty() {
        return torn;
    }
    // Nodes next to a crossing: the only ones either rule can apply to.
    let near = ends(cut);
    // Slivers: both crossings of a node along an axis within TEAR_CELLS of each other; the high
    // one goes. Each is within TEAR_CELLS of this node, so nearer to it than to the edge's other
    // end, and no other node's decision involves the same edge: the drops are decided first and
    // then made.
    let mut drop = Vec::new();
    for &n in &near {
        for axis in 0..3 {
            let low = neighbour(lattice, n, axis, -1).and_then(|m| Some((m, distance(cut, n, m)?)));
            let high = neighbour(lattice, n, axis, 1).and_then(|m| Some((m, distance(cut, n, m)?)));
            if let (Some((_, dl)), Some((mh, dh))) = (low, high)
                && dl + dh < TEAR_CELLS
            {
                drop.push(key(n, mh));
            }
        }
    }
    for k in drop {
        torn.merged += usize::from(cut.remove(&k).is_some());
    }
    // Bridges: an uncut edge between neighbours cut from opposite sides along another axis.
    let mut bridges = Vec::new();
    for &n in &near {
        for along in 0..3 {
            let Some(m) = neighbour(lattice, n, along, 1) else { continue };
            if cut.contains_key(&key(n, m)) {
                continue;
            }
            let opposite = (0..3).filter(|&a| a != along).any(|axis| {
                match (cut_side(lattice, cut, n, axis), cut_side(lattice, cut, m, axis)) {
                    (Some((sn, dn)), Some((sm, dm))) => sn != sm && dn + dm < TEAR_CELLS,
                    _ => false,
                }
            });
            if opposite {
                bridges.push(key(n, m));
            }
        }
    }
    for k in bridges {
        torn.bridged += usize::from(cut.insert(k, 0.5).is_none());
    }
    // Bridges at the body's end: a node cut from one side along an axis, near it, where the body
    // goes on past it, and its neighbour beyond it in the plane across the axis cut so too (the
    // surface runs along the plane there); its neighbour on this side in that plane, where the
    // body ends on the far side, is uncut toward the side it has and joins the sides alone. The
    // surface is carried on along the plane to it: its edge toward that side is cut as far from
    // it as the node's is, leaving less than PLANE_CELLS of material between the cut and the end.
    let mut carried: Vec<((u32, u32), f64)> = Vec::new();
    for &m in &near {
        for axis in 0..3 {
            let Some((sm, dm)) = cut_side(lattice, cut, m, axis) else { continue };
            if dm >= PLANE_CELLS || neighbour(lattice, m, axis, -i64::from(sm)).is_none() {
                continue;
            }
            for along in (0..3).filter(|&a| a != axis) {
                for step in [-1, 1] {
                    let Some(n) = neighbour(lattice, m, along, step) else { continue };
                    let beyond = neighbour(lattice, m, along, -step).and_then(|b| cut_side(lattice, cut, b, axis));
                    if !beyond.is_some_and(|(sb, db)| sb == sm && db < PLANE_CELLS)
                        || cut.contains_key(&key(n, m))
                        || end_side(lattice, cut, n, axis) != Some(-sm)
                    {
                        continue;
                    }
                    let Some(inner) = neighbour(lattice, n, axis, i64::from(sm)) else { continue };
                    carried.push((key(n, inner), if n < inner { dm } else { 1.0 - dm }));
                }
            }
        }
    }
    for (k, t) in carried {
        if let std::collections::btree_map::Entry::Vacant(e) = cut.entry(k) {
            e.insert(t);
            torn.bridged += 1;
        }
    }
    torn
}

/// The side along `axis` on which the body ends at node `n`: `Some(s)` when `n` has no neighbour
/// toward `s` and an uncut edge toward the other side; `None` otherwise.
fn end_side(lattice: &Lattice, cut: &BTreeMap<(u32, u32), f64>, n: u32, axis: usize) -> Option<i8> {
    match (neighbour(lattice, n, axis, -1), neighbour(lattice, n, axis, 1)) {
        (Some(m), None) if distance(cut, n, m).is_none() => Some(1),
        (None, Some(m)) if distance(cut, n, m).is_none() => Some(-1),
        _ => None,
    }
}

/// The edges that would close the holes of one node in `cut` (crossed edges of `lattice` by
/// their nodes, the crossing's parameter from the lower node), with their crossings: for each
/// node uncut along an axis while every neighbour it has in the plane across that axis (at least
/// two) is cut from the same side along it, near the plane (within [`PLANE_CELLS`]), its
/// edge toward that side, at their crossings' mean distance. Found on `cut` as it is, so a hole
/// closed never closes another. [`crate::vna::CutTopology::rebuild`] closes them.
pub fn holes(lattice: &Lattice, cut: &BTreeMap<(u32, u32), f64>) -> Vec<((u32, u32), f64)> {
    let near = ends(cut);
    // A hole's node is not next to a crossing along the axis, but its neighbours in the plane
    // are: look at the neighbours of the nodes next to a crossing.
    let mut candidates: Vec<u32> = near
        .iter()
        .flat_map(|&n| (0..3).flat_map(move |axis| [-1, 1].map(move |step| (n, axis, step))))
        .filter_map(|(n, axis, step)| neighbour(lattice, n, axis, step))
        .collect();
    candidates.sort_unstable();
    candidates.dedup();
    let mut closes = Vec::new();
    for &n in &candidates {
        for axis in 0..3 {
            let (low, high) = (neighbour(lattice, n, axis, -1), neighbour(lattice, n, axis, 1));
            let cut_here = |m: Option<u32>| m.is_some_and(|m| cut.contains_key(&key(n, m)));
            if cut_here(low) || cut_here(high) {
                continue;
            }
            let mut side = None;
            let mut distances = Vec::with_capacity(4);
            let mut whole = true;
            for other in (0..3).filter(|&a| a != axis) {
                for step in [-1, 1] {
                    let Some(m) = neighbour(lattice, n, other, step) else { continue };
                    match cut_side(lattice, cut, m, axis) {
                        Some((s, d)) if d < PLANE_CELLS && side.is_none_or(|x| x == s) => {
                            side = Some(s);
                            distances.push(d);
                        }
                        _ => whole = false,
                    }
                }
            }
            let (Some(s), true) = (side, whole && distances.len() >= 2) else { continue };
            let Some(m) = (if s < 0 { low } else { high }) else { continue };
            let d = distances.iter().sum::<f64>() / distances.len() as f64;
            closes.push((n, m, d));
        }
    }
    let mut edges: Vec<((u32, u32), f64)> =
        closes.into_iter().map(|(n, m, d)| (key(n, m), if n < m { d } else { 1.0 - d })).collect();
    edges.sort_by_key(|e| e.0);
    edges.dedup_by(|a, b| a.0 == b.0);
    edges
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collide::EdgeCut;
    use crate::vna::CutTopology;
    use crate::vna::tests::{block, stroke};

    fn pieces(l: &Lattice, strokes: &[(f64, f64, f64)]) -> usize {
        let edges = strokes.iter().flat_map(|&(y, z0, z1)| stroke(l, y, z0, z1));
        CutTopology::rebuild(l, edges).pieces
    }

    #[test]
    fn two_passes_on_either_side_of_a_node_plane_separate_whether_they_overlap_or_abut() {
        let l = block();
        // The node plane y = 3 cm; the first pass 0.1 mm below it from the top to z = 2.5 cm, the
        // second 0.1 mm above it from z = 3.5 cm (overlapping) or 2.5 cm (abutting) to the bottom.
        for (y1, y2) in [(0.0299, 0.0301), (0.0301, 0.0299), (0.0285, 0.0315), (0.028, 0.031), (0.027, 0.0335)] {
            for z2 in [0.035, 0.025, 0.0251] {
                assert_eq!(pieces(&l, &[(y1, 0.08, 0.025), (y2, z2, -0.01)]), 2, "y {y1} / {y2}, second from z {z2}");
            }
        }
    }

    #[test]
    fn a_node_left_uncut_inside_a_cut_along_a_node_plane_is_cut_from_its_neighbours_side() {
        let l = block();
        // A cut 0.1 mm above the node plane y = 3 cm: every node of the plane is cut from its high
        // side. Leave out the crossings of an inner node, of a node on the block's face and of
        // a corner node (two neighbours in the plane): each joins the pieces alone.
        let full: Vec<EdgeCut> = stroke(&l, 0.0301, 0.08, -0.01);
        for ijk in [[3, 3, 3], [0, 3, 2], [6, 3, 6]] {
            let hole = l.node_at(ijk).expect("a node");
            let edges: Vec<EdgeCut> = full.iter().copied().filter(|e| e.a != hole && e.b != hole).collect();
            assert_eq!(edges.len(), full.len() - 1);
            let mut cut: BTreeMap<(u32, u32), f64> = edges.iter().map(|e| ((e.a, e.b), e.t)).collect();
            assert_eq!(tear(&l, &mut cut), Torn::default(), "{ijk:?}");
            let above = l.node_at([ijk[0], 4, ijk[2]]).expect("a node");
            let found = holes(&l, &cut);
            assert_eq!(found.len(), 1, "{ijk:?}: {found:?}");
            let ((a, b), t) = found[0];
            assert_eq!((a, b), (hole.min(above), hole.max(above)), "{ijk:?}");
            let d = if hole < above { t } else { 1.0 - t };
            assert!((d - 0.01).abs() < 1e-6, "{ijk:?}: at {d}");
            let topology = CutTopology::rebuild(&l, edges);
            assert_eq!(topology.pieces, 2, "{ijk:?}");
            assert_eq!(topology.torn.holes, 1);
            assert!(topology.cut.contains_key(&(a, b)));
        }
        // Two neighbouring nodes left out: each has an uncut neighbour, nothing is closed (a cut's
        // end is never extended).
        let (a, b) = (l.node_at([3, 3, 3]).expect("a node"), l.node_at([4, 3, 3]).expect("a node"));
        let cut: BTreeMap<(u32, u32), f64> = full
            .iter()
            .filter(|e| ![a, b].contains(&e.a) && ![a, b].contains(&e.b))
            .map(|e| ((e.a, e.b), e.t))
            .collect();
        assert!(holes(&l, &cut).is_empty());
        // A hole in a slit stopped 3.5 cm down (a node of its top row left out) is closed too;
        // the slit parts nothing, and its end is where it was.
        let slit: Vec<EdgeCut> = stroke(&l, 0.0301, 0.08, 0.035);
        let hole = l.node_at([3, 3, 6]).expect("a node");
        let edges: Vec<EdgeCut> = slit.iter().copied().filter(|e| e.a != hole && e.b != hole).collect();
        let topology = CutTopology::rebuild(&l, edges);
        assert_eq!((topology.pieces, topology.torn.holes), (1, 1));
        let whole = CutTopology::rebuild(&l, slit);
        assert_eq!(topology.cut.keys().collect::<Vec<_>>(), whole.cut.keys().collect::<Vec<_>>());
    }

    /// The crossed edges of a stroke of an 8 cm edge along y in the plane x = `x`, from z0 down
    /// to z1.
    fn stroke_x(l: &Lattice, x: f64, z0: f64, z1: f64) -> Vec<EdgeCut> {
        let edge: Vec<nalgebra::Point3<f64>> =
            (0..9).map(|k| nalgebra::Point3::new(0.0, -0.01 + 0.01 * k as f64, 0.0)).collect();
        let hash = crate::collide::SpatialHash::new(l, &l.rest, l.cell);
        let surface = crate::sweep::SweptSurface::between(
            &edge,
            &nalgebra::Isometry3::translation(x, 0.0, z0),
            &nalgebra::Isometry3::translation(x, 0.0, z1),
            0.005,
            0.1,
        )
        .expect("surface");
        crate::collide::cut_edges(l, &l.rest, &hash, &surface).edges
    }

    #[test]
    fn a_cut_that_crosses_a_node_plane_where_the_body_ends_at_it_separates() {
        // A block of 1 cm cells, 6 x 6 x 6, whose top layer ends at the node plane x = 3 cm: the
        // plane's nodes on the top face have no neighbour toward +x. The blade passes 0.1 mm
        // beyond that plane through the top layer, so those nodes' only edge along x is not
        // crossed, and 0.1 mm short of it below, so the nodes under them are cut from their low
        // side: the top nodes joined the low piece to the high one through the edges down
        // (random:1361 in random:1187's resection, mask files, all 150 frame sets trusted,
        // lobe on). Either order of the two passes' heights, and the whole cut on one side.
        let fraction: Vec<f32> = (0..216).map(|idx| if idx / 36 == 5 && idx % 6 >= 3 { 0.0 } else { 1.0 }).collect();
        let l = Lattice::from_fractions(nalgebra::Point3::origin(), 0.01, [6, 6, 6], &fraction, 0.01);
        for (top, below) in [(0.0301, 0.0299), (0.0299, 0.0301), (0.0301, 0.0301), (0.0299, 0.0299)] {
            let mut edges = stroke_x(&l, top, 0.08, 0.055);
            edges.extend(stroke_x(&l, below, 0.056, -0.01));
            let topology = CutTopology::rebuild(&l, edges);
            assert_eq!(topology.pieces, 2, "x {top} over {below}");
            // One surface through both passes separates by itself: no rule fires.
            assert_eq!(top == below, topology.torn == Torn::default(), "x {top} over {below}: {:?}", topology.torn);
        }
    }

    #[test]
    fn the_rules_change_nothing_for_one_surface_and_keep_a_slice_thicker_than_the_tear_limit() {
        let l = block();
        for y in [0.023, 0.03, 0.0299, 0.0301] {
            let mut cut: BTreeMap<(u32, u32), f64> =
                stroke(&l, y, 0.08, -0.01).into_iter().map(|e| ((e.a, e.b), e.t)).collect();
            let before = cut.clone();
            assert_eq!(tear(&l, &mut cut), Torn::default(), "y = {y}");
            assert_eq!(cut, before);
        }
        // A partial slit: nothing either.
        let mut cut: BTreeMap<(u32, u32), f64> =
            stroke(&l, 0.023, 0.08, 0.035).into_iter().map(|e| ((e.a, e.b), e.t)).collect();
        assert_eq!(tear(&l, &mut cut), Torn::default());
        // Two whole cuts 0.8 cells apart across a node plane, or a cell apart: a slice comes off.
        assert_eq!(pieces(&l, &[(0.026, 0.08, -0.01), (0.034, 0.08, -0.01)]), 3);
        assert_eq!(pieces(&l, &[(0.025, 0.08, -0.01), (0.035, 0.08, -0.01)]), 3);
        // Closer than TEAR_CELLS: one cut.
        assert_eq!(pieces(&l, &[(0.0285, 0.08, -0.01), (0.0315, 0.08, -0.01)]), 2);
        assert_eq!(pieces(&l, &[(0.027, 0.08, -0.01), (0.033, 0.08, -0.01)]), 2);
    }
}
