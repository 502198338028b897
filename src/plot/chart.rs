//! XY charts: scatter and line plots with linear or logarithmic axes, a legend and reference
//! lines.

use std::path::Path;

use crate::error::{Error, Result};

use super::canvas::{text_size, Align, Canvas, Marker, Rect, TextStyle};
use super::colour::{series_colour, Rgb};
use super::ticks::{
    decade_at_or_above, decade_at_or_below, decade_span, format_tick, pow10, ticks_within,
};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SeriesStyle {
    /// A marker at each point.
    Markers,
    /// Straight lines joining the points in the order given.
    Lines,
    /// Both.
    LinesAndMarkers,
}

impl SeriesStyle {
    fn has_markers(self) -> bool {
        self != SeriesStyle::Lines
    }

    fn has_lines(self) -> bool {
        self != SeriesStyle::Markers
    }
}

/// One named set of points.
///
/// Its colour and marker default to the `i`-th entries of [`super::PALETTE`] and
/// [`Marker::ALL`] for the `i`-th series of the chart; its style defaults to the plot's
/// ([`scatter_plot`]: markers, [`line_plot`]: lines and markers).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    name: String,
    points: Vec<(f64, f64)>,
    colour: Option<Rgb>,
    marker: Option<Marker>,
    style: Option<SeriesStyle>,
}

impl Series {
    /// A series called `name` (shown in the legend unless empty) through `points` `(x, y)`.
    pub fn new(name: impl Into<String>, points: impl IntoIterator<Item = (f64, f64)>) -> Self {
        Series {
            name: name.into(),
            points: points.into_iter().collect(),
            colour: None,
            marker: None,
            style: None,
        }
    }

    /// Draws the series in `colour`.
    pub fn colour(mut self, colour: Rgb) -> Self {
        self.colour = Some(colour);
        self
    }

    /// Draws the series' points as `marker`.
    pub fn marker(mut self, marker: Marker) -> Self {
        self.marker = Some(marker);
        self
    }

    /// Draws the series in `style`, whatever the plot's default.
    pub fn style(mut self, style: SeriesStyle) -> Self {
        self.style = Some(style);
        self
    }

    /// The name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The points.
    pub fn points(&self) -> &[(f64, f64)] {
        &self.points
    }
}

/// Where the legend goes: a corner inside the plot area, or nowhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LegendPosition {
    /// A corner of the plot area clear of points, lines and labels if there is one, else
    /// beside the plot area, on the right.
    Auto,
    /// Top left corner.
    TopLeft,
    /// Top right corner.
    TopRight,
    /// Bottom left corner.
    BottomLeft,
    /// Bottom right corner.
    BottomRight,
    /// Beside the plot area, on the right (the plot area narrows to make room).
    Outside,
    /// No legend.
    Hidden,
}

/// A labelled reference line across the plot at a fixed x (vertical) or y (horizontal).
#[derive(Debug, Clone, PartialEq)]
struct RefLine {
    value: f64,
    label: String,
}

/// The description of an XY chart, drawn by [`scatter_plot`] or [`line_plot`].
///
/// ```
/// use rdlidar::plot::{line_plot, Chart, Series};
///
/// # fn main() -> rdlidar::Result<()> {
/// let chart = Chart::new("Recovery error")
///     .x_label("pulse length K_p")
///     .y_label("relative error")
///     .log_y(true)
///     .series(Series::new("FISTA", [(100.0, 0.5), (200.0, 0.05), (400.0, 0.01)]))
///     .vline(250.0, "critical K_p");
/// let fig = line_plot(&chart)?;
/// assert_eq!((fig.canvas().width(), fig.canvas().height()), (800, 520));
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    log_x: bool,
    log_y: bool,
    x_range: Option<(f64, f64)>,
    y_range: Option<(f64, f64)>,
    width: usize,
    height: usize,
    series: Vec<Series>,
    vlines: Vec<RefLine>,
    hlines: Vec<RefLine>,
    legend: LegendPosition,
}

impl Chart {
    /// An empty 800 × 520 chart titled `title` (no title if empty), linear axes fitted to the
    /// data, legend placed automatically.
    pub fn new(title: impl Into<String>) -> Self {
        Chart {
            title: title.into(),
            x_label: String::new(),
            y_label: String::new(),
            log_x: false,
            log_y: false,
            x_range: None,
            y_range: None,
            width: 800,
            height: 520,
            series: Vec::new(),
            vlines: Vec::new(),
            hlines: Vec::new(),
            legend: LegendPosition::Auto,
        }
    }

    /// The label under the x axis.
    pub fn x_label(mut self, label: impl Into<String>) -> Self {
        self.x_label = label.into();
        self
    }

    /// The label left of the y axis (drawn reading upwards).
    pub fn y_label(mut self, label: impl Into<String>) -> Self {
        self.y_label = label.into();
        self
    }

    /// A logarithmic x axis, labelled by decades.
    pub fn log_x(mut self, on: bool) -> Self {
        self.log_x = on;
        self
    }

    /// A logarithmic y axis, labelled by decades.
    pub fn log_y(mut self, on: bool) -> Self {
        self.log_y = on;
        self
    }

    /// Shows exactly `lo ..= hi` on the x axis instead of the data's range; points outside are
    /// clipped.
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    /// Shows exactly `lo ..= hi` on the y axis.
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    /// The image size in pixels.
    pub fn size(mut self, width: usize, height: usize) -> Self {
        self.width = width;
        self.height = height;
        self
    }

    /// Adds a series.
    pub fn series(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// Adds a dashed vertical line at `x`, labelled at its top (e.g. a critical value).
    pub fn vline(mut self, x: f64, label: impl Into<String>) -> Self {
        self.vlines.push(RefLine {
            value: x,
            label: label.into(),
        });
        self
    }

    /// Adds a dashed horizontal line at `y`, labelled at its right end.
    pub fn hline(mut self, y: f64, label: impl Into<String>) -> Self {
        self.hlines.push(RefLine {
            value: y,
            label: label.into(),
        });
        self
    }

    /// Places the legend.
    pub fn legend(mut self, position: LegendPosition) -> Self {
        self.legend = position;
        self
    }
}

/// A rendered chart: the image and where its data coordinates lie.
#[derive(Debug, Clone, PartialEq)]
pub struct ChartFigure {
    canvas: Canvas,
    plot: Rect,
    legend: Option<Rect>,
    x: Axis,
    y: Axis,
}

impl ChartFigure {
    /// The image.
    pub fn canvas(&self) -> &Canvas {
        &self.canvas
    }

    /// The image, for further drawing.
    pub fn into_canvas(self) -> Canvas {
        self.canvas
    }

    /// The framed plot area; the frame is its outermost ring of pixels.
    pub fn plot_area(&self) -> Rect {
        self.plot
    }

    /// The legend's box, if one was drawn.
    pub fn legend_area(&self) -> Option<Rect> {
        self.legend
    }

    /// The data range shown on the x axis.
    pub fn x_range(&self) -> (f64, f64) {
        (self.x.lo, self.x.hi)
    }

    /// The data range shown on the y axis.
    pub fn y_range(&self) -> (f64, f64) {
        (self.y.lo, self.y.hi)
    }

    /// The labelled tick values of the x axis.
    pub fn x_ticks(&self) -> Vec<f64> {
        self.x.major.iter().map(|(v, _)| *v).collect()
    }

    /// The labelled tick values of the y axis.
    pub fn y_ticks(&self) -> Vec<f64> {
        self.y.major.iter().map(|(v, _)| *v).collect()
    }

    /// The pixel position `(column, row)` of the data point `(x, y)`, in real coordinates (the
    /// pixel containing it is the integer part); `None` for a value a logarithmic axis cannot
    /// show or a non-finite one. Points outside the shown ranges map outside the plot area.
    pub fn to_pixel(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let (fx, fy) = (self.x.frac(x)?, self.y.frac(y)?);
        Some(place(self.plot, fx, fy))
    }

    /// The image as a PNG file, in memory.
    pub fn encode_png(&self) -> Vec<u8> {
        self.canvas.encode_png()
    }

    /// Writes the image to `path` as a PNG file, atomically.
    ///
    /// # Errors
    /// [`Error::File`] naming `path` when it cannot be written.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        self.canvas.save_png(path)
    }
}

/// Draws `chart` with markers only, except for series styled otherwise (e.g. "error against run
/// time" for a set of solvers).
///
/// # Errors
/// [`Error::InvalidParameter`] for a chart without any point (`series`), a zero or oversized
/// image (`width`, `height`) or one too small for its labels (`size`), an axis range that is
/// reversed, empty or not positive on a logarithmic axis (`x_range`, `y_range`), a point or
/// reference line at a non-positive value on a logarithmic axis (`log_x`, `log_y`), or data
/// spanning more than `f64` can hold with margins (`range`); [`Error::NonFinite`] for a NaN or
/// infinite coordinate.
pub fn scatter_plot(chart: &Chart) -> Result<ChartFigure> {
    render(chart, SeriesStyle::Markers)
}

/// Draws `chart` with each series' points joined by lines in the order given, and marked (e.g.
/// "error against pulse length", with the critical length as a vertical line).
///
/// # Errors
/// As [`scatter_plot`].
pub fn line_plot(chart: &Chart) -> Result<ChartFigure> {
    render(chart, SeriesStyle::LinesAndMarkers)
}

// ---------------------------------------------------------------------------------------------
// Axes

/// A tick label: plain text, or a power of ten drawn as "10" with a raised exponent.
#[derive(Debug, Clone, PartialEq)]
enum Label {
    Text(String),
    Power(i32),
}

/// One axis: the range shown, the labelled ticks and the unlabelled (minor) ones.
#[derive(Debug, Clone, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    major: Vec<(f64, Label)>,
    minor: Vec<f64>,
}

impl Axis {
    /// Where `v` falls between the ends, 0 at `lo` and 1 at `hi`.
    fn frac(&self, v: f64) -> Option<f64> {
        if !v.is_finite() || (self.log && v <= 0.0) {
            return None;
        }
        Some(if self.log {
            (v.log10() - self.lo.log10()) / (self.hi.log10() - self.lo.log10())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        })
    }
}

/// The pixel position of the fractions `(fx, fy)` of a plot area: 0 and 1 at the centres of its
/// frame's pixels, y upwards.
fn place(plot: Rect, fx: f64, fy: f64) -> (f64, f64) {
    let x = plot.x as f64 + 0.5 + fx * (plot.width - 1) as f64;
    let y = plot.bottom() as f64 - 0.5 - fy * (plot.height - 1) as f64;
    (x, y)
}

/// Fraction of the data's span left free at each end of a fitted axis.
const MARGIN: f64 = 0.05;

/// Builds an axis over `values` (or exactly `range`), with about `target` labelled ticks.
fn build_axis(values: &[f64], range: Option<(f64, f64)>, log: bool, target: usize) -> Result<Axis> {
    let fitted = range.is_none();
    let (mut lo, mut hi) = match range {
        Some(r) => r,
        None => values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            }),
    };
    if log {
        if fitted {
            let data = (lo, hi);
            let (mut l0, mut l1) = (lo.log10(), hi.log10());
            if l0 == l1 {
                l0 -= 0.5;
                l1 += 0.5;
            }
            let pad = MARGIN * (l1 - l0);
            lo = 10f64.powf(l0 - pad);
            hi = 10f64.powf(l1 + pad);
            if !(lo >= f64::MIN_POSITIVE && hi.is_finite()) {
                return Err(Error::param(
                    "range",
                    format!(
                        "the data span [{}, {}]: too wide for a logarithmic axis",
                        data.0, data.1
                    ),
                ));
            }
            decade_span(lo, hi)?;
            if decade_at_or_below(hi) - decade_at_or_above(lo) < 1 {
                // Fewer than two decades inside: show the enclosing decades.
                lo = pow10(decade_at_or_below(lo));
                hi = pow10(decade_at_or_above(hi));
            }
        }
        decade_span(lo, hi)?;
        if lo == hi {
            return Err(Error::param("range", format!("[{lo}, {hi}] is empty")));
        }
        Ok(log_axis(lo, hi, target))
    } else {
        if fitted {
            if lo == hi {
                let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
                lo -= d;
                hi += d;
            }
            let pad = MARGIN * (hi - lo);
            lo -= pad;
            hi += pad;
        }
        linear_axis(lo, hi, target)
    }
}

fn linear_axis(lo: f64, hi: f64, target: usize) -> Result<Axis> {
    if !(hi - lo).is_finite() || hi - lo <= 0.0 {
        return Err(Error::param(
            "range",
            format!("[{lo}, {hi}] cannot be divided into ticks"),
        ));
    }
    let (ticks, e) = ticks_within(lo, hi, target);
    let largest = ticks.iter().fold(0f64, |m, t| m.max(t.abs()));
    Ok(Axis {
        lo,
        hi,
        log: false,
        major: ticks
            .iter()
            .map(|&t| (t, Label::Text(format_tick(t, e, largest))))
            .collect(),
        minor: Vec::new(),
    })
}

fn log_axis(lo: f64, hi: f64, target: usize) -> Axis {
    let (k0, k1) = (decade_at_or_above(lo), decade_at_or_below(hi));
    let mut major = Vec::new();
    let mut minor = Vec::new();
    let inside = |v: f64| v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12);
    if k1 > k0 {
        let count = (k1 - k0 + 1) as usize;
        let stride = count.div_ceil(target.max(2)).max(1) as i32;
        // Label the multiples of the stride (10^0, 10^3, ...) if there are two of them, else
        // every stride-th decade from the first.
        let multiples = (k0..=k1).filter(|k| k.rem_euclid(stride) == 0).count();
        let origin = if multiples >= 2 { 0 } else { k0 };
        for k in k0..=k1 {
            if (k - origin).rem_euclid(stride) == 0 {
                major.push((pow10(k), Label::Power(k)));
            } else {
                minor.push(pow10(k));
            }
        }
        if (hi / lo).log10() <= 6.5 {
            for k in decade_at_or_below(lo)..=k1 {
                for m in 2..=9 {
                    let v = m as f64 * pow10(k);
                    if inside(v) {
                        minor.push(v);
                    }
                }
            }
        }
    } else {
        // A range within about one decade: label 1, 2 and 5 times the powers of ten.
        for k in decade_at_or_below(lo)..=decade_at_or_above(hi) {
            for m in [1, 2, 5] {
                let v = m as f64 * pow10(k);
                if inside(v) {
                    major.push((v, Label::Text(format_tick(v, k, hi))));
                }
            }
        }
    }
    Axis {
        lo,
        hi,
        log: true,
        major,
        minor,
    }
}

// ---------------------------------------------------------------------------------------------
// Drawing

const INK: Rgb = Rgb::hex(0x262626);
const FRAME: Rgb = Rgb::hex(0x404040);
const GRID: Rgb = Rgb::hex(0xe8e8e8);
const REF_LINE: Rgb = Rgb::hex(0x595959);
const LEGEND_EDGE: Rgb = Rgb::hex(0xbfbfbf);
const TEXT: TextStyle = TextStyle::new(2, INK);
const TITLE: TextStyle = TextStyle::new(2, Rgb::hex(0x111111)).bold();
const EXPONENT: TextStyle = TextStyle::new(1, INK);

const PAD: i64 = 14;
const TICK_LEN: i64 = 6;
const MINOR_TICK_LEN: i64 = 3;
const LINE_WIDTH: f64 = 2.2;
const MARKER_RADIUS: f64 = 4.6;
const HALO: f64 = 1.4;

/// The size of a tick label.
fn label_size(label: &Label) -> (i64, i64) {
    match label {
        Label::Text(s) => text_size(s, TEXT),
        Label::Power(k) => {
            let (bw, bh) = text_size("10", TEXT);
            let (ew, _) = text_size(&k.to_string(), EXPONENT);
            (bw + 1 + ew, bh + exponent_rise())
        }
    }
}

/// How far the exponent's top stands above the top of the "10".
fn exponent_rise() -> i64 {
    4
}

/// Draws a tick label with its box's top-left corner at `(x, y)`.
fn draw_label(canvas: &mut Canvas, label: &Label, x: i64, y: i64) {
    match label {
        Label::Text(s) => {
            canvas.text(x, y, s, TEXT);
        }
        Label::Power(k) => {
            let rise = exponent_rise();
            let base = canvas.text(x, y + rise, "10", TEXT);
            canvas.text(base.right() + 1, y, &k.to_string(), EXPONENT);
        }
    }
}

/// The top row of text in `style` whose capitals are centred on row `centre`.
fn top_for_centre(centre: i64, style: TextStyle) -> i64 {
    centre - (7 * style.scale.max(1) as i64 - 1) / 2
}

/// Everything a chart needs, checked.
fn validate(chart: &Chart) -> Result<()> {
    let mut any = false;
    for s in &chart.series {
        for (i, &(x, y)) in s.points.iter().enumerate() {
            if !x.is_finite() || !y.is_finite() {
                return Err(Error::NonFinite {
                    what: format!("point {i} ({x}, {y}) of series `{}`", s.name),
                });
            }
            for (log, v, name, axis) in [
                (chart.log_x, x, "log_x", "x"),
                (chart.log_y, y, "log_y", "y"),
            ] {
                if log && v <= 0.0 {
                    return Err(Error::param(
                        name,
                        format!(
                            "point {i} of series `{}` has {axis} = {v}; a logarithmic axis \
                             needs positive values",
                            s.name
                        ),
                    ));
                }
            }
            any = true;
        }
    }
    if !any {
        return Err(Error::param("series", "the chart has no data points"));
    }
    for (lines, log, name) in [
        (&chart.vlines, chart.log_x, "log_x"),
        (&chart.hlines, chart.log_y, "log_y"),
    ] {
        for l in lines {
            if !l.value.is_finite() {
                return Err(Error::NonFinite {
                    what: format!("reference line `{}` at {}", l.label, l.value),
                });
            }
            if log && l.value <= 0.0 {
                return Err(Error::param(
                    name,
                    format!(
                        "reference line `{}` at {} on a logarithmic axis",
                        l.label, l.value
                    ),
                ));
            }
        }
    }
    for (range, log, name) in [
        (chart.x_range, chart.log_x, "x_range"),
        (chart.y_range, chart.log_y, "y_range"),
    ] {
        if let Some((lo, hi)) = range {
            if !lo.is_finite() || !hi.is_finite() {
                return Err(Error::NonFinite {
                    what: format!("{name} [{lo}, {hi}]"),
                });
            }
            if lo >= hi {
                return Err(Error::param(
                    name,
                    format!("[{lo}, {hi}] must have its lower end first and not be empty"),
                ));
            }
            if log && lo <= 0.0 {
                return Err(Error::param(
                    name,
                    format!("[{lo}, {hi}] on a logarithmic axis must be positive"),
                ));
            }
        }
    }
    Ok(())
}

fn render(chart: &Chart, default_style: SeriesStyle) -> Result<ChartFigure> {
    validate(chart)?;
    let mut canvas = Canvas::new(chart.width, chart.height, Rgb::WHITE)?;
    let (w, h) = (chart.width as i64, chart.height as i64);

    let xs: Vec<f64> = chart
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .chain(chart.vlines.iter().map(|l| l.value))
        .collect();
    let ys: Vec<f64> = chart
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .chain(chart.hlines.iter().map(|l| l.value))
        .collect();
    // About one labelled tick per 80 pixels across and 45 pixels up, fewer if the labels
    // would crowd (the plot area's size is estimated before the layout).
    let (est_w, est_h) = (w - 180, h - 130);
    let mut x_target = (est_w / 80).clamp(2, 12) as usize;
    let x = loop {
        let axis = build_axis(&xs, chart.x_range, chart.log_x, x_target)?;
        let widest = axis
            .major
            .iter()
            .map(|(_, l)| label_size(l).0)
            .max()
            .unwrap_or(0);
        let fracs: Vec<f64> = axis
            .major
            .iter()
            .filter_map(|(v, _)| axis.frac(*v))
            .collect();
        let closest = fracs
            .windows(2)
            .map(|p| (p[1] - p[0]) * est_w as f64)
            .fold(f64::INFINITY, f64::min);
        if closest >= (widest + 20) as f64 || x_target <= 2 {
            break axis;
        }
        x_target -= 1;
    };
    let y_target = (est_h / 45).clamp(2, 10) as usize;
    let y = build_axis(&ys, chart.y_range, chart.log_y, y_target)?;

    // Layout, from the outside in; `reserve` columns on the right are kept for a legend.
    let line_h = text_size("X", TEXT).1;
    let title_h = if chart.title.is_empty() {
        0
    } else {
        text_size(&chart.title, TITLE).1 + 12
    };
    let y_label_w = if chart.y_label.is_empty() {
        0
    } else {
        line_h + 10
    };
    let x_label_h = if chart.x_label.is_empty() {
        0
    } else {
        line_h + 8
    };
    let widest = |a: &Axis| a.major.iter().map(|(_, l)| label_size(l).0).max();
    let tallest = |a: &Axis| a.major.iter().map(|(_, l)| label_size(l).1).max();
    let y_tick_w = widest(&y).unwrap_or(0);
    let y_tick_h = tallest(&y).unwrap_or(line_h);
    let x_tick_h = tallest(&x).unwrap_or(line_h);
    let x_last_w = x.major.last().map(|(_, l)| label_size(l).0).unwrap_or(0);
    let layout = |reserve: i64| -> Result<Rect> {
        let left = PAD + y_label_w + y_tick_w + 6 + TICK_LEN;
        let right = PAD + reserve.max(x_last_w / 2).max(8);
        let top = PAD + title_h + (y_tick_h / 2).max(4);
        let bottom = PAD + x_label_h + x_tick_h + 6 + TICK_LEN;
        let plot = Rect::new(left, top, w - left - right, h - top - bottom);
        if plot.width < 60 || plot.height < 40 {
            return Err(Error::param(
                "size",
                format!(
                    "{w} x {h} pixels leave no room for the plot area after its labels; \
                     try at least 320 x 240"
                ),
            ));
        }
        Ok(plot)
    };

    // The series' looks, and their points on screen for a given plot area.
    struct Look {
        name: String,
        colour: Rgb,
        marker: Marker,
        style: SeriesStyle,
    }
    let looks: Vec<Look> = chart
        .series
        .iter()
        .enumerate()
        .map(|(i, s)| Look {
            name: s.name.clone(),
            colour: s.colour.unwrap_or_else(|| series_colour(i)),
            marker: s.marker.unwrap_or_else(|| Marker::nth(i)),
            style: s.style.unwrap_or(default_style),
        })
        .collect();
    let on_screen = |plot: Rect| -> Vec<Vec<(f64, f64)>> {
        chart
            .series
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .map(|&(px, py)| {
                        let fx = x.frac(px).unwrap_or(f64::NAN);
                        let fy = y.frac(py).unwrap_or(f64::NAN);
                        place(plot, fx, fy)
                    })
                    .collect()
            })
            .collect()
    };
    let col_in =
        |plot: Rect, v: f64| place(plot, x.frac(v).unwrap_or(f64::NAN), 0.0).0.floor() as i64;
    let row_in =
        |plot: Rect, v: f64| place(plot, 0.0, y.frac(v).unwrap_or(f64::NAN)).1.floor() as i64;

    // The labels of the reference lines, inside the plot near the lines' ends.
    let ref_labels = |plot: Rect| -> Vec<(Rect, &str)> {
        let inner = plot.inflate(-1);
        let mut out = Vec::new();
        let mut stacked = 0;
        for l in &chart.vlines {
            let c = col_in(plot, l.value);
            if l.label.is_empty() || !inner.contains(c, inner.y) {
                continue;
            }
            let (tw, th) = text_size(&l.label, TEXT);
            let y0 = plot.y + 8 + stacked * (th + 8);
            stacked += 1;
            let x0 = if c + 8 + tw + 4 < plot.right() {
                c + 8
            } else {
                c - 8 - tw
            };
            out.push((Rect::new(x0, y0, tw, th), l.label.as_str()));
        }
        for l in &chart.hlines {
            let r = row_in(plot, l.value);
            if l.label.is_empty() || !inner.contains(inner.x, r) {
                continue;
            }
            let (tw, th) = text_size(&l.label, TEXT);
            let y0 = if r - 6 - th > plot.y {
                r - 6 - th
            } else {
                r + 8
            };
            out.push((
                Rect::new(plot.right() - 8 - tw, y0, tw, th),
                l.label.as_str(),
            ));
        }
        out
    };

    // The legend's size, and its place: a corner, or beside the plot area.
    const SAMPLE_W: i64 = 32;
    const ROW_H: i64 = 24;
    const BOX_PAD: i64 = 8;
    const BESIDE: i64 = 14;
    let entries: Vec<usize> = (0..looks.len())
        .filter(|&i| !looks[i].name.is_empty())
        .collect();
    let legend_size = (!entries.is_empty() && chart.legend != LegendPosition::Hidden).then(|| {
        let name_w = entries
            .iter()
            .map(|&i| text_size(&looks[i].name, TEXT).0)
            .max()
            .unwrap_or(0);
        (
            2 * BOX_PAD + SAMPLE_W + 8 + name_w,
            2 * BOX_PAD + ROW_H * entries.len() as i64 - 4,
        )
    });
    let corner = |plot: Rect, pos: LegendPosition, (bw, bh): (i64, i64)| {
        let inset = 10;
        let lx = match pos {
            LegendPosition::TopLeft | LegendPosition::BottomLeft => plot.x + inset,
            _ => plot.right() - inset - bw,
        };
        let ly = match pos {
            LegendPosition::BottomLeft | LegendPosition::BottomRight => plot.bottom() - inset - bh,
            _ => plot.y + inset,
        };
        Rect::new(lx, ly, bw, bh)
    };
    // How much of the data and labels a box would hide.
    let covered = |plot: Rect, r: Rect, pixels: &[Vec<(f64, f64)>], labels: &[(Rect, &str)]| {
        let zone = r.inflate(6);
        let hit = |&(px, py): &(f64, f64)| zone.contains(px.floor() as i64, py.floor() as i64);
        let mut n = 0;
        for (look, pts) in looks.iter().zip(pixels) {
            if look.style.has_markers() {
                n += 4 * pts.iter().filter(|p| hit(p)).count();
            }
            if look.style.has_lines() {
                for seg in pts.windows(2) {
                    let ((x0, y0), (x1, y1)) = (seg[0], seg[1]);
                    n += (0..=16)
                        .map(|k| k as f64 / 16.0)
                        .filter(|t| hit(&(x0 + t * (x1 - x0), y0 + t * (y1 - y0))))
                        .count();
                }
            }
        }
        let crossing = chart
            .vlines
            .iter()
            .filter(|l| (zone.x..zone.right()).contains(&col_in(plot, l.value)))
            .count()
            + chart
                .hlines
                .iter()
                .filter(|l| (zone.y..zone.bottom()).contains(&row_in(plot, l.value)))
                .count();
        n + 100 * crossing
            + 100
                * labels
                    .iter()
                    .filter(|(l, _)| !l.inflate(3).intersect(&zone).is_empty())
                    .count()
    };

    let mut plot = layout(0)?;
    let mut pixels = on_screen(plot);
    let legend = match (legend_size, chart.legend) {
        (None, _) | (_, LegendPosition::Hidden) => None,
        (Some(size), LegendPosition::Outside) => match layout(size.0 + BESIDE) {
            Ok(p) => {
                plot = p;
                pixels = on_screen(plot);
                Some(Rect::new(plot.right() + BESIDE, plot.y, size.0, size.1))
            }
            Err(_) => Some(corner(plot, LegendPosition::TopRight, size)),
        },
        (Some(size), LegendPosition::Auto) => {
            let labels = ref_labels(plot);
            let (best, score) = [
                LegendPosition::TopRight,
                LegendPosition::TopLeft,
                LegendPosition::BottomRight,
                LegendPosition::BottomLeft,
            ]
            .into_iter()
            .map(|p| (p, covered(plot, corner(plot, p, size), &pixels, &labels)))
            .min_by_key(|&(_, n)| n)
            .unwrap_or((LegendPosition::TopRight, 0));
            match layout(size.0 + BESIDE) {
                Ok(p) if score > 0 => {
                    plot = p;
                    pixels = on_screen(plot);
                    Some(Rect::new(plot.right() + BESIDE, plot.y, size.0, size.1))
                }
                _ => Some(corner(plot, best, size)),
            }
        }
        (Some(size), pos) => Some(corner(plot, pos, size)),
    };
    let col = |fx: f64| place(plot, fx, 0.0).0.floor() as i64;
    let row = |fy: f64| place(plot, 0.0, fy).1.floor() as i64;

    // Grid at the labelled ticks.
    for (v, _) in &x.major {
        let c = col(x.frac(*v).unwrap_or(0.0));
        if c > plot.x && c < plot.right() - 1 {
            canvas.vline(c, plot.y + 1, plot.bottom() - 2, 1, GRID);
        }
    }
    for (v, _) in &y.major {
        let r = row(y.frac(*v).unwrap_or(0.0));
        if r > plot.y && r < plot.bottom() - 1 {
            canvas.hline(plot.x + 1, plot.right() - 2, r, 1, GRID);
        }
    }

    // Reference lines.
    let inner = plot.inflate(-1);
    canvas.set_clip(inner);
    for l in &chart.vlines {
        let c = col_in(plot, l.value);
        canvas.dashed_vline(c, plot.y + 1, plot.bottom() - 2, 2, 9, 6, REF_LINE);
    }
    for l in &chart.hlines {
        let r = row_in(plot, l.value);
        canvas.dashed_hline(plot.x + 1, plot.right() - 2, r, 2, 9, 6, REF_LINE);
    }

    // Series: lines first, then markers over them.
    for (look, pts) in looks.iter().zip(&pixels) {
        if look.style.has_lines() {
            canvas.polyline(pts, LINE_WIDTH, look.colour);
        }
    }
    for (look, pts) in looks.iter().zip(&pixels) {
        if look.style.has_markers() {
            for &(px, py) in pts {
                canvas.marker_grown(px, py, MARKER_RADIUS, HALO, look.marker, Rgb::WHITE);
                canvas.marker(px, py, MARKER_RADIUS, look.marker, look.colour);
            }
        }
    }

    // Labels of the reference lines, on a white ground.
    for (r, text) in ref_labels(plot) {
        canvas.fill_rect(r.inflate(3), Rgb::WHITE);
        canvas.text(r.x, r.y, text, TextStyle::new(2, REF_LINE));
    }
    canvas.reset_clip();

    // Frame, ticks and their labels.
    canvas.stroke_rect(plot, 1, FRAME);
    for v in &x.minor {
        if let Some(f) = x.frac(*v) {
            canvas.vline(
                col(f),
                plot.bottom(),
                plot.bottom() + MINOR_TICK_LEN - 1,
                1,
                FRAME,
            );
        }
    }
    for v in &y.minor {
        if let Some(f) = y.frac(*v) {
            canvas.hline(plot.x - MINOR_TICK_LEN, plot.x - 1, row(f), 1, FRAME);
        }
    }
    for (v, label) in &x.major {
        let c = col(x.frac(*v).unwrap_or(0.0));
        canvas.vline(c, plot.bottom(), plot.bottom() + TICK_LEN - 1, 1, FRAME);
        let (lw, _) = label_size(label);
        draw_label(&mut canvas, label, c - lw / 2, plot.bottom() + TICK_LEN + 6);
    }
    for (v, label) in &y.major {
        let r = row(y.frac(*v).unwrap_or(0.0));
        canvas.hline(plot.x - TICK_LEN, plot.x - 1, r, 1, FRAME);
        let (lw, _) = label_size(label);
        // Centre the digits (not the raised exponent) on the tick.
        let rise = if matches!(label, Label::Power(_)) {
            exponent_rise()
        } else {
            0
        };
        draw_label(
            &mut canvas,
            label,
            plot.x - TICK_LEN - 6 - lw,
            top_for_centre(r, TEXT) - rise,
        );
    }

    // Axis labels and title.
    if !chart.x_label.is_empty() {
        canvas.text_aligned(
            plot.x + plot.width / 2,
            h - PAD,
            &chart.x_label,
            TEXT,
            Align::Centre,
            Align::End,
        );
    }
    if !chart.y_label.is_empty() {
        let (tw, _) = text_size(&chart.y_label, TEXT);
        canvas.text_vertical(PAD, plot.y + plot.height / 2 - tw / 2, &chart.y_label, TEXT);
    }
    if !chart.title.is_empty() {
        canvas.text_aligned(
            plot.x + plot.width / 2,
            PAD,
            &chart.title,
            TITLE,
            Align::Centre,
            Align::Start,
        );
    }

    // Legend: a sample of each series' line and marker, then its name.
    if let Some(r) = legend {
        canvas.fill_rect(r, Rgb::WHITE);
        canvas.stroke_rect(r, 1, LEGEND_EDGE);
        for (slot, &i) in entries.iter().enumerate() {
            let look = &looks[i];
            let cy = r.y + BOX_PAD + slot as i64 * ROW_H + (ROW_H - 4) / 2;
            let (sx0, sx1) = ((r.x + BOX_PAD) as f64, (r.x + BOX_PAD + SAMPLE_W) as f64);
            let yc = cy as f64 + 0.5;
            if look.style.has_lines() {
                canvas.line(sx0, yc, sx1, yc, LINE_WIDTH, look.colour);
            }
            if look.style.has_markers() {
                let mx = (sx0 + sx1) / 2.0;
                canvas.marker_grown(mx, yc, MARKER_RADIUS, HALO, look.marker, Rgb::WHITE);
                canvas.marker(mx, yc, MARKER_RADIUS, look.marker, look.colour);
            }
            canvas.text(
                r.x + BOX_PAD + SAMPLE_W + 8,
                top_for_centre(cy, TEXT),
                &look.name,
                TEXT,
            );
        }
    }

    Ok(ChartFigure {
        canvas,
        plot,
        legend,
        x,
        y,
    })
}
