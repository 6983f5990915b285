//! `hullcut run`: the whole pipeline, frame sets in, a cut organ out.

mod logger;
mod snapshot;
pub(crate) mod tissue_log;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use hullcut_dataset::Dataset;
use hullcut_hull::HullParams;
use hullcut_pipeline::{FrameSource, StageTimes, stages, tissue};
use hullcut_pose::{PoseError, Template, pose_error, rigid_from_matrix};
use hullcut_sim::{FarField, HybridParams, HybridSteps};
use hullcut_synth::{SceneConfig, SceneKind, synthesize};
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::backend::{Backend, Carver};
use crate::commands::reconstruct::checks::{self, Faults};
use crate::frames::parse_frames;
use crate::labelling::{LabelMethod, Labelling};
use crate::logging::CameraLogger;
use crate::pose_out::PoseReport;
use crate::progress::bar;
use crate::report::{Provenance, SCHEMA_VERSION, StageTiming, write_json};
use crate::volume::{MIN_VIEWS, WorkspaceArg};
use crate::weak::WeakArg;

/// Run the whole pipeline: segment → hull → pose → cut → simulate, logged to rerun.
///
/// Frame sets come from a recorded dataset (--dataset) or, without one, from the built-in scene:
/// a synthetic six-camera recording of a gloved hand cutting with a scalpel (`hullcut synth`'s
/// `resect` scene: two strokes along one line cut the tip off the organ's left lobe, the second
/// ending at about 4 s, then cut strokes 5 to 25 mm deep), rendered once at start-up into a
/// temporary folder (with a progress bar) and replayed. The frame sets are decoded into memory
/// before the loop when they fit in --preload-mib (decoding is timed apart, `decode`), else read
/// as they are needed. The stages (the hullcut-pipeline crate) run as threads joined by bounded
/// channels: reading, hull (segmentation when the masks are not files, octree carving,
/// surfaces), pose (the tool's blade template fitted to the scalpel silhouettes, tracked, refused
/// when not trusted; with segmented masks, the segmentation's own tracked fit of the tool, whose
/// agreement bounds are looser), and tissue (the blade's swept surface between consecutive
/// trusted poses cuts the organ by the virtual node algorithm; TLED moves it under gravity,
/// resting on the table with friction, pieces kept out of each other; the hand's hull pushes it
/// aside where it presses on it). Untrusted poses never cut; a sweep bridges refused frame sets
/// only between trusted poses at most 0.134 s apart (three refused at 30 fps). At most --queue frame sets are in the stages at once, so no queue grows and the latency
/// (from a frame set's capture to its cut surface) stays bounded. Without --realtime every frame
/// set is processed, the next one taken when there is room; with --realtime the reader keeps to
/// the capture timestamps and a frame set that finds no room is replaced by the next one, the
/// older dropped and counted in the report; it waits at most 5 s between two frame sets: a longer
/// gap in the capture times (or one backwards) is not waited out but counted
/// (counters.realtime_gaps_skipped). Logging (rerun, --export-meshes, --snapshots) runs on its
/// own thread behind a queue of 8 frame sets: without --realtime a full queue makes the loop wait
/// (timed: timings.log_wait), with it the oldest frame set waiting to be logged is dropped
/// (counters.log_dropped).
///
/// Bad input: a camera image that cannot be read (a corrupt PNG, a camera whose files stop
/// mid-recording) or a mask with unknown labels leaves that view out of its frame set (the whole
/// frame set when no view is left); the run goes on, the report lists every fault (faults), and
/// the run exits with an error at the end saying so. A stage that fails or a recording that
/// cannot be written (a full disk) stops the run with the reason; the recording and the report
/// still hold every frame set processed before. A report figure that is not a finite number is
/// written as null, named in the report's non_finite, and makes the run exit with an error.
///
/// The tissue: --tissue organ (the built-in two-lobed liver-like organ, 15 x 10 x 6 cm, resting on
/// the table at z = 0 under the tool), organ-large (the same organ 1.2 times larger, 18 x 12 x 7.2
/// cm, an adult liver's size: 106k lattice nodes at --cell 0.002; with --operational-radius 0.03
/// --far-field frozen only the cells near the blade are stepped; the built-in scene's strokes are
/// then scaled with it) or a PLY/OBJ mesh in world metres; --cell sets its lattice spacing. Material: E = 3 kPa, ν = 0.45, 1000 kg/m³ (liver-like).
///
/// Writes: the rerun recording (hullcut-run.rrd in the current folder unless --rrd, --spawn or
/// --connect says otherwise): images (JPEG) and label masks under world/cams/NAME, hull leaves
/// and meshes under world/hull/LABEL and the lattice nodes under world/tissue/nodes every
/// --rrd-every frames; every frame the blade's estimate and truth under
/// world/tool/{estimate,truth} and the swept blade surface under world/tissue/cut; the pieces'
/// surfaces (cut faces included) under world/tissue/surface whenever they changed (a cut, or a
/// vertex moved by more than 0.2 mm); stage timings under metrics/time/STAGE and accuracy under
/// metrics/accuracy/NAME; when segmenting, where each frame set's labels came from under
/// labelling/source, the learned colours under metrics/appearance/LABEL/{colour,pixels} and the
/// share of the drawn blade they call the hand's under metrics/appearance/blade_as_hand, the
/// possible shadows given back to the table under metrics/shadows/on_table, the pixels an
/// untrusted fit that agreed with the silhouettes taught the colours (before a trusted one did)
/// under metrics/appearance/taught, the pixels each frame set's segmentation tested under
/// metrics/segment/pixels_tested and whether only near the last hull (1) or in the whole
/// rectangle of the box carved in (0) under metrics/segment/near_hull, the weak pixels its
/// hysteresis joined to the foreground under metrics/segment/weak_joined, the pixels enclosed
/// by its foreground filled as holes not of their background's colour under
/// metrics/segment/holes_filled, the time each
/// trusted frame set's lesson (the colours learned from it beside the loop) took under
/// metrics/segment/lesson_ms; on
/// the `frame` and `capture_time` timelines (a file of more than 3,600
/// frame sets is written without rerun's chunk index, which would grow in memory all run long:
/// the viewer reads it from the start). REPORT (JSON) with --report: per-stage timings, sustained
/// fps, latency, each stage against its 60 fps budget, pose accuracy where the dataset has truth,
/// every drop, refusal and skipped sweep counted, the tissue's pieces, memory every minute. With --export-meshes DIR:
/// DIR/NNNNNN/pieceK.ply, the organ's pieces at every frame (world metres, closed). With
/// --snapshots DIR: PNGs drawn by hullcut itself at chosen frames, without a viewer.
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// A recorded dataset to replay; without it, the built-in scene.
    #[arg(long, value_name = "DIR")]
    dataset: Option<PathBuf>,
    /// Log to this .rrd file.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["spawn", "connect"])]
    rrd: Option<PathBuf>,
    /// Start the rerun viewer found on PATH and stream to it.
    #[arg(long, conflicts_with = "connect")]
    spawn: bool,
    /// Stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy.
    #[arg(long, value_name = "URL")]
    connect: Option<String>,
    /// Frames: A:B (half-open) or N (the first N).
    #[arg(long, value_name = "A:B|N")]
    frames: Option<String>,
    /// Pace the replay to the capture timestamps (a stage that falls behind drops frame sets).
    #[arg(long)]
    realtime: bool,
    /// Compute backend: `cpu` (rayon) or `gpu` (wgpu: hull carving, and the tissue's TLED steps
    /// with contacts; segmentation, pose and the hybrid model stay on the CPU). A batch in which a
    /// cell inverts is redone on the CPU, counted in the report's tissue.gpu.
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// The tissue: `organ`, `organ-large` or a PLY/OBJ mesh in world metres.
    #[arg(long, value_name = "NAME|MESH", default_value = "organ")]
    tissue: String,
    /// Lattice spacing of the tissue, metres.
    #[arg(long, value_name = "METRES", default_value_t = 0.005, value_parser = super::positive)]
    cell: f64,
    /// The hybrid model: lattice cells within this distance of the blade's sweep (and cut cells
    /// and their neighbours) run TLED; the others sleep once at rest (`--far-field frozen`, the
    /// default) or are moved by FLSM matched to the material (`--far-field flsm`); cells leave the
    /// region once the blade has left and they have come to rest. Without it every cell is TLED.
    #[arg(long, value_name = "METRES", value_parser = non_negative)]
    operational_radius: Option<f64>,
    /// With --operational-radius: what moves the cells outside the operational region.
    #[arg(long, value_enum, value_name = "MODEL", default_value_t = FarFieldArg::Frozen, requires = "operational_radius")]
    far_field: FarFieldArg,
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
    /// Leaf (voxel) size of the hull, metres. With segmented masks, while the tool's track
    /// predicts it closely (the frame set before trusted, at 20 fps or more, the tool moved at most
    /// 1 cm), the hull is this fine within 1.5 cm of the predicted tool and twice as coarse
    /// elsewhere (the hand's bulk needs no finer; `labelling.counters.hull_fine_near_tool` in the
    /// report counts such frame sets).
    #[arg(long, value_name = "METRES", default_value_t = 0.4 / 128.0)]
    voxel: f64,
    /// Centre the hull on the surface: drop the outer layer of leaves over a solid core
    /// (`reconstruct --trim-slivers`).
    #[arg(long)]
    trim_slivers: bool,
    /// Carve the leaves of the hull carrying the scalpel label again this many octree levels finer (0-3): a
    /// blade thinner than a leaf is then described at half (a quarter, an eighth) of the leaf
    /// while the hand keeps it (`reconstruct --blade-levels`). Costs a few ms per level at 1-2 mm leaves.
    #[arg(long, value_name = "LEVELS", default_value_t = 0,
          value_parser = clap::builder::RangedU64ValueParser::<u32>::new().range(0..=u64::from(hullcut_hull::MAX_REFINE_LEVELS)))]
    blade_levels: u32,
    /// The working volume carved, world metres (default: dataset.toml's `workspace`, else the
    /// space at least three cameras see, above the table when the rig's frame is a table's).
    #[arg(long, value_name = "MINX,MINY,MINZ,MAXX,MAXY,MAXZ", allow_hyphen_values = true)]
    workspace: Option<WorkspaceArg>,
    /// Replay the frame sets this many times, each pass's capture times following the last
    /// pass's (a long run from a short recording: memory over 10 minutes). Later passes log on
    /// the `frame` timeline after the first; snapshots come from the first pass only.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    repeat: u64,
    /// Frame sets of the built-in scene (at 30 fps).
    #[arg(long, value_name = "N", default_value_t = 180, value_parser = clap::value_parser!(u64).range(1..))]
    scene_frames: u64,
    /// Seed of the built-in scene.
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Frame sets in the stages at once (each queue's bound): more lets the stages overlap more
    /// (throughput), fewer keeps the latency down.
    #[arg(long, value_name = "N", default_value_t = hullcut_pipeline::stages::DEFAULT_IN_FLIGHT,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    queue: usize,
    /// Log images (JPEG), masks, hull leaves and meshes and the lattice nodes every N-th frame; the
    /// blade, the swept surface and the scalars every frame; the tissue surface whenever it has
    /// changed (a cut, or a vertex moved by more than 0.2 mm since it was last logged). When
    /// segmenting, the label masks of the frames logged are drawn on the logging thread (unless
    /// they teach the colours: then in the loop), those of the frames between not at all: N
    /// changes what the logging thread does beside the loop, not what the loop computes.
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    rrd_every: u64,
    /// Decode the frame sets into memory before the loop when they take at most this many MiB
    /// (0: never; they are then read as they are needed).
    #[arg(long, value_name = "MIB", default_value_t = 4096)]
    preload_mib: u64,
    /// Write a JSON report.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Write the organ's pieces as PLY meshes, per frame, under this folder.
    #[arg(long, value_name = "DIR")]
    export_meshes: Option<PathBuf>,
    /// Draw PNG snapshots into this folder: NNNNNN-views.png (the six views, masks tinted, the
    /// estimated cutting edge) and NNNNNN-organ.png (the cut organ through one camera).
    #[arg(long, value_name = "DIR")]
    snapshots: Option<PathBuf>,
    /// Frames to snapshot (comma-separated); default every --snapshot-every frames and the last.
    #[arg(long, value_name = "F,F,...", value_delimiter = ',')]
    snapshot_frames: Option<Vec<u64>>,
    /// Snapshot every N-th frame (when --snapshot-frames is not given).
    #[arg(long, value_name = "N", default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..))]
    snapshot_every: u64,
    /// The camera the organ snapshot is drawn through (default: the rig's first).
    #[arg(long, value_name = "NAME")]
    snapshot_camera: Option<String>,
}

/// `--far-field`: what moves the tissue outside the operational region.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum FarFieldArg {
    /// FLSM matched to the material, stepping with TLED (the seed paper's hybrid): slower than
    /// TLED everywhere on two cores and less accurate than `frozen` (`hullcut bench tissue`).
    Flsm,
    /// Nothing: cells at rest away from the blade and the cuts sleep, their nodes held where they
    /// are, until the region reaches them again (the tissue starts all TLED and settles first);
    /// the cheapest and most accurate far field measured (`hullcut bench tissue`).
    Frozen,
}

/// Counted events of a run.
#[derive(Debug, Default, Serialize, Deserialize)]
struct Counters {
    frame_sets_read: u64,
    /// Camera images missing from the frame sets processed (a camera that dropped frames or died).
    views_missing: u64,
    frame_sets_processed: u64,
    /// Dropped by --realtime: read, but a newer frame set came before there was room for it.
    frame_sets_dropped: u64,
    /// Processed frame sets not logged: with --realtime, the logging queue was full.
    log_dropped: u64,
    /// Gaps in the capture times over 5 s (or backwards) that --realtime did not wait out.
    realtime_gaps_skipped: u64,
    /// True poses in truth/poses.jsonl that are not rigid poses (not scored).
    truth_poses_refused: u64,
    poses_trusted: u64,
    poses_refused: u64,
    poses_held: u64,
    sweeps: u64,
    /// Trusted poses that did not sweep because the frames before were refused for too long.
    sweeps_skipped_after_refusal: u64,
    /// Sweeps across refused frame sets from the last trusted pose (at most 0.134 s back).
    sweeps_bridged: u64,
    /// Sweeps too large for the collision test's bounds (a step of metres), not cut.
    sweeps_refused: u64,
    edges_cut: u64,
    /// Frame sets after which the hand's hull was pressing on the tissue, and the most lattice
    /// nodes it pushed at once.
    frames_with_contact: u64,
    max_contact_nodes: u64,
    meshes_exported: u64,
    snapshots_written: u64,
    /// Frames whose tissue surface was logged, and skipped for not having changed visibly.
    tissue_surfaces_logged: u64,
    tissue_surfaces_unchanged: u64,
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
    /// `segment` over the frame sets whose fitted tool was drawn into the views in the loop only
    /// (an untrusted fit that may teach the colours; those logged with their images are drawn on
    /// the logging thread, `log_labels`, and the trusted ones that teach on the lesson's: `learn`).
    #[serde(default)]
    segment_drawn: Option<StageTiming>,
    /// A trusted frame set's lesson (its tool drawn, the colours learned from it) on a thread of
    /// its own beside the segmentation, per lesson (null when none was taken).
    #[serde(default)]
    learn: Option<StageTiming>,
    carve: StageTiming,
    surface: StageTiming,
    pose: StageTiming,
    collide: StageTiming,
    cut_topology: StageTiming,
    cut_surface: StageTiming,
    /// The hand's hull made an obstacle for the tissue.
    contact: StageTiming,
    deform: StageTiming,
    tissue_surface: StageTiming,
    /// Rerun logging, meshes and snapshots, on the logging thread.
    log: StageTiming,
    /// Of `log`, per frame set logged with its images and labelled by the tool's fit: drawing its
    /// label masks, left to the logging thread (null when there were none).
    #[serde(default)]
    log_labels: Option<StageTiming>,
    /// Times the loop waited for the logging queue (without --realtime), per wait.
    log_wait: StageTiming,
    /// From a frame set's capture (without --realtime: from when it was let into the stages) to
    /// its cut surface.
    latency: StageTiming,
    /// Of the latency, the wait for room in the stages (only --realtime waits).
    admission_wait: StageTiming,
    /// Decoding the frame sets into memory before the loop, per frame set (null when read as
    /// needed: `read` holds the decoding then).
    decode: Option<StageTiming>,
}

#[derive(Debug, Serialize, Deserialize)]
struct TissueReport {
    source: String,
    cell_m: f64,
    nodes: usize,
    cells: usize,
    fixed_nodes: usize,
    dt_s: f64,
    dt_critical_s: f64,
    pieces: usize,
    copies: usize,
    virtual_nodes: usize,
    copies_dropped: usize,
    /// Sliver copies torn off after they diverged (also in `copies_dropped`).
    copies_torn: usize,
    inverted_cells: usize,
    kinetic_energy_j: f64,
    simulated_s: f64,
    /// Why the tissue stopped, if it diverged.
    failure: Option<String>,
    /// The hybrid model's operational radius, metres (absent: TLED everywhere).
    operational_radius_m: Option<f64>,
    /// What moved the cells outside it (absent: TLED everywhere).
    far_field: Option<FarField>,
    /// Its TLED steps per FLSM step, FLSM stiffness and interface pull.
    hybrid: Option<HybridSteps>,
    /// Lattice cells run by TLED per frame set (all of them without the hybrid).
    tled_cells_mean: f64,
    tled_cells_max: usize,
    /// Times the operational region changed.
    region_changes: usize,
    /// The GPU backend's adapter and counts (null on the CPU).
    gpu: Option<hullcut_sim::GpuStats>,
    /// The table the tissue rests on.
    table: Option<hullcut_sim::Table>,
    /// Nodes on the table after the last step.
    table_contacts: usize,
    /// Contact planes between pieces at the end (nodes of one piece within a cell of another's
    /// surface), of them nodes found inside the other piece, and nodes put back on a plane after
    /// the last step.
    piece_contact_planes: usize,
    /// See `piece_contact_planes`.
    piece_contact_inside: usize,
    /// See `piece_contact_planes`.
    piece_contact_nodes: usize,
    /// Each piece at the end: volume, place, speed, nodes on the table.
    pieces_at_end: Vec<hullcut_sim::PieceState>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Report {
    schema_version: u32,
    kind: String,
    provenance: Provenance,
    source: String,
    seed: Option<u64>,
    frames: [u64; 2],
    /// Times the frames were replayed (`--repeat`).
    repeat: u64,
    backend: Backend,
    masks: String,
    /// `--outline-offset`: the blade's fit to mask files took the silhouettes as uniformly fatter
    /// or thinner than the tool.
    outline_offset: bool,
    workspace: hullcut_hull::WorkingVolume,
    voxel_m: f64,
    /// Octree levels by which the scalpel's leaves were refined (`--blade-levels`).
    blade_levels: u32,
    realtime: bool,
    /// Frame sets in the stages at once (`--queue`).
    queue: usize,
    /// The most frame sets each queue held at once: read → hull, hull → pose, pose → tissue,
    /// tissue → logging; never more than `queue`.
    queue_max: [usize; 4],
    /// Whether the frame sets were decoded into memory before the loop (`--preload-mib`).
    preloaded: bool,
    /// Stopped by Ctrl-C before the last frame set (everything read until then was processed).
    interrupted: bool,
    /// Why the run stopped before its end, when something failed (null when it did not).
    stopped: Option<String>,
    wall_s: f64,
    /// Frame sets processed per second of wall time, start-up (rendering, the tissue's set-up)
    /// excluded.
    sustained_fps: f64,
    capture_fps: f64,
    counters: Counters,
    /// Camera images and frame sets that could not be used and were left out.
    faults: Faults,
    /// The tissue at the end (null when its stage failed).
    tissue: Option<TissueReport>,
    /// Resident memory at every full minute of the run and at its end (Linux; empty elsewhere).
    memory: Vec<MemorySample>,
    /// Resident memory at the end against its level after the first minute, percent (null for a
    /// run shorter than a minute): a loop that reuses its buffers stays within a few percent.
    memory_growth_pct: Option<f64>,
    /// How the segmented masks were labelled (null with mask files).
    labelling: Option<crate::labelling::LabellingReport>,
    pose: PoseReport,
    timings: Timings,
    /// Each stage against its budget for 60 fps, measured inside the loop (hullcut_pipeline's
    /// `budget`): over_ms > 0 is a miss by that much.
    budget: Vec<hullcut_pipeline::budget::Line>,
    /// Where the frame sets were carved: in a box around the last hull, in the whole working
    /// volume (of those, the ones after a tool not trusted), and hulls that reached the box's
    /// side (carved again in the whole volume).
    carve_region: hullcut_pipeline::region::RegionCounts,
    /// Entities logged to the recording.
    entities: Vec<String>,
    /// Figures of this report that were not finite numbers (written as null): the run exits
    /// with an error naming them.
    non_finite: Vec<String>,
}

/// How often the run samples its memory.
const MEMORY_SAMPLE: Duration = Duration::from_secs(60);

/// The process's memory at one moment of a run.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct MemorySample {
    /// Wall time since processing started, seconds.
    wall_s: f64,
    /// Frame sets processed by then.
    frame_sets: u64,
    /// Resident set size then, MiB.
    rss_mib: f64,
    /// Largest resident set size so far, MiB.
    peak_rss_mib: f64,
}

impl MemorySample {
    /// The process's memory now, from /proc/self/status (`None` where there is none).
    fn now(wall: Duration, frame_sets: u64) -> Option<Self> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let kib = |key: &str| -> Option<f64> {
            let line = status.lines().find(|l| l.starts_with(key))?;
            line[key.len()..].trim().trim_end_matches("kB").trim().parse::<f64>().ok()
        };
        Some(Self {
            wall_s: wall.as_secs_f64(),
            frame_sets,
            rss_mib: kib("VmRSS:")? / 1024.0,
            peak_rss_mib: kib("VmHWM:")? / 1024.0,
        })
    }
}

/// Runs of up to this many frame sets (two minutes at 30 fps) write their recording with rerun's
/// index of its chunks; longer ones without (the viewer reads them from the start).
const INDEXED_FRAME_SETS: u64 = 3600;

/// How far below `ORGAN_TOP` the built-in scene's strokes press the blade's tip, metres.
pub(crate) const BUILTIN_STROKE_DEPTH: [f64; 2] = [0.018, 0.035];

/// The rerun entities a run logs (DESIGN's tree).
pub const ENTITIES: [&str; 17] = [
    "world/cams/NAME",
    "world/cams/NAME/image",
    "world/cams/NAME/labels",
    "world/hull/LABEL",
    "world/tool/estimate",
    "world/tool/truth",
    "world/tissue/nodes",
    "world/tissue/surface",
    "world/tissue/cut",
    "metrics/time/STAGE",
    "metrics/accuracy/NAME",
    crate::logging::POSE_VIEWS_ENTITY,
    crate::logging::POSE_SIGHT_ENTITY,
    crate::logging::POSE_SET_ASIDE_ENTITY,
    crate::logging::POSE_ROLL_SD_ENTITY,
    "world",
    "world/workspace",
];

/// A segmented run with a tool (`tool`) that refused it in `refused` of `frames` frame sets, a
/// fifth or more, without the weak foreground test (`weak`): a line that names
/// `--weak-foreground track-lost`, which may bring the lost track back (a blade or glove of the
/// table's colour), or may not (docs/benchmarks.md).
fn weak_hint(tool: bool, weak: bool, (refused, frames): (usize, usize)) -> Option<String> {
    (tool && !weak && frames > 0 && 5 * refused >= frames).then(|| {
        format!(
            "hint: the tool was refused in {refused} of {frames} frame sets; where the foreground misses a blade or \
             glove of the table's colour, --weak-foreground track-lost lets the other views confirm its faint pixels \
             once the track is lost (docs/benchmarks.md, \"Weak foreground once the track is lost\")"
        )
    })
}

/// Where the weak foreground test ran (`--weak-foreground`), also the weak foreground confirmed in
/// each frame set.
pub const WEAK_ENTITY: &str = crate::logging::WEAK_CONFIRMED_ENTITY;

/// The rerun entities a run logs when it segments (without mask files): where each frame set's
/// labels came from, the colours learned by then, the share of the drawn blade they call the
/// hand's, the possible shadows given back to the table, and the pixels an untrusted fit that
/// agreed with the silhouettes taught the colours (on the frame sets where it did), and what
/// each frame set's segmentation tested: the pixels, whether only near the last hull, the
/// weak pixels that joined the foreground and the holes filled in it; and
/// whether the foreground's hull was searched for a lost tool (or the search paused).
pub const SEGMENTING_ENTITIES: [&str; 12] = [
    "labelling/source",
    "metrics/appearance/LABEL/colour",
    "metrics/appearance/LABEL/pixels",
    "metrics/appearance/blade_as_hand",
    "metrics/shadows/on_table",
    crate::logging::TAUGHT_ENTITY,
    crate::logging::PIXELS_TESTED_ENTITY,
    crate::logging::NEAR_HULL_ENTITY,
    crate::logging::WEAK_JOINED_ENTITY,
    crate::logging::HOLES_FILLED_ENTITY,
    crate::logging::LESSON_ENTITY,
    crate::logging::HULL_SEARCHED_ENTITY,
];

pub fn run(args: &Args) -> anyhow::Result<()> {
    // Ctrl-C stops reading; what is in flight is processed, logged and flushed, and the report is
    // written. A second Ctrl-C quits at once.
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!(
                "interrupted: finishing the frame sets in flight and flushing the recording (Ctrl-C again quits now)"
            );
        })
        .context("installing the Ctrl-C handler")?;
    }
    let sink = match (&args.rrd, args.spawn, &args.connect) {
        (Some(path), _, _) => hullcut_viz::Sink::File(path.clone()),
        (None, true, _) => {
            if which_rerun().is_none() {
                bail!(
                    "--spawn: no `rerun` viewer on PATH (install it with tools/setup.sh --with-viewer or \
                     `pip install rerun-sdk==0.36.3`), or write a file with --rrd"
                );
            }
            hullcut_viz::Sink::Spawn
        }
        (None, false, Some(url)) => hullcut_viz::Sink::Connect(url.clone()),
        (None, false, None) => {
            let path = PathBuf::from("hullcut-run.rrd");
            println!("no --rrd, --spawn or --connect: writing {}", path.display());
            hullcut_viz::Sink::File(path)
        }
    };
    // The frame sets: a dataset, or the built-in scene rendered into a temporary folder.
    let scene_dir;
    let (dataset_path, seed) = match &args.dataset {
        Some(path) => (path.clone(), None),
        None => {
            scene_dir = tempfile::tempdir().context("creating a temporary folder for the built-in scene")?;
            let path = scene_dir.path().join("scene");
            let mut config = SceneConfig::new(SceneKind::Resect, args.seed, args.scene_frames);
            // The organ's top lies 5 to 15 mm below ORGAN_TOP where strokes run (it is domed, and
            // sags under gravity): strokes 18 to 35 mm below it cut about 5 to 25 mm deep.
            config.stroke_depth = BUILTIN_STROKE_DEPTH;
            // Nor truth meshes nor depth maps: the loop reads neither (a tenth of the bytes).
            (config.truth_meshes, config.depth_maps) = (false, false);
            // The hand works on the organ it is shown: over the large one, higher and wider.
            if args.tissue == "organ-large" {
                config.organ_scale = hullcut_sim::LARGE_ORGAN_SCALE;
            }
            let scene = hullcut_synth::Scene::new(config).context("preparing the built-in scene")?;
            let pb = bar(args.scene_frames, "rendering the built-in scene");
            synthesize(&scene, &path, &format!("builtin-cut-seed{}", args.seed), false, &|| pb.inc(1))
                .context("rendering the built-in scene")?;
            pb.finish_and_clear();
            (path, Some(args.seed))
        }
    };
    let ds = Arc::new(Dataset::open(&dataset_path)?);
    let use_files = checks::masks_from_files(&ds, args.masks)?;
    let range = parse_frames(args.frames.as_deref(), ds.meta().frame_count)?;
    let frames: Vec<u64> = ds.frame_numbers().into_iter().filter(|f| range.contains(f)).collect();
    if frames.is_empty() {
        bail!("{}: no frame sets in {}..{}", dataset_path.display(), range.start, range.end);
    }
    // A pass spans its frames' numbers and one frame period more, so the next pass's first frame
    // set follows the last one's as the next frame would.
    let (first, last) = (frames[0], frames[frames.len() - 1]);
    let pass_frames = last + 1;
    let pass_span_ns = ((last - first + 1) as f64 * 1e9 / ds.meta().fps).round() as i64;
    let tool = ds.tool()?;
    let template = tool
        .as_ref()
        .map(Template::new)
        .transpose()
        .with_context(|| ds.root().join("tool.json").display().to_string())?;
    // True poses, each checked: a matrix that is not a rigid pose (a NaN, a rotation entry of
    // 1e19) is not scored, and counted.
    let mut truth: BTreeMap<u64, Isometry3<f64>> = BTreeMap::new();
    let mut truth_refused = 0u64;
    for p in ds.truth_poses()?.unwrap_or_default() {
        match rigid_from_matrix(&p.tool_to_world) {
            Ok(iso) => {
                truth.entry(p.frame).or_insert(iso);
            }
            Err(e) => {
                if truth_refused == 0 {
                    eprintln!(
                        "warning: {}: frame {}: not a rigid pose ({e}); frames with such a true pose are not scored",
                        ds.root().join("truth").join("poses.jsonl").display(),
                        p.frame
                    );
                }
                truth_refused += 1;
            }
        }
    }
    let volume = crate::volume::resolve(args.workspace, Some(&ds), ds.rig())?;
    checks::voxel(args.voxel, volume.aabb.extent())?;
    let hull = HullParams {
        min_views: MIN_VIEWS,
        trim_slivers: args.trim_slivers,
        blade_levels: args.blade_levels,
        ..HullParams::new(volume.aabb, args.voxel)
    };

    let clock = Instant::now();
    let far_field = match args.far_field {
        FarFieldArg::Flsm => FarField::Flsm,
        FarFieldArg::Frozen => FarField::Frozen,
    };
    let hybrid = args.operational_radius.map(|radius| HybridParams { radius, far_field, ..HybridParams::default() });
    let gpu = args.backend.open()?;
    if let Some(g) = &gpu {
        println!("GPU backend: {}", g.summary.info.name);
    }
    let carver = Carver::new(gpu.as_ref())?;
    let tissue = tissue::build(&args.tissue, args.cell, hybrid, gpu)?;
    let setup_s = clock.elapsed().as_secs_f64();
    for warning in &tissue.warnings {
        eprintln!("warning: {warning}");
    }
    println!(
        "tissue: {} nodes, {} cells at {:.1} mm, dt {:.3} ms ({:.0}% of the computed critical step), set up in {:.2} s",
        tissue.sim.lattice().node_count(),
        tissue.sim.cell_count(),
        args.cell * 1e3,
        tissue.sim.dt() * 1e3,
        100.0 * tissue.sim.dt() / tissue.sim.dt_critical(),
        setup_s
    );

    let snapshots = match &args.snapshots {
        Some(dir) => {
            let chosen: std::collections::BTreeSet<u64> = match &args.snapshot_frames {
                Some(list) => list.iter().copied().collect(),
                None => frames
                    .iter()
                    .copied()
                    .filter(|f| f.is_multiple_of(args.snapshot_every))
                    .chain(frames.last().copied())
                    .collect(),
            };
            Some(snapshot::Snapshots::new(dir, chosen, args.snapshot_camera.as_deref(), ds.rig())?)
        }
        None => None,
    };
    // rerun's index of a file's chunks grows in memory until the file is closed (some 10 KB a
    // frame set): a long run's file goes without it, and its memory stays flat.
    let indexed = (frames.len() as u64).saturating_mul(args.repeat) <= INDEXED_FRAME_SETS;
    let rec = hullcut_viz::open_recording_indexed("hullcut-run", &sink, indexed)?;
    hullcut_viz::log_world(&rec)?;
    crate::volume::log(&rec, &volume)?;
    let cams = CameraLogger::new(&rec, ds.rig())?;
    if !use_files {
        crate::logging::log_appearance_style(&rec)?;
    }

    // The frame sets in memory when they fit: decoding is timed apart from the loop.
    let preload = preload_fits(&ds, frames.len(), use_files, args.preload_mib);
    let (source, decode) = if preload {
        let pb = bar(frames.len() as u64, "decoding the frame sets into memory");
        let clock = Instant::now();
        let sets = stages::preload(&ds, &frames, use_files, &|| pb.inc(1));
        pb.finish_and_clear();
        let per_set = clock.elapsed() / u32::try_from(frames.len()).unwrap_or(u32::MAX).max(1);
        (FrameSource::Memory(Arc::clone(&ds), Arc::new(sets)), Some(vec![per_set; frames.len()]))
    } else {
        (FrameSource::Dataset(Arc::clone(&ds)), None)
    };
    let t0 = Instant::now();
    let labelling = if use_files {
        None
    } else {
        let mut labelling = Labelling::new(&ds, tool.as_ref(), hull.clone(), &args.label_frames, args.labels)?;
        crate::weak::set_up(&mut labelling, &ds, args.weak_foreground, args.confirm_weak_foreground)?;
        labelling.set_search_gap(args.search_gap);
        Some(labelling)
    };
    // The hull's meshes of the frames snapshotted (and of those logged: `masks_every`).
    let mesh_frames: Vec<u64> = snapshots.as_ref().map_or_else(Vec::new, |s| s.frames().collect());
    let mut log = logger::LogThread::start(
        logger::Logger {
            rec,
            sink,
            cams,
            ds: Arc::clone(&ds),
            tool: tool.clone(),
            template: template.clone(),
            rrd_every: args.rrd_every,
            export_meshes: args.export_meshes.clone(),
            snapshots,
        },
        args.realtime,
    )?;
    let pipeline = stages::spawn(stages::Setup {
        source,
        frames: frames.clone(),
        repeat: args.repeat,
        pass_span_ns,
        use_files,
        labelling,
        // The label masks of the frame sets logged with their images (the logger's `shown`).
        masks_every: Some(args.rrd_every),
        mesh_frames,
        hull,
        carver,
        template: template.clone(),
        outline_offset: args.outline_offset && use_files,
        tissue,
        in_flight: args.queue,
        realtime: args.realtime,
        stop: Arc::clone(&stop),
    })?;

    let total = (frames.len() as u64).saturating_mul(args.repeat);
    let pb = bar(total, "running");
    let mut memory = Vec::new();
    let mut next_sample = MEMORY_SAMPLE;
    let mut counters = Counters { truth_poses_refused: truth_refused, ..Counters::default() };
    let camera_names = ds.rig().cameras.iter().map(|c| c.name.clone());
    let mut pose_report = PoseReport::new(template.is_some()).with_cameras(camera_names);
    let mut times = StageTimes::default();
    let (mut latency, mut admission) = (Vec::new(), Vec::new());
    let mut tled_cells: Vec<usize> = Vec::new();
    // The results, in order: counted and scored here, logged on the logging thread.
    for work in pipeline.output.iter() {
        counters.frame_sets_processed += 1;
        counters.views_missing += work.set.views.iter().filter(|v| v.is_none()).count() as u64;
        // Where this frame set goes on the `frame` timeline (later passes follow the first).
        let shown = work.frame.saturating_add(work.pass.saturating_mul(pass_frames));
        times.extend(&work.times);
        latency.push(work.latency());
        admission.push(work.admission_wait());
        let truth_iso = truth.get(&work.frame).copied();
        // A pose's error against the truth; none where there is no truth or a figure is not
        // finite (not measured, never a NaN in the report).
        let error = |p: Option<&hullcut_pose::BladePose>| -> Option<PoseError> {
            let measured = match (&template, p, &truth_iso) {
                (Some(template), Some(p), Some(truth)) => Some(pose_error(p, template, truth)),
                _ => None,
            };
            measured.filter(finite_error)
        };
        let mut logged_error = None;
        if let Some(e) = &work.estimate {
            logged_error = error(e.pose.as_ref());
            pose_report.push(e, logged_error, error(e.fitted.as_ref()));
            if e.valid {
                counters.poses_trusted += 1;
            } else {
                counters.poses_refused += 1;
                counters.poses_held += u64::from(e.held);
            }
        }
        if let Some(step) = &work.tissue {
            counters.sweeps += u64::from(step.swept.is_some());
            counters.sweeps_skipped_after_refusal += u64::from(step.sweep_skipped);
            counters.sweeps_bridged += u64::from(step.sweep_bridged);
            if let Some(reason) = &step.sweep_refused {
                if counters.sweeps_refused == 0 {
                    tracing::warn!("frame {}: a sweep was not cut: {reason}", work.frame);
                }
                counters.sweeps_refused += 1;
            }
            counters.edges_cut += step.cut.map_or(0, |c| c.new_edges as u64);
            counters.frames_with_contact += u64::from(step.contacts > 0);
            counters.max_contact_nodes = counters.max_contact_nodes.max(step.contacts as u64);
            tled_cells.push(step.tled_cells);
        }
        if t0.elapsed() >= next_sample {
            memory.extend(MemorySample::now(t0.elapsed(), counters.frame_sets_processed));
            next_sample += MEMORY_SAMPLE;
        }
        pb.inc(1);
        if !log.push(logger::Item { work, shown, truth: truth_iso, error: logged_error }) || log.stopped() {
            break;
        }
    }
    pb.finish_and_clear();
    let wall = t0.elapsed();
    memory.extend(MemorySample::now(wall, counters.frame_sets_processed));
    let outcome = pipeline.join();
    counters.log_dropped = log.dropped;
    let log_wait = std::mem::take(&mut log.waited);
    let (logged, log_result) = log.finish();
    let error = log_result
        .err()
        .map(|e| e.context("stopped while logging the frame sets"))
        .or(outcome.error.map(anyhow::Error::new));
    let interrupted = stop.load(Ordering::SeqCst) && outcome.read.read < total;
    counters.frame_sets_read = outcome.read.read;
    counters.frame_sets_dropped = outcome.read.dropped;
    counters.realtime_gaps_skipped = outcome.read.gaps_skipped;
    counters.snapshots_written = logged.snapshots_written;
    counters.meshes_exported = logged.meshes_exported;
    counters.tissue_surfaces_logged = logged.surfaces.logged;
    counters.tissue_surfaces_unchanged = logged.surfaces.skipped;
    pose_report.finish();
    let faults = outcome.read.faults;
    let (faults_any, faults_summary) = (faults.any(), faults.summary());
    let processed = counters.frame_sets_processed;
    let sim = outcome.sim.as_ref();
    let sustained_fps = counters.frame_sets_processed as f64 / wall.as_secs_f64().max(1e-9);
    println!(
        "{} frame sets in {:.2} s ({sustained_fps:.1} fps sustained; captured at {:.1} fps), {} dropped",
        counters.frame_sets_processed,
        wall.as_secs_f64(),
        ds.meta().fps,
        counters.frame_sets_dropped
    );
    if counters.realtime_gaps_skipped > 0 {
        println!(
            "--realtime: {} gap(s) in the capture times over {} s (or backwards) not waited out",
            counters.realtime_gaps_skipped,
            stages::MAX_REALTIME_GAP_S
        );
    }
    match memory.as_slice() {
        [] => {}
        [last] => println!("memory: {:.0} MiB resident at the end (peak {:.0} MiB)", last.rss_mib, last.peak_rss_mib),
        [first, .., last] => println!(
            "memory: {:.0} MiB resident after {:.0} s, {:.0} MiB at the end, {:.0} s ({:+.1}%; peak {:.0} MiB)",
            first.rss_mib,
            first.wall_s,
            last.rss_mib,
            last.wall_s,
            memory_growth_pct(&memory).unwrap_or(f64::NAN),
            last.peak_rss_mib
        ),
    }
    let budget = hullcut_pipeline::budget::check(&times);
    let latency_timing = StageTiming::from_durations(&latency);
    println!(
        "loop: latency from capture to cut surface {:.1} ms p50, {:.1} p95 (goal {:.0}); {}",
        latency_timing.p50_ms,
        latency_timing.p95_ms,
        hullcut_pipeline::budget::LATENCY_P95_MS,
        hullcut_pipeline::budget::summary(&budget)
    );
    println!("{}", pose_report.summary());
    for line in [pose_report.sight_summary(), pose_report.rig_hint()].into_iter().flatten() {
        println!("{line}");
    }
    if let Some(hint) = outcome
        .labelling
        .as_ref()
        .and_then(|l| weak_hint(l.tool, l.weak_foreground_when.is_some(), pose_report.refused_of()))
    {
        println!("{hint}");
    }
    let pieces_at_end = sim.map(hullcut_sim::CutSim::piece_states);
    if let Some(sim) = sim {
        let topology = sim.topology();
        println!(
            "tissue: {} sweeps cut {} lattice edges; {} piece(s), {} cell copies, {} virtual nodes{}",
            counters.sweeps,
            counters.edges_cut,
            topology.pieces,
            topology.copies.len(),
            topology.virtual_of.len(),
            outcome.failure.as_ref().map_or(String::new(), |f| format!("; STOPPED: {f}"))
        );
        for (k, piece) in pieces_at_end.iter().flatten().enumerate() {
            println!(
                "  piece {k}: {:.1} ml, lowest node {:.2} mm above the table, {} node(s) on it, {} held; speed {:.2} mm/s mean, {:.2} max",
                piece.volume_m3 * 1e6,
                piece.lowest_above_table_m * 1e3,
                piece.on_table,
                piece.held_nodes,
                piece.mean_speed_m_s * 1e3,
                piece.max_speed_m_s * 1e3
            );
        }
    }
    let timing = |d: &[Duration]| StageTiming::from_durations(d);
    let mut non_finite = Vec::new();
    if let Some(path) = &args.report {
        // The weak foreground confirmed is logged wherever its test ran.
        let weak_logged = outcome.labelling.as_ref().is_some_and(|l| {
            l.weak_foreground_when == Some(hullcut_pipeline::WeakWhen::Always) || l.weak_foreground_from.is_some()
        });
        let mut report = Report {
            schema_version: SCHEMA_VERSION,
            kind: "run".to_owned(),
            provenance: Provenance::current(),
            source: args
                .dataset
                .as_ref()
                .map_or_else(|| "built-in scene (resect)".to_owned(), |p| p.display().to_string()),
            seed,
            frames: [range.start, range.end],
            repeat: args.repeat,
            backend: args.backend,
            masks: if use_files { "files" } else { "segment" }.to_owned(),
            outline_offset: args.outline_offset && use_files,
            workspace: volume,
            voxel_m: args.voxel,
            blade_levels: args.blade_levels,
            realtime: args.realtime,
            queue: args.queue,
            queue_max: outcome.queue_max,
            preloaded: preload,
            interrupted,
            stopped: error.as_ref().map(|e| format!("{e:#}")),
            wall_s: wall.as_secs_f64(),
            sustained_fps,
            capture_fps: ds.meta().fps,
            counters,
            faults,
            memory_growth_pct: memory_growth_pct(&memory),
            memory,
            tissue: sim.map(|sim| {
                let topology = sim.topology();
                TissueReport {
                    source: args.tissue.clone(),
                    cell_m: args.cell,
                    nodes: sim.lattice().node_count(),
                    cells: sim.lattice().cells.len(),
                    fixed_nodes: sim.fixed().iter().filter(|&&f| f).count(),
                    dt_s: sim.dt(),
                    dt_critical_s: sim.dt_critical(),
                    pieces: topology.pieces,
                    copies: topology.copies.len(),
                    virtual_nodes: topology.virtual_of.len(),
                    copies_dropped: sim.dropped_copies(),
                    copies_torn: sim.torn_copies(),
                    inverted_cells: sim.inverted_cells(),
                    kinetic_energy_j: sim.kinetic_energy(),
                    simulated_s: sim.time(),
                    failure: outcome.failure.clone(),
                    operational_radius_m: args.operational_radius,
                    far_field: hybrid.map(|h| h.far_field),
                    hybrid: sim.hybrid_steps(),
                    tled_cells_mean: tled_cells.iter().sum::<usize>() as f64 / tled_cells.len().max(1) as f64,
                    tled_cells_max: tled_cells.iter().copied().max().unwrap_or(0),
                    region_changes: sim.region_changes(),
                    gpu: sim.gpu_stats().cloned(),
                    table: sim.table().copied(),
                    table_contacts: sim.table_contacts(),
                    piece_contact_planes: sim.piece_contacts().planes.len(),
                    piece_contact_inside: sim.piece_contacts().inside,
                    piece_contact_nodes: sim.piece_contact_nodes(),
                    pieces_at_end: pieces_at_end.clone().unwrap_or_default(),
                }
            }),
            labelling: outcome.labelling.clone(),
            pose: pose_report,
            budget,
            carve_region: outcome.carve_region,
            timings: Timings {
                read: timing(&times.read),
                segment: (!times.segment.is_empty()).then(|| timing(&times.segment)),
                segment_foreground: (!times.segment_foreground.is_empty()).then(|| timing(&times.segment_foreground)),
                segment_evidence: (!times.segment_evidence.is_empty()).then(|| timing(&times.segment_evidence)),
                segment_drawn: (!times.segment_drawn.is_empty()).then(|| timing(&times.segment_drawn)),
                learn: (!times.learn.is_empty()).then(|| timing(&times.learn)),
                carve: timing(&times.carve),
                surface: timing(&times.surface),
                pose: timing(&times.pose),
                collide: timing(&times.collide),
                cut_topology: timing(&times.cut_topology),
                cut_surface: timing(&times.cut_surface),
                contact: timing(&times.contact),
                deform: timing(&times.deform),
                tissue_surface: timing(&times.tissue_surface),
                log: timing(&logged.times),
                log_labels: (!logged.label_times.is_empty()).then(|| timing(&logged.label_times)),
                log_wait: timing(&log_wait),
                latency: timing(&latency),
                admission_wait: timing(&admission),
                decode: decode.as_deref().map(timing),
            },
            entities: ENTITIES
                .iter()
                .chain(if use_files { &[][..] } else { &SEGMENTING_ENTITIES[..] })
                .chain(if weak_logged { &[WEAK_ENTITY][..] } else { &[][..] })
                .map(|s| (*s).to_owned())
                .collect(),
            non_finite: Vec::new(),
        };
        non_finite = checks::non_finite_fields(&report);
        report.non_finite.clone_from(&non_finite);
        write_json(path, &report)?;
    } else if let Some(sim) = sim {
        // Without a report the essential figures are still checked.
        let figures = [
            ("tissue.kinetic_energy_j", sim.kinetic_energy()),
            ("tissue.simulated_s", sim.time()),
            ("tissue.dt_s", sim.dt()),
            ("sustained_fps", sustained_fps),
        ];
        non_finite.extend(figures.iter().filter(|(_, v)| !v.is_finite()).map(|(name, _)| (*name).to_owned()));
    }
    if let Some(e) = error {
        let kept =
            if args.report.is_some() { "the recording and the report hold them" } else { "the recording holds them" };
        return Err(e.context(format!("the run stopped after {processed} frame set(s) ({kept})")));
    }
    if let Some(f) = outcome.failure {
        bail!("the tissue simulation stopped: {f}");
    }
    if interrupted {
        bail!(
            "interrupted after {} of {} frame sets (the recording and the report hold them all)",
            outcome.read.read,
            frames.len()
        );
    }
    if !non_finite.is_empty() {
        bail!("figures that are not finite numbers (written as null in the report): {}", non_finite.join(", "));
    }
    if faults_any {
        bail!("{faults_summary}");
    }
    Ok(())
}

/// Resident memory at the end of a run against its level after the first minute, percent
/// (`None` without a sample at a minute or later before the end).
fn memory_growth_pct(samples: &[MemorySample]) -> Option<f64> {
    match samples {
        [minute, .., last] if minute.rss_mib > 0.0 => Some(100.0 * (last.rss_mib / minute.rss_mib - 1.0)),
        _ => None,
    }
}

/// Whether `frames` frame sets of `ds` (masks too unless segmented) decoded take at most
/// `limit_mib` MiB (their images at 3 bytes a pixel, masks at 1).
fn preload_fits(ds: &Dataset, frames: usize, with_masks: bool, limit_mib: u64) -> bool {
    let per_pixel = if with_masks { 4 } else { 3 };
    let bytes: u64 = ds
        .rig()
        .cameras
        .iter()
        .map(|c| u64::from(c.width) * u64::from(c.height) * per_pixel)
        .sum::<u64>()
        .saturating_mul(frames as u64);
    bytes <= limit_mib.saturating_mul(1 << 20)
}

/// Whether a pose error is a number in every field (a NaN is not measured, not an error of 0).
fn finite_error(e: &PoseError) -> bool {
    e.normal_deg.is_finite() && e.edge_mm.is_finite() && e.tip_mm.is_finite()
}

/// The `rerun` executable on PATH, if any.
fn which_rerun() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join("rerun")).find(|p| p.is_file())
}

/// A length in metres, 0 or more (`--operational-radius`).
fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{}` is not a length in metres, 0 or more", crate::report::shorten(s, 80))),
    }
}

#[cfg(test)]
mod tests {
    use super::weak_hint;

    #[test]
    fn the_weak_foreground_is_hinted_where_a_fifth_of_the_frame_sets_refused_the_tool_without_it() {
        let hint = weak_hint(true, false, (30, 150)).expect("a fifth refused: a hint");
        assert!(hint.contains("refused in 30 of 150") && hint.contains("--weak-foreground track-lost"), "{hint}");
        assert_eq!(weak_hint(true, false, (29, 150)), None, "less than a fifth");
        assert_eq!(weak_hint(true, true, (150, 150)), None, "the test was asked for");
        assert_eq!(weak_hint(false, false, (150, 150)), None, "no tool to refuse");
        assert_eq!(weak_hint(true, false, (0, 0)), None, "nothing judged");
    }
}
