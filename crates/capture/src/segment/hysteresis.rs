//! Hysteresis: the weak pixels of a window's foreground test ([`ENC_WEAK`], [`ENC_WEAK_DARK`];
//! see [`super::SegmentParams::weak_share`]) that touch sure foreground, 8-connected through other
//! weak pixels, join it; with possible shadows asked for, the weak dark ones left that touch a
//! possible shadow join it; the rest go back to background.

use super::background::{RowKinds, SURE_BIT, WEAK_BIT};
use super::classes::ClassLut;
use super::{ENC_SCALPEL, ENC_SHADOW, ENC_UNKNOWN, ENC_WEAK, ENC_WEAK_DARK};

/// Where the window lies in its image: the image's raw RGB bytes, its width, and the window's
/// first column and row; the background model's mean image (raw RGB, the image's size) and the
/// image's exposure gain against it.
pub(crate) struct ImageWindow<'a> {
    pub raw: &'a [u8],
    pub full_w: usize,
    pub x0: usize,
    pub y0: usize,
    pub background: &'a [u8],
    pub gain: f32,
}

impl ImageWindow<'_> {
    /// The first byte of window pixel `i`'s colour (`w` the window's width).
    fn at(&self, i: usize, w: usize) -> usize {
        3 * ((self.y0 + i / w) * self.full_w + self.x0 + i % w)
    }

    /// Whether window pixel `j`'s colour lies nearer to pixel `i`'s (L1) than to its own
    /// background's: a pixel of the object `i` belongs to, not a streak of a textured table beside
    /// it.
    fn like(&self, j: usize, i: usize, w: usize) -> bool {
        let (a, b) = (self.at(j, w), self.at(i, w));
        let (mut to_object, mut to_background) = (0.0f32, 0.0f32);
        for c in 0..3 {
            let p = f32::from(self.raw[a + c]);
            to_object += (p - f32::from(self.raw[b + c])).abs();
            to_background += (p - self.gain * f32::from(self.background[a + c])).abs();
        }
        to_object < to_background
    }
}

/// Which rows of a window may hold what.
pub(crate) struct Rows<'a> {
    /// Rows that may hold anything but background; brought up to date.
    pub active: &'a mut [bool],
    /// What each row may hold.
    pub kinds: &'a [RowKinds],
}

/// Resolves the weak pixels of `labels` (the window's encoded labels, `w` wide; `rows` says
/// which rows may hold any, and which anything, brought up to date): a weak pixel
/// 8-connected to an object pixel (unknown, hand or scalpel) with two or more object pixels
/// beside it, through weak pixels that join too, each one's colour nearer to the pixel it is
/// reached from than to its own background's ([`ImageWindow::like`]), becomes an object of its
/// colour's class ([`ENC_WEAK`]) or a possible shadow
/// ([`ENC_WEAK_DARK`], with `shadows`; without, it stays background and connects nothing); every
/// other weak pixel becomes background, but that with `shadows` the weak dark ones the objects
/// did not reach that touch a possible shadow ([`ENC_SHADOW`] with two or more such or object
/// pixels beside it), through each other, by the same colour rule, become possible shadows.
/// Except the rim: a joined pixel next to a sure one (of its 8; a possible shadow for those that
/// joined one) and to background (of its 4) goes back to background, for every object's edge
/// pixels, partly covered, are weak and would grow each silhouette by a pixel (a blade 1-3 pixels wide
/// by half or more; the closing bridges the one-pixel gap this leaves where a blade goes on as
/// weak pixels beyond its sure ones). `stack` is scratch. Returns how many pixels joined.
pub(crate) fn grow_into_weak(
    labels: &mut [u8],
    rows: Rows,
    w: usize,
    image: &ImageWindow,
    lut: &ClassLut,
    shadows: bool,
    stack: &mut Vec<u32>,
) -> usize {
    if w == 0 {
        return 0;
    }
    let h = labels.len() / w;
    let Rows { active, kinds } = rows;
    let weak_row = |y: usize| kinds[y].bits & WEAK_BIT != 0;
    if !(0..h).any(weak_row) {
        return 0;
    }
    // A weak pixel's code where it joins, marked JOINED; 0 where it cannot join.
    let joined = |labels: &[u8], i: usize| -> u8 {
        if labels[i] == ENC_WEAK {
            let k = image.at(i, w);
            lut.get(image.raw[k], image.raw[k + 1], image.raw[k + 2]) | JOINED
        } else if shadows {
            ENC_SHADOW | JOINED
        } else {
            0
        }
    };
    // The 4-neighbours of pixel `i`.
    let sides = |i: usize| {
        let (x, y) = (i % w, i / w);
        [(x > 0).then(|| i - 1), (x + 1 < w).then(|| i + 1), (y > 0).then(|| i - w), (y + 1 < h).then(|| i + w)]
            .into_iter()
            .flatten()
    };
    // `stack` ends up holding every joined pixel: a queue read from `next`.
    stack.clear();
    // Weak pixel `i`, whose colour the caller found nearer to the pixel it is reached from than to
    // its background's ([`ImageWindow::like`]), joins.
    let join = |labels: &mut [u8], i: usize, stack: &mut Vec<u32>| {
        let v = joined(labels, i);
        labels[i] = v;
        if v != 0 {
            stack.push(i as u32);
        }
    };
    // Seeds: weak pixels next to an object pixel that has object pixels of its own beside it (a
    // lone pixel of noise, or a pair, seeds nothing: over a textured table its weak neighbours
    // would make a speck that the clean-up keeps). Only the columns within a pixel of a sure
    // object pixel in the rows around are looked at (as the foreground test bounds them).
    let span = |y: usize| {
        let (from, to) = kinds[y].sure;
        (kinds[y].bits & SURE_BIT != 0 && from < to).then(|| (from as usize, (to as usize - 1).min(w - 1)))
    };
    let seeds = |labels: &[u8], j: usize| {
        is_object(labels[j]) && count_around(labels, w, h, j, SEED_NEIGHBOURS, is_object) >= SEED_NEIGHBOURS
    };
    for y in (0..h).filter(|&y| weak_row(y)) {
        let rows = y.saturating_sub(1)..=(y + 1).min(h - 1);
        let Some((a, b)) = rows.filter_map(span).reduce(|(a, b), (c, d)| (a.min(c), b.max(d))) else {
            continue;
        };
        for i in y * w + a.saturating_sub(1)..=y * w + (b + 1).min(w - 1) {
            if !is_weak(labels[i]) {
                continue;
            }
            if first_around(w, h, i, |j| seeds(labels, j) && image.like(i, j, w)).is_some() {
                join(labels, i, stack);
            }
        }
    }
    let mut next = 0;
    spread(labels, w, stack, &mut next, |labels, j, i| is_weak(labels[j]) && image.like(j, i, w), join);
    // Then, with shadows, the weak dark pixels the objects left that touch a possible shadow join
    // it, through each other: a dull tool of the table's shade, darker than the table by about the
    // shadow tolerance, is a possible shadow in patches and weak dark between them and along its
    // thin end (random:2711 in random:2713); the hull tells it from a shadow on the table. Not
    // the weak pixels of another colour: over a textured mat they grew the shadows beside a tool
    // into its evidence (random:2801 in random:2803, four cameras: 35 -> 6 frame sets trusted).
    let from_objects = stack.len();
    if shadows {
        let shadow_seeds = |labels: &[u8], j: usize| {
            labels[j] == ENC_SHADOW
                && count_around(labels, w, h, j, SEED_NEIGHBOURS, |v| v == ENC_SHADOW || is_object(v))
                    >= SEED_NEIGHBOURS
        };
        let join_shadow = |labels: &mut [u8], i: usize, stack: &mut Vec<u32>| {
            labels[i] = ENC_SHADOW | JOINED;
            stack.push(i as u32);
        };
        // Only the weak rows with a possible shadow in or beside them are looked at (a joined pixel
        // is marked, so the rows read as the foreground test left them).
        let near_shadow =
            |labels: &[u8], y: usize| labels[y.saturating_sub(1) * w..((y + 2).min(h)) * w].contains(&ENC_SHADOW);
        for y in (0..h).filter(|&y| weak_row(y)) {
            if !near_shadow(labels, y) {
                continue;
            }
            for i in y * w..(y + 1) * w {
                if labels[i] == ENC_WEAK_DARK
                    && first_around(w, h, i, |j| shadow_seeds(labels, j) && image.like(i, j, w)).is_some()
                {
                    join_shadow(labels, i, stack);
                }
            }
        }
        spread(
            labels,
            w,
            stack,
            &mut next,
            |labels, j, i| labels[j] == ENC_WEAK_DARK && image.like(j, i, w),
            join_shadow,
        );
    }
    // The rim, marked first (the test reads every pixel as it was after the growth): next to what
    // it joined (an object; a possible shadow for those that joined one) and to background.
    let mut grown = stack.len();
    for (n, &i) in stack.iter().enumerate() {
        let i = i as usize;
        let sure = |v: u8| is_object(v) || (n >= from_objects && v == ENC_SHADOW);
        if first_around(w, h, i, |j| sure(labels[j])).is_some()
            && sides(i).any(|j| labels[j] == 0 || is_weak(labels[j]))
        {
            labels[i] |= RIM;
            grown -= 1;
        }
    }
    // Weak pixels and the rim to background, the joined ones unmarked: without branches.
    for y in (0..h).filter(|&y| weak_row(y)) {
        let row = &mut labels[y * w..(y + 1) * w];
        let mut any = 0;
        for v in row.iter_mut() {
            let gone = (*v & RIM != 0) | (*v == ENC_WEAK) | (*v == ENC_WEAK_DARK);
            *v = if gone { 0 } else { *v & !JOINED };
            any |= *v;
        }
        active[y] = any != 0;
    }
    grown
}

/// Grows what joined: for each pixel of `stack` from `*next` on (a queue, `w` the window's width),
/// every 8-neighbour `j` that `may_join(labels, j, i)` admits (`i` the pixel it is reached from)
/// is joined by `join`, which pushes what it joins onto `stack`.
fn spread(
    labels: &mut [u8],
    w: usize,
    stack: &mut Vec<u32>,
    next: &mut usize,
    may_join: impl Fn(&[u8], usize, usize) -> bool,
    join: impl Fn(&mut [u8], usize, &mut Vec<u32>),
) {
    let h = labels.len() / w;
    while let Some(&i) = stack.get(*next) {
        *next += 1;
        let (x, y) = (i as usize % w, i as usize / w);
        for v in y.saturating_sub(1)..=(y + 1).min(h - 1) {
            for j in v * w + x.saturating_sub(1)..=v * w + (x + 1).min(w - 1) {
                if may_join(labels, j, i as usize) {
                    join(labels, j, stack);
                }
            }
        }
    }
}

/// The first of the 8-neighbours of pixel `i` of a window `w` x `h` that passes `test` (given its
/// index).
#[inline]
fn first_around(w: usize, h: usize, i: usize, test: impl Fn(usize) -> bool) -> Option<usize> {
    let (x, y) = (i % w, i / w);
    for v in y.saturating_sub(1)..=(y + 1).min(h - 1) {
        for j in v * w + x.saturating_sub(1)..=v * w + (x + 1).min(w - 1) {
            if j != i && test(j) {
                return Some(j);
            }
        }
    }
    None
}

/// How many of the 8-neighbours of pixel `i` of a window `w` x `h` have a value that passes
/// `test`, counted up to `enough`.
#[inline]
fn count_around(labels: &[u8], w: usize, h: usize, i: usize, enough: usize, test: impl Fn(u8) -> bool) -> usize {
    let (x, y) = (i % w, i / w);
    let mut n = 0;
    for v in y.saturating_sub(1)..=(y + 1).min(h - 1) {
        for j in v * w + x.saturating_sub(1)..=v * w + (x + 1).min(w - 1) {
            if j != i && test(labels[j]) {
                n += 1;
                if n >= enough {
                    return n;
                }
            }
        }
    }
    n
}

/// Sure object pixels (of 8) a sure object pixel needs beside it to seed the hysteresis.
const SEED_NEIGHBOURS: usize = 2;

/// Marks a pixel that joined the foreground, while the weak pixels are resolved.
const JOINED: u8 = 0x08;
/// Marks a joined pixel of the rim, while the weak pixels are resolved.
const RIM: u8 = 0x10;

fn is_weak(v: u8) -> bool {
    v == ENC_WEAK || v == ENC_WEAK_DARK
}

/// A sure object pixel (unknown, hand or scalpel; not one that joined).
fn is_object(v: u8) -> bool {
    (ENC_UNKNOWN..=ENC_SCALPEL).contains(&v)
}

#[cfg(test)]
mod tests {
    use super::super::ENC_HAND as ENC_HAND_FOR_TEST;
    use super::*;
    use hullcut_dataset::label;

    fn lut() -> ClassLut {
        ClassLut::from_fn(|[r, _, _]| if r > 100 { label::SCALPEL } else { label::HAND }, super::super::encode)
    }

    /// Grid from rows of characters: '.' background, 'S' sure (unknown), 'w' weak, 'd' weak dark,
    /// 's' possible shadow.
    fn grid(rows: &[&str]) -> (Vec<u8>, usize) {
        let w = rows[0].len();
        let v = rows
            .iter()
            .flat_map(|r| {
                r.chars().map(|c| match c {
                    'S' => ENC_UNKNOWN,
                    'w' => ENC_WEAK,
                    'd' => ENC_WEAK_DARK,
                    's' => ENC_SHADOW,
                    _ => 0,
                })
            })
            .collect();
        (v, w)
    }

    /// Each row's kinds, as the foreground test says them; `extra` rows say both.
    fn kinds_of(labels: &[u8], w: usize, extra: impl Fn(usize) -> bool) -> Vec<RowKinds> {
        labels
            .chunks(w)
            .enumerate()
            .map(|(y, r)| {
                let weak = r.iter().any(|&v| is_weak(v)) || extra(y);
                let from = r.iter().position(|&v| is_object(v));
                let to = r.iter().rposition(|&v| is_object(v)).map(|x| x + 1);
                let sure = match (from, to) {
                    _ if extra(y) => (0, w as u32),
                    (Some(a), Some(b)) => (a as u32, b as u32),
                    _ => (0, 0),
                };
                let bits = (u8::from(weak) * WEAK_BIT) | (u8::from(sure.0 < sure.1) * SURE_BIT);
                RowKinds { bits, sure }
            })
            .collect()
    }

    fn run(rows: &[&str], shadows: bool, colour: [u8; 3]) -> (Vec<u8>, Vec<bool>, usize) {
        let (mut labels, w) = grid(rows);
        let h = rows.len();
        let raw: Vec<u8> = (0..w * h).flat_map(|_| colour).collect();
        let mut active: Vec<bool> = labels.chunks(w).map(|r| r.iter().any(|&v| v != 0)).collect();
        let kinds = kinds_of(&labels, w, |_| false);
        // A white background: every colour the tests use lies nearer to its neighbours'.
        let white = vec![255; raw.len()];
        let image = ImageWindow { raw: &raw, full_w: w, x0: 0, y0: 0, background: &white, gain: 1.0 };
        let rows = Rows { active: &mut active, kinds: &kinds };
        let n = grow_into_weak(&mut labels, rows, w, &image, &lut(), shadows, &mut Vec::new());
        (labels, active, n)
    }

    #[test]
    fn weak_pixels_join_the_foreground_they_touch_through_each_other_but_its_rim_does_not() {
        let rows = ["SSSS.", "SwwS.", "SSSS.", "..w..", ".....", "ww..."];
        let (labels, active, n) = run(&rows, true, [200, 0, 0]);
        let (mut expected, _) = grid(&["SSSS.", "S..S.", "SSSS.", ".....", ".....", "....."]);
        expected[6] = ENC_SCALPEL;
        expected[7] = ENC_SCALPEL;
        assert_eq!(labels, expected);
        assert_eq!(n, 2);
        assert_eq!(active, [true, true, true, false, false, false]);
    }

    #[test]
    fn a_weak_blade_beyond_the_sure_one_joins_but_for_its_first_pixel() {
        let (labels, _, n) = run(&["SSSS......", "SSSSwwwww.", "SSSS......"], true, [50, 0, 0]);
        assert_eq!(
            &labels[10..20],
            &[
                ENC_UNKNOWN,
                ENC_UNKNOWN,
                ENC_UNKNOWN,
                ENC_UNKNOWN,
                0,
                ENC_HAND_FOR_TEST,
                ENC_HAND_FOR_TEST,
                ENC_HAND_FOR_TEST,
                ENC_HAND_FOR_TEST,
                0
            ]
        );
        assert_eq!(n, 4);
    }

    #[test]
    fn a_weak_pixel_of_its_backgrounds_colour_does_not_join() {
        // A sure block of one colour; beside it a weak patch of nearly its colour and a weak
        // streak of the table's (a brushed steel table's lines beside a hand).
        let rows = ["SSSS..", "SSSSww", "SSSSww", "SSSSww", "SSSS..", "wwwww."];
        let (mut labels, w) = grid(&rows);
        let h = rows.len();
        let (object, table, gain) = ([200u8, 120, 90], [120u8, 120, 125], 0.9f32);
        let background: Vec<u8> = (0..w * h).flat_map(|_| table).collect();
        let raw: Vec<u8> = (0..w * h)
            .flat_map(|i| match (i % w, i / w) {
                (_, 5) => [114, 110, 116],
                (x, _) if x >= 4 => [190, 118, 92],
                _ => object,
            })
            .collect();
        let mut active: Vec<bool> = labels.chunks(w).map(|r| r.iter().any(|&v| v != 0)).collect();
        let kinds = kinds_of(&labels, w, |_| false);
        let image = ImageWindow { raw: &raw, full_w: w, x0: 0, y0: 0, background: &background, gain };
        let rows = Rows { active: &mut active, kinds: &kinds };
        let n = grow_into_weak(&mut labels, rows, w, &image, &lut(), true, &mut Vec::new());
        // The patch joins but for its rim: (4, 1) and (4, 3) touch the sure block and the
        // background above and below.
        let joined: Vec<usize> = (0..w * h).filter(|&i| labels[i] == ENC_SCALPEL).collect();
        assert_eq!(joined, [w + 5, 2 * w + 4, 2 * w + 5, 3 * w + 5]);
        assert_eq!(n, 4);
        assert!(labels[5 * w..].iter().all(|&v| v == 0), "the streak stays background");
    }

    #[test]
    fn a_lone_sure_pixel_or_pair_seeds_nothing() {
        let rows = [".....", ".www.", ".wSw.", ".wSw.", ".www.", "....."];
        let (labels, active, n) = run(&rows, true, [50, 0, 0]);
        assert_eq!(labels, grid(&[".....", ".....", "..S..", "..S..", ".....", "....."]).0);
        assert_eq!((n, active), (0, vec![false, false, true, true, false, false]));
    }

    #[test]
    fn weak_dark_pixels_join_as_possible_shadows_and_only_when_shadows_are_asked_for() {
        let rows = ["SSSw.", "SdSw.", "SSSw.", "s.d.."];
        let (labels, _, n) = run(&rows, true, [50, 0, 0]);
        let (mut expected, _) = grid(&["SSS..", "S.S..", "SSS..", "s...."]);
        expected[6] = ENC_SHADOW;
        assert_eq!(labels, expected);
        assert_eq!(n, 1);
        let (labels, _, n) = run(&rows, false, [50, 0, 0]);
        expected[6] = 0;
        assert_eq!(labels, expected);
        assert_eq!(n, 0);
    }

    #[test]
    fn weak_dark_pixels_touching_a_possible_shadow_join_it_but_for_its_rim_and_no_other_weak_pixel() {
        // A dull blade: possible shadows in a patch, weak dark pixels beyond it, and a weak one of
        // another colour beyond those.
        let rows = ["sss.....", "sssdddw.", "sss.....", "........"];
        let (labels, _, n) = run(&rows, true, [50, 0, 0]);
        let (mut expected, w) = grid(&["sss.....", "sss.....", "sss.....", "........"]);
        expected[w + 4] = ENC_SHADOW;
        expected[w + 5] = ENC_SHADOW;
        assert_eq!(labels, expected, "the first, beside the patch and the background, is its rim; the weak one stays");
        assert_eq!(n, 2);
        let (labels, _, n) = run(&rows, false, [50, 0, 0]);
        assert_eq!((labels, n), (grid(&["sss.....", "sss.....", "sss.....", "........"]).0, 0));
    }

    #[test]
    fn a_weak_pixel_between_an_object_and_a_possible_shadow_joins_the_object() {
        let rows = ["SSSwsss", "SSSwsss", "SSSwsss"];
        let (labels, _, n) = run(&rows, true, [50, 0, 0]);
        let (mut expected, w) = grid(&rows);
        for y in 0..3 {
            expected[y * w + 3] = ENC_HAND_FOR_TEST;
        }
        assert_eq!((labels, n), (expected, 3));
    }

    /// Against a flood fill written plainly: random grids, every weak pixel's fate.
    #[test]
    fn the_grown_pixels_are_those_a_flood_fill_from_the_objects_then_the_possible_shadows_reaches() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..200 {
            let (w, h) = (1 + (next() % 17) as usize, 1 + (next() % 13) as usize);
            let codes = [0, 0, 0, ENC_UNKNOWN, ENC_WEAK, ENC_WEAK, ENC_WEAK_DARK, ENC_SHADOW];
            let labels: Vec<u8> = (0..w * h).map(|_| codes[(next() % 8) as usize]).collect();
            let shadows = next() % 2 == 0;
            let conducts = |v: u8| v == ENC_WEAK || (shadows && v == ENC_WEAK_DARK);
            let mut reached = vec![false; w * h];
            let sure_beside = |i: usize, sure: &[u8]| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                (-1..=1i64)
                    .flat_map(|a| (-1..=1i64).map(move |b| (x + a, y + b)))
                    .filter(|&(u, v)| (u, v) != (x, y) && u >= 0 && v >= 0 && u < w as i64 && v < h as i64)
                    .filter(|&(u, v)| sure.contains(&labels[v as usize * w + u as usize]))
                    .count()
            };
            let flood = |mut todo: Vec<usize>, reached: &mut Vec<bool>, conducts: &dyn Fn(u8) -> bool| {
                while let Some(i) = todo.pop() {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    for (dx, dy) in (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))) {
                        let (u, v) = (x + dx, y + dy);
                        if u < 0 || v < 0 || u >= w as i64 || v >= h as i64 {
                            continue;
                        }
                        let j = v as usize * w + u as usize;
                        if conducts(labels[j]) && !reached[j] {
                            reached[j] = true;
                            todo.push(j);
                        }
                    }
                }
            };
            flood(
                (0..w * h).filter(|&i| labels[i] == ENC_UNKNOWN && sure_beside(i, &[ENC_UNKNOWN]) >= 2).collect(),
                &mut reached,
                &conducts,
            );
            // With shadows, what the objects left floods from the possible shadows, through the
            // weak dark pixels, as possible shadows.
            let mut shadowed = reached.clone();
            if shadows {
                let seeds = (0..w * h)
                    .filter(|&i| labels[i] == ENC_SHADOW && sure_beside(i, &[ENC_UNKNOWN, ENC_SHADOW]) >= 2)
                    .collect();
                flood(seeds, &mut shadowed, &|v| v == ENC_WEAK_DARK);
            }
            let by_shadow: Vec<bool> = (0..w * h).map(|i| shadowed[i] && !reached[i]).collect();
            let mut out = labels.clone();
            let raw = vec![0u8; 3 * w * h];
            let mut active: Vec<bool> = out.chunks(w).map(|r| r.iter().any(|&v| v != 0)).collect();
            // Rows said to hold what they do not too (the foreground test may say so).
            let extra: Vec<bool> = (0..h).map(|_| next() % 4 == 0).collect();
            let kinds = kinds_of(&out, w, |y| extra[y]);
            // A white background: every colour the tests use lies nearer to its neighbours'.
            let white = vec![255; raw.len()];
            let image = ImageWindow { raw: &raw, full_w: w, x0: 0, y0: 0, background: &white, gain: 1.0 };
            let n = grow_into_weak(
                &mut out,
                Rows { active: &mut active, kinds: &kinds },
                w,
                &image,
                &lut(),
                shadows,
                &mut Vec::new(),
            );
            let around = |i: usize, d: i64| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                (-1..=1)
                    .flat_map(|a| (-1..=1).map(move |b| (a, b)))
                    .filter(move |&(a, b): &(i64, i64)| (a, b) != (0, 0) && a.abs() + b.abs() <= d)
                    .map(move |(a, b)| (x + a, y + b))
                    .filter(|&(u, v)| u >= 0 && v >= 0 && u < w as i64 && v < h as i64)
                    .map(|(u, v)| v as usize * w + u as usize)
            };
            let background = |j: usize| labels[j] == 0 || (is_weak(labels[j]) && !shadowed[j]);
            let rim = |i: usize| {
                let sure = |j: usize| labels[j] == ENC_UNKNOWN || (by_shadow[i] && labels[j] == ENC_SHADOW);
                around(i, 2).any(sure) && around(i, 1).any(background)
            };
            for i in 0..w * h {
                let expected = match labels[i] {
                    ENC_WEAK | ENC_WEAK_DARK if !shadowed[i] || rim(i) => 0,
                    _ if by_shadow[i] => ENC_SHADOW,
                    ENC_WEAK => ENC_HAND_FOR_TEST,
                    ENC_WEAK_DARK => ENC_SHADOW,
                    v => v,
                };
                assert_eq!(out[i], expected, "pixel {i} of {w}x{h}");
            }
            assert_eq!(n, (0..w * h).filter(|&i| shadowed[i] && !rim(i)).count());
            for y in 0..h {
                assert_eq!(active[y], out[y * w..(y + 1) * w].iter().any(|&v| v != 0));
            }
        }
    }
}
