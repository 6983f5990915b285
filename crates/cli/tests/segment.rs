//! `hullcut segment` on recordings a lab would bring: two rigs, several looks (one seeded random),
//! with and without empty-scene images, with the tool's geometry or only a few masked frames.
//! The floors are set a few percent below what was measured (scalpel IoU 0.809, 0.855, 0.900,
//! 0.801 for the four looks below; hand 0.991-0.996), so a regression fails while run-to-run
//! noise does not.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hullcut(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hullcut")).args(args).output().expect("hullcut runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn path(p: &Path) -> String {
    p.to_str().expect("utf-8").to_owned()
}

/// `hullcut synth` into `out` on `rig` with `look` and `tool`, without truth meshes, with `extra`
/// arguments.
fn synth_into(out: PathBuf, rig: &str, look: &str, tool: &str, extra: &[&str]) -> PathBuf {
    let out_arg = path(&out);
    let mut args = vec![
        "synth",
        "--out",
        &out_arg,
        "--rig",
        rig,
        "--appearance",
        look,
        "--tool",
        tool,
        "--no-truth-meshes",
        "--no-depth",
    ];
    args.extend_from_slice(extra);
    let o = hullcut(&args);
    assert!(o.status.success(), "synth {rig} {look} {tool}: {}", stderr(&o));
    out
}

/// A synthetic recording of `frames` frame sets at `fps` on `rig` with `look` and `tool`.
fn synth(dir: &Path, rig: &str, look: &str, tool: &str, frames: u32, fps: u32) -> PathBuf {
    let out = dir.join(format!("{rig}-{look}-{tool}").replace(':', "_"));
    let (frames, fps) = (frames.to_string(), fps.to_string());
    synth_into(out, rig, look, tool, &["--frames", &frames, "--fps", &fps, "--seed", "4"])
}

/// The first `frames` frame sets of the resection scene (its own trajectory, 30 fps, seed 1) on
/// `rig` with `look` and `tool`.
fn resection(dir: &Path, rig: &str, look: &str, tool: &str, frames: u32) -> PathBuf {
    synth_into(dir.join("resect"), rig, look, tool, &["--scene", "resect", "--frames", &frames.to_string()])
}

/// Runs `hullcut segment` with `extra` arguments and returns its report.
fn segment(dataset: &Path, extra: &[&str]) -> serde_json::Value {
    let report = dataset.with_extension("segment.json");
    let mut args = vec!["segment".to_owned(), "--dataset".into(), path(dataset), "--report".into(), path(&report)];
    args.extend(extra.iter().map(|s| (*s).to_owned()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = hullcut(&args);
    assert!(o.status.success(), "segment {}: {}", dataset.display(), stderr(&o));
    serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON")
}

/// Pooled IoU of `name` (`hand`, `scalpel`) or of the whole foreground (`foreground`).
fn iou(report: &serde_json::Value, name: &str) -> f64 {
    let acc = &report["accuracy"];
    let score = if name == "foreground" {
        &acc["foreground"]
    } else {
        acc["labels"].as_array().expect("labels").iter().find(|l| l["name"] == name).expect("label scored")
    };
    score["iou_pooled"].as_f64().unwrap_or_else(|| panic!("{name} not scored: {acc}"))
}

/// Segments one synthetic recording from its empty-scene images and the tool's geometry and checks
/// the floors: the whole foreground, the hand and the scalpel (pooled IoU against the truth);
/// returns the report.
fn labels_from_the_scene(rig: &str, look: &str, tool: &str, floors: [f64; 3]) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = 8;
    let ds = synth(dir.path(), rig, look, tool, frames, 10);
    let rrd = dir.path().join("segment.rrd");
    let r = segment(&ds, &["--rrd", &path(&rrd), "--rrd-every", "1"]);
    // Where the labels came from is in the recording for every frame set, the learned colours
    // from the first frame set that taught them on.
    let rows = hullcut_viz::rrd_timeline_rows(&rrd).expect("the recording reads back");
    let rows_of = |e: &str| rows.get(e).copied().unwrap_or(0);
    assert_eq!(rows_of("/labelling/source"), frames as usize, "{rows:?}");
    for e in [
        "/metrics/appearance/hand/colour",
        "/metrics/appearance/hand/pixels",
        "/metrics/appearance/scalpel/colour",
        "/metrics/appearance/scalpel/pixels",
        "/metrics/appearance/blade_as_hand",
    ] {
        assert!(rows_of(e) >= 1, "{e}: nothing logged in {rows:?}");
    }
    let l = &r["labelling"];
    let cams = r["views"].as_u64().expect("views") / u64::from(frames);
    assert_eq!(l["foreground"].as_array().expect("methods").len() as u64, cams, "{l}");
    assert!(l["foreground"].as_array().expect("methods").iter().all(|m| m == "background"), "{l}");
    assert_eq!(l["tool"], true);
    // Most frame sets are labelled by the trusted fit of the tool; colours are learned from them,
    // and the frame sets before the track was trusted are labelled again by those colours.
    let counters = &l["counters"];
    let n = |k: &str| counters[k].as_u64().unwrap_or_else(|| panic!("counter {k}: {counters}"));
    assert_eq!(n("geometry") + n("colour") + n("untrusted") + n("unknown"), u64::from(frames), "{counters}");
    assert!(2 * n("geometry") >= u64::from(frames), "{rig} {look}: {counters}");
    assert!(n("learned") >= 1, "{counters}");
    assert_eq!(n("relabelled"), n("untrusted") + n("unknown"), "{counters}");
    // At 10 fps the track's prediction looks 100 ms ahead and may be centimetres off: the hull is
    // carved at the leaf throughout, never coarser away from where the tool was predicted.
    assert_eq!(n("hull_fine_near_tool"), 0, "{counters}");
    let got = [iou(&r, "foreground"), iou(&r, "hand"), iou(&r, "scalpel")];
    for ((name, g), floor) in ["foreground", "hand", "scalpel"].iter().zip(got).zip(floors) {
        assert!(g >= floor, "{rig} {look} {tool}: {name} IoU {g:.4} < {floor} (all: {got:?})");
    }
    r
}

#[test]
fn segments_the_built_in_rig_with_the_classic_look() {
    let r = labels_from_the_scene("default", "classic", "standard", [0.98, 0.97, 0.78]);
    // Every frame set's fit is trusted (measured), its first too since the fortieth session's
    // hysteresis in the foreground test (refused before, it was labelled again by the colours the
    // later ones taught; every look's untrusted frame sets still are: `labels_from_the_scene`).
    let c = &r["labelling"]["counters"];
    assert_eq!(c["geometry"].as_u64(), Some(8), "{c}");
    assert!(c["weak_joined"].as_u64().is_some_and(|n| n > 0), "{c}");
    // The learned colours tell the steel blade from the blue glove: the fit gets hand hints.
    let share = c["tool_as_hand"].as_f64().expect("tool_as_hand");
    assert!(c["hand_hints"] == true && share < 0.05, "{c}");
}

#[test]
fn segments_the_built_in_rig_with_purple_gloves_and_the_pointed_tool() {
    let _ = labels_from_the_scene("default", "purple-nitrile", "pointed", [0.98, 0.97, 0.82]);
}

#[test]
fn segments_the_built_in_rig_with_a_seeded_random_look() {
    let _ = labels_from_the_scene("default", "random:11", "standard", [0.97, 0.97, 0.86]);
}

#[test]
fn a_shadow_kept_beside_the_blade_does_not_become_the_tool_by_its_colour() {
    // The first 40 frame sets of the resection on the random:89 rig (six cameras) in random:131: a
    // bare hand over a green mat, its dark shadow kept beside the blade where it nears the mat.
    // Measured: scalpel IoU 0.924, precision 0.976, hand 0.969; when the sharpening colours were
    // those learned from the labels sharpened wherever one class was the likelier (the shadow went
    // to the broader class, the tool's, and was learned as the tool) 0.840, 0.882 and 0.974; when
    // a colour also sharpened the labels wherever one class was the likelier 0.746, 0.778 and
    // 0.983.
    let dir = tempfile::tempdir().expect("tempdir");
    let r = segment(&resection(dir.path(), "random:89", "random:131", "standard", 40), &[]);
    let scalpel = r["accuracy"]["labels"].as_array().expect("labels").iter().find(|l| l["name"] == "scalpel");
    let precision = scalpel.and_then(|l| l["precision"].as_f64()).expect("scalpel precision");
    let got = [iou(&r, "hand"), iou(&r, "scalpel"), precision];
    assert!(got[0] >= 0.95 && got[1] >= 0.88 && got[2] >= 0.94, "hand IoU, scalpel IoU, precision {got:?}");
    // Both sets of colours are reported, each with both labels learned; the blade is told apart
    // from the rest of the tool in the colours that label, not in those that sharpen.
    for (key, blade) in [("appearance", true), ("sharpening_appearance", false)] {
        let learned = r["labelling"][key].as_array().unwrap_or_else(|| panic!("{key} reported"));
        let names: Vec<&str> = learned.iter().filter_map(|c| c["label"].as_str()).collect();
        assert_eq!(names, ["hand", "scalpel", "blade"], "{key}");
        let has = |k: usize| learned[k]["rgb"].is_array();
        assert!(has(0) && has(1) && has(2) == blade, "{key}: {learned:?}");
    }
}

#[test]
fn a_blade_the_learned_colours_take_for_the_hand_gets_no_hand_hints() {
    // The resection on the random:97 rig (seven cameras) in random:137: a bare hand holding the
    // pointed tool, a dark blue handle and a thin steel blade. The blade is too thin to learn
    // its colour from, and the steel is surely the hand's to the colours learned from the
    // handle and the hand. Measured on these 24 frame sets: the colours call 18% of the drawn
    // blade the hand's. On 150 frame sets the fit was trusted in 18 (scalpel IoU 0.599) with hand
    // hints throughout, the hints hiding the blade from it; in 102 (0.636) with this gate.
    let dir = tempfile::tempdir().expect("tempdir");
    let r = segment(&resection(dir.path(), "random:97", "random:137", "pointed", 24), &[]);
    let c = &r["labelling"]["counters"];
    let share = c["tool_as_hand"].as_f64().expect("tool_as_hand");
    assert!(c["hand_hints"] == false && share > 0.1, "{c}");
}

#[test]
fn the_hands_shadow_near_the_table_goes_back_to_the_background() {
    // The first 36 frame sets of the resection on the random:317 rig (eight cameras) in
    // random:331: a purple glove holding the pointed tool low over a grey checkered table, the
    // hand's dark shadow right under the blade's tip from frame set 27 on. The hand's hull over
    // its shadow kept the shadow as foreground, labelled the tool's beside the blade (scalpel
    // precision 0.761, IoU 0.696, foreground 0.984); asked of the other views, whose masks see
    // the table behind it darkened as much, it is the background: 0.963, 0.868 and 0.994 (0.926,
    // 0.836 and 0.993 while the shadow beside a fingertip's cell above 4 cm was not asked).
    let dir = tempfile::tempdir().expect("tempdir");
    let rrd = dir.path().join("segment.rrd");
    let r = segment(&resection(dir.path(), "random:317", "random:331", "pointed", 36), &["--rrd", &path(&rrd)]);
    let scalpel = r["accuracy"]["labels"].as_array().expect("labels").iter().find(|l| l["name"] == "scalpel");
    let precision = scalpel.and_then(|l| l["precision"].as_f64()).expect("scalpel precision");
    let foreground = r["accuracy"]["foreground"]["iou_pooled"].as_f64().expect("foreground IoU");
    let got = [iou(&r, "hand"), iou(&r, "scalpel"), precision, foreground];
    assert!(
        got[0] >= 0.98 && got[1] >= 0.83 && got[2] >= 0.94 && got[3] >= 0.99,
        "hand IoU, scalpel IoU and precision, foreground IoU {got:?}"
    );
    let on_table = r["labelling"]["counters"]["shadow_on_table"].as_u64().expect("shadow_on_table");
    assert!(on_table > 0, "{}", r["labelling"]["counters"]);
    // In the recording with each logged frame set's labels: every frame set has possible shadows
    // to ask of.
    let rows = hullcut_viz::rrd_timeline_rows(&rrd).expect("the recording reads back");
    let logged = rows.get("/labelling/source").copied().unwrap_or(0);
    assert!(logged > 0 && rows.get("/metrics/shadows/on_table") == Some(&logged), "{rows:?}");
}

#[test]
fn a_grey_blade_over_a_grey_table_on_four_cameras_is_found_by_the_colours_an_agreeing_fit_taught() {
    // The first 20 frame sets of the resection on the random:503 rig (four cameras) in random:509:
    // a bare light hand holding a dark blue handle, its grey blade over a grey table (a shadow to
    // the foreground test). The hand's hull is fat about the held tool with four views, and its
    // phantom cells hid the blade from two of them: right fits (under 1.5° and 1 mm) refused
    // frame set after frame set, no colours ever learned: 0 labelled by a trusted fit, scalpel
    // IoU 0.288, hand 0.870. Two agreeing fits running, the second's unoccluded pixels teach the
    // colours, and the blade's possible shadows of the tool's colour are no longer the hand's: 17
    // trusted, scalpel 0.900, hand 0.921.
    // The frame sets that taught are marked in the recording.
    let dir = tempfile::tempdir().expect("tempdir");
    let rrd = dir.path().join("segment.rrd");
    let ds = resection(dir.path(), "random:503", "random:509", "standard", 20);
    let r = segment(&ds, &["--rrd", &path(&rrd), "--rrd-every", "1"]);
    let c = &r["labelling"]["counters"];
    let trusted = c["geometry"].as_u64().expect("geometry");
    let taught = c["bootstrapped"].as_u64().expect("bootstrapped");
    assert!(trusted >= 15 && taught >= 1, "{c}");
    let rows = hullcut_viz::rrd_timeline_rows(&rrd).expect("the recording reads back");
    assert_eq!(rows.get("/metrics/appearance/taught").copied(), Some(taught as usize), "{rows:?}");
    let got = [iou(&r, "hand"), iou(&r, "scalpel")];
    assert!(got[0] >= 0.9 && got[1] >= 0.8, "hand and scalpel IoU {got:?}");
}

#[test]
fn a_steel_blade_over_brushed_steel_on_four_cameras_is_trusted_and_teaches_the_colours() {
    // The first 40 frame sets of the resection on the random:257 rig (four cameras) in random:263:
    // a blue glove holding a blue handle, a steel blade over brushed steel. Until the forty-first
    // session no fit was trusted here (six agreed with the silhouettes by chance, five of them
    // 66-263 mm off, and none might teach: taught by them, the colours took the table's grey for
    // the tool's). The blade is a possible shadow in patches and only darker between them; since
    // the forty-second session those pixels join the possible shadows they touch, the hull keeps
    // the blade, and 32 of the 40 are trusted (`hullcut run`: 26 of them within 5° and 5 mm),
    // the colours learned from them; no untrusted fit teaches. Since the blade's thickness is
    // fitted (2026-12-02) 23 (20 of them within 5° and 5 mm): the track is lost from frame set 24
    // on, where it used to come back after a fit 20° off.
    let dir = tempfile::tempdir().expect("tempdir");
    let r = segment(&resection(dir.path(), "random:257", "random:263", "standard", 40), &[]);
    let c = &r["labelling"]["counters"];
    assert!(c["geometry"].as_u64().expect("geometry") >= 20, "{c}");
    assert_eq!(c["bootstrapped"], 0, "{c}");
    assert!(c["learned"].as_u64().expect("learned") >= 1, "{c}");
    assert!(
        r["labelling"]["appearance"].as_array().is_some_and(|a| a.iter().any(|l| !l["rgb"].is_null())),
        "{}",
        r["labelling"]
    );
}

#[test]
fn segments_the_lab8_rig_with_a_bare_hand_and_the_pointed_tool() {
    let _ = labels_from_the_scene("lab8", "skin-medium", "pointed", [0.97, 0.97, 0.77]);
}

#[test]
fn without_empty_scene_images_the_background_is_the_recordings_median_and_shadows_stay_background() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Ten seconds at 3 fps: the hand moves over the table, so each pixel sees the empty scene in
    // most of the frames the median takes.
    let ds = synth(dir.path(), "default", "classic", "standard", 30, 3);
    let with = segment(&ds, &[]);
    for cam in std::fs::read_dir(&ds).expect("dataset").flatten().filter(|e| e.path().is_dir()) {
        for f in std::fs::read_dir(cam.path()).expect("camera").flatten() {
            if f.file_name().to_string_lossy().starts_with("background") {
                std::fs::remove_file(f.path()).expect("rm");
            }
        }
    }
    let without = segment(&ds, &[]);
    let methods = without["labelling"]["foreground"].as_array().expect("methods");
    assert!(!methods.is_empty() && methods.iter().all(|m| m == "median"), "{methods:?}");
    // The synthetic scene casts the hand's and the tool's shadows on the table: darker pixels of
    // unchanged chromaticity, settled by the hull (a shadow has no hull above the table), so the
    // foreground stays close to the truth with either background.
    for r in [&with, &without] {
        let c = &r["labelling"]["counters"];
        assert!(c["shadow_pixels"].as_u64().expect("shadow pixels") > 0, "{c}");
    }
    let (a, b) = (iou(&with, "foreground"), iou(&without, "foreground"));
    assert!(a >= 0.98, "foreground from empty-scene images: IoU {a:.4}");
    assert!(b >= 0.95, "foreground from the median: IoU {b:.4}");
    assert!(iou(&without, "hand") >= 0.93, "{}", without["accuracy"]);
}

#[test]
fn without_a_tool_the_colours_of_masked_frames_label_the_rest() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = synth(dir.path(), "default", "classic", "standard", 8, 10);
    std::fs::remove_file(ds.join("tool.json")).expect("rm tool.json");

    // Nothing tells the hand from the scalpel: a clear error that says what to provide.
    let o = hullcut(&["segment", "--dataset", &path(&ds)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("tool.json") && e.contains("--label-frames") && e.contains(&path(&ds)), "{e}");

    let r = segment(&ds, &["--label-frames", "0,1"]);
    let l = &r["labelling"];
    assert_eq!(l["tool"], false);
    assert_eq!(l["label_frames"], serde_json::json!([0, 1]));
    assert!(l["counters"]["colour"].as_u64().expect("colour") >= 6, "{l}");
    assert!(iou(&r, "hand") >= 0.93 && iou(&r, "scalpel") >= 0.5, "{}", r["accuracy"]);

    let o = hullcut(&["segment", "--dataset", &path(&ds), "--label-frames", "0,99"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("99"), "{}", stderr(&o));
}

#[test]
fn bench_segment_quick_compares_the_methods_per_recording() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "segment", "--quick", "--out", &path(dir.path())]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.path().join("segment.csv")).expect("csv");
    let mut reader = csv::Reader::from_reader(csv.as_bytes());
    let header: Vec<String> = reader.headers().expect("header").iter().map(str::to_owned).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column {name}"));
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("row")).collect();
    // Two recordings at --quick, three methods each and the third with the weak foreground.
    assert_eq!(rows.len(), 8, "{csv}");
    let f = |r: &csv::StringRecord, name: &str| r[col(name)].parse::<f64>().unwrap_or_else(|_| panic!("{name}: {csv}"));
    for recording in rows.iter().map(|r| r[col("recording")].to_owned()).collect::<std::collections::BTreeSet<_>>() {
        let row = |m: &str, weak: &str| {
            rows.iter()
                .find(|r| {
                    r[col("recording")] == recording && &r[col("method")] == m && &r[col("weak_foreground")] == weak
                })
                .expect("a row per method")
        };
        let (colour, geometry, both) = (row("colour", "false"), row("geometry", "false"), row("both", "false"));
        // The weak foreground confirmed adds to the foreground (the built-in rig's two looks: within
        // 0.01 of it, measured 0.992 against 0.996 on the classic look over 24 frame sets).
        let weak = row("both", "true");
        assert!(f(weak, "foreground_iou") > f(both, "foreground_iou") - 0.02, "{recording}: {csv}");
        // Colour alone never fits the tool; geometry alone never labels by colour.
        assert_eq!(f(colour, "by_geometry"), 0.0, "{csv}");
        assert_eq!(f(geometry, "by_colour"), 0.0, "{csv}");
        // The same foreground for all three: the labels differ, not the background model.
        assert_eq!(colour[col("foreground_iou")], both[col("foreground_iou")], "{csv}");
        // The colours learned from the trusted fits sharpen the tool's outline.
        assert!(f(both, "scalpel_iou") > f(geometry, "scalpel_iou"), "{recording}: {csv}");
        assert!(f(both, "ms_mean") > 0.0 && f(both, "ms_mean") >= f(both, "foreground_ms_mean"), "{csv}");
    }
    for name in ["segment_hand.png", "segment_scalpel.png"] {
        assert!(std::fs::read(dir.path().join(name)).expect("png").starts_with(b"\x89PNG"), "{name}");
    }
}

#[test]
fn one_kind_of_evidence_alone_needs_what_it_learns_from() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = synth(dir.path(), "default", "classic", "standard", 3, 10);
    let o = hullcut(&["segment", "--dataset", &path(&ds), "--labels", "colour"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--label-frames"), "{}", stderr(&o));
    std::fs::remove_file(ds.join("tool.json")).expect("rm tool.json");
    let o = hullcut(&["segment", "--dataset", &path(&ds), "--labels", "geometry"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("tool.json"), "{}", stderr(&o));
    let r = segment(&ds, &["--labels", "colour", "--label-frames", "0"]);
    assert_eq!(r["labelling"]["method"], "colour");
    assert_eq!(r["labelling"]["counters"]["colour"], 3, "{}", r["labelling"]);
}

/// Someone walks behind the table in one camera's view for five frame sets and leaves: those views
/// are counted as degraded, their foreground cut back to what the hull explains, no frame set is
/// lost, and the view is no longer degraded once the person has gone; a change that stays becomes
/// the view's usual.
#[test]
fn a_camera_whose_background_changes_is_degraded_and_counted_not_lost() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = synth(dir.path(), "default", "classic", "standard", 16, 10);
    // A red shirt across the top of the view, far behind the working volume: in cam2 for frames
    // 9-13; in cam4 from frame 8 to the end, where it stays long enough (half of the 16 frame
    // sets a view's usual is taken over) to become the new usual at frame 15.
    for (cam, frames) in [("cam2", 9..14), ("cam4", 8..16)] {
        for frame in frames {
            let file = ds.join(cam).join(format!("{frame:06}.png"));
            let mut image = image::open(&file).expect("frame").to_rgb8();
            for y in 10..130 {
                for x in 20..200 {
                    image.put_pixel(x, y, image::Rgb([190, 50, 45]));
                }
            }
            image.save(&file).expect("painted frame");
        }
    }
    let r = segment(&ds, &[]);
    let c = &r["labelling"]["counters"];
    assert_eq!(r["frame_sets"], 16, "{r}");
    assert_eq!(c["degraded_views"], 5 + 7, "{c}");
    // The shirt (21,600 pixels a view, 13 views) would bring the foreground's IoU down to about
    // 0.57; cut back where it was new, it stays close to the truth (measured 0.939: the last frame
    // set of cam4, where the shirt became the usual, counts against it).
    let fg = iou(&r, "foreground");
    assert!(fg >= 0.93, "foreground IoU {fg:.4}: {}", r["accuracy"]);
}

/// A pale glove whose shaded side matches a steel table in colour and shade (random:71 in
/// random:109, four cameras): the foreground test misses that side in every view. Confirmed by
/// the other views' hull, weak foreground fills it (measured 2026-11-28 on the first four frame
/// sets: foreground IoU 0.704 -> 0.820; over frame sets 40-49 0.813 -> 0.967; since the
/// forty-second session, whose weak dark pixels join the possible shadows they touch and so
/// find much of that side without it, 0.859 -> 0.881), and the report says it was asked for and
/// how many pixels it added.
#[test]
fn weak_foreground_the_other_views_confirm_fills_a_glove_of_the_tables_colour() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = resection(dir.path(), "random:71", "random:109", "standard", 4);
    let (plain_rrd, rrd) = (dir.path().join("plain.rrd"), dir.path().join("weak.rrd"));
    let plain = segment(&ds, &["--rrd", &path(&plain_rrd)]);
    let confirmed = segment(&ds, &["--confirm-weak-foreground", "--rrd", &path(&rrd)]);
    let (before, after) = (iou(&plain, "foreground"), iou(&confirmed, "foreground"));
    println!("foreground IoU {before:.4} -> {after:.4}");
    assert!(after > before + 0.015, "{before} -> {after}");
    let (l0, l1) = (&plain["labelling"], &confirmed["labelling"]);
    assert_eq!(
        (l0["confirm_weak_foreground"].as_bool(), l1["confirm_weak_foreground"].as_bool()),
        (Some(false), Some(true))
    );
    assert_eq!(l0["counters"]["weak_confirmed"].as_u64(), Some(0), "{l0}");
    assert!(l1["counters"]["weak_confirmed"].as_u64().expect("counted") > 1000, "{l1}");
    // Logged frame set by frame set with the flag, not at all without it.
    let rows = hullcut_viz::rrd_timeline_rows(&rrd).expect("the recording reads back");
    let logged = rows.get("/labelling/source").copied().unwrap_or(0);
    assert!(logged > 0 && rows.get("/metrics/foreground/weak_confirmed") == Some(&logged), "{rows:?}");
    let rows = hullcut_viz::rrd_timeline_rows(&plain_rrd).expect("the recording reads back");
    assert!(!rows.contains_key("/metrics/foreground/weak_confirmed"), "{rows:?}");
    // Run only once the tool's track is lost, which four frame sets cannot show (six refusals in
    // thirty), it never runs: the labels are the plain run's, and the report says why.
    let waiting = segment(&ds, &["--weak-foreground", "track-lost"]);
    let l2 = &waiting["labelling"];
    assert_eq!(
        (l1["weak_foreground_when"].as_str(), l2["weak_foreground_when"].as_str()),
        (Some("always"), Some("track_lost"))
    );
    assert!(l0["weak_foreground_when"].is_null() && l2["weak_foreground_from"].is_null(), "{l0} {l2}");
    assert_eq!(l2["counters"], l0["counters"], "{l2}");
    assert_eq!(iou(&waiting, "foreground"), before);
}
