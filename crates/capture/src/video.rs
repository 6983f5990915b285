//! Writing videos with OpenCV's `VideoWriter`, and exporting a dataset camera to a video file.
//!
//! The codec follows the file extension: `.avi` → Motion-JPEG (`MJPG`, OpenCV's built-in encoder
//! at quality 95, FFmpeg's as fallback), `.mkv` → FFV1 (lossless, through FFmpeg), `.mp4` →
//! MPEG-4 Part 2 (`mp4v`, through FFmpeg).

use std::path::{Path, PathBuf};

use hullcut_dataset::Dataset;
use image::RgbImage;
use opencv::core::Size;
use opencv::prelude::*;
use opencv::videoio::{self, VideoWriter};

use crate::convert::rgb_to_bgr_mat;
use crate::error::{CaptureError, Context as _};

/// Codec used for a file, chosen from its extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VideoCodec {
    /// Motion-JPEG in AVI (`.avi`): lossy, every frame independent, decodes everywhere.
    Mjpg,
    /// FFV1 (`.mkv`): lossless.
    Ffv1,
    /// MPEG-4 Part 2 (`.mp4`): lossy, inter-frame.
    Mp4v,
}

impl VideoCodec {
    /// The codec for a path's extension (case-insensitive); `None` for other extensions.
    pub fn for_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "avi" => Some(Self::Mjpg),
            "mkv" => Some(Self::Ffv1),
            "mp4" => Some(Self::Mp4v),
            _ => None,
        }
    }

    fn fourcc(self) -> [char; 4] {
        match self {
            Self::Mjpg => ['M', 'J', 'P', 'G'],
            Self::Ffv1 => ['F', 'F', 'V', '1'],
            Self::Mp4v => ['m', 'p', '4', 'v'],
        }
    }
}

fn write_error(path: &Path, message: impl Into<String>) -> CaptureError {
    CaptureError::VideoWrite { path: path.to_owned(), message: message.into() }
}

fn open_writer(path: &Path, fps: f64, width: u32, height: u32) -> Result<VideoWriter, CaptureError> {
    let codec = VideoCodec::for_path(path)
        .ok_or_else(|| write_error(path, "unknown extension: use .avi (MJPG), .mkv (FFV1) or .mp4 (mp4v)"))?;
    let name = path.to_str().ok_or_else(|| write_error(path, "path is not UTF-8"))?;
    let ctx = || format!("opening {} for writing", path.display());
    let [a, b, c, d] = codec.fourcc();
    let fourcc = VideoWriter::fourcc(a, b, c, d).context(ctx)?;
    let size = Size::new(width as i32, height as i32);
    // Motion-JPEG goes through OpenCV's own encoder first: it is always built in and encodes at
    // quality 95, where FFmpeg's MJPEG runs at a bit rate that loses about 2.5 grey levels on
    // noisy texture (measured in the integration tests).
    let backends: &[i32] = match codec {
        VideoCodec::Mjpg => &[videoio::CAP_OPENCV_MJPEG, videoio::CAP_FFMPEG],
        _ => &[videoio::CAP_FFMPEG],
    };
    for &backend in backends {
        let writer = VideoWriter::new_with_backend(name, backend, fourcc, fps, size, true).context(ctx)?;
        if writer.is_opened().context(ctx)? {
            return Ok(writer);
        }
    }
    Err(write_error(path, format!("no OpenCV backend can encode {codec:?} at {width}x{height}")))
}

/// Writes frames to a video at `fps` frames per second; returns the number of frames written.
///
/// All frames must share the first frame's size. An empty iterator writes no file and returns 0.
pub fn write_video<'a>(
    path: impl AsRef<Path>,
    fps: f64,
    frames: impl IntoIterator<Item = &'a RgbImage>,
) -> Result<u64, CaptureError> {
    let path = path.as_ref();
    if !(fps.is_finite() && fps > 0.0) {
        return Err(write_error(path, format!("frame rate {fps} is not positive")));
    }
    let mut frames = frames.into_iter();
    let Some(first) = frames.next() else { return Ok(0) };
    let (w, h) = first.dimensions();
    let mut writer = open_writer(path, fps, w, h)?;
    let mut count = 0u64;
    for image in std::iter::once(first).chain(frames) {
        if image.dimensions() != (w, h) {
            return Err(write_error(
                path,
                format!("frame {count} is {}x{}, the first frame is {w}x{h}", image.width(), image.height()),
            ));
        }
        let mat = rgb_to_bgr_mat(image).context(|| format!("converting frame {count} for {}", path.display()))?;
        writer.write(&mat).context(|| format!("writing frame {count} to {}", path.display()))?;
        count += 1;
    }
    writer.release().context(|| format!("closing {}", path.display()))?;
    Ok(count)
}

/// What [`export_camera_video`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportedVideo {
    /// The video file.
    pub path: PathBuf,
    /// Dataset frame numbers of the video's frames, in order (frames the camera dropped are
    /// absent, so the video's k-th frame is `frames[k]`).
    pub frames: Vec<u64>,
    /// Capture times of the video's frames, nanoseconds: pass them to
    /// [`crate::SourceConfig::with_timestamps`] to replay the video with the recording's clock.
    pub timestamps_ns: Vec<i64>,
}

/// Writes one camera of a dataset to a video at the dataset's frame rate. Frames the camera
/// dropped are skipped (not repeated); the returned [`ExportedVideo`] lists the frames written
/// and their timestamps. A camera without any image writes no file (empty lists). A camera index
/// outside the rig is [`CaptureError::UnknownCamera`].
pub fn export_camera_video(
    dataset: &Dataset,
    camera: usize,
    path: impl AsRef<Path>,
) -> Result<ExportedVideo, CaptureError> {
    let path = path.as_ref();
    let cameras = dataset.meta().cameras.len();
    if camera >= cameras {
        return Err(CaptureError::UnknownCamera { camera, cameras });
    }
    let fps = dataset.meta().fps;
    let mut frames = Vec::new();
    let mut timestamps_ns = Vec::new();
    let mut writer: Option<(VideoWriter, u32, u32)> = None;
    for frame in dataset.frame_numbers() {
        let Some(timestamp_ns) = dataset.timestamp(frame, camera) else { continue };
        let image = dataset.read_image(frame, camera)?;
        let (w, h) = image.dimensions();
        let (writer, ww, wh) = match &mut writer {
            Some(x) => x,
            None => writer.insert((open_writer(path, fps, w, h)?, w, h)),
        };
        if (w, h) != (*ww, *wh) {
            return Err(CaptureError::ImageSize {
                camera,
                what: format!("frame {frame}"),
                w: *ww,
                h: *wh,
                found_w: w,
                found_h: h,
            });
        }
        let mat = rgb_to_bgr_mat(&image).context(|| format!("converting frame {frame} of camera {camera}"))?;
        writer.write(&mat).context(|| format!("writing frame {frame} to {}", path.display()))?;
        frames.push(frame);
        timestamps_ns.push(timestamp_ns);
    }
    if let Some((mut writer, _, _)) = writer {
        writer.release().context(|| format!("closing {}", path.display()))?;
    }
    Ok(ExportedVideo { path: path.to_owned(), frames, timestamps_ns })
}
