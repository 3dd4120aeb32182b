//! The report's figures: inline SVG drawn by `plotters` (text stays text,
//! so no font file is read and the browser renders the labels).

use super::error::ReportError;
use plotters::prelude::*;
use plotters::style::Palette99;

/// Width and height of every figure (px); the page scales them to fit.
const SIZE: (u32, u32) = (640, 420);

/// One group of points drawn alike (a track, an axle, a data split).
pub(crate) struct Points {
    pub label: String,
    /// Index into the palette, so a group keeps its colour across figures.
    pub color: usize,
    pub xy: Vec<(f64, f64)>,
    /// Filled or hollow marks (training against testing).
    pub filled: bool,
}

/// A straight line from `from` to `to` (a fit, the 1:1 line).
pub(crate) struct Segment {
    pub color: Option<usize>,
    pub from: (f64, f64),
    pub to: (f64, f64),
}

/// A vertical interval at `x` from `y.0` to `y.1` (a prediction interval
/// around a predicted value), drawn in a group's colour under its marks.
pub(crate) struct Whisker {
    pub color: usize,
    pub x: f64,
    pub y: (f64, f64),
}

/// Axis titles with units.
pub(crate) struct Axes<'a> {
    pub title: &'a str,
    pub x: &'a str,
    pub y: &'a str,
}

fn color(i: Option<usize>) -> RGBColor {
    match i {
        Some(i) => {
            let c = Palette99::pick(i).to_rgba();
            RGBColor(c.0, c.1, c.2)
        }
        None => RGBColor(120, 120, 120),
    }
}

fn draw_error<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> ReportError {
    ReportError::Figure(e.to_string())
}

/// Largest magnitude a linear axis reaches: its width stays finite.
const LINEAR_AXIS_LIMIT: f64 = 1e300;

/// Narrowest width of a linear axis, relative to its largest magnitude:
/// plotters steps from tick to tick by adding a tenth of the width, which
/// must not vanish in the values' rounding.
const LINEAR_AXIS_MIN_WIDTH: f64 = 1e-9;

/// The range of `values` with 5 % of padding; (0, 1) when there are none.
/// Bounded for plotters' tick search, which runs for ever on an infinite
/// width (values ±1e308 in a damaged model file) or on one too narrow for
/// its values (1e16 to 1e16 + 2): within ±[`LINEAR_AXIS_LIMIT`], at least
/// [`LINEAR_AXIS_MIN_WIDTH`] of the largest magnitude wide.
pub(crate) fn padded(values: impl Iterator<Item = f64>, from_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        let v = v.clamp(-LINEAR_AXIS_LIMIT, LINEAR_AXIS_LIMIT);
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if from_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let narrowest = LINEAR_AXIS_MIN_WIDTH * lo.abs().max(hi.abs());
    let pad = if hi - lo > narrowest {
        0.05 * (hi - lo)
    } else {
        narrowest.max(0.5)
    };
    (lo - pad, hi + pad)
}

/// `v` held inside the axis range `(lo, hi)` (NaN stays NaN): plotters
/// turns a coordinate into pixels with an `i32` sum that overflows for a
/// value millions of axis widths outside it.
fn clip(v: f64, (lo, hi): (f64, f64)) -> f64 {
    if v.is_nan() { v } else { v.clamp(lo, hi) }
}

type Root<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

/// A figure as an SVG string: a white canvas that `draw` fills.
fn svg(draw: impl FnOnce(&Root) -> Result<(), ReportError>) -> Result<String, ReportError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        draw(&root)?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

/// The frame every figure shares: its title, margins and label areas.
fn frame<'a, 'b>(root: &'a Root<'b>, axes: &Axes) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
    let mut b = ChartBuilder::on(root);
    b.caption(axes.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70);
    b
}

/// The axis titles, tick labels and grid in the figures' style; a macro
/// because the mesh's type depends on the axes' kinds (linear, log).
macro_rules! mesh {
    ($chart:expr, $axes:expr) => {
        $chart
            .configure_mesh()
            .x_desc($axes.x)
            .y_desc($axes.y)
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .light_line_style(RGBColor(235, 235, 235))
    };
}

/// The legend box of the series drawn with a label.
macro_rules! legend {
    ($chart:expr, $position:expr) => {
        $chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position($position)
            .draw()
            .map_err(draw_error)?
    };
}

/// A line's legend mark.
fn line_mark(c: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new([(x, y), (x + 16, y)], c.stroke_width(2))
}

/// The y range of marks `ys` (padded) widened to the whiskers' ends, by at
/// most `reach` times the marks' range on either side.
fn reaching_whiskers<I: Iterator<Item = f64>>(
    ys: impl Fn() -> I,
    whiskers: &[Whisker],
    reach: f64,
    from_zero: bool,
) -> (f64, f64) {
    let (m0, m1) = padded(ys(), from_zero);
    let reach = reach * (m1 - m0);
    let ends = whiskers
        .iter()
        .flat_map(|w| [w.y.0, w.y.1])
        .map(|y| y.clamp(m0 - reach, m1 + reach));
    padded(ys().chain(ends), from_zero)
}

/// Opacity of a whisker: the marks stay readable where intervals overlap.
pub(crate) const WHISKER_OPACITY: f64 = 0.35;

/// How far beyond the marks' range the y axis reaches for a prediction
/// interval's whisker, as a share of that range.
pub(crate) const WHISKER_REACH: f64 = 0.5;

/// A scatter of point groups with lines over them, as an SVG element.
pub(crate) fn scatter(
    axes: &Axes,
    points: &[Points],
    lines: &[Segment],
    from_zero: bool,
) -> Result<String, ReportError> {
    scatter_with_whiskers(axes, points, lines, (&[], 0.0), from_zero)
}

/// [`scatter`] with vertical intervals under the marks. The y axis reaches
/// the whiskers' ends, but by at most `reach` times the marks' own range on
/// either side (infinite: all of them), a longer whisker being cut at the
/// frame: one wide prediction interval must not squeeze every mark into a
/// line ([`WHISKER_REACH`]).
pub(crate) fn scatter_with_whiskers(
    axes: &Axes,
    points: &[Points],
    lines: &[Segment],
    (whiskers, reach): (&[Whisker], f64),
    from_zero: bool,
) -> Result<String, ReportError> {
    // Lines count too: a fit's end may lie beyond the marks.
    let ends = || lines.iter().flat_map(|l| [l.from, l.to]);
    let xs = points
        .iter()
        .flat_map(|p| p.xy.iter().map(|q| q.0))
        .chain(ends().map(|q| q.0));
    let ys = || {
        points
            .iter()
            .flat_map(|p| p.xy.iter().map(|q| q.1))
            .chain(ends().map(|q| q.1))
    };
    let (x0, x1) = padded(xs, from_zero);
    let (y0, y1) = reaching_whiskers(ys, whiskers, reach, from_zero);
    let at = |(x, y): (f64, f64)| (clip(x, (x0, x1)), clip(y, (y0, y1)));
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(draw_error)?;
        mesh!(chart, axes).draw().map_err(draw_error)?;
        for w in whiskers {
            let ends = [at((w.x, w.y.0)), at((w.x, w.y.1))];
            if ends.iter().all(|e| e.0.is_finite() && e.1.is_finite()) {
                let c = color(Some(w.color)).mix(WHISKER_OPACITY);
                chart
                    .draw_series(LineSeries::new(ends, c.stroke_width(1)))
                    .map_err(draw_error)?;
            }
        }
        for l in lines {
            let c = color(l.color);
            chart
                .draw_series(LineSeries::new([at(l.from), at(l.to)], c.stroke_width(2)))
                .map_err(draw_error)?;
        }
        for p in points {
            let c = color(Some(p.color));
            let style = if p.filled {
                c.filled()
            } else {
                c.stroke_width(1)
            };
            chart
                .draw_series(p.xy.iter().map(|&q| Circle::new(at(q), 3, style)))
                .map_err(draw_error)?
                .label(p.label.as_str())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, style));
        }
        if points.len() > 1 {
            legend!(chart, SeriesLabelPosition::UpperLeft);
        }
        Ok(())
    })
}

/// One bar of [`bars`]: its value and optional interval (lo, hi).
pub(crate) struct Bar {
    pub value: f64,
    pub interval: Option<(f64, f64)>,
    /// A palette index; None: steel blue.
    pub color: Option<usize>,
}

/// Bars at x = 1, 2, … (labels in the table beside the figure), each with
/// its interval as a whisker, and a zero line.
pub(crate) fn bars(axes: &Axes, bars: &[Bar]) -> Result<String, ReportError> {
    let values = bars.iter().flat_map(|b| {
        let (lo, hi) = b.interval.unwrap_or((b.value, b.value));
        [b.value, lo, hi]
    });
    let (y0, y1) = padded(values, true);
    let y = |v: f64| clip(v, (y0, y1));
    let x1 = bars.len() as f64 + 0.5;
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d(0.5..x1, y0..y1)
            .map_err(draw_error)?;
        mesh!(chart, axes)
            .x_labels(bars.len().clamp(1, 20))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                let x = i as f64 + 1.0;
                let fill = b.color.map_or(RGBColor(70, 110, 160), |c| color(Some(c)));
                Rectangle::new(
                    [(x - 0.3, 0.0), (x + 0.3, y(b.value))],
                    fill.mix(0.8).filled(),
                )
            }))
            .map_err(draw_error)?;
        for (i, b) in bars.iter().enumerate() {
            if let Some((lo, hi)) = b.interval {
                let x = i as f64 + 1.0;
                chart
                    .draw_series(LineSeries::new(
                        [(x, y(lo)), (x, y(hi))],
                        BLACK.stroke_width(2),
                    ))
                    .map_err(draw_error)?;
            }
        }
        chart
            .draw_series(LineSeries::new([(0.5, 0.0), (x1, 0.0)], BLACK))
            .map_err(draw_error)?;
        Ok(())
    })
}

/// Groups of bars at x = 1, 2, … (labels in the table beside the figure):
/// in each group one bar per series, side by side in the series' order and
/// colour, a missing value leaving its place empty; a legend names the
/// series, and a dashed line marks `reference` (1 for ratios).
pub(crate) fn grouped_bars(
    axes: &Axes,
    series: &[(String, usize)],
    groups: &[Vec<Option<f64>>],
    reference: f64,
) -> Result<String, ReportError> {
    let values = groups.iter().flatten().flatten().copied();
    let (y0, y1) = padded(values.chain([reference]), true);
    let x1 = groups.len() as f64 + 0.5;
    let width = 0.8 / series.len().max(1) as f64;
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d(0.5..x1, y0..y1)
            .map_err(draw_error)?;
        mesh!(chart, axes)
            .x_labels(groups.len().clamp(1, 20))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(draw_error)?;
        for (s, (label, c)) in series.iter().enumerate() {
            let fill = color(Some(*c)).mix(0.8).filled();
            let left = |g: usize| g as f64 + 1.0 - 0.4 + s as f64 * width;
            chart
                .draw_series(groups.iter().enumerate().filter_map(|(g, values)| {
                    let v = values.get(s).copied().flatten()?;
                    let v = clip(v, (y0, y1));
                    Some(Rectangle::new([(left(g), 0.0), (left(g) + width, v)], fill))
                }))
                .map_err(draw_error)?
                .label(label.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], fill));
        }
        chart
            .draw_series(LineSeries::new([(0.5, 0.0), (x1, 0.0)], BLACK))
            .map_err(draw_error)?;
        chart
            .draw_series(DashedLineSeries::new(
                [
                    (0.5, clip(reference, (y0, y1))),
                    (x1, clip(reference, (y0, y1))),
                ],
                6,
                4,
                BLACK.stroke_width(1),
            ))
            .map_err(draw_error)?;
        legend!(chart, SeriesLabelPosition::UpperLeft);
        Ok(())
    })
}

/// Lines through points at x = 0, 1, … (steps), one per series, with marks.
pub(crate) fn steps(
    axes: &Axes,
    series: &[(String, usize, Vec<f64>)],
) -> Result<String, ReportError> {
    let n = series.iter().map(|s| s.2.len()).max().unwrap_or(1);
    let (y0, y1) = padded(series.iter().flat_map(|s| s.2.iter().copied()), true);
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d(-0.3..(n as f64 - 0.7), y0..y1)
            .map_err(draw_error)?;
        mesh!(chart, axes)
            .x_labels(n.clamp(1, 20))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(draw_error)?;
        for (label, c, ys) in series {
            let c = color(Some(*c));
            let pts: Vec<(f64, f64)> = ys
                .iter()
                .enumerate()
                .map(|(i, &y)| (i as f64, clip(y, (y0, y1))))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(draw_error)?
                .label(label.as_str())
                .legend(line_mark(c));
            chart
                .draw_series(pts.into_iter().map(|q| Circle::new(q, 4, c.filled())))
                .map_err(draw_error)?;
        }
        legend!(chart, SeriesLabelPosition::UpperRight);
        Ok(())
    })
}

/// A tick label: three significant digits, in exponent form when far
/// from 1.
fn tick(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&v.abs()) {
        format!("{v:.1e}")
    } else {
        let s = format!(
            "{:.*}",
            (2 - v.abs().log10().floor() as i64).max(0) as usize,
            v
        );
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    }
}

/// Most decades a log axis spans, from its top down: the demo's road PSD
/// spans 14. A damaged side table's values (1e-302 to 1e305) on an axis of
/// every decade made plotters' tick search run for ever.
const MAX_DECADES: i32 = 30;

/// Largest value a log axis reaches: its ticks stay finite (10^300).
const LOG_AXIS_TOP: f64 = 1e300;

/// The range of positive `values` widened by 20 % each way (for a log
/// axis), at most [`MAX_DECADES`] below its top and within
/// (1e-300, [`LOG_AXIS_TOP`]); (1, 10) when there are none.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo.is_finite() && hi > lo {
        let hi = (hi * 1.2).min(LOG_AXIS_TOP);
        let lo = (lo / 1.2)
            .max(hi * 10f64.powi(-MAX_DECADES))
            .max(1.0 / LOG_AXIS_TOP);
        if hi > lo { (lo, hi) } else { (hi / 10.0, hi) }
    } else {
        (1.0, 10.0)
    }
}

/// Curves on log-log axes (positive values only), one colour each (the
/// points' `filled` is not used), with fitted lines over them drawn broad
/// and translucent in their curve's colour.
pub(crate) fn log_curves(
    axes: &Axes,
    series: &[Points],
    fits: &[Segment],
    legend_right: bool,
) -> Result<String, ReportError> {
    let positive = |v: &&(f64, f64)| v.0 > 0.0 && v.1 > 0.0 && v.0.is_finite() && v.1.is_finite();
    let all = || series.iter().flat_map(|s| s.xy.iter().filter(positive));
    let (x0, x1) = log_range(all().map(|p| p.0));
    let (y0, y1) = log_range(all().map(|p| p.1));
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(draw_error)?;
        mesh!(chart, axes)
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(draw_error)?;
        for s in series {
            let c = color(Some(s.color));
            let pts: Vec<(f64, f64)> = s.xy.iter().filter(positive).copied().collect();
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                .map_err(draw_error)?
                .label(s.label.as_str())
                .legend(line_mark(c));
        }
        for l in fits.iter().filter(|l| l.from.1 > 0.0 && l.to.1 > 0.0) {
            let c = color(l.color).mix(0.45);
            chart
                .draw_series(LineSeries::new([l.from, l.to], c.stroke_width(6)))
                .map_err(draw_error)?;
        }
        if legend_right {
            legend!(chart, SeriesLabelPosition::LowerRight);
        } else {
            legend!(chart, SeriesLabelPosition::LowerLeft);
        }
        Ok(())
    })
}

/// A grid of cells coloured by value (white at 0 to dark blue at the
/// largest): `cells[i][j]` spans x `x_edges[i]..x_edges[i+1]` and y
/// `y_edges[j]..y_edges[j+1]`. The caption states the scale.
pub(crate) fn heatmap(
    axes: &Axes,
    x_edges: &[f64],
    y_edges: &[f64],
    cells: &[Vec<f64>],
) -> Result<String, ReportError> {
    let increasing = |e: &[f64]| {
        e.len() >= 2
            && e.iter().all(|v| v.abs() <= LINEAR_AXIS_LIMIT)
            && e.windows(2).all(|w| w[1] > w[0])
            && e[e.len() - 1] - e[0] > LINEAR_AXIS_MIN_WIDTH * e[0].abs().max(e[e.len() - 1].abs())
    };
    if !increasing(x_edges) || !increasing(y_edges) {
        return Err(ReportError::Figure(format!(
            "{}: bin edges not finite and increasing ({x_edges:?}, {y_edges:?})",
            axes.title
        )));
    }
    if cells.len() + 1 != x_edges.len() || cells.iter().any(|c| c.len() + 1 != y_edges.len()) {
        return Err(ReportError::Figure(format!(
            "{}: {} columns of cells for {} x edges, or a column not of {} cells",
            axes.title,
            cells.len(),
            x_edges.len(),
            y_edges.len().saturating_sub(1)
        )));
    }
    let max = cells.iter().flatten().copied().fold(0.0f64, f64::max);
    let (x0, x1) = (x_edges[0], x_edges[x_edges.len() - 1]);
    let (y0, y1) = (y_edges[0], y_edges[y_edges.len() - 1]);
    let shade = |v: f64| {
        // sqrt: the maps' energy is concentrated; the tails stay visible.
        let t = if max > 0.0 { (v / max).sqrt() } else { 0.0 };
        let mix = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
        RGBColor(mix(255.0, 20.0), mix(255.0, 50.0), mix(255.0, 120.0))
    };
    svg(|root| {
        let mut chart = frame(root, axes)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(draw_error)?;
        mesh!(chart, axes)
            .disable_mesh()
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(cells.iter().enumerate().flat_map(|(i, col)| {
                col.iter()
                    .enumerate()
                    .filter(|(_, v)| **v > 0.0)
                    .map(move |(j, &v)| {
                        Rectangle::new(
                            [(x_edges[i], y_edges[j]), (x_edges[i + 1], y_edges[j + 1])],
                            shade(v).filled(),
                        )
                    })
            }))
            .map_err(draw_error)?;
        Ok(())
    })
}

/// Curves on a linear x and a logarithmic y axis (`log_y`) or linear y, one
/// colour each, with marks over them (e.g. the runs' operating points on a
/// master curve). Non-positive values are left out on a log axis.
pub(crate) fn curves_with_marks(
    axes: &Axes,
    curves: &[Points],
    marks: &[Points],
    log_y: bool,
) -> Result<String, ReportError> {
    let ok = |v: &&(f64, f64)| v.0.is_finite() && v.1.is_finite() && (!log_y || v.1 > 0.0);
    let all = || {
        curves
            .iter()
            .chain(marks)
            .flat_map(|s| s.xy.iter().filter(ok))
    };
    let (x0, x1) = padded(all().map(|p| p.0), false);
    macro_rules! draw {
        ($chart:expr, $y:expr) => {{
            let at = |(x, y): (f64, f64)| (clip(x, (x0, x1)), $y(y));
            let mut chart = $chart;
            mesh!(chart, axes)
                .y_label_formatter(&|v| tick(*v))
                .draw()
                .map_err(draw_error)?;
            for s in curves {
                let c = color(Some(s.color));
                let pts: Vec<(f64, f64)> = s.xy.iter().filter(ok).map(|&q| at(q)).collect();
                chart
                    .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                    .map_err(draw_error)?
                    .label(s.label.as_str())
                    .legend(line_mark(c));
            }
            for s in marks {
                let c = color(Some(s.color));
                chart
                    .draw_series(
                        s.xy.iter()
                            .filter(ok)
                            .map(|&q| Circle::new(at(q), 3, c.stroke_width(1))),
                    )
                    .map_err(draw_error)?;
            }
            legend!(chart, SeriesLabelPosition::UpperRight);
        }};
    }
    svg(|root| {
        if log_y {
            // Six decades at most: a training error that falls to rounding
            // would squash everything else.
            let (y0, y1) = log_range(all().map(|p| p.1));
            let y0 = y0.max(y1 * 1e-6);
            // Within 30 decades a log axis maps any positive value to a
            // pixel i32 holds: y is not clipped.
            draw!(
                frame(root, axes)
                    .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
                    .map_err(draw_error)?,
                |y: f64| y
            );
        } else {
            let (y0, y1) = padded(all().map(|p| p.1), false);
            draw!(
                frame(root, axes)
                    .build_cartesian_2d(x0..x1, y0..y1)
                    .map_err(draw_error)?,
                |y: f64| clip(y, (y0, y1))
            );
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damaged road side table's curves (values found by mutating one:
    /// 1e-302 to 1e305, 2e-308 to 1.6e308) draw in bounded time on an
    /// axis of at most 30 decades; before, the report hung in plotters.
    #[test]
    fn absurd_values_on_log_axes_draw_and_are_bounded() {
        let axes = Axes {
            title: "t",
            x: "x",
            y: "y",
        };
        for ys in [
            [1.138e-302, 1.0, 8.72e304],
            [2.19e-308, 3.0, 1.593e308],
            [f64::MIN_POSITIVE, 1.0, f64::MAX],
        ] {
            let series = [Points {
                label: "a".into(),
                color: 0,
                xy: ys
                    .iter()
                    .enumerate()
                    .map(|(k, &y)| (1.0 + k as f64, y))
                    .collect(),
                filled: false,
            }];
            let (lo, hi) = log_range(ys.into_iter());
            assert!(hi <= LOG_AXIS_TOP && lo > 0.0, "{lo} {hi}");
            assert!((hi / lo).log10() <= MAX_DECADES as f64 + 1e-9, "{lo} {hi}");
            assert!(log_curves(&axes, &series, &[], false).is_ok());
        }
        // An ordinary range: 20 % wider each way, by hand.
        let (lo, hi) = log_range([2.0, 50.0].into_iter());
        assert!((lo - 2.0 / 1.2).abs() < 1e-12 && (hi - 60.0).abs() < 1e-12);
        // One value, no range: the default decade.
        assert_eq!(log_range([5.0].into_iter()), (1.0, 10.0));
    }

    /// Values of a damaged model file (±1e308: an infinite width) or a
    /// range too narrow for its magnitude made plotters' tick search on a
    /// linear axis run for ever; the range is now bounded and each draws.
    #[test]
    fn absurd_values_on_linear_axes_draw_and_are_bounded() {
        let axes = Axes {
            title: "t",
            x: "x",
            y: "y",
        };
        for ys in [
            [-1e308, 0.0, 1e308],
            [f64::MAX, f64::MAX, f64::MAX],
            [1e16, 1e16 + 2.0, 1e16],
            [5e-324, 0.0, 1e-300],
        ] {
            let (lo, hi) = padded(ys.into_iter(), false);
            assert!(
                lo.is_finite() && hi.is_finite() && (hi - lo).is_finite(),
                "{lo} {hi}"
            );
            assert!(hi - lo >= 1e-9 * lo.abs().max(hi.abs()), "{lo} {hi}");
            let points = [Points {
                label: "a".into(),
                color: 0,
                xy: ys.iter().map(|&y| (y, y)).collect(),
                filled: false,
            }];
            assert!(scatter(&axes, &points, &[], false).is_ok());
        }
        // Whiskers widen the y range by at most half the marks' padded
        // range (0..10 padded: −0.5..10.5, so down to −6): by hand,
        // −6..10 padded 5 % (0.8); a NaN or ±1e308 end draws, cut.
        let whisker = |y| Whisker {
            color: 0,
            x: 1.0,
            y,
        };
        let marks = || [0.0, 10.0].into_iter();
        let (lo, hi) = reaching_whiskers(marks, &[whisker((-100.0, 3.0))], WHISKER_REACH, false);
        assert!(
            (lo + 6.8).abs() < 1e-12 && (hi - 10.8).abs() < 1e-12,
            "{lo} {hi}"
        );
        let (lo, hi) = reaching_whiskers(marks, &[whisker((-1.0, 11.0))], WHISKER_REACH, false);
        assert!(
            (lo + 1.6).abs() < 1e-12 && (hi - 11.6).abs() < 1e-12,
            "{lo} {hi}"
        );
        assert_eq!(
            reaching_whiskers(marks, &[], WHISKER_REACH, false),
            (-0.5, 10.5)
        );
        // Without a limit, all of it: −100..10 padded 5.5.
        let (lo, hi) = reaching_whiskers(marks, &[whisker((-100.0, 3.0))], f64::INFINITY, false);
        assert!(
            (lo + 105.5).abs() < 1e-12 && (hi - 15.5).abs() < 1e-12,
            "{lo} {hi}"
        );
        let points = [Points {
            label: "a".into(),
            color: 0,
            xy: vec![(1.0, 0.0), (2.0, 10.0)],
            filled: false,
        }];
        let odd = [whisker((f64::NAN, 1e308)), whisker((-1e308, f64::INFINITY))];
        assert!(scatter_with_whiskers(&axes, &points, &[], (&odd, f64::INFINITY), false).is_ok());
        // A heat map whose edges are not increasing or do not match its
        // cells is an error, not a hang or an index out of bounds.
        let cells = vec![vec![1.0; 2]; 2];
        assert!(heatmap(&axes, &[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0], &cells).is_ok());
        assert!(heatmap(&axes, &[0.0, 1.0, 1.0], &[0.0, 1.0, 2.0], &cells).is_err());
        assert!(heatmap(&axes, &[0.0, f64::INFINITY, 2.0], &[0.0, 1.0, 2.0], &cells).is_err());
        assert!(heatmap(&axes, &[0.0, 1.0], &[0.0, 1.0, 2.0], &cells).is_err());
        assert!(heatmap(&axes, &[0.0, 1.0, 2.0], &[0.0, 1.0], &cells).is_err());
        // An ordinary range: 5 % wider each way, by hand; one value: ±0.5.
        assert_eq!(padded([0.0, 10.0].into_iter(), false), (-0.5, 10.5));
        assert_eq!(padded([3.0].into_iter(), false), (2.5, 3.5));
        let (lo, hi) = padded([3.0].into_iter(), true);
        assert!(
            (lo + 0.15).abs() < 1e-15 && (hi - 3.15).abs() < 1e-15,
            "{lo} {hi}"
        );
    }
}
