//! `hullcut rig`: inspect a rig file, or write the default six-camera rig.

use std::path::PathBuf;

use hullcut_rig::{Rig, default_rig};

/// Inspect or create rig files (rig.yaml, OpenCV FileStorage YAML).
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: RigCommand,
}

#[derive(Debug, clap::Subcommand)]
enum RigCommand {
    /// Print a table of the rig's cameras (K, distortion, centre, viewing direction, RMS) and
    /// optionally log the rig to a rerun recording.
    ///
    /// Writes: the .rrd given by --rrd (cameras as Transform3D + Pinhole under world/cams/NAME).
    Show {
        /// The rig file.
        file: PathBuf,
        /// Also log the rig to this rerun recording (.rrd).
        #[arg(long, value_name = "FILE")]
        rrd: Option<PathBuf>,
    },
    /// Write the default six-camera rig of the synthetic scenes (a ring around a 0.4 m workspace
    /// above the table, 640x480, mixed elevations, mild distortion).
    ///
    /// Writes: OUT (rig.yaml).
    Default {
        /// Where to write it.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Resample the cameras' images by this factor (0.5 gives 320x240 cameras with the same
        /// fields of view).
        #[arg(long, value_name = "FACTOR", default_value_t = 1.0)]
        scale: f64,
    },
}

/// Runs the command.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.command {
        RigCommand::Show { file, rrd } => {
            let rig = Rig::load(file)?;
            print_table(&rig);
            if let Some(path) = rrd {
                let rec = hullcut_viz::open_recording("hullcut-rig", &hullcut_viz::Sink::File(path.clone()))?;
                hullcut_viz::log_world(&rec)?;
                hullcut_viz::log_rig(&rec, &rig)?;
                hullcut_viz::flush(&rec)?;
                println!("wrote {}", path.display());
            }
            Ok(())
        }
        RigCommand::Default { out, scale } => {
            if !(*scale > 0.0 && scale.is_finite()) {
                anyhow::bail!("--scale must be a positive number, got {scale}");
            }
            let mut rig = default_rig();
            for camera in &mut rig.cameras {
                *camera = camera.scaled(*scale);
            }
            rig.save(out)?;
            println!("wrote {}", out.display());
            Ok(())
        }
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
