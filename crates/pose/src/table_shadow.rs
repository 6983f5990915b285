//! Shadows on the table, told apart from a dull tool by the views together.
//!
//! One view cannot tell a shadow on the table from a dark object of the table's shade: both are
//! the background darkened ([`POSSIBLE_SHADOW`]). The views together can. A shadow lies on the
//! table, so the ray of one of its pixels meets the table (z = 0 in a table's world frame) at a
//! point that every other view sees darkened too, unless something stands in front of it there.
//! Behind a dull tool above the table, the other views see the table as it is: the tool's own
//! shadow falls elsewhere, displaced by its height along the light. Where the tool rests on the
//! table the two meet, and the test cannot tell them apart: the other views then see the tool
//! itself, darkened, where the ray meets the table.
//!
//! With the views' images and backgrounds ([`TableShadows::with_shading`]) the test also asks
//! how dark: a shadow on a matte table keeps the same share of the light in every view, so a view
//! counts the point as darkened only where it sees it about as much darker than its background as
//! the tested pixel is. A steel blade over the hand's shadow, near the table, is then no shadow:
//! it is brighter than the shadow behind it (random:317 in random:331, frame 96: the blade's
//! possible-shadow pixels at 0.75-0.8 of their background, the shadow at 0.48-0.52; a black
//! handle at 0.12-0.2).
//!
//! [`TableShadows::on_table`] is that test for one pixel. The labeller asks it for the possible
//! shadows beside the tool drawn where its track predicts it, whose colour alone would let the
//! fit creep into the hand's shadow; the labelling asks it for every possible shadow the hull
//! kept, which the hand's hull over its own shadow near the table covers.

use hullcut_dataset::label;
use hullcut_rig::Camera;
use image::{GrayImage, RgbImage};
use nalgebra::Point2;

use crate::labels::POSSIBLE_SHADOW;

/// A point on the table is seen darkened (or plain) by a view where a pixel within this many
/// pixels of its projection is a possible shadow (or where all are plain background): the
/// calibration and the shadow's soft edge put it a pixel or so off.
const NEIGHBOURHOOD_PX: i64 = 1;

/// With shading, a view sees a point darkened like the tested pixel where one of its possible
/// shadows within a pixel of the point's projection keeps within this much of the tested pixel's
/// share of its background's light (a shadow's core spans some 0.03, its soft edge more).
pub const SHADE_TOLERANCE: f32 = 0.1;

/// One view's image, its background (the expected image of the empty scene) and the exposure
/// gain of the image against it: how much of the light a pixel keeps.
#[derive(Debug, Clone, Copy)]
pub struct Shading<'a> {
    /// The view's image.
    pub image: &'a RgbImage,
    /// The background's mean image, of the same size.
    pub background: &'a RgbImage,
    /// The image's exposure gain against the background (1 without compensation).
    pub gain: f64,
}

impl Shading<'_> {
    /// The share of its background's light that pixel (`i`, `j`) keeps (`None` outside the
    /// image, or over a black background).
    fn kept(&self, i: usize, j: usize) -> Option<f32> {
        let (w, h) = (self.image.width() as usize, self.image.height() as usize);
        if i >= w || j >= h {
            return None;
        }
        let k = 3 * (j * w + i);
        let sum = |img: &RgbImage| -> Option<f32> {
            let p = img.as_raw().get(k..k + 3)?;
            Some(p.iter().map(|&v| f32::from(v)).sum())
        };
        let (s, e) = (sum(self.image)?, sum(self.background)? * self.gain as f32);
        (e > 0.0).then(|| s / e)
    }
}

/// The views' foreground masks before their possible shadows were resolved: what tells a shadow
/// on the table from an object in front of it ([`TableShadows::on_table`]).
#[derive(Debug, Clone)]
pub struct TableShadows<'a> {
    views: Vec<Option<(&'a Camera, &'a GrayImage)>>,
    /// Per view, its lens' invertible radius ([`hullcut_rig::Distortion::monotonic_radius`]),
    /// found once rather than for every point projected.
    radii: Vec<f64>,
    /// Per view, where given ([`TableShadows::with_shading`]).
    shading: Vec<Option<Shading<'a>>>,
}

/// How one view sees a point of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seen {
    /// A possible shadow there.
    Darkened,
    /// Plain background all around it.
    Plain,
    /// Not seen, or foreground there (something may stand in front of it).
    Undecided,
}

/// What a view compares its possible shadows with: the tested pixel's share of the light.
type Shade<'s, 'a> = Option<(&'s Shading<'a>, f32)>;

impl<'a> TableShadows<'a> {
    /// One entry per rig camera: its camera and its mask, whose [`POSSIBLE_SHADOW`] pixels may be
    /// cast shadows and whose [`label::BACKGROUND`] pixels are the plain background (any other
    /// value is foreground). The world frame's z = 0 must be the table top. A mask whose size is
    /// not its camera's is left out.
    pub fn new(views: Vec<Option<(&'a Camera, &'a GrayImage)>>) -> Self {
        let views: Vec<Option<(&Camera, &GrayImage)>> =
            views.into_iter().map(|v| v.filter(|(c, m)| m.width() == c.width && m.height() == c.height)).collect();
        let radii = views.iter().map(|v| v.map_or(0.0, |(c, _)| c.distortion.monotonic_radius())).collect();
        TableShadows { views, radii, shading: Vec::new() }
    }

    /// Adds the views' shading, one entry per rig camera (see the module docs); an entry whose
    /// image or background is not its camera's size is left out, and a view without shading
    /// counts any possible shadow there as darkened.
    pub fn with_shading(mut self, shading: Vec<Option<Shading<'a>>>) -> Self {
        self.shading = shading
            .into_iter()
            .zip(&self.views)
            .map(|(s, v)| {
                let (camera, _) = v.as_ref()?;
                s.filter(|s| {
                    s.image.dimensions() == (camera.width, camera.height)
                        && s.background.dimensions() == s.image.dimensions()
                })
            })
            .collect();
        self
    }

    /// View `view`'s shading, where given.
    fn shading(&self, view: usize) -> Option<&Shading<'a>> {
        self.shading.get(view).and_then(Option::as_ref)
    }

    /// Whether the possible shadow at pixel (`i`, `j`) of view `view` is a shadow on the table as
    /// the other views see it: its ray meets the table at a point that more of the other views
    /// see darkened than see plain. Views that see foreground there, or do not see the point, do
    /// not count; a ray that does not go down to the table is no shadow on it. With shading for
    /// `view` and another view, that view sees the point darkened only as much as this pixel
    /// (within [`SHADE_TOLERANCE`]); darkened otherwise, it counts as plain.
    pub fn on_table(&self, view: usize, i: usize, j: usize) -> bool {
        let Some(Some((camera, _))) = self.views.get(view) else { return false };
        let Some(ray) = camera.pixel_ray(Point2::new(i as f64, j as f64)) else { return false };
        let down = ray.direction.z;
        // Comparisons false for NaN: a non-finite ray meets nothing.
        if !(down < 0.0 && ray.origin.z > 0.0) {
            return false;
        }
        let point = ray.at(-ray.origin.z / down);
        let kept = self.shading(view).and_then(|s| s.kept(i, j));
        let (mut darkened, mut plain) = (0usize, 0usize);
        for (k, other) in self.views.iter().enumerate() {
            let Some((camera, mask)) = other.filter(|_| k != view) else { continue };
            let Some(pixel) = visible_pixel(camera, self.radii[k], &point) else { continue };
            let shade = self.shading(k).zip(kept);
            match seen(mask, pixel, shade) {
                Seen::Darkened => darkened += 1,
                Seen::Plain => plain += 1,
                Seen::Undecided => {}
            }
        }
        darkened > plain
    }
}

/// The pixel of `p` in `camera`'s image where [`Camera::project`] calls it visible (`radius`: the
/// lens' invertible radius).
fn visible_pixel(camera: &Camera, radius: f64, p: &nalgebra::Point3<f64>) -> Option<Point2<f64>> {
    let pc = camera.world_to_camera(p);
    if pc.z <= 0.0 {
        return None;
    }
    let xn = nalgebra::Vector2::new(pc.x / pc.z, pc.y / pc.z);
    let pixel = camera.normalized_to_pixel(camera.distortion.distort(xn));
    (xn.norm() < radius && camera.contains_pixel(pixel)).then_some(pixel)
}

/// How `mask` shows the table at `pixel` (within [`NEIGHBOURHOOD_PX`]); with `shade` (this
/// view's shading and the tested pixel's share of the light), a possible shadow darkened
/// otherwise than the tested pixel is no darkening of the same point: counted as plain where no
/// foreground is near.
fn seen(mask: &GrayImage, pixel: Point2<f64>, shade: Shade) -> Seen {
    let (w, h) = (i64::from(mask.width()), i64::from(mask.height()));
    let (ci, cj) = (pixel.x.round() as i64, pixel.y.round() as i64);
    let raw = mask.as_raw();
    let mut all_plain = true;
    for y in (cj - NEIGHBOURHOOD_PX).max(0)..=(cj + NEIGHBOURHOOD_PX).min(h - 1) {
        for x in (ci - NEIGHBOURHOOD_PX).max(0)..=(ci + NEIGHBOURHOOD_PX).min(w - 1) {
            match raw[(y * w + x) as usize] {
                POSSIBLE_SHADOW => {
                    let alike = shade.is_none_or(|(s, kept)| {
                        s.kept(x as usize, y as usize).is_some_and(|k| (k - kept).abs() <= SHADE_TOLERANCE)
                    });
                    if alike {
                        return Seen::Darkened;
                    }
                }
                label::BACKGROUND => {}
                _ => all_plain = false,
            }
        }
    }
    if all_plain { Seen::Plain } else { Seen::Undecided }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    /// Three cameras 60 cm from the table's centre, 45° up, around it.
    fn cameras() -> Vec<Camera> {
        (0..3)
            .map(|k| {
                let a = f64::from(k) * 2.0 * std::f64::consts::PI / 3.0;
                let eye = Point3::new(0.42 * a.cos(), 0.42 * a.sin(), 0.42);
                Camera::new(format!("cam{k}"), 320, 240, 300.0, 300.0, 160.0, 120.0)
                    .looking_at(eye, Point3::origin(), Vector3::z())
                    .expect("a camera looking at the table")
            })
            .collect()
    }

    /// Masks with the pixels around each view's projection of `point` set to `value`.
    fn masks_with(cameras: &[Camera], point: &Point3<f64>, value: u8) -> Vec<GrayImage> {
        cameras
            .iter()
            .map(|c| {
                let mut m = GrayImage::new(c.width, c.height);
                let p = c.project(point).pixel;
                for y in (p.y.round() as u32 - 3)..=(p.y.round() as u32 + 3) {
                    for x in (p.x.round() as u32 - 3)..=(p.x.round() as u32 + 3) {
                        m.put_pixel(x, y, image::Luma([value]));
                    }
                }
                m
            })
            .collect()
    }

    fn pixel_of(camera: &Camera, p: &Point3<f64>) -> (usize, usize) {
        let uv = camera.project(p).pixel;
        (uv.x.round() as usize, uv.y.round() as usize)
    }

    #[test]
    fn a_shadow_on_the_table_is_darkened_in_the_other_views_and_a_dull_tip_above_it_is_not() {
        let cams = cameras();
        let on_table = Point3::new(0.03, -0.02, 0.0);
        // Every view sees the same darkened patch of table: a shadow.
        let shadow = masks_with(&cams, &on_table, POSSIBLE_SHADOW);
        let shadows = TableShadows::new(cams.iter().zip(&shadow).map(|(c, m)| Some((c, m))).collect());
        let (i, j) = pixel_of(&cams[0], &on_table);
        assert!(shadows.on_table(0, i, j));
        // A dark tip 2 cm above the table: view 0 sees it darkened, and nothing else is.
        let tip = Point3::new(0.03, -0.02, 0.02);
        let mut masks: Vec<GrayImage> = cams.iter().map(|c| GrayImage::new(c.width, c.height)).collect();
        masks[0] = masks_with(&cams[..1], &tip, POSSIBLE_SHADOW).remove(0);
        let views = TableShadows::new(cams.iter().zip(&masks).map(|(c, m)| Some((c, m))).collect());
        let (i, j) = pixel_of(&cams[0], &tip);
        assert!(!views.on_table(0, i, j));
    }

    /// Images of a grey table (`grey` everywhere) with the pixels around each view's projection
    /// of `point` at `value`.
    fn images_with(cameras: &[Camera], point: &Point3<f64>, grey: u8, value: u8) -> Vec<RgbImage> {
        cameras
            .iter()
            .map(|c| {
                let mut m = RgbImage::from_pixel(c.width, c.height, image::Rgb([grey; 3]));
                let p = c.project(point).pixel;
                for y in (p.y.round() as u32 - 3)..=(p.y.round() as u32 + 3) {
                    for x in (p.x.round() as u32 - 3)..=(p.x.round() as u32 + 3) {
                        m.put_pixel(x, y, image::Rgb([value; 3]));
                    }
                }
                m
            })
            .collect()
    }

    #[test]
    fn with_shading_a_pixel_brighter_than_the_shadow_behind_it_is_no_shadow() {
        let cams = cameras();
        let on_table = Point3::new(0.02, 0.01, 0.0);
        // Every view sees the patch of table darkened to half its light: a shadow.
        let masks = masks_with(&cams, &on_table, POSSIBLE_SHADOW);
        let background: Vec<RgbImage> =
            cams.iter().map(|c| RgbImage::from_pixel(c.width, c.height, image::Rgb([120; 3]))).collect();
        let mut images = images_with(&cams, &on_table, 120, 60);
        fn shading<'a>(images: &'a [RgbImage], background: &'a [RgbImage], gain: f64) -> Vec<Option<Shading<'a>>> {
            images.iter().zip(background).map(|(image, background)| Some(Shading { image, background, gain })).collect()
        }
        let views = || cams.iter().zip(&masks).map(|(c, m)| Some((c, m))).collect::<Vec<_>>();
        let (i, j) = pixel_of(&cams[0], &on_table);
        assert!(TableShadows::new(views()).with_shading(shading(&images, &background, 1.0)).on_table(0, i, j));
        // View 0's pixel keeps 0.8 of its light (a steel blade over the shadow): still a
        // possible shadow to view 0, but not as dark as what the others see there.
        images[0].put_pixel(i as u32, j as u32, image::Rgb([96; 3]));
        assert!(TableShadows::new(views()).on_table(0, i, j), "without shading, any darkening is the shadow");
        assert!(!TableShadows::new(views()).with_shading(shading(&images, &background, 1.0)).on_table(0, i, j));
        // The exposure gain scales the background: at gain 1.6, 96 of 120 keeps half the light.
        let mut gained = shading(&images, &background, 1.0);
        gained[0] = Some(Shading { image: &images[0], background: &background[0], gain: 1.6 });
        assert!(TableShadows::new(views()).with_shading(gained).on_table(0, i, j));
        // Shading of the wrong size is left out: the view counts any darkening.
        let small = RgbImage::new(10, 10);
        let mut odd = shading(&images, &background, 1.0);
        odd[0] = Some(Shading { image: &small, background: &small, gain: 1.0 });
        assert!(TableShadows::new(views()).with_shading(odd).on_table(0, i, j));
    }

    #[test]
    fn views_that_see_foreground_there_decide_nothing() {
        let cams = cameras();
        let on_table = Point3::new(-0.01, 0.02, 0.0);
        // View 1 sees the patch darkened, view 2 sees an object in front of it.
        let mut masks = masks_with(&cams, &on_table, POSSIBLE_SHADOW);
        masks[2] = masks_with(&cams[2..], &on_table, label::HAND).remove(0);
        let (i, j) = pixel_of(&cams[0], &on_table);
        let views = TableShadows::new(cams.iter().zip(&masks).map(|(c, m)| Some((c, m))).collect());
        assert!(views.on_table(0, i, j));
        // With view 1 seeing plain table, one plain against none darkened: not a shadow.
        masks[1] = GrayImage::new(cams[1].width, cams[1].height);
        let views = TableShadows::new(cams.iter().zip(&masks).map(|(c, m)| Some((c, m))).collect());
        assert!(!views.on_table(0, i, j));
    }

    #[test]
    fn a_ray_that_misses_the_table_or_a_missing_view_is_no_shadow_on_it() {
        let cams = cameras();
        let masks: Vec<GrayImage> =
            cams.iter().map(|c| GrayImage::from_pixel(c.width, c.height, image::Luma([POSSIBLE_SHADOW]))).collect();
        let views = TableShadows::new(cams.iter().zip(&masks).map(|(c, m)| Some((c, m))).collect());
        // A view index past the rig's is no shadow.
        assert!(!views.on_table(7, 10, 10));
        // A mask of the wrong size is left out: no view is left to see the point darkened.
        let small = GrayImage::from_pixel(10, 10, image::Luma([POSSIBLE_SHADOW]));
        let views = TableShadows::new(vec![Some((&cams[0], &masks[0])), Some((&cams[1], &small)), None]);
        let (i, j) = pixel_of(&cams[0], &Point3::origin());
        assert!(!views.on_table(0, i, j));
        // A camera below the table sees no shadow on its top.
        let under = Camera::new("under", 320, 240, 300.0, 300.0, 160.0, 120.0)
            .looking_at(Point3::new(0.0, 0.0, -0.5), Point3::origin(), Vector3::y())
            .expect("a camera under the table");
        let views = TableShadows::new(vec![Some((&under, &masks[0])), Some((&cams[1], &masks[1]))]);
        assert!(!views.on_table(0, 160, 120));
    }
}
