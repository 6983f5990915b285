//! Conversions between OpenCV's BGR `Mat`s and the `image` crate's RGB buffers (one pass, no
//! intermediate Mat).

use image::RgbImage;
use opencv::core::{CV_8UC1, CV_8UC3, CV_8UC4, Mat, Scalar};
use opencv::imgproc;
use opencv::prelude::*;

use crate::error::{CaptureError, Context as _};

/// Converts a decoded frame (8-bit BGR, BGRA or grey, as OpenCV's decoders deliver) to RGB.
pub(crate) fn mat_to_rgb(mat: &Mat, camera: usize, sequence: u64) -> Result<RgbImage, CaptureError> {
    let ctx = || format!("converting frame {sequence} of camera {camera}");
    let typ = mat.typ();
    let bgr;
    let src: &Mat = match typ {
        CV_8UC3 => mat,
        CV_8UC1 | CV_8UC4 => {
            let code = if typ == CV_8UC1 { imgproc::COLOR_GRAY2BGR } else { imgproc::COLOR_BGRA2BGR };
            let mut out = Mat::default();
            imgproc::cvt_color_def(mat, &mut out, code).context(ctx)?;
            bgr = out;
            &bgr
        }
        _ => return Err(CaptureError::PixelFormat { camera, sequence, typ, channels: mat.channels() }),
    };
    let (w, h) = (src.cols().max(0) as u32, src.rows().max(0) as u32);
    let mut out = Vec::with_capacity(w as usize * h as usize * 3);
    if src.is_continuous() {
        bgr_to_rgb_into(src.data_bytes().context(ctx)?, &mut out);
    } else {
        for row in 0..src.rows() {
            let r = src.row(row).context(ctx)?;
            let r = r.try_clone().context(ctx)?;
            bgr_to_rgb_into(r.data_bytes().context(ctx)?, &mut out);
        }
    }
    RgbImage::from_raw(w, h, out).ok_or(CaptureError::PixelFormat { camera, sequence, typ, channels: src.channels() })
}

fn bgr_to_rgb_into(src: &[u8], out: &mut Vec<u8>) {
    for px in src.chunks_exact(3) {
        out.extend_from_slice(&[px[2], px[1], px[0]]);
    }
}

/// Copies an RGB image into a new 8-bit BGR Mat.
pub(crate) fn rgb_to_bgr_mat(image: &RgbImage) -> opencv::Result<Mat> {
    let mut mat =
        Mat::new_rows_cols_with_default(image.height() as i32, image.width() as i32, CV_8UC3, Scalar::all(0.0))?;
    let dst = mat.data_bytes_mut()?;
    for (d, s) in dst.chunks_exact_mut(3).zip(image.as_raw().chunks_exact(3)) {
        d[0] = s[2];
        d[1] = s[1];
        d[2] = s[0];
    }
    Ok(mat)
}
