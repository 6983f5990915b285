//! Cast shadows: a pixel darker than its background with its chromaticity unchanged is a shadow
//! on the background, or a dark object of the background's colour; one view cannot tell which.
//! The hull of all views can: carved with such pixels counted as foreground, a cell of a real
//! object is seen as sure foreground by most views (the object against other backgrounds, or in
//! front of the hand), while a cell of a shadow on the table is seen as shadow by most views, and
//! as sure foreground only by those where the hand that casts it stands in front of it.
//! [`keep_supported`] keeps the cells that at least as many views see as sure foreground as see
//! only shadow there; [`cover`] then turns a view's shadow pixels that the kept cells cover into
//! foreground (the rest go back to background).

use image::GrayImage;
use rayon::prelude::*;

use crate::carve::{Footprint, footprint, footprint_counts};
use crate::{Occupancy, Silhouette};

/// The cells of `occ` (carved from `all`, the views' silhouettes with the possible shadows as
/// foreground) that at least as many views see as sure foreground (foreground in their footprint
/// in `sure`, the silhouettes with the possible shadows left out) as see only shadow (foreground
/// in `all` but none in `sure`), with one view at least; and how many cells went.
pub fn keep_supported(
    occ: &Occupancy,
    all: &[Option<Silhouette>],
    sure: &[Option<Silhouette>],
    margin_px: f64,
) -> (Occupancy, usize) {
    let pairs: Vec<(&Silhouette, &Silhouette)> =
        all.iter().zip(sure).filter_map(|(a, s)| a.as_ref().zip(s.as_ref())).collect();
    let keep: Vec<bool> = occ
        .cells
        .par_iter()
        .map(|c| {
            let (mut sure_views, mut shadow_views) = (0, 0);
            for (a, s) in &pairs {
                if footprint_counts(s, c, margin_px).is_some_and(|n| n.foreground() > 0) {
                    sure_views += 1;
                } else if footprint_counts(a, c, margin_px).is_some_and(|n| n.foreground() > 0) {
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
    if !raw.contains(&from) {
        return 0;
    }
    let mut covered = 0;
    for c in &occ.cells {
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
