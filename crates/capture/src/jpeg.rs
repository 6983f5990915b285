//! JPEG encoding through OpenCV (libjpeg-turbo where OpenCV is built with it, as Debian's is):
//! several times faster than the pure-Rust encoder, for images logged every few frames.

use opencv::core::{CV_8UC3, Mat, Scalar, Vector};
use opencv::imgcodecs;
use opencv::prelude::*;

use crate::error::{CaptureError, Context as _};

/// Encodes RGB images to JPEG, reusing its buffers from one image to the next.
#[derive(Debug)]
pub struct JpegEncoder {
    quality: i32,
    bgr: Mat,
    encoded: Vector<u8>,
}

impl JpegEncoder {
    /// An encoder at `quality` (0 to 100, clamped).
    pub fn new(quality: u8) -> Self {
        JpegEncoder { quality: i32::from(quality.min(100)), bgr: Mat::default(), encoded: Vector::new() }
    }

    /// Encodes `rgb` (`width` x `height`, 3 bytes a pixel, rows packed) into `out` (cleared
    /// first). An error when the buffer's size does not match, or OpenCV fails.
    pub fn encode(&mut self, rgb: &[u8], width: u32, height: u32, out: &mut Vec<u8>) -> Result<(), CaptureError> {
        let ctx = || format!("encoding a {width}x{height} JPEG");
        let (rows, cols) = (i32::try_from(height).unwrap_or(i32::MAX), i32::try_from(width).unwrap_or(i32::MAX));
        if rgb.len() != width as usize * height as usize * 3 {
            return Err(CaptureError::Encode(format!(
                "{}: {} bytes of RGB, not {width} x {height} x 3",
                ctx(),
                rgb.len()
            )));
        }
        if self.bgr.rows() != rows || self.bgr.cols() != cols || self.bgr.typ() != CV_8UC3 {
            self.bgr = Mat::new_rows_cols_with_default(rows, cols, CV_8UC3, Scalar::all(0.0)).context(ctx)?;
        }
        let dst = self.bgr.data_bytes_mut().context(ctx)?;
        for (d, s) in dst.chunks_exact_mut(3).zip(rgb.chunks_exact(3)) {
            d[0] = s[2];
            d[1] = s[1];
            d[2] = s[0];
        }
        let params = Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, self.quality]);
        let ok = imgcodecs::imencode(".jpg", &self.bgr, &mut self.encoded, &params).context(ctx)?;
        if !ok {
            return Err(CaptureError::Encode(format!("{}: OpenCV's encoder refused the image", ctx())));
        }
        out.clear();
        out.extend_from_slice(self.encoded.as_slice());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_jpeg_decodes_back_to_about_the_image() {
        let (w, h) = (64u32, 48u32);
        let rgb: Vec<u8> = (0..w * h).flat_map(|k| [(k % w * 4) as u8, (k / w * 5) as u8, 128]).collect();
        let mut encoder = JpegEncoder::new(90);
        let mut jpeg = Vec::new();
        encoder.encode(&rgb, w, h, &mut jpeg).expect("encodes");
        let back = image::load_from_memory(&jpeg).expect("a JPEG").to_rgb8();
        assert_eq!(back.dimensions(), (w, h));
        let worst = back.as_raw().iter().zip(&rgb).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(0);
        // Smooth ramps: a JPEG at quality 90 stays within a few levels (red and green ramps
        // swapped with blue would be off by over a hundred).
        assert!(worst <= 12, "off by {worst}");
        // The buffers are reused; a wrong size is an error, not a panic.
        encoder.encode(&rgb, w, h, &mut jpeg).expect("encodes again");
        assert!(encoder.encode(&rgb[1..], w, h, &mut jpeg).is_err());
    }
}
