//! Chessboard corner detection with sub-pixel refinement (OpenCV), across all images in parallel.

use std::path::Path;

use hullcut_rig::Camera;
use nalgebra::Point2;
use opencv::core::{Mat, Point2f, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;
use opencv::{calib3d, imgcodecs, imgproc};
use rayon::prelude::*;

use crate::error::Context as _;
use crate::{CalibError, ImageSet, Observations, Pattern};

/// Half-size of the sub-pixel refinement window, pixels (OpenCV's stereo sample uses the same).
const SUBPIX_HALF_WINDOW: i32 = 11;

/// What detection found in one image.
#[derive(Debug, Clone)]
pub struct Detection {
    /// Image size (width, height).
    pub size: (u32, u32),
    /// Inner corners in OpenCV order, pixels; `None` when the board was not found.
    pub corners: Option<Vec<Point2<f64>>>,
}

fn read(path: &Path, flags: i32) -> Result<Mat, CalibError> {
    let img = imgcodecs::imread(path, flags).context(|| format!("reading {}", path.display()))?;
    if img.empty() {
        return Err(CalibError::Image { path: path.to_owned() });
    }
    Ok(img)
}

/// Reads an image as 8-bit RGB: (width, height, pixels row-major).
pub fn read_rgb(path: &Path) -> Result<(u32, u32, Vec<u8>), CalibError> {
    let bgr = read(path, imgcodecs::IMREAD_COLOR)?;
    let mut rgb = Mat::default();
    imgproc::cvt_color_def(&bgr, &mut rgb, imgproc::COLOR_BGR2RGB)
        .context(|| format!("converting {}", path.display()))?;
    let bytes = rgb.data_bytes().context(|| format!("reading pixels of {}", path.display()))?.to_vec();
    Ok((rgb.cols() as u32, rgb.rows() as u32, bytes))
}

/// Reads an image as 8-bit RGB with the camera's lens distortion removed (same `K`), for viewers
/// whose camera model has no distortion (rerun's Pinhole).
pub fn read_rgb_undistorted(path: &Path, camera: &Camera) -> Result<(u32, u32, Vec<u8>), CalibError> {
    let ctx = || format!("undistorting {}", path.display());
    let bgr = read(path, imgcodecs::IMREAD_COLOR)?;
    let k = Mat::from_slice_2d(&[[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])
        .context(ctx)?;
    let coeffs = camera.distortion.to_array();
    let d = Mat::from_slice(&coeffs).context(ctx)?;
    let mut undistorted = Mat::default();
    calib3d::undistort_def(&bgr, &mut undistorted, &k, &d).context(ctx)?;
    let mut rgb = Mat::default();
    imgproc::cvt_color_def(&undistorted, &mut rgb, imgproc::COLOR_BGR2RGB).context(ctx)?;
    let bytes = rgb.data_bytes().context(ctx)?.to_vec();
    Ok((rgb.cols() as u32, rgb.rows() as u32, bytes))
}

/// Detects the board's inner corners in one image and refines them to sub-pixel accuracy.
pub fn detect_corners(path: &Path, pattern: &Pattern) -> Result<Detection, CalibError> {
    let gray = read(path, imgcodecs::IMREAD_GRAYSCALE)?;
    let size = (gray.cols() as u32, gray.rows() as u32);
    let board = Size::new(pattern.cols as i32, pattern.rows as i32);
    let mut corners = Vector::<Point2f>::new();
    let ctx = || format!("detecting the board in {}", path.display());
    let flags = calib3d::CALIB_CB_ADAPTIVE_THRESH | calib3d::CALIB_CB_NORMALIZE_IMAGE;
    let found = calib3d::find_chessboard_corners(&gray, board, &mut corners, flags).context(ctx)?;
    if !found || corners.len() != pattern.corner_count() {
        return Ok(Detection { size, corners: None });
    }
    let criteria =
        TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 30, 0.01).context(ctx)?;
    let window = Size::new(SUBPIX_HALF_WINDOW, SUBPIX_HALF_WINDOW);
    imgproc::corner_sub_pix(&gray, &mut corners, window, Size::new(-1, -1), criteria).context(ctx)?;
    let corners = corners.iter().map(|p| Point2::new(f64::from(p.x), f64::from(p.y))).collect();
    Ok(Detection { size, corners: Some(corners) })
}

/// Detects the board in every image of the set (in parallel), checking that each camera's images
/// share one size. `progress` is called once per image.
pub fn detect_all(set: &ImageSet, pattern: &Pattern, progress: &(dyn Fn() + Sync)) -> Result<Observations, CalibError> {
    let jobs: Vec<(usize, usize)> = (0..set.cameras.len())
        .flat_map(|c| (0..set.views.len()).filter(move |&v| set.paths[c][v].is_some()).map(move |v| (c, v)))
        .collect();
    let results: Vec<_> = jobs
        .par_iter()
        .map(|&(c, v)| {
            let path = set.paths[c][v]
                .as_deref()
                .ok_or_else(|| CalibError::Image { path: set.root.join(&set.cameras[c]).join(&set.views[v]) })?;
            let d = detect_corners(path, pattern);
            progress();
            d.map(|d| (c, v, d))
        })
        .collect::<Result<_, _>>()?;
    let mut sizes: Vec<Option<(u32, u32)>> = vec![None; set.cameras.len()];
    let mut obs = Observations::new(set.cameras.clone(), Vec::new(), set.views.clone());
    obs.has_image = set.paths.iter().map(|p| p.iter().map(Option::is_some).collect()).collect();
    for (c, v, d) in results {
        match sizes[c] {
            None => sizes[c] = Some(d.size),
            Some((w, h)) if (w, h) != d.size => {
                return Err(CalibError::ImageSize {
                    path: set.root.join(&set.cameras[c]).join(&set.views[v]),
                    camera: set.cameras[c].clone(),
                    w,
                    h,
                    found_w: d.size.0,
                    found_h: d.size.1,
                });
            }
            Some(_) => {}
        }
        obs.corners[c][v] = d.corners;
    }
    obs.image_sizes = sizes.into_iter().map(|s| s.unwrap_or((0, 0))).collect();
    Ok(obs)
}
