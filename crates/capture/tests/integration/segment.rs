//! Segmentation on procedural images with known masks.

use anyhow::Result;
use hullcut_capture::{ColourClass, ColourClasses, IouAccumulator, Method, SegmentParams, Segmenter, Window, iou};
use hullcut_dataset::{FrameSet, View, label};
use image::{GrayImage, RgbImage};

use crate::common::{backgrounds, render, render_frame};

const W: u32 = 640;
const H: u32 = 480;
const CAMERAS: usize = 6;

/// Exposure gain of frame k: the ±15 % drift of the renderer's hard setting, and 1 in between.
fn gain(frame: u64) -> f64 {
    [1.0, 1.15, 0.85, 1.07, 0.93][(frame % 5) as usize]
}

fn frame_set(frame: u64) -> (FrameSet, Vec<GrayImage>) {
    let mut views = Vec::new();
    let mut truth = Vec::new();
    for camera in 0..CAMERAS {
        let (image, mask) = render_frame(W, H, camera, frame, gain(frame));
        views.push(Some(View { camera, timestamp_ns: frame as i64, image, mask: None }));
        truth.push(mask);
    }
    (FrameSet { frame, timestamp_ns: frame as i64, views }, truth)
}

/// The procedural scene's palette as colour classes (the library writes no colour of its own): a
/// blue glove (60,110,200) as hand and steel (150,150,155) handle / (205,205,210) blade as
/// scalpel, shaded 0.3–1.0 with ±15 % exposure, chromaticity spread 0.03.
fn palette() -> ColourClasses {
    let shade = (0.3 * 0.85, 1.0 * 1.15);
    ColourClasses {
        classes: vec![
            ColourClass::from_albedo(label::HAND, [60.0, 110.0, 200.0], shade, 0.03),
            ColourClass::from_albedo(label::SCALPEL, [150.0, 150.0, 155.0], shade, 0.03),
            ColourClass::from_albedo(label::SCALPEL, [205.0, 205.0, 210.0], shade, 0.03),
        ],
        reject_mahalanobis2: None,
    }
}

/// Default settings with the palette's classes.
fn with_palette() -> SegmentParams {
    SegmentParams { classes: Some(palette()), ..SegmentParams::default() }
}

fn segmenter(params: SegmentParams) -> Result<Segmenter> {
    let bgs: Vec<Vec<RgbImage>> = (0..CAMERAS).map(|c| backgrounds(W, H, c, 3)).collect();
    Ok(Segmenter::new(params, &bgs)?)
}

/// Fraction of truly-background pixels labelled as anything else.
fn false_foreground(pred: &GrayImage, truth: &GrayImage) -> (u64, u64) {
    let mut fp = 0;
    let mut bg = 0;
    for (&p, &t) in pred.as_raw().iter().zip(truth.as_raw()) {
        if t == label::BACKGROUND {
            bg += 1;
            fp += u64::from(p != label::BACKGROUND);
        }
    }
    (fp, bg)
}

#[test]
fn background_model_segments_hand_and_scalpel() -> Result<()> {
    let mut seg = segmenter(with_palette())?;
    assert_eq!(seg.method(0), Some(Method::Background));
    let mut acc = IouAccumulator::new();
    let (mut fp, mut bg) = (0, 0);
    for frame in 0..10 {
        let (set, truth) = frame_set(frame);
        let masks = seg.segment_frame_set(&set)?;
        for (camera, (m, t)) in masks.iter().zip(&truth).enumerate() {
            let m = m.as_ref().expect("every view present");
            acc.add(camera, m, t)?;
            let (f, b) = false_foreground(m, t);
            fp += f;
            bg += b;
        }
    }
    let report = acc.report();
    println!("{}", serde_json::to_string_pretty(&report)?);
    let false_rate = fp as f64 / bg as f64;
    println!("false foreground: {fp} of {bg} background pixels ({false_rate:.6})");
    let [hand, scalpel] = [&report.labels[0], &report.labels[1]];
    assert_eq!((hand.name.as_str(), scalpel.name.as_str()), ("hand", "scalpel"));
    assert_eq!(report.views, 60);
    // Measured over these 60 views (10 frames, exposure 0.85..1.15): hand IoU pooled 0.992, worst
    // view 0.989; scalpel pooled 0.926, worst 0.893, recall 0.9995; false foreground 3.1e-4 of the
    // background. Nearly every error is an edge pixel: a pixel a quarter covered by the object
    // already differs clearly from the drape, so silhouettes grow by about half a pixel per side
    // (conservative for carving). That costs a 7-pixel handle and a 1-3 pixel blade far more IoU
    // than the 120-pixel glove, hence the lower scalpel bounds. The bounds leave 2-3 % (hand) and
    // about 5 % (scalpel) for changes to the scene or defaults; recall must stay near 1 because a
    // missed blade pixel can carve the blade away.
    assert!(hand.iou_pooled.is_some_and(|v| v > 0.97) && hand.iou_min.is_some_and(|v| v > 0.95), "{hand:?}");
    assert!(scalpel.iou_pooled.is_some_and(|v| v > 0.88) && scalpel.iou_min.is_some_and(|v| v > 0.84), "{scalpel:?}");
    assert!(hand.recall.is_some_and(|v| v > 0.99) && scalpel.recall.is_some_and(|v| v > 0.99));
    assert!(false_rate < 1e-3, "false foreground {false_rate}");
    Ok(())
}

#[test]
fn exposure_change_is_not_foreground_with_compensation() -> Result<()> {
    // An empty scene at ±15 % exposure. With compensation the estimated gain matches the true one
    // within 1 % (a median over ~1200 pixels, each with noise of about 1 %) and almost nothing is
    // foreground (measured: 0 pixels); without it 21 % of the image is foreground at either gain
    // (wherever 15 % of the brightness exceeds the 8 % tolerance plus the 3τ noise allowance).
    let mut seg = segmenter(with_palette())?;
    let mut raw = segmenter(SegmentParams { exposure_compensation: false, ..with_palette() })?;
    for (k, g) in [1.15, 0.85].into_iter().enumerate() {
        let (image, _) = render(W, H, 2, None, g, 0x5eed + k as u64);
        let fg = |m: &GrayImage| {
            m.as_raw().iter().filter(|&&v| v != label::BACKGROUND).count() as f64 / m.as_raw().len() as f64
        };
        let compensated = fg(&seg.segment(2, &image)?);
        let estimated = seg.last_exposure_gain(2).unwrap_or(0.0);
        let uncompensated = fg(&raw.segment(2, &image)?);
        println!(
            "gain {g}: estimated {estimated:.4}, foreground {compensated:.6} with, {uncompensated:.4} without compensation"
        );
        assert!((estimated - g).abs() < 0.01, "gain {g} estimated as {estimated}");
        assert!(compensated < 1e-4, "{compensated}");
        assert!(uncompensated > 0.1, "{uncompensated}");
    }
    Ok(())
}

#[test]
fn shadows_are_background_only_when_tolerated() -> Result<()> {
    // A cast shadow: the empty scene darkened to 60 % inside a disc (chromaticity unchanged).
    // The default tolerates 8 % darkening (the synthetic scenes have no shadows), so the disc is
    // foreground; with shadow_tolerance 0.5 it is background, while the glove (chromaticity far
    // from the drape's) stays foreground.
    let (mut image, _) = render(W, H, 0, None, 1.0, 0x5ad0);
    let (cx, cy, r) = (320.0, 300.0, 60.0);
    for (x, y, p) in image.enumerate_pixels_mut() {
        if (f64::from(x) - cx).hypot(f64::from(y) - cy) < r {
            p.0 = p.0.map(|v| (f64::from(v) * 0.6).round() as u8);
        }
    }
    let disc = std::f64::consts::PI * r * r;
    let fg = |m: &GrayImage| m.as_raw().iter().filter(|&&v| v != label::BACKGROUND).count() as f64;
    let mut strict = segmenter(with_palette())?;
    let mut tolerant = segmenter(SegmentParams { shadow_tolerance: 0.5, ..with_palette() })?;
    let (strict_fg, tolerant_fg) = (fg(&strict.segment(0, &image)?), fg(&tolerant.segment(0, &image)?));
    println!("shadow disc {disc:.0} px: foreground {strict_fg} (default), {tolerant_fg} (shadow tolerance 0.5)");
    assert!(strict_fg > 0.9 * disc, "{strict_fg}");
    assert!(tolerant_fg < 0.01 * disc, "{tolerant_fg}");
    let (set, truth) = frame_set(2);
    let mask = tolerant.segment(0, &set.views[0].as_ref().expect("present").image)?;
    assert!(iou(&mask, &truth[0], label::HAND).is_some_and(|v| v > 0.97));
    Ok(())
}

#[test]
fn opening_erases_the_thin_blade_which_is_why_it_is_off() -> Result<()> {
    // A 3x3 opening removes anything thinner than 3 px: the glove survives, the narrow end of
    // the blade (1-3 px, widened by about a pixel by mixed edge pixels) does not. Measured on this
    // frame set: scalpel recall 0.9997 without, 0.957 with the opening (the lost 4 % are blade,
    // the part the pose needs most); hand IoU 0.992 either way.
    let (set, truth) = frame_set(4);
    let mut plain = segmenter(with_palette())?;
    let mut opened = segmenter(SegmentParams { open_radius: 1, ..with_palette() })?;
    let (mut a, mut b) = (IouAccumulator::new(), IouAccumulator::new());
    for (camera, (p, o)) in
        plain.segment_frame_set(&set)?.iter().zip(opened.segment_frame_set(&set)?.iter()).enumerate()
    {
        a.add(camera, p.as_ref().expect("present"), &truth[camera])?;
        b.add(camera, o.as_ref().expect("present"), &truth[camera])?;
    }
    let (a, b) = (a.report(), b.report());
    let recall = |r: &hullcut_capture::SegmentationReport| r.labels[1].recall.unwrap_or(0.0);
    println!(
        "scalpel recall {:.4} plain, {:.4} opened; hand IoU {:?} / {:?}",
        recall(&a),
        recall(&b),
        a.labels[0].iou_pooled,
        b.labels[0].iou_pooled
    );
    assert!(recall(&b) < recall(&a) - 0.02);
    assert!(b.labels[0].iou_pooled.is_some_and(|v| v > 0.97));
    Ok(())
}

/// A window tests only its pixels: outside it the mask is background, inside it (away from its
/// border by the clean-up's reach) the mask is the whole image's; a window of the whole image, or
/// none, is the whole image's mask byte for byte; an empty window is all background; windows
/// reaching past the image are clipped to it. The same masks reused from call to call.
#[test]
fn a_window_segments_its_pixels_as_the_whole_image_does_and_nothing_else() -> Result<()> {
    let params = SegmentParams { open_radius: 1, close_radius: 2, ..with_palette() };
    let reach = params.open_radius + params.close_radius + 1;
    let mut whole = segmenter(params.clone())?;
    let mut windowed = segmenter(params)?;
    let windows = [
        Some(Window { x0: 100, y0: 60, x1: 420, y1: 400 }),
        Some(Window::whole(W, H)),
        None,
        Some(Window { x0: 500, y0: 300, x1: 900, y1: 700 }),
        Some(Window { x0: 10, y0: 10, x1: 10, y1: 200 }),
        Some(Window { x0: 0, y0: 0, x1: 17, y1: 480 }),
    ];
    let mut masks = Vec::new();
    let mut compared = 0u64;
    for frame in [2, 7] {
        let (set, _) = frame_set(frame);
        let reference = whole.segment_frame_set(&set)?;
        windowed.segment_frame_set_within(&set, &mut masks, &windows)?;
        for (camera, (m, r)) in masks.iter().zip(&reference).enumerate() {
            let (m, r) = (m.as_ref().expect("present"), r.as_ref().expect("present"));
            let win = windows[camera].map_or(Window::whole(W, H), |w| w.clipped(W, H));
            if win == Window::whole(W, H) {
                assert!(m == r, "camera {camera}: a window of the whole image changed the mask");
                continue;
            }
            for (x, y, p) in m.enumerate_pixels() {
                let inside = x >= win.x0 && x < win.x1 && y >= win.y0 && y < win.y1;
                let deep = x >= win.x0 + reach && x + reach < win.x1 && y >= win.y0 + reach && y + reach < win.y1;
                if !inside {
                    assert_eq!(p.0[0], label::BACKGROUND, "camera {camera}, pixel ({x}, {y}) outside {win:?}");
                } else if deep {
                    assert_eq!(p.0[0], r.get_pixel(x, y).0[0], "camera {camera}, pixel ({x}, {y}) inside {win:?}");
                    compared += u64::from(p.0[0] != label::BACKGROUND);
                }
            }
        }
    }
    // The windows held foreground to compare (the procedural hand is in the middle).
    assert!(compared > 10_000, "{compared} foreground pixels compared");
    Ok(())
}

/// Kept masks ([`Segmenter::keep_masks`]) handed back frame set after frame set come out as a
/// segmenter that clears every pixel outside the window gives them, over windows that move,
/// grow, shrink, vanish and cover the whole image in turn, their foreground changed in between
/// inside the window (as the labelling does); a mask that is not the one last written (a new
/// buffer full of foreground) is cleared whole.
#[test]
fn kept_masks_come_out_as_masks_cleared_whole() -> Result<()> {
    let params = SegmentParams { open_radius: 1, close_radius: 2, ..with_palette() };
    let mut plain = segmenter(params.clone())?;
    let mut keeping = segmenter(params)?;
    keeping.keep_masks(true);
    let (set, _) = frame_set(4);
    let (mut kept, mut fresh) = (Vec::new(), Vec::new());
    let mut seed = 41u64;
    let mut next = |n: u32| {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 33) % u64::from(n)) as u32
    };
    let mut foreground = 0u64;
    for step in 0..40 {
        let windows: Vec<Option<Window>> = (0..CAMERAS)
            .map(|_| match next(8) {
                0 => None,
                1 => Some(Window { x0: 5, y0: 5, x1: 5, y1: 5 }),
                _ => {
                    let (x0, y0) = (next(W), next(H));
                    Some(Window { x0, y0, x1: x0 + 1 + next(W), y1: y0 + 1 + next(H) })
                }
            })
            .collect();
        if step == 25 {
            // Another buffer, full of foreground, where camera 0's kept mask was.
            kept[0] = Some(GrayImage::from_pixel(W, H, image::Luma([label::HAND])));
        }
        keeping.segment_frame_set_within(&set, &mut kept, &windows)?;
        plain.segment_frame_set_within(&set, &mut fresh, &windows)?;
        for (camera, (k, f)) in kept.iter_mut().zip(fresh.iter_mut()).enumerate() {
            let (k, f) = (k.as_mut().expect("present"), f.as_mut().expect("present"));
            assert!(k == f, "step {step}, camera {camera}: the kept mask differs from one cleared whole");
            foreground += k.iter().filter(|&&p| p != label::BACKGROUND).count() as u64;
            // The labelling changes the foreground between frame sets, and only the foreground.
            for p in k.iter_mut().chain(f.iter_mut()).filter(|p| **p != label::BACKGROUND) {
                *p = label::UNKNOWN;
            }
        }
    }
    assert!(foreground > 100_000, "{foreground} foreground pixels compared");
    Ok(())
}

/// Stretches of rows test only their pixels: around each row's foreground (grown by the
/// clean-up's reach and more) they give the whole image's mask and report nothing reaching past
/// them, and the pixels they hold as tested; cut through the objects they report it; without
/// stretches for a view, its window.
#[test]
fn stretches_segment_their_pixels_and_tell_when_the_objects_reach_past_them() -> Result<()> {
    let params = SegmentParams { open_radius: 1, close_radius: 2, ..with_palette() };
    let reach = params.open_radius + params.close_radius + 1;
    let mut whole = segmenter(params.clone())?;
    let mut stretched = segmenter(params)?;
    let (set, _) = frame_set(5);
    let reference = whole.segment_frame_set(&set)?;
    // Each row's foreground in the reference, from its first to its last pixel.
    let extent = |m: &GrayImage| -> Vec<Option<(u32, u32)>> {
        (0..m.height())
            .map(|y| {
                let xs: Vec<u32> = (0..m.width()).filter(|&x| m.get_pixel(x, y).0[0] != label::BACKGROUND).collect();
                Some((*xs.first()?, *xs.last()? + 1))
            })
            .collect()
    };
    let extents: Vec<Vec<Option<(u32, u32)>>> =
        reference.iter().map(|m| extent(m.as_ref().expect("present"))).collect();
    let around = |rows: &[Option<(u32, u32)>], grow: u32| -> Vec<(u32, u32)> {
        (0..rows.len())
            .map(|y| {
                // The rows within `grow` of this one, their extents grown by `grow`.
                let near =
                    rows[y.saturating_sub(grow as usize)..(y + grow as usize + 1).min(rows.len())].iter().flatten();
                near.fold((u32::MAX, 0), |(a, b), &(c, d)| (a.min(c.saturating_sub(grow)), b.max(d + grow)))
            })
            .collect()
    };
    let margin = 3 * reach;
    let wide: Vec<Option<Vec<(u32, u32)>>> =
        extents.iter().enumerate().map(|(k, e)| (k != 2).then(|| around(e, margin))).collect();
    let mut masks = Vec::new();
    let tested = stretched.segment_frame_set_stretches(&set, &mut masks, &[], &wide)?;
    let reached: Vec<bool> = tested.iter().map(|t| t.reached_past).collect();
    assert_eq!(reached, vec![false; set.views.len()], "nothing reaches past stretches around the objects");
    // The pixels tested: each row's stretch within the image, or the whole image without them.
    for (k, (t, view)) in tested.iter().zip(&set.views).enumerate() {
        let (w, h) = view.as_ref().expect("present").image.dimensions();
        let expected: u64 = match &wide[k] {
            Some(stretches) => stretches.iter().map(|&(a, b)| u64::from(b.min(w).saturating_sub(a.min(w)))).sum(),
            None => u64::from(w) * u64::from(h),
        };
        assert_eq!(t.pixels, expected, "camera {k}");
        assert!(t.pixels > 0, "camera {k}");
    }
    let mut compared = 0u64;
    for (k, (m, r)) in masks.iter().zip(&reference).enumerate() {
        let (m, r) = (m.as_ref().expect("present"), r.as_ref().expect("present"));
        let Some(stretches) = &wide[k] else {
            assert!(m == r, "camera {k}: no stretches, the whole window");
            continue;
        };
        for (x, y, p) in m.enumerate_pixels() {
            let (a, b) = stretches[y as usize];
            if x < a || x >= b {
                assert_eq!(p.0[0], label::BACKGROUND, "camera {k}, pixel ({x}, {y}) outside its stretch");
            } else {
                assert_eq!(p.0[0], r.get_pixel(x, y).0[0], "camera {k}, pixel ({x}, {y})");
                compared += u64::from(p.0[0] != label::BACKGROUND);
            }
        }
    }
    assert!(compared > 10_000, "{compared} foreground pixels compared");
    // The left half of each row's foreground only: the objects reach past the stretches' ends.
    let halves: Vec<Option<Vec<(u32, u32)>>> = extents
        .iter()
        .map(|e| Some(e.iter().map(|r| r.map_or((0, 0), |(a, b)| (a.saturating_sub(margin), (a + b) / 2))).collect()))
        .collect();
    let tested = stretched.segment_frame_set_stretches(&set, &mut masks, &[], &halves)?;
    let reached: Vec<bool> = tested.iter().map(|t| t.reached_past).collect();
    assert_eq!(reached, vec![true; set.views.len()], "cut through the objects");
    Ok(())
}

#[test]
fn parallel_frame_set_equals_camera_by_camera() -> Result<()> {
    let (set, _) = frame_set(3);
    let mut a = segmenter(with_palette())?;
    let mut b = segmenter(with_palette())?;
    let parallel = a.segment_frame_set(&set)?;
    for (camera, view) in set.views.iter().enumerate() {
        let view = view.as_ref().expect("present");
        let single = b.segment(camera, &view.image)?;
        assert!(parallel[camera].as_ref() == Some(&single), "camera {camera}");
    }
    // A missing view stays missing; a wrong-sized image is an error naming the camera.
    let mut partial = set.clone();
    partial.views[4] = None;
    assert!(a.segment_frame_set(&partial)?[4].is_none());
    let err = a.segment(1, &RgbImage::new(320, 240)).expect_err("size");
    assert!(err.to_string().contains("camera 1"), "{err}");
    Ok(())
}

#[test]
fn colour_classes_are_learnt_from_truth_masks() -> Result<()> {
    let samples: Vec<(RgbImage, GrayImage)> = (0..3).map(|k| render_frame(W, H, k as usize, k, 1.0)).collect();
    let learnt = ColourClasses::fit(samples.iter().map(|(i, m)| (i, m)), 100)?;
    let hand = learnt.classes.iter().find(|c| c.label == label::HAND).expect("hand class");
    let scalpel = learnt.classes.iter().find(|c| c.label == label::SCALPEL).expect("scalpel class");
    // Glove chromaticity (60, 200)/370 = (0.162, 0.541); steel about (0.33, 0.34). Edge pixels
    // mixed with the drape pull the means by at most a few hundredths.
    println!("learnt hand mean {:?}, scalpel mean {:?}", hand.mean, scalpel.mean);
    assert!((hand.mean[0] - 0.162).abs() < 0.02 && (hand.mean[1] - 0.541).abs() < 0.03, "{hand:?}");
    assert!((scalpel.mean[0] - 0.33).abs() < 0.03 && (scalpel.mean[1] - 0.34).abs() < 0.03, "{scalpel:?}");
    assert_eq!(learnt.classify([60, 110, 200]), label::HAND);
    assert_eq!(learnt.classify([150, 150, 155]), label::SCALPEL);
    assert_eq!(palette().classify([30, 55, 100]), label::HAND, "a shaded glove");
    assert_eq!(palette().classify([62, 62, 64]), label::SCALPEL, "a shaded handle");

    // Segmenting with the learnt classes is as good as with the palette (within 2 %). The
    // blade's edge pixels, mixed with the drape, decide the scalpel's difference: with the whole
    // noise allowance in the chromaticity test (`chroma_noise` 1) the palette scored 0.929 and the
    // learnt classes 0.919; with the default half, more of those pixels are foreground, and the
    // learnt classes take more of them for the scalpel (false positives 477 -> 592 with the
    // palette, 550 -> 705 learnt; 0.913 and 0.898).
    let mut seg = segmenter(with_palette())?;
    let mut with_defaults = IouAccumulator::new();
    let mut with_learnt = IouAccumulator::new();
    let (set, truth) = frame_set(7);
    for (camera, m) in seg.segment_frame_set(&set)?.iter().enumerate() {
        with_defaults.add(camera, m.as_ref().expect("present"), &truth[camera])?;
    }
    seg.set_classes(Some(learnt))?;
    for (camera, m) in seg.segment_frame_set(&set)?.iter().enumerate() {
        with_learnt.add(camera, m.as_ref().expect("present"), &truth[camera])?;
    }
    for k in 0..2 {
        let (d, l) = (with_defaults.report().labels[k].iou_pooled, with_learnt.report().labels[k].iou_pooled);
        assert!(l.unwrap_or(0.0) > d.unwrap_or(1.0) - 0.02, "label {k}: learnt {l:?} defaults {d:?}");
    }

    // Too few pixels of a label is an error naming it.
    let empty = GrayImage::new(W, H);
    let err = ColourClasses::fit([(&samples[0].0, &empty)], 100).expect_err("no hand pixels");
    assert!(err.to_string().contains("hand"), "{err}");
    Ok(())
}

#[test]
fn iou_counts_pixels_and_ignores_unknown_truth() {
    let mut truth = GrayImage::new(4, 1);
    let mut pred = GrayImage::new(4, 1);
    // truth: hand hand bg unknown; pred: hand bg hand hand.
    for (x, v) in [1, 1, 0, 255].into_iter().enumerate() {
        truth.put_pixel(x as u32, 0, image::Luma([v]));
    }
    for (x, v) in [1, 0, 1, 1].into_iter().enumerate() {
        pred.put_pixel(x as u32, 0, image::Luma([v]));
    }
    // Intersection 1 (x=0); union 3 (x=0,1,2); x=3 is unknown in truth and not counted.
    assert_eq!(iou(&pred, &truth, label::HAND), Some(1.0 / 3.0));
    assert_eq!(iou(&pred, &truth, label::SCALPEL), None, "label in neither mask");
    assert_eq!(iou(&pred, &GrayImage::new(2, 2), label::HAND), None, "sizes differ");
    let mut acc = IouAccumulator::new();
    acc.add(0, &pred, &truth).expect("same size");
    let r = acc.report();
    assert_eq!((r.labels[0].true_positive, r.labels[0].false_positive, r.labels[0].false_negative), (1, 1, 1));
    assert_eq!(r.labels[1].views, 0);
    assert!(acc.add(0, &pred, &GrayImage::new(2, 2)).is_err());
}

#[test]
fn mog2_fallback_finds_objects_entering_a_learnt_scene() -> Result<()> {
    // Without empty-scene images MOG2 learns the background from the stream: here 300 frames of
    // the empty scene (8 noise realizations in turn), then the hand and scalpel enter. MOG2 learns
    // at rate 1/min(2n, history) after n frames, so early on (n = 15: rate 1/30) a uniformly
    // coloured, slowly moving glove is absorbed within a few frames (measured: hand recall 0.64);
    // after 300 frames the rate is 1/500 and the objects stay foreground.
    let (w, h) = (320, 240);
    let mut seg = Segmenter::new(with_palette(), &[Vec::new()])?;
    assert_eq!(seg.method(0), Some(Method::Mog2));
    let empty: Vec<RgbImage> = (0..8).map(|k| render(w, h, 0, None, 1.0, 0xe0 + k).0).collect();
    for k in 0..300 {
        seg.segment(0, &empty[k % empty.len()])?;
    }
    let mut acc = IouAccumulator::new();
    for frame in 0..10 {
        let (image, truth) = render_frame(w, h, 0, frame, 1.0);
        acc.add(0, &seg.segment(0, &image)?, &truth)?;
    }
    let r = acc.report();
    println!("{}", serde_json::to_string(&r)?);
    // Measured: hand IoU 0.985 pooled, 0.978 worst; scalpel 0.816 pooled (edge pixels weigh more
    // at half resolution), recall 0.999. Bounds leave about 3 % (hand) and 6 % (scalpel).
    let [hand, scalpel] = [&r.labels[0], &r.labels[1]];
    assert!(hand.iou_pooled.is_some_and(|v| v > 0.95) && hand.iou_min.is_some_and(|v| v > 0.93), "{hand:?}");
    assert!(scalpel.iou_pooled.is_some_and(|v| v > 0.75) && scalpel.recall.is_some_and(|v| v > 0.98), "{scalpel:?}");
    Ok(())
}

/// Sensor noise, grey levels: the sum of four uniform deviates on ±2, σ = sqrt(4 · 16/12) ≈ 2.3.
fn sensor_noise(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        (0..4)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 40) as f64 / f64::from(1u32 << 24) * 4.0 - 2.0
            })
            .sum::<f64>()
    }
}

/// Wood (133, 99, 67) with sensor noise of σ ≈ 2.3 levels per channel (the spread that makes
/// τ = 7), and inside a disc a pale hand of about the wood's brightness (127, 96, 86): its
/// chromaticity differs from the wood's by 0.108 of its channel sum, the median of the pale hand
/// over wood that the whole noise allowance hid (a never-seen recording, rig random:409 in look
/// random:421: Σ|c − ê·s| ≈ 33 levels against κ·s + 3τ ≈ 39.5).
fn pale_hand_over_wood(seed: u64, hand: bool) -> RgbImage {
    let mut noise = sensor_noise(seed);
    RgbImage::from_fn(160, 120, |x, y| {
        let inside = hand && (f64::from(x) - 80.0).hypot(f64::from(y) - 60.0) < 30.0;
        let base = if inside { [127.0, 96.0, 86.0] } else { [133.0, 99.0, 67.0] };
        image::Rgb(base.map(|c: f64| (c + noise()).round().clamp(0.0, 255.0) as u8))
    })
}

#[test]
fn a_pale_hand_over_wood_is_foreground_with_half_the_noise_allowance_and_the_wood_is_not() -> Result<()> {
    let backgrounds = vec![(0..3).map(|k| pale_hand_over_wood(11 + k, false)).collect::<Vec<_>>()];
    let frame = pale_hand_over_wood(99, true);
    let disc = |x: u32, y: u32| (f64::from(x) - 80.0).hypot(f64::from(y) - 60.0) < 30.0;
    let shares = |params: SegmentParams| -> Result<(f64, f64)> {
        let mask = Segmenter::new(params, &backgrounds)?.segment(0, &frame)?;
        let (mut hand, mut inside, mut wood, mut outside) = (0u32, 0u32, 0u32, 0u32);
        for (x, y, p) in mask.enumerate_pixels() {
            let fg = u32::from(p.0[0] != label::BACKGROUND);
            if disc(x, y) {
                (hand, inside) = (hand + fg, inside + 1);
            } else if !disc(x.saturating_sub(3), y) && !disc(x + 3, y) {
                // Away from the disc's edge (the closing may grow it by a pixel).
                (wood, outside) = (wood + fg, outside + 1);
            }
        }
        Ok((f64::from(hand) / f64::from(inside), f64::from(wood) / f64::from(outside)))
    };
    // The tests alone (no hysteresis), then with it.
    let alone = SegmentParams { weak_share: 1.0, ..SegmentParams::default() };
    let (half, half_wood) = shares(alone.clone())?;
    let (whole, whole_wood) = shares(SegmentParams { chroma_noise: 1.0, ..alone })?;
    let (joined, joined_wood) = shares(SegmentParams { chroma_noise: 1.0, ..SegmentParams::default() })?;
    println!(
        "pale hand found: {half:.3} with half the allowance, {whole:.3} with all of it, {joined:.3} with all of it and \
         the pixels that pass at half the tolerances joining it; wood: {half_wood:.5}, {whole_wood:.5}, {joined_wood:.5}"
    );
    assert!(half > 0.95, "{half}");
    assert!(whole < 0.2, "{whole}");
    assert!(half_wood < 1e-3, "{half_wood}");
    // The hysteresis finds the hand that the whole allowance hides, and no wood.
    assert!(joined > 0.95, "{joined}");
    assert!(joined_wood < 1e-3, "{joined_wood}");
    // Outside 0..1 is refused, naming the setting.
    let bad = Segmenter::new(SegmentParams { chroma_noise: 1.5, ..SegmentParams::default() }, &backgrounds);
    assert!(bad.is_err_and(|e| e.to_string().contains("chroma_noise")));
    for share in [0.0, -0.5, 1.5, f64::NAN] {
        let bad = Segmenter::new(SegmentParams { weak_share: share, ..SegmentParams::default() }, &backgrounds);
        assert!(bad.is_err_and(|e| e.to_string().contains("weak_share")), "{share}");
    }
    Ok(())
}

/// Wood with sensor noise as [`pale_hand_over_wood`]'s, and a blue hand (a rectangle from the
/// image's left edge) with five patches in it: the wood shifted towards the hand's colour (its
/// chromaticity 0.04 of the channel sum from the wood's, background pixel by pixel), the wood
/// itself (a gap in the hand), the wood 6% brighter (background pixel by pixel), the wood
/// shifted as far towards green (some 65° away from the hand's colour: the table under a light of
/// another colour, not the hand), and the first patch's colour again at the image's left edge
/// (not enclosed).
fn hand_with_patches(seed: u64, hand: bool) -> RgbImage {
    let mut noise = sensor_noise(seed);
    let wood = [133.0, 99.0, 67.0];
    RgbImage::from_fn(200, 120, |x, y| {
        let base = match hand_patch(x, y) {
            Some(Patch::Pale | Patch::Open) if hand => [127.0, 99.0, 73.0],
            Some(Patch::Brighter) if hand => wood.map(|c| c * 1.06),
            Some(Patch::Away) if hand => [127.0, 105.0, 67.0],
            None if hand && x < 180 && (20..100).contains(&y) => [60.0, 110.0, 200.0],
            _ => wood,
        };
        image::Rgb(base.map(|c: f64| (c + noise()).round().clamp(0.0, 255.0) as u8))
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Patch {
    Pale,
    Gap,
    Brighter,
    Away,
    Open,
}

/// Which patch of [`hand_with_patches`] a pixel lies in.
fn hand_patch(x: u32, y: u32) -> Option<Patch> {
    let square = |x0: u32, y0: u32| (x0..x0 + 14).contains(&x) && (y0..y0 + 14).contains(&y);
    [
        (40, 35, Patch::Pale),
        (80, 35, Patch::Gap),
        (120, 35, Patch::Brighter),
        (150, 65, Patch::Away),
        (0, 65, Patch::Open),
    ]
    .into_iter()
    .find(|&(x0, y0, _)| square(x0, y0))
    .map(|(_, _, p)| p)
}

/// Holes enclosed by the hand whose pixels pass as background one by one are filled where their
/// mean colour is not their background's (of a chromaticity towards the hand's, or brighter), and
/// left where it is (a gap showing the wood), where it leans away from the hand's, or where the
/// hole is open to the image's edge.
#[test]
fn holes_of_another_colour_than_their_background_are_filled_and_gaps_are_not() -> Result<()> {
    let backgrounds = vec![(0..3).map(|k| hand_with_patches(21 + k, false)).collect::<Vec<_>>()];
    let frame = hand_with_patches(7, true);
    let shares = |fill_holes: bool| -> Result<Vec<(Patch, f64)>> {
        let mask = Segmenter::new(SegmentParams { fill_holes, ..SegmentParams::default() }, &backgrounds)?
            .segment(0, &frame)?;
        Ok([Patch::Pale, Patch::Gap, Patch::Brighter, Patch::Away, Patch::Open]
            .into_iter()
            .map(|patch| {
                // The patch less its rim (the closing may reach a pixel into a gap).
                let inner = |x: u32, y: u32| (0..9).all(|k| hand_patch(x + k % 3 - 1, y + k / 3 - 1) == Some(patch));
                let (mut fg, mut n) = (0u32, 0u32);
                for (_, _, p) in mask.enumerate_pixels().filter(|&(x, y, _)| x > 0 && y > 0 && inner(x, y)) {
                    (fg, n) = (fg + u32::from(p.0[0] != label::BACKGROUND), n + 1);
                }
                (patch, f64::from(fg) / f64::from(n.max(1)))
            })
            .collect())
    };
    let (without, with) = (shares(false)?, shares(true)?);
    println!("foreground share of each patch without the hole filling {without:?}, with it {with:?}");
    let share = |v: &[(Patch, f64)], p: Patch| v.iter().find(|(q, _)| *q == p).map_or(f64::NAN, |(_, s)| *s);
    // Pixel by pixel the pale and brighter patches are background (a few noisy pixels aside).
    assert!(share(&without, Patch::Pale) < 0.5, "{without:?}");
    assert!(share(&without, Patch::Brighter) < 0.3, "{without:?}");
    assert!(share(&without, Patch::Open) < 0.3, "{without:?}");
    assert!(share(&without, Patch::Away) < 0.5, "{without:?}");
    // As holes they are not the wood; the gap is, and the open patch is no hole.
    assert!(share(&with, Patch::Pale) > 0.99, "{with:?}");
    assert!(share(&with, Patch::Brighter) > 0.99, "{with:?}");
    assert!(share(&with, Patch::Gap) < 0.01, "{with:?}");
    assert!(share(&with, Patch::Open) < 0.3, "{with:?}");
    assert_eq!(share(&with, Patch::Away), share(&without, Patch::Away), "{with:?}");
    Ok(())
}
