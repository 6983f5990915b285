//! Segmentation speed: milliseconds per frame set of six 640x480 views (procedural scene, three
//! empty-scene images per camera), with the default clean-up, without clean-up, with OpenCV's
//! `morphologyEx` closing for comparison, and with the MOG2 fallback.
//!
//! `cargo run --release -p hullcut-capture --example segment_bench` (set `HULLCUT_BENCH_QUICK=1`
//! for a smoke run). Uses all rayon threads (one per core unless `RAYON_NUM_THREADS` says
//! otherwise).

#[path = "../tests/integration/common.rs"]
mod common;

use std::time::Instant;

use hullcut_capture::{SegmentParams, Segmenter};
use hullcut_dataset::{FrameSet, View};
use image::RgbImage;
use opencv::core::{Mat, Point, Size};
use opencv::imgproc;
use opencv::prelude::*;
use rayon::prelude::*;

const W: u32 = 640;
const H: u32 = 480;
const CAMERAS: usize = 6;

fn summary(name: &str, mut ms: Vec<f64>) {
    ms.sort_by(f64::total_cmp);
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    let p = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    println!(
        "{name:<44} mean {mean:6.3} ms  p50 {:6.3}  p95 {:6.3}  min {:6.3}  ({} runs)",
        p(0.5),
        p(0.95),
        ms[0],
        ms.len()
    );
}

fn time(iterations: usize, mut f: impl FnMut()) -> Vec<f64> {
    for _ in 0..iterations.min(5) {
        f();
    }
    (0..iterations)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    let quick = std::env::var_os("HULLCUT_BENCH_QUICK").is_some();
    let iterations = if quick { 5 } else { 300 };
    println!("{CAMERAS} x {W}x{H}, {} rayon threads", rayon::current_num_threads());
    let backgrounds: Vec<Vec<RgbImage>> = (0..CAMERAS).map(|c| common::backgrounds(W, H, c, 3)).collect();
    let views = (0..CAMERAS)
        .map(|c| Some(View { camera: c, timestamp_ns: 0, image: common::render_frame(W, H, c, 3, 1.07).0, mask: None }))
        .collect();
    let set = FrameSet { frame: 3, timestamp_ns: 0, views };

    let mut seg = Segmenter::new(SegmentParams::default(), &backgrounds)?;
    let mut masks = Vec::new();
    let run = |seg: &mut Segmenter, masks: &mut Vec<_>| {
        if let Err(e) = seg.segment_frame_set_into(&set, masks) {
            eprintln!("{e}");
        }
    };
    summary("background model + clean-up (default)", time(iterations, || run(&mut seg, &mut masks)));
    summary("  same, new masks each time", time(iterations, || drop(seg.segment_frame_set(&set))));

    let bare = SegmentParams { min_neighbors: 0, close_radius: 0, ..SegmentParams::default() };
    let mut seg = Segmenter::new(bare, &backgrounds)?;
    summary("background model, no clean-up", time(iterations, || run(&mut seg, &mut masks)));

    // OpenCV's closing (3x3) of six label masks, wrapping our buffers without copies; compare
    // with the clean-up share above (neighbour filter + closing + label bookkeeping).
    let mut seg = Segmenter::new(SegmentParams::default(), &backgrounds)?;
    let masks: Vec<Vec<u8>> = seg.segment_frame_set(&set)?.into_iter().flatten().map(|m| m.into_raw()).collect();
    let kernel = imgproc::get_structuring_element(imgproc::MORPH_RECT, Size::new(3, 3), Point::new(-1, -1))?;
    let opencv_close = time(iterations, || {
        masks.par_iter().for_each(|m| {
            let run = || -> opencv::Result<()> {
                let src = Mat::from_slice(m)?;
                let src = src.reshape(1, H as i32)?;
                let mut dst = Mat::default();
                imgproc::morphology_ex_def(&src, &mut dst, imgproc::MORPH_CLOSE, &kernel)?;
                Ok(())
            };
            if let Err(e) = run() {
                eprintln!("morphologyEx: {e}");
            }
        })
    });
    summary("OpenCV morphologyEx close 3x3 only", opencv_close);

    let mut mog2 = Segmenter::new(SegmentParams::default(), &vec![Vec::new(); CAMERAS])?;
    summary("MOG2 fallback + clean-up", time(iterations.min(100), || drop(mog2.segment_frame_set(&set))));
    Ok(())
}
