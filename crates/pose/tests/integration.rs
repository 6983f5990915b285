//! The blade pose on rendered scenes with exact truth: accuracy, refusal, holding, bad input.

use hullcut_dataset::{ToolGeometry, label};
use hullcut_hull::{HullParams, WorkingVolume, carve, silhouettes};
use hullcut_pose::{
    PoseError, PoseEstimate, Sight, Template, Tracker, TrackerParams, ViewInput, isometry_from_matrix, pose_error,
};
use hullcut_rig::RigPreset;
use hullcut_synth::{Appearance, CameraRenderer, Light, Part, Scene, SceneConfig, SceneKind, ToolKind};
use image::GrayImage;
use nalgebra::{Isometry3, Matrix4, Vector3};

const LEAF: f64 = 0.4 / 128.0;

/// A rig and a tool: the built-in scene's, and others, so that nothing is tuned to one geometry.
#[derive(Debug, Clone, Copy)]
struct Setup {
    rig: RigPreset,
    tool: ToolKind,
}

const BUILTIN: Setup = Setup { rig: RigPreset::Default, tool: ToolKind::Standard };
/// Eight 1280x720 cameras (one overhead, one strongly distorted) and the pointed scalpel.
const LAB8: Setup = Setup { rig: RigPreset::Lab8, tool: ToolKind::Pointed };
/// A seeded random rig (seed 5: six cameras of mixed sizes) and the standard scalpel.
const RANDOM: Setup = Setup { rig: RigPreset::Random(5), tool: ToolKind::Standard };

fn scene(setup: Setup, kind: SceneKind, seed: u64, frames: u64) -> Scene {
    let mut config = SceneConfig::new(kind, seed, frames);
    config.rig = setup.rig.rig();
    config.tool = setup.tool;
    Scene::new(config).expect("scene")
}

/// Carving as `reconstruct` does it: the rig's own working volume, three views per cell.
fn hull_params(rig: &hullcut_rig::Rig) -> HullParams {
    let volume = WorkingVolume::from_rig(rig, 3, true).expect("volume");
    HullParams::new(volume.aabb, LEAF)
}

/// One frame's estimate and, for a frame that hands out a pose (trusted or held), its error.
struct Step {
    estimate: PoseEstimate,
    error: Option<PoseError>,
}

/// Tracks `frames` frames of a rendered scene from `first`, with truth masks passed through `edit`
/// (camera index, frame, mask) and the tool as `tool` (the scene's own when `None`).
#[allow(clippy::too_many_arguments)] // the clip, the tool and the edit, each named
fn track(
    setup: Setup,
    kind: SceneKind,
    seed: u64,
    first: u64,
    frames: u64,
    tool: Option<&ToolGeometry>,
    edit: impl Fn(usize, u64, &mut GrayImage),
) -> Vec<Step> {
    track_with(TrackerParams::default(), setup, kind, seed, first, frames, tool, edit)
}

/// [`track`] with the tracker's settings given.
#[allow(clippy::too_many_arguments)] // the settings, the clip, the tool and the edit, each named
fn track_with(
    params: TrackerParams,
    setup: Setup,
    kind: SceneKind,
    seed: u64,
    first: u64,
    frames: u64,
    tool: Option<&ToolGeometry>,
    edit: impl Fn(usize, u64, &mut GrayImage),
) -> Vec<Step> {
    track_scene(params, &scene(setup, kind, seed, first + frames), first, frames, tool, edit)
}

/// [`track_with`] on a scene made already.
fn track_scene(
    params: TrackerParams,
    scene: &Scene,
    first: u64,
    frames: u64,
    tool: Option<&ToolGeometry>,
    edit: impl Fn(usize, u64, &mut GrayImage),
) -> Vec<Step> {
    let template = Template::new(tool.unwrap_or(&scene.scalpel().geometry)).expect("template");
    track_template(params, scene, first, frames, template, edit)
}

/// [`track_scene`] with the template given.
fn track_template(
    params: TrackerParams,
    scene: &Scene,
    first: u64,
    frames: u64,
    template: Template,
    edit: impl Fn(usize, u64, &mut GrayImage),
) -> Vec<Step> {
    let rig = scene.config().rig.clone();
    let truth_template = Template::new(&scene.scalpel().geometry).expect("template");
    let mut tracker = Tracker::new(template, params);
    let params = hull_params(&rig);
    (first..first + frames)
        .map(|f| {
            let masks: Vec<Option<GrayImage>> = (0..rig.cameras.len())
                .map(|c| {
                    scene.render_view(f, c).map(|v| {
                        let mut m = v.mask;
                        edit(c, f, &mut m);
                        m
                    })
                })
                .collect();
            let estimate = estimate(&mut tracker, &rig, &masks, &params, f, scene.frame_timestamp(f));
            let truth = isometry_from_matrix(&scene.truth_pose(f).tool_to_world).expect("truth");
            let error = estimate.pose.as_ref().map(|p| pose_error(p, &truth_template, &truth));
            Step { estimate, error }
        })
        .collect()
}

fn estimate(
    tracker: &mut Tracker,
    rig: &hullcut_rig::Rig,
    masks: &[Option<GrayImage>],
    params: &HullParams,
    frame: u64,
    timestamp_ns: i64,
) -> PoseEstimate {
    let refs: Vec<Option<&GrayImage>> = masks.iter().map(Option::as_ref).collect();
    let occ = carve(&silhouettes(rig, &refs).expect("sizes"), params).expect("carve");
    tracker.update(frame, timestamp_ns, &occ, &mask_inputs(rig, masks))
}

/// Each camera's view with its mask (no image): what the tracker is given.
fn mask_inputs<'a>(rig: &'a hullcut_rig::Rig, masks: &'a [Option<GrayImage>]) -> Vec<Option<ViewInput<'a>>> {
    rig.cameras
        .iter()
        .zip(masks)
        .map(|(camera, m)| m.as_ref().map(|mask| ViewInput { camera, mask, image: None }))
        .collect()
}

/// Mean, 95th percentile and maximum.
fn stats(mut v: Vec<f64>) -> [f64; 3] {
    assert!(!v.is_empty(), "no values");
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let p95 = v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1];
    [mean, p95, v[v.len() - 1]]
}

/// Normal (deg) and tip (mm) error statistics of the trusted frames, and the valid fraction.
fn summary(name: &str, steps: &[Step]) -> ([f64; 3], [f64; 3], f64) {
    let trusted: Vec<PoseError> = steps.iter().filter(|s| s.estimate.valid).filter_map(|s| s.error).collect();
    let valid = steps.iter().filter(|s| s.estimate.valid).count() as f64 / steps.len() as f64;
    let normal = stats(trusted.iter().map(|e| e.normal_deg).collect());
    let tip = stats(trusted.iter().map(|e| e.tip_mm).collect());
    println!("{name}: normal deg (mean, p95, max) {normal:.2?}, tip mm {tip:.2?}, valid {valid:.2}");
    for s in steps.iter().filter(|s| !s.estimate.valid) {
        println!("  frame {} refused: {:?}", s.estimate.frame, s.estimate.reason);
    }
    (normal, tip, valid)
}

fn no_edit(_: usize, _: u64, _: &mut GrayImage) {}

#[test]
fn static_and_cut_scenes_are_within_a_degree_and_a_millimetre_on_every_rig() {
    // Measured on the built-in rig: static (seed 1, frames 0..12) 0.27° / 0.11 mm, a pose at rest;
    // cut (seed 2, frames 30..60) mean 0.26° / 0.29 mm, p95 0.51° / 0.43 mm (0.87° and 0.23° before
    // the blade's thickness was fitted, 2026-12-02).
    // A millimetre everywhere; a degree on the built-in rig, two on the others (measured: lab8
    // 0.16-0.31°, the random rig's six mixed cameras 0.10°; 0.69-0.75° and 1.43-1.88° before).
    for (name, setup, kind, seed, first, frames, degrees) in [
        ("static", BUILTIN, SceneKind::Static, 1, 0, 12, 1.0),
        ("cut", BUILTIN, SceneKind::Cut, 2, 30, 30, 1.0),
        ("static lab8", LAB8, SceneKind::Static, 1, 0, 6, 2.0),
        ("cut lab8", LAB8, SceneKind::Cut, 2, 30, 12, 2.0),
        ("cut random rig", RANDOM, SceneKind::Cut, 4, 30, 12, 2.0),
    ] {
        let steps = track(setup, kind, seed, first, frames, None, no_edit);
        let (normal, tip, valid) = summary(name, &steps);
        assert_eq!(valid, 1.0, "{name}: every frame should be trusted");
        assert!(normal[0] <= degrees && tip[0] <= 1.0, "{name}: mean {normal:?} deg, {tip:?} mm");
        assert!(normal[1] <= 2.0 * degrees && tip[1] <= 2.0, "{name}: p95 {normal:?} deg, {tip:?} mm");
    }
}

#[test]
fn the_images_of_a_tool_whose_blade_and_handle_differ_change_no_right_fit() {
    // The colours of the blade and of the handle are learned from trusted fits and refuse a view
    // where the blade lies on the handle's colours; where the fit is right (truth masks), no view
    // may be refused so, on the built-in rig with a blue anodized handle and a dull blade
    // (skin-dark) and on lab8 in a seeded random look; the parts learned apart on both.
    for (name, setup, look) in
        [("built-in rig, skin-dark", BUILTIN, "skin-dark"), ("lab8, random:811", LAB8, "random:811")]
    {
        let mut config = SceneConfig::new(SceneKind::Cut, 2, 42);
        config.rig = setup.rig.rig();
        config.tool = setup.tool;
        config.appearance = Appearance::from_name(look).expect("a look");
        let scene = Scene::new(config).expect("scene");
        let rig = scene.config().rig.clone();
        let template = Template::new(&scene.scalpel().geometry).expect("template");
        let (mut plain, mut coloured) = (
            Tracker::new(template.clone(), TrackerParams::default()),
            Tracker::new(template, TrackerParams::default()),
        );
        let params = hull_params(&rig);
        let mut told_when_judged = 0;
        for f in 30..42 {
            let views: Vec<_> = (0..rig.cameras.len()).map(|c| scene.render_view(f, c)).collect();
            let masks: Vec<Option<&GrayImage>> = views.iter().map(|v| v.as_ref().map(|v| &v.mask)).collect();
            let occ = carve(&silhouettes(&rig, &masks).expect("sizes"), &params).expect("carve");
            let inputs = |images: bool| -> Vec<Option<ViewInput>> {
                rig.cameras
                    .iter()
                    .zip(&views)
                    .map(|(camera, v)| {
                        v.as_ref().map(|v| ViewInput { camera, mask: &v.mask, image: images.then_some(&v.image) })
                    })
                    .collect()
            };
            let ts = scene.frame_timestamp(f);
            let a = plain.update(f, ts, &occ, &inputs(false));
            let b = coloured.update(f, ts, &occ, &inputs(true));
            assert_eq!(b.diagnostics.views_handle_coloured, 0, "{name}, frame {f}: {:?}", b.diagnostics);
            assert_eq!((a.valid, &a.pose, &a.reason), (b.valid, &b.pose, &b.reason), "{name}, frame {f}");
            assert!(b.valid, "{name}, frame {f}: {:?}", b.reason);
            assert!(!a.diagnostics.parts_told_apart, "{name}, frame {f}: no images, no colours");
            told_when_judged += usize::from(b.diagnostics.parts_told_apart);
        }
        assert!(!plain.parts_told_apart(), "{name}: no images, nothing learned");
        assert!(coloured.parts_told_apart(), "{name}: the blade's and the handle's colours told apart");
        assert!(told_when_judged > 0, "{name}: the judged fits knew the parts apart");
    }
}

/// Every label grown one pixel into the background (four neighbours; the scalpel wins a tie):
/// a segmentation that takes in the blended edge pixels.
fn fatter(_: usize, _: u64, mask: &mut GrayImage) {
    let before = mask.clone();
    let (w, h) = before.dimensions();
    for (x, y, p) in mask.enumerate_pixels_mut() {
        if p[0] != label::BACKGROUND {
            continue;
        }
        let around = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
        p[0] = around
            .iter()
            .filter(|&&(i, j)| i < w && j < h)
            .map(|&(i, j)| before.get_pixel(i, j)[0])
            .filter(|&l| l != label::BACKGROUND)
            .max()
            .unwrap_or(label::BACKGROUND);
    }
}

/// Every labelled pixel beside the background (four neighbours) dropped: a segmentation that
/// loses the blended edge pixels.
fn thinner(_: usize, _: u64, mask: &mut GrayImage) {
    let before = mask.clone();
    let (w, h) = before.dimensions();
    for (x, y, p) in mask.enumerate_pixels_mut() {
        let around = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
        if around.iter().any(|&(i, j)| i < w && j < h && before.get_pixel(i, j)[0] == label::BACKGROUND) {
            p[0] = label::BACKGROUND;
        }
    }
}

#[test]
fn masks_a_pixel_fatter_or_thinner_than_the_tool_keep_the_blade_within_two_degrees() {
    // Masks from elsewhere (a lab's own segmentation) take in or lose a blade's blended edge
    // pixels. Measured (cut, seed 2, frames 30..42), worst trusted frame with the outline offset /
    // without it: lab8 fatter 1.26° 0.43 mm / none of 12 trusted; lab8 thinner 1.37° 1.22 mm / 6.32°
    // 7.07 mm with 4 refused; random rig fatter 0.56° 0.44 mm / 1.64° 2.43 mm; random rig thinner
    // 0.82° 0.50 mm / 7.60° 2.37 mm. The offsets found: 0.91-0.95 px fatter, 0.72-0.77 px thinner.
    // Since the blade's thickness is fitted (2026-12-02) the first frame set's search from the
    // hull crept through all its iterations with the offset held at 0 on lab8's fatter masks
    // (10.96° off); the offset now joins the search at half its iterations (0.54°).
    type Edit = fn(usize, u64, &mut GrayImage);
    let with_offset = TrackerParams { outline_offset: true, ..TrackerParams::default() };
    for (name, setup) in [("lab8", LAB8), ("random rig", RANDOM)] {
        for (edit_name, edit, sign) in [("fatter", fatter as Edit, 1.0), ("thinner", thinner as Edit, -1.0)] {
            let name = format!("{name}, masks a pixel {edit_name}");
            let steps = track_with(with_offset.clone(), setup, SceneKind::Cut, 2, 30, 12, None, edit);
            let (_, _, valid) = summary(&name, &steps);
            assert_eq!(valid, 1.0, "{name}: every frame should be trusted");
            for s in &steps {
                let e = s.error.expect("a trusted frame has a pose");
                assert!(!e.exceeds(2.0, 2.0), "{name}: frame {} off by {e:?}", s.estimate.frame);
                let offset = s.estimate.diagnostics.fit_offset_px * sign;
                assert!((0.5..=1.2).contains(&offset), "{name}: frame {} offset {offset} px", s.estimate.frame);
            }
        }
    }
    // The scene exercises what the offset is for: without it (the default) the thinner masks turn
    // the blade.
    let steps = track(RANDOM, SceneKind::Cut, 2, 30, 12, None, thinner);
    let off = steps.iter().filter(|s| !s.estimate.valid || s.error.is_none_or(|e| e.exceeds(4.0, 5.0))).count();
    assert!(off >= 6, "without the offset only {off} of 12 frames were refused or off by 4°");
}

#[test]
fn hard_scene_never_trusts_a_pose_off_by_5_degrees_or_5_mm() {
    // Fast strokes edge-on to two cameras, the index finger over the spine, camera 4 dropping
    // frames. Measured (seed 3, frames 20..50): all valid, mean 1.31° / 0.40 mm, max 2.96° / 1.73 mm.
    for (name, setup, frames) in [("hard", BUILTIN, 30), ("hard lab8", LAB8, 15)] {
        let steps = track(setup, SceneKind::Hard, 3, 20, frames, None, no_edit);
        let (_, _, valid) = summary(name, &steps);
        for s in steps.iter().filter(|s| s.estimate.valid) {
            let e = s.error.expect("a trusted frame has a pose");
            assert!(!e.exceeds(5.0, 5.0), "{name}: frame {} trusted with {e:?}", s.estimate.frame);
        }
        assert!(valid >= 0.8, "{name}: valid fraction {valid}");
    }
}

#[test]
fn views_edge_on_stand_in_for_a_third_seeing_view_only_where_the_blade_cannot_turn_about_its_axis() {
    // Two rigs of four cameras where two views see the blade's face and two more see it edge-on
    // (the resection of random:1049 in random:1087 and random:1021 in random:1051). Measured with
    // truth masks: on the first the edge-on views fix the blade's turn about its long axis
    // (spans of 15-35°), so they stand in for a third seeing view; on the second, fits in 28 of
    // the first 60 frame sets turn 15-19° off in roll with the tip within a millimetre and still
    // fit every silhouette (spans of 50° and more), and are refused. Since the blade's thickness
    // is fitted (2026-12-02) most of the second's fits from frame set 15 on are refused before the
    // span is asked (two views see the face, fewer than two edge-on); six still span 45°.
    let stood_in =
        |steps: &[Step]| steps.iter().filter(|s| s.estimate.valid && s.estimate.diagnostics.views_seen == 2).count();
    let fixed = Setup { rig: RigPreset::Random(1049), tool: ToolKind::Standard };
    let steps = track(fixed, SceneKind::Resect, 1, 0, 40, None, no_edit);
    let (_, _, valid) = summary("random:1049", &steps);
    assert!(stood_in(&steps) >= 30, "random:1049: {} trusted with two views seeing", stood_in(&steps));
    assert!(valid >= 0.85, "random:1049: valid fraction {valid}");
    let turning = Setup { rig: RigPreset::Random(1021), tool: ToolKind::Pointed };
    let turning_steps = track(turning, SceneKind::Resect, 1, 0, 60, None, no_edit);
    let unfixed =
        turning_steps.iter().filter(|s| s.estimate.diagnostics.roll_span_deg.is_some_and(|span| span >= 45.0)).count();
    assert!(unfixed >= 4, "random:1021: {unfixed} fits found turning 45° or more");
    for (name, steps) in [("random:1049", &steps), ("random:1021", &turning_steps)] {
        for s in steps.iter().filter(|s| s.estimate.valid) {
            let e = s.error.expect("a trusted frame has a pose");
            assert!(!e.exceeds(5.0, 5.0), "{name}: frame {} trusted with {e:?}", s.estimate.frame);
        }
    }
}

#[test]
fn the_blades_turn_about_its_long_axis_is_held_less_well_in_coarser_pixels() {
    // The pointed blade in the cut scene (seed 2, frame sets 30..40), truth masks, on the built-in
    // rig at 640x480 and the same rig at 320x240: the fits' `roll_sd_deg` (the turn's deviation
    // for a pixel of noise) grows as the pixels do, by two for the pixels' size and some more for
    // the fewer outline samples (2√2 together). Measured: median 3.98° -> 11.91° (`hullcut run`
    // on the 320x240 resection gives 8-20°).
    let median_roll_sd = |factor: f64| {
        let mut config = SceneConfig::new(SceneKind::Cut, 2, 40);
        config.rig = RigPreset::Default.rig();
        config.rig.cameras.iter_mut().for_each(|c| *c = c.scaled(factor));
        config.tool = ToolKind::Pointed;
        let scene = Scene::new(config).expect("scene");
        let steps = track_scene(TrackerParams::default(), &scene, 30, 10, None, no_edit);
        let mut sd: Vec<f64> = steps.iter().filter_map(|s| s.estimate.diagnostics.roll_sd_deg).collect();
        assert!(sd.len() >= 8, "{factor}: {} fits with a deviation", sd.len());
        sd.sort_by(f64::total_cmp);
        sd[sd.len() / 2]
    };
    let (fine, coarse) = (median_roll_sd(1.0), median_roll_sd(0.5));
    println!("roll sd per pixel of noise, median: 640x480 {fine:.2}°, 320x240 {coarse:.2}°");
    assert!(fine > 0.0 && coarse / fine > 2.0 && coarse / fine < 4.0, "{fine}° -> {coarse}°");
}

#[test]
fn a_blade_fitted_as_thick_as_it_is_is_not_turned_to_cover_its_thickness() {
    // Truth masks. Seen edge-on, or at a steep slant, a blade is as wide as it is thick (0.4 mm
    // the standard blade, 0.35 mm the pointed one: a third of a pixel to a pixel here), and a
    // template of its mid-plane alone turned about the long axis to cover that width. Measured,
    // the mean normal error with the mid-plane alone -> with both faces: the built-in rig's static
    // blade 0.87° -> 0.27°, lab8's (the pointed blade, 1280x720) 0.75° -> 0.31°, its cut
    // 0.69° -> 0.16°, the seeded random rig's cut 1.88° -> 0.10°; every error a turn about the
    // long axis.
    for (name, setup, kind, seed, first, frames) in [
        ("static", BUILTIN, SceneKind::Static, 1, 0, 12),
        ("static lab8", LAB8, SceneKind::Static, 1, 0, 6),
        ("cut lab8", LAB8, SceneKind::Cut, 2, 30, 12),
        ("cut random rig", RANDOM, SceneKind::Cut, 4, 30, 12),
    ] {
        let scene = scene(setup, kind, seed, first + frames);
        let mean_normal = |faces: bool| {
            let mut template = Template::new(&scene.scalpel().geometry).expect("template");
            if !faces {
                template.blade_faces = template.blade.clone();
            }
            let steps = track_template(TrackerParams::default(), &scene, first, frames, template, no_edit);
            let (normal, _, valid) = summary(name, &steps);
            assert_eq!(valid, 1.0, "{name}: every frame should be trusted (faces: {faces})");
            normal[0]
        };
        let (plane, faces) = (mean_normal(false), mean_normal(true));
        println!("{name}: mean normal error, mid-plane {plane:.3}°, both faces {faces:.3}°");
        assert!(faces <= 0.5 && faces <= 0.6 * plane, "{name}: {plane}° -> {faces}°");
    }
}

#[test]
fn a_blade_the_masks_lost_in_one_view_is_on_background_there_not_behind_the_hand() {
    // The blade's pixels of camera 0 turned to background (a dark blade taken for a shadow) or to
    // the hand, in frames 30..36 of the cut scene: the view that does not see the blade's face is
    // counted on background in the first case, hidden by the hand in the second.
    for (to, name) in [(label::BACKGROUND, "background"), (label::HAND, "hand")] {
        let lose = move |c: usize, _: u64, m: &mut GrayImage| {
            if c == 0 {
                m.pixels_mut().filter(|p| p.0[0] == label::SCALPEL).for_each(|p| p.0[0] = to);
            }
        };
        let steps = track(BUILTIN, SceneKind::Cut, 2, 30, 6, None, lose);
        let counts: Vec<(usize, usize, usize, usize)> = steps
            .iter()
            .map(|s| {
                let d = &s.estimate.diagnostics;
                (d.views_seen, d.views_edge_on, d.views_hidden, d.views_on_background)
            })
            .collect();
        println!("camera 0's blade as {name}: (seen, edge-on, hidden, on background) {counts:?}");
        let expected = if to == label::BACKGROUND { (0, 1) } else { (1, 0) };
        for (s, c) in steps.iter().zip(&counts) {
            assert_eq!((c.2, c.3), expected, "{name}: frame {} counted {c:?}", s.estimate.frame);
            // Nor is the view set aside: it shows no blade where the others put it, and may be
            // right (only a view that lost the blade in patches is).
            assert_eq!(s.estimate.diagnostics.view_set_aside, None, "{name}: frame {}", s.estimate.frame);
        }
    }
}

#[test]
fn a_frame_without_the_scalpel_is_refused_and_the_last_pose_held_for_a_bounded_time() {
    // Frames 30..36 of the cut scene; the scalpel vanishes from every mask from frame 33 on (as
    // if the segmentation lost it). 30 frames per second: 0.5 s of hold covers the rest.
    let gone = |_: usize, f: u64, m: &mut GrayImage| {
        if f >= 33 {
            m.pixels_mut().filter(|p| p.0[0] == label::SCALPEL).for_each(|p| p.0[0] = label::BACKGROUND);
        }
    };
    let steps = track(BUILTIN, SceneKind::Cut, 2, 30, 6, None, gone);
    let last_trusted = steps[2].estimate.pose.clone().expect("frame 32 is trusted");
    for s in &steps[3..] {
        let e = &s.estimate;
        assert!(!e.valid && e.held, "frame {}: {e:?}", e.frame);
        assert_eq!(e.reason.as_deref(), Some("no scalpel leaves in the hull"));
        assert_eq!(e.pose.as_ref(), Some(&last_trusted), "the held pose is the last trusted one");
        assert!(e.confidence == 0.0);
    }

    // Past the hold time nothing is held.
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 2, 60)).expect("scene");
    let rig = scene.config().rig.clone();
    let mut tracker =
        Tracker::new(Template::new(&scene.scalpel().geometry).expect("template"), TrackerParams::default());
    let params = hull_params(&rig);
    let masks = |f: u64, keep: bool| -> Vec<Option<GrayImage>> {
        (0..rig.cameras.len())
            .map(|c| {
                scene.render_view(f, c).map(|v| {
                    let mut m = v.mask;
                    if !keep {
                        gone(c, 99, &mut m);
                    }
                    m
                })
            })
            .collect()
    };
    let first = estimate(&mut tracker, &rig, &masks(30, true), &params, 30, scene.frame_timestamp(30));
    assert!(first.valid);
    let soon = estimate(&mut tracker, &rig, &masks(40, false), &params, 40, scene.frame_timestamp(40));
    assert!(soon.held, "0.33 s later the pose is held");
    let late = estimate(&mut tracker, &rig, &masks(50, false), &params, 50, scene.frame_timestamp(50));
    assert!(!late.valid && !late.held && late.pose.is_none(), "0.67 s later nothing is held: {late:?}");
}

#[test]
fn two_scalpel_like_components_are_refused() {
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 2, 40)).expect("scene");
    let rig = scene.config().rig.clone();
    let t = Scene::seconds(scene.frame_timestamp(35));
    let mut parts = scene.parts_at(t);
    let shift = Isometry3::translation(0.0, -0.12, 0.0);
    let twins: Vec<Part> = parts
        .iter()
        .filter(|p| p.label == label::SCALPEL)
        .map(|p| Part { label: p.label, albedo: p.albedo, mesh: p.mesh.transformed(&shift) })
        .collect();
    parts.extend(twins);
    let masks: Vec<Option<GrayImage>> = rig
        .cameras
        .iter()
        .map(|c| {
            let layers = CameraRenderer::new(c, Light::default()).render(&parts);
            GrayImage::from_raw(c.width, c.height, layers.labels)
        })
        .collect();
    let mut tracker =
        Tracker::new(Template::new(&scene.scalpel().geometry).expect("template"), TrackerParams::default());
    let params = hull_params(&rig);
    let e = estimate(&mut tracker, &rig, &masks, &params, 35, scene.frame_timestamp(35));
    assert!(!e.valid && !e.held && e.pose.is_none());
    let reason = e.reason.expect("a reason");
    assert!(reason.starts_with("two scalpel-like components"), "{reason} {:?}", e.diagnostics);
}

#[test]
fn a_tool_file_in_millimetres_is_refused_and_a_tool_of_another_size_does_not_match_the_hull() {
    let scene = Scene::new(SceneConfig::new(SceneKind::Cut, 2, 33)).expect("scene");
    let scaled = |factor: f64| {
        let mut tool = scene.scalpel().geometry.clone();
        let scale = |p: &mut nalgebra::Point3<f64>| *p = nalgebra::Point3::from(p.coords * factor);
        tool.mesh.vertices.iter_mut().for_each(scale);
        tool.cutting_edge.iter_mut().for_each(scale);
        scale(&mut tool.tip);
        if let Some(o) = tool.blade_outline.as_mut() {
            o.iter_mut().for_each(scale);
        }
        tool.blade_thickness *= factor;
        tool
    };
    // In millimetres: the template and the geometric labeller refuse it up front, before
    // gridding a 150 m tool at 1 mm.
    let mm = scaled(1000.0);
    for message in [
        Template::new(&mm).err().map(|e| e.to_string()),
        hullcut_pose::ToolLabeller::new(&mm, TrackerParams::default(), hullcut_pose::LabelParams::default())
            .err()
            .map(|e| e.to_string()),
    ] {
        let message = message.unwrap_or_default();
        assert!(message.contains("in metres") && message.contains("millimetres"), "{message}");
    }
    // A tool a tenth of the scene's (1.5 cm) is a tool, but not the one in the hull: every frame
    // is refused by the tracker.
    let small = scaled(0.1);
    let steps = track(BUILTIN, SceneKind::Cut, 2, 30, 3, Some(&small), no_edit);
    for s in &steps {
        let e = &s.estimate;
        assert!(!e.valid && e.pose.is_none());
        let reason = e.reason.as_deref().unwrap_or_default();
        assert!(reason.starts_with("the tool does not match the hull"), "{reason}");
    }
}

#[test]
fn a_tool_with_a_vertex_far_out_or_not_a_number_is_refused_before_anything_is_sized_from_it() {
    let scene = Scene::new(SceneConfig::new(SceneKind::Static, 1, 1)).expect("scene");
    let good = scene.scalpel().geometry.clone();
    assert!(hullcut_pose::check_tool(&good).is_ok());
    let refused = |edit: &dyn Fn(&mut ToolGeometry)| {
        let mut tool = good.clone();
        edit(&mut tool);
        // Refused at once, by the template and by the labeller alike: no grid of 1e300 m is built.
        let clock = std::time::Instant::now();
        let template = Template::new(&tool).err().map(|e| e.to_string()).unwrap_or_default();
        let labeller = hullcut_pose::ToolLabeller::new(&tool, TrackerParams::default(), Default::default())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(clock.elapsed() < std::time::Duration::from_secs(5), "{template}");
        assert_eq!(template, labeller);
        template
    };
    let e = refused(&|t| t.mesh.vertices[3].x = 1e300);
    assert!(e.contains("spans 1.000e300 m") && e.contains("mesh vertex 3"), "{e}");
    let e = refused(&|t| t.mesh.vertices[0].y = f64::NAN);
    assert!(e.contains("mesh vertex 0") && e.contains("not a finite number"), "{e}");
    let e = refused(&|t| t.cutting_edge[1].z = 1e308);
    assert!(e.contains("cutting_edge point 1"), "{e}");
    let e = refused(&|t| t.tip.x = f64::INFINITY);
    assert!(e.contains("the tip") && e.contains("not a finite number"), "{e}");
    let e = refused(&|t| t.blade_normal = Vector3::zeros());
    assert!(e.contains("blade_normal"), "{e}");
    let e = refused(&|t| t.blade_thickness = f64::NAN);
    assert!(e.contains("blade_thickness"), "{e}");
}

#[test]
fn a_true_pose_that_is_not_a_rotation_is_refused_at_once() {
    use hullcut_pose::{MatrixError, rigid_from_matrix};
    // A rotation entry of 1e19 once made the rotation fit loop without end.
    let mut m = Matrix4::identity();
    m[(0, 0)] = 1e19;
    let clock = std::time::Instant::now();
    assert!(matches!(rigid_from_matrix(&m), Err(MatrixError::NotOrthonormal { .. })));
    assert!(clock.elapsed() < std::time::Duration::from_secs(1));
    assert!(isometry_from_matrix(&m).is_none());
    // A scaled rotation, a reflection, a NaN: each named.
    let scaled = Matrix4::identity() * 2.0;
    assert!(matches!(rigid_from_matrix(&scaled), Err(MatrixError::NotOrthonormal { .. })));
    let mut mirror = Matrix4::identity();
    mirror[(2, 2)] = -1.0;
    assert!(matches!(rigid_from_matrix(&mirror), Err(MatrixError::Reflection { .. })));
    let mut nan = Matrix4::identity();
    nan[(1, 2)] = f64::NAN;
    let e = rigid_from_matrix(&nan).expect_err("a NaN");
    assert!(matches!(e, MatrixError::NonFinite { row: 1, col: 2, .. }));
    assert!(e.to_string().contains("(1, 2)"), "{e}");
    // A rotation written with 1e-7 rounding is made exactly a rotation (to 1e-12, far below the
    // rounding), keeping the translation.
    let truth = Isometry3::new(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.4, -0.5, 0.6));
    let mut rounded = truth.to_homogeneous();
    rounded[(0, 1)] += 1e-7;
    rounded[(2, 0)] -= 1e-7;
    let back = rigid_from_matrix(&rounded).expect("a rotation");
    let r = back.rotation.to_rotation_matrix().into_inner();
    assert!((r.transpose() * r - nalgebra::Matrix3::identity()).abs().max() < 1e-12);
    assert!(back.rotation.angle_to(&truth.rotation) < 1e-6);
    assert_eq!(back.translation.vector, truth.translation.vector);
}

#[test]
fn a_pose_with_nan_is_not_an_isometry_and_a_pose_is_checked_for_finiteness() {
    let mut m = Matrix4::identity();
    assert!(isometry_from_matrix(&m).is_some());
    m[(0, 3)] = f64::NAN;
    assert!(isometry_from_matrix(&m).is_none());
    let scene = Scene::new(SceneConfig::new(SceneKind::Static, 1, 1)).expect("scene");
    let template = Template::new(&scene.scalpel().geometry).expect("template");
    let good = hullcut_pose::BladePose::new(&template, Isometry3::translation(0.0, 0.0, 0.1));
    assert!(good.is_finite());
    let bad =
        hullcut_pose::BladePose::new(&template, Isometry3::new(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros()));
    assert!(!bad.is_finite());
}

/// The geometric labeller over one frame's foreground (labels dropped, as segmentation gives it)
/// whose tool it trusts, then thirteen frame sets with no foreground at all (the hull holds no
/// tool to find), then the foreground again: while the searches of the hull find nothing they run
/// on every frame set, then on every second, then every fourth; the first search that finds the
/// tool ends the pacing. With a gap of 1 every frame set is searched.
#[test]
fn a_lost_tool_is_searched_for_on_fewer_frame_sets_while_the_searches_find_nothing() {
    // The built-in rig and tool, and eight 1280x720 cameras with the pointed blade.
    for setup in [BUILTIN, LAB8] {
        lost_tool_searches(setup);
    }
}

/// [`a_lost_tool_is_searched_for_on_fewer_frame_sets_while_the_searches_find_nothing`] on one rig and tool.
fn lost_tool_searches(setup: Setup) {
    use hullcut_pose::{LabelParams, ToolLabeller};
    let scene = scene(setup, SceneKind::Static, 1, 1);
    let rig = scene.config().rig.clone();
    let params = hull_params(&rig);
    let seen: Vec<Option<GrayImage>> = (0..rig.cameras.len())
        .map(|c| {
            scene.render_view(0, c).map(|v| {
                let mut m = v.mask;
                m.iter_mut().filter(|p| **p != label::BACKGROUND).for_each(|p| *p = label::UNKNOWN);
                m
            })
        })
        .collect();
    let empty: Vec<Option<GrayImage>> =
        seen.iter().map(|m| m.as_ref().map(|m| GrayImage::new(m.width(), m.height()))).collect();
    let run = |gap: u32| {
        let tracker = TrackerParams { agreement: (0.82, 0.92), outline_offset: false, ..TrackerParams::default() };
        let mut labeller =
            ToolLabeller::new(&scene.scalpel().geometry, tracker, LabelParams::default()).expect("labeller");
        labeller.set_max_search_gap(gap);
        (0..18u64)
            .map(|frame| {
                let masks = if (1..=13).contains(&frame) { &empty } else { &seen };
                let refs: Vec<Option<&GrayImage>> = masks.iter().map(Option::as_ref).collect();
                let occ = carve(&silhouettes(&rig, &refs).expect("sizes"), &params).expect("carve");
                let inputs = mask_inputs(&rig, masks);
                // A frame set every 0.1 s: the track's hold (0.5 s) ends at frame set 6.
                let out = labeller.label(frame, frame as i64 * 100_000_000, &occ, &[], &inputs, None);
                (out.estimate.valid, out.stats.search_paused, out.estimate.reason)
            })
            .collect::<Vec<_>>()
    };
    let paced = run(4);
    let valid: Vec<bool> = paced.iter().map(|s| s.0).collect();
    let paused: Vec<u64> = (0..18).filter(|&f| paced[f as usize].1).collect();
    assert!(valid[0], "{setup:?}: the first frame set trusted: {:?}", paced[0].2);
    assert!(!valid[1..=15].contains(&true), "{valid:?}");
    // Searched on 1 and 2 (the second failure), 4 (the third), then every fourth: 8, 12, 16,
    // which finds the tool again; 17 follows its track.
    assert_eq!(paused, vec![3, 5, 6, 7, 9, 10, 11, 13, 14, 15], "{setup:?}: {paced:?}");
    assert!(valid[16] && valid[17], "{paced:?}");
    // Past the hold, a paused frame set says why it was not searched.
    let reason = paced[9].2.as_deref().unwrap_or_default();
    assert!(reason.contains("one frame set in 4") && reason.contains("the last 4 searches"), "{reason}");
    // Every frame set searched: found again as soon as the tool is back.
    let every = run(1);
    assert!(every.iter().all(|s| !s.1), "{every:?}");
    assert!(every[0].0 && !every[1..14].iter().any(|s| s.0) && every[14..].iter().all(|s| s.0), "{every:?}");
}

/// Each view's sight of the fitted blade is given by its place in the rig, a view without a mask
/// has none, and the sights add up to the counts of each kind; on two rigs.
#[test]
fn each_views_sight_of_the_blade_is_given_by_its_place_in_the_rig() {
    for (name, setup) in [("built-in rig", BUILTIN), ("random:5", RANDOM)] {
        let scene = scene(setup, SceneKind::Cut, 3, 42);
        let rig = scene.config().rig.clone();
        let template = Template::new(&scene.scalpel().geometry).expect("template");
        let mut tracker = Tracker::new(template, TrackerParams::default());
        let params = hull_params(&rig);
        // The second camera gives no mask.
        let missing = 1;
        let mut judged = 0;
        for f in 30..36 {
            let views: Vec<_> =
                (0..rig.cameras.len()).map(|c| scene.render_view(f, c).filter(|_| c != missing)).collect();
            let masks: Vec<Option<&GrayImage>> = views.iter().map(|v| v.as_ref().map(|v| &v.mask)).collect();
            let occ = carve(&silhouettes(&rig, &masks).expect("sizes"), &params).expect("carve");
            let inputs: Vec<Option<ViewInput>> = rig
                .cameras
                .iter()
                .zip(&views)
                .map(|(camera, v)| v.as_ref().map(|v| ViewInput { camera, mask: &v.mask, image: Some(&v.image) }))
                .collect();
            let e = tracker.update(f, scene.frame_timestamp(f), &occ, &inputs);
            let d = &e.diagnostics;
            if e.fitted.is_none() {
                continue;
            }
            judged += 1;
            assert_eq!(d.sight.len(), rig.cameras.len(), "{name}, frame {f}");
            assert_eq!(d.sight[missing], None, "{name}, frame {f}: no mask, no sight");
            let count = |kind: Sight| d.sight.iter().filter(|s| **s == Some(kind)).count();
            assert_eq!(
                [Sight::Seen, Sight::EdgeOn, Sight::Hidden, Sight::OnBackground, Sight::HandleColoured].map(count),
                [d.views_seen, d.views_edge_on, d.views_hidden, d.views_on_background, d.views_handle_coloured],
                "{name}, frame {f}: {d:?}"
            );
            assert!(d.views_seen >= 2, "{name}, frame {f}: truth masks, the blade's face seen: {d:?}");
        }
        assert!(judged >= 5, "{name}: {judged} of 6 frames fitted");
    }
}

/// From frame 34 on, the scalpel's pixels of camera 0 in a checkerboard of 3-pixel blocks turned
/// to background: a grey blade come over a grey table, half lost from one view's foreground in
/// patches.
fn patchy_in_camera_0(c: usize, f: u64, m: &mut GrayImage) {
    if c == 0 && f >= 34 {
        for (x, y, p) in m.enumerate_pixels_mut() {
            if p.0[0] == label::SCALPEL && (x / 3 + y / 3) % 2 == 0 {
                p.0[0] = label::BACKGROUND;
            }
        }
    }
}

#[test]
fn a_view_whose_mask_lost_the_blade_in_patches_is_set_aside_and_the_others_fit_it() {
    // The cut scene's frames 30..44, on the built-in rig (six cameras) and on eight cameras with
    // the pointed scalpel, camera 0's blade in patches from frame 34: the fit that keeps every
    // view cannot explain the patches' outlines and is refused; set aside, that view leaves the
    // blade to the others, within a degree or two of the truth. With whole masks no view is set
    // aside.
    for setup in [BUILTIN, LAB8] {
        let never = TrackerParams { set_aside_share: 2.0, ..TrackerParams::default() };
        let kept = track_with(never, setup, SceneKind::Cut, 2, 30, 14, None, patchy_in_camera_0);
        let aside = track(setup, SceneKind::Cut, 2, 30, 14, None, patchy_in_camera_0);
        let whole = track(setup, SceneKind::Cut, 2, 30, 14, None, no_edit);
        let trusted = |steps: &[Step]| steps.iter().filter(|s| s.estimate.valid).count();
        println!("{setup:?}, camera 0 patchy: {} of 14 trusted keeping it", trusted(&kept));
        let (normal, tip, valid) = summary(&format!("{setup:?}, camera 0 patchy, set aside"), &aside);
        let set_aside: Vec<Option<usize>> = aside.iter().map(|s| s.estimate.diagnostics.view_set_aside).collect();
        println!("{setup:?}: views set aside {set_aside:?}");
        assert!(set_aside[4..].iter().all(|v| *v == Some(0)), "{setup:?}: {set_aside:?}");
        assert!(set_aside.iter().all(|v| v.is_none_or(|k| k == 0)), "{setup:?}: {set_aside:?}");
        assert!(valid >= 0.9 && trusted(&aside) > trusted(&kept), "{setup:?}: {valid}");
        assert!(normal[2] < 3.0 && tip[2] < 2.0, "{setup:?}: normal {normal:?}, tip {tip:?}");
        let whole_aside: Vec<u64> = whole
            .iter()
            .filter(|s| s.estimate.diagnostics.view_set_aside.is_some())
            .map(|s| s.estimate.frame)
            .collect();
        assert!(whole_aside.is_empty(), "{setup:?}: a view of whole masks set aside in frames {whole_aside:?}");
    }
}
