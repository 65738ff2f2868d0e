//! Small plotting helper over `plotters` for the benchmark figures: a grid of
//! panels, each with log or linear axes, lines with markers, and labelled
//! reference lines (the real-time line, the thesis's numbers).
//!
//! Log axes are drawn as linear axes over log10 of the values, labelled 1eK at
//! the integer exponents: the same picture as a log scale, one code path.
#![allow(dead_code)]

use plotters::prelude::*;
use std::path::Path;

#[derive(Clone, Debug, Default)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// Dashed-looking (thin, no markers) instead of a line with markers.
    pub thin: bool,
}

#[derive(Clone, Debug, Default)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_log: bool,
    pub y_log: bool,
    pub series: Vec<Series>,
    /// Horizontal reference lines (y, label).
    pub hlines: Vec<(f64, String)>,
    /// Vertical reference lines (x, label).
    pub vlines: Vec<(f64, String)>,
}

const COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
];

fn tf(v: f64, log: bool) -> Option<f64> {
    if !v.is_finite() {
        return None;
    }
    if log {
        (v > 0.0).then(|| v.log10())
    } else {
        Some(v)
    }
}

fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if log {
        let (a, b) = (lo.floor(), hi.ceil());
        if a == b { (a - 1.0, b + 1.0) } else { (a, b) }
    } else {
        let pad = if hi > lo { 0.05 * (hi - lo) } else { 1.0 };
        (
            (lo - pad).min(if lo >= 0.0 { 0.0 } else { lo - pad }),
            hi + pad,
        )
    }
}

fn label(v: f64, log: bool) -> String {
    if log {
        if (v - v.round()).abs() < 1e-6 {
            format!("1e{}", v.round() as i64)
        } else {
            String::new()
        }
    } else if v.abs() >= 1000.0 || (v != 0.0 && v.abs() < 0.01) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Draws `panels` in a grid of `cols` columns into a PNG.
pub fn draw(path: &Path, title: &str, panels: &[Panel], cols: usize) -> Result<(), String> {
    let cols = cols.max(1).min(panels.len().max(1));
    let rows = panels.len().div_ceil(cols).max(1);
    let size = (560 * cols as u32, 420 * rows as u32 + 40);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    }
    let err = |e: &dyn std::fmt::Debug| format!("{}: {e:?}", path.display());
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| err(&e))?;
    let areas = root.split_evenly((rows, cols));
    for (panel, area) in panels.iter().zip(areas.iter()) {
        let (xl, yl) = (panel.x_log, panel.y_log);
        let xs = panel
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .chain(panel.vlines.iter().map(|l| l.0))
            .filter_map(|v| tf(v, xl));
        let ys = panel
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1))
            .chain(panel.hlines.iter().map(|l| l.0))
            .filter_map(|v| tf(v, yl));
        let (x0, x1) = range(xs, xl);
        let (y0, mut y1) = range(ys, yl);
        // Headroom for the legend in the upper right corner, above the data.
        y1 += if yl {
            (0.3 * (y1 - y0)).max(1.0).ceil()
        } else {
            0.3 * (y1 - y0)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(&e))?;
        let xfmt = move |v: &f64| label(*v, xl);
        let yfmt = move |v: &f64| label(*v, yl);
        chart
            .configure_mesh()
            .x_desc(&panel.x_label)
            .y_desc(&panel.y_label)
            .x_label_formatter(&xfmt)
            .y_label_formatter(&yfmt)
            .x_labels(if xl {
                ((x1 - x0) as usize * 2 + 1).min(20)
            } else {
                8
            })
            .y_labels(if yl {
                ((y1 - y0) as usize * 2 + 1).min(24)
            } else {
                8
            })
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| err(&e))?;
        for (y, text) in &panel.hlines {
            let Some(y) = tf(*y, yl) else { continue };
            chart
                .draw_series(LineSeries::new(
                    vec![(x0, y), (x1, y)],
                    BLACK.mix(0.5).stroke_width(1),
                ))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    text.clone(),
                    (x0 + 0.02 * (x1 - x0), y),
                    ("sans-serif", 13).into_font().color(&BLACK.mix(0.7)),
                )))
                .map_err(|e| err(&e))?;
        }
        for (x, text) in &panel.vlines {
            let Some(x) = tf(*x, xl) else { continue };
            chart
                .draw_series(LineSeries::new(
                    vec![(x, y0), (x, y1)],
                    BLACK.mix(0.5).stroke_width(1),
                ))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    text.clone(),
                    (x, y1 - 0.05 * (y1 - y0)),
                    ("sans-serif", 13).into_font().color(&BLACK.mix(0.7)),
                )))
                .map_err(|e| err(&e))?;
        }
        for (k, s) in panel.series.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter_map(|&(x, y)| Some((tf(x, xl)?, tf(y, yl)?)))
                .collect();
            if pts.is_empty() {
                continue;
            }
            let width = if s.thin { 1 } else { 2 };
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(width)))
                .map_err(|e| err(&e))?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            if !s.thin {
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                    .map_err(|e| err(&e))?;
            }
        }
        if panel.series.iter().any(|s| !s.label.is_empty()) {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.4))
                .label_font(("sans-serif", 13))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
