//! XY charts: scatter and line plots with linear or logarithmic axes, a legend and reference
//! lines, drawn with plotters.

use std::path::Path;

use crate::error::{Error, Result};

use super::axis::Axis;
use super::colour::Rgb;
use super::Bitmap;

/// The shape of a series' markers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Marker {
    /// A filled disc.
    Circle,
    /// A filled square.
    Square,
    /// A filled triangle pointing up.
    TriangleUp,
    /// A filled square standing on a corner.
    Diamond,
    /// A filled triangle pointing down.
    TriangleDown,
    /// A diagonal cross (×).
    Cross,
    /// An upright cross (+).
    Plus,
}

impl Marker {
    /// Every marker, in the order series take them by default.
    pub const ALL: [Marker; 7] = [
        Marker::Circle,
        Marker::Square,
        Marker::TriangleUp,
        Marker::Diamond,
        Marker::TriangleDown,
        Marker::Cross,
        Marker::Plus,
    ];

    /// The marker of series `i`: [`Marker::ALL`], cycled.
    pub fn nth(i: usize) -> Marker {
        Marker::ALL[i % Marker::ALL.len()]
    }

    /// The outline of a polygonal marker of radius 1 (y downwards).
    pub(super) fn outline(self) -> Vec<(f64, f64)> {
        const A: f64 = 0.3; // half the width of a cross's arms
        const L: f64 = 1.15; // half the length of a cross's arms
        let plus = [
            (-A, -L),
            (A, -L),
            (A, -A),
            (L, -A),
            (L, A),
            (A, A),
            (A, L),
            (-A, L),
            (-A, A),
            (-L, A),
            (-L, -A),
            (-A, -A),
        ];
        match self {
            Marker::Circle => (0..24)
                .map(|k| {
                    let t = k as f64 * std::f64::consts::TAU / 24.0;
                    (t.cos(), t.sin())
                })
                .collect(),
            Marker::Square => vec![(-0.85, -0.85), (0.85, -0.85), (0.85, 0.85), (-0.85, 0.85)],
            Marker::TriangleUp => vec![(0.0, -1.2), (1.1, 0.75), (-1.1, 0.75)],
            Marker::TriangleDown => vec![(0.0, 1.2), (1.1, -0.75), (-1.1, -0.75)],
            Marker::Diamond => vec![(0.0, -1.25), (1.0, 0.0), (0.0, 1.25), (-1.0, 0.0)],
            Marker::Plus => plus.to_vec(),
            Marker::Cross => {
                let r = std::f64::consts::FRAC_1_SQRT_2;
                plus.iter()
                    .map(|&(x, y)| (r * (x - y), r * (x + y)))
                    .collect()
            }
        }
    }
}

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
    pub(super) fn has_markers(self) -> bool {
        self != SeriesStyle::Lines
    }

    pub(super) fn has_lines(self) -> bool {
        self != SeriesStyle::Markers
    }
}

/// One named set of points.
///
/// Its colour and marker default to the `i`-th entries of [`super::PALETTE`] and
/// [`Marker::ALL`] for the `i`-th series of the chart; its style defaults to the plot's
/// ([`scatter_plot`](super::scatter_plot): markers, [`line_plot`](super::line_plot): lines and markers).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub(super) name: String,
    pub(super) points: Vec<(f64, f64)>,
    pub(super) colour: Option<Rgb>,
    pub(super) marker: Option<Marker>,
    pub(super) style: Option<SeriesStyle>,
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

/// Where the legend goes: a corner inside the plot area, beside it, or nowhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LegendPosition {
    /// Top left corner.
    TopLeft,
    /// Top right corner.
    TopRight,
    /// Bottom left corner.
    BottomLeft,
    /// Bottom right corner.
    BottomRight,
    /// Beside the plot area, on the right (the plot area narrows to make room; in the top
    /// right corner if the image is too narrow). The default: it hides no data.
    Outside,
    /// No legend.
    Hidden,
}

/// A labelled reference line across the plot at a fixed x (vertical) or y (horizontal).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct RefLine {
    pub value: f64,
    pub label: String,
}

/// The description of an XY chart, drawn by [`scatter_plot`](super::scatter_plot) or [`line_plot`](super::line_plot).
///
/// ```
/// use rdlidar::report::plot::{line_plot, Chart, Series};
///
/// # fn main() -> rdlidar::Result<()> {
/// let chart = Chart::new("Recovery error")
///     .x_label("pulse length Kₚ")
///     .y_label("relative error ‖X − X̂‖/‖X‖")
///     .log_y(true)
///     .series(Series::new("FISTA", [(100.0, 0.5), (200.0, 0.05), (400.0, 0.01)]))
///     .vline(250.0, "critical Kₚ");
/// let fig = line_plot(&chart)?;
/// assert_eq!(fig.y_ticks(), [0.01, 0.1]); // the powers of ten in the data's range
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    pub(super) title: String,
    pub(super) x_label: String,
    pub(super) y_label: String,
    pub(super) log_x: bool,
    pub(super) log_y: bool,
    pub(super) x_range: Option<(f64, f64)>,
    pub(super) y_range: Option<(f64, f64)>,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) series: Vec<Series>,
    pub(super) vlines: Vec<RefLine>,
    pub(super) hlines: Vec<RefLine>,
    pub(super) legend: LegendPosition,
}

impl Chart {
    /// An empty 800 × 520 chart titled `title` (no title if empty), linear axes fitted to the
    /// data, the legend beside the plot area.
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
            legend: LegendPosition::Outside,
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

    /// A logarithmic x axis, labelled by powers of ten.
    pub fn log_x(mut self, on: bool) -> Self {
        self.log_x = on;
        self
    }

    /// A logarithmic y axis, labelled by powers of ten.
    pub fn log_y(mut self, on: bool) -> Self {
        self.log_y = on;
        self
    }

    /// Shows exactly `lo ..= hi` on the x axis instead of the data's range; what lies outside
    /// is clipped.
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

/// A drawn chart.
#[derive(Debug, Clone, PartialEq)]
pub struct ChartFigure {
    pub(super) image: Bitmap,
    pub(super) x: Axis,
    pub(super) y: Axis,
}

impl ChartFigure {
    /// The image's width in pixels.
    pub fn width(&self) -> usize {
        self.image.width
    }

    /// The image's height in pixels.
    pub fn height(&self) -> usize {
        self.image.height
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
        self.x.ticks.iter().map(|t| t.value).collect()
    }

    /// The labelled tick values of the y axis.
    pub fn y_ticks(&self) -> Vec<f64> {
        self.y.ticks.iter().map(|t| t.value).collect()
    }

    /// The image as a PNG file, in memory.
    pub fn encode_png(&self) -> Vec<u8> {
        self.image.encode_png()
    }

    /// Writes the image to `path` as a PNG file, atomically: on error no file is left at
    /// `path`, or the one there is left as it was.
    ///
    /// # Errors
    /// [`Error::File`] naming `path` when it cannot be written.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        self.image.save_png(path.as_ref())
    }
}

/// Everything a chart needs, checked.
pub(super) fn validate(chart: &Chart) -> Result<()> {
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
