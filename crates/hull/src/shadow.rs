//! Cast shadows: a pixel darker than its background with its chromaticity unchanged is a shadow
//! on the background, or a dark object of the background's colour; one view cannot tell which.
//! The hull of all views can: carved with such pixels counted as foreground, a cell of a real
//! object is seen as sure foreground by most views (the object against other backgrounds, or in
//! front of the hand), while a cell of a shadow on the table is seen as shadow by most views, and
//! as sure foreground only by those where the hand that casts it stands in front of it.
//! [`keep_supported`] keeps the cells that at least as many views see as sure foreground as see
//! only shadow there, and those that two views see as sure foreground in front of everything else
//! (a dark tool over a table of its colour is seen as shadow from above, as sure foreground from
//! the side; the hand's shadow is seen as sure foreground only through the hand); [`cover`] then
//! turns a view's shadow pixels that the kept cells cover into foreground (the rest go back to
//! background).

use image::GrayImage;
use rayon::prelude::*;

use crate::carve::{Footprint, footprint};
use crate::{Cell, Occupancy, Silhouette};

/// A cell that this many views see as sure foreground, in front of every other object, is kept
/// whatever the others see.
pub const SURE_VIEWS: usize = 2;

/// Cast shadows lie on the table: a cell wholly this high above the table top (z = 0 in a table's
/// frame) is an object, whatever its shading says. The hull of a shadow rises above the table
/// where the views' cones over it overlap, by about half the shadow's width times the tangent of
/// the lowest camera's elevation: some 2-3 cm for a hand's shadow seen from 20-40° up. Where a
/// real object stands on the table (a phantom organ, a tray), shadows fall on it too, higher than
/// this: the rule then keeps them as objects; hullcut's organ is virtual and casts no shadow.
pub const SHADOW_HULL_HEIGHT: f64 = 0.04;

/// How the views support one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Support {
    /// Kept: high above the table, or seen as sure foreground by at least as many views as see
    /// only shadow there.
    Strong,
    /// Seen as sure foreground by [`SURE_VIEWS`] views or more, but as only shadow by more: kept
    /// when that many of them see it in front of the strong and the marked cells ([`Front`]).
    Sure,
    /// Dropped, unless marked as an object.
    None,
}

/// The cells of `occ` (carved from `all`, the views' silhouettes with the possible shadows as
/// foreground) that at least as many views see as sure foreground (foreground in their footprint
/// in `sure`, the silhouettes with the possible shadows left out) as see only shadow there
/// (foreground in `all` but none in `sure`), one at least; with `table`, the world frame's z = 0
/// being the table top, also every cell wholly above [`SHADOW_HULL_HEIGHT`] (a skin-toned hand
/// over a wooden table looks like a shadow of it where it is shaded); also every cell `objects`
/// marks (by index; shorter or empty marks none: cells known to be an object, such as the
/// tracked tool's). A cell that more views see as shadow is kept too when [`SURE_VIEWS`] views
/// see sure foreground in its footprint that no cell kept or marked nearer the camera explains (a
/// dull tool over a table of its colour, seen as shadow from above and as sure foreground from
/// the side), but not when the sure foreground there is an object in front of it (the hand over
/// its own shadow, seen through it by the views near the light's direction: several of them on a
/// rig of many cameras). Returns the kept cells, which of them only the marks kept, and how many
/// went.
pub fn keep_supported(
    occ: &Occupancy,
    all: &[Option<Silhouette>],
    sure: &[Option<Silhouette>],
    margin_px: f64,
    table: bool,
    objects: &[bool],
) -> Supported {
    let pairs: Vec<(&Silhouette, &Silhouette)> =
        all.iter().zip(sure).filter_map(|(a, s)| a.as_ref().zip(s.as_ref())).collect();
    let support: Vec<Support> = occ
        .cells
        .par_iter()
        .map(|c| {
            if table && c.min.z > SHADOW_HULL_HEIGHT {
                return Support::Strong;
            }
            let (mut sure_views, mut shadow_views) = (0, 0);
            for (n, (a, s)) in pairs.iter().enumerate() {
                // Settled: the views left cannot outnumber the sure ones.
                if sure_views > 0 && sure_views >= shadow_views + pairs.len() - n {
                    return Support::Strong;
                }
                // One footprint per view, both tables read on it.
                let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(a, c, margin_px) else { continue };
                if s.counts(i0, j0, i1, j1).foreground() > 0 {
                    sure_views += 1;
                } else if a.counts(i0, j0, i1, j1).foreground() > 0 {
                    shadow_views += 1;
                }
            }
            if sure_views > 0 && sure_views >= shadow_views {
                Support::Strong
            } else if sure_views >= SURE_VIEWS {
                Support::Sure
            } else {
                Support::None
            }
        })
        .collect();
    let marked = |k: usize| objects.get(k).copied().unwrap_or(false);
    let mut seen: Vec<bool> = support.iter().map(|s| *s == Support::Strong).collect();
    // What stands in front of a contested cell: the strong cells and the marked objects.
    let front: Vec<bool> = seen.iter().enumerate().map(|(k, s)| *s || marked(k)).collect();
    let contested: Vec<usize> = (0..support.len()).filter(|&k| support[k] == Support::Sure).collect();
    if !contested.is_empty() {
        let fronts: Vec<Option<Front>> =
            pairs.par_iter().map(|(_, s)| Front::of(occ, &front, &contested, s, margin_px)).collect();
        let in_front: Vec<bool> = contested
            .par_iter()
            .map(|&k| {
                let c = &occ.cells[k];
                let views = pairs
                    .iter()
                    .zip(&fronts)
                    .filter(|((_, s), front)| {
                        front.as_ref().is_some_and(|f| f.sees_sure(s, c, occ.leaf_size, margin_px))
                    })
                    .count();
                views >= SURE_VIEWS
            })
            .collect();
        for (&k, in_front) in contested.iter().zip(in_front) {
            seen[k] = in_front;
        }
    }
    let mut occupancy = occ.clone();
    occupancy.cells.clear();
    let mut marked_only = Vec::new();
    for (k, c) in occ.cells.iter().enumerate() {
        if seen[k] || marked(k) {
            occupancy.cells.push(*c);
            marked_only.push(!seen[k]);
        }
    }
    let dropped = occ.cells.len() - occupancy.cells.len();
    let seen_through = contested.iter().filter(|&&k| !seen[k] && !marked(k)).count();
    Supported { occupancy, marked_only, dropped, seen_through }
}

/// What [`keep_supported`] kept.
#[derive(Debug, Clone)]
pub struct Supported {
    /// The kept cells.
    pub occupancy: Occupancy,
    /// Per kept cell: kept only because it was marked as an object, no view's support would
    /// have kept it (it may be the object, or a shadow beside it).
    pub marked_only: Vec<bool>,
    /// How many cells went.
    pub dropped: usize,
    /// Of those, how many [`SURE_VIEWS`] views or more saw as sure foreground, but only through
    /// an object in front of them (the hand over its own shadow).
    pub seen_through: usize,
}

/// Distance of a cell's nearest point from a camera, along its axis, at most: its centre's depth
/// less its half-diagonal.
fn near_depth(view: &Silhouette, c: &Cell) -> f64 {
    view.camera().world_to_camera(&c.centre()).z - 0.87 * c.size
}

/// The depth of the nearest cell in front ([`Support::Strong`], or marked as an object) at each
/// pixel of a window of one view (the box of the contested cells' footprints), over each cell's
/// footprint box.
#[derive(Debug)]
struct Front {
    i0: usize,
    j0: usize,
    width: usize,
    height: usize,
    /// Nearest depth (metres along the camera's axis; infinite where no such cell lies), row
    /// by row.
    depth: Vec<f32>,
}

impl Front {
    /// The window over the contested cells' footprints in `view`, and the cells `in_front` marks
    /// drawn into it; `None` when no contested cell is in view.
    fn of(occ: &Occupancy, in_front: &[bool], contested: &[usize], view: &Silhouette, margin_px: f64) -> Option<Self> {
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for &k in contested {
            if let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, &occ.cells[k], margin_px) {
                lo = [lo[0].min(i0), lo[1].min(j0)];
                hi = [hi[0].max(i1), hi[1].max(j1)];
            }
        }
        if lo[0] > hi[0] {
            return None;
        }
        let (width, height) = (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1);
        let mut front = Front { i0: lo[0], j0: lo[1], width, height, depth: vec![f32::INFINITY; width * height] };
        for (c, _) in occ.cells.iter().zip(in_front).filter(|(_, f)| **f) {
            let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, c, 0.0) else { continue };
            if i1 < lo[0] || i0 > hi[0] || j1 < lo[1] || j0 > hi[1] {
                continue;
            }
            let d = near_depth(view, c) as f32;
            let (a0, a1) = (i0.max(lo[0]) - lo[0], i1.min(hi[0]) - lo[0]);
            for j in j0.max(lo[1])..=j1.min(hi[1]) {
                let row = (j - lo[1]) * width;
                for z in &mut front.depth[row + a0..=row + a1] {
                    *z = z.min(d);
                }
            }
        }
        Some(front)
    }

    /// Whether `view` (the sure silhouette) sees sure foreground in the footprint of `c` at a
    /// pixel where no cell of the front lies in front of it by more than a leaf.
    fn sees_sure(&self, view: &Silhouette, c: &Cell, leaf: f64, margin_px: f64) -> bool {
        let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, c, margin_px) else { return false };
        if view.counts(i0, j0, i1, j1).foreground() == 0 {
            return false;
        }
        let behind = (near_depth(view, c) - leaf) as f32;
        (j0..=j1).any(|j| {
            (i0..=i1).any(|i| {
                let (Some(x), Some(y)) = (i.checked_sub(self.i0), j.checked_sub(self.j0)) else { return false };
                let nearest =
                    if x < self.width && y < self.height { self.depth[y * self.width + x] } else { f32::INFINITY };
                nearest >= behind && view.counts(i, j, i, j).foreground() > 0
            })
        })
    }
}

/// Which cells of `occ` still show foreground (any non-zero pixel) in their footprint in every
/// view of `masks` given: masks changed after carving (possible shadows given back to the
/// background once shown to lie on the table). `views` are the silhouettes carved from, for
/// their cameras; a view not given in `masks` (`None`, or shorter) is not asked, nor is a cell
/// wholly above [`SHADOW_HULL_HEIGHT`] (no shadow's hull rises there), nor a view its footprint
/// misses. One footprint scan per low cell and view asked.
pub fn still_seen(
    occ: &Occupancy,
    views: &[Option<Silhouette>],
    masks: &[Option<&GrayImage>],
    margin_px: f64,
) -> Vec<bool> {
    let asked: Vec<(&Silhouette, &GrayImage)> = views
        .iter()
        .zip(masks)
        .filter_map(|(v, m)| v.as_ref().zip(*m))
        .filter(|(v, m)| m.dimensions() == (v.camera().width, v.camera().height))
        .collect();
    occ.cells
        .par_iter()
        .map(|c| {
            if c.min.z > SHADOW_HULL_HEIGHT {
                return true;
            }
            asked.iter().all(|(view, mask)| {
                let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, c, margin_px) else { return true };
                let w = mask.width() as usize;
                (j0..=j1).any(|j| mask.as_raw()[j * w + i0..=j * w + i1].iter().any(|&p| p != 0))
            })
        })
        .collect()
}

/// Sets the pixels of `mask` valued `from` that the footprint of a cell of `occ` covers in `view`
/// to `to`, and every other `from` pixel to 0; returns how many became `to`. `view` must be the
/// silhouette of this view's camera (its tables are not read).
pub fn cover(occ: &Occupancy, view: &Silhouette, mask: &mut GrayImage, from: u8, to: u8, margin_px: f64) -> u64 {
    let covered = cover_split(occ, view, mask, from, margin_px, |_| true, [to, to]);
    covered[0] + covered[1]
}

/// [`cover`] in two kinds: a `from` pixel that the footprint of a cell `firm` holds (by index in
/// `occ`) covers becomes `to[0]`, one that only other cells cover `to[1]`; every other `from`
/// pixel becomes 0. Returns how many became each (with `to[0] == to[1]`, all count as the first).
/// `to[1]` must be a value `mask` does not hold before.
pub fn cover_split(
    occ: &Occupancy,
    view: &Silhouette,
    mask: &mut GrayImage,
    from: u8,
    margin_px: f64,
    firm: impl Fn(usize) -> bool,
    to: [u8; 2],
) -> [u64; 2] {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let raw: &mut [u8] = mask;
    // Which blocks of `BLOCK`² pixels hold a `from` pixel: a cell whose footprint can only reach
    // blocks without one is skipped after projecting its centre.
    let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
    let mut blocks = vec![false; bw * bh];
    let mut any = false;
    for (k, _) in raw.iter().enumerate().filter(|(_, p)| **p == from) {
        blocks[(k / w / BLOCK) * bw + (k % w) / BLOCK] = true;
        any = true;
    }
    if !any {
        return [0, 0];
    }
    let reaches = |lo: [f64; 2], hi: [f64; 2]| {
        let clip = |x: f64, n: usize| (x.max(0.0) as usize / BLOCK).min(n - 1);
        if hi[0] < 0.0 || hi[1] < 0.0 || lo[0] > (w - 1) as f64 || lo[1] > (h - 1) as f64 {
            return false;
        }
        let (b0, b1) = (clip(lo[0], bw), clip(hi[0], bw));
        (clip(lo[1], bh)..=clip(hi[1], bh)).any(|bj| blocks[bj * bw + b0..=bj * bw + b1].contains(&true))
    };
    let cam = view.camera();
    let limit = view.field_radius().unwrap_or(view.monotonic_radius());
    let split = to[0] != to[1];
    let mut covered = [0u64, 0];
    for (k, c) in occ.cells.iter().enumerate() {
        // Every pixel of the footprint lies within the disc holding the cell's projection, widened
        // by the margin, the lens' bow over the footprint and a pixel of rounding.
        if let Some((uv, r)) = cam.project_ball(&c.centre(), c.bounding_radius(), 1e-3, limit) {
            let pad = r + margin_px + view.curvature() * 4.0 * r * r + 1.0;
            if !reaches([uv.x - pad, uv.y - pad], [uv.x + pad, uv.y + pad]) {
                continue;
            }
        }
        let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, c, margin_px) else { continue };
        let kind = usize::from(split && !firm(k));
        for j in j0..=j1 {
            for p in raw.get_mut(j * w + i0..=j * w + i1).into_iter().flatten() {
                if *p == from {
                    *p = to[kind];
                    covered[kind] += 1;
                } else if split && kind == 0 && *p == to[1] {
                    // A firm cell covers what another cell only covered before it.
                    *p = to[0];
                    covered[0] += 1;
                    covered[1] = covered[1].saturating_sub(1);
                }
            }
        }
    }
    for p in raw.iter_mut().filter(|p| **p == from) {
        *p = 0;
    }
    covered
}

/// Side of the blocks in which [`cover`] looks for pixels to cover, pixels.
const BLOCK: usize = 8;

#[cfg(test)]
mod tests {
    use hullcut_rig::Camera;
    use image::{GrayImage, Luma};
    use nalgebra::{Point3, Vector3};

    use super::*;
    use crate::{Cell, Occupancy};

    /// A camera 1 m above the table looking down, and one 1 cm cell on the table under it.
    fn scene() -> (Camera, Occupancy) {
        let camera = Camera::new("top", 200, 200, 200.0, 200.0, 100.0, 100.0)
            .looking_at(Point3::new(0.0, 0.0, 1.0), Point3::origin(), Vector3::y())
            .expect("a camera looking down");
        let cell = Cell {
            min: Point3::new(-0.005, -0.005, 0.0),
            size: 0.01,
            hand: true,
            scalpel: false,
            solid: true,
            refuted_by: None,
        };
        let occ = Occupancy {
            cells: vec![cell],
            leaf_size: 0.01,
            origin: Point3::new(-0.005, -0.005, 0.0),
            resolution: 1,
            stats: Default::default(),
        };
        (camera, occ)
    }

    #[test]
    fn a_low_cell_whose_footprint_went_back_to_the_background_is_no_longer_seen() {
        let (camera, occ) = scene();
        let view = Silhouette::new(&camera, &GrayImage::from_pixel(200, 200, Luma([255])));
        let views = [Some(view)];
        let empty = GrayImage::new(200, 200);
        assert_eq!(still_seen(&occ, &views, &[Some(&empty)], 0.5), vec![false], "its view shows it no foreground now");
        let mut one = GrayImage::new(200, 200);
        one.put_pixel(100, 100, Luma([1]));
        assert_eq!(still_seen(&occ, &views, &[Some(&one)], 0.5), vec![true], "one pixel in its footprint keeps it");
        assert_eq!(still_seen(&occ, &views, &[None], 0.5), vec![true], "a view not asked keeps it");
        let mut high = occ.clone();
        high.cells[0].min.z = SHADOW_HULL_HEIGHT + 0.01;
        assert_eq!(still_seen(&high, &views, &[Some(&empty)], 0.5), vec![true], "above any shadow's hull");
    }

    #[test]
    fn a_cell_seen_only_as_shadow_goes_unless_it_is_known_to_be_an_object() {
        let (camera, occ) = scene();
        let all = Silhouette::new(&camera, &GrayImage::from_pixel(200, 200, Luma([255])));
        let sure = Silhouette::new(&camera, &GrayImage::new(200, 200));
        let (views, sures) = ([Some(all)], [Some(sure)]);
        let kept = keep_supported(&occ, &views, &sures, 0.5, true, &[]);
        assert_eq!((kept.occupancy.cells.len(), kept.dropped), (0, 1), "seen as shadow by its only view");
        let kept = keep_supported(&occ, &views, &sures, 0.5, true, &[true]);
        assert_eq!((kept.occupancy.cells.len(), kept.dropped), (1, 0), "marked as an object (the tracked tool's)");
        assert_eq!(kept.marked_only, vec![true], "kept by the mark alone");
        let kept = keep_supported(&occ, &views, &sures, 0.5, true, &[false]);
        assert!(kept.occupancy.cells.is_empty(), "a mark of false keeps nothing");
        // Seen as sure foreground, it stays whatever the marks say.
        let sure = Silhouette::new(&camera, &GrayImage::from_pixel(200, 200, Luma([255])));
        let kept = keep_supported(&occ, &views, &[Some(sure.clone())], 0.5, true, &[]);
        assert_eq!(kept.occupancy.cells.len(), 1);
        let kept = keep_supported(&occ, &views, &[Some(sure)], 0.5, true, &[true]);
        assert_eq!(kept.marked_only, vec![false], "seen, not only marked");
    }

    #[test]
    fn a_table_cell_seen_as_sure_only_through_an_object_in_front_goes() {
        let looking = |name: &str, eye: Point3<f64>, up: Vector3<f64>| {
            Camera::new(name, 200, 200, 200.0, 200.0, 100.0, 100.0)
                .looking_at(eye, Point3::origin(), up)
                .expect("a camera looking at the cell")
        };
        // Two cameras above the cell see sure foreground over all of it; three from the sides
        // see only shadow there.
        let cameras = [
            looking("top", Point3::new(0.0, 0.0, 1.0), Vector3::y()),
            looking("top2", Point3::new(0.02, 0.0, 1.0), Vector3::y()),
            looking("east", Point3::new(1.0, 0.0, 0.3), Vector3::z()),
            looking("west", Point3::new(-1.0, 0.0, 0.3), Vector3::z()),
            looking("north", Point3::new(0.0, 1.0, 0.3), Vector3::z()),
        ];
        let full = GrayImage::from_pixel(200, 200, Luma([255]));
        let all: Vec<Option<Silhouette>> = cameras.iter().map(|c| Some(Silhouette::new(c, &full))).collect();
        let sure: Vec<Option<Silhouette>> = cameras
            .iter()
            .enumerate()
            .map(|(k, c)| Some(Silhouette::new(c, &if k < 2 { full.clone() } else { GrayImage::new(200, 200) })))
            .collect();
        let (_, table_cell) = scene();
        // Nothing in front of it: the two views above see the cell itself (a dull tool seen as
        // sure foreground from two sides, as shadow from the rest).
        let kept = keep_supported(&table_cell, &all, &sure, 0.5, true, &[]);
        assert_eq!(
            (kept.occupancy.cells.len(), kept.dropped),
            (1, 0),
            "seen as sure foreground in front of everything by two views"
        );
        // A 2 cm object 10 cm above it (above the shadow hull's height: an object) hides it from
        // both views above: what they see there is the object, so the cell below is its shadow.
        let object = Cell {
            min: Point3::new(-0.01, -0.01, 0.1),
            size: 0.02,
            hand: true,
            scalpel: false,
            solid: true,
            refuted_by: None,
        };
        let mut both = table_cell.clone();
        both.cells.push(object);
        let kept = keep_supported(&both, &all, &sure, 0.5, true, &[]);
        assert_eq!((kept.dropped, kept.seen_through), (1, 1), "the cell under the object is its shadow");
        assert_eq!(kept.occupancy.cells, vec![object]);
        // Marked as an object, it stays, kept by the mark alone.
        let kept = keep_supported(&both, &all, &sure, 0.5, true, &[true, false]);
        assert_eq!(kept.marked_only, vec![true, false]);
        // Without the table rule the object is contested as well, and with nothing strong in
        // front of either both stay.
        let kept = keep_supported(&both, &all, &sure, 0.5, false, &[]);
        assert_eq!(kept.occupancy.cells.len(), 2);
        // Seen as sure foreground by one view only, it goes whatever is in front.
        let one: Vec<Option<Silhouette>> = cameras
            .iter()
            .enumerate()
            .map(|(k, c)| Some(Silhouette::new(c, &if k < 1 { full.clone() } else { GrayImage::new(200, 200) })))
            .collect();
        let kept = keep_supported(&table_cell, &all, &one, 0.5, true, &[]);
        assert!(kept.occupancy.cells.is_empty());
        assert_eq!(kept.seen_through, 0, "one view is not enough to look through anything");
    }

    #[test]
    fn cover_paints_what_every_cells_footprint_covers() {
        // A distorted camera looking down at cells of many sizes, some near its plane or beside
        // the image, over a mask with patches of `from` pixels.
        let mut camera = Camera::new("top", 320, 240, 260.0, 255.0, 158.0, 121.0)
            .looking_at(Point3::new(0.05, -0.02, 0.6), Point3::origin(), Vector3::y())
            .expect("a camera looking down");
        camera.distortion = hullcut_rig::Distortion { k1: -0.2, k2: 0.05, p1: 1e-3, p2: -5e-4, k3: 0.0 };
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let cells: Vec<Cell> = (0..600)
            .map(|_| {
                let size = 0.002 + 0.008 * next();
                let min = Point3::new(next() * 0.8 - 0.4, next() * 0.6 - 0.3, next() * 0.62 - 0.02);
                Cell { min, size, hand: true, scalpel: false, solid: true, refuted_by: None }
            })
            .collect();
        let occ =
            Occupancy { cells, leaf_size: 0.002, origin: Point3::origin(), resolution: 1, stats: Default::default() };
        let (from, to) = (7u8, 9u8);
        let mut mask = GrayImage::from_pixel(320, 240, Luma([1]));
        for _ in 0..25 {
            let (i, j) = ((next() * 300.0) as u32, (next() * 220.0) as u32);
            for y in j..j + 20 {
                for x in i..i + 20 {
                    if (x + y) % 3 != 0 {
                        mask.put_pixel(x, y, Luma([from]));
                    }
                }
            }
        }
        let view = Silhouette::new(&camera, &mask);
        // Paints the footprints of the cells `which` picks, `from` (or `over`) pixels to `to`.
        let paint = |expected: &mut GrayImage, which: &dyn Fn(usize) -> bool, over: u8, to: u8| {
            for (_, c) in occ.cells.iter().enumerate().filter(|(k, _)| which(*k)) {
                if let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(&view, c, 0.5) {
                    for j in j0..=j1 {
                        for i in i0..=i1 {
                            let p = expected.get_pixel_mut(i as u32, j as u32);
                            if p.0[0] == from || p.0[0] == over {
                                p.0[0] = to;
                            }
                        }
                    }
                }
            }
        };
        let original = mask.clone();
        let mut expected = mask.clone();
        paint(&mut expected, &|_| true, from, to);
        let painted = expected.iter().filter(|&&p| p == to).count() as u64;
        expected.iter_mut().filter(|p| **p == from).for_each(|p| *p = 0);
        let covered = cover(&occ, &view, &mut mask, from, to, 0.5);
        assert!(painted > 0 && expected.contains(&0), "the scene covers some pixels, not all");
        assert_eq!(covered, painted);
        assert!(mask == expected, "cover differs from painting every cell's footprint");
        // In two kinds: the odd cells' pixels become 11, then the even (firm) cells' 9, over them.
        let firm = |k: usize| k.is_multiple_of(2);
        let mut expected = original.clone();
        paint(&mut expected, &|k| !firm(k), from, 11);
        paint(&mut expected, &firm, 11, to);
        expected.iter_mut().filter(|p| **p == from).for_each(|p| *p = 0);
        let mut mask = original;
        let covered = cover_split(&occ, &view, &mut mask, from, 0.5, firm, [to, 11]);
        let count = |v: u8| expected.iter().filter(|&&p| p == v).count() as u64;
        assert!(count(to) > 0 && count(11) > 0, "both kinds cover some pixels");
        assert_eq!(covered, [count(to), count(11)]);
        assert!(mask == expected, "cover_split differs from painting the other cells, then the firm ones");
    }
}
