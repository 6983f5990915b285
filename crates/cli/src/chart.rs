//! PNG line charts for the benchmarks (plotters, bitmap backend, DejaVu Sans from the system).

use std::path::Path;
use std::sync::Once;

use anyhow::{Context as _, bail};
use plotters::prelude::*;

/// Where Debian's fonts-dejavu-core puts the font (installed by tools/setup.sh).
const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

static REGISTER: Once = Once::new();

fn register_font() -> anyhow::Result<()> {
    let mut result = Ok(());
    REGISTER.call_once(|| {
        result = std::fs::read(FONT)
            .with_context(|| format!("reading the chart font {FONT} (tools/setup.sh installs fonts-dejavu-core)"))
            .and_then(|bytes| {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                    .map_err(|_| anyhow::anyhow!("{FONT} is not a usable font"))
            });
    });
    result
}

/// One named series of (x, y) points.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points.
    pub points: Vec<(f64, f64)>,
}

/// Axis scaling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    Linear,
    /// Base-10 logarithmic.
    Log,
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn range(series: &[Series], axis: impl Fn(&(f64, f64)) -> f64, scale: Scale) -> (f64, f64) {
    let vals: Vec<f64> = series.iter().flat_map(|s| s.points.iter().map(&axis)).filter(|v| v.is_finite()).collect();
    let (lo, hi) = vals.iter().fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    match scale {
        Scale::Log => (lo.max(1e-12) / 1.5, hi.max(1e-12) * 1.5),
        Scale::Linear => {
            let pad = 0.08 * (hi - lo).abs().max(1e-9);
            (lo - pad, hi + pad)
        }
    }
}

/// A compact tick label: plain for moderate magnitudes, scientific otherwise.
fn tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-2..1e5).contains(&a) {
        let text = format!("{v:.3}");
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        format!("{v:.0e}")
    }
}

/// Draws `series` as lines with markers into a 1000x650 PNG.
pub fn line_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    scales: (Scale, Scale),
    series: &[Series],
) -> anyhow::Result<()> {
    chart(path, [title, x_label, y_label], scales, series, true)
}

/// Draws `series` as markers alone (points that no order joins) into a 1000x650 PNG.
pub fn scatter_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    scales: (Scale, Scale),
    series: &[Series],
) -> anyhow::Result<()> {
    chart(path, [title, x_label, y_label], scales, series, false)
}

fn chart(
    path: &Path,
    [title, x_label, y_label]: [&str; 3],
    scales: (Scale, Scale),
    series: &[Series],
    lines: bool,
) -> anyhow::Result<()> {
    register_font()?;
    if series.iter().all(|s| s.points.is_empty()) {
        bail!("{}: nothing to plot", path.display());
    }
    let (x0, x1) = range(series, |p| p.0, scales.0);
    let (y0, y1) = range(series, |p| p.1, scales.1);
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE).context("drawing the chart background")?;
    let draw = |chart_result: anyhow::Result<()>| chart_result.with_context(|| format!("drawing {}", path.display()));
    macro_rules! body {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style(("sans-serif", 16))
                .x_label_formatter(&|v| tick(*v))
                .y_label_formatter(&|v| tick(*v))
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for (i, s) in series.iter().enumerate() {
                let color = COLORS[i % COLORS.len()];
                let line: &[(f64, f64)] = if lines { &s.points } else { &[] };
                let drawn = chart
                    .draw_series(LineSeries::new(line.iter().copied(), color.stroke_width(2)))
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .label(s.label.clone());
                if lines {
                    drawn.legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
                } else {
                    drawn.legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
                }
                chart
                    .draw_series(s.points.iter().map(|&p| Circle::new(p, if lines { 4 } else { 6 }, color.filled())))
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 16))
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok(())
        }};
    }
    let mut builder = ChartBuilder::on(&root);
    builder.caption(title, ("sans-serif", 24)).margin(15).x_label_area_size(50).y_label_area_size(80);
    let result: anyhow::Result<()> = match scales {
        (Scale::Log, Scale::Log) => body!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
                .map_err(|e| anyhow::anyhow!("{e}"))?
        ),
        (Scale::Linear, Scale::Log) => {
            body!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        (Scale::Log, Scale::Linear) => {
            body!(builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        (Scale::Linear, Scale::Linear) => {
            body!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
    };
    draw(result)?;
    root.present().with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
