//! A frame set's label masks left to be drawn later, off the loop's path
//! ([`Labelling::defer_drawing`]), are the masks its labelling would have drawn at once, frame set
//! after frame set, on three rigs, looks and tools (the second and third seeded random); and
//! [`Labelling::label`] draws them at once whatever the deferral says. The colours a trusted frame
//! set teaches beside the labelling are taken two frame sets later, or when settled, and at once
//! where they are not learned beside it.

use hullcut_dataset::Dataset;
use hullcut_hull::{HullParams, WorkingVolume};
use hullcut_pipeline::{Carver, LabelMethod, LabelSource, Labelling};
use hullcut_rig::RigPreset;
use hullcut_synth::{Appearance, Scene, SceneConfig, SceneKind, ToolKind, synthesize};

/// A resection of `frames` frame sets on `rig` with `appearance` and `tool`, opened, and how to
/// set up its labelling.
fn recording(
    rig: &str,
    appearance: Appearance,
    tool: ToolKind,
    frames: u64,
) -> (tempfile::TempDir, Dataset, impl Fn(&Dataset) -> Labelling) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut config = SceneConfig::new(SceneKind::Resect, 3, frames);
    config.rig = RigPreset::parse(rig).expect("a rig").rig();
    config.appearance = appearance;
    config.tool = tool;
    config.truth_meshes = false;
    config.depth_maps = false;
    let scene = Scene::new(config).expect("the scene");
    let root = dir.path().join("recording");
    synthesize(&scene, &root, "deferred", false, &|| {}).expect("the recording is written");
    let ds = Dataset::open(&root).expect("the recording opens");
    let tool = ds.tool().expect("tool.json reads");
    let volume = WorkingVolume::from_rig(ds.rig(), 3, true).expect("a working volume");
    let hull = HullParams { min_views: 3, ..HullParams::new(volume.aabb, 0.4 / 128.0) };
    let labelling =
        move |ds: &Dataset| Labelling::new(ds, tool.as_ref(), hull.clone(), &[], LabelMethod::Both).expect("labelling");
    (dir, ds, labelling)
}

/// Labels the first `frames` frame sets of a resection both ways, every frame set's masks
/// wanted: drawn at once, and deferred (then drawn from what the labelling handed out). Returns
/// how many were deferred, and how many trusted frame sets taught the colours: drawn at once
/// one way, drawn by their lessons the other, they teach the same colours.
fn drawn_and_deferred(rig: &str, appearance: Appearance, tool: ToolKind, frames: u64) -> (u64, u64) {
    let (_dir, ds, labelling) = recording(rig, appearance, tool, frames);
    let (mut now, mut later) = (labelling(&ds), labelling(&ds));
    later.defer_drawing(true);
    for l in [&mut now, &mut later] {
        l.learn_beside(true);
    }
    let (mut carve_now, mut carve_later) = (Carver::Cpu, Carver::Cpu);
    for frame in ds.frame_numbers() {
        let set = ds.read_frame_set(frame, false).expect("a frame set");
        let drawn = now.label_with(&set, &mut carve_now, true).expect("labelled");
        let mut deferred = later.label_with(&set, &mut carve_later, true).expect("labelled");
        assert_eq!(drawn.source, deferred.source, "{rig}, frame {frame}");
        let pose = |l: &hullcut_pipeline::labelling::Labelled| {
            l.estimate.as_ref().and_then(|e| e.fitted.as_ref()).map(|f| f.tool_to_world)
        };
        assert_eq!(pose(&drawn), pose(&deferred), "{rig}, frame {frame}: the fits part");
        let masks = match deferred.pending.take() {
            Some(pending) => {
                assert!(matches!(deferred.source, LabelSource::Geometry | LabelSource::UntrustedGeometry));
                assert!(deferred.masks.iter().all(Option::is_none), "{rig}, frame {frame}: masks and pending both");
                assert!(!deferred.drawn, "{rig}, frame {frame}: counted as drawn");
                pending.draw(&set, deferred.occupancy.as_ref().expect("the fit's hull"))
            }
            None => deferred.masks,
        };
        assert_eq!(masks.len(), drawn.masks.len());
        for (k, (a, b)) in drawn.masks.iter().zip(&masks).enumerate() {
            assert!(a == b, "{rig}, frame {frame}, view {k}: the masks drawn later differ");
        }
    }
    now.settle().expect("the last lesson is taken");
    later.settle().expect("the last lesson is taken");
    let (report_now, report_later) = (now.report(), later.report());
    // The lessons drawn from what the labelling handed out teach what those drawn at once do.
    assert_eq!(report_now.lessons, report_later.lessons, "{rig}");
    assert_eq!(report_now.counters.learned, report_later.counters.learned, "{rig}");
    assert_eq!(format!("{:?}", report_now.appearance), format!("{:?}", report_later.appearance), "{rig}");
    assert_eq!(
        format!("{:?}", report_now.sharpening_appearance),
        format!("{:?}", report_later.sharpening_appearance),
        "{rig}"
    );
    // Drawn at once: the same frame sets both ways but for those deferred, and those whose
    // untrusted fit was drawn but the colours labelled (neither drawn nor deferred later).
    assert_eq!(report_now.deferred, 0);
    assert!(report_later.drawn + report_later.deferred <= report_now.drawn, "{rig}");
    // `label` draws at once whatever the deferral says (the first ten frame sets: all but the
    // first teach nothing, and some are deferred above).
    let mut eager = labelling(&ds);
    eager.defer_drawing(true);
    for frame in ds.frame_numbers().into_iter().take(10) {
        let set = ds.read_frame_set(frame, false).expect("a frame set");
        let labelled = eager.label(&set, &mut carve_later).expect("labelled");
        assert!(labelled.pending.is_none(), "{rig}, frame {frame}: `label` left masks to draw");
    }
    (report_later.deferred, report_later.lessons)
}

#[test]
fn label_masks_drawn_later_are_the_masks_drawn_at_once() {
    for (rig, appearance, tool) in [
        ("default", Appearance::classic(), ToolKind::Standard),
        ("random:1669", Appearance::random(1693), ToolKind::Pointed),
        // Shadows given back to the table beside the tool from frame set 28 on.
        ("random:557", Appearance::random(571), ToolKind::Standard),
    ] {
        let (deferred, lessons) = drawn_and_deferred(rig, appearance, tool, 30);
        // Some frame sets teach the colours (beside the labelling), the others wait.
        assert!(deferred > 0 && lessons > 0, "{rig}: {deferred} deferred, {lessons} lessons");
    }
}

/// The colours the first trusted frame set teaches beside the labelling are taken two frame sets
/// after it: the two frame sets labelled after it see none learned, the one after them does (the
/// built-in scene's look, and a random one on a random rig); settled at once, they are taken at
/// once; not learned beside it, they are taken before its labelling returns.
#[test]
fn the_colours_taught_beside_the_labelling_are_taken_two_frame_sets_later_or_when_settled() {
    for (rig, appearance, tool) in [
        ("default", Appearance::classic(), ToolKind::Standard),
        ("random:2851", Appearance::random(2857), ToolKind::Pointed),
    ] {
        let (_dir, ds, make) = recording(rig, appearance, tool, 12);
        let frames = ds.frame_numbers();
        let (mut labelling, mut carver) = (make(&ds), Carver::Cpu);
        labelling.learn_beside(true);
        let learned = |l: &Labelling| l.report().counters.learned;
        // The first frame set that hands a lesson over.
        let mut first = None;
        for (n, &frame) in frames.iter().enumerate() {
            let set = ds.read_frame_set(frame, false).expect("a frame set");
            labelling.label_with(&set, &mut carver, false).expect("labelled");
            if labelling.report().lessons == 1 {
                first = Some(n);
                break;
            }
        }
        let first = first.unwrap_or_else(|| panic!("{rig}: no frame set of {} taught the colours", frames.len()));
        assert_eq!(learned(&labelling), 0, "{rig}: taken at once");
        // Labelled on, the labelling takes them on the second frame set after; another, settled
        // right after the frame set that taught, takes them at once.
        for (k, &frame) in frames[first + 1..].iter().take(2).enumerate() {
            let set = ds.read_frame_set(frame, false).expect("a frame set");
            let labelled = labelling.label_with(&set, &mut carver, false).expect("labelled");
            assert_eq!(learned(&labelling), k as u64, "{rig}: frame {frame}, {} after the lesson", k + 1);
            assert_eq!(labelled.lesson_ms.is_some(), k == 1, "{rig}: frame {frame}");
        }
        let (mut settled, mut carver) = (make(&ds), Carver::Cpu);
        settled.learn_beside(true);
        for &frame in &frames[..=first] {
            let set = ds.read_frame_set(frame, false).expect("a frame set");
            settled.label_with(&set, &mut carver, false).expect("labelled");
        }
        settled.settle().expect("settled");
        assert_eq!(learned(&settled), 1, "{rig}: not taken when settled");
        assert!(!settled.learned().iter().all(|c| c.mean.is_none()), "{rig}: no colour learned");
        // Not learned beside the labelling, they are taken before the frame set's labelling
        // returns, and the report counts no wait.
        let (mut at_once, mut carver) = (make(&ds), Carver::Cpu);
        for &frame in &frames[..=first] {
            let set = ds.read_frame_set(frame, false).expect("a frame set");
            at_once.label_with(&set, &mut carver, false).expect("labelled");
        }
        assert_eq!(learned(&at_once), 1, "{rig}: not taken at once");
        assert_eq!(at_once.report().lessons_waited, 0, "{rig}");
    }
}
