//! Line plots as SVG files (plotters), for the experiments.

use crate::error::LabError;
use std::path::Path;

use plotters::prelude::*;

/// One named curve of `(x, y)` points.
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
}

/// How the y axis is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YScale {
    /// From 0 to a bit above the largest value.
    Linear,
    /// Logarithmic from `floor` up: for curves that differ by orders of magnitude (a
    /// filter's centimetres against dead reckoning's metres).
    Log { floor_milli: u32 },
}

/// Draws `series` on one chart with a linear y axis and writes it to `path`.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), LabError> {
    lines_scaled(path, title, x_label, y_label, series, YScale::Linear)
}

/// Draws `series` on one chart and writes it to `path`.
pub fn lines_scaled(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    scale: YScale,
) -> Result<(), LabError> {
    let x_max = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .fold(1.0f64, f64::max);
    let y_max = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold(1.0f64, f64::max)
        * 1.1;
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| LabError::Plot {
        path: path.to_owned(),
        message: e.to_string(),
    };
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55);
    match scale {
        YScale::Linear => {
            let chart = builder
                .build_cartesian_2d(0.0..x_max, 0.0..y_max)
                .map_err(|e| err(&e))?;
            draw_lines(chart, x_label, y_label, series).map_err(|e| err(&e))?;
        }
        YScale::Log { floor_milli } => {
            let floor = floor_milli.max(1) as f64 / 1000.0;
            let chart = builder
                .build_cartesian_2d(0.0..x_max, (floor..y_max.max(floor * 10.0)).log_scale())
                .map_err(|e| err(&e))?;
            let clamped: Vec<Series> = series
                .iter()
                .map(|s| Series {
                    name: s.name,
                    points: s.points.iter().map(|&(x, y)| (x, y.max(floor))).collect(),
                })
                .collect();
            draw_lines(chart, x_label, y_label, &clamped).map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

type Chart<'a, Y> =
    ChartContext<'a, SVGBackend<'a>, Cartesian2d<plotters::coord::types::RangedCoordf64, Y>>;

/// Mesh, curves and legend on an already built chart (linear or log y).
fn draw_lines<'a, Y>(
    mut chart: Chart<'a, Y>,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), DrawingAreaErrorKind<std::io::Error>>
where
    Y: Ranged<ValueType = f64> + plotters::coord::ranged1d::ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()?;
    let colours = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
    ];
    for (k, s) in series.iter().enumerate() {
        let colour = colours[k % colours.len()];
        chart
            .draw_series(LineSeries::new(
                s.points.iter().copied(),
                colour.stroke_width(2),
            ))?
            .label(s.name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    Ok(())
}

/// One bar: a mean and its error (drawn ± `error`).
pub struct Bar<'a> {
    pub name: &'a str,
    pub value: f64,
    pub error: f64,
}

/// Draws `bars` side by side with error bars and writes the chart to `path`.
pub fn bars(path: &Path, title: &str, y_label: &str, bars: &[Bar]) -> Result<(), LabError> {
    let y_max = bars
        .iter()
        .map(|b| b.value + b.error)
        .fold(1.0f64, f64::max)
        * 1.15;
    let n = bars.len().max(1);
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| LabError::Plot {
        path: path.to_owned(),
        message: e.to_string(),
    };
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..n as f64, 0.0..y_max)
        .map_err(|e| err(&e))?;
    let names: Vec<&str> = bars.iter().map(|b| b.name).collect();
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n * 2 + 1)
        .x_label_formatter(&|x| {
            // Label only the bars' centres (k + 0.5).
            let k = x - 0.5;
            if (k - k.round()).abs() < 1e-6 && k >= 0.0 {
                names
                    .get(k.round() as usize)
                    .copied()
                    .unwrap_or("")
                    .to_string()
            } else {
                String::new()
            }
        })
        .y_desc(y_label)
        .draw()
        .map_err(|e| err(&e))?;
    let fill = RGBColor(31, 119, 180);
    chart
        .draw_series(bars.iter().enumerate().map(|(k, b)| {
            let x = k as f64;
            Rectangle::new([(x + 0.2, 0.0), (x + 0.8, b.value)], fill.filled())
        }))
        .map_err(|e| err(&e))?;
    chart
        .draw_series(bars.iter().enumerate().flat_map(|(k, b)| {
            let x = k as f64 + 0.5;
            let (lo, hi) = ((b.value - b.error).max(0.0), b.value + b.error);
            [
                PathElement::new(vec![(x, lo), (x, hi)], BLACK.stroke_width(2)),
                PathElement::new(vec![(x - 0.08, lo), (x + 0.08, lo)], BLACK.stroke_width(2)),
                PathElement::new(vec![(x - 0.08, hi), (x + 0.08, hi)], BLACK.stroke_width(2)),
            ]
        }))
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
