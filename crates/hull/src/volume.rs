//! The working volume: the box that carving covers, from the command line, the dataset or the
//! rig (shared/DESIGN.md, "Working volume").
//!
//! Derived from a rig, it is the bounding box of the space that at least `min_views` cameras see
//! (all of them when the rig has fewer), above the table (z ≥ 0) when the rig's world frame is a
//! table's. It is found by sampling: a first grid over a search box around the point the cameras'
//! optical axes converge on (half as wide again as the farthest camera is from it), then a finer
//! grid over what the first kept, each box padded by one sample spacing so that nothing seen is
//! cut off. A rig whose cameras look the same way (their axes do not converge) sees an unbounded
//! region; its search box then starts twice the cameras' spread in front of them, and the volume
//! is reported as capped by the search box.

use hullcut_rig::{Camera, Rig};
use nalgebra::{Matrix3, Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{Aabb, HullError};

/// Samples per side of the first (search) grid.
const SEARCH_SAMPLES: usize = 48;
/// Samples per side of the second (refining) grid.
const REFINE_SAMPLES: usize = 64;
/// Points nearer a camera than this (along its axis) count as unseen, metres.
const NEAR_M: f64 = 0.01;

/// Where a working volume came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum VolumeSource {
    /// `--workspace` on the command line.
    CommandLine,
    /// `workspace` in the dataset's `dataset.toml`.
    Dataset,
    /// Derived from the rig: the space at least `min_views` of its cameras see.
    Rig {
        /// Cameras that must see a point for it to be inside.
        min_views: usize,
        /// Cameras in the rig.
        cameras: usize,
        /// Clipped to z ≥ 0 (the rig's world frame is a table's).
        above_table: bool,
        /// The region seen reached the search box (cameras that look the same way see an
        /// unbounded region), so the volume is the search box's share of it.
        capped: bool,
    },
}

impl VolumeSource {
    /// A short description for people ("derived from the rig: seen by at least 3 of 8 cameras,
    /// above the table").
    pub fn describe(&self) -> String {
        match self {
            Self::CommandLine => "given with --workspace".to_owned(),
            Self::Dataset => "given in dataset.toml".to_owned(),
            Self::Rig { min_views, cameras, above_table, capped } => {
                let mut s = format!("derived from the rig: seen by at least {min_views} of {cameras} cameras");
                if *above_table {
                    s.push_str(", above the table");
                }
                if *capped {
                    s.push_str(", capped by the search box (the cameras' axes do not converge)");
                }
                s
            }
        }
    }
}

/// The box carving covers and where it came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkingVolume {
    /// The box, world metres.
    #[serde(serialize_with = "serialize_aabb", deserialize_with = "deserialize_aabb")]
    pub aabb: Aabb,
    /// Where it came from.
    pub source: VolumeSource,
    /// Cameras that see no part of the volume: they take no part in carving.
    pub blind_cameras: Vec<String>,
}

fn serialize_aabb<S: serde::Serializer>(a: &Aabb, s: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeStruct;
    let mut st = s.serialize_struct("Aabb", 2)?;
    st.serialize_field("min", &[a.min.x, a.min.y, a.min.z])?;
    st.serialize_field("max", &[a.max.x, a.max.y, a.max.z])?;
    st.end()
}

fn deserialize_aabb<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Aabb, D::Error> {
    #[derive(Deserialize)]
    struct Corners {
        min: [f64; 3],
        max: [f64; 3],
    }
    let c = Corners::deserialize(d)?;
    Ok(Aabb { min: Point3::from(c.min), max: Point3::from(c.max) })
}

impl WorkingVolume {
    /// A volume given explicitly (command line or dataset), checked: finite corners, `min < max` on
    /// every axis, and seen (some part of it) by at least `min_views` cameras of the rig (all of
    /// them when fewer); cameras that see none of it are listed.
    pub fn given(
        min: [f64; 3],
        max: [f64; 3],
        source: VolumeSource,
        rig: &Rig,
        min_views: usize,
    ) -> Result<Self, HullError> {
        let aabb = Aabb { min: Point3::from(min), max: Point3::from(max) };
        aabb.check()?;
        if rig.is_empty() {
            return Err(HullError::Volume("the rig has no cameras".to_owned()));
        }
        let radii: Vec<f64> = rig.cameras.iter().map(|c| c.distortion.monotonic_radius()).collect();
        // Which cameras see some point of a 16³ grid over the box.
        let mut seeing = vec![false; rig.len()];
        let n = 16;
        let step = (aabb.max - aabb.min) / n as f64;
        for idx in 0..n * n * n {
            let p = aabb.min
                + Vector3::new((idx % n) as f64 + 0.5, ((idx / n) % n) as f64 + 0.5, (idx / (n * n)) as f64 + 0.5)
                    .component_mul(&step);
            for (k, (c, &r)) in rig.cameras.iter().zip(&radii).enumerate() {
                seeing[k] |= sees(c, r, &p);
            }
        }
        let k = min_views.clamp(1, rig.len());
        let count = seeing.iter().filter(|&&s| s).count();
        if count < k {
            return Err(HullError::Volume(format!(
                "{count} of the rig's {} cameras see any part of the volume {}; carving needs {k}",
                rig.len(),
                describe_box(&aabb)
            )));
        }
        let blind_cameras = blind(rig, &seeing);
        Ok(Self { aabb, source, blind_cameras })
    }

    /// The volume derived from a rig: the space at least `min_views` cameras see (all of them
    /// when there are fewer), above the table when `above_table`.
    pub fn from_rig(rig: &Rig, min_views: usize, above_table: bool) -> Result<Self, HullError> {
        let seen = seen_volume(rig, min_views, above_table)?;
        let seeing: Vec<bool> = seen.samples_per_camera.iter().map(|&n| n > 0).collect();
        Ok(Self {
            aabb: seen.aabb,
            source: VolumeSource::Rig {
                min_views: seen.min_views,
                cameras: rig.len(),
                above_table,
                capped: seen.capped,
            },
            blind_cameras: blind(rig, &seeing),
        })
    }

    /// One line for people: the box in millimetres, its source, and the cameras that see none of
    /// it.
    pub fn describe(&self) -> String {
        let mut s = format!("working volume {}, {}", describe_box(&self.aabb), self.source.describe());
        if !self.blind_cameras.is_empty() {
            s.push_str(&format!("; seen by none of it (left out of carving): {}", self.blind_cameras.join(", ")));
        }
        s
    }
}

fn blind(rig: &Rig, seeing: &[bool]) -> Vec<String> {
    rig.cameras.iter().zip(seeing).filter(|&(_, &s)| !s).map(|(c, _)| c.name.clone()).collect()
}

/// A box in millimetres for messages.
fn describe_box(a: &Aabb) -> String {
    let (lo, hi) = (a.min * 1e3, a.max * 1e3);
    format!("x {:.0}..{:.0}, y {:.0}..{:.0}, z {:.0}..{:.0} mm", lo.x, hi.x, lo.y, hi.y, lo.z, hi.z)
}

/// What [`seen_volume`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct SeenVolume {
    /// The bounding box of the sampled points seen by `min_views` cameras, padded by a sample.
    pub aabb: Aabb,
    /// The number of cameras required (the request, at most the rig's size).
    pub min_views: usize,
    /// Whether the seen region reached the search box.
    pub capped: bool,
    /// Kept samples of the refining grid that each camera sees (rig order).
    pub samples_per_camera: Vec<u64>,
}

/// Whether a camera sees a world point: in front of it, within its lens' invertible radius, and
/// projecting inside its image (pixel centres span `0..=w-1`, `0..=h-1`).
fn sees(cam: &Camera, radius: f64, p: &Point3<f64>) -> bool {
    let pc = cam.world_to_camera(p);
    if pc.z <= NEAR_M {
        return false;
    }
    let xn = nalgebra::Vector2::new(pc.x / pc.z, pc.y / pc.z);
    if xn.norm() >= radius {
        return false;
    }
    let uv = cam.normalized_to_pixel(cam.distortion.distort(xn));
    uv.x >= -0.5 && uv.y >= -0.5 && uv.x <= cam.width as f64 - 0.5 && uv.y <= cam.height as f64 - 0.5
}

/// The point nearest every camera's optical axis (least squares), or `None` when the axes are
/// nearly parallel.
fn convergence(rig: &Rig) -> Option<Point3<f64>> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for cam in &rig.cameras {
        let d = cam.viewing_direction().into_inner();
        let m = Matrix3::identity() - d * d.transpose();
        a += m;
        b += m * cam.centre().coords;
    }
    let eig = a.symmetric_eigen();
    let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    // Axes within about 10° of each other leave one direction nearly unconstrained.
    if rig.len() < 2 || lo < 0.03 * hi {
        return None;
    }
    let p = a.try_inverse()? * b;
    let p = Point3::from(p);
    // The point must lie in front of the cameras, or they do not converge on it.
    rig.cameras.iter().all(|c| c.world_to_camera(&p).z > 0.0).then_some(p)
}

/// Samples the box on an `n`³ grid: the kept sample centres' box (padded by one spacing) and
/// per-camera counts of kept samples, or `None` when no sample is seen by `k` cameras.
fn sample(rig: &Rig, radii: &[f64], search: &Aabb, n: usize, k: usize) -> Option<(Aabb, Vec<u64>)> {
    let step = (search.max - search.min) / n as f64;
    let found = (0..n * n * n)
        .into_par_iter()
        .fold(
            || (None::<Aabb>, vec![0u64; rig.len()]),
            |(mut bbox, mut counts), idx| {
                let (i, j, l) = (idx % n, (idx / n) % n, idx / (n * n));
                let p = search.min + Vector3::new(i as f64 + 0.5, j as f64 + 0.5, l as f64 + 0.5).component_mul(&step);
                let seen: Vec<bool> = rig.cameras.iter().zip(radii).map(|(c, &r)| sees(c, r, &p)).collect();
                if seen.iter().filter(|&&s| s).count() >= k {
                    for (c, s) in counts.iter_mut().zip(&seen) {
                        *c += u64::from(*s);
                    }
                    bbox = Some(match bbox {
                        None => Aabb { min: p, max: p },
                        Some(b) => Aabb { min: b.min.inf(&p), max: b.max.sup(&p) },
                    });
                }
                (bbox, counts)
            },
        )
        .reduce(
            || (None, vec![0u64; rig.len()]),
            |(a, ca), (b, cb)| {
                let bbox = match (a, b) {
                    (Some(a), Some(b)) => Some(Aabb { min: a.min.inf(&b.min), max: a.max.sup(&b.max) }),
                    (a, b) => a.or(b),
                };
                (bbox, ca.iter().zip(&cb).map(|(x, y)| x + y).collect())
            },
        );
    let (bbox, counts) = found;
    let b = bbox?;
    Some((Aabb { min: b.min - step, max: b.max + step }, counts))
}

/// The space at least `min_views` cameras of the rig see (all of them when fewer), as a box;
/// clipped to z ≥ 0 with `above_table`. See the module docs.
pub fn seen_volume(rig: &Rig, min_views: usize, above_table: bool) -> Result<SeenVolume, HullError> {
    if rig.is_empty() {
        return Err(HullError::Volume("the rig has no cameras".to_owned()));
    }
    let k = min_views.clamp(1, rig.len());
    let centres: Vec<Point3<f64>> = rig.cameras.iter().map(Camera::centre).collect();
    let mean = Point3::from(centres.iter().map(|c| c.coords).sum::<Vector3<f64>>() / centres.len() as f64);
    let spread = centres.iter().map(|c| (c - mean).norm()).fold(0.0, f64::max);
    let centre = convergence(rig).unwrap_or_else(|| {
        let d: Vector3<f64> = rig.cameras.iter().map(|c| c.viewing_direction().into_inner()).sum();
        let d = d.try_normalize(1e-9).unwrap_or_else(Vector3::z);
        mean + d * (2.0 * spread).max(0.5)
    });
    let half = 1.5 * centres.iter().map(|c| (c - centre).norm()).fold(0.0, f64::max);
    if !(half.is_finite() && half > 0.0) {
        return Err(HullError::Volume("the cameras' positions span no space".to_owned()));
    }
    let mut search = Aabb { min: centre - Vector3::repeat(half), max: centre + Vector3::repeat(half) };
    if above_table {
        search.min.z = search.min.z.max(0.0);
        if search.max.z <= search.min.z {
            return Err(HullError::Volume("every camera is below the table (z < 0)".to_owned()));
        }
    }
    let radii: Vec<f64> = rig.cameras.iter().map(|c| c.distortion.monotonic_radius()).collect();
    let none = || HullError::Volume(format!("no point above the table is seen by {k} of the rig's cameras"));
    let (first, _) = sample(rig, &radii, &search, SEARCH_SAMPLES, k).ok_or_else(none)?;
    let clipped = Aabb { min: first.min.sup(&search.min), max: first.max.inf(&search.max) };
    // Touching the search box means the seen region goes on beyond it; the table's plane is a
    // cut the caller asked for.
    let touches =
        |a: usize| clipped.max[a] >= search.max[a] || clipped.min[a] <= search.min[a] && !(a == 2 && above_table);
    let capped = (0..3).any(touches);
    let (mut aabb, samples_per_camera) = sample(rig, &radii, &clipped, REFINE_SAMPLES, k).ok_or_else(none)?;
    if above_table {
        aabb.min.z = aabb.min.z.max(0.0);
    }
    aabb.min = aabb.min.sup(&search.min);
    aabb.max = aabb.max.inf(&search.max);
    aabb.check()?;
    Ok(SeenVolume { aabb, min_views: k, capped, samples_per_camera })
}
