//! Holes: background pixels of a window's mask enclosed by its foreground (4-connected through
//! each other, touching no edge of the window), with more objects than possible shadows beside
//! them, are tested as a whole: the mean colour of their pixels clear of the hole's edge against
//! their background's mean, and filled where the hole is brighter, or where the means tell them
//! apart in chromaticity and the hole's colour leans towards the objects' around it (see
//! [`super::SegmentParams::fill_holes`]).
//!
//! A pixel's test allows for the sensor's noise; over a hole's n pixels the noise falls by √n,
//! and a hand of nearly its background's colour, background pixel by pixel, is not background on
//! the mean. Every such hole carves the hull through the hand (random:2473 in random:2593: holes
//! of up to 138 pixels in the hand over a grey backdrop), while a gap between the fingers shows
//! the background itself. A hole's edge pixels are partly covered by the objects around it, of a
//! colour between theirs and the background's, and a small gap is mostly such pixels: only the
//! pixels clear of the edge are summed, and a hole with fewer than [`MIN_INNER`] is left. The
//! table seen through a gap, in the hand's soft shadow and lit by a light of another colour, may
//! differ from its background too, but not towards the hand's colour.

use super::classes::ClassLut;
use super::{ENC_UNKNOWN, SHADOW_LIKE, SegmentParams, WindowRows, decode};
use hullcut_dataset::label;

/// A run of background pixels in a window's row: `x0..x1`.
#[derive(Debug, Clone, Copy)]
struct Run {
    y: u32,
    x0: u32,
    x1: u32,
}

/// A hole's colour sums: the image's and its background's, per channel.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    image: [u64; 3],
    background: [u64; 3],
    /// Its pixels whose 4-neighbours are all in it, which the colour sums are over.
    inner: u32,
    /// Its 4-neighbours that are objects (hand, scalpel, unknown).
    objects: u32,
    /// The image's colour summed over those objects.
    ring: [u64; 3],
    /// Its 4-neighbours that are possible shadows.
    shadows: u32,
}

/// The fewest pixels clear of a hole's edge (all four neighbours in it) whose mean colour tells
/// a hole from its background; a smaller hole is left.
const MIN_INNER: u32 = 4;

/// When a hole is filled: its mean colour against its background's mean, the background
/// scaled by the exposure gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HoleRule {
    /// Filled where its chromaticity differs from its background's by more than this (L1,
    /// relative to the channel sum).
    pub chroma: f64,
    /// Filled where it is brighter than its background by more than this (relative).
    pub brighter: f64,
    /// A hole darker than this (relative) whose chromaticity differs by no more than
    /// `dark_chroma` may be a shadow: left.
    pub darker: f64,
    /// See `darker`.
    pub dark_chroma: f64,
}

impl HoleRule {
    /// The rule of these settings: the weak share of the chromaticity and brightness
    /// tolerances; a shadow darker than the shadow tolerance within the whole chromaticity
    /// tolerance.
    pub(crate) fn of(params: &SegmentParams) -> Self {
        let share = params.weak_share.clamp(0.0, 1.0);
        Self {
            chroma: share * params.chroma_tolerance,
            brighter: share * params.brightness_tolerance,
            darker: params.shadow_tolerance,
            dark_chroma: params.chroma_tolerance,
        }
    }

    /// Whether a hole of these sums (`gain` the image's exposure gain against the background)
    /// is to be filled.
    fn fills(&self, sums: &Sums, gain: f64) -> bool {
        if sums.shadows >= sums.objects {
            // More possible shadows than objects around it: the table lit between shadows, or
            // in a shadow's penumbra, perhaps.
            return false;
        }
        if sums.inner < MIN_INNER {
            // Too few pixels clear of its edge to tell its colour.
            return false;
        }
        let total = |c: &[u64; 3]| c.iter().sum::<u64>() as f64;
        let (si, sb) = (total(&sums.image), gain * total(&sums.background));
        if si <= 0.0 || sb <= 0.0 {
            // A black hole or a black background: no chromaticity to compare; only brighter.
            return si > 0.0 && sb <= 0.0;
        }
        let ratio = si / sb;
        if ratio > 1.0 + self.brighter {
            return true;
        }
        // Chromaticities less the background's: the hole's, and the objects' around it.
        let background = |c: usize| gain * sums.background[c] as f64 / sb;
        let hole: [f64; 3] = std::array::from_fn(|c| sums.image[c] as f64 / si - background(c));
        let sr = total(&sums.ring);
        let ring: [f64; 3] =
            std::array::from_fn(|c| if sr > 0.0 { sums.ring[c] as f64 / sr - background(c) } else { 0.0 });
        let chroma: f64 = hole.iter().map(|d| d.abs()).sum();
        let dot = |a: &[f64; 3], b: &[f64; 3]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        // Its colour leans towards the objects' around it (within 60°), not elsewhere (the
        // table in their soft shadow, lit by the room's light of another colour); objects of
        // about the background's chromaticity (a grey glove over a grey table) give no direction,
        // and such a hole is filled only where brighter.
        let distinct = ring.iter().map(|d| d.abs()).sum::<f64>() > self.chroma;
        let towards = distinct && dot(&hole, &ring) >= 0.5 * (dot(&hole, &hole) * dot(&ring, &ring)).sqrt();
        chroma > self.chroma && towards && (ratio >= 1.0 - self.darker || chroma > self.dark_chroma)
    }
}

/// The image behind a window: its raw RGB bytes and width, the background model's mean image
/// (raw RGB, the image's size) and the image's exposure gain against it.
pub(crate) struct Behind<'a> {
    pub raw: &'a [u8],
    pub full_w: usize,
    pub background: &'a [u8],
    pub gain: f64,
}

/// Scratch of the hole filling, reused from frame set to frame set.
#[derive(Debug, Default)]
pub(crate) struct Holes {
    runs: Vec<Run>,
    /// The first run of each row, and one past the last row's.
    starts: Vec<usize>,
    /// Union-find over the runs.
    parent: Vec<u32>,
    /// Per run (its root's): whether it touches the window's edge.
    open: Vec<bool>,
    sums: Vec<Sums>,
}

impl Holes {
    /// Fills the holes of `out` (the window's decoded labels) that `rule` tells from their
    /// background, each pixel with its colour's label from `lut` (unknown where the table has
    /// none); returns the pixels filled.
    pub(crate) fn fill(
        &mut self,
        out: &mut WindowRows,
        h: usize,
        behind: &Behind,
        rule: &HoleRule,
        lut: &ClassLut,
    ) -> u64 {
        let w = out.w;
        if w == 0 || h == 0 {
            return 0;
        }
        self.runs.clear();
        self.starts.clear();
        for y in 0..h {
            self.starts.push(self.runs.len());
            let row = out.row(y);
            let mut x = next_background(row, 0);
            while x < w {
                let x1 = next_object(row, x);
                self.runs.push(Run { y: y as u32, x0: x as u32, x1: x1 as u32 });
                x = next_background(row, x1);
            }
        }
        self.starts.push(self.runs.len());
        let n = self.runs.len();
        self.parent.clear();
        self.parent.extend(0..n as u32);
        // Runs of neighbouring rows that share a column are one component (4-connected).
        for y in 1..h {
            let (mut a, a_end) = (self.starts[y - 1], self.starts[y]);
            let (mut b, b_end) = (self.starts[y], self.starts[y + 1]);
            while a < a_end && b < b_end {
                let (ra, rb) = (self.runs[a], self.runs[b]);
                if ra.x0 < rb.x1 && rb.x0 < ra.x1 {
                    union(&mut self.parent, a as u32, b as u32);
                }
                if ra.x1 <= rb.x1 {
                    a += 1;
                } else {
                    b += 1;
                }
            }
        }
        self.open.clear();
        self.open.resize(n, false);
        for (i, r) in self.runs.iter().enumerate() {
            if r.y == 0 || r.y as usize == h - 1 || r.x0 == 0 || r.x1 as usize == w {
                let root = find(&mut self.parent, i as u32) as usize;
                self.open[root] = true;
            }
        }
        if (0..n).all(|i| self.open[find(&mut self.parent, i as u32) as usize]) {
            return 0;
        }
        self.sums.clear();
        self.sums.resize(n, Sums::default());
        // What encloses each hole: its 4-neighbours that are objects (and their colours), and
        // possible shadows.
        let (x_off, y_off) = (out.x0, out.y0);
        let pixel = |x: usize, y: usize| 3 * ((y_off + y) * behind.full_w + x_off + x);
        for i in 0..n {
            let root = find(&mut self.parent, i as u32) as usize;
            if self.open[root] {
                continue;
            }
            let r = self.runs[i];
            let (y, x0, x1) = (r.y as usize, r.x0 as usize, r.x1 as usize);
            let s = &mut self.sums[root];
            // The runs of a hole touch no edge of the window: its ends and the rows above and
            // below are in it.
            let mut tally = |p: u8, x: usize, y: usize| {
                if p == SHADOW_LIKE {
                    s.shadows += 1;
                } else if p != label::BACKGROUND {
                    s.objects += 1;
                    let k = pixel(x, y);
                    for c in 0..3 {
                        s.ring[c] += u64::from(behind.raw[k + c]);
                    }
                }
            };
            let row = out.row(y);
            let (left, right) = (row[x0 - 1], row[x1]);
            tally(left, x0 - 1, y);
            tally(right, x1, y);
            for yy in [y - 1, y + 1] {
                for (x, &p) in out.row(yy)[x0..x1].iter().enumerate() {
                    tally(p, x0 + x, yy);
                }
            }
            // Its inner pixels only: one with an object beside it is partly covered by it, of a
            // colour between the object's and the background's, and a small gap between the
            // fingers is mostly such pixels.
            for x in r.x0 + 1..r.x1.saturating_sub(1) {
                let xi = x as usize;
                if out.row(y - 1)[xi] != label::BACKGROUND || out.row(y + 1)[xi] != label::BACKGROUND {
                    continue;
                }
                let k = pixel(xi, y);
                for c in 0..3 {
                    s.image[c] += u64::from(behind.raw[k + c]);
                    s.background[c] += u64::from(behind.background[k + c]);
                }
                s.inner += 1;
            }
        }
        let mut filled = 0;
        for i in 0..n {
            let root = find(&mut self.parent, i as u32) as usize;
            if self.open[root] || !rule.fills(&self.sums[root], behind.gain) {
                continue;
            }
            let r = self.runs[i];
            let row = out.row(r.y as usize);
            for x in r.x0..r.x1 {
                let k = pixel(x as usize, r.y as usize);
                let e = lut.get(behind.raw[k], behind.raw[k + 1], behind.raw[k + 2]);
                row[x as usize] = decode(if e == 0 { ENC_UNKNOWN } else { e });
            }
            filled += u64::from(r.x1 - r.x0);
        }
        filled
    }
}

/// The first background pixel of `row` at `x` or after (`row.len()` if none), eight pixels at a
/// time where none of them is.
fn next_background(row: &[u8], mut x: usize) -> usize {
    const ONES: u64 = 0x0101_0101_0101_0101;
    while let Some(eight) = row.get(x..x + 8).and_then(|b| <[u8; 8]>::try_from(b).ok()) {
        let v = u64::from_le_bytes(eight);
        // Whether a byte of `v` is zero.
        if v.wrapping_sub(ONES) & !v & (ONES << 7) != 0 {
            break;
        }
        x += 8;
    }
    x + row.get(x..).map_or(0, |rest| rest.iter().position(|&p| p == label::BACKGROUND).unwrap_or(rest.len()))
}

/// The first pixel of `row` that is not background at `x` or after (`row.len()` if none), eight
/// pixels at a time where all of them are.
fn next_object(row: &[u8], mut x: usize) -> usize {
    while let Some(eight) = row.get(x..x + 8).and_then(|b| <[u8; 8]>::try_from(b).ok()) {
        if u64::from_le_bytes(eight) != 0 {
            break;
        }
        x += 8;
    }
    x + row.get(x..).map_or(0, |rest| rest.iter().position(|&p| p != label::BACKGROUND).unwrap_or(rest.len()))
}

/// The root of `i`'s component, halving the path on the way.
fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[i as usize];
        parent[i as usize] = parent[p as usize];
        i = p;
    }
    i
}

/// Joins the components of `a` and `b` (the larger root under the smaller, for a fixed order).
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment::encode;

    #[test]
    fn the_runs_are_found_eight_pixels_at_a_time_as_one_by_one() {
        let mut seed = 9u64;
        for case in 0..2_000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let len = (seed >> 40) as usize % 70;
            let density = (seed >> 20) % 100;
            let row: Vec<u8> = (0..len)
                .map(|_| {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    if (seed >> 33) % 100 < density {
                        [label::HAND, SHADOW_LIKE, 255][(seed >> 50) as usize % 3]
                    } else {
                        0
                    }
                })
                .collect();
            for x in 0..=len {
                let bg = (x..len).find(|&i| row[i] == label::BACKGROUND).unwrap_or(len);
                let obj = (x..len).find(|&i| row[i] != label::BACKGROUND).unwrap_or(len);
                assert_eq!(next_background(&row, x), bg, "case {case} at {x}: {row:?}");
                assert_eq!(next_object(&row, x), obj, "case {case} at {x}: {row:?}");
            }
        }
    }

    /// A rule that fills every enclosed hole with colour in it.
    const EVERY: HoleRule = HoleRule { chroma: -1.0, brighter: -1.0, darker: 1.0, dark_chroma: -1.0 };

    /// The background pixels of a `w`×`h` mask whose component (4-connected) touches no edge of
    /// the mask, has more objects than possible shadows among its pixels' 4-neighbours and
    /// [`MIN_INNER`] or more pixels whose 4-neighbours are all background, found by a flood from
    /// each pixel in turn.
    fn enclosed(mask: &[u8], w: usize, h: usize) -> Vec<Hole> {
        let mut component = vec![usize::MAX; w * h];
        // Per component: open, objects, possible shadows, inner pixels.
        let mut seen: Vec<(bool, u32, u32, u32)> = Vec::new();
        for start in 0..w * h {
            if mask[start] != label::BACKGROUND || component[start] != usize::MAX {
                continue;
            }
            let id = seen.len();
            seen.push((false, 0, 0, 0));
            let mut stack = vec![start];
            component[start] = id;
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                let near = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < w).then(|| i + 1),
                    (y > 0).then(|| i - w),
                    (y + 1 < h).then(|| i + w),
                ];
                if near.iter().any(Option::is_none) {
                    seen[id].0 = true;
                }
                if near.iter().flatten().all(|&j| mask[j] == label::BACKGROUND) {
                    seen[id].3 += 1;
                }
                for j in near.into_iter().flatten() {
                    match mask[j] {
                        SHADOW_LIKE => seen[id].2 += 1,
                        label::BACKGROUND if component[j] == usize::MAX => {
                            component[j] = id;
                            stack.push(j);
                        }
                        label::BACKGROUND => {}
                        _ => seen[id].1 += 1,
                    }
                }
            }
        }
        component
            .iter()
            .map(|&c| match seen.get(c) {
                Some(&(false, objects, shadows, inner)) if objects > shadows && inner >= MIN_INNER => Hole::Filled,
                Some(&(false, objects, shadows, _)) if objects <= shadows => Hole::AmongShadows,
                Some(&(false, ..)) => Hole::Small,
                _ => Hole::Not,
            })
            .collect()
    }

    /// What [`enclosed`] makes of a pixel.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Hole {
        Not,
        Filled,
        AmongShadows,
        Small,
    }

    /// Random masks of objects and possible shadows, in windows of random images: every
    /// background pixel the objects enclose is filled with its colour's label, and nothing else
    /// changes.
    #[test]
    fn the_holes_filled_are_the_components_of_background_the_objects_enclose() {
        let lut = ClassLut::from_fn(|[r, _, _]| if r > 127 { label::SCALPEL } else { label::HAND }, encode);
        let mut seed = 5u64;
        let mut next = |n: u64| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 33) % n
        };
        let mut holes = Holes::default();
        let (mut filled_total, mut shadowed_total, mut small_total) = (0u64, 0u64, 0u64);
        for case in 0..1000 {
            let (full_w, full_h) = (1 + next(80) as usize, 1 + next(60) as usize);
            let (x0, y0) = (next(full_w as u64) as usize, next(full_h as u64) as usize);
            let (w, h) = (1 + next((full_w - x0) as u64) as usize, 1 + next((full_h - y0) as u64) as usize);
            let density = 50 + next(40);
            // Blocks of 1-3 pixels a side, for holes of every size.
            let block = 1 + next(3) as usize;
            let (bw, bh) = (full_w.div_ceil(block), full_h.div_ceil(block));
            let blocks: Vec<u8> = (0..bw * bh)
                .map(|_| match next(100) {
                    d if d < density / 4 => SHADOW_LIKE,
                    d if d < density => label::HAND,
                    _ => label::BACKGROUND,
                })
                .collect();
            let mut full: Vec<u8> =
                (0..full_w * full_h).map(|i| blocks[(i / full_w / block) * bw + i % full_w / block]).collect();
            let raw: Vec<u8> = (0..3 * full_w * full_h).map(|_| 1 + next(255) as u8).collect();
            let background: Vec<u8> = (0..3 * full_w * full_h).map(|_| next(256) as u8).collect();
            let window: Vec<u8> = (0..h).flat_map(|y| full[(y0 + y) * full_w + x0..][..w].to_vec()).collect();
            let want = enclosed(&window, w, h);
            let before = full.clone();
            let behind = Behind { raw: &raw, full_w, background: &background, gain: 1.0 };
            let mut out = WindowRows { full: &mut full, full_w, x0, y0, w };
            let filled = holes.fill(&mut out, h, &behind, &EVERY, &lut);
            assert_eq!(filled, want.iter().filter(|&&e| e == Hole::Filled).count() as u64, "case {case}");
            for (i, (&now, &was)) in full.iter().zip(&before).enumerate() {
                let (x, y) = (i % full_w, i / full_w);
                let inside = (x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y);
                if inside && want[(y - y0) * w + x - x0] == Hole::Filled {
                    let expect = if raw[3 * i] > 127 { label::SCALPEL } else { label::HAND };
                    assert_eq!(now, expect, "case {case}: pixel ({x}, {y}) enclosed");
                } else {
                    assert_eq!(now, was, "case {case}: pixel ({x}, {y}) not enclosed");
                }
            }
            filled_total += filled;
            shadowed_total += want.iter().filter(|&&e| e == Hole::AmongShadows).count() as u64;
            small_total += want.iter().filter(|&&e| e == Hole::Small).count() as u64;
        }
        let counts = format!("{filled_total} filled, {shadowed_total} among shadows, {small_total} in small holes");
        assert!(filled_total > 1_000 && shadowed_total > 100 && small_total > 100, "{counts}");
    }

    fn sums(image: [u64; 3], background: [u64; 3]) -> Sums {
        // The objects around it of the hole's colour.
        Sums { image, background, inner: 10, objects: 10, ring: image, shadows: 0 }
    }

    #[test]
    fn a_hole_is_filled_where_its_mean_is_not_its_backgrounds_and_left_where_it_may_be_a_shadow_or_among_shadows() {
        let rule = HoleRule::of(&SegmentParams::default());
        let grey = [1000, 1000, 1000];
        // The background itself, at any exposure.
        assert!(!rule.fills(&sums(grey, grey), 1.0));
        assert!(!rule.fills(&sums([1200, 1200, 1200], grey), 1.2));
        // Chromaticity 0.04 away (over the weak share of κ, 0.03), 0.02 away (under).
        assert!(rule.fills(&sums([1060, 1000, 940], grey), 1.0));
        assert!(!rule.fills(&sums([1030, 1000, 970], grey), 1.0));
        // Brighter by 6% (over the weak share of β, 4%); by 6% but the gain explains it.
        assert!(rule.fills(&sums([1060, 1060, 1060], grey), 1.0));
        assert!(!rule.fills(&sums([1060, 1060, 1060], grey), 1.05));
        // Darker than the shadow tolerance, 0.04 away in chromaticity: perhaps a shadow, left;
        // 0.07 away (over κ): filled.
        assert!(!rule.fills(&sums([530, 500, 470], grey), 1.0));
        assert!(rule.fills(&sums([552, 500, 448], grey), 1.0));
        // Black: nothing to compare but a black background.
        assert!(!rule.fills(&sums([0, 0, 0], grey), 1.0));
        assert!(rule.fills(&sums([10, 10, 10], [0, 0, 0]), 1.0));
        assert!(!rule.fills(&sums([0, 0, 0], [0, 0, 0]), 1.0));
        // As many possible shadows as objects around it: left, whatever its colour.
        let shaded = Sums { objects: 4, shadows: 4, ..sums([1060, 1060, 1060], grey) };
        assert!(!rule.fills(&shaded, 1.0));
        assert!(rule.fills(&Sums { objects: 5, ..shaded }, 1.0));
        // Its colour leans away from the objects' around it: left.
        let away = Sums { ring: [1000, 1000, 1060], ..sums([1060, 1000, 940], grey) };
        assert!(!rule.fills(&away, 1.0));
        assert!(rule.fills(&Sums { ring: [1100, 1000, 1000], ..away }, 1.0));
        // Objects around it of about the background's chromaticity: no direction to lean in.
        let grey = Sums { ring: [1010, 1000, 990], ..sums([1060, 1000, 940], grey) };
        assert!(!rule.fills(&grey, 1.0));
        assert!(rule.fills(&Sums { image: [1070, 1070, 1070], ..grey }, 1.0));
        // Too few pixels clear of its edge to tell.
        assert!(!rule.fills(&Sums { inner: MIN_INNER - 1, objects: 5, ..shaded }, 1.0));
        assert!(rule.fills(&Sums { inner: MIN_INNER, objects: 5, ..shaded }, 1.0));
    }
}
