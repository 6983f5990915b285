//! A frame set's label masks left to be drawn later, off the loop's path
//! ([`Labelling::defer_drawing`]), are the masks its labelling would have drawn at once, frame set
//! after frame set, on three rigs, looks and tools (the second and third seeded random); and
//! [`Labelling::label`] draws them at once whatever the deferral says.

use hullcut_dataset::Dataset;
use hullcut_hull::{HullParams, WorkingVolume};
use hullcut_pipeline::{Carver, LabelMethod, LabelSource, Labelling};
use hullcut_rig::RigPreset;
use hullcut_synth::{Appearance, Scene, SceneConfig, SceneKind, ToolKind, synthesize};

/// Labels the first `frames` frame sets of a resection both ways, every frame set's masks
/// wanted: drawn at once, and deferred where they teach nothing (then drawn from what the
/// labelling handed out). Returns how many were deferred and how many drawn at once.
fn drawn_and_deferred(rig: &str, appearance: Appearance, tool: ToolKind, frames: u64) -> (u64, u64) {
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
    let labelling = || Labelling::new(&ds, tool.as_ref(), hull.clone(), &[], LabelMethod::Both).expect("labelling");
    let (mut now, mut later) = (labelling(), labelling());
    later.defer_drawing(true);
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
    let (report_now, report_later) = (now.report(), later.report());
    // Drawn at once: the same frame sets both ways but for those deferred, and those whose
    // untrusted fit was drawn but the colours labelled (neither drawn nor deferred later).
    assert_eq!(report_now.deferred, 0);
    assert!(report_later.drawn + report_later.deferred <= report_now.drawn, "{rig}");
    // `label` draws at once whatever the deferral says (the first ten frame sets: all but the
    // first teach nothing, and some are deferred above).
    let mut eager = labelling();
    eager.defer_drawing(true);
    for frame in ds.frame_numbers().into_iter().take(10) {
        let set = ds.read_frame_set(frame, false).expect("a frame set");
        let labelled = eager.label(&set, &mut carve_later).expect("labelled");
        assert!(labelled.pending.is_none(), "{rig}, frame {frame}: `label` left masks to draw");
    }
    (report_later.deferred, report_later.drawn)
}

#[test]
fn label_masks_drawn_later_are_the_masks_drawn_at_once() {
    for (rig, appearance, tool) in [
        ("default", Appearance::classic(), ToolKind::Standard),
        ("random:1669", Appearance::random(1693), ToolKind::Pointed),
        // Shadows given back to the table beside the tool from frame set 28 on.
        ("random:557", Appearance::random(571), ToolKind::Standard),
    ] {
        let (deferred, drawn) = drawn_and_deferred(rig, appearance, tool, 30);
        // Some frame sets teach the colours (drawn at once), the others wait.
        assert!(deferred > 0 && drawn > 0, "{rig}: {deferred} deferred, {drawn} drawn at once");
    }
}
