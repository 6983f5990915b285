//! `hullcut rig`: inspect a rig file, or write the default six-camera rig.

use std::path::PathBuf;

use anyhow::bail;
use hullcut_rig::{Rig, RigPreset};

/// Inspect or create rig files (rig.yaml, OpenCV FileStorage YAML).
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: RigCommand,
}

#[derive(Debug, clap::Subcommand)]
enum RigCommand {
    /// Print a table of the rig's cameras (K, distortion, centre, viewing direction, RMS) and the
    /// working volume derived from it (the space at least three cameras see), and optionally log
    /// the rig to a rerun recording.
    ///
    /// Writes: the .rrd given by --rrd (cameras as Transform3D + Pinhole under world/cams/NAME, the
    /// volume under world/workspace).
    Show {
        /// The rig: a rig.yaml file, or a built-in rig (default, lab8, random:SEED).
        file: String,
        /// Also log the rig to this rerun recording (.rrd).
        #[arg(long, value_name = "FILE")]
        rrd: Option<PathBuf>,
    },
    /// Write a rig (a rig.yaml file or a built-in rig) as a COLMAP text model: cameras.txt (OPENCV
    /// cameras, FULL_OPENCV where k3 is not zero), images.txt (one image NAME.png per camera, poses
    /// world → camera), an empty points3D.txt; the principal point moved by half a pixel to COLMAP's
    /// convention. `hullcut import-calibration --colmap` reads it back.
    ///
    /// Writes: OUT/cameras.txt, OUT/images.txt, OUT/points3D.txt.
    Export {
        /// The rig: a rig.yaml file, or a built-in rig (default, lab8, random:SEED).
        file: String,
        /// The folder to write the COLMAP model into.
        #[arg(long, value_name = "DIR")]
        colmap: PathBuf,
        /// Metres per unit of the model's translations (above 0).
        #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = super::positive)]
        scale: f64,
    },
    /// Write a built-in rig of the synthetic scenes: `default` (six 640x480 cameras on a ring,
    /// mixed elevations, mild distortion), `lab8` (eight 1280x720 cameras, one overhead, one with
    /// strong distortion) or `random:SEED`.
    ///
    /// Writes: OUT (rig.yaml).
    Default {
        /// Which rig: default, lab8 or random:SEED.
        #[arg(long, value_name = "NAME", default_value = "default", value_parser = preset_parser)]
        rig: RigPreset,
        /// Where to write it.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Resample the cameras' images by this factor (0.5 gives 320x240 cameras with the same
        /// fields of view).
        #[arg(long, value_name = "FACTOR", default_value_t = 1.0, value_parser = super::positive)]
        scale: f64,
    },
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.command {
        RigCommand::Show { file, rrd } => {
            let rig = load_rig(file)?;
            print_table(&rig);
            let volume = crate::volume::resolve(None, None, &rig)?;
            if let Some(path) = rrd {
                let rec = hullcut_viz::open_recording("hullcut-rig", &hullcut_viz::Sink::File(path.clone()))?;
                hullcut_viz::log_world(&rec)?;
                hullcut_viz::log_rig(&rec, &rig)?;
                crate::volume::log(&rec, &volume)?;
                hullcut_viz::flush(&rec)?;
                println!("wrote {}", path.display());
            }
            Ok(())
        }
        RigCommand::Export { file, colmap, scale } => {
            let rig = load_rig(file)?;
            hullcut_rig::colmap::write_colmap(&rig, colmap, *scale)?;
            println!("wrote {} (COLMAP text model, {} cameras)", colmap.display(), rig.len());
            Ok(())
        }
        RigCommand::Default { rig, out, scale } => {
            let mut rig = rig.rig();
            for camera in &mut rig.cameras {
                *camera = camera.scaled(*scale);
            }
            rig.save(out)?;
            println!("wrote {}", out.display());
            Ok(())
        }
    }
}

/// `rig default --rig`: a built-in rig's name (anything else is bad usage).
fn preset_parser(s: &str) -> Result<RigPreset, String> {
    RigPreset::parse(s).ok_or_else(|| format!("not a built-in rig ({})", RigPreset::NAMES))
}

/// A rig by built-in name (default, lab8, random:SEED) or from a rig.yaml file.
pub(crate) fn load_rig(name: &str) -> anyhow::Result<Rig> {
    match RigPreset::parse(name) {
        Some(preset) => Ok(preset.rig()),
        None if std::path::Path::new(name).exists() => Ok(Rig::load(name)?),
        None => bail!("{name}: neither a built-in rig ({}) nor a rig.yaml file", RigPreset::NAMES),
    }
}

fn print_table(rig: &Rig) {
    println!("{} cameras; world frame: {}", rig.len(), rig.world_frame.to_key());
    println!(
        "{:<8} {:>9} {:>8} {:>8} {:>8} {:>8} | {:>8} {:>8} {:>9} {:>9} {:>8} | {:>25} | {:>24} | {:>7}",
        "camera",
        "size",
        "fx",
        "fy",
        "cx",
        "cy",
        "k1",
        "k2",
        "p1",
        "p2",
        "k3",
        "centre (m)",
        "viewing direction",
        "rms_px"
    );
    for c in &rig.cameras {
        let d = c.distortion;
        let o = c.centre();
        let v = c.viewing_direction();
        let rms = c.rms_reprojection_error.map_or_else(|| "-".to_owned(), |r| format!("{r:.4}"));
        println!(
            "{:<8} {:>9} {:>8.2} {:>8.2} {:>8.2} {:>8.2} | {:>8.4} {:>8.4} {:>9.2e} {:>9.2e} {:>8.4} | {:>7.4} {:>7.4} {:>7.4}   | {:>6.3} {:>6.3} {:>6.3}   | {:>7}",
            c.name,
            format!("{}x{}", c.width, c.height),
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            d.k1,
            d.k2,
            d.p1,
            d.p2,
            d.k3,
            o.x,
            o.y,
            o.z,
            v.x,
            v.y,
            v.z,
            rms
        );
    }
}
