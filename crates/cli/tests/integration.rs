//! End-to-end tests of the `hullcut` binary: calibration of real photos, reports, rig files, exit
//! codes and bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hullcut_rig::Rig;

const SAMPLES: &str = "/usr/share/doc/opencv-doc/examples/data";

fn hullcut(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hullcut")).args(args).output().expect("hullcut runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

mod common;
use common::read_csv;

/// `tools/stereo-sample.sh` lays out OpenCV's stereo photos as a calibration tree.
fn stereo_tree(dir: &Path) -> PathBuf {
    assert!(Path::new(SAMPLES).join("left01.jpg").exists(), "opencv-doc photos missing: run tools/setup.sh");
    let out = dir.join("stereo");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../tools/stereo-sample.sh");
    let status = Command::new("bash").arg(script).arg(&out).status().expect("bash");
    assert!(status.success());
    out
}

#[test]
fn calibrate_sample_photos_end_to_end() {
    let dir = tempfile::tempdir().expect("tempdir");
    let images = stereo_tree(dir.path());
    let (rig, report, rrd) = (dir.path().join("rig.yaml"), dir.path().join("report.json"), dir.path().join("cal.rrd"));
    let o = hullcut(&[
        "calibrate",
        "--images",
        images.to_str().expect("utf-8"),
        "--pattern",
        "9x6",
        "--square",
        "0.025",
        "--out",
        rig.to_str().expect("utf-8"),
        "--report",
        report.to_str().expect("utf-8"),
        "--rrd",
        rrd.to_str().expect("utf-8"),
        "--world-board",
        "01.jpg",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("pair left-right"), "{stdout}");

    let rig = Rig::load(&rig).expect("rig.yaml loads");
    assert_eq!(rig.len(), 2);
    assert_eq!(rig.world_frame.to_key(), "board:01.jpg");
    // World frame from the board: both cameras look down at it from positive z.
    for c in &rig.cameras {
        assert!(c.centre().z > 0.1, "{} at {:?}", c.name, c.centre());
        assert!(c.viewing_direction().z < 0.0);
    }

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(json["schema_version"], 1);
    assert_eq!(json["kind"], "calibration");
    assert!(json["git_hash"].is_string() && json["hullcut_version"].is_string());
    assert_eq!(json["cameras"].as_array().expect("cameras").len(), 2);
    assert_eq!(json["images"].as_array().expect("images").len(), 26);
    for key in ["count", "mean_ms", "p50_ms", "p95_ms", "max_ms"] {
        assert!(json["timings"]["detect"][key].is_number(), "timings.detect.{key}");
    }
    let rms = json["rms_px"].as_f64().expect("rms");
    assert!(rms > 0.05 && rms < 1.0, "RMS {rms} px");
    assert!(json["pairs"][0]["baseline_m"].as_f64().expect("baseline") > 0.0);

    // The recording exists and holds data (the viewer's own check is `rerun rrd verify`).
    assert!(std::fs::metadata(&rrd).expect("rrd").len() > 100_000);

    // `rig show` prints a table of the same rig.
    let o = hullcut(&["rig", "show", dir.path().join("rig.yaml").to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("left") && table.contains("right") && table.contains("board:01.jpg"), "{table}");
}

#[test]
fn usage_errors_exit_2_and_failures_exit_1() {
    let o = hullcut(&["calibrate", "--images", "x"]);
    assert_eq!(o.status.code(), Some(2), "missing required flags is bad usage");
    let o = hullcut(&["no-such-command"]);
    assert_eq!(o.status.code(), Some(2));
    let o = hullcut(&[
        "calibrate",
        "--images",
        "/nonexistent/dir",
        "--pattern",
        "9x6",
        "--square",
        "0.02",
        "--out",
        "/tmp/x.yaml",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("/nonexistent/dir"), "{}", stderr(&o));
    // A value outside what a flag takes is bad usage too, and the message names the flag.
    let o =
        hullcut(&["calibrate", "--images", "/tmp", "--pattern", "9by6", "--square", "0.02", "--out", "/tmp/x.yaml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--pattern"), "{}", stderr(&o));
    let o = hullcut(&["calibrate", "--images", "/tmp", "--pattern", "9x6", "--square", "0", "--out", "/tmp/x.yaml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--square"), "{}", stderr(&o));
}

/// Flags that take one of a fixed set of values list them in `--help` and when refusing another
/// (exit 2, bad usage); numbers outside a flag's range are bad usage too.
#[test]
fn a_value_a_flag_does_not_take_is_bad_usage_and_the_values_are_listed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("x");
    let out = out.to_str().expect("utf-8");
    let o = hullcut(&["synth", "--help"]);
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(help.contains("resect") && help.contains("cut, static, hard, resect"), "{help}");
    let o = hullcut(&["synth", "--out", out, "--scene", "bogus"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("cut, static, hard, resect"), "{}", stderr(&o));
    let reconstruct = ["reconstruct", "--dataset", CUT_SMALL, "--out", out];
    let run = ["run", "--dataset", CUT_SMALL];
    for command in [&reconstruct[..], &run[..]] {
        let o = hullcut(&[command, &["--masks", "bogus"]].concat());
        assert_eq!(o.status.code(), Some(2), "{command:?}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains("bogus") && e.contains("auto, files, segment"), "{command:?}: {e}");
        // The short help lists the values (the long one may describe each).
        let o = hullcut(&[command[0], "-h"]);
        assert!(String::from_utf8_lossy(&o.stdout).contains("auto, files, segment"), "{} -h", command[0]);
    }
    for (args, flag) in [
        (&["run", "--dataset", CUT_SMALL, "--queue", "0"][..], "--queue"),
        (&["run", "--dataset", CUT_SMALL, "--repeat", "0"][..], "--repeat"),
        (&["synth", "--out", out, "--frames", "0"][..], "--frames"),
        (&["synth", "--out", out, "--fps=-30"][..], "--fps"),
        (&["segment", "--dataset", CUT_SMALL, "--rrd-every", "0"][..], "--rrd-every"),
        (&["rig", "default", "--out", out, "--rig", "lab9"][..], "--rig"),
        (&["import-videos", "--rig", "r.yaml", "--out", out, "--video", "cam0"][..], "--video"),
    ] {
        let o = hullcut(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(flag), "{args:?}: {}", stderr(&o));
    }
    assert!(!dir.path().join("x").exists(), "nothing written on bad usage");
}

/// A value given whole on the command line (here 100,000 characters) is cut where an error
/// repeats it, saying how much was left out.
#[test]
fn a_long_bad_value_is_not_echoed_whole() {
    let long = format!("/nonexistent/{}", "r".repeat(100_000));
    let o = hullcut(&["rig", "show", &long]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.len() < 2_000 && e.starts_with("error: /nonexistent/rrr") && e.contains("more chars)"), "{e:.2000}");
    let o = hullcut(&["synth", "--out", "/nonexistent/x", "--scene", &long]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.len() < 2_000 && e.contains("more chars)") && e.contains("cut, static, hard, resect"), "{e:.2000}");
}

/// `hullcut --version` gives the git commit that reports carry.
#[test]
fn the_version_names_the_commit_reports_carry() {
    let dir = tempfile::tempdir().expect("tempdir");
    let report = dir.path().join("sim.json");
    let scenario = scenario("hex-stretch.toml");
    let o = hullcut(&["sim", "--scenario", &scenario, "--report", report.to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    let version = json["hullcut_version"].as_str().expect("version");
    let hash = json["git_hash"].as_str().expect("hash");
    assert!(!hash.is_empty());
    let o = hullcut(&["--version"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout), format!("hullcut {version} ({hash})\n"));
}

#[test]
fn broken_rig_file_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("rig.yaml");
    let o = hullcut(&["rig", "default", "--out", path.to_str().expect("utf-8")]);
    assert!(o.status.success());
    let text = std::fs::read_to_string(&path).expect("read");
    // Break camera 3's rotation matrix: drop one value.
    let broken = text.replacen(
        "rotation_matrix: !!opencv-matrix\n      rows: 3\n      cols: 3",
        "rotation_matrix: !!opencv-matrix\n      rows: 3\n      cols: 2",
        4,
    );
    std::fs::write(&path, broken).expect("write");
    let o = hullcut(&["rig", "show", path.to_str().expect("utf-8")]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("rig.yaml") && e.contains("camera_0.rotation_matrix") && e.contains("3x2"), "{e}");
}

#[test]
fn help_names_every_output_file() {
    let o = hullcut(&["calibrate", "--help"]);
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    for flag in ["--images", "--pattern", "--square", "--out", "--report", "--rrd", "--world-board"] {
        assert!(help.contains(flag), "calibrate --help lacks {flag}");
    }
    assert!(help.contains("Writes:"), "{help}");
}

fn scenario(name: &str) -> String {
    format!("{}/../../examples/scenarios/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn sim_single_hexahedron_report_matches_closed_form() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (report, rrd) = (dir.path().join("sim.json"), dir.path().join("sim.rrd"));
    let o = hullcut(&[
        "sim",
        "--scenario",
        &scenario("hex-stretch.toml"),
        "--report",
        report.to_str().expect("utf-8"),
        "--rrd",
        rrd.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(json["kind"], "simulation");
    assert_eq!(json["stable"], true);
    // P_xx * area for F = diag(1.3, 1, 1), λ = μ = 20 kPa (see the scenario's header).
    let expected = 1.3 * (20_000.0 * (1.0 - 1.0 / 1.69) + 20_000.0 * 1.3 * 0.3 / 1.69) * 0.01;
    let rx = json["reactions"][0]["force_n"][0].as_f64().expect("reaction");
    assert!((rx - expected).abs() < 1e-4 * expected, "{rx} vs {expected}");
    assert!(json["stability"]["dt_critical_s"].as_f64().expect("dt") > 0.0);
    assert!(json["timings"]["step"]["p95_ms"].is_number());
    assert!(std::fs::metadata(&rrd).expect("rrd").len() > 1000);
}

/// Runs `hullcut` with the GPU backend: `None` (the test skips, saying so) when this machine has
/// no adapter and `CI` is not set; CI has lavapipe, so there a missing adapter fails the test.
fn hullcut_on_gpu(args: &[&str]) -> Option<Output> {
    let o = hullcut(args);
    if !o.status.success() && stderr(&o).contains("no GPU adapter") && std::env::var_os("CI").is_none() {
        eprintln!("skipping a GPU test: {}", stderr(&o));
        return None;
    }
    Some(o)
}

#[test]
fn sim_on_the_gpu_backend_matches_the_closed_form_and_reports_its_batches() {
    let dir = tempfile::tempdir().expect("tempdir");
    let report = dir.path().join("sim.json");
    let report_arg = report.to_str().expect("utf-8");
    let hex = scenario("hex-stretch.toml");
    let Some(o) = hullcut_on_gpu(&["sim", "--scenario", &hex, "--backend", "gpu", "--report", report_arg]) else {
        return;
    };
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(json["backend"], "gpu");
    assert_eq!(json["stable"], true);
    let expected = 1.3 * (20_000.0 * (1.0 - 1.0 / 1.69) + 20_000.0 * 1.3 * 0.3 / 1.69) * 0.01;
    let rx = json["reactions"][0]["force_n"][0].as_f64().expect("reaction");
    assert!((rx - expected).abs() < 1e-3 * expected, "{rx} vs {expected}");
    let gpu = &json["gpu"];
    assert!(gpu["adapter"].as_str().is_some_and(|a| !a.is_empty()), "{gpu}");
    assert_eq!(gpu["steps"].as_u64(), json["steps"].as_u64(), "every step ran on the GPU: {gpu}");
    assert_eq!(gpu["cpu_batches"], 0, "{gpu}");
    assert!(gpu["device_ms"].is_null() || gpu["device_ms"].as_f64().is_some_and(|ms| ms > 0.0), "{gpu}");
    // The hybrid (the seed's liver press, TLED ratio 0.4) on both backends: the probe agrees to
    // a thousandth of its displacement.
    let mut probes = Vec::new();
    for backend in ["cpu", "gpu"] {
        let o = hullcut(&[
            "sim",
            "--scenario",
            &scenario("liver-press.toml"),
            "--backend",
            backend,
            "--report",
            report_arg,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
        assert!(json["hybrid"].is_object(), "a hybrid: {}", json["hybrid"]);
        let d: Vec<f64> = json["probes"][0]["displacement_m"]
            .as_array()
            .expect("probe")
            .iter()
            .map(|x| x.as_f64().expect("number"))
            .collect();
        probes.push(d);
    }
    let scale = probes[0].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = probes[0].iter().zip(&probes[1]).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(scale > 1e-5 && worst <= 1e-3 * scale, "cpu {:?} gpu {:?}", probes[0], probes[1]);
}

#[test]
fn sim_bad_scenarios_name_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.toml");
    let base = std::fs::read_to_string(scenario("hex-stretch.toml")).expect("read");
    for (text, needle) in [
        (base.replace("density = 1000.0", "density = 1000.0\nyoung = 5.0"), "young"),
        (base.replace("mu = 20000.0", "mu = -20000.0"), "material.mu"),
        (base.replace("displace = [0.03, 0.0, 0.0]", "displace = [0.03, 0.0, 0.0]\nfix = [\"x\"]"), "boundary[1]"),
        (format!("{base}\n[[boundary]]\nfaces = [\"x+\"]\nfix = [\"x\"]\n"), "contradicts boundary[1]"),
    ] {
        std::fs::write(&path, text).expect("write");
        let o = hullcut(&["sim", "--scenario", path.to_str().expect("utf-8")]);
        assert_eq!(o.status.code(), Some(1), "{needle}");
        assert!(stderr(&o).contains(needle), "expected `{needle}` in: {}", stderr(&o));
    }
}

#[test]
fn sim_cuts_the_organ_with_a_moving_blade_and_reports_the_pieces() {
    // The built-in organ's lobe tip cut off by a blade drawn across it (examples/scenarios):
    // all TLED, then with a far field that sleeps; both end in two pieces of the same volumes.
    let dir = tempfile::tempdir().expect("tempdir");
    let base = std::fs::read_to_string(scenario("organ-resect.toml")).expect("read");
    let frozen = base.replace("[cut.table]", "operational_radius = 0.03\nfar_field = \"frozen\"\n\n[cut.table]");
    assert_ne!(frozen, base);
    let mut volumes = Vec::new();
    for (name, text) in [("tled", &base), ("frozen", &frozen)] {
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).expect("write");
        let (report, rrd) = (dir.path().join(format!("{name}.json")), dir.path().join(format!("{name}.rrd")));
        let o = hullcut(&[
            "sim",
            "--scenario",
            path.to_str().expect("utf-8"),
            "--report",
            report.to_str().expect("utf-8"),
            "--rrd",
            rrd.to_str().expect("utf-8"),
        ]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).expect("report")).expect("json");
        assert_eq!(r["kind"], "cut-simulation");
        assert_eq!(r["far_field"], name);
        assert_eq!(r["stable"], true, "{name}");
        assert_eq!(r["frames"], 108, "1.8 s at 60 Hz");
        let simulated = r["simulated_time_s"].as_f64().expect("time");
        assert!((simulated - 1.8).abs() < 0.002, "{name}: the body keeps the blade's clock: {simulated}");
        assert_eq!(r["cutting"]["pieces"], 2, "{name}: the lobe's tip is cut off");
        assert!(r["cutting"]["edges_crossed"].as_u64().expect("edges") > 30, "{name}");
        // The blade moves from 0.3 s to 1.3 s: 60 frames, one more for the sweep that reaches back.
        let cut_frames = r["cutting"]["cut_frames"].as_u64().expect("frames");
        assert!((60..=61).contains(&cut_frames), "{name}: {cut_frames}");
        let cells = r["lattice"]["cells"].as_f64().expect("cells");
        let awake = r["tled_cells_mean"].as_f64().expect("mean");
        if name == "frozen" {
            assert!(awake < 0.8 * cells, "the far field sleeps: {awake} of {cells}");
        } else {
            assert!(awake >= cells, "{awake} of {cells}");
        }
        let mut v: Vec<f64> =
            r["pieces"].as_array().expect("pieces").iter().map(|p| p["volume_m3"].as_f64().expect("volume")).collect();
        v.sort_by(f64::total_cmp);
        volumes.push(v);
        let entities = hullcut_viz::rrd_entities(&rrd).expect("the recording reads back");
        for e in ["/world/tissue/surface", "/world/tissue/cut", "/world/tool/edge"] {
            assert!(entities.contains(e), "{name}: {e} in {entities:?}");
        }
    }
    // The same cut through the same lattice, the body where it cut a little apart: the same
    // pieces within 1% (measured 0.4%).
    for (a, b) in volumes[0].iter().zip(&volumes[1]) {
        assert!((a - b).abs() < 1e-2 * b, "{volumes:?}");
    }
    // The small piece is the lobe's tip beyond x = 55 mm: a few percent of the organ.
    assert!(volumes[0][0] > 0.01 * volumes[0][1] && volumes[0][0] < 0.1 * volumes[0][1], "{volumes:?}");
}

#[test]
fn sim_cut_scenarios_refuse_what_cutting_does_not_do_naming_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.toml");
    let base = std::fs::read_to_string(scenario("organ-resect.toml")).expect("read");
    for (text, needle) in [
        (base.replace("duration = 1.8", "duration = 1.8\ndt = 1e-4"), "run.dt"),
        (base.replace("{ time = 1.3,", "{ time = 0.2,"), "cut.path[1].time"),
        (base.replace("[cut.table]", "far_field = \"frozen\"\n[cut.table]"), "cut.far_field"),
        (base.replace("[cut.table]", "far_field = \"asleep\"\n[cut.table]"), "cut.far_field"),
        (base.replace("edge = [[0.055, -0.05, -0.002], ", "edge = ["), "cut.edge"),
        (base.replace("friction = 0.5", "friction = -1.0"), "cut.table.friction"),
        (format!("{base}\n[[boundary]]\nfaces = [\"z-\"]\nfix = [\"z\"]\n"), "boundary[0]"),
        (format!("{base}\n[[load]]\nbox = {{ min = [0, 0, 0], max = [1, 1, 1] }}\nforce = [0, 0, 1]\n"), "load"),
        (base.replace("offset = [0.0, 0.11, 0.0]", "offset = [0.0, nan, 0.0]"), "cut.path[1].offset"),
    ] {
        assert_ne!(text, base, "{needle}");
        std::fs::write(&path, text).expect("write");
        let o = hullcut(&["sim", "--scenario", path.to_str().expect("utf-8")]);
        assert_eq!(o.status.code(), Some(1), "{needle}");
        assert!(stderr(&o).contains(needle), "expected `{needle}` in: {}", stderr(&o));
    }
}

#[test]
fn bench_tissue_quick_compares_the_far_fields_with_all_tled() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "tissue", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    for chart in ["tissue_cost.png", "tissue_error_near.png", "tissue_error_all.png", "tissue_speed.png"] {
        assert!(dir.path().join(chart).metadata().expect(chart).len() > 1000, "{chart}");
    }
    let (header, rows) = read_csv(&dir.path().join("tissue.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).expect(name);
    let (model, near, all, pieces, awake) =
        (col("model"), col("rms_near_mm_worst"), col("rms_all_mm_worst"), col("pieces"), col("tled_cells_mean"));
    let num = |r: &Vec<String>, c: usize| r[c].parse::<f64>().expect("number");
    // Two organ sizes at a surgeon's pace, four models each; then the faster stroke.
    assert_eq!(rows.iter().filter(|r| r[col("blade_m_s")] == "0.11").count(), 8);
    for r in &rows {
        assert_eq!(r[pieces], "2", "every model cuts the lobe's tip off: {r:?}");
        // The seed paper's hybrid (its FLSM settings, off by 20-30 mm everywhere: the baseline of
        // what not to do, not a model `hullcut run` offers) may diverge at a copy of a few
        // percent of a cell: on the paper-size organ it does since holes of one node in a cut are
        // closed. Any other failure, or any failure of another model, fails the test.
        let failure = &r[col("failure")];
        let seed_diverged = r[model] == "seed" && failure.contains("diverged");
        assert!(failure.is_empty() || seed_diverged, "{r:?}");
        match r[model].as_str() {
            "tled" => assert_eq!((num(r, near), num(r, all)), (0.0, 0.0), "the reference"),
            // The issue's bounds for the far field that sleeps, on these small organs.
            "frozen" => assert!(num(r, near) < 0.5 && num(r, all) < 2.0, "{r:?}"),
            _ => assert!(num(r, near) > 0.0, "{r:?}"),
        }
    }
    for organ in ["8 mm", "paper-size"] {
        let of = |m: &str| rows.iter().find(|r| r[0] == organ && r[model] == m).map(|r| num(r, awake)).expect(m);
        assert!(of("frozen") < 0.5 * of("tled"), "{organ}: the far field sleeps");
    }
}

#[test]
fn bench_sim_quick_writes_tables_and_charts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "sim", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Every table reads back with the csv crate, every row as wide as its header (a GPU's name
    // holds commas: it is quoted).
    for name in ["scaling", "ratio", "stability", "kernels", "collision", "backends"] {
        let (_, rows) = read_csv(&dir.path().join(format!("{name}.csv")));
        assert!(rows.len() >= 2, "{name}.csv: {rows:?}");
    }
    for name in ["scaling", "ratio", "stability"] {
        let png = std::fs::read(dir.path().join(format!("{name}.png"))).expect("png");
        assert!(png.starts_with(b"\x89PNG"), "{name}.png is a PNG");
    }
    // The all-TLED reference has zero error against itself, and at ratio 0.4 FLSM matched to the
    // material is closer to it than the seed's FLSM settings.
    let (_, rows) = read_csv(&dir.path().join("ratio.csv"));
    assert!(rows[0][..2] == ["1", "matched"] && rows[0][4] == "0.000000", "{:?}", rows[0]);
    let rms = |settings: &str| -> f64 {
        let row = rows.iter().find(|r| r[0] == "0.4" && r[1] == settings).expect("a ratio 0.4 row");
        row[4].parse().expect("rms")
    };
    assert!(rms("matched") < rms("seed"), "{rows:?}");
    // Kernel throughput on one and two threads.
    let (_, kernels) = read_csv(&dir.path().join("kernels.csv"));
    for kernel in ["tled_internal_forces", "tled_step", "flsm_step"] {
        for threads in ["1", "2"] {
            let row = kernels
                .iter()
                .find(|r| r[0] == kernel && r[1] == threads)
                .unwrap_or_else(|| panic!("{kernel} on {threads} threads: {kernels:?}"));
            assert!(row[5].parse::<f64>().expect("rate") > 0.0, "{row:?}");
        }
    }
    // CPU against GPU: both lines where there is an adapter (always in CI: lavapipe).
    let (header, rows) = read_csv(&dir.path().join("backends.csv"));
    assert_eq!(header[1], "device");
    let on = |b: &str| rows.iter().filter(|r| r[0] == b).count();
    assert_eq!(on("cpu"), 2, "{rows:?}");
    if std::env::var_os("CI").is_some() || on("gpu") > 0 {
        assert_eq!(on("gpu"), 2, "{rows:?}");
    }
    assert!(rows.iter().all(|r| r[6].parse::<f64>().expect("rate") > 0.0), "{rows:?}");
    assert!(std::fs::read(dir.path().join("backends.png")).expect("png").starts_with(b"\x89PNG"));
}

#[test]
fn bench_backends_quick_writes_the_cpu_and_gpu_lines_alone() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "backends", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, rows) = read_csv(&dir.path().join("backends.csv"));
    let on = |b: &str| rows.iter().filter(|r| r[0] == b).count();
    assert_eq!(on("cpu"), 2, "{rows:?}");
    if std::env::var_os("CI").is_some() || on("gpu") > 0 {
        assert_eq!(on("gpu"), 2, "{rows:?}");
    }
    // Only the backends part of `bench sim`.
    assert!(!dir.path().join("scaling.csv").exists());
}

#[test]
fn bench_loop_quick_measures_speed_beside_the_blade_and_the_tissue() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "loop", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (header, rows) = read_csv(&dir.path().join("loop.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap_or_else(|| panic!("{name} in {header:?}"));
    // Mask files at two leaves, and segmenting: every frame set through, every one timed.
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert_eq!(rows.iter().filter(|r| r[col("masks")] == "segment").count(), 1, "{rows:?}");
    for r in &rows {
        let f = |name: &str| r[col(name)].parse::<f64>().unwrap_or_else(|_| panic!("{name} in {r:?}"));
        assert_eq!(r[col("frames")], "12", "{r:?}");
        assert!(f("fps") > 0.0 && f("latency_p95_ms") >= f("latency_p50_ms"), "{r:?}");
        assert!(f("carve_ms") > 0.0 && f("deform_ms") > 0.0, "{r:?}");
        // Truth masks: the blade fitted within a millimetre where it was trusted.
        assert!(f("trusted") >= 10.0 && f("tip_mm_mean") < 1.0, "{r:?}");
    }
    for png in ["loop_speed.png", "loop_accuracy.png"] {
        assert!(std::fs::read(dir.path().join(png)).expect("png").starts_with(b"\x89PNG"), "{png}");
    }
}

#[test]
fn bench_cut_quick_runs_one_stress_case_of_each_family_and_charts_them() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "cut", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (header, rows) = read_csv(&dir.path().join("cut_stress.csv"));
    let column = |name: &str| header.iter().position(|h| h == name).expect(name);
    let families: std::collections::BTreeSet<&str> = rows.iter().map(|r| r[column("family")].as_str()).collect();
    assert_eq!(rows.len(), families.len(), "one case per family: {rows:?}");
    assert!(families.len() >= 10, "{families:?}");
    for row in &rows {
        assert_eq!(row[column("separated")], "true", "{row:?}");
        assert_eq!(row[column("stable")], "true", "{row:?}");
        assert!(row[column("frame_ms_mean")].parse::<f64>().expect("ms") > 0.0, "{row:?}");
    }
    for name in ["cut_stress_cost", "cut_stress_pieces"] {
        let png = std::fs::read(dir.path().join(format!("{name}.png"))).expect("png");
        assert!(png.starts_with(b"\x89PNG"), "{name}.png is a PNG");
    }
}

/// The benchmark tables committed under docs/bench read back with the csv crate, every row as
/// wide as its header.
#[test]
fn the_committed_benchmark_tables_read_back_as_csv() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/bench"));
    let tables: Vec<PathBuf> = walk(root).into_iter().filter(|p| p.extension().is_some_and(|e| e == "csv")).collect();
    assert!(tables.len() >= 10, "{tables:?}");
    for table in tables {
        let (header, rows) = read_csv(&table);
        assert!(header.len() >= 2 && !rows.is_empty(), "{}", table.display());
    }
}

#[test]
fn bench_hull_quick_compares_octree_and_dense_grid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "hull", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.path().join("hull.csv")).expect("csv");
    let rows: Vec<Vec<String>> = csv::Reader::from_reader(csv.as_bytes())
        .records()
        .map(|r| r.expect("a CSV row").iter().map(str::to_owned).collect())
        .collect();
    // rig, method, volume, leaf_mm, carve_ms, cells_kept, hand IoU, scalpel IoU: two rigs (the
    // default and lab8) at two leaves.
    let octree = |rig: &str, leaf: &str| {
        rows.iter().find(|r| r[0] == rig && r[1] == "octree" && r[2] == "tight" && r[3] == leaf).expect("octree row")
    };
    assert_eq!(rows.iter().filter(|r| r[1] == "octree" && r[2] == "tight").count(), 4, "{csv}");
    // Where both ran, the octree gives the dense grid's occupancy (the same IoU with the exact
    // hull; it keeps a uniform block as one cell, so it keeps fewer cells).
    let dense: Vec<_> = rows.iter().filter(|r| r[1] == "dense grid").collect();
    assert!(!dense.is_empty(), "{csv}");
    for d in dense {
        let o = octree(&d[0], &d[3]);
        assert_eq!(o[6..], d[6..], "{o:?} vs {d:?}");
        let cells = |r: &Vec<String>| r[5].parse::<u64>().expect("cells");
        assert!(cells(o) <= cells(d), "{o:?} vs {d:?}");
    }
    // The GPU's octree (where there is an adapter; always in CI) keeps the same cells, hence the
    // same IoU.
    let gpu_rows: Vec<_> = rows.iter().filter(|r| r[1] == "octree on the GPU").collect();
    if std::env::var_os("CI").is_some() || !gpu_rows.is_empty() {
        assert_eq!(gpu_rows.len(), 4, "{csv}");
    }
    for gpu in gpu_rows {
        let o = octree(&gpu[0], &gpu[3]);
        assert_eq!((&o[5], &o[6..]), (&gpu[5], &gpu[6..]), "{gpu:?}");
    }
    // Trimming the slivers brings the hand closer to the exact hull.
    for t in rows.iter().filter(|r| r[1] == "octree, slivers trimmed") {
        let o = octree(&t[0], &t[3]);
        let iou = |r: &Vec<String>| r[6].parse::<f64>().expect("hand IoU");
        assert!(iou(t) > iou(o), "{t:?} vs {o:?}");
    }
    // Carving the blade's leaves a level finer brings the scalpel closer to the exact hull on
    // every rig and leaf.
    let refined: Vec<_> = rows.iter().filter(|r| r[1] == "octree, blade refined a level").collect();
    assert_eq!(refined.len(), 4, "{csv}");
    for b in refined {
        let o = octree(&b[0], &b[3]);
        let iou = |r: &Vec<String>| r[7].parse::<f64>().expect("scalpel IoU");
        assert!(iou(b) > iou(o), "{b:?} vs {o:?}");
    }
    for name in [
        "hull_speed.png",
        "hull_accuracy.png",
        "hull_blade.png",
        "hull_robustness_noise.png",
        "hull_robustness_cameras.png",
    ] {
        assert!(std::fs::read(dir.path().join(name)).expect("png").starts_with(b"\x89PNG"), "{name}");
    }
    // Robustness: the clean classic hull against itself is 1; noise and fewer cameras only lower it.
    let (_, rows) = read_csv(&dir.path().join("hull_robustness.csv"));
    let iou = |experiment: &str, votes: &str| -> Vec<f64> {
        rows.iter().filter(|r| r[0] == experiment && r[1] == votes).map(|r| r[6].parse().expect("iou")).collect()
    };
    let noise = iou("noise", "1");
    assert_eq!(noise.len(), 5, "{rows:?}");
    assert_eq!(noise[0], 1.0, "{rows:?}");
    assert!(noise.windows(2).all(|w| w[1] <= w[0]), "{noise:?}");
    let cameras = iou("cameras", "1");
    assert_eq!((cameras.len(), cameras[4]), (5, 1.0), "{rows:?}");
    assert!(cameras.windows(2).all(|w| w[1] >= w[0]), "{cameras:?}");
}

#[test]
fn synth_writes_a_dataset_a_report_and_a_recording() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out, report, rrd) = (dir.path().join("ds"), dir.path().join("synth.json"), dir.path().join("synth.rrd"));
    let rig = concat!(env!("CARGO_MANIFEST_DIR"), "/../../calibration/default-rig-320x240.yaml");
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let args = ["synth", "--out", &path(&out), "--frames", "4", "--scene", "hard", "--seed", "7", "--rig", rig];
    let o = hullcut(&[&args[..], &["--report", &path(&report), "--rrd", &path(&rrd)]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    assert_eq!(r["schema_version"], 1);
    assert_eq!(r["kind"], "synth");
    assert_eq!(r["scene"], "hard");
    assert_eq!(r["views"].as_u64().expect("views") + r["dropped_views"].as_u64().expect("dropped"), 24);
    assert!(r["mean_scalpel_pixels_per_view"].as_f64().expect("scalpel px") > 10.0);
    assert!(std::fs::metadata(&rrd).expect("rrd written").len() > 10_000);
    for file in ["dataset.toml", "rig.yaml", "frames.csv", "tool.json", "tool.ply", "truth/poses.jsonl"] {
        assert!(out.join(file).exists(), "{file}");
    }

    // The output exists now: refused without --force (naming it), replaced with it.
    let again = hullcut(&args);
    assert_eq!(again.status.code(), Some(1));
    assert!(stderr(&again).contains(&path(&out)), "{}", stderr(&again));
    let forced = hullcut(&[&args[..], &["--force"]].concat());
    assert!(forced.status.success(), "{}", stderr(&forced));

    // A scene that is not one is bad usage (exit 2), and the message lists every scene.
    let unknown = hullcut(&["synth", "--out", &path(&dir.path().join("x")), "--scene", "juggling"]);
    assert_eq!(unknown.status.code(), Some(2));
    assert!(stderr(&unknown).contains("juggling") && stderr(&unknown).contains("cut, static, hard, resect"));
    assert!(!dir.path().join("x").exists());
}

#[test]
fn the_committed_dataset_is_complete_and_small() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small"));
    let ds = hullcut_dataset::Dataset::open(root).expect("datasets/cut-small opens");
    assert_eq!(ds.meta().cameras.len(), 6);
    assert!(ds.dropped().is_empty());
    assert!(ds.has_masks() && ds.tool().expect("tool").is_some());
    let size: u64 = walk(root).iter().map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)).sum();
    assert!(size <= 10_000_000, "datasets/cut-small is {size} bytes; the issue allows 10 MB");
    // It was written by `hullcut synth` with the command in datasets/README.md: the same command
    // reproduces it bit for bit (images, masks, truth).
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("again");
    let rig = root.join("rig.yaml");
    let o = hullcut(&[
        "synth",
        "--rig",
        rig.to_str().expect("utf-8"),
        "--frames",
        "9",
        "--fps",
        "4",
        "--background-frames",
        "2",
        "--seed",
        "1",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let again = hullcut_dataset::Dataset::open(&out).expect("regenerated");
    for frame in [0, 8] {
        let (a, b) = (ds.read_frame_set(frame, true).expect("a"), again.read_frame_set(frame, true).expect("b"));
        for (va, vb) in a.views.iter().zip(&b.views) {
            let (va, vb) = (va.as_ref().expect("view"), vb.as_ref().expect("view"));
            assert_eq!(va.image, vb.image);
            assert_eq!(va.mask, vb.mask);
            assert_eq!(va.timestamp_ns, vb.timestamp_ns);
        }
    }
    assert_eq!(ds.truth_poses().expect("poses"), again.truth_poses().expect("poses"));
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("read_dir").flatten() {
        let p = entry.path();
        if p.is_dir() { out.extend(walk(&p)) } else { out.push(p) }
    }
    out
}

#[test]
fn reconstruct_with_the_blade_refined_carves_its_leaves_finer_and_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let run = |levels: &str| {
        let (out, report) = (dir.path().join(format!("rec{levels}")), dir.path().join(format!("rec{levels}.json")));
        let o = hullcut(&[
            "reconstruct",
            "--dataset",
            dataset,
            "--out",
            &path(&out),
            "--frames",
            "6:8",
            "--masks",
            "files",
            "--blade-levels",
            levels,
            "--report",
            &path(&report),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let ply = out.join("hull").join("scalpel").join("000006.ply");
        let mesh = hullcut_dataset::read_ply(&ply).expect("mesh written");
        assert!(hullcut_hull::is_watertight(&mesh), "{} is not closed", ply.display());
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
        r
    };
    let (plain, refined) = (run("0"), run("1"));
    assert_eq!((plain["blade_levels"].as_u64(), refined["blade_levels"].as_u64()), (Some(0), Some(1)));
    assert_eq!(plain["counters"]["leaves_refined"].as_u64(), Some(0));
    assert!(refined["counters"]["leaves_refined"].as_u64().expect("refined") > 0, "{}", refined["counters"]);
    // More than three levels is bad usage.
    let o =
        hullcut(&["reconstruct", "--dataset", dataset, "--out", &path(&dir.path().join("x")), "--blade-levels", "4"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn reconstruct_the_committed_dataset_writes_closed_meshes_and_an_accuracy_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
    let (out, report) = (dir.path().join("rec"), dir.path().join("rec.json"));
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let o = hullcut(&[
        "reconstruct",
        "--dataset",
        dataset,
        "--out",
        &path(&out),
        "--frames",
        "6:9",
        "--masks",
        "segment",
        "--report",
        &path(&report),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for label in ["hand", "scalpel"] {
        for frame in 6..9 {
            let ply = out.join("hull").join(label).join(format!("{frame:06}.ply"));
            let mesh = hullcut_dataset::read_ply(&ply).expect("mesh written");
            assert!(hullcut_hull::is_watertight(&mesh), "{} is not closed", ply.display());
        }
    }
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    assert_eq!(r["kind"], "reconstruction");
    assert_eq!(r["masks"], "segment");
    assert_eq!(r["counters"]["frame_sets"], 3);
    // The working volume is the rig's (no --workspace, none in dataset.toml): the space three of
    // its cameras see, above the table, stated in the report; the leaves are the 3.125 mm asked for.
    assert_eq!(r["workspace"]["source"]["kind"], "rig", "{}", r["workspace"]);
    assert_eq!(r["workspace"]["source"]["min_views"], 3);
    assert_eq!(r["workspace"]["aabb"]["min"][2], 0.0, "above the table");
    assert_eq!(r["voxel_m"], 0.4 / 128.0);
    let side = r["resolution"].as_f64().expect("resolution") * 0.4 / 128.0;
    let extent = (0..3)
        .map(|a| {
            r["workspace"]["aabb"]["max"][a].as_f64().expect("max")
                - r["workspace"]["aabb"]["min"][a].as_f64().expect("min")
        })
        .fold(0.0, f64::max);
    assert!(side >= extent && side < 2.0 * extent, "octree side {side} m for a {extent} m volume");
    for a in r["accuracy"].as_array().expect("accuracy") {
        // The truth is in the dataset: every label is scored on every frame.
        assert_eq!(a["frames"], 3, "{a}");
        let iou = a["iou_mean"].as_f64().expect("iou");
        let bound = a["exact_hull_truth_iou_mean"].as_f64().expect("exact hull iou");
        assert!(iou > 0.0 && iou <= 1.0 && bound > 0.0, "{a}");
        assert!(a["chamfer_mm_mean"].as_f64().expect("chamfer") < 30.0, "{a}");
    }
    for key in ["read", "segment", "carve", "surface", "total"] {
        assert!(r["timings"][key]["count"].as_u64().expect("timing") >= 1, "{key}");
    }
    // The foreground test and the fit's evidence are parts of the segmentation, every frame set.
    let t = &r["timings"];
    let mean = |k: &str| t[k]["mean_ms"].as_f64().unwrap_or_else(|| panic!("{k}: {t}"));
    for part in ["segment_foreground", "segment_evidence"] {
        assert_eq!(t[part]["count"].as_u64(), Some(3), "{t}");
    }
    assert!(mean("segment_foreground") + mean("segment_evidence") <= mean("segment") + 1e-6, "{t}");

    let bad = hullcut(&["reconstruct", "--dataset", dataset, "--out", &path(&out), "--frames", "20:30"]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(stderr(&bad).contains("20:30") && stderr(&bad).contains("9 frames"), "{}", stderr(&bad));
    let bad = hullcut(&["reconstruct", "--dataset", dataset, "--out", &path(&out), "--masks", "magic"]);
    assert_eq!(bad.status.code(), Some(2), "{}", stderr(&bad));
    assert!(stderr(&bad).contains("magic"));
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read_dir").flatten() {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

fn pose_lines(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("poses.jsonl"))
        .expect("poses.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

#[test]
fn reconstruct_on_the_gpu_backend_scores_as_the_cpu_does() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let mut reports = Vec::new();
    for backend in ["cpu", "gpu"] {
        let (out, report) = (dir.path().join(backend), dir.path().join(format!("{backend}.json")));
        let args = ["reconstruct", "--dataset", dataset, "--out", &path(&out), "--frames", "3:6", "--backend", backend];
        let Some(o) = hullcut_on_gpu(&[&args[..], &["--report", &path(&report)]].concat()) else { return };
        assert!(o.status.success(), "{}", stderr(&o));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
        assert_eq!(r["backend"], backend);
        reports.push(r);
    }
    // The same cells up to f32 rounding at pixel edges (none differ on these frames in practice):
    // the scores agree to a hundredth, and the view that disagreed most is the same.
    for (a, b) in
        reports[0]["accuracy"].as_array().expect("cpu").iter().zip(reports[1]["accuracy"].as_array().expect("gpu"))
    {
        let (x, y) = (a["iou_mean"].as_f64().expect("iou"), b["iou_mean"].as_f64().expect("iou"));
        assert!((x - y).abs() < 0.01 * x.max(0.01), "{a} against {b}");
    }
    assert_eq!(reports[0]["view_disagreement"]["disagreed_most"], reports[1]["view_disagreement"]["disagreed_most"]);
}

#[test]
fn reconstruct_writes_one_pose_line_per_frame_as_the_contract_says() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small"));
    let (out, report) = (dir.path().join("rec"), dir.path().join("rec.json"));
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let args = |ds: &Path| {
        ["reconstruct", "--dataset", &path(ds), "--out", &path(&out), "--masks", "files", "--accuracy-every", "9"]
            .map(str::to_owned)
    };
    let mut with_report: Vec<String> = args(dataset).to_vec();
    let rrd = dir.path().join("rec.rrd");
    with_report.extend(["--report".to_owned(), path(&report), "--rrd".to_owned(), path(&rrd)]);
    let o = hullcut(&with_report.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 9);
    for (k, l) in lines.iter().enumerate() {
        assert_eq!(l["frame"], k as u64);
        // Measured on cut-small (320x240, truth masks): all 9 trusted, 1.26° and 0.95 mm mean.
        assert_eq!(l["valid"], true, "{l}");
        assert_eq!(l["held"], false);
        let c = l["confidence"].as_f64().expect("confidence");
        assert!((0.0..=1.0).contains(&c));
        let n: Vec<f64> = serde_json::from_value(l["plane_normal"].clone()).expect("normal");
        assert!((n.iter().map(|x| x * x).sum::<f64>().sqrt() - 1.0).abs() < 1e-9);
        let edge: Vec<[f64; 3]> = serde_json::from_value(l["edge"].clone()).expect("edge");
        assert!(edge.len() >= 2);
        let tip: [f64; 3] = serde_json::from_value(l["tip"].clone()).expect("tip");
        assert_eq!(tip, edge[0], "the edge runs from the tip");
        let _: [f64; 3] = serde_json::from_value(l["plane_point"].clone()).expect("plane point");
    }
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let p = &r["pose"];
    assert_eq!(
        (p["frames"].as_u64(), p["valid_frames"].as_u64(), p["trusted_wrong"].as_u64()),
        (Some(9), Some(9), Some(0))
    );
    assert!(p["tip_mm"]["mean"].as_f64().expect("tip error") < 2.0, "{p}");
    assert!(p["normal_deg"]["mean"].as_f64().expect("normal error") < 2.5, "{p}");
    assert_eq!(p["per_frame"].as_array().expect("per frame").len(), 9);
    assert!(r["timings"]["pose"]["count"].as_u64() == Some(9));
    // What the views made of each frame's fitted blade is logged, as `run` logs it.
    let rows = hullcut_viz::rrd_timeline_rows(&rrd).expect("the recording reads back");
    for kind in ["seen", "edge_on", "hidden", "on_background", "handle_coloured"] {
        let entity = format!("/metrics/pose/views/{kind}");
        assert_eq!(rows.get(&entity).copied(), Some(9), "{entity}: {rows:?}");
    }
    // And each camera's sight of it: a row for every fit the report counts it as judging.
    let cameras = p["per_camera"].as_array().expect("per camera");
    assert!(cameras.len() >= 4, "{p}");
    for c in cameras {
        let name = c["camera"].as_str().expect("a camera's name");
        let judged = c["judged"].as_u64().expect("fits judged") as usize;
        assert!(judged > 0 && judged <= 9, "{c}");
        let entity = format!("/metrics/pose/sight/{name}");
        assert_eq!(rows.get(&entity).copied().unwrap_or(0), judged, "{entity}: {rows:?}");
        // Whether the fit set it aside, on the same rows.
        let entity = format!("/metrics/pose/set_aside/{name}");
        assert_eq!(rows.get(&entity).copied().unwrap_or(0), judged, "{entity}: {rows:?}");
    }

    // Without tool.json every frame is refused with its reason, and no pose fields are written.
    let bare = dir.path().join("bare");
    copy_tree(dataset, &bare);
    std::fs::remove_file(bare.join("tool.json")).expect("rm tool.json");
    let o = hullcut(&args(&bare).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    for l in pose_lines(&out) {
        assert_eq!((&l["valid"], &l["held"]), (&serde_json::json!(false), &serde_json::json!(false)));
        assert!(l.get("tip").is_none() && l.get("edge").is_none(), "{l}");
        assert!(l["reason"].as_str().expect("reason").contains("tool.json"), "{l}");
    }
}

const CUT_SMALL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cut-small");

/// A copy of datasets/cut-small under `dir`, to corrupt (the shipped dataset is never touched).
fn cut_small_copy(dir: &Path) -> PathBuf {
    let ds = dir.join("cut-small");
    copy_tree(Path::new(CUT_SMALL), &ds);
    ds
}

/// `hullcut reconstruct` of one frame from the masks, into `dir/rec`.
fn reconstruct_frame(dataset: &Path, dir: &Path, extra: &[&str]) -> Output {
    let (ds, out) = (dataset.to_str().expect("utf-8"), dir.join("rec"));
    let args = ["reconstruct", "--dataset", ds, "--out", out.to_str().expect("utf-8"), "--frames", "1:2"];
    hullcut(&[&args[..], &["--masks", "files"], extra].concat())
}

#[test]
fn reconstruct_refuses_a_voxel_of_zero_or_beyond_the_workspace() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A 0.4 m cube given as the working volume (the rig's own is 1.8 m wide).
    let ws = "--workspace=-0.2,-0.2,0,0.2,0.2,0.4";
    for voxel in ["0", "-0.01", "0.5", "NaN"] {
        let o = reconstruct_frame(Path::new(CUT_SMALL), dir.path(), &[&format!("--voxel={voxel}"), ws]);
        assert_eq!(o.status.code(), Some(1), "--voxel {voxel}");
        let e = stderr(&o);
        assert!(e.contains(&format!("--voxel {voxel}")) && e.contains("0.4 m"), "--voxel {voxel}: {e}");
    }
    // The whole workspace as one leaf is allowed.
    let o = reconstruct_frame(Path::new(CUT_SMALL), dir.path(), &["--voxel", "0.4", ws]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn reconstruct_names_a_mask_with_a_label_it_does_not_know() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    let path = ds.join("masks/cam3/000001.png");
    let mut mask = image::open(&path).expect("mask").into_luma8();
    mask.put_pixel(17, 5, image::Luma([7]));
    mask.save(&path).expect("save");
    let o = reconstruct_frame(&ds, dir.path(), &[]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains(path.to_str().expect("utf-8")) && e.contains("cam3"), "{e}");
    assert!(e.contains("(17, 5) holds 7") && e.contains("1 pixels"), "{e}");
}

#[test]
fn reconstruct_names_a_mask_of_the_wrong_size() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    let path = ds.join("masks/cam2/000001.png");
    image::GrayImage::new(160, 120).save(&path).expect("save");
    let o = reconstruct_frame(&ds, dir.path(), &[]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains(path.to_str().expect("utf-8")) && e.contains("160x120") && e.contains("cam2"), "{e}");
}

#[test]
fn reconstruct_names_a_rig_that_does_not_match_the_dataset() {
    // reconstruct has no --rig flag: the rig is the dataset's rig.yaml, checked by Dataset::open.
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    let rig = ds.join("rig.yaml");
    let text = std::fs::read_to_string(&rig).expect("rig.yaml");
    let renamed = text.replace("name: \"cam5\"", "name: \"cam9\"");
    let start = text.find("camera_5:").expect("camera_5");
    let removed = text[..start].replace("camera_count: 6", "camera_count: 5");
    for (broken, needle) in [(renamed, "cam9"), (removed, "(5 cameras)")] {
        std::fs::write(&rig, broken).expect("write");
        let o = reconstruct_frame(&ds, dir.path(), &[]);
        assert_eq!(o.status.code(), Some(1), "{needle}");
        let e = stderr(&o);
        assert!(e.contains(rig.to_str().expect("utf-8")) && e.contains(needle), "{needle}: {e}");
    }
}

/// Sets to background every foreground pixel with a background pixel among its 8 neighbours.
fn erode_one_pixel(mask: &image::GrayImage) -> image::GrayImage {
    let (w, h) = (mask.width() as i64, mask.height() as i64);
    let background =
        |x: i64, y: i64| (0..w).contains(&x) && (0..h).contains(&y) && mask[(x as u32, y as u32)].0[0] == 0;
    let mut out = mask.clone();
    for y in 0..h {
        for x in 0..w {
            if (-1..=1).any(|dy| (-1..=1).any(|dx| background(x + dx, y + dy))) {
                out.put_pixel(x as u32, y as u32, image::Luma([0]));
            }
        }
    }
    out
}

#[test]
fn reconstruct_names_the_camera_whose_masks_disagree() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    let report_of = |name: &str| -> serde_json::Value {
        let report = dir.path().join(format!("{name}.json"));
        let out = dir.path().join(name);
        let o = hullcut(&[
            "reconstruct",
            "--dataset",
            ds.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
            "--frames",
            "0:2",
            "--masks",
            "files",
            "--accuracy-every",
            "100",
            "--report",
            report.to_str().expect("utf-8"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json")
    };
    let clean = report_of("clean");
    let d = &clean["view_disagreement"];
    let cameras: Vec<&str> = d["lone_refutations"]
        .as_array()
        .expect("per camera")
        .iter()
        .map(|c| c["camera"].as_str().expect("name"))
        .collect();
    assert_eq!(cameras, ["cam0", "cam1", "cam2", "cam3", "cam4", "cam5"]);
    assert!(
        d["lone_refutations"].as_array().expect("per camera").iter().all(|c| c["cells"].as_u64().expect("cells") > 0)
    );
    // On clean masks every camera refutes some cells alone, the most about twice the median
    // (measured 1.9, cam2, frames 0-1).
    let clean_ratio = d["most_over_median"].as_f64().expect("ratio");
    assert!(clean_ratio < 2.5, "{d}");

    // cam4's segmentation misses the outline: one pixel less all round, in every frame.
    for frame in 0..2 {
        let path = ds.join(format!("masks/cam4/{frame:06}.png"));
        let mask = image::open(&path).expect("mask").into_luma8();
        erode_one_pixel(&mask).save(&path).expect("save");
    }
    let eroded = report_of("eroded");
    let d = &eroded["view_disagreement"];
    assert_eq!(d["disagreed_most"], "cam4", "{d}");
    // Measured 3.6x the median (frames 0-1; 3.4x over all nine frames, 6.7x eroded by 2 px).
    let ratio = d["most_over_median"].as_f64().expect("ratio");
    assert!(ratio > 2.8, "{d}");
}

#[test]
fn bench_pose_quick_writes_errors_refusals_and_charts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = hullcut(&["bench", "pose", "--quick", "--out", dir.path().to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (header, rows) = read_csv(&dir.path().join("pose.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).expect(name);
    for r in &rows {
        // Truth masks, six views: never a trusted pose off by 5° or 5 mm.
        assert_eq!(r[col("trusted_wrong")], "0", "{r:?}");
    }
    let six_views = rows.iter().find(|r| r[0] == "cameras" && r[col("cameras")] == "6").expect("six-camera row");
    assert_eq!(six_views[col("invalid_rate")], "0.0000");
    assert!(six_views[col("tip_mm_mean")].parse::<f64>().expect("tip") < 1.0, "{six_views:?}");
    for name in ["pose_leaf.png", "pose_time.png", "pose_cameras.png", "pose_noise.png", "pose_invalid.png"] {
        assert!(std::fs::read(dir.path().join(name)).expect("png").starts_with(b"\x89PNG"), "{name}");
    }
}

#[test]
fn gpu_info_names_the_adapter_it_would_use_or_says_there_is_none() {
    let o = hullcut(&["gpu-info"]);
    let out = String::from_utf8_lossy(&o.stdout);
    if o.status.success() {
        assert!(out.contains("using ") && out.contains("storage buffer binding up to"), "{out}");
    } else {
        // CI has Mesa's software adapter: none there is a broken setup, not a pass.
        assert!(std::env::var_os("CI").is_none(), "no adapter in CI: {}", stderr(&o));
        assert_eq!(o.status.code(), Some(1));
        assert!(stderr(&o).contains("no GPU adapter"), "{}", stderr(&o));
    }
    // A name that matches nothing lists what there is.
    let o = Command::new(env!("CARGO_BIN_EXE_hullcut"))
        .arg("gpu-info")
        .env("HULLCUT_GPU_ADAPTER", "no-such-adapter-xyz")
        .output()
        .expect("run hullcut");
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.contains("no-such-adapter-xyz") || err.contains("no GPU adapter"), "{err}");
}

#[test]
fn reconstruct_of_masks_all_scalpel_says_what_it_cannot_measure_and_ends_promptly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    // Frame 0's masks are scalpel in every pixel of every view: the hull is the whole working
    // volume, its exact visual hull unbounded by any view, its surface up to 30 cm from the tool.
    for cam in 0..6 {
        let path = ds.join(format!("masks/cam{cam}/000000.png"));
        let mask = image::open(&path).expect("mask").into_luma8();
        image::GrayImage::from_pixel(mask.width(), mask.height(), image::Luma([2])).save(&path).expect("save");
    }
    let (out, report) = (dir.path().join("rec"), dir.path().join("rec.json"));
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let clock = std::time::Instant::now();
    let o = hullcut(&[
        "reconstruct",
        "--dataset",
        &path(&ds),
        "--out",
        &path(&out),
        "--frames",
        "1",
        "--masks",
        "files",
        "--workspace=-0.2,-0.2,0,0.2,0.2,0.4",
        "--voxel",
        "0.00625",
        "--report",
        &path(&report),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(clock.elapsed() < std::time::Duration::from_secs(300), "{:?}", clock.elapsed());
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let accuracy = r["accuracy"].as_array().expect("accuracy");
    let of = |label: &str| accuracy.iter().find(|a| a["label"] == label).expect(label).clone();
    let (scalpel, hand) = (of("scalpel"), of("hand"));
    for a in [&scalpel, &hand] {
        assert_eq!(a["exact_hull_not_measurable"], 1, "{a}");
        assert!(a["exact_hull_iou_mean"].is_null() && a["exact_hull_truth_iou_mean"].is_null(), "{a}");
    }
    // The scalpel's hull is measured against the tool, however far its surface lies.
    assert!(scalpel["chamfer_mm_mean"].as_f64().is_some_and(f64::is_finite), "{scalpel}");
    // No hand was carved: its IoU is 0, its surface distance not measured (n/a, never NaN).
    assert_eq!(hand["iou_mean"].as_f64(), Some(0.0), "{hand}");
    assert_eq!(hand["not_measured"], 1, "{hand}");
    assert!(hand["chamfer_mm_mean"].is_null(), "{hand}");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("Chamfer n/a") && !stdout.contains("NaN"), "{stdout}");
    assert_eq!(r["non_finite"].as_array().map(Vec::len), Some(0), "{}", r["non_finite"]);
}

#[test]
fn reconstruct_goes_on_past_a_corrupt_image_and_lists_it_in_its_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ds = cut_small_copy(dir.path());
    // Frame 1: cam1's image cut short; frame 2: every camera's image garbage.
    let cut = ds.join("cam1/000001.png");
    let bytes = std::fs::read(&cut).expect("png");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).expect("truncate");
    for cam in 0..6 {
        std::fs::write(ds.join(format!("cam{cam}/000002.png")), b"not a PNG").expect("garbage");
    }
    let (out, report) = (dir.path().join("rec"), dir.path().join("rec.json"));
    let path = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let o = hullcut(&[
        "reconstruct",
        "--dataset",
        &path(&ds),
        "--out",
        &path(&out),
        "--frames",
        "0:4",
        "--masks",
        "files",
        "--accuracy-every",
        "100",
        "--report",
        &path(&report),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("frame 1, camera cam1") && stderr(&o).contains("000001.png"), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    assert_eq!(r["counters"]["frame_sets"], 3, "frame 2 left out whole: {}", r["counters"]);
    let f = &r["faults"];
    assert_eq!((f["views"].as_u64(), f["frame_sets"].as_u64()), (Some(7), Some(1)), "{f}");
    assert!(r["stopped"].is_null(), "{}", r["stopped"]);
    // One pose line per frame still: frame 2's says why it has no pose.
    let lines = pose_lines(&out);
    assert_eq!(lines.len(), 4);
    assert_eq!(lines[2]["valid"], false);
    assert!(lines[2]["reason"].as_str().expect("reason").contains("could not be read"), "{}", lines[2]);
    assert!(out.join("hull/scalpel/000001.ply").is_file() && out.join("hull/scalpel/000003.ply").is_file());
}
