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
//! [`TableShadows::on_table`] is that test for one pixel. The labeller asks it only for the
//! possible shadows beside the tool drawn where its track predicts it (a few hundred pixels per
//! frame set), whose colour alone would let the fit creep into the hand's shadow.

use hullcut_dataset::label;
use hullcut_rig::Camera;
use image::GrayImage;
use nalgebra::Point2;

use crate::labels::POSSIBLE_SHADOW;

/// A point on the table is seen darkened (or plain) by a view where a pixel within this many
/// pixels of its projection is a possible shadow (or where all are plain background): the
/// calibration and the shadow's soft edge put it a pixel or so off.
const NEIGHBOURHOOD_PX: i64 = 1;

/// The views' foreground masks before their possible shadows were resolved: what tells a shadow
/// on the table from an object in front of it ([`TableShadows::on_table`]).
#[derive(Debug, Clone)]
pub struct TableShadows<'a> {
    views: Vec<Option<(&'a Camera, &'a GrayImage)>>,
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

impl<'a> TableShadows<'a> {
    /// One entry per rig camera: its camera and its mask, whose [`POSSIBLE_SHADOW`] pixels may be
    /// cast shadows and whose [`label::BACKGROUND`] pixels are the plain background (any other
    /// value is foreground). The world frame's z = 0 must be the table top. A mask whose size is
    /// not its camera's is left out.
    pub fn new(views: Vec<Option<(&'a Camera, &'a GrayImage)>>) -> Self {
        let views =
            views.into_iter().map(|v| v.filter(|(c, m)| m.width() == c.width && m.height() == c.height)).collect();
        TableShadows { views }
    }

    /// Whether the possible shadow at pixel (`i`, `j`) of view `view` is a shadow on the table as
    /// the other views see it: its ray meets the table at a point that more of the other views
    /// see darkened than see plain. Views that see foreground there, or do not see the point, do
    /// not count; a ray that does not go down to the table is no shadow on it.
    pub fn on_table(&self, view: usize, i: usize, j: usize) -> bool {
        let Some(Some((camera, _))) = self.views.get(view) else { return false };
        let Some(ray) = camera.pixel_ray(Point2::new(i as f64, j as f64)) else { return false };
        let down = ray.direction.z;
        // Comparisons false for NaN: a non-finite ray meets nothing.
        if !(down < 0.0 && ray.origin.z > 0.0) {
            return false;
        }
        let point = ray.at(-ray.origin.z / down);
        let (mut darkened, mut plain) = (0usize, 0usize);
        for (k, other) in self.views.iter().enumerate() {
            let Some((camera, mask)) = other.filter(|_| k != view) else { continue };
            let projection = camera.project(&point);
            if !projection.visible {
                continue;
            }
            match seen(mask, projection.pixel) {
                Seen::Darkened => darkened += 1,
                Seen::Plain => plain += 1,
                Seen::Undecided => {}
            }
        }
        darkened > plain
    }
}

/// How `mask` shows the table at `pixel` (within [`NEIGHBOURHOOD_PX`]).
fn seen(mask: &GrayImage, pixel: Point2<f64>) -> Seen {
    let (w, h) = (i64::from(mask.width()), i64::from(mask.height()));
    let (ci, cj) = (pixel.x.round() as i64, pixel.y.round() as i64);
    let raw = mask.as_raw();
    let mut all_plain = true;
    for y in (cj - NEIGHBOURHOOD_PX).max(0)..=(cj + NEIGHBOURHOOD_PX).min(h - 1) {
        for x in (ci - NEIGHBOURHOOD_PX).max(0)..=(ci + NEIGHBOURHOOD_PX).min(w - 1) {
            match raw[(y * w + x) as usize] {
                POSSIBLE_SHADOW => return Seen::Darkened,
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
