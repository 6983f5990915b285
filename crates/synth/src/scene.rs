//! A synthetic scene: rig, scalpel, hand, trajectory, lighting, camera timing and drops.

use hullcut_dataset::{Mesh, TruthPose, label};
use hullcut_rig::Rig;
use image::{GrayImage, ImageBuffer, Luma, RgbImage};
use nalgebra::Point3;
use rayon::prelude::*;

use crate::render::{CameraRenderer, Layers, Part, ShadowMap};
use crate::sensor::expose_channels;
use crate::texture::mix64;
use crate::{Appearance, Resection, Scalpel, SceneKind, SynthError, ToolKind, Trajectory, TriMesh, hand_mesh_on};

/// Start of every synthetic recording: 2026-11-18 00:00:00 UTC, in nanoseconds since the epoch.
pub const START_NS: i64 = 1_795_478_400_000_000_000;

/// A 16-bit depth image in millimetres.
pub type DepthImage = ImageBuffer<Luma<u16>, Vec<u16>>;

/// Everything that defines a synthetic recording.
#[derive(Debug, Clone)]
pub struct SceneConfig {
    /// What the tool does.
    pub kind: SceneKind,
    /// Seed for every random choice (trajectory, timing, noise).
    pub seed: u64,
    /// Nominal frame rate.
    pub fps: f64,
    /// Number of frame sets.
    pub frames: u64,
    /// The cameras.
    pub rig: Rig,
    /// Standard deviation of the sensor's read noise, 8-bit levels.
    pub noise_sigma: f32,
    /// Relative amplitude of the slow exposure drift (0.15 = ±15 %).
    pub exposure_drift: f32,
    /// Sub-frame renders averaged over the shutter time (1 = no motion blur).
    pub motion_blur_samples: usize,
    /// Shutter (exposure) time, seconds.
    pub shutter_s: f64,
    /// Standard deviation of each camera's timestamp jitter, seconds.
    pub jitter_s: f64,
    /// Camera that drops frames and the fraction it drops (the `hard` scene).
    pub dropping_camera: Option<(usize, f64)>,
    /// Empty-scene images written per camera for the background model.
    pub background_frames: usize,
    /// Write world-frame truth meshes for every frame and label.
    pub truth_meshes: bool,
    /// Write every view's depth map (depth/, 16-bit millimetres): the hull's benchmark scores
    /// against them; the loop never reads them (a tenth of a recording's bytes).
    pub depth_maps: bool,
    /// PNG compression of the written dataset.
    pub compression: hullcut_dataset::PngCompression,
    /// How far below [`crate::ORGAN_TOP`] the blade's tip presses during a stroke, metres, drawn
    /// uniformly from this range per stroke (`cut` and `hard` scenes, and `resect` after its
    /// resection).
    pub stroke_depth: [f64; 2],
    /// How the scene looks (hand, tool finish, table, light, shadows).
    pub appearance: Appearance,
    /// Which scalpel the hand holds.
    pub tool: ToolKind,
    /// The organ the tool works on, times the built-in organ's size (its strokes, resection and
    /// hovering scaled with it about the origin, the tool and hand unchanged): 1 for the built-in
    /// organ, 1.2 for the large one (`hullcut run --tissue organ-large`).
    pub organ_scale: f64,
}

/// Default of [`SceneConfig::stroke_depth`]: shallow strokes, the tool's pose being what these
/// scenes measure.
pub const DEFAULT_STROKE_DEPTH: [f64; 2] = [0.008, 0.025];

impl SceneConfig {
    /// The defaults of a scene kind on the default rig.
    pub fn new(kind: SceneKind, seed: u64, frames: u64) -> Self {
        let hard = kind == SceneKind::Hard;
        SceneConfig {
            kind,
            seed,
            fps: 30.0,
            frames,
            rig: hullcut_rig::default_rig(),
            noise_sigma: 2.0,
            exposure_drift: if hard { 0.15 } else { 0.04 },
            motion_blur_samples: if hard { 3 } else { 1 },
            shutter_s: 0.008,
            jitter_s: 150e-6,
            dropping_camera: hard.then_some((4, 0.1)),
            background_frames: 5,
            truth_meshes: true,
            depth_maps: true,
            compression: hullcut_dataset::PngCompression::Fast,
            stroke_depth: DEFAULT_STROKE_DEPTH,
            appearance: Appearance::classic(),
            tool: ToolKind::Standard,
            organ_scale: 1.0,
        }
    }
}

/// One rendered camera view with its truth.
#[derive(Debug, Clone)]
pub struct RenderedView {
    /// Capture time, nanoseconds.
    pub timestamp_ns: i64,
    /// The colour image.
    pub image: RgbImage,
    /// Label mask: the first surface hit by each pixel's centre ray.
    pub mask: GrayImage,
    /// Depth along the optical axis, millimetres (0 where nothing is hit at a finite distance).
    pub depth: DepthImage,
    /// Triangles skipped because they came too close to the camera.
    pub skipped_triangles: usize,
}

/// A synthetic scene ready to render.
#[derive(Debug)]
pub struct Scene {
    config: SceneConfig,
    scalpel: Scalpel,
    trajectory: Trajectory,
    renderers: Vec<CameraRenderer>,
    /// Capture timestamps per frame and camera; None where the camera dropped the frame.
    schedule: Vec<Vec<Option<i64>>>,
}

impl Scene {
    /// Prepares a scene: the trajectory, camera timing and each camera's rays and background.
    pub fn new(config: SceneConfig) -> Result<Self, SynthError> {
        if config.rig.is_empty() {
            return Err(SynthError::Config("the rig has no cameras".into()));
        }
        if !(config.fps > 0.0 && config.fps.is_finite()) {
            return Err(SynthError::Config(format!("fps must be positive, got {}", config.fps)));
        }
        if !(config.organ_scale.is_finite() && (0.1..=10.0).contains(&config.organ_scale)) {
            return Err(SynthError::Config(format!("organ_scale must be 0.1 to 10, got {}", config.organ_scale)));
        }
        if config.motion_blur_samples == 0 {
            return Err(SynthError::Config("motion_blur_samples must be at least 1".into()));
        }
        let scalpel = Scalpel::of(config.tool);
        let duration = config.frames as f64 / config.fps;
        // The cameras' azimuths about the working area (the hard scene strokes edge-on to them).
        let azimuths: Vec<f64> =
            config.rig.cameras.iter().map(|c| c.centre().y.atan2(c.centre().x).to_degrees()).collect();
        let trajectory = Trajectory::for_scene_with(
            config.kind,
            config.seed,
            duration,
            scalpel.geometry.tip,
            config.stroke_depth,
            &azimuths,
            Resection::for_tool(config.tool),
        )
        .scaled(config.organ_scale);
        let (light, background) = (config.appearance.light, config.appearance.background);
        let renderers =
            config.rig.cameras.par_iter().map(|c| CameraRenderer::with_background(c, light, background)).collect();
        let schedule = Self::schedule(&config);
        Ok(Scene { config, scalpel, trajectory, renderers, schedule })
    }

    fn schedule(config: &SceneConfig) -> Vec<Vec<Option<i64>>> {
        let period_ns = 1e9 / config.fps;
        let cameras = config.rig.len();
        let uniform = |h: u64| (h >> 11) as f64 / (1u64 << 53) as f64;
        (0..config.frames)
            .map(|f| {
                (0..cameras)
                    .map(|c| {
                        let h = mix64(config.seed ^ mix64(f << 8 | c as u64));
                        if let Some((cam, fraction)) = config.dropping_camera
                            && cam == c
                            && (uniform(mix64(h ^ 0xd409)) < fraction || f % 23 == 11)
                        {
                            return None;
                        }
                        // A fixed offset per camera (trigger delay) plus jitter per frame.
                        let offset = (uniform(mix64(config.seed ^ c as u64 ^ 0x0ff5)) - 0.5) * 0.8e-3;
                        let jitter = config.jitter_s * f64::from(crate::sensor::standard_normal(h));
                        Some(START_NS + (f as f64 * period_ns + (offset + jitter) * 1e9).round() as i64)
                    })
                    .collect()
            })
            .collect()
    }

    /// The configuration.
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

    /// The scalpel.
    pub fn scalpel(&self) -> &Scalpel {
        &self.scalpel
    }

    /// The tool's trajectory.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The renderer of camera `camera`.
    pub fn renderer(&self, camera: usize) -> Option<&CameraRenderer> {
        self.renderers.get(camera)
    }

    /// Capture time of a camera's frame, None when dropped (or out of range).
    pub fn timestamp(&self, frame: u64, camera: usize) -> Option<i64> {
        self.schedule.get(frame as usize)?.get(camera).copied().flatten()
    }

    /// A frame set's time: the median of its cameras' timestamps (lower median), or the nominal time
    /// when every camera dropped it.
    pub fn frame_timestamp(&self, frame: u64) -> i64 {
        let mut t: Vec<i64> = self.schedule.get(frame as usize).into_iter().flatten().flatten().copied().collect();
        t.sort_unstable();
        t.get(t.len().saturating_sub(1) / 2)
            .copied()
            .unwrap_or(START_NS + (frame as f64 * 1e9 / self.config.fps) as i64)
    }

    /// Seconds since the start of the recording.
    pub fn seconds(timestamp_ns: i64) -> f64 {
        (timestamp_ns - START_NS) as f64 * 1e-9
    }

    /// The world-frame parts (hand, handle, blade) at time `t` seconds.
    pub fn parts_at(&self, t: f64) -> Vec<Part> {
        let state = self.trajectory.state_at(t);
        let pose = state.tool_to_world;
        let look = &self.config.appearance;
        vec![
            Part {
                label: label::HAND,
                albedo: look.hand,
                mesh: hand_mesh_on(state.grip, &self.scalpel.fit).transformed(&pose),
            },
            Part { label: label::SCALPEL, albedo: look.handle, mesh: self.scalpel.handle.transformed(&pose) },
            Part { label: label::SCALPEL, albedo: look.blade, mesh: self.scalpel.blade.transformed(&pose) },
        ]
    }

    /// Renders the parts at time `t` through a camera, with their shadow when the look has them.
    fn render_at(&self, renderer: &CameraRenderer, t: f64) -> Layers {
        let parts = self.parts_at(t);
        let look = &self.config.appearance;
        let shadow = if look.shadows { ShadowMap::cast(&parts, &look.light) } else { None };
        renderer.render_shadowed(&parts, shadow.as_ref())
    }

    /// Per-channel gains of a camera's frame: its exposure and the light's colour then.
    fn gains(&self, frame: u64, camera: usize, t: f64) -> [f32; 3] {
        let g = self.exposure_gain(frame, camera);
        self.config.appearance.colour_gains(t).map(|c| c * g)
    }

    /// Exposure gain of a camera's frame: a slow drift, different per camera.
    pub fn exposure_gain(&self, frame: u64, camera: usize) -> f32 {
        let t = frame as f64 / self.config.fps;
        let phase = camera as f64 * 1.3 + (self.config.seed % 97) as f64 * 0.1;
        1.0 + self.config.exposure_drift * (std::f64::consts::TAU * t / 4.0 + phase).sin() as f32
    }

    /// Renders one camera's view of a frame, None when the camera dropped it.
    pub fn render_view(&self, frame: u64, camera: usize) -> Option<RenderedView> {
        let timestamp_ns = self.timestamp(frame, camera)?;
        let renderer = self.renderers.get(camera)?;
        let cam = renderer.camera();
        let t = Self::seconds(timestamp_ns);
        let centre = self.render_at(renderer, t);
        let n = self.config.motion_blur_samples;
        let rgb = if n > 1 {
            let mut sum: Vec<[f32; 3]> = vec![[0.0; 3]; centre.rgb.len()];
            for k in 0..n {
                let offset = self.config.shutter_s * (k as f64 / (n - 1) as f64 - 0.5);
                let layers: Layers = if 2 * k + 1 == n { centre.clone() } else { self.render_at(renderer, t + offset) };
                for (s, c) in sum.iter_mut().zip(&layers.rgb) {
                    for ch in 0..3 {
                        s[ch] += c[ch] / n as f32;
                    }
                }
            }
            sum
        } else {
            centre.rgb.clone()
        };
        let salt = mix64(self.config.seed ^ mix64(frame << 8 | camera as u64) ^ 0x5e45);
        let image =
            expose_channels(&rgb, cam.width, cam.height, self.gains(frame, camera, t), self.config.noise_sigma, salt);
        let mask = GrayImage::from_raw(cam.width, cam.height, centre.labels).unwrap_or_default();
        let depth_mm: Vec<u16> =
            centre.depth.iter().map(|&z| (z * 1000.0).round().clamp(0.0, 65535.0) as u16).collect();
        let depth = DepthImage::from_raw(cam.width, cam.height, depth_mm).unwrap_or_default();
        Some(RenderedView { timestamp_ns, image, mask, depth, skipped_triangles: centre.skipped_triangles })
    }

    /// An empty-scene image of a camera (for the background model), with its own noise and a small
    /// exposure change between images.
    pub fn render_background(&self, camera: usize, index: usize) -> Option<RgbImage> {
        let renderer = self.renderers.get(camera)?;
        let cam = renderer.camera();
        let layers = renderer.render(&[]);
        let gain = 1.0 + 0.5 * self.config.exposure_drift * ((index as f32) * 1.7).sin();
        let gains = self.config.appearance.colour_gains(0.0).map(|c| c * gain);
        let salt = mix64(self.config.seed ^ 0xb6 ^ mix64((index as u64) << 8 | camera as u64));
        Some(expose_channels(&layers.rgb, cam.width, cam.height, gains, self.config.noise_sigma, salt))
    }

    /// The true tool pose at a frame set's time.
    pub fn truth_pose(&self, frame: u64) -> TruthPose {
        let timestamp_ns = self.frame_timestamp(frame);
        let pose = self.trajectory.state_at(Self::seconds(timestamp_ns)).tool_to_world;
        TruthPose { frame, timestamp_ns, tool_to_world: pose.to_homogeneous() }
    }

    /// World-frame truth meshes per label name at a frame set's time.
    pub fn truth_meshes(&self, frame: u64) -> Vec<(&'static str, Mesh)> {
        let parts = self.parts_at(Self::seconds(self.frame_timestamp(frame)));
        label::NAMED
            .iter()
            .map(|&(l, name)| {
                let mut mesh = TriMesh::default();
                for p in parts.iter().filter(|p| p.label == l) {
                    mesh.append(&p.mesh);
                }
                (name, mesh)
            })
            .collect()
    }

    /// The blade tip in world coordinates at time `t`.
    pub fn tip_at(&self, t: f64) -> Point3<f64> {
        self.trajectory.state_at(t).tool_to_world * self.scalpel.geometry.tip
    }
}
