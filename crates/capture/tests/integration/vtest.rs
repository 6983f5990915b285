//! MOG2 on real footage: OpenCV's `vtest.avi` (768x576, static camera, people walking).

use std::path::Path;

use anyhow::Result;
use hullcut_capture::{FrameSource, Method, SegmentParams, Segmenter, SourceConfig, SourceSpec};
use image::GrayImage;
use opencv::core::{CV_32S, Mat};
use opencv::imgproc;
use opencv::prelude::*;

const VTEST: &str = "/usr/share/doc/opencv-doc/examples/data/vtest.avi";

/// Connected components of the foreground (8-connected): areas, largest first.
fn component_areas(mask: &GrayImage) -> Result<Vec<i32>> {
    let bin: Vec<u8> = mask.as_raw().iter().map(|&v| u8::from(v != 0) * 255).collect();
    let m = Mat::from_slice(&bin)?;
    let m = m.reshape(1, mask.height() as i32)?;
    let (mut labels, mut stats, mut centroids) = (Mat::default(), Mat::default(), Mat::default());
    let n = imgproc::connected_components_with_stats(&m, &mut labels, &mut stats, &mut centroids, 8, CV_32S)?;
    let mut areas: Vec<i32> =
        (1..n).map(|i| stats.at_2d::<i32>(i, imgproc::CC_STAT_AREA).copied()).collect::<Result<_, _>>()?;
    areas.sort_unstable_by(|a, b| b.cmp(a));
    Ok(areas)
}

/// Frames MOG2 gets to learn the scene before it is judged (its learning rate is 1/(2n) early on).
const WARM_UP: usize = 50;

#[test]
fn slow_vtest_mog2_foreground_is_people_and_sparse() -> Result<()> {
    if !Path::new(VTEST).is_file() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{VTEST} is missing (package opencv-doc; tools/setup.sh)"
        );
        eprintln!("skipping: {VTEST} not found (install the Debian package opencv-doc)");
        return Ok(());
    }
    let mut source = FrameSource::open(SourceConfig::new(0, SourceSpec::File(VTEST.into())))?;
    let mut seg = Segmenter::new(SegmentParams::default(), &[Vec::new()])?;
    assert_eq!(seg.method(0), Some(Method::Mog2));
    let mut frames = 0;
    let mut fractions = Vec::new();
    let (mut top_fg, mut top_px) = (0u64, 0u64);
    let (mut top3_share, mut small_share, mut largest) = (Vec::new(), Vec::new(), Vec::new());
    while let Some(frame) = source.next_frame()? {
        let mask = seg.segment(0, &frame.image)?;
        frames += 1;
        if frames <= WARM_UP {
            continue;
        }
        let (w, h) = mask.dimensions();
        let total = mask.as_raw().iter().filter(|&&v| v != 0).count();
        fractions.push(total as f64 / mask.as_raw().len() as f64);
        // Top sixth of the frame: the building's facade and roofline (one path with an
        // occasional walker crosses it on the left).
        let top_rows = &mask.as_raw()[..(h / 6 * w) as usize];
        top_fg += top_rows.iter().filter(|&&v| v != 0).count() as u64;
        top_px += top_rows.len() as u64;
        if frames % 10 == 0 && total > 0 {
            let areas = component_areas(&mask)?;
            top3_share.push(f64::from(areas.iter().take(3).sum::<i32>()) / total as f64);
            small_share.push(f64::from(areas.iter().filter(|&&a| a < 50).sum::<i32>()) / total as f64);
            largest.push(f64::from(areas[0]));
        }
    }
    let stat = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        (s[0], s[s.len() / 2], s[s.len() - 1])
    };
    let (f_min, f_med, f_max) = stat(&fractions);
    let (t3_min, t3_med, _) = stat(&top3_share);
    let (_, sm_med, sm_max) = stat(&small_share);
    let (big_min, _, big_max) = stat(&largest);
    let top = top_fg as f64 / top_px as f64;
    println!(
        "vtest.avi: {frames} frames; after {WARM_UP}: foreground fraction min {f_min:.4} median {f_med:.4} max {f_max:.4}"
    );
    println!("top sixth foreground {top:.5}; largest component {big_min}..{big_max} px");
    println!(
        "3 largest components hold min {t3_min:.3} median {t3_med:.3}; components < 50 px hold median {sm_med:.3} max {sm_max:.3}"
    );
    assert_eq!(frames, 795);
    // Measured after frame 50: foreground 0.51 %..4.35 % of the frame, median 1.97 %. Five to
    // eight walkers of about 30x80 px (2,400 px each) are 3-4 % of the 768x576 frame, and fewer
    // are in view at times, so the band is the people; below 0.1 % the walkers were missed,
    // above 8 % the background model has broken (global change, learning gone wrong).
    assert!(f_min > 0.001 && f_max < 0.08, "foreground fraction {f_min}..{f_max}");
    assert!((0.01..0.04).contains(&f_med), "median foreground fraction {f_med}");
    // Measured 0.21 % in the top sixth (the facade never moves; the walker on the top-left path
    // is most of it). 1 % would be speckle all over a static region.
    assert!(top < 0.01, "foreground in the static top rows {top}");
    // Concentrated (every 10th frame): the three largest components hold a median 70 % (min
    // 44 %) of the foreground, specks under 50 px a median 3.8 % (max 15 %: wind in the tree and
    // the tape). Someone is always in view: the largest component measured 1,042..10,915 px, one
    // person up to a group walking together, never a large part of the 442,368-px frame.
    assert!(t3_med > 0.5 && t3_min > 0.3, "top-3 share median {t3_med} min {t3_min}");
    assert!(sm_med < 0.1 && sm_max < 0.3, "speck share median {sm_med} max {sm_max}");
    assert!(big_min > 500.0 && big_max < 40_000.0, "largest component {big_min}..{big_max}");
    Ok(())
}
