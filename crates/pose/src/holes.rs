//! Filling the small holes of a label mask: background pixels that the foreground encloses
//! (4-connected background, so a hole touches no background outside it even at a corner) in
//! components of at most a given area.
//!
//! A tool whose colour matches the background's somewhere (a grey handle over a grey table, a
//! steel blade reflecting it) leaves holes in its silhouette, and every hole's rim is an outline
//! against the background that no pose of the tool explains: the fit's evidence
//! ([`crate::ToolLabeller`]) fills them before its outline is sampled.
//!
//! A hole is made of *interior runs* alone: in a row, the background between its first and last
//! foreground pixel. Runs of neighbouring rows that share a column are one component; a component
//! leaks where a run has, directly above or below it, a background pixel outside that row's first
//! and last foreground pixel, or lies in the first or last row.

/// One interior run: its row and its columns `a..b`, and its component (union-find parent).
#[derive(Debug, Clone, Copy)]
struct Run {
    y: usize,
    a: usize,
    b: usize,
    parent: usize,
}

fn root(runs: &mut [Run], mut i: usize) -> usize {
    while runs[i].parent != i {
        let up = runs[runs[i].parent].parent;
        runs[i].parent = up;
        i = up;
    }
    i
}

/// Fills the holes of at most `max_area` pixels in the `w`×`h` window at (`x0`, `y0`) of `buf`
/// (row stride `stride`; zero is background, and so is everything outside the window) with
/// `fill`; returns the pixels filled.
pub(crate) fn fill_holes(
    buf: &mut [u8],
    stride: usize,
    (x0, y0, w, h): (usize, usize, usize, usize),
    (max_area, fill): (usize, u8),
) -> usize {
    if max_area == 0 || w < 3 || h < 3 {
        return 0;
    }
    let mut runs = Vec::new();
    // Per row: its first and last foreground column (`None` for a row without any).
    let mut rows: Vec<Option<(usize, usize)>> = Vec::with_capacity(h);
    let row = |y: usize| (y0 + y) * stride + x0..(y0 + y) * stride + x0 + w;
    for y in 0..h {
        let r = &buf[row(y)];
        let span = r.iter().position(|&p| p != 0).zip(r.iter().rposition(|&p| p != 0));
        if let Some((f, l)) = span {
            let mut i = f + 1;
            while i < l {
                match r[i..l].iter().position(|&p| p == 0) {
                    None => break,
                    Some(s) => {
                        let a = i + s;
                        let b = a + r[a..l].iter().position(|&p| p != 0).unwrap_or(l - a);
                        runs.push(Run { y, a, b, parent: runs.len() });
                        i = b;
                    }
                }
            }
        }
        rows.push(span);
    }
    if runs.is_empty() {
        return 0;
    }
    // Runs of neighbouring rows sharing a column are one component.
    let mut upper = 0;
    for i in 0..runs.len() {
        let Run { y, a, b, .. } = runs[i];
        if y == 0 {
            continue;
        }
        while upper < runs.len() && runs[upper].y < y - 1 {
            upper += 1;
        }
        let mut j = upper;
        while j < runs.len() && runs[j].y == y - 1 {
            if runs[j].a < b && a < runs[j].b {
                let (ri, rj) = (root(&mut runs, i), root(&mut runs, j));
                if ri != rj {
                    runs[ri.max(rj)].parent = ri.min(rj);
                }
            }
            j += 1;
        }
    }
    // Per component root: its area and whether it leaks.
    let mut area = vec![(0, false); runs.len()];
    for i in 0..runs.len() {
        let Run { y, a, b, .. } = runs[i];
        let outside = |n: Option<usize>| match n.and_then(|n| rows.get(n)) {
            // A row without foreground, or beyond the window, is background outside any hole.
            None | Some(None) => true,
            Some(Some((f, l))) => a < *f || b > l + 1,
        };
        let leaks = y == 0 || y + 1 == h || outside(y.checked_sub(1)) || outside(Some(y + 1));
        let r = root(&mut runs, i);
        area[r].0 += b - a;
        area[r].1 |= leaks;
    }
    let mut filled = 0;
    for i in 0..runs.len() {
        let r = root(&mut runs, i);
        let (size, leaks) = area[r];
        if leaks || size > max_area {
            continue;
        }
        let Run { y, a, b, .. } = runs[i];
        let start = row(y).start;
        buf[start + a..start + b].fill(fill);
        filled += b - a;
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(rows: &[&str]) -> (Vec<u8>, usize, usize) {
        let w = rows[0].len();
        let buf = rows.iter().flat_map(|r| r.bytes().map(|c| if c == b'#' { 255 } else { 0 })).collect();
        (buf, w, rows.len())
    }

    fn show(buf: &[u8], w: usize) -> Vec<String> {
        buf.chunks(w).map(|r| r.iter().map(|&p| if p == 0 { '.' } else { '#' }).collect()).collect()
    }

    fn filled(rows: &[&str], max_area: usize) -> Vec<String> {
        let (mut buf, w, h) = parse(rows);
        fill_holes(&mut buf, w, (0, 0, w, h), (max_area, 255));
        show(&buf, w)
    }

    #[test]
    fn fills_enclosed_background_and_leaves_what_reaches_outside() {
        let rows = [
            "..........",
            ".#######..",
            ".#..#..#..",
            ".#..#..#..",
            ".####.##..",
            ".#......#.",
            ".########.",
            "..........",
        ];
        // The left hole (4 px) is enclosed; the right one opens at (5,4) into the lower one,
        // which is enclosed too: together 4 + 1 + 6 = 11 px.
        assert_eq!(
            filled(&rows, 100),
            [
                "..........",
                ".#######..",
                ".#######..",
                ".#######..",
                ".#######..",
                ".########.",
                ".########.",
                "..........",
            ]
        );
        // At most 10 px: only the left hole; at most 11, both.
        assert_eq!(filled(&rows, 10)[2], ".####..#..");
        assert_eq!(filled(&rows, 10)[5], ".#......#.");
        assert_eq!(filled(&rows, 11)[5], ".########.");
    }

    #[test]
    fn a_gap_open_at_a_corner_or_an_edge_of_the_window_is_no_hole() {
        // The gap touches the background above through (3,0)'s row: it leaks.
        let open_above = ["###.###", "#.....#", "#######"];
        assert_eq!(filled(&open_above, 100), open_above);
        // Diagonal contact with the outside does not leak (4-connected background): the hole at
        // (2,2) touches (3,1) and (3,3) at corners only.
        let diagonal = ["......", ".##...", ".#.#..", ".##...", "......"];
        assert_eq!(filled(&diagonal, 100)[2], ".###..");
        // A run in the window's last row leaks.
        let last = ["#####", "#...#", "#...#"];
        assert_eq!(filled(&last, 100), last);
    }

    #[test]
    fn fills_only_inside_its_window() {
        let w = 8;
        let mut buf = vec![0u8; w * 6];
        // A ring of label 7 at columns 2..6, rows 1..5 of the buffer; the window is columns 1..7,
        // rows 0..6.
        for y in 1..5 {
            for x in 2..6 {
                if y == 1 || y == 4 || x == 2 || x == 5 {
                    buf[y * w + x] = 7;
                }
            }
        }
        let n = fill_holes(&mut buf, w, (1, 0, 6, 6), (10, 9));
        assert_eq!(n, 4);
        assert_eq!(&buf[2 * w..3 * w], &[0, 0, 7, 9, 9, 7, 0, 0]);
        // A window that cuts the ring: what it holds of the hole reaches its edge, and leaks.
        let mut cut = buf.clone();
        cut[2 * w + 3..2 * w + 5].fill(0);
        assert_eq!(fill_holes(&mut cut, w, (1, 0, 6, 3), (10, 9)), 0);
    }

    /// The holes by a flood fill from the window's border over 4-connected background, each
    /// remaining component measured: what `fill_holes` must fill.
    fn flood_filled(buf: &[u8], w: usize, h: usize, max_area: usize) -> Vec<u8> {
        let mut comp = vec![usize::MAX; w * h];
        let mut out = buf.to_vec();
        let mut next = 0;
        for start in 0..w * h {
            if buf[start] != 0 || comp[start] != usize::MAX {
                continue;
            }
            let (mut stack, mut members, mut leaks) = (vec![start], Vec::new(), false);
            comp[start] = next;
            while let Some(k) = stack.pop() {
                members.push(k);
                let (x, y) = (k % w, k / w);
                leaks |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
                let mut push = |n: usize| {
                    if buf[n] == 0 && comp[n] == usize::MAX {
                        comp[n] = next;
                        stack.push(n);
                    }
                };
                if x > 0 {
                    push(k - 1);
                }
                if x + 1 < w {
                    push(k + 1);
                }
                if y > 0 {
                    push(k - w);
                }
                if y + 1 < h {
                    push(k + w);
                }
            }
            if !leaks && members.len() <= max_area {
                for k in members {
                    out[k] = 5;
                }
            }
            next += 1;
        }
        out
    }

    #[test]
    fn fills_what_a_flood_fill_from_the_border_leaves_on_random_masks() {
        let mut seed = 11u64;
        let mut next = |n: usize| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) % n as u64) as usize
        };
        let mut filled_any = 0;
        for round in 0..300 {
            let (w, h) = (3 + next(20), 3 + next(20));
            // Foreground at a density that leaves holes of every size, some touching the border.
            let density = 30 + next(60);
            let buf: Vec<u8> = (0..w * h).map(|_| if next(100) < density { 1 + next(3) as u8 } else { 0 }).collect();
            let max_area = next(12);
            let expected = flood_filled(&buf, w, h, max_area);
            let mut got = buf.clone();
            let n = fill_holes(&mut got, w, (0, 0, w, h), (max_area, 5));
            assert_eq!(got, expected, "round {round}: {w}x{h}, at most {max_area}");
            assert_eq!(n, got.iter().zip(&buf).filter(|(a, b)| a != b).count());
            filled_any += usize::from(n > 0);
        }
        assert!(filled_any > 50, "{filled_any} rounds filled a hole");
    }
}
