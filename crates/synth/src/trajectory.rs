//! Tool trajectories: approach, press into the (virtual) organ on the table, cut strokes of varied
//! speed, depth and angle, lift; repeated with new parameters drawn from the seed.
//!
//! A pose is given by the blade tip's world position and three angles: the stroke's azimuth (the
//! blade plane is vertical and contains the stroke direction), the pitch of the tool axis below the
//! horizontal (tip lowest), and a roll of the blade about the tool axis. Between keyframes every
//! quantity follows a smoothstep, so velocity is continuous and the peak speed of a stroke is 1.5x
//! its mean.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};

use crate::scalpel::ToolKind;

/// Height of the top of the virtual organ resting on the table (a 6 cm thick liver), metres.
pub const ORGAN_TOP: f64 = 0.06;

/// What a scene does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneKind {
    /// Cut strokes at moderate speed (up to about 0.2 m/s), every camera delivering every frame.
    Cut,
    /// The tool held still in the organ, for accuracy averaged over frames.
    Static,
    /// Fast strokes (peaks of 0.5 m/s) with the blade edge-on to two cameras, the index finger over
    /// the blade, motion blur, strong exposure changes and a camera dropping frames.
    Hard,
    /// A resection: two strokes along one line across the built-in organ's left lobe (x = 5.5 cm,
    /// along +y), the second down to the table, which cut its tip off; then strokes as in `Cut`.
    Resect,
}

impl SceneKind {
    /// Every scene with its command-line name.
    pub const ALL: [(SceneKind, &'static str); 4] = [
        (SceneKind::Cut, "cut"),
        (SceneKind::Static, "static"),
        (SceneKind::Hard, "hard"),
        (SceneKind::Resect, "resect"),
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(k, _)| *k == self).map_or("cut", |(_, n)| n)
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<SceneKind> {
        Self::ALL.iter().find(|(_, n)| *n == name).map(|(k, _)| *k)
    }
}

/// One keyframe of the tool's motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Key {
    /// Time, seconds from the start of the recording.
    pub time: f64,
    /// Blade tip, world metres.
    pub tip: Point3<f64>,
    /// Stroke azimuth, radians (direction of travel in the table plane).
    pub azimuth: f64,
    /// Tool axis below the horizontal, radians.
    pub pitch: f64,
    /// Blade roll about the tool axis, radians.
    pub roll: f64,
    /// Hand grip in [0, 1] (see [`crate::hand_mesh`]).
    pub grip: f64,
}

/// The tool's state at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolState {
    /// Tool frame → world frame.
    pub tool_to_world: Isometry3<f64>,
    /// Hand grip in [0, 1].
    pub grip: f64,
}

/// How the resection of [`SceneKind::Resect`] holds the blade: its pitch and the first pass's
/// height. Both passes run along one line across the left lobe (x = 5.5 cm, along +y, 10 cm/s),
/// the second with the tip 2 mm below the table; the first must be high enough that its cutting
/// edge reaches past the lobe's 35 mm (lattice included), and low enough that the two passes'
/// edges overlap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resection {
    /// The tool axis below the horizontal, degrees.
    pub pitch_deg: f64,
    /// The first pass's tip above the table, metres.
    pub first_pass_m: f64,
}

impl Resection {
    /// The resection for a tool. The standard blade's curved edge rises 26 mm above the tip at
    /// 60°: a first pass at 12 mm reaches 38 mm. The pointed No. 11 blade's straight edge rises
    /// only 21 mm at 60° (a first pass at 12 mm reached 33 mm: the true poses left the lobe
    /// joined by its top at 6 mm cells), so it is held steeper, at 70° (24 mm), with the first
    /// pass at 16 mm: it reaches 40 mm and the passes overlap by 6 mm.
    pub fn for_tool(tool: ToolKind) -> Self {
        match tool {
            ToolKind::Standard => Resection { pitch_deg: 60.0, first_pass_m: 0.012 },
            ToolKind::Pointed => Resection { pitch_deg: 70.0, first_pass_m: 0.016 },
        }
    }
}

/// The resection of [`SceneKind::Resect`] from time 0 (see [`Resection`]). Returns the last key.
fn resection(keys: &mut Vec<Key>, hover: &dyn Fn(Point3<f64>) -> Point3<f64>, how: Resection) -> Key {
    const X: f64 = 0.055;
    let (y0, y1) = (-0.035, 0.055);
    let stroke_s = (y1 - y0) / 0.1;
    let at = |y: f64, z: f64| Point3::new(X, y, z);
    let above = ORGAN_TOP + 0.004;
    let base = Key {
        time: 0.0,
        tip: hover(at(y0, 0.0)),
        azimuth: std::f64::consts::FRAC_PI_2,
        pitch: how.pitch_deg.to_radians(),
        roll: 0.0,
        grip: 0.6,
    };
    let mut t = 0.0;
    keys.push(base);
    let mut go = |dt: f64, tip: Point3<f64>, grip: f64| {
        t += dt;
        keys.push(Key { time: t, tip, grip, ..base });
        Key { time: t, tip, grip, ..base }
    };
    go(0.6, at(y0, above), 0.85);
    for depth in [how.first_pass_m, -0.002] {
        go(0.35, at(y0, depth), 0.85);
        go(stroke_s, at(y1, depth), 0.85);
        go(0.35, at(y1, above), 0.85);
        if depth > 0.0 {
            go(0.5, at(y0, above), 0.85);
        }
    }
    go(0.6, hover(at(y1, 0.0)), 0.6)
}

/// A piecewise-smoothstep trajectory through keyframes.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    keys: Vec<Key>,
    tip_in_tool: Point3<f64>,
}

fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Rotation whose columns are the tool axes in world coordinates for the given angles.
pub fn tool_rotation(azimuth: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    let s = Vector3::new(azimuth.cos(), azimuth.sin(), 0.0);
    let up = Vector3::z();
    let x = s * pitch.cos() - up * pitch.sin();
    let y0 = s * pitch.sin() + up * pitch.cos();
    let z0 = x.cross(&y0);
    let y = y0 * roll.cos() + z0 * roll.sin();
    let z = x.cross(&y);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
}

impl Trajectory {
    /// A trajectory through `keys` (sorted by time) for a tool whose tip is at `tip_in_tool`.
    pub fn new(keys: Vec<Key>, tip_in_tool: Point3<f64>) -> Self {
        Trajectory { keys, tip_in_tool }
    }

    /// The same motion for an organ `s` times the built-in one's size: every key's tip position
    /// scaled about the origin (the organ's centre on the table), times and orientations kept.
    pub fn scaled(mut self, s: f64) -> Self {
        if s != 1.0 {
            for key in &mut self.keys {
                key.tip = Point3::from(key.tip.coords * s);
            }
        }
        self
    }

    /// The keyframes.
    pub fn keys(&self) -> &[Key] {
        &self.keys
    }

    /// The interpolated keyframe values at time `t` (clamped to the first and last key).
    pub fn key_at(&self, t: f64) -> Key {
        let keys = &self.keys;
        let Some(first) = keys.first() else {
            return Key { time: t, tip: Point3::origin(), azimuth: 0.0, pitch: 0.0, roll: 0.0, grip: 0.0 };
        };
        let i = keys.partition_point(|k| k.time <= t);
        if i == 0 {
            return *first;
        }
        if i == keys.len() {
            return keys[i - 1];
        }
        let (a, b) = (&keys[i - 1], &keys[i]);
        let w = smoothstep((t - a.time) / (b.time - a.time));
        let lerp = |p: f64, q: f64| p + (q - p) * w;
        Key {
            time: t,
            tip: a.tip + (b.tip - a.tip) * w,
            azimuth: lerp(a.azimuth, b.azimuth),
            pitch: lerp(a.pitch, b.pitch),
            roll: lerp(a.roll, b.roll),
            grip: lerp(a.grip, b.grip),
        }
    }

    /// The tool's pose and grip at time `t`.
    pub fn state_at(&self, t: f64) -> ToolState {
        let k = self.key_at(t);
        let rotation = tool_rotation(k.azimuth, k.pitch, k.roll);
        let origin = k.tip - rotation * self.tip_in_tool.coords;
        let tool_to_world =
            Isometry3::from_parts(Translation3::from(origin.coords), UnitQuaternion::from_rotation_matrix(&rotation));
        ToolState { tool_to_world, grip: k.grip }
    }

    /// The highest tip speed over `[0, duration]`, sampled every millisecond, m/s.
    pub fn peak_tip_speed(&self, duration: f64) -> f64 {
        let dt = 1e-3;
        let steps = (duration / dt).ceil() as usize;
        (0..steps)
            .map(|i| (self.key_at((i + 1) as f64 * dt).tip - self.key_at(i as f64 * dt).tip).norm() / dt)
            .fold(0.0, f64::max)
    }

    /// The trajectory of a scene, `duration` seconds long, deterministic for a seed; strokes press
    /// the tip `stroke_depth` (a range, metres) below [`ORGAN_TOP`]. `camera_azimuths` (degrees,
    /// the rig's cameras about the working area) are the directions the hard scene strokes along,
    /// edge-on to those cameras (the first three; the default rig's 15°, 75° and 135° without).
    pub fn for_scene(
        kind: SceneKind,
        seed: u64,
        duration: f64,
        tip_in_tool: Point3<f64>,
        stroke_depth: [f64; 2],
        camera_azimuths: &[f64],
    ) -> Self {
        let resection = Resection::for_tool(ToolKind::Standard);
        Self::for_scene_with(kind, seed, duration, tip_in_tool, stroke_depth, camera_azimuths, resection)
    }

    /// As [`Self::for_scene`], with the resection of a tool ([`Resection::for_tool`]).
    pub fn for_scene_with(
        kind: SceneKind,
        seed: u64,
        duration: f64,
        tip_in_tool: Point3<f64>,
        stroke_depth: [f64; 2],
        camera_azimuths: &[f64],
        how: Resection,
    ) -> Self {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x7a3c_91e5_0d42_b6f1);
        let deg = f64::to_radians;
        let mut keys = Vec::new();
        let hover = |tip: Point3<f64>| Point3::new(tip.x, tip.y, ORGAN_TOP + 0.12);
        match kind {
            SceneKind::Static => {
                let key = Key {
                    time: 0.0,
                    tip: Point3::new(0.01, -0.005, ORGAN_TOP - 0.012),
                    azimuth: deg(30.0),
                    pitch: deg(42.0),
                    roll: deg(6.0),
                    grip: 0.4,
                };
                keys.push(key);
                keys.push(Key { time: duration.max(1.0), ..key });
            }
            SceneKind::Cut | SceneKind::Hard | SceneKind::Resect => {
                let hard = kind == SceneKind::Hard;
                // A stroke along a camera's azimuth is edge-on to it (and to a camera opposite).
                let edge_on: Vec<f64> = match camera_azimuths {
                    [] => vec![15.0, 75.0, 135.0],
                    a => a.iter().take(3).copied().collect(),
                };
                let mut t = 0.0;
                let mut cycle = 0usize;
                let mut previous: Option<Key> = None;
                if kind == SceneKind::Resect {
                    let lifted = resection(&mut keys, &hover, how);
                    t = lifted.time;
                    previous = Some(lifted);
                }
                // Moves between strokes: quick in the hard scene, unhurried otherwise.
                let (transfer_s, approach_s, lift_s) = if hard { (0.7, 0.5, 0.45) } else { (1.0, 1.0, 1.0) };
                while t < duration + 1.0 {
                    let azimuth = if hard {
                        deg(edge_on[cycle % edge_on.len()] + rng.random_range(-2.0..2.0))
                    } else {
                        deg(rng.random_range(0.0..360.0))
                    };
                    let pitch = deg(rng.random_range(32.0..55.0));
                    let roll = if hard { 0.0 } else { deg(rng.random_range(-12.0..12.0)) };
                    let depth = rng.random_range(stroke_depth[0]..stroke_depth[1].max(stroke_depth[0] + 1e-9));
                    let length = if hard { 0.10 } else { rng.random_range(0.05..0.09) };
                    let mean_speed = if hard { 0.1 / 0.3 } else { rng.random_range(0.05..0.12) };
                    let grip = if hard { 1.0 } else { rng.random_range(0.1..0.7) };
                    let dir = Vector3::new(azimuth.cos(), azimuth.sin(), 0.0);
                    let centre = Point3::new(rng.random_range(-0.02..0.02), rng.random_range(-0.015..0.015), 0.0);
                    let start = centre - dir * (length / 2.0);
                    let entry = Point3::new(start.x, start.y, ORGAN_TOP + 0.004);
                    let pressed = Point3::new(start.x, start.y, ORGAN_TOP - depth);
                    let end = pressed + dir * length;
                    let base = Key { time: t, tip: hover(entry), azimuth, pitch, roll, grip };
                    match previous {
                        None => keys.push(base),
                        Some(prev) => {
                            // Turn toward the new stroke while moving over to it.
                            let mut az = azimuth;
                            while az - prev.azimuth > std::f64::consts::PI {
                                az -= std::f64::consts::TAU;
                            }
                            while az - prev.azimuth < -std::f64::consts::PI {
                                az += std::f64::consts::TAU;
                            }
                            t += transfer_s;
                            keys.push(Key { time: t, tip: hover(entry), azimuth: az, ..base });
                        }
                    }
                    let az = keys.last().map_or(azimuth, |k| k.azimuth);
                    let stroke_grip = if hard { 1.0 } else { (grip + 0.25).min(1.0) };
                    t += approach_s;
                    keys.push(Key { time: t, tip: entry, azimuth: az, grip: stroke_grip, ..base });
                    t += 0.35;
                    keys.push(Key { time: t, tip: pressed, azimuth: az, grip: stroke_grip, ..base });
                    t += length / mean_speed;
                    keys.push(Key { time: t, tip: end, azimuth: az, grip: stroke_grip, ..base });
                    t += lift_s;
                    let lifted = Key { time: t, tip: hover(end), azimuth: az, grip, ..base };
                    keys.push(lifted);
                    previous = Some(lifted);
                    cycle += 1;
                }
            }
        }
        Trajectory::new(keys, tip_in_tool)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::DEFAULT_STROKE_DEPTH;

    #[test]
    fn the_resection_reaches_the_table_twice_along_one_line_then_cuts_as_usual() {
        let tip = Point3::new(0.038, 0.003, 0.0);
        let tr = Trajectory::for_scene(SceneKind::Resect, 1, 8.0, tip, DEFAULT_STROKE_DEPTH, &[]);
        let tips: Vec<Point3<f64>> = (0..800).map(|i| tr.state_at(i as f64 * 0.01).tool_to_world * tip).collect();
        let low: Vec<&Point3<f64>> = tips[..400].iter().filter(|p| p.z < ORGAN_TOP - 0.02).collect();
        assert!(!low.is_empty());
        assert!(low.iter().all(|p| (p.x - 0.055).abs() < 1e-9), "one line across the left lobe");
        let deepest = low.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        assert!((deepest + 0.002).abs() < 1e-9, "down to 2 mm below the table: {deepest}");
        // Two passes: the tip crosses y = 0.01 (the lobe's centre line) low twice.
        let crossings =
            tips[..400].windows(2).filter(|w| w[0].z < 0.02 && (w[0].y - 0.01) * (w[1].y - 0.01) <= 0.0).count();
        assert_eq!(crossings, 2);
        // The quick descents to the table peak near 0.3 m/s; the strokes themselves at 0.15.
        assert!(tr.peak_tip_speed(8.0) < 0.35);
        assert!(tips[400..].iter().any(|p| p.x != 0.055 && p.z < ORGAN_TOP), "cut strokes follow");
    }

    #[test]
    fn the_resections_two_passes_cut_through_the_lobe_with_either_tools_edge() {
        // The lobe (35 mm, the lattice's top cells included); each pass's cutting edge spans a
        // height range above the tip, and the two ranges must join with room to spare (a few
        // millimetres of the fitted pose's error) and reach past the lobe's top.
        for (kind, name) in ToolKind::ALL {
            let geometry = crate::Scalpel::of(kind).geometry;
            let how = Resection::for_tool(kind);
            let tr =
                Trajectory::for_scene_with(SceneKind::Resect, 1, 8.0, geometry.tip, DEFAULT_STROKE_DEPTH, &[], how);
            let mut spans = Vec::new();
            for i in 0..400 {
                let (a, b) = (tr.state_at(i as f64 * 0.01), tr.state_at((i + 1) as f64 * 0.01));
                let (ta, tb) = (a.tool_to_world * geometry.tip, b.tool_to_world * geometry.tip);
                if ta.z < 0.02 && (ta.y - 0.01) * (tb.y - 0.01) <= 0.0 {
                    let z: Vec<f64> = geometry.cutting_edge.iter().map(|p| (a.tool_to_world * p).z).collect();
                    spans.push(z.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &z| (lo.min(z), hi.max(z))));
                }
            }
            assert_eq!(spans.len(), 2, "{name}: two passes");
            let (high, low) = (spans[0], spans[1]);
            assert!(low.0 < 0.0 && high.1 > 0.036, "{name}: {low:?} {high:?}");
            assert!(low.1 - high.0 > 0.004, "{name}: the passes overlap by {:.1} mm", (low.1 - high.0) * 1e3);
        }
    }

    #[test]
    fn tool_rotation_is_right_handed_with_the_tip_down_and_the_spine_up() {
        let r = tool_rotation(0.7, 0.6, 0.1);
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
        assert!((r.matrix().transpose() * r.matrix() - Matrix3::identity()).norm() < 1e-12);
        assert!((r * Vector3::x()).z < 0.0, "the tip points down");
        assert!((r * Vector3::y()).z > 0.0, "the spine points up, the cutting edge down");
    }

    #[test]
    fn tip_follows_keys_and_hard_strokes_peak_at_half_a_metre_per_second() {
        let tip = Point3::new(0.038, 0.003, 0.0);
        let tr = Trajectory::for_scene(SceneKind::Hard, 3, 6.0, tip, DEFAULT_STROKE_DEPTH, &[]);
        for k in tr.keys() {
            let s = tr.state_at(k.time);
            assert!((s.tool_to_world * tip - k.tip).norm() < 1e-12);
        }
        let peak = tr.peak_tip_speed(6.0);
        assert!((0.45..0.56).contains(&peak), "peak {peak} m/s");
        let cut = Trajectory::for_scene(SceneKind::Cut, 3, 6.0, tip, DEFAULT_STROKE_DEPTH, &[]);
        assert!(cut.peak_tip_speed(6.0) < 0.25);
        let still = Trajectory::for_scene(SceneKind::Static, 3, 6.0, tip, DEFAULT_STROKE_DEPTH, &[]);
        assert_eq!(still.peak_tip_speed(6.0), 0.0);
    }

    #[test]
    fn same_seed_same_trajectory() {
        let tip = Point3::new(0.038, 0.003, 0.0);
        assert_eq!(
            Trajectory::for_scene(SceneKind::Cut, 9, 5.0, tip, DEFAULT_STROKE_DEPTH, &[]),
            Trajectory::for_scene(SceneKind::Cut, 9, 5.0, tip, DEFAULT_STROKE_DEPTH, &[])
        );
        assert_ne!(
            Trajectory::for_scene(SceneKind::Cut, 9, 5.0, tip, DEFAULT_STROKE_DEPTH, &[]),
            Trajectory::for_scene(SceneKind::Cut, 10, 5.0, tip, DEFAULT_STROKE_DEPTH, &[])
        );
    }
}
