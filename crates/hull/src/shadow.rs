//! Cast shadows: a pixel darker than its background with its chromaticity unchanged is a shadow
//! on the background, or a dark object of the background's colour; one view cannot tell which.
//! The hull of all views can: carved with such pixels counted as foreground, a cell of a real
//! object is seen as sure foreground by most views (the object against other backgrounds, or in
//! front of the hand), while a cell of a shadow on the table is seen as shadow by most views, and
//! as sure foreground only by those where the hand that casts it stands in front of it.
//! [`keep_supported`] keeps the cells that two views see as sure foreground, or at least as many
//! as see only shadow there (a dark tool over a table of its colour is seen as shadow from above,
//! as sure foreground from the side); [`cover`] then turns a view's shadow pixels that the kept cells cover into
//! foreground (the rest go back to background).

use image::GrayImage;
use rayon::prelude::*;

use crate::carve::{Footprint, Projected, footprint, project};

/// A cell that this many views see as sure foreground is kept whatever the others see: the hand
/// stands between a shadow and a camera near the light's direction, seldom two.
pub const SURE_VIEWS: usize = 2;
use crate::{Occupancy, Silhouette};

/// Cast shadows lie on the table: a cell wholly this high above the table top (z = 0 in a table's
/// frame) is an object, whatever its shading says. The hull of a shadow rises above the table
/// where the views' cones over it overlap, by about half the shadow's width times the tangent of
/// the lowest camera's elevation: some 2-3 cm for a hand's shadow seen from 20-40° up. Where a
/// real object stands on the table (a phantom organ, a tray), shadows fall on it too, higher than
/// this: the rule then keeps them as objects; hullcut's organ is virtual and casts no shadow.
pub const SHADOW_HULL_HEIGHT: f64 = 0.04;

/// The cells of `occ` (carved from `all`, the views' silhouettes with the possible shadows as
/// foreground) that [`SURE_VIEWS`] views see as sure foreground (foreground in their footprint in
/// `sure`, the silhouettes with the possible shadows left out), or at least as many views as see
/// only shadow there (foreground in `all` but none in `sure`), one at least; with `table`, the
/// world frame's z = 0 being the table top, also every cell wholly above [`SHADOW_HULL_HEIGHT`]
/// (a skin-toned hand over a wooden table looks like a shadow of it where it is shaded); also every
/// cell `objects` marks (by index; shorter or empty marks none: cells known to be an object, such
/// as the tracked tool's); and how many cells went.
pub fn keep_supported(
    occ: &Occupancy,
    all: &[Option<Silhouette>],
    sure: &[Option<Silhouette>],
    margin_px: f64,
    table: bool,
    objects: &[bool],
) -> (Occupancy, usize) {
    let pairs: Vec<(&Silhouette, &Silhouette)> =
        all.iter().zip(sure).filter_map(|(a, s)| a.as_ref().zip(s.as_ref())).collect();
    let keep: Vec<bool> = occ
        .cells
        .par_iter()
        .enumerate()
        .map(|(k, c)| {
            if (table && c.min.z > SHADOW_HULL_HEIGHT) || objects.get(k).copied().unwrap_or(false) {
                return true;
            }
            let (mut sure_views, mut shadow_views) = (0, 0);
            for (a, s) in &pairs {
                // One footprint per view, both tables read on it.
                let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(a, c, margin_px) else { continue };
                if s.counts(i0, j0, i1, j1).foreground() > 0 {
                    sure_views += 1;
                    if sure_views >= SURE_VIEWS {
                        return true;
                    }
                } else if a.counts(i0, j0, i1, j1).foreground() > 0 {
                    shadow_views += 1;
                }
            }
            sure_views > 0 && sure_views >= shadow_views
        })
        .collect();
    let mut out = occ.clone();
    out.cells = occ.cells.iter().zip(&keep).filter(|(_, k)| **k).map(|(c, _)| *c).collect();
    let dropped = occ.cells.len() - out.cells.len();
    (out, dropped)
}

/// Sets the pixels of `mask` valued `from` that the footprint of a cell of `occ` covers in `view`
/// to `to`, and every other `from` pixel to 0; returns how many became `to`. `view` must be the
/// silhouette of this view's camera (its tables are not read).
pub fn cover(occ: &Occupancy, view: &Silhouette, mask: &mut GrayImage, from: u8, to: u8, margin_px: f64) -> u64 {
    let w = mask.width() as usize;
    let raw: &mut [u8] = mask;
    // The box of the `from` pixels: a cell whose footprint misses it is skipped after projecting
    // its centre.
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for (k, _) in raw.iter().enumerate().filter(|(_, p)| **p == from) {
        let (i, j) = ((k % w) as f64, (k / w) as f64);
        lo = [lo[0].min(i), lo[1].min(j)];
        hi = [hi[0].max(i), hi[1].max(j)];
    }
    if lo[0] > hi[0] {
        return 0;
    }
    let cam = view.camera();
    let focal = cam.fx.max(cam.fy);
    let mut covered = 0;
    for c in &occ.cells {
        let centre = c.centre();
        if let Projected::Pixel([u, v]) = project(view, &centre) {
            // A bound on the footprint's half-side: the cell's half-diagonal at its centre's
            // depth, twice over for the lens and the margin.
            let r = 2.0 * (0.87 * c.size * focal / cam.world_to_camera(&centre).z + margin_px) + 1.0;
            if u + r < lo[0] || u - r > hi[0] || v + r < lo[1] || v - r > hi[1] {
                continue;
            }
        }
        let Footprint::Pixels { i0, j0, i1, j1, .. } = footprint(view, c, margin_px) else { continue };
        for j in j0..=j1 {
            for p in raw.get_mut(j * w + i0..=j * w + i1).into_iter().flatten() {
                if *p == from {
                    *p = to;
                    covered += 1;
                }
            }
        }
    }
    for p in raw.iter_mut().filter(|p| **p == from) {
        *p = 0;
    }
    covered
}

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
        let cell = Cell { min: Point3::new(-0.005, -0.005, 0.0), size: 0.01, hand: true, scalpel: false, solid: true };
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
    fn a_cell_seen_only_as_shadow_goes_unless_it_is_known_to_be_an_object() {
        let (camera, occ) = scene();
        let all = Silhouette::new(&camera, &GrayImage::from_pixel(200, 200, Luma([255])));
        let sure = Silhouette::new(&camera, &GrayImage::new(200, 200));
        let (views, sures) = ([Some(all)], [Some(sure)]);
        let (kept, dropped) = keep_supported(&occ, &views, &sures, 0.5, true, &[]);
        assert_eq!((kept.cells.len(), dropped), (0, 1), "seen as shadow by its only view");
        let (kept, dropped) = keep_supported(&occ, &views, &sures, 0.5, true, &[true]);
        assert_eq!((kept.cells.len(), dropped), (1, 0), "marked as an object (the tracked tool's)");
        let (kept, _) = keep_supported(&occ, &views, &sures, 0.5, true, &[false]);
        assert!(kept.cells.is_empty(), "a mark of false keeps nothing");
        // Seen as sure foreground, it stays whatever the marks say.
        let sure = Silhouette::new(&camera, &GrayImage::from_pixel(200, 200, Luma([255])));
        let (kept, _) = keep_supported(&occ, &views, &[Some(sure)], 0.5, true, &[]);
        assert_eq!(kept.cells.len(), 1);
    }
}
