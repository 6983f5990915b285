//! The default six-camera rig of the synthetic scenes (`calibration/default-rig.yaml`).

use nalgebra::{Point3, Vector3};

use crate::{Camera, Distortion, Rig, WorldFrame};

/// Point every default camera looks at: 15 cm above the table's centre.
pub const DEFAULT_TARGET: [f64; 3] = [0.0, 0.0, 0.15];

/// Side of the cubic workspace the default rig covers, metres (x, y in ±0.2, z in 0..0.4).
pub const DEFAULT_WORKSPACE: f64 = 0.4;

/// The default rig: six 640x480 cameras on a ring around a 0.4 m workspace above a table at z = 0,
/// at mixed elevations (about 20° to 40° above the horizontal), 0.9 to 1.1 m from the target, each with its own focal length, principal point and a
/// realistic mild barrel distortion. The world frame is the table's (z up, origin at its centre).
pub fn default_rig() -> Rig {
    // (azimuth°, horizontal distance m, height m, fx, fy, cx, cy, k1, k2, p1, p2)
    #[rustfmt::skip]
    let specs: [[f64; 11]; 6] = [
        [15.0,  0.84, 0.45, 602.0, 600.5, 321.3, 238.2, -0.110, 0.060,  2.0e-4, -1.5e-4],
        [75.0,  0.90, 0.75, 596.5, 597.8, 318.9, 241.6, -0.085, 0.042, -1.2e-4,  3.0e-4],
        [135.0, 0.86, 0.38, 605.2, 604.1, 322.4, 236.7, -0.120, 0.075,  1.0e-4,  1.0e-4],
        [195.0, 0.82, 0.62, 598.8, 599.9, 317.6, 242.9, -0.095, 0.050, -2.5e-4, -0.8e-4],
        [255.0, 0.89, 0.50, 600.9, 601.7, 320.8, 239.4, -0.105, 0.058,  0.6e-4,  2.2e-4],
        [315.0, 0.84, 0.80, 603.6, 602.2, 319.5, 240.8, -0.080, 0.038, -0.9e-4, -2.0e-4],
    ];
    let target = Point3::from(DEFAULT_TARGET);
    let cameras = specs
        .iter()
        .enumerate()
        .filter_map(|(i, &[az, dist, height, fx, fy, cx, cy, k1, k2, p1, p2])| {
            let a = az.to_radians();
            let eye = Point3::new(dist * a.cos(), dist * a.sin(), height);
            let mut cam = Camera::new(format!("cam{i}"), 640, 480, fx, fy, cx, cy);
            cam.distortion = Distortion { k1, k2, p1, p2, k3: 0.0 };
            cam.looking_at(eye, target, Vector3::z())
        })
        .collect();
    Rig::new(cameras, WorldFrame::Table("table: origin at the table top's centre, z up".to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_camera_sees_the_whole_workspace() {
        let rig = default_rig();
        assert_eq!(rig.len(), 6);
        let h = DEFAULT_WORKSPACE / 2.0;
        for cam in &rig.cameras {
            for &x in &[-h, h] {
                for &y in &[-h, h] {
                    for &z in &[0.0, DEFAULT_WORKSPACE] {
                        let p = cam.project(&Point3::new(x, y, z));
                        assert!(p.visible, "{} misses workspace corner ({x}, {y}, {z}): {:?}", cam.name, p.pixel);
                    }
                }
            }
        }
    }
}
