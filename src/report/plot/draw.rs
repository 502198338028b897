//! Drawing a chart with plotters: the layout, grid and axes, series (clipped to the axes'
//! ranges), dashed reference lines and the legend.

use plotters::element::{ComposedElement, DashedPathElement};
use plotters::prelude::{
    ChartBuilder, Color, DrawingBackend, EmptyElement, LineSeries, PathElement, PointSeries,
    Polygon, RGBColor, Rectangle, ShapeStyle, WHITE,
};
use plotters::style::text_anchor::HPos;

use crate::error::{Error, Result};

use super::axis::Axis;
use super::chart::{validate, Chart, ChartFigure, LegendPosition, Marker, SeriesStyle};
use super::colour::{series_colour, Rgb};
use super::text::{drawn, Area, Font};
use super::{check_size, Bitmap};

const INK: Rgb = Rgb::hex(0x262626);
const FRAME: Rgb = Rgb::hex(0x404040);
const GRID: Rgb = Rgb::hex(0xe3e3e3);
const MINOR_GRID: Rgb = Rgb::hex(0xf3f3f3);
const REF_LINE: Rgb = Rgb::hex(0x595959);
const LEGEND_EDGE: Rgb = Rgb::hex(0xbfbfbf);
const TITLE: Font = Font::bold(22.0);
const LABEL: Font = Font::new(19.0);
const TICKS: Font = Font::new(18.0);
const SMALL: Font = Font::new(18.0);

const PAD: i32 = 14;
const TICK_LEN: i32 = 6;
const LINE_WIDTH: u32 = 3;
const MARKER_RADIUS: f64 = 5.0;
const HALO: f64 = 1.5;
const SAMPLE_W: i32 = 34;
const ROW_H: i32 = 26;
const BOX_PAD: i32 = 9;
const BESIDE: i32 = 16;

/// A pixel rectangle: left, top, width, height.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rect(i32, i32, i32, i32);

impl Rect {
    fn contains(self, (x, y): (f64, f64)) -> bool {
        x >= self.0 as f64
            && x < (self.0 + self.2) as f64
            && y >= self.1 as f64
            && y < (self.1 + self.3) as f64
    }

    fn grow(self, d: i32) -> Rect {
        Rect(self.0 - d, self.1 - d, self.2 + 2 * d, self.3 + 2 * d)
    }

    fn corners(self) -> [(i32, i32); 2] {
        [(self.0, self.1), (self.0 + self.2, self.1 + self.3)]
    }
}

/// A marker: a white halo and the shape, polygons around a point.
type MarkerElement<C, DB> = ComposedElement<C, DB, Polygon<(i32, i32)>, Polygon<(i32, i32)>>;

/// A marker of `radius` pixels centred on `at`, on a white halo that keeps it apart from lines
/// and other markers under it.
fn marker<C, DB: DrawingBackend>(
    at: C,
    kind: Marker,
    radius: f64,
    colour: Rgb,
) -> MarkerElement<C, DB> {
    let shape = |r: f64| -> Vec<(i32, i32)> {
        kind.outline()
            .iter()
            .map(|&(x, y)| ((x * r).round() as i32, (y * r).round() as i32))
            .collect()
    };
    EmptyElement::at(at)
        + Polygon::new(shape(radius + HALO), WHITE.filled())
        + Polygon::new(shape(radius), RGBColor::from(colour).filled())
}

/// The part of the segment `a`–`b` inside `[x0, x1] × [y0, y1]` (Liang–Barsky).
fn clip(
    a: (f64, f64),
    b: (f64, f64),
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Option<[(f64, f64); 2]> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - x0),
        (dx, x1 - a.0),
        (-dy, a.1 - y0),
        (dy, y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else if p < 0.0 {
            t0 = t0.max(q / p);
        } else {
            t1 = t1.min(q / p);
        }
    }
    (t0 <= t1).then_some([
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ])
}

/// The polylines of `points` inside `[x0, x1] × [y0, y1]`.
fn clipped_runs(points: &[(f64, f64)], xs: (f64, f64), ys: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for w in points.windows(2) {
        let Some([p, q]) = clip(w[0], w[1], xs, ys) else {
            open = false;
            continue;
        };
        match runs.last_mut() {
            Some(run) if open && p == w[0] => run.push(q),
            _ => runs.push(vec![p, q]),
        }
        open = q == w[1];
    }
    runs
}

/// A series as drawn.
struct Look<'a> {
    name: &'a str,
    colour: Rgb,
    marker: Marker,
    style: SeriesStyle,
    /// The points on the drawn scales.
    points: Vec<(f64, f64)>,
}

/// A chart with its axes fitted and its texts measured, before and during drawing.
struct Plan<'a> {
    chart: &'a Chart,
    x: Axis,
    y: Axis,
    xe: (f64, f64),
    ye: (f64, f64),
    looks: Vec<Look<'a>>,
    title: Font,
    /// Width of the y tick labels' column, height of the x tick labels' row.
    y_area: i32,
    x_area: i32,
    x_last_w: i32,
    legend_size: Option<(i32, i32)>,
    /// Widths of the reference lines' labels, vertical lines first.
    ref_w: Vec<i32>,
}

/// Draws `chart` with markers only, except for series styled otherwise (e.g. "time against
/// error" for every run of a set of solvers).
///
/// # Errors
/// [`Error::InvalidParameter`] for a chart without any point (`series`), a zero or oversized
/// image (`width`, `height`) or one too small for its labels (`size`), an axis range that is
/// reversed, empty or not positive on a logarithmic axis (`x_range`, `y_range`), a point or
/// reference line at a value ≤ 0 on a logarithmic axis (`log_x`, `log_y`), or data spanning
/// more than `f64` can hold with margins (`range`); [`Error::NonFinite`] for a NaN or infinite
/// coordinate.
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

/// Draws `chart`, each series by default in `default_style`.
pub(super) fn render(chart: &Chart, default_style: SeriesStyle) -> Result<ChartFigure> {
    validate(chart)?;
    check_size(chart.width, chart.height)?;
    let plan = Plan::new(chart, default_style)?;
    let (plot, legend) = plan.place()?;
    let image = Bitmap::draw(chart.width, chart.height, |root| {
        plan.draw(root, plot, legend)
    })?;
    Ok(ChartFigure {
        image,
        x: plan.x,
        y: plan.y,
    })
}

impl<'a> Plan<'a> {
    fn new(chart: &'a Chart, default_style: SeriesStyle) -> Result<Self> {
        let (w, h) = (chart.width as i32, chart.height as i32);
        let points = chart.series.iter().flat_map(|s| s.points.iter());
        let xs: Vec<f64> = points
            .clone()
            .map(|p| p.0)
            .chain(chart.vlines.iter().map(|l| l.value))
            .collect();
        let ys: Vec<f64> = points
            .map(|p| p.1)
            .chain(chart.hlines.iter().map(|l| l.value))
            .collect();
        // About one labelled tick per 110 pixels across and 50 up.
        let x_target = ((w - 200) / 110).clamp(2, 12) as usize;
        let y_target = ((h - 140) / 50).clamp(2, 10) as usize;
        let x = Axis::fit(&xs, chart.x_range, chart.log_x, x_target)?;
        let y = Axis::fit(&ys, chart.y_range, chart.log_y, y_target)?;

        let looks: Vec<Look> = chart
            .series
            .iter()
            .enumerate()
            .map(|(i, s)| Look {
                name: &s.name,
                colour: s.colour.unwrap_or_else(|| series_colour(i)),
                marker: s.marker.unwrap_or_else(|| Marker::nth(i)),
                style: s.style.unwrap_or(default_style),
                points: s.points.iter().map(|&(u, v)| (x.at(u), y.at(v))).collect(),
            })
            .collect();

        let title_w = TITLE.width(&chart.title)?;
        let room = (w - 2 * PAD).max(1);
        let title = if title_w > room {
            Font::bold((TITLE.size * room as f64 / title_w as f64).floor().max(9.0))
        } else {
            TITLE
        };
        let y_tick_w = TICKS.widest(y.ticks.iter().map(|t| t.text.as_str()))?;
        let x_last_w = TICKS.widest(x.ticks.last().map(|t| t.text.as_str()))?;
        let named: Vec<&str> = looks
            .iter()
            .map(|l| l.name)
            .filter(|n| !n.is_empty())
            .collect();
        let name_w = SMALL.widest(named.iter().copied())?;
        let legend_size =
            (!named.is_empty() && chart.legend != LegendPosition::Hidden).then(|| {
                let rows = named.len() as i32;
                (
                    2 * BOX_PAD + SAMPLE_W + 10 + name_w,
                    2 * BOX_PAD + ROW_H * rows - 8,
                )
            });
        let ref_w = chart
            .vlines
            .iter()
            .chain(&chart.hlines)
            .map(|l| SMALL.width(&l.label))
            .collect::<Result<_>>()?;
        Ok(Plan {
            chart,
            xe: x.ends(),
            ye: y.ends(),
            x,
            y,
            looks,
            title,
            y_area: y_tick_w + 2 * TICK_LEN + 2,
            x_area: TICKS.height() + 2 * TICK_LEN + 4,
            x_last_w,
            legend_size,
            ref_w,
        })
    }

    /// The plot area, with `reserve` columns on the right kept for a legend.
    fn plot_area(&self, reserve: i32) -> Result<Rect> {
        let (w, h) = (self.chart.width as i32, self.chart.height as i32);
        let desc = |text: &str| {
            if text.is_empty() {
                0
            } else {
                LABEL.height() + LABEL.hat_rise() + 8
            }
        };
        let title_h = if self.chart.title.is_empty() {
            0
        } else {
            self.title.height() + 10
        };
        let left = PAD + desc(&self.chart.y_label) + self.y_area;
        let right = PAD + reserve.max(self.x_last_w / 2).max(8);
        let top = PAD + title_h + TICKS.height() / 2;
        let bottom = PAD + desc(&self.chart.x_label) + self.x_area;
        let plot = Rect(left, top, w - left - right, h - top - bottom);
        if plot.2 < 60 || plot.3 < 40 {
            return Err(Error::param(
                "size",
                format!(
                    "{w} x {h} pixels leave no room for the plot area after its labels; \
                     try at least 400 x 300"
                ),
            ));
        }
        Ok(plot)
    }

    /// Where the point `(u, v)` of the drawn scales lands in `plot`.
    fn pixel(&self, plot: Rect, (u, v): (f64, f64)) -> (f64, f64) {
        let (xe, ye) = (self.xe, self.ye);
        (
            plot.0 as f64 + (u - xe.0) / (xe.1 - xe.0) * plot.2 as f64,
            (plot.1 + plot.3) as f64 - (v - ye.0) / (ye.1 - ye.0) * plot.3 as f64,
        )
    }

    /// The labels of the reference lines in `plot`, with their boxes:
    /// those of vertical lines at the top, beside the line, stacked; those of horizontal lines
    /// at the right end, above the line.
    fn ref_labels(&self, plot: Rect) -> Vec<(Rect, &'a str)> {
        let h = SMALL.height();
        let mut out = Vec::new();
        let lines = self.chart.vlines.iter().map(|l| (true, l));
        let lines = lines.chain(self.chart.hlines.iter().map(|l| (false, l)));
        for ((vertical, l), &tw) in lines.zip(&self.ref_w) {
            let (c, r) = if vertical {
                (self.pixel(plot, (self.x.at(l.value), self.ye.0)).0, 0.0)
            } else {
                (0.0, self.pixel(plot, (self.xe.0, self.y.at(l.value))).1)
            };
            let inside = if vertical {
                c > plot.0 as f64 && c < (plot.0 + plot.2) as f64
            } else {
                r > plot.1 as f64 && r < (plot.1 + plot.3) as f64
            };
            if l.label.is_empty() || !inside {
                continue;
            }
            let (c, r) = (c.round() as i32, r.round() as i32);
            let boxed = if vertical {
                // Beside the line near its top, right or left, lower down if data is there.
                let right = c + 8 + tw + 4 < plot.0 + plot.2;
                let sides = [right, !right];
                let slots = (0..4).flat_map(|row| sides.map(|r| (row, r)));
                let at = |(row, right): (i32, bool)| {
                    let y0 = plot.1 + 8 + (out.len() as i32 + row) * (h + 10);
                    Rect(if right { c + 8 } else { c - 8 - tw }, y0, tw, h)
                };
                let fits = |b: &Rect| b.0 > plot.0 && b.1 + b.3 < plot.1 + plot.3;
                slots
                    .map(at)
                    .find(|b| fits(b) && self.hidden_data(plot, b.grow(4)) == 0)
                    .unwrap_or_else(|| at((0, right)))
            } else {
                let above = r - 8 - h;
                let y0 = if above > plot.1 { above } else { r + 8 };
                Rect(plot.0 + plot.2 - 8 - tw, y0, tw, h)
            };
            out.push((boxed, l.label.as_str()));
        }
        out
    }

    /// How much of the data (markers and lines) the box `zone` of `plot` would hide.
    fn hidden_data(&self, plot: Rect, zone: Rect) -> usize {
        let mut n = 0;
        for look in &self.looks {
            let px: Vec<(f64, f64)> = look.points.iter().map(|&p| self.pixel(plot, p)).collect();
            if look.style.has_markers() {
                n += 4 * px.iter().filter(|&&p| zone.contains(p)).count();
            }
            if look.style.has_lines() {
                for s in px.windows(2) {
                    n += (0..=16)
                        .map(|k| k as f64 / 16.0)
                        .map(|t| {
                            (
                                s[0].0 + t * (s[1].0 - s[0].0),
                                s[0].1 + t * (s[1].1 - s[0].1),
                            )
                        })
                        .filter(|&p| zone.contains(p))
                        .count();
                }
            }
        }
        n
    }

    /// The plot area and the legend's box.
    fn place(&self) -> Result<(Rect, Option<Rect>)> {
        let plot = self.plot_area(0)?;
        let Some(size) = self.legend_size else {
            return Ok((plot, None));
        };
        let (w, h) = size;
        let (left, right) = (plot.0 + 10, plot.0 + plot.2 - 10 - w);
        let (top, low) = (plot.1 + 10, plot.1 + plot.3 - 10 - h);
        Ok(match self.chart.legend {
            LegendPosition::Hidden => (plot, None),
            LegendPosition::TopLeft => (plot, Some(Rect(left, top, w, h))),
            LegendPosition::TopRight => (plot, Some(Rect(right, top, w, h))),
            LegendPosition::BottomLeft => (plot, Some(Rect(left, low, w, h))),
            LegendPosition::BottomRight => (plot, Some(Rect(right, low, w, h))),
            LegendPosition::Outside => match self.plot_area(w + BESIDE) {
                Ok(p) => (p, Some(Rect(p.0 + p.2 + BESIDE, p.1, w, h))),
                Err(_) => (plot, Some(Rect(right, top, w, h))),
            },
        })
    }

    fn draw(&self, root: &Area, plot: Rect, legend: Option<Rect>) -> Result<()> {
        let (chart, x, y, xe, ye) = (self.chart, &self.x, &self.y, self.xe, self.ye);
        let (w, h) = (chart.width as i32, chart.height as i32);
        let mut cc = drawn(
            ChartBuilder::on(root)
                .margin_top(plot.1)
                .margin_left(plot.0 - self.y_area)
                .margin_right(w - plot.0 - plot.2)
                .margin_bottom(h - plot.1 - plot.3 - self.x_area)
                .x_label_area_size(self.x_area)
                .y_label_area_size(self.y_area)
                .build_cartesian_2d(x.scale(), y.scale()),
        )?;
        // Grid, axes and tick marks by plotters; the tick labels are drawn as text after.
        let no_text = |_: &f64| String::new();
        drawn(
            cc.configure_mesh()
                .bold_line_style(RGBColor::from(GRID))
                .light_line_style(RGBColor::from(MINOR_GRID))
                .axis_style(RGBColor::from(FRAME))
                .set_all_tick_mark_size(TICK_LEN)
                .label_style(TICKS.style(INK))
                .x_label_formatter(&no_text)
                .y_label_formatter(&no_text)
                .draw(),
        )?;
        let (px, py) = cc.plotting_area().get_pixel_range();
        let (top, bottom) = (py.start, py.end - 1);
        for t in &x.ticks {
            let c = cc.backend_coord(&(t.at, ye.0)).0;
            let at = (c, bottom + 1 + TICK_LEN + 6);
            TICKS.put(root, &t.text, INK, at, HPos::Center)?;
        }
        for t in &y.ticks {
            let r = cc.backend_coord(&(xe.0, t.at)).1;
            let at = (px.start - 1 - TICK_LEN - 6, r - TICKS.cap() / 2);
            TICKS.put(root, &t.text, INK, at, HPos::Right)?;
        }

        // Reference lines, dashed.
        let dashed = RGBColor::from(REF_LINE).stroke_width(2);
        for l in &chart.vlines {
            let c = cc.backend_coord(&(x.at(l.value), ye.0)).0;
            if px.contains(&c) {
                let line = DashedPathElement::new([(c, top), (c, bottom)], 9, 6, dashed);
                drawn(root.draw(&line))?;
            }
        }
        for l in &chart.hlines {
            let r = cc.backend_coord(&(xe.0, y.at(l.value))).1;
            if py.contains(&r) {
                let line = DashedPathElement::new([(px.start, r), (px.end - 1, r)], 9, 6, dashed);
                drawn(root.draw(&line))?;
            }
        }

        // Series: lines first, then markers over them.
        for look in &self.looks {
            if look.style.has_lines() {
                let style = RGBColor::from(look.colour).stroke_width(LINE_WIDTH);
                for run in clipped_runs(&look.points, xe, ye) {
                    drawn(cc.draw_series(LineSeries::new(run, style)))?;
                }
            }
        }
        for look in &self.looks {
            if look.style.has_markers() {
                let inside = look
                    .points
                    .iter()
                    .copied()
                    .filter(|&(u, v)| u >= xe.0 && u <= xe.1 && v >= ye.0 && v <= ye.1);
                let (kind, colour) = (look.marker, look.colour);
                let make = |at, r, _| marker(at, kind, r, colour);
                let style = ShapeStyle::from(&RGBColor::from(colour));
                drawn(cc.draw_series(PointSeries::of_element(
                    inside,
                    MARKER_RADIUS,
                    style,
                    &make,
                )))?;
            }
        }

        // Labels of the reference lines, on a white ground; the frame (the axes drew its left
        // and bottom sides); axis labels and title.
        for (r, text) in self.ref_labels(plot) {
            drawn(root.draw(&Rectangle::new(r.grow(3).corners(), WHITE.filled())))?;
            SMALL.put(root, text, REF_LINE, (r.0, r.1), HPos::Left)?;
        }
        let edge = RGBColor::from(FRAME).stroke_width(1);
        let frame = [(px.start - 1, top), (px.end - 1, bottom + 1)];
        drawn(root.draw(&Rectangle::new(frame, edge)))?;
        let mid = (px.start + px.end) / 2;
        if !chart.x_label.is_empty() {
            let at = (mid, h - PAD - LABEL.height());
            LABEL.put(root, &chart.x_label, INK, at, HPos::Center)?;
        }
        if !chart.y_label.is_empty() {
            let at = (PAD + LABEL.hat_rise(), (top + bottom) / 2);
            LABEL.put_upwards(root, &chart.y_label, INK, at)?;
        }
        if !chart.title.is_empty() {
            // Centred over the plot area, as far as the image allows.
            let half = self.title.width(&chart.title)? / 2;
            let mid = mid.min(w - PAD - half).max(PAD + half);
            self.title
                .put(root, &chart.title, INK, (mid, PAD), HPos::Center)?;
        }
        if let Some(r) = legend {
            self.draw_legend(root, r)?;
        }
        Ok(())
    }

    /// The legend in the box `r`: a sample of each named series' line and marker, then its
    /// name.
    fn draw_legend(&self, root: &Area, r: Rect) -> Result<()> {
        drawn(root.draw(&Rectangle::new(r.corners(), WHITE.filled())))?;
        let border = RGBColor::from(LEGEND_EDGE).stroke_width(1);
        drawn(root.draw(&Rectangle::new(r.corners(), border)))?;
        let named = self.looks.iter().filter(|l| !l.name.is_empty());
        for (slot, look) in named.enumerate() {
            let cy = r.1 + BOX_PAD + slot as i32 * ROW_H + (ROW_H - 8) / 2;
            let (x0, x1) = (r.0 + BOX_PAD, r.0 + BOX_PAD + SAMPLE_W);
            if look.style.has_lines() {
                let style = RGBColor::from(look.colour).stroke_width(LINE_WIDTH);
                drawn(root.draw(&PathElement::new(vec![(x0, cy), (x1, cy)], style)))?;
            }
            if look.style.has_markers() {
                let m = marker(((x0 + x1) / 2, cy), look.marker, MARKER_RADIUS, look.colour);
                drawn(root.draw(&m))?;
            }
            let at = (x1 + 10, cy - SMALL.cap() / 2);
            SMALL.put(root, look.name, INK, at, HPos::Left)?;
        }
        Ok(())
    }
}
