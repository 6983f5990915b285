//! Measuring the loop against the truth of a synthetic recording: speed (fps, latency from
//! capture to cut surface, each stage's times inside the loop) beside accuracy (the blade's tip
//! against the true poses, the resected piece's volume against a reference cut by the true
//! poses). `hullcut bench loop` charts these; a lab's program can call them on its own
//! recordings when they carry true poses (`truth/poses.jsonl`).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use hullcut_dataset::Dataset;
use hullcut_pose::{BladePose, Template, pose_error, rigid_from_matrix};
use hullcut_sim::CutSim;
use nalgebra::Isometry3;

use crate::error::{Context as _, Error, fail};
use crate::no_tool_estimate;
use crate::stages::{Setup, StageTimes, spawn};
use crate::tissue::{self, Sweeper};

/// The tool's true poses (tool to world) by frame, `None` when the dataset records none.
pub fn truth_poses(ds: &Dataset) -> Result<Option<BTreeMap<u64, Isometry3<f64>>>, Error> {
    let Some(poses) = ds.truth_poses().context("reading the true poses")? else {
        return Ok(None);
    };
    let mut truth = BTreeMap::new();
    for p in poses {
        let iso = rigid_from_matrix(&p.tool_to_world).with_context(|| format!("the true pose of frame {}", p.frame))?;
        truth.insert(p.frame, iso);
    }
    Ok(Some(truth))
}

/// The volume of the smallest piece, millilitres, when the organ is in two or more pieces.
pub fn resected_ml(sim: &CutSim) -> Option<f64> {
    let states = sim.piece_states();
    (states.len() >= 2).then(|| states.iter().map(|s| s.volume_m3 * 1e6).fold(f64::INFINITY, f64::min))
}

/// The piece that the true poses cut off the built-in organ at lattice spacing `cell_m` (finer
/// than the loop's, so that the reference holds neither the loop's lattice nor its pose error),
/// stepping the organ by the recording's frame gaps: `None` when they cut nothing off.
pub fn reference_resection_ml(
    ds: &Dataset,
    template: &Template,
    truth: &BTreeMap<u64, Isometry3<f64>>,
    cell_m: f64,
) -> Result<Option<f64>, Error> {
    let mut organ = tissue::build("organ", cell_m, None, None)?;
    let mut sweeper = Sweeper::default();
    let mut last_ts = None;
    let mut times = StageTimes::default();
    for frame in ds.frame_numbers() {
        let ts = ds.frame_timestamp(frame).unwrap_or(0);
        let seconds = last_ts.map_or(0.0, |t: i64| (ts.saturating_sub(t) as f64 * 1e-9).clamp(0.0, 0.2));
        last_ts = Some(ts);
        let mut estimate = no_tool_estimate(frame, ts);
        if let Some(iso) = truth.get(&frame) {
            estimate.valid = true;
            estimate.pose = Some(BladePose::new(template, *iso));
        }
        let mut step = sweeper.next(Some(&estimate), Some(template), organ.cell);
        organ.step(&mut step, seconds, None, &mut times).with_context(|| format!("the reference, frame {frame}"))?;
    }
    Ok(resected_ml(&organ.sim))
}

/// What one run of the loop measured.
#[derive(Debug)]
pub struct Measured {
    /// Frame sets that came out of the loop.
    pub frames: u64,
    /// Wall time from spawning the stages to the last result, seconds.
    pub wall_s: f64,
    /// Each frame set's latency from capture to its cut surface.
    pub latencies: Vec<Duration>,
    /// Every stage's times inside the loop.
    pub times: StageTimes,
    /// Frame sets whose blade pose was trusted and has a true pose to compare with.
    pub trusted: u64,
    /// The blade tip's error of each of those, millimetres.
    pub tip_mm: Vec<f64>,
    /// Pieces the organ ended in.
    pub pieces: usize,
    /// The resected (smallest) piece's volume, millilitres, when the organ is in pieces.
    pub resected_ml: Option<f64>,
}

impl Measured {
    /// Frame sets per second, sustained over the run.
    pub fn fps(&self) -> f64 {
        self.frames as f64 / self.wall_s.max(1e-9)
    }

    /// The blade tip's mean error, millimetres (NaN when no pose was trusted).
    pub fn tip_mm_mean(&self) -> f64 {
        if self.tip_mm.is_empty() { f64::NAN } else { self.tip_mm.iter().sum::<f64>() / self.tip_mm.len() as f64 }
    }

    /// The resected piece's volume error against `reference_ml`, percent: 100 when the organ
    /// was not cut in pieces.
    pub fn tissue_error_pct(&self, reference_ml: f64) -> f64 {
        match (self.pieces >= 2, self.resected_ml) {
            (true, Some(ml)) => 100.0 * (ml - reference_ml).abs() / reference_ml,
            _ => 100.0,
        }
    }
}

/// Runs the loop of `setup` to its end, taking its results as fast as they come, and measures
/// it: the blade against `truth` through `template` (frames without a true pose are not
/// scored). Fails when a stage failed or the tissue stopped (a divergence).
pub fn run_measured(
    setup: Setup,
    template: &Template,
    truth: &BTreeMap<u64, Isometry3<f64>>,
) -> Result<Measured, Error> {
    let clock = Instant::now();
    let pipeline = spawn(setup)?;
    let mut m = Measured {
        frames: 0,
        wall_s: 0.0,
        latencies: Vec::new(),
        times: StageTimes::default(),
        trusted: 0,
        tip_mm: Vec::new(),
        pieces: 0,
        resected_ml: None,
    };
    for work in pipeline.output.iter() {
        m.frames += 1;
        m.latencies.push(work.latency());
        m.times.extend(&work.times);
        if let (Some(e), Some(iso)) = (&work.estimate, truth.get(&work.frame))
            && let (true, Some(p)) = (e.valid, &e.pose)
        {
            m.trusted += 1;
            m.tip_mm.push(pose_error(p, template, iso).tip_mm);
        }
    }
    m.wall_s = clock.elapsed().as_secs_f64();
    let outcome = pipeline.join();
    if let Some(e) = outcome.error {
        return Err(e);
    }
    if let Some(f) = outcome.failure {
        fail!("the tissue stopped: {f}");
    }
    let Some(sim) = outcome.sim else {
        fail!("the tissue stage ended without its simulation");
    };
    m.pieces = sim.pieces();
    m.resected_ml = resected_ml(&sim);
    Ok(m)
}

/// A shared dataset's true poses and tool template, or an error that says which is missing.
pub fn truth_and_template(ds: &Arc<Dataset>) -> Result<(Template, BTreeMap<u64, Isometry3<f64>>), Error> {
    let Some(tool) = ds.tool().context("reading tool.json")? else {
        fail!("{}: no tool.json: the blade cannot be measured", ds.root().display());
    };
    let template = Template::new(&tool).context("the tool's template")?;
    let Some(truth) = truth_poses(ds)? else {
        fail!("{}: no true poses (truth/poses.jsonl): the blade cannot be measured", ds.root().display());
    };
    Ok((template, truth))
}
