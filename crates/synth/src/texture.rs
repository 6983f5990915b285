//! The static background: a table covered by a green surgical drape, the floor beyond it and the
//! room's walls, as albedo functions of world position or direction. Deterministic, no state.

use nalgebra::{Point3, Vector3};

/// Half extent of the table top along x and y, metres (a 1.2 x 0.9 m table).
pub const TABLE_HALF: [f64; 2] = [0.6, 0.45];
/// Height of the floor below the table top, metres.
pub const FLOOR_Z: f64 = -0.75;

/// Drape albedo (linear 0..1 per channel).
const DRAPE: [f32; 3] = [40.0 / 255.0, 110.0 / 255.0, 70.0 / 255.0];
/// Floor albedo.
const FLOOR: [f32; 3] = [95.0 / 255.0, 90.0 / 255.0, 85.0 / 255.0];
/// Wall colour (already lit).
const WALL: [f32; 3] = [120.0 / 255.0, 130.0 / 255.0, 140.0 / 255.0];

/// A 64-bit mix (splitmix64's finalizer): a cheap, well-distributed hash.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Smooth value noise in [-1, 1] with unit lattice spacing.
pub(crate) fn value_noise(x: f64, y: f64, salt: u64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (fx, fy) = (x - xf, y - yf);
    let (ix, iy) = (xf as i64, yf as i64);
    let corner = |dx: i64, dy: i64| {
        let h = mix64(salt ^ mix64(((ix + dx) as u64).wrapping_mul(0x9e37_79b9) ^ ((iy + dy) as u64) << 32));
        (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let sx = fx * fx * (3.0 - 2.0 * fx);
    let sy = fy * fy * (3.0 - 2.0 * fy);
    let top = corner(0, 0) + (corner(1, 0) - corner(0, 0)) * sx;
    let bottom = corner(0, 1) + (corner(1, 1) - corner(0, 1)) * sx;
    top + (bottom - top) * sy
}

/// What a background ray hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BackgroundHit {
    /// A horizontal surface (table or floor) at ray parameter `s` with this albedo.
    Surface {
        /// Ray parameter of the hit.
        s: f64,
        /// Albedo at the hit.
        albedo: [f32; 3],
    },
    /// The walls: a colour already lit, and no depth.
    Wall([f32; 3]),
}

/// Traces a ray `origin + s * direction` against the table (the green drape), the floor and the
/// walls.
pub fn trace_background(origin: &Point3<f64>, direction: &Vector3<f64>) -> BackgroundHit {
    trace_background_on(origin, direction, &crate::Background::Drape)
}

/// The table position a ray hits, if it hits the table top.
pub fn table_hit(origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<(f64, f64)> {
    if direction.z >= -1e-12 {
        return None;
    }
    let p = origin + direction * (-origin.z / direction.z);
    (p.x.abs() <= TABLE_HALF[0] && p.y.abs() <= TABLE_HALF[1]).then_some((p.x, p.y))
}

/// Traces a ray against a table covered by `table`, the floor and the walls.
pub fn trace_background_on(origin: &Point3<f64>, direction: &Vector3<f64>, table: &crate::Background) -> BackgroundHit {
    if direction.z < -1e-12 {
        let s = -origin.z / direction.z;
        if let Some((x, y)) = table_hit(origin, direction) {
            return BackgroundHit::Surface { s, albedo: table.albedo(x, y) };
        }
        let s = (FLOOR_Z - origin.z) / direction.z;
        let p = origin + direction * s;
        let n = 1.0 + 0.12 * value_noise(p.x / 0.05, p.y / 0.05, 7);
        return BackgroundHit::Surface { s, albedo: FLOOR.map(|c| c * n as f32) };
    }
    let elevation = direction.z / direction.norm();
    let azimuth = direction.y.atan2(direction.x);
    let n = 1.0 + 0.06 * value_noise(azimuth * 20.0, elevation * 20.0, 11) + 0.1 * elevation;
    BackgroundHit::Wall(WALL.map(|c| c * n as f32))
}

/// Albedo of the drape at table position (x, y): cloth mottling at 1 and 3.5 cm, a fine weave and
/// soft folds.
pub fn drape_albedo(x: f64, y: f64) -> [f32; 3] {
    let mottle = 0.10 * value_noise(x / 0.01, y / 0.01, 3) + 0.07 * value_noise(x / 0.035, y / 0.035, 5);
    let weave = 0.05 * (std::f64::consts::TAU * x / 0.003).sin() * (std::f64::consts::TAU * y / 0.003).sin();
    let fold = 0.08 * ((std::f64::consts::TAU * (x * 0.8 + y * 0.6) / 0.15).sin()).powi(2);
    let f = (1.0 + mottle + weave - fold) as f32;
    DRAPE.map(|c| c * f)
}
