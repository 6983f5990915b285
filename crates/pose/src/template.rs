//! The instrument's known shape (`tool.json`), reduced to what the fit needs: the blade as a
//! convex polygon in its mid-plane, the body (handle) as a vertex set whose projection's convex
//! hull stands for its silhouette, and interior points of both.

use hullcut_dataset::ToolGeometry;
use hullcut_hull::accuracy::winding_number;
use nalgebra::{Point2, Point3, Vector3};

use crate::ToolError;
use crate::geometry::{MAX_EIGEN_ITERATIONS, convex_hull};
use crate::labels::MAX_TOOL_SIDE_M;

/// Interior points aimed at on the blade and on the body each (the coverage term's samples).
const INTERIOR_TARGET: usize = 48;
/// Most interior grid steps along one side: a sliver of a blade, whose area is tiny beside its
/// length, gets samples at most this fine along it instead of billions of them.
const MAX_GRID_STEPS: usize = 256;

/// The tool as the fit sees it, in the tool frame (metres).
#[derive(Debug, Clone)]
pub struct Template {
    /// Blade outline: a convex polygon in the blade's mid-plane, in order.
    pub blade: Vec<Point3<f64>>,
    /// The blade's corners on both its faces: [`Template::blade`] moved half the blade's
    /// thickness either way along its normal, a convex prism, whose projection's hull is the
    /// blade's silhouette. Seen edge-on a blade is as wide as it is thick (0.35-0.4 mm, a third of
    /// a pixel to a pixel on the rigs measured), and a fit of the mid-plane alone turned it about
    /// its long axis to cover that width (docs/benchmarks.md, "The blade's thickness").
    pub blade_faces: Vec<Point3<f64>>,
    /// Vertices of the tool mesh off the blade (the handle); empty for a bare blade.
    pub body: Vec<Point3<f64>>,
    /// Points inside the blade (first [`Template::blade_interior`] of them), then inside the body.
    pub interior: Vec<Point3<f64>>,
    /// How many of [`Template::interior`] lie on the blade.
    pub blade_interior: usize,
    /// Blade tip.
    pub tip: Point3<f64>,
    /// Cutting edge, tip to heel.
    pub edge: Vec<Point3<f64>>,
    /// Unit blade normal.
    pub normal: Vector3<f64>,
    /// Centre of the blade polygon (the point the tracker filters and rotations pivot about).
    pub blade_centre: Point3<f64>,
    /// Length of the whole tool along its longest axis, metres (to check a hull matches it).
    pub length: f64,
}

impl Template {
    /// Builds the template of a tool: the blade polygon is the convex hull of `blade_outline`
    /// (or, without one, of the mesh vertices within a blade thickness of the mid-plane through
    /// the tip), projected onto the mid-plane; the body is every other mesh vertex.
    ///
    /// The tool is checked first ([`check_tool`]): a number that is not finite or a tool larger
    /// than [`MAX_TOOL_SIDE_M`] is refused before anything is sized from it.
    pub fn new(tool: &ToolGeometry) -> Result<Self, ToolError> {
        check_tool(tool)?;
        let n = tool.blade_normal.normalize();
        let plane_tol = tool.blade_thickness.max(1e-6);
        let on_blade = |p: &Point3<f64>| (p - tool.tip).dot(&n).abs() <= plane_tol;
        let candidates: Vec<Point3<f64>> = match &tool.blade_outline {
            Some(outline) if outline.len() >= 3 => outline.clone(),
            _ => {
                let mut v: Vec<Point3<f64>> = tool.mesh.vertices.iter().copied().filter(on_blade).collect();
                v.extend(tool.cutting_edge.iter().copied());
                v
            }
        };
        // In-plane basis: u along the edge (tip → heel reversed), w = n × u.
        let heel = tool.cutting_edge.last().copied().unwrap_or(tool.tip);
        let along = tool.tip - heel;
        let u = (along - n * along.dot(&n))
            .try_normalize(1e-12)
            .or_else(|| n.cross(&Vector3::x()).try_normalize(1e-6))
            .or_else(|| n.cross(&Vector3::y()).try_normalize(1e-6))
            .ok_or_else(|| ToolError::Template("the blade normal spans no blade plane".to_owned()))?;
        let w = n.cross(&u);
        let to_plane = |p: &Point3<f64>| Point2::new((p - tool.tip).dot(&u), (p - tool.tip).dot(&w));
        let from_plane = |q: &Point2<f64>| tool.tip + u * q.x + w * q.y;
        let flat: Vec<Point2<f64>> = candidates.iter().map(to_plane).collect();
        let polygon = convex_hull(&flat);
        if polygon.len() < 3 {
            return Err(ToolError::Template("the blade outline spans no area".to_owned()));
        }
        let blade: Vec<Point3<f64>> = polygon.iter().map(from_plane).collect();
        let half = n * (tool.blade_thickness / 2.0);
        let blade_faces: Vec<Point3<f64>> = blade.iter().flat_map(|p| [p + half, p - half]).collect();
        let blade_centre = Point3::from(blade.iter().map(|p| p.coords).sum::<Vector3<f64>>() / blade.len() as f64);

        let mut interior = blade_interior(&polygon).iter().map(from_plane).collect::<Vec<_>>();
        let blade_interior = interior.len();
        let body: Vec<Point3<f64>> = tool
            .mesh
            .vertices
            .iter()
            .copied()
            .filter(|p| !on_blade(p) || !inside_polygon(&polygon, &to_plane(p)))
            .collect();
        interior.extend(body_interior(tool, &body));

        let all: Vec<Point3<f64>> = tool.mesh.vertices.iter().copied().chain(blade.iter().copied()).collect();
        let length = principal_length(&all);
        Ok(Template {
            blade,
            blade_faces,
            body,
            interior,
            blade_interior,
            tip: tool.tip,
            edge: tool.cutting_edge.clone(),
            normal: n,
            blade_centre,
            length,
        })
    }
}

impl Template {
    /// The pose turned over: rotated half a turn about the tool's long axis through the blade's
    /// centre (spine and cutting edge swapped, the plane kept).
    pub fn turned_over(&self, pose: &nalgebra::Isometry3<f64>) -> nalgebra::Isometry3<f64> {
        let axis = self.long_axis();
        let half_turn = nalgebra::UnitQuaternion::from_scaled_axis(axis * std::f64::consts::PI);
        let c = self.blade_centre.coords;
        let about_centre = nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(c - half_turn * c), half_turn);
        pose * about_centre
    }

    /// The tool's long axis in the tool frame: the unit direction from the body's centre (the
    /// blade's, for a bare blade) to the tip; the blade turns over, or rolls, about it.
    pub fn long_axis(&self) -> Vector3<f64> {
        (self.tip - self.body_or_blade_centre()).normalize()
    }

    /// Centre of the body's vertices, or of the blade for a bare blade.
    pub fn body_or_blade_centre(&self) -> Point3<f64> {
        if self.body.is_empty() {
            return self.blade_centre;
        }
        Point3::from(self.body.iter().map(|p| p.coords).sum::<Vector3<f64>>() / self.body.len() as f64)
    }
}

/// A grid of points inside a convex polygon, about [`INTERIOR_TARGET`] of them (at most
/// [`MAX_GRID_STEPS`] a side).
fn blade_interior(polygon: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let (lo, hi) = bounds2(polygon);
    let area = polygon_area(polygon).abs();
    let extent = (hi - lo).max();
    let spacing = (area / INTERIOR_TARGET as f64).sqrt().max(extent / MAX_GRID_STEPS as f64);
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Vec::new();
    }
    // Samples at lo + (k + 1/2) spacing short of hi, counted instead of stepped (a step below the
    // coordinates' rounding would never arrive).
    let steps = |span: f64| ((span / spacing - 0.5).ceil().max(0.0) as usize).min(MAX_GRID_STEPS + 1);
    let (nx, ny) = (steps(hi.x - lo.x), steps(hi.y - lo.y));
    let mut out = Vec::new();
    for j in 0..ny {
        let y = lo.y + (j as f64 + 0.5) * spacing;
        for i in 0..nx {
            let q = Point2::new(lo.x + (i as f64 + 0.5) * spacing, y);
            if inside_polygon(polygon, &q) {
                out.push(q);
            }
        }
    }
    out
}

/// A grid of points inside the tool mesh but off the blade (the body), about
/// [`INTERIOR_TARGET`] of them.
fn body_interior(tool: &ToolGeometry, body: &[Point3<f64>]) -> Vec<Point3<f64>> {
    if body.is_empty() {
        return Vec::new();
    }
    let mut lo = body[0];
    let mut hi = body[0];
    for p in body {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let volume = (hi - lo).iter().map(|d| d.max(1e-4)).product::<f64>();
    let spacing = (volume / INTERIOR_TARGET as f64).cbrt();
    let steps = (hi - lo).map(|d| ((d / spacing).round() as usize).clamp(1, MAX_GRID_STEPS));
    let mut out = Vec::new();
    for i in 0..steps.x {
        for j in 0..steps.y {
            for k in 0..steps.z {
                let f = Vector3::new(
                    (i as f64 + 0.5) / steps.x as f64,
                    (j as f64 + 0.5) / steps.y as f64,
                    (k as f64 + 0.5) / steps.z as f64,
                );
                let p = lo + (hi - lo).component_mul(&f);
                if winding_number(&tool.mesh, &p) > 0.5 {
                    out.push(p);
                }
            }
        }
    }
    out
}

fn bounds2(points: &[Point2<f64>]) -> (Point2<f64>, Point2<f64>) {
    let mut lo = Point2::new(f64::MAX, f64::MAX);
    let mut hi = Point2::new(f64::MIN, f64::MIN);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

/// Signed area (positive for counter-clockwise).
pub(crate) fn polygon_area(polygon: &[Point2<f64>]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0
}

/// Whether a point is inside a convex polygon of either orientation (boundary included).
pub(crate) fn inside_polygon(polygon: &[Point2<f64>], q: &Point2<f64>) -> bool {
    let n = polygon.len();
    let mut sign = 0.0f64;
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        let c = (b - a).perp(&(q - a));
        if c != 0.0 {
            if sign != 0.0 && c.signum() != sign {
                return false;
            }
            sign = c.signum();
        }
    }
    true
}

/// Extent along the first principal axis (the bounding box's longest side where the axis cannot
/// be found).
fn principal_length(points: &[Point3<f64>]) -> f64 {
    let n = points.len().max(1) as f64;
    let mean = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    let mut cov = nalgebra::Matrix3::zeros();
    for p in points {
        let d = p.coords - mean;
        cov += d * d.transpose();
    }
    let Some(eig) = nalgebra::SymmetricEigen::try_new(cov, f64::EPSILON, MAX_EIGEN_ITERATIONS) else {
        let (mut lo, mut hi) = (Vector3::repeat(f64::MAX), Vector3::repeat(f64::MIN));
        for p in points {
            lo = lo.inf(&p.coords);
            hi = hi.sup(&p.coords);
        }
        return (hi - lo).max().max(0.0);
    };
    let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for p in points {
        let s = (p.coords - mean).dot(&axis);
        lo = lo.min(s);
        hi = hi.max(s);
    }
    hi - lo
}

/// Refuses a tool no template or grid can be built from: a number that is not finite, a blade
/// normal of no length, a blade thickness that is negative or larger than the tool, or a tool
/// (its mesh, tip, cutting edge and blade outline together) spanning more than
/// [`MAX_TOOL_SIDE_M`]. tool.json is in metres: a file in millimetres is a thousand times too
/// large, and one stray vertex at 1e300 would size the template's grids and samples beyond any
/// memory. Every template and grid of the tool is built after this check.
pub fn check_tool(tool: &ToolGeometry) -> Result<(), ToolError> {
    let points = tool
        .mesh
        .vertices
        .iter()
        .enumerate()
        .map(|(k, p)| (format!("mesh vertex {k}"), p))
        .chain(std::iter::once(("the tip".to_owned(), &tool.tip)))
        .chain(tool.cutting_edge.iter().enumerate().map(|(k, p)| (format!("cutting_edge point {k}"), p)))
        .chain(tool.blade_outline.iter().flatten().enumerate().map(|(k, p)| (format!("blade_outline point {k}"), p)));
    let (mut lo, mut hi) = (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY));
    let mut largest: Option<(f64, String, Point3<f64>)> = None;
    for (what, p) in points {
        if !p.coords.iter().all(|c| c.is_finite()) {
            return Err(ToolError::Template(format!("{what} is [{}, {}, {}]: not a finite number", p.x, p.y, p.z)));
        }
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
        let magnitude = p.coords.amax();
        if largest.as_ref().is_none_or(|(m, _, _)| magnitude > *m) {
            largest = Some((magnitude, what, *p));
        }
    }
    let side = (hi - lo).max();
    if !(side.is_finite() && side <= MAX_TOOL_SIDE_M) {
        let farthest = largest
            .map(|(_, what, p)| {
                format!("; its largest coordinate is {what}'s, [{:.3e}, {:.3e}, {:.3e}]", p.x, p.y, p.z)
            })
            .unwrap_or_default();
        return Err(ToolError::Template(format!(
            "the tool (mesh, tip, cutting edge, outline) spans {side:.3e} m, more than the {MAX_TOOL_SIDE_M} m a \
             hand-held tool does \
             (tool.json and its mesh are in metres: a file in millimetres?){farthest}"
        )));
    }
    let normal = tool.blade_normal;
    if !(normal.iter().all(|c| c.is_finite()) && normal.norm() > 1e-12) {
        return Err(ToolError::Template(format!(
            "blade_normal [{}, {}, {}] is not a direction",
            normal.x, normal.y, normal.z
        )));
    }
    let thickness = tool.blade_thickness;
    if !(0.0..=MAX_TOOL_SIDE_M).contains(&thickness) {
        return Err(ToolError::Template(format!(
            "blade_thickness {thickness} m: must be 0 or more and at most {MAX_TOOL_SIDE_M} m"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blades_faces_lie_half_its_thickness_either_side_of_its_mid_plane() {
        for scalpel in [hullcut_synth::Scalpel::new(), hullcut_synth::Scalpel::pointed()] {
            let tool = &scalpel.geometry;
            let t = Template::new(tool).expect("a template");
            assert_eq!(t.blade_faces.len(), 2 * t.blade.len());
            for (k, p) in t.blade.iter().enumerate() {
                let (a, b) = (t.blade_faces[2 * k], t.blade_faces[2 * k + 1]);
                // Each corner's pair straddles it along the normal, a thickness apart.
                assert!(((a - b).dot(&t.normal) - tool.blade_thickness).abs() < 1e-12);
                assert!((Point3::from((a.coords + b.coords) / 2.0) - p).norm() < 1e-12);
                assert!(((a - p).cross(&t.normal)).norm() < 1e-12);
            }
            // The faces are no larger than the mesh's blade: every corner within the tool's box.
            let (lo, hi) = tool
                .mesh
                .vertices
                .iter()
                .fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(lo, hi), v| {
                    (lo.inf(&v.coords), hi.sup(&v.coords))
                });
            for p in &t.blade_faces {
                let inside = (0..3).all(|i| p[i] >= lo[i] - 1e-9 && p[i] <= hi[i] + 1e-9);
                assert!(inside, "{p} outside the mesh's box {lo} .. {hi}");
            }
        }
    }
}
