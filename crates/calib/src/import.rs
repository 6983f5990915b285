//! Calibrations made by other tools: a folder of per-camera OpenCV FileStorage files (YAML, XML or
//! JSON, as `cv::FileStorage` writes them), one camera per file, read with OpenCV itself.
//!
//! Each file holds (the first key found of each list is used):
//! - the intrinsic matrix: `camera_matrix`, `cameraMatrix`, `K`, `intrinsic` or `M` (3x3);
//! - the distortion: `distortion_coefficients`, `dist_coeffs`, `distCoeffs`, `D`, `dist` or
//!   `distortion` (4, 5 or more coefficients in OpenCV's order; beyond k3 they must be zero, as
//!   hullcut's lens model is OpenCV's five-coefficient one);
//! - the rotation, world → camera: `R`, `rotation_matrix` (3x3) or `rvec`, `rotation_vector`
//!   (Rodrigues, 3x1);
//! - the translation, world → camera: `T`, `t`, `tvec` or `translation_vector` (3x1), in the
//!   file's unit: `scale` (metres per unit) converts it, e.g. 0.001 for a calibration made with
//!   its board's squares in millimetres;
//! - the image size: `image_width` and `image_height`, `width` and `height`, or `image_size` /
//!   `imageSize` (width, height).
//!
//! The camera's name is the file's stem; cameras come in natural order (cam2 before cam10). The
//! world frame is whatever frame the files' extrinsics share.

use std::path::{Path, PathBuf};

use hullcut_rig::{Camera, Distortion, MAX_CAMERAS, MAX_IMAGE_SIDE, Rig, WorldFrame};
use nalgebra::{Matrix3, Rotation3, Vector3};
use opencv::core::{FileNode, FileNodeTraitConst, FileStorage, FileStorageTraitConst, Mat, MatTraitConst};
use opencv::prelude::MatTraitConstManual;

/// File extensions read as FileStorage files.
const EXTENSIONS: [&str; 4] = ["yml", "yaml", "xml", "json"];
/// Largest file read, bytes (a camera's calibration is a few kilobytes).
const MAX_FILE_BYTES: u64 = 1 << 20;
/// Largest accepted max |RᵀR − I| of a rotation matrix (files at six significant digits pass).
const ROTATION_TOLERANCE: f64 = 1e-5;

/// Why a calibration could not be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The folder cannot be listed, or holds no calibration files.
    #[error("{path}: {message}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A file is unreadable or a value in it is missing or wrong.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the key.
        message: String,
    },
    /// The cameras read are not a valid rig (a number out of its range; the error names the folder
    /// and the camera).
    #[error(transparent)]
    Rig(#[from] hullcut_rig::RigError),
}

fn file_error(path: &Path, message: impl Into<String>) -> ImportError {
    ImportError::File { path: path.to_owned(), message: message.into() }
}

/// The first of `keys` present in the file, with the key found.
fn node<'k>(fs: &FileStorage, path: &Path, keys: &[&'k str]) -> Result<Option<(&'k str, FileNode)>, ImportError> {
    for &k in keys {
        let n = fs.get(k).map_err(|e| file_error(path, format!("reading `{k}`: {e}")))?;
        if !n.is_none().unwrap_or(true) {
            return Ok(Some((k, n)));
        }
    }
    Ok(None)
}

/// A matrix node's values, row by row, as f64, with its shape.
fn matrix(path: &Path, key: &str, n: &FileNode) -> Result<(usize, usize, Vec<f64>), ImportError> {
    let bad = |m: String| file_error(path, format!("`{key}`: {m}"));
    let mat: Mat = n.mat().map_err(|e| bad(format!("not a matrix ({e})")))?;
    if mat.empty() {
        // A plain sequence of numbers (`[a, b, c]`, as JSON files and some tools write).
        if n.is_seq().unwrap_or(false) {
            let len = n.size().unwrap_or(0);
            if len == 0 || len > 64 {
                return Err(bad(format!("a sequence of {len} numbers")));
            }
            let mut v = Vec::with_capacity(len);
            for i in 0..len as i32 {
                let x = n.at(i).and_then(|x| x.real()).map_err(|e| bad(e.to_string()))?;
                v.push(x);
            }
            return finite(path, key, len, 1, v);
        }
        return Err(bad("empty".to_owned()));
    }
    let (rows, cols) = (mat.rows().max(0) as usize, mat.cols().max(0) as usize);
    if rows * cols > 64 || mat.channels() != 1 {
        return Err(bad(format!("a {rows}x{cols}x{} matrix", mat.channels())));
    }
    let mut as_f64 = Mat::default();
    mat.convert_to(&mut as_f64, opencv::core::CV_64F, 1.0, 0.0).map_err(|e| bad(e.to_string()))?;
    let v = as_f64.data_typed::<f64>().map_err(|e| bad(e.to_string()))?.to_vec();
    finite(path, key, rows, cols, v)
}

fn finite(
    path: &Path,
    key: &str,
    rows: usize,
    cols: usize,
    v: Vec<f64>,
) -> Result<(usize, usize, Vec<f64>), ImportError> {
    if v.iter().any(|x| !x.is_finite()) {
        return Err(file_error(path, format!("`{key}` holds a number that is not finite")));
    }
    Ok((rows, cols, v))
}

fn required<'k>(
    fs: &FileStorage,
    path: &Path,
    keys: &[&'k str],
    what: &str,
) -> Result<(&'k str, FileNode), ImportError> {
    node(fs, path, keys)?.ok_or_else(|| file_error(path, format!("no {what} (looked for {})", keys.join(", "))))
}

fn size_value(path: &Path, key: &str, n: &FileNode) -> Result<u32, ImportError> {
    let v = n.real().map_err(|e| file_error(path, format!("`{key}`: {e}")))?;
    if !(v >= 1.0 && v <= f64::from(MAX_IMAGE_SIDE) && v.fract() == 0.0) {
        return Err(file_error(path, format!("`{key}` = {v} is not an image size in 1..={MAX_IMAGE_SIDE}")));
    }
    Ok(v as u32)
}

fn image_size(fs: &FileStorage, path: &Path) -> Result<(u32, u32), ImportError> {
    for (w, h) in [("image_width", "image_height"), ("width", "height")] {
        if let (Some((kw, nw)), Some((kh, nh))) = (node(fs, path, &[w])?, node(fs, path, &[h])?) {
            return Ok((size_value(path, kw, &nw)?, size_value(path, kh, &nh)?));
        }
    }
    let (key, n) = required(fs, path, &["image_size", "imageSize"], "image size")?;
    let (_, _, v) = matrix(path, key, &n)?;
    let [w, h] = v[..] else {
        return Err(file_error(path, format!("`{key}` must hold two numbers (width, height), found {}", v.len())));
    };
    let check = |x: f64| (x >= 1.0 && x <= f64::from(MAX_IMAGE_SIDE) && x.fract() == 0.0).then_some(x as u32);
    match (check(w), check(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(file_error(path, format!("`{key}` = ({w}, {h}) is not an image size in 1..={MAX_IMAGE_SIDE}"))),
    }
}

/// Reads one camera's file.
pub fn read_opencv_camera(path: &Path, name: &str, scale: f64) -> Result<Camera, ImportError> {
    let meta = std::fs::metadata(path).map_err(|e| file_error(path, e.to_string()))?;
    if meta.len() > MAX_FILE_BYTES {
        return Err(file_error(path, format!("{} bytes, more than a camera's calibration file holds", meta.len())));
    }
    let fs = FileStorage::new(path, opencv::core::FileStorage_READ, "")
        .map_err(|e| file_error(path, format!("not an OpenCV FileStorage file: {e}")))?;
    if !fs.is_opened().unwrap_or(false) {
        return Err(file_error(path, "OpenCV cannot open it as a FileStorage file"));
    }
    let (width, height) = image_size(&fs, path)?;
    let (kk, kn) = required(&fs, path, &["camera_matrix", "cameraMatrix", "K", "intrinsic", "M"], "intrinsic matrix")?;
    let (r, c, k) = matrix(path, kk, &kn)?;
    if (r, c) != (3, 3) {
        return Err(file_error(path, format!("`{kk}` must be 3x3, found {r}x{c}")));
    }
    if !(k[0] > 0.0 && k[4] > 0.0) || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || (k[8] - 1.0).abs() > 1e-12 {
        return Err(file_error(path, format!("`{kk}` must be [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0")));
    }
    if k[1] != 0.0 {
        return Err(file_error(path, format!("`{kk}` has a skew of {}: not supported", k[1])));
    }
    let distortion = match node(
        &fs,
        path,
        &["distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "dist", "distortion"],
    )? {
        None => Distortion::NONE,
        Some((dk, dn)) => {
            let (_, _, d) = matrix(path, dk, &dn)?;
            if d.len() < 4 || d[5.min(d.len())..].iter().any(|&x| x != 0.0) {
                return Err(file_error(
                    path,
                    format!(
                        "`{dk}` has {} coefficients with rational or prism terms (beyond k3) not 0; hullcut reads k1, k2, p1, p2, k3",
                        d.len()
                    ),
                ));
            }
            Distortion { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d.get(4).copied().unwrap_or(0.0) }
        }
    };
    let rotation = match node(&fs, path, &["R", "rotation_matrix"])? {
        Some((rk, rn)) => {
            let (r, c, m) = matrix(path, rk, &rn)?;
            if (r, c) != (3, 3) {
                return Err(file_error(path, format!("`{rk}` must be 3x3, found {r}x{c}")));
            }
            let m = Matrix3::from_row_slice(&m);
            let deviation = (m.transpose() * m - Matrix3::identity()).abs().max();
            if deviation > ROTATION_TOLERANCE || m.determinant() <= 0.0 {
                return Err(file_error(
                    path,
                    format!("`{rk}` is not a rotation (max |RᵀR − I| = {deviation:.2e}, det = {:.6})", m.determinant()),
                ));
            }
            let svd = m.svd(true, true);
            match (svd.u, svd.v_t) {
                (Some(u), Some(v_t)) => Rotation3::from_matrix_unchecked(u * v_t),
                _ => Rotation3::from_matrix_unchecked(m),
            }
        }
        None => {
            let (rk, rn) = required(&fs, path, &["rvec", "rotation_vector"], "rotation (R, rotation_matrix, rvec)")?;
            let (_, _, v) = matrix(path, rk, &rn)?;
            let [x, y, z] = v[..] else {
                return Err(file_error(path, format!("`{rk}` must hold three numbers, found {}", v.len())));
            };
            Rotation3::from_scaled_axis(Vector3::new(x, y, z))
        }
    };
    let (tk, tn) = required(&fs, path, &["T", "t", "tvec", "translation_vector"], "translation (T, tvec)")?;
    let (_, _, t) = matrix(path, tk, &tn)?;
    let [tx, ty, tz] = t[..] else {
        return Err(file_error(path, format!("`{tk}` must hold three numbers, found {}", t.len())));
    };
    let mut cam = Camera::new(name, width, height, k[0], k[4], k[2], k[5]);
    cam.distortion = distortion;
    cam.rotation = rotation;
    cam.translation = Vector3::new(tx, ty, tz) * scale;
    Ok(cam)
}

/// Reads a folder of per-camera files as a rig (see the module docs); translations are multiplied
/// by `scale` (metres per unit of the files).
pub fn read_opencv_cameras(dir: &Path, scale: f64) -> Result<Rig, ImportError> {
    let folder = |message: String| ImportError::Folder { path: dir.to_owned(), message };
    if !(scale.is_finite() && scale > 0.0) {
        return Err(folder(format!("the scale must be a positive number of metres per unit, got {scale}")));
    }
    let entries = std::fs::read_dir(dir).map_err(|e| folder(e.to_string()))?;
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| folder(e.to_string()))?.path();
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        if !ext.is_some_and(|e| EXTENSIONS.contains(&e.as_str())) || !path.is_file() {
            continue;
        }
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else { continue };
        if files.len() >= MAX_CAMERAS {
            return Err(folder(format!("more than {MAX_CAMERAS} calibration files")));
        }
        files.push((stem.to_owned(), path));
    }
    if files.is_empty() {
        return Err(folder(format!("no calibration files (*.{})", EXTENSIONS.join(", *."))));
    }
    files.sort_by(|a, b| hullcut_rig::natural_cmp(&a.0, &b.0));
    if let Some(w) = files.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(folder(format!(
            "two files for camera `{}`: {} and {}",
            w[0].0,
            w[0].1.display(),
            w[1].1.display()
        )));
    }
    let cameras = files.iter().map(|(name, path)| read_opencv_camera(path, name, scale)).collect::<Result<_, _>>()?;
    let rig =
        Rig::new(cameras, WorldFrame::Other(format!("opencv files {} (scale {scale} m per unit)", dir.display())));
    rig.validate(&dir.display().to_string())?;
    Ok(rig)
}
