//! A calibrated pinhole camera with OpenCV's distortion and world→camera extrinsics.

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector2, Vector3};

use crate::Distortion;

/// A calibrated camera: intrinsics, distortion, image size and world→camera pose.
///
/// Extrinsics follow OpenCV: `x_cam = R · x_world + t`, camera axes x right, y down, z forward.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Camera name (the folder name in datasets and calibration image trees).
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
    /// World→camera rotation `R`.
    pub rotation: Rotation3<f64>,
    /// World→camera translation `t`, metres.
    pub translation: Vector3<f64>,
    /// RMS reprojection error of the calibration that produced this camera, pixels.
    pub rms_reprojection_error: Option<f64>,
}

/// Where a world point lands in a camera image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Pixel coordinates (u, v); pixel (col i, row j) has its centre at (i, j).
    pub pixel: Point2<f64>,
    /// Depth along the optical axis, metres (negative behind the camera).
    pub depth: f64,
    /// True when the point is in front of the camera, within the distortion's invertible range and
    /// inside the image (`-0.5 <= u < width - 0.5`, likewise v).
    pub visible: bool,
}

/// A ray in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start of the ray (the camera centre), world metres.
    pub origin: Point3<f64>,
    /// Unit direction, world frame.
    pub direction: Unit<Vector3<f64>>,
}

impl Ray {
    /// The point at distance `s` along the ray.
    pub fn at(&self, s: f64) -> Point3<f64> {
        self.origin + self.direction.into_inner() * s
    }
}

impl Camera {
    /// A distortion-free camera at the world origin looking along +z.
    pub fn new(name: impl Into<String>, width: u32, height: u32, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self {
            name: name.into(),
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            distortion: Distortion::NONE,
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
            rms_reprojection_error: None,
        }
    }

    /// The same camera with its image resampled by `factor` (0.5 halves width and height): focal
    /// lengths scale, and the principal point keeps its place on the sensor under the convention
    /// that pixel centres sit at integer coordinates (`c' = (c + 0.5) · factor − 0.5`).
    /// Distortion is in normalized coordinates and does not change.
    pub fn scaled(&self, factor: f64) -> Camera {
        let mut c = self.clone();
        c.width = ((self.width as f64) * factor).round().max(1.0) as u32;
        c.height = ((self.height as f64) * factor).round().max(1.0) as u32;
        c.fx *= factor;
        c.fy *= factor;
        c.cx = (self.cx + 0.5) * factor - 0.5;
        c.cy = (self.cy + 0.5) * factor - 0.5;
        c
    }

    /// The intrinsic matrix `K`.
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Sets the pose so that the camera sits at `eye` and looks at `target`, with image "up" (−y)
    /// as close to `up` as possible. Returns `None` if `eye == target` or the view is parallel to `up`.
    pub fn looking_at(mut self, eye: Point3<f64>, target: Point3<f64>, up: Vector3<f64>) -> Option<Self> {
        let z = (target - eye).try_normalize(1e-12)?;
        let x = z.cross(&up).try_normalize(1e-12)?;
        let y = z.cross(&x);
        // Rows of R are the camera axes expressed in world coordinates.
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        self.rotation = Rotation3::from_matrix_unchecked(r);
        self.translation = -(self.rotation * eye.coords);
        Some(self)
    }

    /// The camera centre in world coordinates, `-Rᵀ t`.
    pub fn centre(&self) -> Point3<f64> {
        Point3::from(-(self.rotation.inverse() * self.translation))
    }

    /// The optical axis (camera +z) in world coordinates.
    pub fn viewing_direction(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(self.rotation.inverse() * Vector3::z())
    }

    /// World point → camera frame.
    #[inline]
    pub fn world_to_camera(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * p.coords + self.translation)
    }

    /// Normalized image coordinates (after distortion) → pixel.
    #[inline]
    pub fn normalized_to_pixel(&self, xd: Vector2<f64>) -> Point2<f64> {
        Point2::new(self.fx * xd.x + self.cx, self.fy * xd.y + self.cy)
    }

    /// Pixel → distorted normalized image coordinates.
    #[inline]
    pub fn pixel_to_normalized(&self, uv: Point2<f64>) -> Vector2<f64> {
        Vector2::new((uv.x - self.cx) / self.fx, (uv.y - self.cy) / self.fy)
    }

    /// Whether a pixel position lies inside the image (`-0.5 <= u < width - 0.5`, likewise v).
    #[inline]
    pub fn contains_pixel(&self, uv: Point2<f64>) -> bool {
        uv.x >= -0.5 && uv.y >= -0.5 && uv.x < self.width as f64 - 0.5 && uv.y < self.height as f64 - 0.5
    }

    /// A point in the camera frame → pixel, with distortion (no visibility test).
    #[inline]
    pub fn project_camera_point(&self, pc: &Point3<f64>) -> Point2<f64> {
        let xn = Vector2::new(pc.x / pc.z, pc.y / pc.z);
        self.normalized_to_pixel(self.distortion.distort(xn))
    }

    /// World point → pixel, with a visibility flag (see [`Projection::visible`]).
    #[inline]
    pub fn project(&self, p: &Point3<f64>) -> Projection {
        let pc = self.world_to_camera(p);
        let depth = pc.z;
        if depth <= 0.0 {
            return Projection { pixel: Point2::new(f64::NAN, f64::NAN), depth, visible: false };
        }
        let xn = Vector2::new(pc.x / pc.z, pc.y / pc.z);
        let pixel = self.normalized_to_pixel(self.distortion.distort(xn));
        let visible = xn.norm() < self.distortion.monotonic_radius() && self.contains_pixel(pixel);
        Projection { pixel, depth, visible }
    }

    /// A disc of pixels that holds the projection of every point within `rho` of the world point
    /// `centre`: the centre's pixel and the disc's radius. `None` where the ball comes nearer than
    /// `near` to the camera's plane, or where the normalized points it spans may reach
    /// `max_radius` (beyond the lens' invertible radius a projection folds back: pass
    /// [`Distortion::monotonic_radius`]), or where the camera's numbers are not finite; the
    /// caller then projects what it needs point by point.
    ///
    /// With the centre at `(X, Y, Z)` in the camera frame, a point of the ball lies within
    /// `rho (1 + |(X, Y)| / Z) / (Z - rho)` of the centre in normalized coordinates, and the
    /// distortion stretches that by at most [`Distortion::stretch_bound`].
    ///
    /// [`Distortion::monotonic_radius`]: crate::Distortion::monotonic_radius
    /// [`Distortion::stretch_bound`]: crate::Distortion::stretch_bound
    pub fn project_ball(
        &self,
        centre: &Point3<f64>,
        rho: f64,
        near: f64,
        max_radius: f64,
    ) -> Option<(Point2<f64>, f64)> {
        self.project_ball_in_camera(&self.world_to_camera(centre), rho, near, max_radius)
    }

    /// [`Camera::project_ball`] of a centre already in the camera's frame (`pc`), for a caller
    /// that has it (for its depth).
    #[inline(always)]
    pub fn project_ball_in_camera(
        &self,
        pc: &Point3<f64>,
        rho: f64,
        near: f64,
        max_radius: f64,
    ) -> Option<(Point2<f64>, f64)> {
        // Comparisons that are false for NaN: a non-finite ball gives no disc.
        (pc.z - rho > near).then_some(())?;
        let xn = Vector2::new(pc.x / pc.z, pc.y / pc.z);
        let spread = rho * (1.0 + xn.norm()) / (pc.z - rho);
        let reach = xn.norm() + spread;
        (reach < max_radius).then_some(())?;
        let radius = self.fx.abs().max(self.fy.abs()) * self.distortion.stretch_bound(reach) * spread;
        // A non-finite focal length or coefficient bounds nothing.
        radius.is_finite().then(|| (self.normalized_to_pixel(self.distortion.distort(xn)), radius))
    }

    /// Pixel → undistorted normalized image coordinates `(x/z, y/z)`.
    ///
    /// Returns `None` when the inversion does not converge (see [`Distortion::undistort`]).
    pub fn undistort(&self, uv: Point2<f64>) -> Option<Vector2<f64>> {
        self.distortion.undistort(self.pixel_to_normalized(uv))
    }

    /// Pixel → undistorted pixel (the pixel an ideal camera with the same `K` would see).
    pub fn undistort_pixel(&self, uv: Point2<f64>) -> Option<Point2<f64>> {
        self.undistort(uv).map(|xn| self.normalized_to_pixel(xn))
    }

    /// Where an ideal (undistorted) pixel reads in this camera's distorted image: the pixel
    /// position the same viewing direction lands on, or `None` where it falls outside the
    /// image or beyond `max_radius`, the radius up to which the distortion is one-to-one
    /// ([`Distortion::monotonic_radius`], a search: computed once by the caller for a whole
    /// image). What undistorting an image for display samples.
    #[inline]
    pub fn distorted_source(&self, ideal: Point2<f64>, max_radius: f64) -> Option<Point2<f64>> {
        let xn = self.pixel_to_normalized(ideal);
        let uv = self.normalized_to_pixel(self.distortion.distort(xn));
        (xn.norm() < max_radius && self.contains_pixel(uv)).then_some(uv)
    }

    /// Pixel → the world ray through it, starting at the camera centre.
    pub fn pixel_ray(&self, uv: Point2<f64>) -> Option<Ray> {
        let xn = self.undistort(uv)?;
        let dir_cam = Vector3::new(xn.x, xn.y, 1.0);
        Some(Ray { origin: self.centre(), direction: Unit::new_normalize(self.rotation.inverse() * dir_cam) })
    }
}
