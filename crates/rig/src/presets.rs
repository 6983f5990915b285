//! Rigs other than the default one, so that nothing is tuned to one geometry: an eight-camera
//! 1280x720 lab rig ([`lab8_rig`]) and seeded random rigs ([`random_rig`]), chosen by name with
//! [`RigPreset`].

use nalgebra::{Point3, Vector3};

use crate::{Camera, Distortion, Rig, WorldFrame, default_rig};

/// The world frame of the synthetic rigs: the table's.
const TABLE_FRAME: &str = "table: origin at the table top's centre, z up";

/// The eight-camera rig: 1280x720 cameras at different distances (0.45 to 1.2 m) and focal lengths
/// (650 to 1500 px), one looking straight down from 1 m above the table, one wide-angle with strong
/// barrel distortion (k1 = -0.32), the others on a ring at 12° to 45° of elevation, each aimed at
/// its own point near the working area (a lab's cameras never share one exact target).
pub fn lab8_rig() -> Rig {
    // (azimuth°, horizontal distance m, height m, fx, fy, cx, cy, k1, k2, p1, p2, k3, target x, y, z)
    #[rustfmt::skip]
    let specs: [[f64; 15]; 7] = [
        [  5.0, 0.70, 0.40, 1100.0, 1101.5, 641.2, 358.7, -0.060,  0.020,  1.0e-4, -2.0e-4, 0.0,  0.01,  0.00, 0.08],
        [ 52.0, 1.10, 0.55, 1500.0, 1498.0, 636.8, 362.4, -0.030,  0.010, -0.5e-4,  1.0e-4, 0.0, -0.01,  0.02, 0.10],
        [ 98.0, 0.55, 0.30,  800.0,  801.2, 644.1, 355.9, -0.110,  0.050,  2.0e-4,  0.5e-4, 0.0,  0.00, -0.01, 0.07],
        [141.0, 0.90, 0.72, 1250.0, 1248.3, 638.5, 361.1, -0.050,  0.015, -1.5e-4, -1.0e-4, 0.0,  0.02,  0.01, 0.09],
        [188.0, 0.78, 0.22,  950.0,  952.0, 642.7, 359.3, -0.080,  0.030,  0.8e-4,  1.2e-4, 0.0, -0.02,  0.00, 0.08],
        [236.0, 1.00, 0.62, 1350.0, 1351.1, 639.9, 357.6, -0.040,  0.012,  1.1e-4, -0.7e-4, 0.0,  0.00,  0.02, 0.11],
        [300.0, 0.45, 0.45,  650.0,  649.0, 640.5, 360.8, -0.320,  0.120,  0.0,     0.0,   -0.020, 0.00,  0.00, 0.08],
    ];
    let mut cameras: Vec<Camera> = specs
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let a = s[0].to_radians();
            let eye = Point3::new(s[1] * a.cos(), s[1] * a.sin(), s[2]);
            let mut cam = Camera::new(format!("cam{i}"), 1280, 720, s[3], s[4], s[5], s[6]);
            cam.distortion = Distortion { k1: s[7], k2: s[8], p1: s[9], p2: s[10], k3: s[11] };
            cam.looking_at(eye, Point3::new(s[12], s[13], s[14]), Vector3::z())
        })
        .collect();
    // Straight down from 1 m, image "up" toward +y.
    let mut top = Camera::new("cam7", 1280, 720, 1000.0, 1000.0, 640.0, 360.0);
    top.distortion = Distortion { k1: -0.070, k2: 0.025, p1: 0.0, p2: 0.0, k3: 0.0 };
    if let Some(top) = top.looking_at(Point3::new(0.02, -0.03, 1.0), Point3::new(0.0, 0.0, 0.08), Vector3::y()) {
        cameras.push(top);
    }
    Rig::new(cameras, WorldFrame::Table(TABLE_FRAME.to_owned()))
}

/// splitmix64's finalizer: a cheap, well-distributed hash.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Image sizes a random rig draws from.
const SIZES: [(u32, u32); 4] = [(640, 480), (800, 600), (960, 540), (1280, 720)];

/// A seeded random rig: 4 to 9 cameras spread around the table (jittered azimuths), 0.5 to 1.2 m
/// away at 15° to 55° of elevation, image sizes from 640x480 to 1280x720, focal lengths that make a
/// 0.3 m working area fill 40% to 70% of the short side, barrel distortion from none to strong
/// (k1 down to -0.25), aimed within 3 cm of a point 8 cm above the table. The same seed gives the
/// same rig.
pub fn random_rig(seed: u64) -> Rig {
    let mut state = mix(seed ^ 0x005e_ed0f_2196);
    let mut uniform = move |lo: f64, hi: f64| {
        state = mix(state);
        lo + (hi - lo) * ((state >> 11) as f64 / (1u64 << 53) as f64)
    };
    let n = 4 + (uniform(0.0, 6.0) as usize).min(5);
    let phase = uniform(0.0, 360.0);
    let cameras = (0..n)
        .filter_map(|i| {
            let az = (phase + 360.0 * i as f64 / n as f64 + uniform(-15.0, 15.0)).to_radians();
            let dist = uniform(0.5, 1.2);
            let elevation = uniform(15.0, 55.0).to_radians();
            let eye = Point3::new(
                dist * elevation.cos() * az.cos(),
                dist * elevation.cos() * az.sin(),
                0.08 + dist * elevation.sin(),
            );
            let (w, h) = SIZES[(uniform(0.0, 4.0) as usize).min(3)];
            let f = uniform(0.4, 0.7) * f64::from(h) * dist / 0.3;
            let mut cam = Camera::new(
                format!("cam{i}"),
                w,
                h,
                f,
                f * uniform(0.998, 1.002),
                (f64::from(w) - 1.0) / 2.0 + uniform(-8.0, 8.0),
                (f64::from(h) - 1.0) / 2.0 + uniform(-8.0, 8.0),
            );
            let k1 = uniform(-0.25, 0.0);
            cam.distortion = Distortion {
                k1,
                k2: -0.3 * k1 * uniform(0.0, 1.0),
                p1: uniform(-2e-4, 2e-4),
                p2: uniform(-2e-4, 2e-4),
                k3: 0.0,
            };
            let target = Point3::new(uniform(-0.03, 0.03), uniform(-0.03, 0.03), 0.08 + uniform(-0.02, 0.02));
            cam.looking_at(eye, target, Vector3::z())
        })
        .collect();
    Rig::new(cameras, WorldFrame::Table(TABLE_FRAME.to_owned()))
}

/// A rig chosen by name: `default` (six 640x480 cameras), `lab8` (eight 1280x720 cameras) or
/// `random:SEED`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigPreset {
    /// [`default_rig`].
    Default,
    /// [`lab8_rig`].
    Lab8,
    /// [`random_rig`] with this seed.
    Random(u64),
}

impl RigPreset {
    /// The names `parse` accepts, for help texts.
    pub const NAMES: &'static str = "default, lab8, random:SEED";

    /// Parses `default`, `lab8` or `random:SEED`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "default" => Some(Self::Default),
            "lab8" => Some(Self::Lab8),
            _ => s.strip_prefix("random:").and_then(|n| n.parse().ok()).map(Self::Random),
        }
    }

    /// The preset's name, as `parse` reads it.
    pub fn name(&self) -> String {
        match self {
            Self::Default => "default".to_owned(),
            Self::Lab8 => "lab8".to_owned(),
            Self::Random(seed) => format!("random:{seed}"),
        }
    }

    /// The rig.
    pub fn rig(&self) -> Rig {
        match self {
            Self::Default => default_rig(),
            Self::Lab8 => lab8_rig(),
            Self::Random(seed) => random_rig(*seed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every camera of a rig sees a 0.2 m cube around the working area's centre (8 cm above the
    /// table) whole: the scenes' hand and tool stay in it.
    fn sees_the_working_area(rig: &Rig) {
        for cam in &rig.cameras {
            for k in 0..8 {
                let p = Point3::new(
                    if k & 1 == 0 { -0.1 } else { 0.1 },
                    if k & 2 == 0 { -0.1 } else { 0.1 },
                    if k & 4 == 0 { 0.0 } else { 0.2 },
                );
                let proj = cam.project(&p);
                assert!(proj.visible, "{} misses ({:.2}, {:.2}, {:.2}): {:?}", cam.name, p.x, p.y, p.z, proj.pixel);
            }
        }
    }

    #[test]
    fn lab8_has_eight_hd_cameras_one_overhead_one_strongly_distorted() {
        let rig = lab8_rig();
        assert_eq!(rig.len(), 8);
        assert!(rig.cameras.iter().all(|c| (c.width, c.height) == (1280, 720)));
        let down = rig.cameras.iter().filter(|c| c.viewing_direction().z < -0.99).count();
        assert_eq!(down, 1, "one camera looks straight down");
        assert!(rig.cameras.iter().any(|c| c.distortion.k1 <= -0.3));
        sees_the_working_area(&rig);
    }

    #[test]
    fn random_rigs_are_seeded_and_see_the_working_area() {
        assert_eq!(random_rig(7), random_rig(7));
        assert_ne!(random_rig(7), random_rig(8));
        for seed in 0..20 {
            let rig = random_rig(seed);
            assert!((4..=9).contains(&rig.len()), "seed {seed}: {} cameras", rig.len());
            sees_the_working_area(&rig);
        }
    }

    #[test]
    fn presets_parse_their_names() {
        for p in [RigPreset::Default, RigPreset::Lab8, RigPreset::Random(42)] {
            assert_eq!(RigPreset::parse(&p.name()), Some(p));
        }
        assert_eq!(RigPreset::parse("random:x"), None);
        assert_eq!(RigPreset::parse("lab9"), None);
    }
}
