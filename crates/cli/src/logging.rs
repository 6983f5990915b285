//! Logging dataset content to rerun: undistorted camera images (JPEG) and label masks under
//! `world/cams/<name>`, and a tool's pose and geometry under `world/tool/<which>`.
//!
//! When segmenting, where each frame set's labels came from goes to `labelling/source` (text) and
//! the colours learned so far to `metrics/appearance/<label>/{colour,pixels}`, the possible
//! shadows given back to the table to `metrics/shadows/on_table`, the pixels an untrusted but
//! agreeing fit taught the colours to `metrics/appearance/taught` ([`log_labelling`]).
//!
//! Decimation policy: images and masks every `every`-th frame (they dominate a recording's size:
//! ~40 KB per JPEG image and 300 KB per mask at 640x480); poses and scalars every frame.

use anyhow::Context as _;
use hullcut_dataset::{FrameSet, ToolGeometry, label};
use hullcut_pipeline::{LabelSource, LabelTrace};
use hullcut_rig::Rig;
use hullcut_viz::{RecordingStream, UndistortMap};
use nalgebra::{Matrix4, Point3};

/// Label classes with the colours every recording uses.
pub const LABEL_CLASSES: [(u16, &str, [u8; 4]); 4] = [
    (label::BACKGROUND as u16, "background", [0, 0, 0, 0]),
    (label::HAND as u16, "hand", [70, 130, 255, 160]),
    (label::SCALPEL as u16, "scalpel", [255, 200, 40, 200]),
    (label::UNKNOWN as u16, "unknown", [255, 0, 255, 120]),
];

/// Where a frame set's label source is logged.
pub const LABEL_SOURCE_ENTITY: &str = "labelling/source";
/// The share of the drawn blade the learned colours call the hand's (the fit's hand hints stop
/// above 0.1).
pub const BLADE_AS_HAND_ENTITY: &str = "metrics/appearance/blade_as_hand";
/// The possible shadows given back to the table in a frame set, pixels over its views (the
/// report's `shadow_on_table`, frame set by frame set).
pub const SHADOW_ON_TABLE_ENTITY: &str = "metrics/shadows/on_table";
/// The weak foreground the other views' hull confirmed in a frame set, pixels over its views
/// (`--confirm-weak-foreground`; the report's `weak_confirmed`, frame set by frame set).
pub const WEAK_CONFIRMED_ENTITY: &str = "metrics/foreground/weak_confirmed";
/// The pixels an untrusted fit that agreed with the silhouettes taught the colours in a frame
/// set, over its views, before any trusted fit taught them (the report's `counters.bootstrapped`
/// counts these frame sets).
pub const TAUGHT_ENTITY: &str = "metrics/appearance/taught";
/// The pixels whose foreground a frame set's segmentation tested, over its views (the report's
/// `counters.pixels_tested`, frame set by frame set).
pub const PIXELS_TESTED_ENTITY: &str = "metrics/segment/pixels_tested";
/// 1 where a frame set's views were segmented only where the last hull can be seen (row by row),
/// 0 where in the whole rectangle of the box carved in (the report's
/// `counters.segmented_near_hull`, frame set by frame set).
pub const NEAR_HULL_ENTITY: &str = "metrics/segment/near_hull";
/// The pixels that passed a frame set's foreground test only at half its tolerances and joined
/// the foreground they touch, over its views (the segmenter's hysteresis; the report's
/// `counters.weak_joined`, frame set by frame set).
pub const WEAK_JOINED_ENTITY: &str = "metrics/segment/weak_joined";
/// The background pixels enclosed by a frame set's foreground that it filled as holes whose mean
/// colour is not their background's, over its views (`SegmentParams::fill_holes`; the report's
/// `counters.holes_filled`, frame set by frame set).
pub const HOLES_FILLED_ENTITY: &str = "metrics/segment/holes_filled";
/// The time a trusted frame set's lesson (its tool drawn, the colours learned from it) took on its
/// own thread, ms, logged on the frame set whose labelling took its colours (the report's
/// `timings.learn`, lesson by lesson).
pub const LESSON_ENTITY: &str = "metrics/segment/lesson_ms";
/// 1 where a frame set's foreground hull was searched for a lost tool, 0 where the search was
/// paused (`--search-gap`); nothing where the track held the tool (the report's
/// `labelling.counters.searches` and `searches_paused`, frame set by frame set).
pub const HULL_SEARCHED_ENTITY: &str = "metrics/pose/hull_searched";
/// What the views make of the fitted blade, one series per kind ([`POSE_VIEW_KINDS`]): the views
/// that see its face, see it edge-on, have it hidden by the hand, on background, or on the
/// handle's colours (a frame's `views_*` in the run report's `pose.per_frame`); all 0 where
/// nothing was fitted (the refusal's reason says why).
pub const POSE_VIEWS_ENTITY: &str = "metrics/pose/views/KIND";
/// The kinds of [`POSE_VIEWS_ENTITY`].
pub const POSE_VIEW_KINDS: [&str; 5] = ["seen", "edge_on", "hidden", "on_background", "handle_coloured"];

/// The series of one kind of [`POSE_VIEWS_ENTITY`].
pub fn pose_views_entity(kind: &str) -> String {
    format!("metrics/pose/views/{kind}")
}

/// Per camera, 1 where it saw the fitted blade's face, 0 where it saw the blade otherwise
/// (edge-on, hidden by the hand, on background, on the handle's colours), nothing where it gave
/// no evidence (no mask, the tool out of its view, nothing fitted): when each camera loses the
/// blade (a frame's `Diagnostics::sight`; the run report's `pose.per_camera` sums it).
pub const POSE_SIGHT_ENTITY: &str = "metrics/pose/sight/CAM";

/// The series of one camera of [`POSE_SIGHT_ENTITY`].
pub fn pose_sight_entity(camera: &str) -> String {
    format!("metrics/pose/sight/{camera}")
}

/// Per camera, 1 where the fit set it aside (its residuals made up half the fit's cost or more,
/// and the tool was fitted again without it: `Diagnostics::view_set_aside`), 0 where it gave
/// evidence and was kept, nothing where it gave none (the run report's `pose.per_camera[].set_aside`
/// sums it).
pub const POSE_SET_ASIDE_ENTITY: &str = "metrics/pose/set_aside/CAM";

/// How well the views hold the fitted blade's turn about its long axis: the turn's standard
/// deviation for a pixel of noise on every residual, degrees (a frame's `roll_sd_deg` in the run
/// report's `pose.per_frame`); nothing where nothing was fitted or the views leave the turn free.
pub const POSE_ROLL_SD_ENTITY: &str = "metrics/pose/roll_sd";

/// The series of one camera of [`POSE_SET_ASIDE_ENTITY`].
pub fn pose_set_aside_entity(camera: &str) -> String {
    format!("metrics/pose/set_aside/{camera}")
}

/// Logs what the views made of a frame set's fitted blade ([`POSE_VIEWS_ENTITY`]), how well they
/// hold its turn about its long axis ([`POSE_ROLL_SD_ENTITY`]) and what each of `rig`'s cameras
/// did ([`POSE_SIGHT_ENTITY`], [`POSE_SET_ASIDE_ENTITY`]).
pub fn log_pose_views(rec: &RecordingStream, d: &hullcut_pose::Diagnostics, rig: &Rig) -> anyhow::Result<()> {
    let counts = [d.views_seen, d.views_edge_on, d.views_hidden, d.views_on_background, d.views_handle_coloured];
    for (kind, n) in POSE_VIEW_KINDS.iter().zip(counts) {
        hullcut_viz::log_scalar(rec, &pose_views_entity(kind), n as f64)?;
    }
    if let Some(sd) = d.roll_sd_deg {
        hullcut_viz::log_scalar(rec, POSE_ROLL_SD_ENTITY, sd)?;
    }
    for (k, (camera, sight)) in rig.cameras.iter().zip(&d.sight).enumerate() {
        if let Some(sight) = sight {
            let seen = f64::from(u8::from(*sight == hullcut_pose::Sight::Seen));
            hullcut_viz::log_scalar(rec, &pose_sight_entity(&camera.name), seen)?;
            let aside = f64::from(u8::from(d.view_set_aside == Some(k)));
            hullcut_viz::log_scalar(rec, &pose_set_aside_entity(&camera.name), aside)?;
        }
    }
    Ok(())
}

/// The learned colour of a label (`hand`, `scalpel`, `blade`) at mid brightness, as three series.
pub fn appearance_colour_entity(label: &str) -> String {
    format!("metrics/appearance/{label}/colour")
}

/// The weight of a label's learned colour (pixels, decayed).
pub fn appearance_pixels_entity(label: &str) -> String {
    format!("metrics/appearance/{label}/pixels")
}

/// Names and colours the learned colours' series, the blade's too (static; once per recording).
pub fn log_appearance_style(rec: &RecordingStream) -> anyhow::Result<()> {
    for name in hullcut_capture::segment::LEARNED_NAMES {
        hullcut_viz::log_series_style(
            rec,
            &appearance_colour_entity(name),
            &[("red", [220, 40, 40]), ("green", [40, 170, 40]), ("blue", [40, 80, 230])],
        )?;
    }
    Ok(())
}

/// Logs where a frame set's labels came from (a warning when the tool's fit was not trusted and
/// no colour could label instead), the colours learned by then (a label with none learned yet
/// logs nothing), the share of the drawn blade they call the hand's (once there is one) and the
/// possible shadows given back to the table (where any were asked), the weak foreground
/// confirmed (with `--confirm-weak-foreground`) and the pixels an untrusted but agreeing fit
/// taught the colours (where it did), at the current time.
pub fn log_labelling(rec: &RecordingStream, trace: &LabelTrace) -> anyhow::Result<()> {
    let (text, warning) = match trace.source {
        LabelSource::Geometry => ("geometry: the tool's trusted fit drawn into the views", false),
        LabelSource::Colour => ("colour: the learned colours (the tool's fit was not trusted)", false),
        LabelSource::UntrustedGeometry if trace.taught.is_some() => (
            "untrusted geometry: the tool's fit drawn although the tracker did not trust it; it agreed with the \
             silhouettes and taught the colours",
            true,
        ),
        LabelSource::UntrustedGeometry => {
            ("untrusted geometry: the tool's fit drawn although the tracker did not trust it", true)
        }
        LabelSource::Unknown => ("unknown: neither the tool's fit nor learned colours labelled the foreground", true),
    };
    hullcut_viz::log_text(rec, LABEL_SOURCE_ENTITY, text, warning)?;
    if let Some(share) = trace.blade_as_hand {
        hullcut_viz::log_scalar(rec, BLADE_AS_HAND_ENTITY, share)?;
    }
    if let Some(pixels) = trace.shadow_on_table {
        hullcut_viz::log_scalar(rec, SHADOW_ON_TABLE_ENTITY, pixels as f64)?;
    }
    if let Some(pixels) = trace.weak_confirmed {
        hullcut_viz::log_scalar(rec, WEAK_CONFIRMED_ENTITY, pixels as f64)?;
    }
    if let Some(pixels) = trace.taught {
        hullcut_viz::log_scalar(rec, TAUGHT_ENTITY, pixels as f64)?;
    }
    hullcut_viz::log_scalar(rec, PIXELS_TESTED_ENTITY, trace.segmented.pixels as f64)?;
    hullcut_viz::log_scalar(rec, NEAR_HULL_ENTITY, f64::from(u8::from(trace.segmented.near_hull)))?;
    hullcut_viz::log_scalar(rec, WEAK_JOINED_ENTITY, trace.segmented.weak_joined as f64)?;
    hullcut_viz::log_scalar(rec, HOLES_FILLED_ENTITY, trace.segmented.holes_filled as f64)?;
    if let Some(ms) = trace.lesson_ms {
        hullcut_viz::log_scalar(rec, LESSON_ENTITY, ms)?;
    }
    if let Some(searched) = trace.hull_search {
        hullcut_viz::log_scalar(rec, HULL_SEARCHED_ENTITY, f64::from(u8::from(searched)))?;
    }
    for colour in &trace.learned {
        hullcut_viz::log_scalar(rec, &appearance_pixels_entity(&colour.label), colour.pixels)?;
        if let Some(rgb) = colour.rgb {
            hullcut_viz::log_scalars(rec, &appearance_colour_entity(&colour.label), &rgb.map(f64::from))?;
        }
    }
    Ok(())
}

/// JPEG quality of logged images.
const JPEG_QUALITY: u8 = 85;

/// Per-camera undistortion maps of a rig, built once.
#[derive(Debug)]
pub struct CameraLogger {
    names: Vec<String>,
    /// For the label masks (nearest, labels stay labels).
    maps: Vec<UndistortMap>,
    /// The encoder and buffers, reused from frame to frame.
    scratch: std::sync::Mutex<Scratch>,
}

/// Buffers a frame set's logging reuses.
#[derive(Debug)]
struct Scratch {
    /// OpenCV's JPEG encoder, with its own buffers.
    jpeg: hullcut_capture::JpegEncoder,
    /// Per camera, OpenCV's bilinear remap for the images (vectorised: 0.65 ms for a 640x480
    /// image where [`UndistortMap`]'s takes 1.2, on the logging thread beside the loop).
    images: Vec<hullcut_capture::ImageUndistorter>,
    /// An undistorted label mask.
    labels: Vec<u8>,
}

impl CameraLogger {
    /// Logs the rig and the label classes (static) and prepares the maps.
    pub fn new(rec: &RecordingStream, rig: &Rig) -> anyhow::Result<Self> {
        hullcut_viz::log_rig(rec, rig)?;
        hullcut_viz::log_label_classes(rec, &LABEL_CLASSES)?;
        Ok(CameraLogger {
            names: rig.cameras.iter().map(|c| c.name.clone()).collect(),
            maps: rig.cameras.iter().map(UndistortMap::new).collect(),
            scratch: std::sync::Mutex::new(Scratch {
                jpeg: hullcut_capture::JpegEncoder::new(JPEG_QUALITY),
                images: rig
                    .cameras
                    .iter()
                    .map(hullcut_capture::ImageUndistorter::new)
                    .collect::<Result<_, _>>()
                    .context("preparing the logged images' undistortion")?,
                labels: Vec::new(),
            }),
        })
    }

    /// Logs every present view's image (and mask, when present) of a frame set, undistorted.
    pub fn log_frame_set(&self, rec: &RecordingStream, set: &FrameSet) -> anyhow::Result<()> {
        for view in set.views.iter().flatten() {
            let (Some(name), Some(map)) = (self.names.get(view.camera), self.maps.get(view.camera)) else {
                continue;
            };
            let (w, h) = view.image.dimensions();
            if (w, h) != (map.width(), map.height()) {
                anyhow::bail!("camera {name}: image is {w}x{h}, the rig says {}x{}", map.width(), map.height());
            }
            let mut scratch = self.scratch.lock().map_err(|_| anyhow::anyhow!("the logging buffers were poisoned"))?;
            let Scratch { jpeg: encoder, images, labels } = &mut *scratch;
            let Some(undistorter) = images.get_mut(view.camera) else { continue };
            let rgb = undistorter
                .undistort_rgb(view.image.as_raw())
                .with_context(|| format!("camera {name}: undistorting an image for rerun"))?;
            // rerun keeps the encoded bytes: a new buffer each time.
            let mut jpeg = Vec::new();
            encoder
                .encode(rgb, w, h, &mut jpeg)
                .with_context(|| format!("camera {name}: encoding a JPEG for rerun"))?;
            hullcut_viz::log_image_jpeg(rec, name, jpeg)?;
            if let Some(mask) = &view.mask {
                if !map.remap_into(mask.as_raw(), 1, false, labels) {
                    anyhow::bail!("camera {name}: remapping a mask of the wrong size");
                }
                hullcut_viz::log_labels(rec, name, w, h, labels)?;
            }
        }
        Ok(())
    }
}

/// Logs a tool at a pose under `world/tool/<which>`: its mesh, cutting edge and tip.
pub fn log_tool(
    rec: &RecordingStream,
    which: &str,
    tool: &ToolGeometry,
    tool_to_world: &Matrix4<f64>,
) -> anyhow::Result<()> {
    let apply = |p: &Point3<f64>| {
        let q = tool_to_world.transform_point(p);
        [q.x as f32, q.y as f32, q.z as f32]
    };
    let base = format!("world/tool/{which}");
    let colour = if which == "truth" { [80, 220, 120, 255] } else { [255, 120, 40, 255] };
    let vertices: Vec<[f32; 3]> = tool.mesh.vertices.iter().map(apply).collect();
    hullcut_viz::log_mesh3d(rec, &format!("{base}/mesh"), &vertices, &tool.mesh.triangles, colour)?;
    let edge: Vec<[f32; 3]> = tool.cutting_edge.iter().map(apply).collect();
    hullcut_viz::log_line_strips3d(rec, &format!("{base}/edge"), &[edge], colour, 0.0005)?;
    hullcut_viz::log_points3d(rec, &format!("{base}/tip"), &[apply(&tool.tip)], colour, 0.0015)?;
    Ok(())
}
