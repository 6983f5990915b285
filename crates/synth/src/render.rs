//! A z-buffered triangle rasterizer for calibrated, distorted cameras.
//!
//! Exactness: every pixel centre is turned into its undistorted ray once per camera (Newton
//! inversion of the rig's distortion); triangles are tested against those rays in the undistorted
//! image plane, where straight edges stay straight, and the depth is the exact ray–plane
//! intersection in double precision. A pixel's label and depth are therefore those of the first
//! surface the ray through its centre hits (DESIGN's convention), with no approximation from the
//! distortion. Colour is sampled at the pixel centre too (no anti-aliasing); only the static
//! background is supersampled.

use hullcut_rig::Camera;
use nalgebra::{Point3, Vector2, Vector3};

use crate::texture::{BackgroundHit, table_hit, trace_background_on};
use crate::{Background, TriMesh};

/// Triangles with a vertex closer than this to the camera plane are skipped (and counted).
pub const NEAR: f64 = 0.02;

/// A directional light with an ambient term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Unit direction toward the light, world frame.
    pub direction: Vector3<f64>,
    /// Ambient fraction.
    pub ambient: f32,
    /// Diffuse fraction.
    pub diffuse: f32,
}

impl Default for Light {
    fn default() -> Self {
        Light { direction: Vector3::new(0.25, -0.35, 1.0).normalize(), ambient: 0.3, diffuse: 0.7 }
    }
}

impl Light {
    /// Lambert factor for a unit world normal.
    pub fn lambert(&self, normal: &Vector3<f64>) -> f32 {
        self.ambient + self.diffuse * normal.dot(&self.direction).max(0.0) as f32
    }
}

/// An object to draw: a closed world-frame mesh with a label and an albedo.
#[derive(Debug, Clone)]
pub struct Part {
    /// Label written into the mask where this part is the first hit.
    pub label: u8,
    /// Linear albedo per channel, 0..1.
    pub albedo: [f32; 3],
    /// The mesh in world coordinates.
    pub mesh: TriMesh,
}

/// What one render produces before the sensor model: lit colour, labels and depth per pixel.
#[derive(Debug, Clone)]
pub struct Layers {
    /// Lit colour per pixel (linear 0..1), row-major.
    pub rgb: Vec<[f32; 3]>,
    /// Label per pixel.
    pub labels: Vec<u8>,
    /// Depth along the optical axis per pixel, metres; 0 where the ray hits nothing at a finite
    /// distance (the walls).
    pub depth: Vec<f64>,
    /// Triangles skipped because they came closer than [`NEAR`] to the camera.
    pub skipped_triangles: usize,
}

/// A camera prepared for rendering: per-pixel rays and the lit static background.
#[derive(Debug, Clone)]
pub struct CameraRenderer {
    camera: Camera,
    /// Undistorted normalized coordinates per pixel centre; NaN where the distortion cannot be
    /// inverted.
    rays: Vec<[f64; 2]>,
    background_rgb: Vec<[f32; 3]>,
    background_depth: Vec<f64>,
    /// Table position seen through each pixel centre, NaN where the ray misses the table (for
    /// shadows).
    table_xy: Vec<[f32; 2]>,
    background: Background,
    light: Light,
    /// The lens' invertible radius, computed once (it is a root search).
    monotonic_radius: f64,
}

impl CameraRenderer {
    /// Precomputes rays and the background (the green drape) for `camera` under `light`.
    pub fn new(camera: &Camera, light: Light) -> Self {
        Self::with_background(camera, light, Background::Drape)
    }

    /// Precomputes rays and the background for `camera` under `light`, the table covered by
    /// `background`.
    pub fn with_background(camera: &Camera, light: Light, background: Background) -> Self {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut rays = vec![[f64::NAN; 2]; w * h];
        for j in 0..h {
            for i in 0..w {
                if let Some(xn) = camera.undistort(nalgebra::Point2::new(i as f64, j as f64)) {
                    rays[j * w + i] = [xn.x, xn.y];
                }
            }
        }
        let mut renderer = CameraRenderer {
            camera: camera.clone(),
            rays,
            background_rgb: vec![[0.0; 3]; w * h],
            background_depth: vec![0.0; w * h],
            table_xy: vec![[f32::NAN; 2]; w * h],
            background,
            light,
            monotonic_radius: camera.distortion.monotonic_radius(),
        };
        renderer.shade_background();
        renderer
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The undistorted normalized ray of a pixel centre (None outside the image or where the
    /// distortion is not invertible).
    pub fn ray(&self, i: usize, j: usize) -> Option<Vector2<f64>> {
        let w = self.camera.width as usize;
        if i >= w || j >= self.camera.height as usize {
            return None;
        }
        let r = self.rays[j * w + i];
        (!r[0].is_nan()).then(|| Vector2::new(r[0], r[1]))
    }

    /// The ray at a sub-pixel position, bilinear in the per-pixel table.
    fn ray_at(&self, u: f64, v: f64) -> Option<Vector2<f64>> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let i0 = (u.floor().max(0.0) as usize).min(w - 2);
        let j0 = (v.floor().max(0.0) as usize).min(h - 2);
        let (fu, fv) = (u - i0 as f64, v - j0 as f64);
        let r00 = self.ray(i0, j0)?;
        let r10 = self.ray(i0 + 1, j0)?;
        let r01 = self.ray(i0, j0 + 1)?;
        let r11 = self.ray(i0 + 1, j0 + 1)?;
        Some((r00 * (1.0 - fu) + r10 * fu) * (1.0 - fv) + (r01 * (1.0 - fu) + r11 * fu) * fv)
    }

    fn shade_background(&mut self) {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let origin = self.camera.centre();
        let to_world = self.camera.rotation.inverse();
        let up_shade = self.light.lambert(&Vector3::z());
        let offsets = [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)];
        for j in 0..h {
            for i in 0..w {
                let k = j * w + i;
                let Some(centre) = self.ray(i, j) else { continue };
                let world = |r: Vector2<f64>| to_world * Vector3::new(r.x, r.y, 1.0);
                self.background_depth[k] = match trace_background_on(&origin, &world(centre), &self.background) {
                    BackgroundHit::Surface { s, .. } => s,
                    BackgroundHit::Wall(_) => 0.0,
                };
                if let Some((x, y)) = table_hit(&origin, &world(centre)) {
                    self.table_xy[k] = [x as f32, y as f32];
                }
                let mut sum = [0.0f32; 3];
                for (du, dv) in offsets {
                    let r = self.ray_at(i as f64 + du, j as f64 + dv).unwrap_or(centre);
                    let c = match trace_background_on(&origin, &world(r), &self.background) {
                        BackgroundHit::Surface { albedo, .. } => albedo.map(|a| a * up_shade),
                        BackgroundHit::Wall(c) => c,
                    };
                    for ch in 0..3 {
                        sum[ch] += c[ch] / offsets.len() as f32;
                    }
                }
                self.background_rgb[k] = sum;
            }
        }
    }

    /// Renders the parts over the static background.
    pub fn render(&self, parts: &[Part]) -> Layers {
        self.render_shadowed(parts, None)
    }

    /// Renders the parts over the static background, the table darkened where `shadow` says the
    /// parts hide the light (the diffuse term goes, the ambient one stays).
    pub fn render_shadowed(&self, parts: &[Part], shadow: Option<&ShadowMap>) -> Layers {
        let mut rgb = self.background_rgb.clone();
        if let Some(shadow) = shadow {
            let lit = self.light.lambert(&Vector3::z());
            let dark = if lit > 0.0 { self.light.ambient / lit } else { 1.0 };
            for (px, xy) in rgb.iter_mut().zip(&self.table_xy) {
                if xy[0].is_nan() {
                    continue;
                }
                let s = shadow.at(f64::from(xy[0]), f64::from(xy[1]));
                if s > 0.0 {
                    let f = 1.0 - s * (1.0 - dark);
                    *px = px.map(|c| c * f);
                }
            }
        }
        let mut layers = Layers {
            rgb,
            labels: vec![hullcut_dataset::label::BACKGROUND; self.rays.len()],
            depth: vec![f64::INFINITY; self.rays.len()],
            skipped_triangles: 0,
        };
        for part in parts {
            self.draw(part, &mut layers);
        }
        for (d, bg) in layers.depth.iter_mut().zip(&self.background_depth) {
            if d.is_infinite() {
                *d = *bg;
            }
        }
        layers
    }

    /// Pixel bounding box (inclusive) of a camera-frame triangle, allowing for the curvature the
    /// distortion gives its edges; None when it misses the image.
    fn pixel_bounds(&self, tri: [Point3<f64>; 3]) -> Option<[usize; 4]> {
        let cam = &self.camera;
        let (w, h) = (cam.width as f64, cam.height as f64);
        let limit = self.monotonic_radius;
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for e in 0..3 {
            let (p, q) = (tri[e], tri[(e + 1) % 3]);
            for s in [0.0, 0.25, 0.5, 0.75] {
                let x = p + (q - p) * s;
                let xn = Vector2::new(x.x / x.z, x.y / x.z);
                if xn.norm() >= limit {
                    return Some([0, 0, w as usize - 1, h as usize - 1]);
                }
                let uv = cam.normalized_to_pixel(cam.distortion.distort(xn));
                u0 = u0.min(uv.x);
                v0 = v0.min(uv.y);
                u1 = u1.max(uv.x);
                v1 = v1.max(uv.y);
            }
        }
        // Sampled edges bound the curved ones to well under a pixel for these lenses; one pixel of
        // margin covers the rest.
        let (u0, v0, u1, v1) = ((u0 - 1.0).ceil(), (v0 - 1.0).ceil(), (u1 + 1.0).floor(), (v1 + 1.0).floor());
        if u1 < 0.0 || v1 < 0.0 || u0 > w - 1.0 || v0 > h - 1.0 {
            return None;
        }
        Some([u0.max(0.0) as usize, v0.max(0.0) as usize, u1.min(w - 1.0) as usize, v1.min(h - 1.0) as usize])
    }

    fn draw(&self, part: &Part, layers: &mut Layers) {
        let cam = &self.camera;
        let w = cam.width as usize;
        let pc: Vec<Point3<f64>> = part.mesh.vertices.iter().map(|p| cam.world_to_camera(p)).collect();
        let to_world = cam.rotation.inverse();
        for t in &part.mesh.triangles {
            let tri = t.map(|i| pc[i as usize]);
            if tri.iter().any(|p| p.z < NEAR) {
                layers.skipped_triangles += 1;
                continue;
            }
            let [a, b, c] = tri;
            let n = (b - a).cross(&(c - a));
            let d = n.dot(&a.coords);
            if d >= 0.0 {
                continue; // facing away from the camera (closed meshes: hidden anyway)
            }
            let Some([i0, j0, i1, j1]) = self.pixel_bounds(tri) else { continue };
            let shade = self.light.lambert(&(to_world * n).normalize());
            let colour = part.albedo.map(|x| x * shade);
            let q = |p: Point3<f64>| Vector2::new(p.x / p.z, p.y / p.z);
            let (qa, qb, qc) = (q(a), q(b), q(c));
            let cross = |u: Vector2<f64>, v: Vector2<f64>| u.x * v.y - u.y * v.x;
            let area = cross(qb - qa, qc - qa);
            if area == 0.0 {
                continue;
            }
            let sign = area.signum();
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let k = j * w + i;
                    let [x, y] = self.rays[k];
                    let r = Vector2::new(x, y);
                    if !(sign * cross(qc - qb, r - qb) >= 0.0
                        && sign * cross(qa - qc, r - qc) >= 0.0
                        && sign * cross(qb - qa, r - qa) >= 0.0)
                    {
                        continue; // outside, or a NaN ray
                    }
                    let z = d / (n.x * x + n.y * y + n.z);
                    if z > 0.0 && z < layers.depth[k] {
                        layers.depth[k] = z;
                        layers.labels[k] = part.label;
                        layers.rgb[k] = colour;
                    }
                }
            }
        }
    }
}

/// The shadow the parts cast on the table (z = 0) under a directional light, on a 1 mm grid,
/// softened over 3 mm (a penumbra): 0 lit, 1 in full shadow.
#[derive(Debug, Clone)]
pub struct ShadowMap {
    origin: [f64; 2],
    dims: [usize; 2],
    shade: Vec<f32>,
}

/// Cell of the shadow grid, metres.
const SHADOW_CELL: f64 = 0.001;

impl ShadowMap {
    /// Casts the parts' shadow along `light`; `None` when the light is at or below the horizon or
    /// nothing casts a shadow on the table.
    pub fn cast(parts: &[Part], light: &Light) -> Option<Self> {
        let l = light.direction;
        if l.z <= 1e-6 {
            return None;
        }
        let onto_table = |p: &Point3<f64>| [p.x - l.x * p.z / l.z, p.y - l.y * p.z / l.z];
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        let flat: Vec<Vec<[f64; 2]>> = parts
            .iter()
            .map(|part| {
                part.mesh
                    .vertices
                    .iter()
                    .map(|p| {
                        let q = onto_table(p);
                        for a in 0..2 {
                            lo[a] = lo[a].min(q[a]);
                            hi[a] = hi[a].max(q[a]);
                        }
                        q
                    })
                    .collect()
            })
            .collect();
        if lo[0] > hi[0] {
            return None;
        }
        // Two cells of padding each side for the penumbra; at most a 2 m square of shadow.
        let origin = [lo[0] - 2.0 * SHADOW_CELL, lo[1] - 2.0 * SHADOW_CELL];
        let dims = [0, 1].map(|a| (((hi[a] - lo[a]) / SHADOW_CELL).ceil() as usize + 5).min(2000));
        let mut hard = vec![0u8; dims[0] * dims[1]];
        for (part, q) in parts.iter().zip(&flat) {
            for t in &part.mesh.triangles {
                let [a, b, c] = t.map(|i| q[i as usize]);
                let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                if area.abs() < 1e-14 {
                    continue;
                }
                let cell = |v: f64, a: usize| ((v - origin[a]) / SHADOW_CELL - 0.5).max(0.0);
                let i0 = cell(a[0].min(b[0]).min(c[0]), 0).floor() as usize;
                let i1 = (cell(a[0].max(b[0]).max(c[0]), 0).ceil() as usize).min(dims[0] - 1);
                let j0 = cell(a[1].min(b[1]).min(c[1]), 1).floor() as usize;
                let j1 = (cell(a[1].max(b[1]).max(c[1]), 1).ceil() as usize).min(dims[1] - 1);
                let edge =
                    |p: [f64; 2], q: [f64; 2], x: f64, y: f64| (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]);
                for j in j0..=j1 {
                    let y = origin[1] + (j as f64 + 0.5) * SHADOW_CELL;
                    for i in i0..=i1 {
                        let x = origin[0] + (i as f64 + 0.5) * SHADOW_CELL;
                        let (e0, e1, e2) = (edge(a, b, x, y), edge(b, c, x, y), edge(c, a, x, y));
                        if e0 * area >= 0.0 && e1 * area >= 0.0 && e2 * area >= 0.0 {
                            hard[j * dims[0] + i] = 1;
                        }
                    }
                }
            }
        }
        // A 3x3 box filter: a penumbra of about 3 mm.
        let mut shade = vec![0.0f32; hard.len()];
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let mut sum = 0u32;
                for dj in j.saturating_sub(1)..=(j + 1).min(dims[1] - 1) {
                    for di in i.saturating_sub(1)..=(i + 1).min(dims[0] - 1) {
                        sum += u32::from(hard[dj * dims[0] + di]);
                    }
                }
                shade[j * dims[0] + i] = sum as f32 / 9.0;
            }
        }
        Some(ShadowMap { origin, dims, shade })
    }

    /// The shadow at table position (x, y): 0 lit, 1 in full shadow.
    pub fn at(&self, x: f64, y: f64) -> f32 {
        let (fi, fj) = ((x - self.origin[0]) / SHADOW_CELL, (y - self.origin[1]) / SHADOW_CELL);
        if !(fi >= 0.0 && fj >= 0.0) {
            return 0.0;
        }
        let (i, j) = (fi as usize, fj as usize);
        if i >= self.dims[0] || j >= self.dims[1] {
            return 0.0;
        }
        self.shade[j * self.dims[0] + i]
    }
}
