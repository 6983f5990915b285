//! `hullcut reconstruct`: visual hulls of hand and scalpel for every frame set of a dataset.

pub(crate) mod checks;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use hullcut_dataset::{Dataset, FrameSet, Mesh, label};
use hullcut_hull::accuracy::{
    grid_iou, outer_surface_samples, sample_surface, silhouette_consistency, surface_distance, volumetric_iou,
};
use hullcut_hull::{DenseGrid, HullParams, Occupancy, WorkingVolume, carve, carve_within, silhouettes};
use hullcut_pose::{Template, Tracker, TrackerParams, ViewInput, pose_error, rigid_from_matrix};
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use self::checks::{Faults, ViewDisagreement};
use crate::backend::{Backend, Carver};
use crate::frames::parse_frames;
use crate::labelling::{LabelMethod, Labelling, LabellingReport};
use crate::logging::{CameraLogger, log_tool};
use crate::pose_out::{PoseReport, PoseWriter, log_blade, no_tool_estimate};
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};
use crate::volume::{MIN_VIEWS, WorkspaceArg};
use crate::weak::WeakArg;

/// Carve the visual hull of hand and scalpel from every frame set of a dataset.
///
/// Each view's label mask (from masks/, or segmented from the images) becomes summed-area tables;
/// an octree over the working volume is carved by testing every cell's whole projected footprint in
/// every view, so a blade thinner than a voxel survives; pixels of the other label never carve
/// (occlusion-aware labels); a missing view is left out; a cell fewer than three views can see is
/// outside the volume (no ghost volumes where only one or two cameras look); with --carve-votes K a
/// cell needs K background views to go (one bad silhouette cannot delete the tool). The working
/// volume is --workspace, else dataset.toml's `workspace`, else the space at least three of the
/// rig's cameras see (above the table when the rig's world frame is a table's); it is printed,
/// and the report and the recording (world/workspace) state it and its source. Surfaces are closed meshes by surface nets. Where the dataset has truth, the report
/// gives volumetric IoU against the true shapes and against the exact visual hull (the best any
/// silhouette method reaches from these views: truth masks carved at a quarter of the voxel), and
/// Chamfer and Hausdorff distances to the true surfaces. Per camera, the report counts the cells
/// that camera alone refuted while every other view saw foreground, and names the camera that
/// disagreed most (a bad mask or calibration shows as several times the others' count). A mask
/// pixel outside the labels 0, 1, 2, 255 is an error naming the mask file.
///
/// Bad input: a camera image or mask that cannot be read (a corrupt PNG) or holds unknown labels
/// is left out of its frame set, the frame carved from the other views (a frame set with no
/// usable view is left out whole, its poses.jsonl line saying so); the report lists every fault
/// and the command exits with an error at the end naming the first. An accuracy figure that
/// cannot be measured (no hull surface; for the exact visual hull, a view entirely one label or
/// more than 8.4 million quarter leaves) is left out, counted, and printed as
/// n/a; a report figure that is not a finite number is written as null, named in non_finite,
/// and is an error. An error while writing stops the frames, and the report still covers the
/// frames before it.
///
/// The blade's pose: the dataset's tool.json (the instrument's known shape) is fitted to the
/// scalpel silhouettes (with segmented masks: the segmentation's own fit of the tool into the
/// foreground's hull, whose agreement bounds are looser), starting from the scalpel hull or from
/// the track, tracked with a One Euro filter (with --outline-offset and mask files, the fit allows
/// the scalpel's silhouettes to be uniformly fatter or thinner than the tool by up to 1.5 px: a
/// lab's segmentation that takes in or loses the blade's blended edge); a frame whose confidence
/// is too low (fit disagrees with the silhouettes, blade seen by
/// too few views or hidden by the hand from more views than see it, too few scalpel leaves,
/// implausible jump) is refused with a reason and the last
/// trusted pose is held for up to 0.5 s. Without a tool.json every frame is refused. Where the
/// dataset has true poses, the report gives normal, edge and tip errors per frame and aggregated.
///
/// Writes: OUT/hull/LABEL/NNNNNN.ply (closed world-frame meshes, LABEL hand or scalpel; a label with
/// nothing carved writes no file and is counted); OUT/poses.jsonl (one line per frame: valid, held,
/// confidence, plane_point, plane_normal, edge, tip in world metres, or the reason it was refused);
/// REPORT (JSON) with --report; an .rrd (images, masks, leaves as points and meshes under
/// world/hull/LABEL, the blade's estimate and truth under world/tool/{estimate,truth}, timings,
/// confidence and accuracy as scalars, and under metrics/pose/views/KIND how many views see the
/// fitted blade's face, see it edge-on, have it hidden by the hand, on background or on the
/// handle's colour, and under metrics/pose/sight/CAM 1 where that camera sees its face, 0 where
/// not) with --rrd. Prints how often each camera saw the fitted blade's face (a `views:` line).
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The dataset.
    #[arg(long, value_name = "DIR")]
    dataset: PathBuf,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Leaf (voxel) size, metres, above 0 and at most the working volume's longest side.
    #[arg(long, value_name = "METRES", default_value_t = 0.4 / 128.0)]
    voxel: f64,
    /// The working volume, world metres (default: dataset.toml's `workspace`, else the space at
    /// least three cameras see).
    #[arg(long, value_name = "MINX,MINY,MINZ,MAXX,MAXY,MAXZ", allow_hyphen_values = true)]
    workspace: Option<WorkspaceArg>,
    /// Frames: A:B (half-open) or N (the first N).
    #[arg(long, value_name = "A:B|N")]
    frames: Option<String>,
    /// Compute backend of carving: `cpu` (rayon) or `gpu` (wgpu; the same rules, corners projected
    /// in f32).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// Where masks come from: files (masks/), segment (from the images), auto (files if present).
    #[arg(long, value_enum, value_name = "SOURCE", default_value_t = checks::MaskSource::Auto)]
    masks: checks::MaskSource,
    /// With mask files: let the blade's fit take the scalpel's silhouettes as up to 1.5 px fatter
    /// or thinner than the tool all around (a lab's own segmentation that takes in or loses the
    /// blade's blended edge pixels; a thin blade seen at a slant turns 5-10° for a pixel of width).
    /// The offset found is `fit_offset_px` per frame in the report. No effect when segmenting
    /// (the segmentation's own fit holds the offset at 0).
    #[arg(long)]
    outline_offset: bool,
    /// With segmented masks: frames whose masks/ seed the learned colours (comma-separated; see
    /// `segment --help`).
    #[arg(long, value_name = "F,F,...", value_delimiter = ',')]
    label_frames: Vec<u64>,
    /// With segmented masks: what labels the foreground: both (the tool's geometry, sharpened by
    /// learned colours), geometry (the fitted tool alone), colour (the colours of --label-frames
    /// alone).
    #[arg(long, value_enum, value_name = "METHOD", default_value_t = LabelMethod::Both)]
    labels: LabelMethod,
    /// With segmented masks: when a pixel the foreground test calls background, but that differs from it by half
    /// its tolerances, becomes foreground where the other views' hull covers it (a hand or glove of
    /// the table's colour, a grey blade over a grey table): `never`, `always`, or `track-lost`,
    /// from the frame set after the tool's track was refused in 6 of the last 30 frame sets on (the
    /// report's `labelling.weak_foreground_from` says where). It costs a second foreground test
    /// and a carving that keeps what one view alone refutes: some 30 ms a frame set on six 640x480
    /// views. It brings some recordings' lost tracks back and loses others (docs/benchmarks.md,
    /// "Weak foreground once the track is lost"), so it is not on by default.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = WeakArg::Never)]
    weak_foreground: WeakArg,
    /// The same as `--weak-foreground always`.
    #[arg(long)]
    confirm_weak_foreground: bool,
    /// With segmented masks: while searches of the hull's thin parts for a lost tool find no
    /// trusted fit, search one frame set in at most N (every frame set until two fail in a row,
    /// then every second, every fourth...). A failed search costs 100-400 ms on two cores: a
    /// steadier frame rate where the tool is lost for long (random:691 in random:701: 3.3 -> 5.6
    /// fps with 4), but fewer chances to find it again (random:769 in random:773: 48 -> 2 frame
    /// sets trusted, 126 -> 0 of the organ's edges cut). The report counts both
    /// (`labelling.counters.searches`, `searches_paused`).
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::builder::RangedU64ValueParser::<u32>::new().range(1..=64))]
    search_gap: u32,
    /// Views that must see a cell as background to carve it (k of N).
    #[arg(long, value_name = "K", default_value_t = 1,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    carve_votes: usize,
    /// Drop the outer layer of leaves over a solid core (leaves whose centre lies outside the
    /// silhouettes' cone): a hull centred on the surface instead of enclosing it, closer to the
    /// exact visual hull; a blade thinner than a leaf keeps its leaves. Without it the hull
    /// contains everything the masks show.
    #[arg(long)]
    trim_slivers: bool,
    /// Carve the leaves carrying the scalpel label again this many octree levels finer (0-3): a
    /// blade thinner than a leaf is then described at half (a quarter, an eighth) of the leaf
    /// while the hand keeps it. Costs a few ms per level at 1-2 mm leaves.
    #[arg(long, value_name = "LEVELS", default_value_t = 0,
          value_parser = clap::builder::RangedU64ValueParser::<u32>::new().range(0..=u64::from(hullcut_hull::MAX_REFINE_LEVELS)))]
    blade_levels: u32,
    /// Measure accuracy every N-th frame (it costs about a second per frame).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    accuracy_every: u64,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Log to this rerun recording.
    #[arg(long, value_name = "FILE")]
    rrd: Option<PathBuf>,
    /// Log images and leaves every N-th frame (meshes and scalars every frame).
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    rrd_every: u64,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct LabelAccuracy {
    label: String,
    frames: usize,
    iou_mean: Option<f64>,
    iou_min: Option<f64>,
    exact_hull_iou_mean: Option<f64>,
    exact_hull_truth_iou_mean: Option<f64>,
    chamfer_mm_mean: Option<f64>,
    hausdorff_mm_max: Option<f64>,
    /// Frames with truth whose IoU or surface distance could not be measured (no hull surface
    /// for the label, a figure that is not finite): left out of the means.
    not_measured: usize,
    /// Frames with truth whose exact visual hull was not measurable: a view's truth mask is one
    /// label everywhere, or the hull holds more than [`MAX_EXACT_LEAVES`] quarter leaves.
    exact_hull_not_measurable: usize,
    #[serde(skip)]
    iou: Vec<f64>,
    #[serde(skip)]
    exact: Vec<f64>,
    #[serde(skip)]
    exact_truth: Vec<f64>,
    #[serde(skip)]
    chamfer: Vec<f64>,
    #[serde(skip)]
    hausdorff: Vec<f64>,
}

/// Re-projected hull against the observed masks, per camera.
#[derive(Debug, Default, Serialize, Deserialize)]
struct Consistency {
    camera: String,
    frames: usize,
    iou_mean: Option<f64>,
    iou_min: Option<f64>,
    #[serde(skip)]
    values: Vec<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Timings {
    read: StageTiming,
    segment: Option<StageTiming>,
    /// Of `segment`, the foreground test of every view.
    #[serde(default)]
    segment_foreground: Option<StageTiming>,
    /// Of `segment`, the tool's fit's evidence (its provisional labels).
    #[serde(default)]
    segment_evidence: Option<StageTiming>,
    carve: StageTiming,
    surface: StageTiming,
    pose: StageTiming,
    /// The pose's parts: the views' evidence (regions, distance transforms, outlines) and the fit.
    pose_evidence: StageTiming,
    pose_fit: StageTiming,
    accuracy: StageTiming,
    total: StageTiming,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct Counters {
    frame_sets: usize,
    views_missing: usize,
    cells_kept: u64,
    kept_against_refutation: u64,
    unlabelled_cells: u64,
    /// Cells dropped as seen by fewer than `min_views` views (outside the volume).
    unseen_cells: u64,
    /// Leaves dropped as the outer layer over a solid core (--trim-slivers).
    slivers_trimmed: u64,
    /// Scalpel leaves carved again at a finer leaf (--blade-levels).
    leaves_refined: u64,
    footprint_tests: u64,
    empty_label_frames: usize,
    meshes_written: usize,
    /// True poses in truth/poses.jsonl that are not rigid poses (not scored).
    truth_poses_refused: u64,
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    #[serde(flatten)]
    provenance: Provenance,
    dataset: String,
    out: String,
    frames: [u64; 2],
    backend: Backend,
    masks: String,
    /// `--outline-offset`: the blade's fit to mask files took the silhouettes as uniformly fatter
    /// or thinner than the tool.
    outline_offset: bool,
    workspace: WorkingVolume,
    voxel_m: f64,
    resolution: usize,
    carve_votes: usize,
    min_support: usize,
    min_views: usize,
    trim_slivers: bool,
    /// Octree levels by which the scalpel's leaves were refined (`--blade-levels`).
    blade_levels: u32,
    /// Why the reconstruction stopped before its last frame, when something failed.
    stopped: Option<String>,
    counters: Counters,
    /// Camera images and frame sets that could not be used and were left out.
    faults: Faults,
    accuracy: Vec<LabelAccuracy>,
    silhouette_consistency: Vec<Consistency>,
    view_disagreement: ViewDisagreement,
    /// How the segmented masks were labelled (null with mask files).
    labelling: Option<LabellingReport>,
    pose: PoseReport,
    timings: Timings,
    /// Figures of this report that were not finite numbers (written as null): the command exits
    /// with an error naming them.
    non_finite: Vec<String>,
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let t_start = Instant::now();
    let mut carver = Carver::new(args.backend.open()?.as_ref())?;
    let ds = Dataset::open(&args.dataset)?;
    let volume = crate::volume::resolve(args.workspace, Some(&ds), ds.rig())?;
    checks::voxel(args.voxel, volume.aabb.extent())?;
    let use_files = checks::masks_from_files(&ds, args.masks)?;
    let range = parse_frames(args.frames.as_deref(), ds.meta().frame_count)?;
    let params = HullParams {
        carve_votes: args.carve_votes,
        min_views: MIN_VIEWS,
        trim_slivers: args.trim_slivers,
        blade_levels: args.blade_levels,
        ..HullParams::new(volume.aabb, args.voxel)
    };
    let tool = ds.tool()?;
    let mut labelling = if use_files {
        None
    } else {
        let mut labelling = Labelling::new(&ds, tool.as_ref(), params.clone(), &args.label_frames, args.labels)?;
        crate::weak::set_up(&mut labelling, &ds, args.weak_foreground, args.confirm_weak_foreground)?;
        labelling.set_search_gap(args.search_gap);
        Some(labelling)
    };
    let mut counters = Counters::default();
    // True poses, each checked: a matrix that is not a rigid pose (a NaN, a rotation entry of
    // 1e19) scores nothing, and is counted.
    let mut poses: BTreeMap<u64, Isometry3<f64>> = BTreeMap::new();
    for p in ds.truth_poses()?.unwrap_or_default() {
        match rigid_from_matrix(&p.tool_to_world) {
            Ok(iso) => {
                poses.entry(p.frame).or_insert(iso);
            }
            Err(e) => {
                if counters.truth_poses_refused == 0 {
                    eprintln!(
                        "warning: {}: frame {}: not a rigid pose ({e}); frames with such a true pose are not scored",
                        ds.root().join("truth").join("poses.jsonl").display(),
                        p.frame
                    );
                }
                counters.truth_poses_refused += 1;
            }
        }
    }
    let template = tool
        .as_ref()
        .map(Template::new)
        .transpose()
        .with_context(|| ds.root().join("tool.json").display().to_string())?;
    // Mask files only: a colour-labelled segmentation fitted here keeps the offset at 0 as the
    // geometric labeller's fit does.
    let tracking = TrackerParams { outline_offset: args.outline_offset && use_files, ..TrackerParams::default() };
    let mut tracker = template.clone().map(|t| Tracker::new(t, tracking));
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut pose_writer = PoseWriter::create(&args.out.join("poses.jsonl"))?;
    let camera_names = ds.rig().cameras.iter().map(|c| c.name.clone());
    let mut pose_report = PoseReport::new(template.is_some()).with_cameras(camera_names);
    let rec = match &args.rrd {
        Some(path) => {
            let rec = hullcut_viz::open_recording("hullcut-reconstruct", &hullcut_viz::Sink::File(path.clone()))?;
            hullcut_viz::log_world(&rec)?;
            crate::volume::log(&rec, &volume)?;
            let cams = CameraLogger::new(&rec, ds.rig())?;
            Some((rec, cams))
        }
        None => None,
    };
    for (_, name) in label::NAMED {
        let dir = args.out.join("hull").join(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let frames: Vec<u64> = ds.frame_numbers().into_iter().filter(|f| range.contains(f)).collect();
    let pb = bar(frames.len() as u64, "carving");
    let mut t = StageTimes::default();
    let mut accuracy: Vec<LabelAccuracy> = label::NAMED
        .iter()
        .map(|&(_, name)| LabelAccuracy { label: name.to_owned(), ..LabelAccuracy::default() })
        .collect();
    let mut consistency: Vec<Consistency> =
        ds.meta().cameras.iter().map(|c| Consistency { camera: c.clone(), ..Consistency::default() }).collect();
    let mut disagreement = ViewDisagreement::new(&ds.meta().cameras);
    let mut resolution = 0;
    let mut faults = Faults::default();
    let mut flushed = Instant::now();
    let mut process = |frame: u64| -> anyhow::Result<()> {
        let t_frame = Instant::now();
        let clock = Instant::now();
        // A camera image that cannot be used is left out of its frame set; a frame set with no
        // usable image is left out whole, its pose line saying so.
        let (set, frame_faults) = checks::read_frame_set(&ds, frame, use_files || ds.has_masks());
        for fault in &frame_faults {
            tracing::warn!("left out: {fault}");
        }
        faults.add(frame_faults, set.is_some());
        let Some(mut set) = set else {
            let mut e = no_tool_estimate(frame, ds.frame_timestamp(frame).unwrap_or(0));
            e.reason = Some("the frame set could not be read (the report lists why)".to_owned());
            pose_writer.write(&e)?;
            pose_report.push(&e, None, None);
            pb.inc(1);
            return Ok(());
        };
        t.read.push(clock.elapsed());
        // Masks read with the images are the truth. Segmenting moves them aside (the segmented masks
        // take their place, nothing is copied); with mask files they are what is carved.
        let mut set_aside: Vec<Option<image::GrayImage>> = Vec::new();
        // Segmenting carves the foreground's hull and fits the tool into it to label the views: the
        // hull, its cells near the tool labelled scalpel, is this frame's.
        let (mut labelled_hull, mut labelled_estimate) = (None, None);
        if let Some(labelling) = &mut labelling {
            let clock = Instant::now();
            let labelled = hullcut_pipeline::on_pool(|| labelling.label(&set, &mut carver))?;
            let carve_ms = labelled.carve_ms;
            t.segment.push(clock.elapsed().saturating_sub(Duration::from_secs_f64(carve_ms * 1e-3)));
            t.segment_foreground.push(Duration::from_secs_f64(labelled.foreground_ms * 1e-3));
            t.segment_evidence.extend(labelled.stats.as_ref().map(|s| Duration::from_secs_f64(s.evidence_ms * 1e-3)));
            t.carve.push(Duration::from_secs_f64(carve_ms * 1e-3));
            for (view, mask) in set.views.iter_mut().zip(labelled.masks) {
                set_aside.push(view.as_mut().and_then(|v| std::mem::replace(&mut v.mask, mask)));
            }
            labelled_hull = labelled.occupancy;
            labelled_estimate = labelled.estimate;
        }
        let clock = Instant::now();
        let masks: Vec<Option<&image::GrayImage>> =
            set.views.iter().map(|v| v.as_ref().and_then(|v| v.mask.as_ref())).collect();
        let views = silhouettes(ds.rig(), &masks).with_context(|| format!("frame {frame}"))?;
        let occ = match labelled_hull {
            Some(occ) => occ,
            None => {
                let occ = hullcut_pipeline::on_pool(|| carver.carve(&views, &params))
                    .with_context(|| format!("frame {frame}"))?;
                t.carve.push(clock.elapsed());
                occ
            }
        };
        resolution = occ.resolution;
        counters.frame_sets += 1;
        counters.views_missing += occ.stats.views_missing;
        counters.cells_kept += occ.cells.len() as u64;
        counters.kept_against_refutation += occ.stats.kept_against_refutation;
        counters.unlabelled_cells += occ.stats.unlabelled_cells;
        counters.unseen_cells += occ.stats.unseen_cells;
        counters.slivers_trimmed += occ.stats.slivers_trimmed;
        counters.leaves_refined += occ.stats.leaves_refined;
        counters.footprint_tests += occ.stats.footprint_tests;
        disagreement.add(&occ.stats);

        let clock = Instant::now();
        let mut grids = Vec::new();
        for &(l, name) in &label::NAMED {
            let grid = DenseGrid::from_occupancy(&occ, Some(l));
            let mesh = grid.as_ref().map(DenseGrid::surface);
            match &mesh {
                Some(mesh) => {
                    let path = args.out.join("hull").join(name).join(format!("{frame:06}.ply"));
                    hullcut_dataset::write_ply(&path, mesh)?;
                    counters.meshes_written += 1;
                }
                None => counters.empty_label_frames += 1,
            }
            grids.push((l, name, grid, mesh));
        }
        t.surface.push(clock.elapsed());

        let clock = Instant::now();
        let inputs: Vec<Option<ViewInput>> = ds
            .rig()
            .cameras
            .iter()
            .zip(&masks)
            .zip(&set.views)
            .map(|((camera, mask), v)| mask.map(|mask| ViewInput { camera, mask, image: v.as_ref().map(|v| &v.image) }))
            .collect();
        // Segmented with the tool's geometry: the labelling's tracked fit is the pose, as in
        // `hullcut run`; with mask files, the blade is fitted to them.
        let from_labelling = labelled_estimate.is_some();
        let estimate = match (labelled_estimate, &mut tracker) {
            (Some(estimate), _) => estimate,
            (None, Some(tracker)) => {
                hullcut_pipeline::on_pool(|| tracker.update(frame, set.timestamp_ns, &occ, &inputs))
            }
            (None, None) => no_tool_estimate(frame, set.timestamp_ns),
        };
        t.pose.push(clock.elapsed());
        // The labelling's fit is timed in `segment`; its parts are not the pose stage's.
        let part = |ms: f64| {
            if from_labelling { Duration::ZERO } else { Duration::try_from_secs_f64(ms * 1e-3).unwrap_or_default() }
        };
        t.pose_evidence.push(part(estimate.diagnostics.evidence_ms));
        t.pose_fit.push(part(estimate.diagnostics.fit_ms));
        pose_writer.write(&estimate)?;
        let truth_iso = poses.get(&frame);
        if let Some(template) = &template {
            let error = |p: Option<&hullcut_pose::BladePose>| {
                p.zip(truth_iso).map(|(p, truth)| pose_error(p, template, truth)).filter(finite_error)
            };
            if truth_iso.is_some() {
                pose_report.push(&estimate, error(estimate.pose.as_ref()), error(estimate.fitted.as_ref()));
            }
        }
        if truth_iso.is_none() {
            pose_report.push(&estimate, None, None);
        }

        if frame.is_multiple_of(args.accuracy_every) {
            let clock = Instant::now();
            let truth_masks: Vec<Option<&image::GrayImage>> =
                if labelling.is_some() { set_aside.iter().map(Option::as_ref).collect() } else { masks.clone() };
            let exact = exact_hull(&ds, &truth_masks, &occ, &params, labelling.is_some())?;
            for (c, view) in consistency.iter_mut().zip(&views) {
                if let Some(iou) = view.as_ref().and_then(|v| silhouette_consistency(&occ, v)).filter(|x| x.is_finite())
                {
                    c.values.push(iou);
                }
            }
            for (k, (l, name, grid, mesh)) in grids.iter().enumerate() {
                let truth = truth_mesh(&ds, name, frame, tool.as_ref(), truth_iso)?;
                let (exact, measurable) = match &exact {
                    Exact::NoMasks => (None, true),
                    Exact::Carved(occ) => (Some(occ), true),
                    Exact::NotMeasurable => (None, false),
                };
                if truth.is_some() && !measurable {
                    accuracy[k].exact_hull_not_measurable += 1;
                }
                score(&mut accuracy[k], grid.as_ref(), mesh.as_ref(), truth.as_ref(), exact, *l, occ.leaf_size);
            }
            t.accuracy.push(clock.elapsed());
            if let Some((rec, _)) = &rec {
                hullcut_viz::set_frame(rec, i64::try_from(frame).unwrap_or(i64::MAX));
                for a in &accuracy {
                    if let Some(iou) = a.iou.last() {
                        hullcut_viz::log_scalar(rec, &format!("metrics/accuracy/{}_iou", a.label), *iou)?;
                    }
                }
            }
        }
        if let Some((rec, cams)) = &rec {
            log_hull(rec, cams, &set, &occ, &grids, frame, args.rrd_every, 1)?;
            let last = |d: &[Duration]| d.last().map_or(0.0, |d| d.as_secs_f64() * 1e3);
            hullcut_viz::log_scalar(rec, "metrics/time/carve", last(&t.carve))?;
            hullcut_viz::log_scalar(rec, "metrics/time/surface", last(&t.surface))?;
            if let (Some(tool), Some(truth)) = (&tool, truth_iso) {
                log_tool(rec, "truth", tool, &truth.to_homogeneous())?;
            }
            if let (Some(template), Some(truth)) = (&template, truth_iso) {
                log_blade(rec, "truth", &hullcut_pose::BladePose::new(template, *truth))?;
            }
            match estimate.pose.as_ref().filter(|p| p.is_finite()) {
                Some(p) => log_blade(rec, "estimate", p)?,
                None => hullcut_viz::log_clear(rec, "world/tool/estimate")?,
            }
            hullcut_viz::log_scalar(rec, "metrics/pose/confidence", estimate.confidence)?;
            hullcut_viz::log_scalar(rec, "metrics/pose/outline_offset_px", estimate.diagnostics.fit_offset_px)?;
            hullcut_viz::log_scalar(rec, "metrics/pose/valid", f64::from(u8::from(estimate.valid)))?;
            crate::logging::log_pose_views(rec, &estimate.diagnostics, ds.rig())?;
            hullcut_viz::log_scalar(rec, "metrics/time/pose", t.pose.last().map_or(0.0, |d| d.as_secs_f64() * 1e3))?;
            // A recording that cannot be written (a full disk) shows only when flushed.
            if flushed.elapsed() >= FLUSH_EVERY {
                hullcut_viz::flush(rec).context("writing the recording")?;
                flushed = Instant::now();
            }
        }
        t.total.push(t_frame.elapsed());
        pb.inc(1);
        Ok(())
    };
    // The first error stops the frames; everything before it is flushed and reported.
    let mut stopped = None;
    for &frame in &frames {
        if let Err(e) = process(frame) {
            stopped = Some(e.context(format!("stopped at frame {frame}")));
            break;
        }
    }
    pb.finish_and_clear();
    let stopped = [
        stopped,
        pose_writer.finish().err(),
        rec.as_ref().and_then(|(rec, _)| hullcut_viz::flush(rec).err().map(anyhow::Error::new)),
    ]
    .into_iter()
    .flatten()
    .next();
    pose_report.finish();
    for a in &mut accuracy {
        a.frames = a.iou.len();
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        a.iou_mean = mean(&a.iou);
        a.iou_min = a.iou.iter().copied().reduce(f64::min);
        a.exact_hull_iou_mean = mean(&a.exact);
        a.exact_hull_truth_iou_mean = mean(&a.exact_truth);
        a.chamfer_mm_mean = mean(&a.chamfer);
        a.hausdorff_mm_max = a.hausdorff.iter().copied().reduce(f64::max);
    }
    for c in &mut consistency {
        c.frames = c.values.len();
        c.iou_mean = (!c.values.is_empty()).then(|| c.values.iter().sum::<f64>() / c.values.len() as f64);
        c.iou_min = c.values.iter().copied().reduce(f64::min);
    }
    let carve_t = StageTiming::from_durations(&t.carve);
    println!(
        "carved {} frame sets at {resolution}³ ({:.2} mm leaves): carve {:.2} ms, surfaces {:.2} ms per frame (mean)",
        counters.frame_sets,
        params.leaf_size * 1e3,
        carve_t.mean_ms,
        StageTiming::from_durations(&t.surface).mean_ms
    );
    for a in accuracy.iter().filter(|a| a.frames > 0) {
        println!(
            "  {:8} IoU {} with the truth (the exact visual hull reaches {}; IoU with it {}), Chamfer {} mm, Hausdorff {} mm over {} frames{}",
            a.label,
            figure(a.iou_mean, 3),
            figure(a.exact_hull_truth_iou_mean, 3),
            figure(a.exact_hull_iou_mean, 3),
            figure(a.chamfer_mm_mean, 2),
            figure(a.hausdorff_mm_max, 2),
            a.frames,
            if a.exact_hull_not_measurable > 0 {
                format!(
                    " ({} frame(s) with no exact visual hull to compare: see the report)",
                    a.exact_hull_not_measurable
                )
            } else {
                String::new()
            }
        );
    }
    println!("{}", pose_report.summary());
    for line in [pose_report.sight_summary(), pose_report.rig_hint()].into_iter().flatten() {
        println!("{line}");
    }
    disagreement.finish();
    if let Some(line) = disagreement.summary() {
        println!("{line}");
    }
    let (faults_any, faults_summary) = (faults.any(), faults.summary());
    let mut non_finite = Vec::new();
    if let Some(path) = &args.report {
        let mut report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "reconstruction".to_owned(),
            provenance: Provenance::current(),
            dataset: args.dataset.display().to_string(),
            out: args.out.display().to_string(),
            frames: [range.start, range.end],
            backend: args.backend,
            masks: if use_files { "files" } else { "segment" }.to_owned(),
            outline_offset: args.outline_offset && use_files,
            workspace: volume.clone(),
            voxel_m: params.leaf_size,
            resolution,
            carve_votes: params.carve_votes,
            min_support: params.min_support,
            min_views: params.min_views,
            trim_slivers: params.trim_slivers,
            blade_levels: params.blade_levels,
            stopped: stopped.as_ref().map(|e| format!("{e:#}")),
            counters,
            faults,
            accuracy,
            silhouette_consistency: consistency,
            view_disagreement: disagreement,
            labelling: labelling.as_mut().map(|l| l.settle().map(|()| l.report())).transpose()?,
            pose: pose_report,
            timings: Timings {
                read: StageTiming::from_durations(&t.read),
                segment: (!t.segment.is_empty()).then(|| StageTiming::from_durations(&t.segment)),
                segment_foreground: (!t.segment_foreground.is_empty())
                    .then(|| StageTiming::from_durations(&t.segment_foreground)),
                segment_evidence: (!t.segment_evidence.is_empty())
                    .then(|| StageTiming::from_durations(&t.segment_evidence)),
                carve: carve_t,
                surface: StageTiming::from_durations(&t.surface),
                pose: StageTiming::from_durations(&t.pose),
                pose_evidence: StageTiming::from_durations(&t.pose_evidence),
                pose_fit: StageTiming::from_durations(&t.pose_fit),
                accuracy: StageTiming::from_durations(&t.accuracy),
                total: StageTiming::from_durations(&[t_start.elapsed()]),
            },
            non_finite: Vec::new(),
        };
        non_finite = checks::non_finite_fields(&report);
        report.non_finite.clone_from(&non_finite);
        write_json(path, &report)?;
    }
    if let Some(e) = stopped {
        let kept = if args.report.is_some() { " (the outputs and the report hold the frames before it)" } else { "" };
        return Err(e.context(format!("reconstruction stopped{kept}")));
    }
    if !non_finite.is_empty() {
        bail!("figures that are not finite numbers (written as null in the report): {}", non_finite.join(", "));
    }
    if faults_any {
        bail!("{faults_summary}");
    }
    Ok(())
}

/// How often a recording is flushed, to find a sink that cannot write (a full disk).
const FLUSH_EVERY: Duration = Duration::from_secs(2);

/// Leaves of a quarter of the voxel the exact visual hull may carve at most: over this (a hull
/// the size of the working volume) it is not measurable, counted, not carved for minutes.
pub const MAX_EXACT_LEAVES: f64 = 8_388_608.0;

/// The exact visual hull of a frame, or why it was not carved.
enum Exact {
    /// No truth masks: nothing to compare.
    NoMasks,
    /// Not measurable: a view's truth mask is one label everywhere (that view bounds nothing),
    /// or the hull holds more than [`MAX_EXACT_LEAVES`] quarter leaves.
    NotMeasurable,
    /// The truth masks carved at a quarter leaf.
    Carved(Occupancy),
}

/// The exact visual hull: the truth masks carved at a quarter leaf, inside the cells that carving
/// the truth masks at this leaf keeps (carving is conservative), so it costs a few times one
/// carving instead of a whole octree four levels deeper; not measured when a truth mask is
/// all hand or all scalpel, or beyond [`MAX_EXACT_LEAVES`].
fn exact_hull(
    ds: &Dataset,
    truth_masks: &[Option<&image::GrayImage>],
    occ: &Occupancy,
    params: &HullParams,
    segmented: bool,
) -> anyhow::Result<Exact> {
    if truth_masks.iter().all(Option::is_none) {
        return Ok(Exact::NoMasks);
    }
    let one_label = |m: &image::GrayImage| label::NAMED.iter().any(|&(l, _)| m.as_raw().iter().all(|&p| p == l));
    if truth_masks.iter().flatten().any(|m| one_label(m)) {
        return Ok(Exact::NotMeasurable);
    }
    let truth_views = silhouettes(ds.rig(), truth_masks)?;
    let coarse = if segmented { Some(carve(&truth_views, params)?) } else { None };
    let seeds = coarse.as_ref().unwrap_or(occ);
    let fine = HullParams { leaf_size: params.leaf_size / 4.0, ..params.clone() };
    let leaves: f64 = seeds.cells.iter().map(|c| (c.size / fine.leaf_size).powi(3)).sum();
    if !(leaves.is_finite() && leaves <= MAX_EXACT_LEAVES) {
        return Ok(Exact::NotMeasurable);
    }
    Ok(Exact::Carved(carve_within(&truth_views, &fine, &seeds.cells)?))
}

/// Whether a pose error is a number in every field (a NaN is not measured, not an error of 0).
fn finite_error(e: &hullcut_pose::PoseError) -> bool {
    e.normal_deg.is_finite() && e.edge_mm.is_finite() && e.tip_mm.is_finite()
}

/// A figure for the terminal: `n/a` when it was not measured.
fn figure(value: Option<f64>, decimals: usize) -> String {
    value.filter(|v| v.is_finite()).map_or_else(|| "n/a".to_owned(), |v| format!("{v:.decimals$}"))
}

#[derive(Debug, Default)]
struct StageTimes {
    read: Vec<Duration>,
    segment: Vec<Duration>,
    segment_foreground: Vec<Duration>,
    segment_evidence: Vec<Duration>,
    carve: Vec<Duration>,
    surface: Vec<Duration>,
    pose: Vec<Duration>,
    pose_evidence: Vec<Duration>,
    pose_fit: Vec<Duration>,
    accuracy: Vec<Duration>,
    total: Vec<Duration>,
}

/// The true shape of a label at a frame: the dataset's truth mesh, or for the scalpel its tool
/// mesh at the true pose.
fn truth_mesh(
    ds: &Dataset,
    name: &str,
    frame: u64,
    tool: Option<&hullcut_dataset::ToolGeometry>,
    pose: Option<&Isometry3<f64>>,
) -> anyhow::Result<Option<Mesh>> {
    if let Some(mesh) = ds.read_truth_mesh(name, frame)? {
        return Ok(Some(mesh));
    }
    Ok(match (name, tool, pose) {
        ("scalpel", Some(tool), Some(pose)) => Some(Mesh {
            vertices: tool.mesh.vertices.iter().map(|p| pose * p).collect(),
            triangles: tool.mesh.triangles.clone(),
        }),
        _ => None,
    })
}

/// Scores one label of one frame against its truth. A figure that cannot be measured (no hull
/// surface, a truth mesh with a vertex at infinity) or comes out not finite is left out and
/// counted in `not_measured`, never averaged in as NaN.
fn score(
    acc: &mut LabelAccuracy,
    grid: Option<&DenseGrid>,
    mesh: Option<&Mesh>,
    truth: Option<&Mesh>,
    exact: Option<&Occupancy>,
    l: u8,
    leaf: f64,
) {
    let Some(truth) = truth else { return };
    const SAMPLES: usize = 8000;
    let finite = |v: &f64| v.is_finite();
    let mut missed = false;
    match volumetric_iou(grid, truth, SAMPLES).filter(finite) {
        Some(iou) => acc.iou.push(iou),
        None => missed = true,
    }
    if let Some(exact) = exact {
        let exact_grid = DenseGrid::from_occupancy(exact, Some(l));
        if let (Some(g), Some(e)) = (grid, exact_grid.as_ref())
            && let Some(iou) = grid_iou(g, e, SAMPLES).filter(finite)
        {
            acc.exact.push(iou);
        }
        if let Some(iou) = volumetric_iou(exact_grid.as_ref(), truth, SAMPLES).filter(finite) {
            acc.exact_truth.push(iou);
        }
    }
    let distance = mesh.and_then(|mesh| {
        let spacing = leaf;
        let ours = sample_surface(mesh, spacing);
        let theirs = outer_surface_samples(truth, spacing);
        surface_distance(&ours, &theirs, 2.0 * leaf)
    });
    match distance.filter(|d| d.chamfer.is_finite() && d.hausdorff.is_finite()) {
        Some(d) => {
            acc.chamfer.push(d.chamfer * 1e3);
            acc.hausdorff.push(d.hausdorff * 1e3);
        }
        None => missed = true,
    }
    acc.not_measured += usize::from(missed);
}

/// Logs one frame set's images and masks and hull leaves (every `every`-th frame) and hull
/// meshes (every `mesh_every`-th frame), on the frame and capture-time timelines.
#[allow(clippy::too_many_arguments)] // what one frame logs, and its two decimation rates
pub(crate) fn log_hull(
    rec: &hullcut_viz::RecordingStream,
    cams: &CameraLogger,
    set: &FrameSet,
    occ: &Occupancy,
    grids: &[(u8, &str, Option<DenseGrid>, Option<Mesh>)],
    frame: u64,
    every: u64,
    mesh_every: u64,
) -> anyhow::Result<()> {
    hullcut_viz::set_frame(rec, i64::try_from(frame).unwrap_or(i64::MAX));
    hullcut_viz::set_capture_time_ns(rec, set.timestamp_ns);
    let colours = |l: u8| if l == label::HAND { [70, 130, 255, 255] } else { [255, 200, 40, 255] };
    if frame.is_multiple_of(every) {
        cams.log_frame_set(rec, set)?;
        for &(l, name) in &label::NAMED {
            let centres: Vec<[f32; 3]> = occ
                .cells
                .iter()
                .filter(|c| c.has(l))
                .map(|c| c.centre())
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect();
            hullcut_viz::log_points3d(
                rec,
                &format!("world/hull/{name}/leaves"),
                &centres,
                colours(l),
                (occ.leaf_size / 2.0) as f32,
            )?;
        }
    }
    for (l, name, _, mesh) in grids.iter().filter(|_| frame.is_multiple_of(mesh_every)) {
        if let Some(mesh) = mesh {
            let v: Vec<[f32; 3]> = mesh.vertices.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
            hullcut_viz::log_mesh3d(rec, &format!("world/hull/{name}/mesh"), &v, &mesh.triangles, colours(*l))?;
        }
    }
    Ok(())
}
