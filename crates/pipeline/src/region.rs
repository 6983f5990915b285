//! Where each frame set is carved: around the last frame set's hull, not the whole working
//! volume. Hands and tools move a few centimetres between frame sets, and carving the rig's whole
//! volume costs 1.6-2x carving a box around them (docs/benchmarks.md, "Visual hull").
//!
//! The box is the last hull's bounds padded by [`PAD_M`], snapped outward to the full volume's
//! leaf grid (so its leaves are the full carving's leaves) and clipped to the volume. A hull that
//! reaches a face of the box inside the volume may go on past it: that frame set is carved again
//! in the whole volume. Every [`FULL_EVERY`]-th frame set, and whenever the last hull was empty,
//! the whole volume is carved, so that something entering the view away from the hand is found
//! within a fraction of a second.

use hullcut_capture::segment::Window;
use hullcut_hull::{Aabb, Occupancy};
use hullcut_rig::Camera;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Margin around the last hull, metres: a hand at 1 m/s moves 3.3 cm in a 30 fps frame.
pub const PAD_M: f64 = 0.05;

/// The whole volume is carved at least every this many frame sets.
pub const FULL_EVERY: u64 = 15;

/// Counts of where frame sets were carved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RegionCounts {
    /// Carved in a box around the last hull.
    pub boxed: u64,
    /// Carved in the whole volume (first frame set, every [`FULL_EVERY`]-th, after an empty hull).
    pub full: u64,
    /// Hulls that reached the box's side inside the volume.
    pub clipped: u64,
    /// Of those, frame sets carved again in the whole volume (with mask files; a segmented
    /// frame set keeps its hull, and the next one is carved in the whole volume).
    pub redone: u64,
}

/// Chooses the box each frame set is carved in.
#[derive(Debug, Clone)]
pub struct CarveRegion {
    full: Aabb,
    leaf: f64,
    last: Option<Aabb>,
    since_full: u64,
    /// What it chose so far.
    pub counts: RegionCounts,
}

impl CarveRegion {
    /// Boxes within the working volume `full`, on its grid of `leaf` metres.
    pub fn new(full: Aabb, leaf: f64) -> Self {
        CarveRegion { full, leaf, last: None, since_full: 0, counts: RegionCounts::default() }
    }

    /// The box to carve the next frame set in.
    pub fn next_box(&mut self) -> Aabb {
        match self.last {
            Some(last) if self.since_full + 1 < FULL_EVERY => {
                self.since_full += 1;
                self.counts.boxed += 1;
                self.around(&last)
            }
            _ => {
                self.since_full = 0;
                self.counts.full += 1;
                self.full
            }
        }
    }

    /// The whole working volume.
    pub fn full(&self) -> Aabb {
        self.full
    }

    /// Takes the hull carved in `region`; `true` when it reaches a side of `region` that lies
    /// inside the working volume (it may go on past it: carve the frame set again in the whole
    /// volume and hand that hull to this again).
    pub fn update(&mut self, region: &Aabb, occ: &Occupancy) -> bool {
        let Some(bounds) = bounds(occ) else {
            self.last = None;
            return false;
        };
        let eps = 1e-9 + 1e-6 * self.leaf;
        let clipped = (0..3).any(|a| {
            (bounds.min[a] <= region.min[a] + eps && region.min[a] > self.full.min[a] + eps)
                || (bounds.max[a] >= region.max[a] - eps && region.max[a] < self.full.max[a] - eps)
        });
        if clipped {
            self.counts.clipped += 1;
            self.last = None;
            return true;
        }
        self.last = Some(bounds);
        false
    }

    /// `last` padded by [`PAD_M`], snapped outward to the volume's leaf grid, clipped to it.
    fn around(&self, last: &Aabb) -> Aabb {
        let (o, leaf) = (self.full.min, self.leaf);
        let snap_down = |v: f64, a: usize| o[a] + ((v - o[a]) / leaf).floor() * leaf;
        let snap_up = |v: f64, a: usize| o[a] + ((v - o[a]) / leaf).ceil() * leaf;
        let min = Point3::from(Vector3::from_fn(|a, _| snap_down(last.min[a] - PAD_M, a).max(self.full.min[a])));
        let max = Point3::from(Vector3::from_fn(|a, _| snap_up(last.max[a] + PAD_M, a).min(self.full.max[a])));
        if (0..3).any(|a| max[a] <= min[a]) {
            return self.full;
        }
        Aabb { min, max }
    }
}

/// The bounds of a hull's kept cells (`None` when it has none).
fn bounds(occ: &Occupancy) -> Option<Aabb> {
    let mut cells = occ.cells.iter();
    let first = cells.next()?;
    let (mut lo, mut hi) = (first.min, first.min + Vector3::repeat(first.size));
    for c in cells {
        lo = lo.inf(&c.min);
        hi = hi.sup(&(c.min + Vector3::repeat(c.size)));
    }
    Some(Aabb { min: lo, max: hi })
}

/// Points per edge where a box is projected into a view ([`window`]).
const EDGE_SAMPLES: usize = 32;

/// Pixels of slack around the sampled edges' rectangle in [`window`]: between two samples 1/32
/// of an edge apart a lens bows the edge's image by far less.
const SAMPLE_SLACK_PX: f64 = 2.0;

/// The rectangle of `camera`'s pixels where the box `b` can be seen, grown by `pad` pixels and
/// clipped to the image (empty where the box lies off it): the box's projection lies within the
/// rectangle around the projections of its twelve edges (the pinhole image of a box is the convex
/// polygon its edges bound, and a lens within its invertible radius maps that region's boundary
/// onto the boundary of its image), each edge followed through the lens at 32
/// points. `None` where a point of an edge lies within a millimetre of the camera's plane or
/// behind it, or beyond the lens' invertible radius: then the whole image.
pub fn window(camera: &Camera, b: &Aabb, pad: f64) -> Option<Window> {
    let radius = camera.distortion.monotonic_radius();
    let corner = |k: usize| {
        Point3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        )
    };
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    // The edges: corner pairs that differ in one axis.
    for k in 0..8 {
        for axis in [1, 2, 4].into_iter().filter(|a| k & a == 0) {
            let (from, to) = (corner(k), corner(k | axis));
            for n in 0..=EDGE_SAMPLES {
                let p = from + (to - from) * (n as f64 / EDGE_SAMPLES as f64);
                let pc = camera.world_to_camera(&p);
                // NaN fails too: then the whole image.
                if pc.z.is_nan() || pc.z <= 1e-3 {
                    return None;
                }
                let xn = nalgebra::Vector2::new(pc.x / pc.z, pc.y / pc.z);
                let r = xn.norm();
                if r.is_nan() || r >= radius {
                    return None;
                }
                let uv = camera.normalized_to_pixel(camera.distortion.distort(xn));
                lo = [lo[0].min(uv.x), lo[1].min(uv.y)];
                hi = [hi[0].max(uv.x), hi[1].max(uv.y)];
            }
        }
    }
    let grow = pad.max(0.0) + SAMPLE_SLACK_PX;
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    let clamp = |v: f64, n: f64| v.clamp(0.0, n) as u32;
    if !(lo[0].is_finite() && lo[1].is_finite() && hi[0].is_finite() && hi[1].is_finite()) {
        return None;
    }
    let window = Window {
        x0: clamp((lo[0] - grow).floor(), w),
        y0: clamp((lo[1] - grow).floor(), h),
        x1: clamp((hi[0] + grow).ceil() + 1.0, w),
        y1: clamp((hi[1] + grow).ceil() + 1.0, h),
    };
    Some(window.clipped(camera.width, camera.height))
}

#[cfg(test)]
mod tests {
    use hullcut_hull::{Cell, HullParams, carve, silhouettes};

    use super::*;

    fn occupancy(cells: &[(Point3<f64>, f64)]) -> Occupancy {
        Occupancy {
            cells: cells
                .iter()
                .map(|&(min, size)| Cell { min, size, hand: true, scalpel: false, solid: true, refuted_by: None })
                .collect(),
            leaf_size: 0.01,
            origin: Point3::origin(),
            resolution: 64,
            stats: Default::default(),
        }
    }

    #[test]
    fn boxes_follow_the_hull_on_the_leaf_grid_and_a_clipped_hull_asks_for_the_whole_volume() {
        let full = Aabb { min: Point3::new(-0.3, -0.3, 0.0), max: Point3::new(0.3, 0.3, 0.4) };
        let mut region = CarveRegion::new(full, 0.01);
        // The first frame set: the whole volume.
        assert_eq!(region.next_box(), full);
        let hand = occupancy(&[(Point3::new(0.0, 0.0, 0.1), 0.01), (Point3::new(0.02, 0.0, 0.12), 0.01)]);
        assert!(!region.update(&full, &hand));
        // Then a box 5 cm around it, on the grid.
        let b = region.next_box();
        let expect_min = Point3::new(-0.05, -0.05, 0.05);
        let expect_max = Point3::new(0.08, 0.06, 0.18);
        assert!((b.min - expect_min).norm() < 1e-9 && (b.max - expect_max).norm() < 1e-9, "{b:?}");
        for a in 0..3 {
            let k = (b.min[a] - full.min[a]) / 0.01;
            assert!((k - k.round()).abs() < 1e-6, "off the leaf grid: {b:?}");
        }
        // A hull reaching the box's side inside the volume: carve again.
        let moved = occupancy(&[(Point3::new(0.07, 0.0, 0.1), 0.01)]);
        assert!(region.update(&b, &moved));
        assert_eq!(region.counts.clipped, 1);
        // Until a hull is taken in the whole volume, the next box is the whole volume.
        assert_eq!(region.next_box(), full);
        // A hull on the volume's own side (the table) is not clipped.
        let low = occupancy(&[(Point3::new(0.0, 0.0, 0.0), 0.01)]);
        assert!(!region.update(&full, &low));
        let b = region.next_box();
        assert_eq!(b.min.z, 0.0);
        assert!(!region.update(&b, &low));
        // The whole volume every FULL_EVERY frame sets, and after an empty hull.
        let mut fulls = 0;
        for _ in 0..FULL_EVERY {
            let b = region.next_box();
            fulls += usize::from(b == full);
            region.update(&b, &low);
        }
        assert_eq!(fulls, 1);
        region.update(&full, &occupancy(&[]));
        assert_eq!(region.next_box(), full);
    }

    #[test]
    fn every_point_of_a_box_projects_into_its_window_through_any_lens() {
        // Three rigs' lenses (lab8's and the random rig's distort), boxes small and large,
        // near and off the image.
        let rigs = [
            hullcut_rig::RigPreset::Default.rig(),
            hullcut_rig::RigPreset::Lab8.rig(),
            hullcut_rig::RigPreset::Random(5).rig(),
        ];
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut tested, mut inside_image) = (0, 0);
        for rig in &rigs {
            for _ in 0..60 {
                let centre = Point3::new(next() * 0.6 - 0.3, next() * 0.6 - 0.3, next() * 0.3);
                let half = Vector3::new(next(), next(), next()) * 0.15 + Vector3::repeat(0.005);
                let b = Aabb { min: centre - half, max: centre + half };
                for camera in &rig.cameras {
                    let Some(win) = window(camera, &b, 0.0) else { continue };
                    tested += 1;
                    for _ in 0..400 {
                        let p = b.min + (b.max - b.min).component_mul(&Vector3::new(next(), next(), next()));
                        let pr = camera.project(&p);
                        if !pr.visible {
                            continue;
                        }
                        inside_image += 1;
                        // The pixel whose centre is nearest.
                        let (x, y) = (pr.pixel.x.round(), pr.pixel.y.round());
                        assert!(
                            x >= f64::from(win.x0)
                                && x < f64::from(win.x1)
                                && y >= f64::from(win.y0)
                                && y < f64::from(win.y1),
                            "{p:?} at ({x:.2}, {y:.2}) outside {win:?} of {b:?}"
                        );
                    }
                }
            }
        }
        assert!(tested > 300 && inside_image > 50_000, "{tested} windows, {inside_image} points seen");
        // A box behind a camera, or one beyond the lens' invertible radius: the whole image.
        let camera = &rigs[0].cameras[0];
        let behind = camera.centre() - camera.viewing_direction().into_inner();
        let b = Aabb { min: behind - Vector3::repeat(0.01), max: behind + Vector3::repeat(0.01) };
        assert_eq!(window(camera, &b, 3.0), None);
        // A box that is not finite: the whole image, never a window that loses the hand.
        let nan = Aabb { min: Point3::new(f64::NAN, 0.0, 0.0), max: Point3::new(0.1, 0.1, 0.1) };
        let huge = Aabb { min: Point3::new(-f64::MAX, 0.0, 0.0), max: Point3::new(f64::MAX, 0.1, 0.1) };
        assert_eq!((window(camera, &nan, 3.0), window(camera, &huge, 3.0)), (None, None));
        // A box well inside the view: a window much smaller than the image, grown by the pad.
        let ahead = camera.centre() + camera.viewing_direction().into_inner() * 0.5;
        let b = Aabb { min: ahead - Vector3::repeat(0.01), max: ahead + Vector3::repeat(0.01) };
        let (small, padded) = (window(camera, &b, 0.0).expect("seen"), window(camera, &b, 10.0).expect("seen"));
        assert!(small.area() * 20 < u64::from(camera.width) * u64::from(camera.height), "{small:?}");
        assert_eq!(
            (padded.x0 + 10, padded.y0 + 10, padded.x1 - 10, padded.y1 - 10),
            (small.x0, small.y0, small.x1, small.y1)
        );
    }

    #[test]
    fn carving_in_the_box_keeps_the_whole_volumes_leaves_there() {
        // The default rig's masks of a 4 cm ball.
        let rig = hullcut_rig::RigPreset::Default.rig();
        let ball = Point3::new(0.02, -0.01, 0.12);
        let masks: Vec<image::GrayImage> = rig
            .cameras
            .iter()
            .map(|c| {
                image::GrayImage::from_fn(c.width, c.height, |x, y| {
                    let ray = c.pixel_ray(nalgebra::Point2::new(f64::from(x), f64::from(y)));
                    let hit = ray.is_some_and(|r| {
                        let t = (ball - r.origin).dot(&r.direction);
                        (r.origin + r.direction.into_inner() * t - ball).norm() < 0.04
                    });
                    image::Luma([u8::from(hit)])
                })
            })
            .collect();
        let refs: Vec<Option<&image::GrayImage>> = masks.iter().map(Some).collect();
        let views = silhouettes(&rig, &refs).expect("silhouettes");
        let full = Aabb { min: Point3::new(-0.4, -0.4, 0.0), max: Point3::new(0.4, 0.4, 0.4) };
        let params = HullParams::new(full, 0.005);
        let whole = carve(&views, &params).expect("carves");
        let mut region = CarveRegion::new(full, 0.005);
        region.update(&full, &whole);
        let b = region.next_box();
        assert!(b != full);
        let boxed = carve(&views, &HullParams { workspace: b, ..params.clone() }).expect("carves");
        assert!(!region.update(&b, &boxed));
        let volume = |o: &Occupancy| o.volume(None);
        assert!(volume(&whole) > 0.0);
        assert!((volume(&boxed) - volume(&whole)).abs() < 1e-12, "{} against {}", volume(&boxed), volume(&whole));
        // The same leaves, one by one: every leaf centre of one hull lies in the other.
        for (a, b) in [(&boxed, &whole), (&whole, &boxed)] {
            for c in &a.cells {
                let centre = c.min + Vector3::repeat(c.size / 2.0);
                assert!(b.contains(&centre, None), "{centre:?}");
            }
        }
    }
}
