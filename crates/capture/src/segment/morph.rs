//! Morphological clean-up of label images on plain byte buffers (row-major, `w * h`).
//!
//! Written here rather than with OpenCV's `morphologyEx` because the passes carry the labels
//! along, work in the segmenter's reusable buffers without Mat copies, and skip rows without
//! foreground (most rows of a view: the hand and scalpel are small), which OpenCV cannot know;
//! `examples/segment_bench.rs` times both. Every pass is written as slice zips that vectorize.
//! Non-zero is foreground. Dilation takes the maximum, so with the segmenter's working encoding
//! (unknown < hand < scalpel) a thin blade is never swallowed by the hand around it.
//!
//! `active[y]` says whether row y may hold foreground. A row marked inactive counts as all zero
//! and its bytes are left as they were (never read): zeroing them would cost more than the
//! passes themselves on a mostly empty view.

/// Keeps a foreground pixel only if at least `min` of its 8 neighbours are foreground: removes
/// isolated noise pixels while keeping one-pixel-wide lines (two neighbours each). Fills
/// `active_out` for `dst`.
#[allow(clippy::too_many_arguments)] // buffers of one pass, kept apart for the borrow checker
pub(crate) fn neighbour_filter(
    src: &[u8],
    dst: &mut [u8],
    w: usize,
    min: u8,
    active: &[bool],
    active_out: &mut [bool],
    vsum: &mut Vec<u8>,
) {
    let h = active.len();
    vsum.clear();
    vsum.resize(w, 0);
    for y in 0..h {
        active_out[y] = active[y];
        if !active[y] {
            continue;
        }
        let out = &mut dst[y * w..(y + 1) * w];
        if min == 0 {
            out.copy_from_slice(&src[y * w..(y + 1) * w]);
            continue;
        }
        let row = &src[y * w..(y + 1) * w];
        // vsum[x] = foreground count in column x over rows y-1..=y+1.
        for (v, &m) in vsum.iter_mut().zip(row) {
            *v = u8::from(m != 0);
        }
        if y > 0 && active[y - 1] {
            for (v, &a) in vsum.iter_mut().zip(&src[(y - 1) * w..y * w]) {
                *v += u8::from(a != 0);
            }
        }
        if y + 1 < h && active[y + 1] {
            for (v, &b) in vsum.iter_mut().zip(&src[(y + 1) * w..(y + 2) * w]) {
                *v += u8::from(b != 0);
            }
        }
        let keep = |count: u8, m: u8| if count >= min { m } else { 0 };
        if w >= 2 {
            // Interior: neighbours = vsum[x-1] + vsum[x] + vsum[x+1] - self.
            for ((((o, &m), &l), &c), &r) in
                out[1..w - 1].iter_mut().zip(&row[1..w - 1]).zip(&vsum[..w - 2]).zip(&vsum[1..w - 1]).zip(&vsum[2..])
            {
                *o = keep(l + c + r - u8::from(m != 0), m);
            }
            out[0] = keep(vsum[0] + vsum[1] - u8::from(row[0] != 0), row[0]);
            out[w - 1] = keep(vsum[w - 2] + vsum[w - 1] - u8::from(row[w - 1] != 0), row[w - 1]);
        } else if w == 1 {
            out[0] = keep(vsum[0] - u8::from(row[0] != 0), row[0]);
        }
        active_out[y] = any(out);
    }
}

/// Whether a row holds any non-zero byte.
#[inline]
pub(crate) fn any(row: &[u8]) -> bool {
    row.iter().fold(0u8, |a, &v| a | v) != 0
}

/// Grey dilation (maximum) over a (2r+1)² square; pixels outside the image do not count.
#[allow(clippy::too_many_arguments)] // buffers of one pass, kept apart for the borrow checker
pub(crate) fn dilate_max(
    src: &[u8],
    dst: &mut [u8],
    w: usize,
    r: usize,
    active: &[bool],
    active_out: &mut [bool],
    tmp: &mut Vec<u8>,
) {
    let h = active.len();
    // Rows of `tmp` are written before they are read; only its length matters.
    tmp.resize(w * h, 0);
    for y in 0..h {
        if active[y] {
            horizontal(&mut tmp[y * w..(y + 1) * w], &src[y * w..(y + 1) * w], r, u8::max);
        }
    }
    for y in 0..h {
        let window = y.saturating_sub(r)..(y + r + 1).min(h);
        let out = &mut dst[y * w..(y + 1) * w];
        let mut rows = window.filter(|&yy| active[yy]);
        let Some(first) = rows.next() else {
            active_out[y] = false;
            continue;
        };
        out.copy_from_slice(&tmp[first * w..(first + 1) * w]);
        for yy in rows {
            for (o, &s) in out.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *o = (*o).max(s);
            }
        }
        active_out[y] = true;
    }
}

/// Erosion (minimum) over a (2r+1)² square; pixels outside the image do not count (no erosion
/// from the image border). On a label image, `dst != 0` is the binary erosion of `src != 0`.
#[allow(clippy::too_many_arguments)] // buffers of one pass, kept apart for the borrow checker
pub(crate) fn erode_min(
    src: &[u8],
    dst: &mut [u8],
    w: usize,
    r: usize,
    active: &[bool],
    active_out: &mut [bool],
    tmp: &mut Vec<u8>,
) {
    let h = active.len();
    // Rows of `tmp` are written before they are read; only its length matters.
    tmp.resize(w * h, 0);
    for y in 0..h {
        if active[y] {
            horizontal(&mut tmp[y * w..(y + 1) * w], &src[y * w..(y + 1) * w], r, u8::min);
        }
    }
    for y in 0..h {
        let window = y.saturating_sub(r)..(y + r + 1).min(h);
        let out = &mut dst[y * w..(y + 1) * w];
        // An inactive row in the window is all zero, and so is the minimum.
        if !window.clone().all(|yy| active[yy]) {
            active_out[y] = false;
            continue;
        }
        out.copy_from_slice(&tmp[y * w..(y + 1) * w]);
        for yy in window.filter(|&yy| yy != y) {
            for (o, &s) in out.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *o = (*o).min(s);
            }
        }
        active_out[y] = any(out);
    }
}

/// `row[x] = op over src[x-r..=x+r]` (clamped to the row).
fn horizontal<F: Fn(u8, u8) -> u8 + Copy>(row: &mut [u8], src: &[u8], r: usize, op: F) {
    row.copy_from_slice(src);
    let w = row.len();
    for d in 1..=r.min(w.saturating_sub(1)) {
        for (o, &s) in row[..w - d].iter_mut().zip(&src[d..]) {
            *o = op(*o, s);
        }
        for (o, &s) in row[d..].iter_mut().zip(&src[..w - d]) {
            *o = op(*o, s);
        }
    }
}
