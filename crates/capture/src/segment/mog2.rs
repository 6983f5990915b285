//! The fallback when a camera has no empty-scene images: OpenCV's adaptive Gaussian-mixture
//! background subtractor (MOG2, Zivkovic 2004/2006), learning the background from the stream.

use std::fmt;

use image::RgbImage;
use opencv::core::{Mat, Ptr};
use opencv::prelude::*;
use opencv::video;

use crate::convert::rgb_to_bgr_mat;
use crate::error::{CaptureError, Context as _};

/// Settings of the MOG2 fallback (OpenCV's defaults, except shadows which are background here).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mog2Params {
    /// Frames of history that shape the model.
    pub history: i32,
    /// Squared Mahalanobis distance beyond which a pixel is foreground.
    pub var_threshold: f64,
    /// Detect shadows (marked and then treated as background).
    pub detect_shadows: bool,
    /// Learning rate; negative lets OpenCV choose from the history length.
    pub learning_rate: f64,
}

impl Default for Mog2Params {
    fn default() -> Self {
        Self { history: 500, var_threshold: 16.0, detect_shadows: true, learning_rate: -1.0 }
    }
}

/// MOG2's value for a certain foreground pixel (shadows are 127).
const MOG2_FOREGROUND: u8 = 255;

/// One camera's MOG2 model.
pub(crate) struct Mog2 {
    camera: usize,
    subtractor: Ptr<video::BackgroundSubtractorMOG2>,
    learning_rate: f64,
    mask: Mat,
    frames: u64,
}

impl fmt::Debug for Mog2 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Mog2").field("camera", &self.camera).field("frames", &self.frames).finish_non_exhaustive()
    }
}

impl Mog2 {
    pub(crate) fn new(camera: usize, params: &Mog2Params) -> Result<Self, CaptureError> {
        let subtractor =
            video::create_background_subtractor_mog2(params.history, params.var_threshold, params.detect_shadows)
                .context(|| format!("creating the MOG2 background model of camera {camera}"))?;
        Ok(Self { camera, subtractor, learning_rate: params.learning_rate, mask: Mat::default(), frames: 0 })
    }

    /// Updates the model with `image` and writes 1 where it is foreground, 0 elsewhere.
    pub(crate) fn apply(&mut self, image: &RgbImage, out: &mut [u8]) -> Result<(), CaptureError> {
        let (camera, frame) = (self.camera, self.frames);
        let ctx = || format!("applying MOG2 to frame {frame} of camera {camera}");
        let bgr = rgb_to_bgr_mat(image).context(ctx)?;
        BackgroundSubtractorMOG2Trait::apply(&mut self.subtractor, &bgr, &mut self.mask, self.learning_rate)
            .context(ctx)?;
        let bytes = self.mask.data_bytes().context(ctx)?;
        if bytes.len() != out.len() {
            return Err(CaptureError::OpenCv {
                context: ctx(),
                source: opencv::Error::new(opencv::core::StsUnmatchedSizes, "MOG2 mask size differs from the image"),
            });
        }
        for (o, &m) in out.iter_mut().zip(bytes) {
            *o = u8::from(m == MOG2_FOREGROUND);
        }
        self.frames += 1;
        Ok(())
    }
}
