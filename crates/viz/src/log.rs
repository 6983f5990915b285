//! Logging hullcut's domain types at the entity paths of DESIGN.md's entity tree.

use hullcut_rig::{Camera, Rig};
use rerun::components::{self, MediaType, TransformRelation};
use rerun::datatypes::{ChannelDatatype, ClassDescription, Mat3x3, Rgba32};
use rerun::{
    AnnotationContext, AsComponents, EncodedImage, EntityPath, EntityPathPart, Image, ImageFormat, Pinhole, Points2D,
    Points3D, RecordingStream, Scalars, SegmentationImage, Transform3D, ViewCoordinates,
};

use crate::VizError;

/// What rerun adds to a hullcut pixel coordinate to get its own.
///
/// hullcut (like OpenCV) puts the centre of pixel (col i, row j) at (i, j); rerun puts it at
/// (i + 0.5, j + 0.5), the image spanning `[0, width] × [0, height]`. Every 2-D position and the
/// principal point are shifted by this before logging, so images, 2-D overlays and projected 3-D
/// data line up.
pub const RERUN_PIXEL_OFFSET: f32 = 0.5;

/// The world entity, root of everything spatial.
pub const WORLD: &str = "world";

/// `world/cams/<camera_name>`, the camera name kept as one path part even if it holds `/` or
/// other characters that rerun's path syntax would interpret.
pub fn camera_entity_path(camera_name: &str) -> EntityPath {
    EntityPath::new(vec![EntityPathPart::new(WORLD), EntityPathPart::new("cams"), EntityPathPart::new(camera_name)])
}

/// `world/cams/<camera_name>/image`, where a camera's images go.
pub fn image_entity_path(camera_name: &str) -> EntityPath {
    camera_entity_path(camera_name) / EntityPathPart::new("image")
}

fn log_at(rec: &RecordingStream, entity: EntityPath, data: &impl AsComponents, static_: bool) -> Result<(), VizError> {
    rec.log_with_static(entity.clone(), static_, data)
        .map_err(|error| VizError::Log { entity: entity.to_string(), error })
}

fn check_size(
    camera: &str,
    what: &'static str,
    width: u32,
    height: u32,
    channels: u64,
    actual: usize,
) -> Result<(), VizError> {
    let expected = u64::from(width) * u64::from(height) * channels;
    let actual = actual as u64;
    if expected == actual {
        Ok(())
    } else {
        Err(VizError::ImageSize { camera: camera.to_owned(), what, width, height, expected, actual })
    }
}

/// Logs `world`'s view coordinates (right-handed, z up) as static data.
pub fn log_world(rec: &RecordingStream) -> Result<(), VizError> {
    log_at(rec, EntityPath::from(WORLD), &ViewCoordinates::RIGHT_HAND_Z_UP(), true)
}

/// Logs every camera of the rig as static data at `world/cams/<name>`: its world→camera pose as a
/// [`Transform3D`] with [`TransformRelation::ChildFromParent`], and a pinhole with the camera's
/// `K`, resolution and OpenCV axes (RDF: x right, y down, z forward).
///
/// rerun's pinhole has no distortion: images logged under a camera must be undistorted first,
/// or 3-D data will not line up with them.
pub fn log_rig(rec: &RecordingStream, rig: &Rig) -> Result<(), VizError> {
    for camera in &rig.cameras {
        log_camera(rec, camera)?;
    }
    Ok(())
}

/// Logs one camera as [`log_rig`] does.
pub fn log_camera(rec: &RecordingStream, camera: &Camera) -> Result<(), VizError> {
    let entity = camera_entity_path(&camera.name);
    let t = camera.translation;
    let transform = Transform3D::from_translation_mat3x3([t.x as f32, t.y as f32, t.z as f32], rotation_mat3x3(camera))
        .with_relation(TransformRelation::ChildFromParent);
    log_at(rec, entity.clone(), &transform, true)?;

    let pinhole = Pinhole::new(image_from_camera(camera))
        .with_resolution([camera.width as f32, camera.height as f32])
        .with_camera_xyz(components::ViewCoordinates::RDF);
    log_at(rec, entity, &pinhole, true)
}

/// The world→camera rotation `R` in rerun's column-major matrix.
fn rotation_mat3x3(camera: &Camera) -> Mat3x3 {
    let r = camera.rotation.matrix();
    Mat3x3::from([0, 1, 2].map(|c| [r[(0, c)] as f32, r[(1, c)] as f32, r[(2, c)] as f32]))
}

/// `K` in rerun's column-major matrix and pixel convention.
fn image_from_camera(camera: &Camera) -> Mat3x3 {
    let (cx, cy) = (camera.cx as f32 + RERUN_PIXEL_OFFSET, camera.cy as f32 + RERUN_PIXEL_OFFSET);
    Mat3x3::from([[camera.fx as f32, 0.0, 0.0], [0.0, camera.fy as f32, 0.0], [cx, cy, 1.0]])
}

/// Logs an RGB image (8 bits per channel, interleaved `RGBRGB…`, rows top to bottom) at
/// `world/cams/<camera_name>/image`, at the current time.
///
/// Fails without logging if `rgb` does not hold `width × height × 3` bytes.
pub fn log_image_rgb(
    rec: &RecordingStream,
    camera_name: &str,
    width: u32,
    height: u32,
    rgb: &[u8],
) -> Result<(), VizError> {
    check_size(camera_name, "RGB image", width, height, 3, rgb.len())?;
    let image = Image::new(rgb, ImageFormat::rgb8([width, height]));
    log_at(rec, image_entity_path(camera_name), &image, false)
}

/// Logs a JPEG-encoded image at `world/cams/<camera_name>/image`, at the current time; the viewer
/// decodes it. Use this for decimated logging of long recordings.
///
/// The bytes are not checked: a corrupt JPEG shows as an error in the viewer, not here.
pub fn log_image_jpeg(rec: &RecordingStream, camera_name: &str, jpeg_bytes: Vec<u8>) -> Result<(), VizError> {
    let image = EncodedImage::new(jpeg_bytes).with_media_type(MediaType::jpeg());
    log_at(rec, image_entity_path(camera_name), &image, false)
}

/// Logs a label image (one byte per pixel, a class id) at `world/cams/<camera_name>/labels`, at
/// the current time. The classes' names and colours come from [`log_label_classes`].
///
/// Fails without logging if `labels` does not hold `width × height` bytes.
pub fn log_labels(
    rec: &RecordingStream,
    camera_name: &str,
    width: u32,
    height: u32,
    labels: &[u8],
) -> Result<(), VizError> {
    check_size(camera_name, "label image", width, height, 1, labels.len())?;
    let image = SegmentationImage::new(labels, ImageFormat::segmentation([width, height], ChannelDatatype::U8));
    log_at(rec, camera_entity_path(camera_name) / EntityPathPart::new("labels"), &image, false)
}

/// Logs the label classes `(id, name, RGBA colour)` once, as static data at the root, so every
/// label image of the recording is drawn with them.
pub fn log_label_classes(rec: &RecordingStream, classes: &[(u16, &str, [u8; 4])]) -> Result<(), VizError> {
    let context = AnnotationContext::new(
        classes.iter().map(|&(id, name, rgba)| ClassDescription::from((id, name, Rgba32::from(rgba)))),
    );
    log_at(rec, EntityPath::root(), &context, true)
}

/// Logs 2-D points in hullcut pixel coordinates (see [`RERUN_PIXEL_OFFSET`]) at
/// `world/cams/<camera_name>/image/<sub>`, at the current time, e.g. detected chessboard corners.
///
/// `radius_px` is in image pixels.
pub fn log_image_points(
    rec: &RecordingStream,
    camera_name: &str,
    sub: &str,
    points: &[[f32; 2]],
    color: [u8; 4],
    radius_px: f32,
) -> Result<(), VizError> {
    let positions = points.iter().map(|&[u, v]| [u + RERUN_PIXEL_OFFSET, v + RERUN_PIXEL_OFFSET]);
    let points = Points2D::new(positions).with_colors([color]).with_radii([radius_px]);
    log_at(rec, image_entity_path(camera_name) / EntityPath::from(sub), &points, false)
}

/// Logs 3-D points in world coordinates (metres) at `path` (e.g. `world/board`), at the current
/// time. `radius_m` is in metres.
pub fn log_points3d(
    rec: &RecordingStream,
    path: &str,
    points: &[[f32; 3]],
    color: [u8; 4],
    radius_m: f32,
) -> Result<(), VizError> {
    let points = Points3D::new(points.iter().copied()).with_colors([color]).with_radii([radius_m]);
    log_at(rec, EntityPath::from(path), &points, false)
}

/// Logs 3-D points at `path`, each with its own colour (`colors` one per point).
pub fn log_points3d_colored(
    rec: &RecordingStream,
    path: &str,
    points: &[[f32; 3]],
    colors: &[[u8; 4]],
    radius_m: f32,
) -> Result<(), VizError> {
    let points = Points3D::new(points.iter().copied()).with_colors(colors.iter().copied()).with_radii([radius_m]);
    log_at(rec, EntityPath::from(path), &points, false)
}

/// Logs a triangle mesh in world coordinates at `path` (e.g. `world/tissue/surface`), one colour,
/// with vertex normals computed here so it shades in the viewer.
pub fn log_mesh3d(
    rec: &RecordingStream,
    path: &str,
    vertices: &[[f32; 3]],
    triangles: &[[u32; 3]],
    color: [u8; 4],
) -> Result<(), VizError> {
    let mut normals = vec![[0.0f32; 3]; vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices.get(i as usize).copied().unwrap_or_default());
        let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        for &i in t {
            if let Some(acc) = normals.get_mut(i as usize) {
                for k in 0..3 {
                    acc[k] += n[k];
                }
            }
        }
    }
    for n in &mut normals {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len > 0.0 {
            *n = n.map(|x| x / len);
        }
    }
    let mesh = rerun::Mesh3D::new(vertices.iter().copied())
        .with_triangle_indices(triangles.iter().copied())
        .with_vertex_normals(normals)
        .with_albedo_factor(Rgba32::from_unmultiplied_rgba(color[0], color[1], color[2], color[3]));
    log_at(rec, EntityPath::from(path), &mesh, false)
}

/// Logs 3-D line strips in world coordinates (metres) at `path` (e.g. the cutting edge under
/// `world/tool/truth/edge`), at the current time. `radius_m` is in metres.
pub fn log_line_strips3d(
    rec: &RecordingStream,
    path: &str,
    strips: &[Vec<[f32; 3]>],
    color: [u8; 4],
    radius_m: f32,
) -> Result<(), VizError> {
    let strips = rerun::LineStrips3D::new(strips.iter().cloned()).with_colors([color]).with_radii([radius_m]);
    log_at(rec, EntityPath::from(path), &strips, false)
}

/// Logs an axis-aligned box (world metres, from `min` to `max`) with a label at `path` (e.g. the
/// working volume at `world/workspace`), static: it holds for the whole recording.
pub fn log_box3d(rec: &RecordingStream, path: &str, min: [f32; 3], max: [f32; 3], label: &str) -> Result<(), VizError> {
    let size = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
    let boxes = rerun::Boxes3D::from_mins_and_sizes([min], [size])
        .with_labels([label.to_owned()])
        .with_colors([Rgba32::from_unmultiplied_rgba(160, 160, 160, 255)]);
    log_at(rec, EntityPath::from(path), &boxes, true)
}

/// Logs one scalar at `path` (the full path, e.g. `metrics/time/carve`), at the current time.
pub fn log_scalar(rec: &RecordingStream, path: &str, value: f64) -> Result<(), VizError> {
    log_at(rec, EntityPath::from(path), &Scalars::single(value), false)
}

/// Logs several scalars at `path` at the current time, one series each (styled by
/// [`log_series_style`]).
pub fn log_scalars(rec: &RecordingStream, path: &str, values: &[f64]) -> Result<(), VizError> {
    log_at(rec, EntityPath::from(path), &Scalars::new(values.iter().copied()), false)
}

/// Names and colours the series of the scalars logged at `path` (static: logged once, it holds for
/// the whole recording).
pub fn log_series_style(rec: &RecordingStream, path: &str, series: &[(&str, [u8; 3])]) -> Result<(), VizError> {
    let style = rerun::SeriesLines::new()
        .with_names(series.iter().map(|(name, _)| *name))
        .with_colors(series.iter().map(|(_, [r, g, b])| Rgba32::from_unmultiplied_rgba(*r, *g, *b, 255)));
    log_at(rec, EntityPath::from(path), &style, true)
}

/// Logs a line of text at `path` at the current time, as a warning or as information.
pub fn log_text(rec: &RecordingStream, path: &str, text: &str, warning: bool) -> Result<(), VizError> {
    let level = if warning { components::TextLogLevel::WARN } else { components::TextLogLevel::INFO };
    log_at(rec, EntityPath::from(path), &rerun::TextLog::new(text).with_level(level), false)
}

/// Clears `path` and everything under it from the current time on (an entity that has nothing to
/// show this frame, e.g. a pose that was refused).
pub fn log_clear(rec: &RecordingStream, path: &str) -> Result<(), VizError> {
    log_at(rec, EntityPath::from(path), &rerun::Clear::recursive(), false)
}

#[cfg(test)]
mod tests {
    use hullcut_rig::Camera;
    use nalgebra::{Point3, Vector3};

    use super::*;

    fn apply(m: &Mat3x3, p: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|row| (0..3).map(|col| m.get(row, col) * p[col]).sum())
    }

    fn camera() -> Camera {
        Camera::new("c", 640, 480, 500.0, 510.0, 300.0, 250.0)
            .looking_at(Point3::new(0.7, -0.4, 0.9), Point3::new(0.05, 0.02, 0.0), Vector3::z())
            .expect("valid pose")
    }

    /// rerun's transform and pinhole, applied as rerun applies them, put a world point on the same
    /// pixel as the rig's camera model, shifted by half a pixel. Tolerance: f32 rounding of
    /// coordinates near 1 m and a 500 px focal length, well under 1e-3 px.
    #[test]
    fn rerun_matrices_reproduce_the_camera_projection() {
        let camera = camera();
        let (r, k) = (rotation_mat3x3(&camera), image_from_camera(&camera));
        let t = camera.translation;
        for p in [Point3::new(0.0, 0.0, 0.0), Point3::new(0.1, -0.05, 0.03), Point3::new(-0.2, 0.1, 0.2)] {
            let rotated = apply(&r, [p.x as f32, p.y as f32, p.z as f32]);
            let pc = [rotated[0] + t.x as f32, rotated[1] + t.y as f32, rotated[2] + t.z as f32];
            let uvw = apply(&k, pc);
            let (u, v) = (uvw[0] / uvw[2], uvw[1] / uvw[2]);
            let expected = camera.project(&p).pixel;
            assert!((f64::from(u) - (expected.x + 0.5)).abs() < 1e-3, "u {u} vs {}", expected.x);
            assert!((f64::from(v) - (expected.y + 0.5)).abs() < 1e-3, "v {v} vs {}", expected.y);
        }
    }
}
