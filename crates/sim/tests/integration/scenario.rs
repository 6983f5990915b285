//! Bad scenario input never crashes, hangs or lies (issue 24): every value is checked where it is
//! read, the error names the file and the key, counts and sizes that would be allocated or looped
//! over are bounded, and no text makes the parser panic. `tests/corpus/` holds one small file per
//! bad input found so far; its first line names the key the error must name.

use std::path::Path;

use hullcut_sim::{MAX_STEPS, Scenario, ScriptedCut, Simulation};
use proptest::prelude::*;

/// A valid scenario touching every table, small enough to build in milliseconds: eight 1 cm cells,
/// one of them TLED (the operational region) and the rest FLSM.
const VALID: &str = r#"[body]
shape = "box"
size = [0.02, 0.02, 0.02]
cell = 0.01

[material]
lambda = 20000.0
mu = 20000.0
density = 1000.0

[tled]
integration = "one-point"
hourglass = 0.075

[flsm]
w = 1
alpha = 0.8
region_damping = 0.1

[hybrid]
ratio = 0.5
operational = { center = [0.005, 0.005, 0.005], radius = 0.001 }
beta = 200.0
substeps = 2

[[boundary]]
faces = ["x-"]
fix = ["x", "y", "z"]

[[boundary]]
box = { min = [0.02, 0.0, 0.0], max = [0.02, 0.02, 0.02] }
displace = [0.001, 0.0, 0.0]
ramp = 0.005

[run]
duration = 0.01
dt = "auto"
safety = 0.8
damping = 50.0
gravity = [0.0, 0.0, -9.81]

[[load]]
box = { min = [0.015, 0.0, 0.015], max = [0.02, 0.02, 0.02] }
force = [0.0, 0.0, -0.01]

[report]
reaction = ["x-"]
probes = [[0.02, 0.01, 0.01]]
interval = 0.001
"#;

/// `VALID` with `from` (which must occur) replaced by `to`.
fn with(from: &str, to: &str) -> String {
    assert!(VALID.contains(from), "`{from}` is not in the valid scenario");
    VALID.replacen(from, to, 1)
}

/// Parsing `text` fails with an error naming the file and `key`.
fn refused(text: &str, key: &str) {
    let e = Scenario::parse(text, "bad.toml").expect_err(key);
    let msg = e.to_string();
    assert!(msg.starts_with("bad.toml: ") && msg.contains(&format!("`{key}`")), "expected `{key}` in: {msg}");
}

#[test]
fn the_valid_scenario_parses_and_builds() {
    let s = Scenario::parse(VALID, "valid.toml").expect("parses");
    let sim = Simulation::from_scenario(&s).expect("builds");
    assert!(sim.hybrid_steps().is_some(), "a hybrid");
    let advances = sim.advances_for(s.run.duration).expect("a short run");
    assert!(advances >= 1 && advances * sim.steps_per_advance() as u64 <= MAX_STEPS);
}

#[test]
fn a_time_step_of_1e_minus_30_is_refused_naming_run_dt() {
    refused(&with("dt = \"auto\"", "dt = 1e-30"), "run.dt");
    refused(&with("dt = \"auto\"", "dt = nan"), "run.dt");
    refused(&with("dt = \"auto\"", "dt = 1e30"), "run.dt");
}

#[test]
fn a_safety_of_1e_minus_300_is_refused_naming_run_safety() {
    refused(&with("safety = 0.8", "safety = 1e-300"), "run.safety");
    refused(&with("safety = 0.8", "safety = 0.0"), "run.safety");
    refused(&with("safety = 0.8", "safety = 1.5"), "run.safety");
}

#[test]
fn a_billion_substeps_are_refused_naming_hybrid_substeps() {
    refused(&with("substeps = 2", "substeps = 1000000000"), "hybrid.substeps");
    refused(&with("substeps = 2", "substeps = 0"), "hybrid.substeps");
}

#[test]
fn a_density_of_1e308_is_refused_naming_material_density() {
    refused(&with("density = 1000.0", "density = 1e308"), "material.density");
    refused(&with("density = 1000.0", "density = 1e-3"), "material.density");
    refused(&with("mu = 20000.0", "mu = 1e308"), "material.mu");
    refused(&with("lambda = 20000.0", "lambda = 1e308"), "material.lambda");
    refused(&with("lambda = 20000.0", "lambda = nan"), "material.lambda");
}

#[test]
fn a_nan_probe_is_refused_naming_report_probes() {
    refused(&with("probes = [[0.02, 0.01, 0.01]]", "probes = [[nan, 0.01, 0.01]]"), "report.probes[0]");
    refused(
        &with("probes = [[0.02, 0.01, 0.01]]", "probes = [[0.02, 0.01, 0.01], [0.0, inf, 0.0]]"),
        "report.probes[1]",
    );
}

#[test]
fn a_nan_operational_centre_is_refused_naming_the_key() {
    refused(&with("center = [0.005, 0.005, 0.005]", "center = [nan, 0.005, 0.005]"), "hybrid.operational.center");
    refused(&with("radius = 0.001", "radius = nan"), "hybrid.operational.radius");
    refused(&with("radius = 0.001", "radius = -1.0"), "hybrid.operational.radius");
}

#[test]
fn a_huge_lattice_is_refused_before_it_is_allocated() {
    refused(
        &with("size = [0.02, 0.02, 0.02]\ncell = 0.01", "size = [1000.0, 1000.0, 1000.0]\ncell = 0.001"),
        "body.cell",
    );
    refused("[body]\nshape = \"organ\"\ncell = 0.00002\n", "body.cell");
    refused(&with("cell = 0.01", "cell = 0.0"), "body.cell");
    refused(&with("cell = 0.01", "cell = nan"), "body.cell");
    refused(&with("size = [0.02, 0.02, 0.02]", "size = [0.02, -0.02, 0.02]"), "body.size");
}

#[test]
fn every_number_must_be_finite_and_in_range() {
    for (from, to, key) in [
        ("interval = 0.001", "interval = nan", "report.interval"),
        ("interval = 0.001", "interval = -1.0", "report.interval"),
        ("ramp = 0.005", "ramp = inf", "boundary[1].ramp"),
        ("displace = [0.001, 0.0, 0.0]", "displace = [nan, 0.0, 0.0]", "boundary[1].displace"),
        ("max = [0.02, 0.02, 0.02] }\ndisplace", "max = [0.02, nan, 0.02] }\ndisplace", "boundary[1].box.max"),
        ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -inf]", "run.gravity"),
        ("damping = 50.0", "damping = -1.0", "run.damping"),
        ("duration = 0.01", "duration = nan", "run.duration"),
        ("duration = 0.01", "duration = 0.0", "run.duration"),
        ("beta = 200.0", "beta = 1e308", "hybrid.beta"),
        ("ratio = 0.5", "ratio = nan", "hybrid.ratio"),
        ("hourglass = 0.075", "hourglass = inf", "tled.hourglass"),
        ("region_damping = 0.1", "region_damping = nan", "flsm.region_damping"),
        ("alpha = 0.8", "alpha = nan", "flsm.alpha"),
        ("force = [0.0, 0.0, -0.01]", "force = [0.0, 0.0, 1e308]", "load[0].force"),
        ("min = [0.015, 0.0, 0.015]", "min = [0.015, -inf, 0.015]", "load[0].box.min"),
    ] {
        refused(&with(from, to), key);
    }
}

#[test]
fn counts_read_from_the_file_are_bounded() {
    refused(&with("w = 1", "w = 1000000000000"), "flsm.w");
    let probes = vec!["[0.0, 0.0, 0.0]"; hullcut_sim::scenario::MAX_PROBES + 1].join(", ");
    refused(&with("probes = [[0.02, 0.01, 0.01]]", &format!("probes = [{probes}]")), "report.probes");
    let boundary = "[[boundary]]\nfaces = [\"x-\"]\nfix = [\"x\"]\n".repeat(hullcut_sim::scenario::MAX_BOUNDARIES + 1);
    refused(&format!("{VALID}\n{boundary}"), "boundary");
    refused(&with("faces = [\"x-\"]", &format!("faces = [{}]", ["\"x-\""; 7].join(", "))), "boundary[0].faces");
}

#[test]
fn a_run_of_more_than_max_steps_is_refused_when_built() {
    let text = with("dt = \"auto\"", "dt = 1e-9").replacen("duration = 0.01", "duration = 100.0", 1);
    let s = Scenario::parse(&text, "long.toml").expect("every value is in range");
    let e = Simulation::from_scenario(&s).expect_err("1e11 steps");
    let msg = e.to_string();
    assert!(msg.contains("`run.duration`") && msg.contains(&MAX_STEPS.to_string()), "{msg}");
    let sim = Simulation::from_scenario(&Scenario::parse(VALID, "valid.toml").expect("parses")).expect("builds");
    for duration in [f64::NAN, f64::INFINITY, -1.0, 0.0, 1e300] {
        let e = sim.advances_for(duration).expect_err("refused");
        assert!(e.to_string().contains("run.duration"), "{duration}: {e}");
    }
}

#[test]
fn an_oversized_scenario_file_is_refused_unread() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("big.toml");
    let padding = "# padding\n".repeat((hullcut_sim::scenario::MAX_SCENARIO_BYTES as usize) / 10 + 1);
    std::fs::write(&path, format!("{VALID}{padding}")).expect("write");
    let e = Scenario::load(&path).expect_err("too large");
    assert!(e.to_string().contains("larger than"), "{e}");
}

/// A valid scenario with a blade that cuts: a 2 x 2 x 2 cm block of 1 cm cells on a table, an
/// upright edge drawn through it in a few frames, the far field asleep beyond 5 mm.
const VALID_CUT: &str = r#"[body]
shape = "box"
size = [0.02, 0.02, 0.02]
cell = 0.01

[material]
lambda = 20000.0
mu = 20000.0
density = 1000.0

[[boundary]]
faces = ["x-"]
fix = ["x", "y", "z"]

[run]
duration = 0.05
safety = 0.8
damping = 50.0
gravity = [0.0, 0.0, -9.81]

[report]
interval = 0.01

[cut]
edge = [[0.012, -0.005, -0.001], [0.012, -0.005, 0.025]]
path = [{ time = 0.0, offset = [0.0, 0.0, 0.0] }, { time = 0.03, offset = [0.0, 0.03, 0.0] }]
operational_radius = 0.005
far_field = "frozen"

[cut.table]
friction = 0.5
"#;

#[test]
fn the_valid_cut_scenario_cuts_the_block() {
    let s = Scenario::parse(VALID_CUT, "cut.toml").expect("parses");
    let mut run = ScriptedCut::from_scenario(&s).expect("builds");
    let mut crossed = 0;
    for _ in 0..run.frames_for(s.run.duration) {
        crossed += run.frame().expect("stable").cut.map_or(0, |c| c.new_edges);
    }
    assert!(crossed > 0, "the blade crossed lattice edges");
}

/// Every file of `tests/corpus/` is refused, by the parser or when the simulation is built, with
/// an error naming the key its first line (`# key: ...`) gives.
#[test]
fn the_regression_corpus_is_refused_naming_each_key() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("corpus folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 7, "{} corpus files", files.len());
    for path in files {
        let text = std::fs::read_to_string(&path).expect("read");
        let key = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# key: "))
            .unwrap_or_else(|| panic!("{}: the first line must be `# key: ...`", path.display()))
            .trim();
        let name = path.display().to_string();
        let e = match Scenario::parse(&text, &name) {
            Err(e) => e,
            Ok(s) if s.cut.is_some() => match ScriptedCut::from_scenario(&s) {
                Err(e) => e,
                Ok(_) => panic!("{name}: accepted"),
            },
            Ok(s) => match Simulation::from_scenario(&s) {
                Err(e) => e,
                Ok(_) => panic!("{name}: accepted"),
            },
        };
        let msg = e.to_string();
        assert!(msg.contains(&format!("`{key}`")), "{name}: expected `{key}` in: {msg}");
    }
}

/// Hostile literals a mutation puts in place of a number.
const HOSTILE: [&str; 14] = [
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-30",
    "1e-300",
    "0",
    "-1",
    "1000000000",
    "18446744073709551615",
    "9223372036854775807",
    "-0.0",
    "5e-324",
];

/// Byte ranges of the numbers in `VALID`.
fn numbers() -> Vec<(usize, usize)> {
    numbers_in(VALID)
}

/// Byte ranges of the numbers in `text`.
fn numbers_in(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = (b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit)))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'));
        if starts {
            let mut j = i + 1;
            while j < b.len() && (b[j].is_ascii_digit() || matches!(b[j], b'.' | b'e' | b'E' | b'+' | b'-' | b'_')) {
                j += 1;
            }
            out.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// Whatever a scenario that parsed holds is finite (a sample of the values `validate` checks).
fn all_finite(s: &Scenario) -> bool {
    let r = &s.run;
    [s.body.cell, s.material.lambda, s.material.mu, s.material.density, r.duration, r.safety, r.damping]
        .iter()
        .chain(&r.gravity)
        .chain(s.report.probes.iter().flatten())
        .chain(s.hybrid.operational.iter().flat_map(|o| o.center.iter()))
        .all(|x| x.is_finite())
        && s.dt().is_none_or(f64::is_finite)
        && s.report.interval.is_finite()
}

proptest! {
    // Each case parses a short text: 64 cases of each kind take milliseconds.
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Arbitrary bytes are refused or parsed, never a panic.
    #[test]
    fn arbitrary_bytes_never_panic_the_parser(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let text = String::from_utf8_lossy(&bytes);
        if let Ok(s) = Scenario::parse(&text, "fuzz.toml") {
            prop_assert!(all_finite(&s));
        }
    }

    /// A valid scenario with bytes overwritten, inserted or deleted is refused or parsed with every
    /// value finite, never a panic.
    #[test]
    fn byte_mutated_scenarios_never_panic_the_parser(
        edits in proptest::collection::vec((any::<proptest::sample::Index>(), any::<u8>(), 0..3u8), 1..8),
    ) {
        let mut bytes = VALID.as_bytes().to_vec();
        for (at, byte, op) in edits {
            let i = at.index(bytes.len());
            match op {
                0 => bytes[i] = byte,
                1 => bytes.insert(i, byte),
                _ if bytes.len() > 1 => {
                    bytes.remove(i);
                }
                _ => {}
            }
        }
        let text = String::from_utf8_lossy(&bytes);
        if let Ok(s) = Scenario::parse(&text, "fuzz.toml") {
            prop_assert!(all_finite(&s));
        }
    }

    /// A cutting scenario with numbers replaced by hostile literals is refused, or it builds (or
    /// is refused naming a key) and runs its frames to the end or to a reported divergence with
    /// finite positions: never a panic, never a NaN.
    #[test]
    fn hostile_numbers_in_a_cut_scenario_are_refused_or_run(
        picks in proptest::collection::vec((any::<proptest::sample::Index>(), 0..HOSTILE.len()), 1..3),
    ) {
        let spans = numbers_in(VALID_CUT);
        let mut chosen: Vec<((usize, usize), &str)> =
            picks.iter().map(|(at, h)| (spans[at.index(spans.len())], HOSTILE[*h])).collect();
        chosen.sort_by_key(|c| std::cmp::Reverse(c.0));
        chosen.dedup_by(|a, b| a.0 == b.0);
        let mut text = VALID_CUT.to_owned();
        for ((start, end), literal) in chosen {
            text.replace_range(start..end, literal);
        }
        let Ok(s) = Scenario::parse(&text, "fuzz.toml") else { return Ok(()) };
        prop_assert!(all_finite(&s));
        let Ok(mut run) = ScriptedCut::from_scenario(&s) else { return Ok(()) };
        // A few frames at most: a hostile interval or duration must not make this long.
        for _ in 0..run.frames_for(s.run.duration).min(4) {
            if run.frame().is_err() {
                break;
            }
            prop_assert!(run.sim.node_positions().iter().all(|p| p.coords.iter().all(|x| x.is_finite())));
        }
    }

    /// A valid scenario with numbers replaced by hostile literals (NaN, infinities, extremes) is
    /// refused or parsed with every value finite.
    #[test]
    fn hostile_numbers_are_refused_or_finite(
        picks in proptest::collection::vec((any::<proptest::sample::Index>(), 0..HOSTILE.len()), 1..4),
    ) {
        let spans = numbers();
        let mut chosen: Vec<((usize, usize), &str)> =
            picks.iter().map(|(at, h)| (spans[at.index(spans.len())], HOSTILE[*h])).collect();
        // Replace from the end so earlier spans stay where they were; a span picked twice once.
        chosen.sort_by_key(|c| std::cmp::Reverse(c.0));
        chosen.dedup_by(|a, b| a.0 == b.0);
        let mut text = VALID.to_owned();
        for ((start, end), literal) in chosen {
            text.replace_range(start..end, literal);
        }
        if let Ok(s) = Scenario::parse(&text, "fuzz.toml") {
            prop_assert!(all_finite(&s));
        }
    }
}
