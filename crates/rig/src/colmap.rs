//! COLMAP's text model (`cameras.txt`, `images.txt`), read into a [`Rig`] and written from one.
//!
//! Conventions (COLMAP's documentation, "Output format"):
//! - `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`. Read: `SIMPLE_PINHOLE` (f, cx, cy),
//!   `PINHOLE` (fx, fy, cx, cy), `SIMPLE_RADIAL` (f, cx, cy, k), `RADIAL` (f, cx, cy, k1, k2),
//!   `OPENCV` (fx, fy, cx, cy, k1, k2, p1, p2) and `FULL_OPENCV` (… k3, k4, k5, k6) when its
//!   rational terms k4..k6 are zero; any other model is refused, naming it and its line.
//! - `images.txt`: two lines per image, `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` then its 2-D
//!   points (ignored). The pose is world → camera (`x_cam = R(q) x_world + t`), with OpenCV's camera
//!   axes (x right, y down, z forward): ours.
//! - Pixels: COLMAP puts the centre of the top-left pixel at (0.5, 0.5), hullcut at (0, 0), so the
//!   principal point moves by half a pixel each way.
//! - Units: a COLMAP model's scale is whatever its reconstruction fixed; `scale` (metres per model
//!   unit) multiplies its translations. The world frame is the model's.
//!
//! One rig camera per image: a multi-camera rig's model has one image per camera. The camera's name
//! is the image's folder (`cam0/000000.png` → `cam0`) or, for an image at the top level, its file
//! stem (`cam0.png` → `cam0`); cameras come in natural order of name (cam2 before cam10).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Read as _;
use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::limits::check_camera;
use crate::{Camera, Distortion, MAX_CAMERAS, Rig, RigError, WorldFrame, shorten};

/// Largest file of a COLMAP text model read, bytes (a rig's model is a few kilobytes; points
/// lines of a large reconstruction are skipped line by line, never held whole beyond this).
const MAX_FILE_BYTES: u64 = 256 << 20;

/// Camera models this reader accepts, for error messages.
pub const SUPPORTED_MODELS: &str = "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV (k4..k6 = 0)";

struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    distortion: Distortion,
}

impl Intrinsics {
    /// A camera with these intrinsics at the world origin, named `name`.
    fn camera(&self, name: String) -> Camera {
        let mut cam = Camera::new(name, self.width, self.height, self.fx, self.fy, self.cx, self.cy);
        cam.distortion = self.distortion;
        cam
    }
}

/// Reads a text file of at most [`MAX_FILE_BYTES`] (reading stops there, so a device or a growing
/// file cannot make it read forever).
fn read_text(path: &Path) -> Result<String, RigError> {
    let read = |error| RigError::Read { path: path.to_owned(), error };
    let file = std::fs::File::open(path).map_err(read)?;
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1).read_to_end(&mut bytes).map_err(read)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(RigError::TooLarge { file: path.display().to_string(), limit: MAX_FILE_BYTES });
    }
    String::from_utf8(bytes).map_err(|e| {
        read(std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {}", e.utf8_error())))
    })
}

/// The lines of a COLMAP text file with their 1-based numbers, comments and blank lines skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn invalid(file: &Path, line: usize, message: impl Into<String>) -> RigError {
    RigError::Invalid { file: file.display().to_string(), key: format!("line {line}"), message: message.into() }
}

fn numbers(file: &Path, line: usize, fields: &[&str]) -> Result<Vec<f64>, RigError> {
    fields
        .iter()
        .map(|f| {
            let v: f64 = f.parse().map_err(|_| invalid(file, line, format!("`{}` is not a number", shorten(f))))?;
            if !v.is_finite() {
                return Err(invalid(file, line, format!("`{}` is not finite", shorten(f))));
            }
            Ok(v)
        })
        .collect()
}

fn parse_cameras(path: &Path) -> Result<BTreeMap<u64, Intrinsics>, RigError> {
    let text = read_text(path)?;
    let mut out = BTreeMap::new();
    for (n, line) in data_lines(&text) {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 4 {
            return Err(invalid(path, n, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]"));
        }
        let id: u64 =
            f[0].parse().map_err(|_| invalid(path, n, format!("camera id `{}` is not a number", shorten(f[0]))))?;
        let size = |s: &str| -> Result<u32, RigError> {
            s.parse::<u32>().ok().filter(|&v| v > 0 && v <= crate::MAX_IMAGE_SIDE).ok_or_else(|| {
                invalid(
                    path,
                    n,
                    format!("image size `{}` is not a whole number in 1..={}", shorten(s), crate::MAX_IMAGE_SIDE),
                )
            })
        };
        let (width, height) = (size(f[2])?, size(f[3])?);
        let p = numbers(path, n, &f[4..])?;
        let model = f[1].to_owned();
        let expected = match model.as_str() {
            "SIMPLE_PINHOLE" => 3,
            "PINHOLE" | "SIMPLE_RADIAL" => 4,
            "RADIAL" => 5,
            "OPENCV" => 8,
            "FULL_OPENCV" => 12,
            other => {
                return Err(invalid(
                    path,
                    n,
                    format!("camera model `{}` is not supported (supported: {SUPPORTED_MODELS})", shorten(other)),
                ));
            }
        };
        if p.len() != expected {
            return Err(invalid(path, n, format!("{model} takes {expected} parameters, found {}", p.len())));
        }
        let none = Distortion::NONE;
        let (fx, fy, cx, cy, distortion) = match model.as_str() {
            "SIMPLE_PINHOLE" => (p[0], p[0], p[1], p[2], none),
            "PINHOLE" => (p[0], p[1], p[2], p[3], none),
            "SIMPLE_RADIAL" => (p[0], p[0], p[1], p[2], Distortion { k1: p[3], ..none }),
            "RADIAL" => (p[0], p[0], p[1], p[2], Distortion { k1: p[3], k2: p[4], ..none }),
            "OPENCV" => (p[0], p[1], p[2], p[3], Distortion { k1: p[4], k2: p[5], p1: p[6], p2: p[7], k3: 0.0 }),
            _ => {
                if p[9] != 0.0 || p[10] != 0.0 || p[11] != 0.0 {
                    return Err(invalid(
                        path,
                        n,
                        "FULL_OPENCV with rational terms (k4, k5, k6 not zero) is not supported: hullcut's lens model \
                         is OpenCV's five-coefficient one",
                    ));
                }
                (p[0], p[1], p[2], p[3], Distortion { k1: p[4], k2: p[5], p1: p[6], p2: p[7], k3: p[8] })
            }
        };
        if out.len() >= MAX_CAMERAS * 16 {
            return Err(invalid(path, n, format!("more than {} cameras, too many for a rig", MAX_CAMERAS * 16)));
        }
        // COLMAP's top-left pixel centre is (0.5, 0.5); ours is (0, 0).
        let intrinsics = Intrinsics { width, height, fx, fy, cx: cx - 0.5, cy: cy - 0.5, distortion };
        check_camera(&intrinsics.camera(String::new())).map_err(|p| invalid(path, n, p.message))?;
        out.insert(id, intrinsics);
    }
    Ok(out)
}

/// The rig camera an image belongs to: its folder, or its file stem at the top level.
fn camera_name(image: &str) -> String {
    let path = Path::new(image);
    match path.parent().and_then(|p| p.components().next()) {
        Some(first) => first.as_os_str().to_string_lossy().into_owned(),
        None => path.file_stem().map_or_else(|| image.to_owned(), |s| s.to_string_lossy().into_owned()),
    }
}

/// Reads a COLMAP text model (the folder holding `cameras.txt` and `images.txt`) as a rig, its
/// translations multiplied by `scale` (metres per model unit). See the module docs.
pub fn read_colmap(dir: &Path, scale: f64) -> Result<Rig, RigError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(RigError::Invalid {
            file: dir.display().to_string(),
            key: "scale".to_owned(),
            message: format!("must be a positive number of metres per model unit, got {}", crate::short_number(scale)),
        });
    }
    let cameras_path = dir.join("cameras.txt");
    let images_path = dir.join("images.txt");
    let intrinsics = parse_cameras(&cameras_path)?;
    let text = read_text(&images_path)?;
    let mut cameras: Vec<(String, usize, Camera)> = Vec::new();
    // Every other data line is an image's 2-D points (possibly empty, so blank lines count here).
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.starts_with('#'));
    while let Some((n, line)) = lines.next() {
        if line.is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 {
            return Err(invalid(&images_path, n, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME"));
        }
        let v = numbers(&images_path, n, &f[1..8])?;
        let camera_id: u64 = f[8]
            .parse()
            .map_err(|_| invalid(&images_path, n, format!("camera id `{}` is not a number", shorten(f[8]))))?;
        let name_field = f[9..].join(" ");
        let Some(k) = intrinsics.get(&camera_id) else {
            return Err(invalid(&images_path, n, format!("camera {camera_id} is not in {}", cameras_path.display())));
        };
        let q = Quaternion::new(v[0], v[1], v[2], v[3]);
        let norm = q.norm();
        if (norm - 1.0).abs() >= 1e-3 || norm.is_nan() {
            return Err(invalid(&images_path, n, format!("the rotation quaternion has length {norm}, not 1")));
        }
        let rotation = UnitQuaternion::from_quaternion(q).to_rotation_matrix();
        let name = camera_name(&name_field);
        if name.is_empty() {
            return Err(invalid(&images_path, n, "the image name gives no camera name"));
        }
        if let Some((_, first, _)) = cameras.iter().find(|(c, _, _)| *c == name) {
            return Err(invalid(
                &images_path,
                n,
                format!(
                    "a second image of camera `{}` (the first on line {first}): a rig's model has one image per camera",
                    shorten(&name)
                ),
            ));
        }
        if cameras.len() >= MAX_CAMERAS {
            return Err(invalid(&images_path, n, format!("more than {MAX_CAMERAS} cameras")));
        }
        let mut cam = k.camera(name.clone());
        cam.rotation = rotation;
        cam.translation = Vector3::new(v[4], v[5], v[6]) * scale;
        check_camera(&cam)
            .map_err(|p| invalid(&images_path, n, format!("camera `{}`: {}", shorten(&name), p.message)))?;
        cameras.push((name, n, cam));
        // The image's 2-D points.
        lines.next();
    }
    if cameras.is_empty() {
        return Err(RigError::Invalid {
            file: images_path.display().to_string(),
            key: "IMAGE_ID lines".to_owned(),
            message: "no images: nothing to make cameras of".to_owned(),
        });
    }
    cameras.sort_by(|a, b| crate::natural_cmp(&a.0, &b.0));
    let frame = WorldFrame::Other(format!("colmap model {} (scale {scale} m per unit)", dir.display()));
    Ok(Rig::new(cameras.into_iter().map(|(_, _, c)| c).collect(), frame))
}

/// Writes a rig as a COLMAP text model in `dir` (`cameras.txt`, `images.txt`, an empty
/// `points3D.txt`): one camera and one image (`NAME.png`) per rig camera, `OPENCV` cameras, or
/// `FULL_OPENCV` where k3 is not zero; translations divided by `scale` (metres per model unit).
pub fn write_colmap(rig: &Rig, dir: &Path, scale: f64) -> Result<(), RigError> {
    let io = |path: std::path::PathBuf| move |error: std::io::Error| RigError::Write { path, error };
    std::fs::create_dir_all(dir).map_err(io(dir.to_owned()))?;
    let mut cameras = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let mut images = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    for (i, c) in rig.cameras.iter().enumerate() {
        let id = i + 1;
        let d = &c.distortion;
        let (cx, cy) = (c.cx + 0.5, c.cy + 0.5);
        let mut params = vec![c.fx, c.fy, cx, cy, d.k1, d.k2, d.p1, d.p2];
        let model = if d.k3 == 0.0 {
            "OPENCV"
        } else {
            params.extend([d.k3, 0.0, 0.0, 0.0]);
            "FULL_OPENCV"
        };
        let p: Vec<String> = params.iter().map(|v| format!("{v:.17e}")).collect();
        let _ = writeln!(cameras, "{id} {model} {} {} {}", c.width, c.height, p.join(" "));
        let q = UnitQuaternion::from_rotation_matrix(&c.rotation);
        let t = c.translation / scale;
        let _ = writeln!(
            images,
            "{id} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {id} {}.png\n",
            q.w, q.i, q.j, q.k, t.x, t.y, t.z, c.name
        );
    }
    for (file, text) in
        [("cameras.txt", cameras), ("images.txt", images), ("points3D.txt", "# 3D point list (none)\n".to_owned())]
    {
        let path = dir.join(file);
        std::fs::write(&path, text).map_err(io(path.clone()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_names_give_camera_names() {
        assert_eq!(camera_name("cam3/000012.png"), "cam3");
        assert_eq!(camera_name("left.jpg"), "left");
        assert_eq!(camera_name("rig/cam3/x.png"), "rig");
    }
}
