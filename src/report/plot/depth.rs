//! Depth maps side by side, sharing one colour bar.

use std::path::Path;

use ndarray::Array2;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::{ChartBuilder, Color, LabelAreaPosition, RGBColor, Ranged, Rectangle};
use plotters::style::text_anchor::HPos;

use crate::error::{Error, Result};

use super::axis::{tick_text, Scale};
use super::colour::{viridis, Rgb};
use super::text::{drawn, Area, Font};
use super::{Bitmap, MAX_SIDE};

/// The colour of pixels without a return (depth −1): a light grey that no colour of
/// [`viridis`] comes near.
pub const NO_RETURN_COLOUR: Rgb = Rgb::hex(0xd4d4d4);

/// The colour of pixels that were not observed ([`crate::lidar::UNOBSERVED`], −2): the pixels a
/// coded aperture blocks.
pub const UNOBSERVED_COLOUR: Rgb = Rgb::hex(0xf2c4c4);

/// The colour bar and layout of [`depth_panels`].
#[derive(Debug, Clone, PartialEq)]
pub struct DepthOptions {
    units_per_bin: f64,
    unit: String,
    label: String,
    title: String,
    upscale: Option<usize>,
    range: Option<(i32, i32)>,
}

impl DepthOptions {
    /// Depth bin `b` is shown as the depth `b · units_per_bin` in `unit` (e.g. `0.15` and
    /// `"m"`); the colour bar is labelled "depth (m)".
    pub fn new(units_per_bin: f64, unit: impl Into<String>) -> Self {
        DepthOptions {
            units_per_bin,
            unit: unit.into(),
            label: "depth".into(),
            title: String::new(),
            upscale: None,
            range: None,
        }
    }

    /// A title over the whole figure.
    pub fn title(mut self, title: impl Into<String>) -> Self {
        self.title = title.into();
        self
    }

    /// The colour bar's label, before the unit in parentheses (default "depth").
    pub fn label(mut self, label: impl Into<String>) -> Self {
        self.label = label.into();
        self
    }

    /// Draws each map pixel as a `factor × factor` square. By default the factor makes the
    /// longer side of a map about 275 pixels (3 for a 100 × 100 map), and at least 1.
    pub fn upscale(mut self, factor: usize) -> Self {
        self.upscale = Some(factor);
        self
    }

    /// Colours bins `lo ..= hi` from one end of [`viridis`] to the other (bins outside take the
    /// end colours). By default the range is that of all the maps' returns.
    pub fn range(mut self, lo: i32, hi: i32) -> Self {
        self.range = Some((lo, hi));
        self
    }
}

impl Default for DepthOptions {
    /// Depths in bins.
    fn default() -> Self {
        DepthOptions::new(1.0, "bins")
    }
}

/// Drawn depth panels.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFigure {
    image: Bitmap,
    upscale: usize,
    range: (f64, f64),
}

impl DepthFigure {
    /// The image's width in pixels.
    pub fn width(&self) -> usize {
        self.image.width
    }

    /// The image's height in pixels.
    pub fn height(&self) -> usize {
        self.image.height
    }

    /// The upscaling factor used: each map pixel is drawn as a square this many pixels wide.
    pub fn upscale(&self) -> usize {
        self.upscale
    }

    /// The range of bins spanned by the colour bar, bottom to top (widened by half a bin each
    /// way when all returns have the same depth).
    pub fn bin_range(&self) -> (f64, f64) {
        self.range
    }

    /// The colour of depth bin `bin` ([`NO_RETURN_COLOUR`] for −1, [`UNOBSERVED_COLOUR`] for −2).
    pub fn colour_of(&self, bin: i32) -> Rgb {
        colour_in(self.range, bin)
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

fn colour_in(range: (f64, f64), bin: i32) -> Rgb {
    if bin == crate::lidar::UNOBSERVED {
        UNOBSERVED_COLOUR
    } else if bin < 0 {
        NO_RETURN_COLOUR
    } else {
        viridis((bin as f64 - range.0) / (range.1 - range.0))
    }
}

const INK: Rgb = Rgb::hex(0x262626);
const FRAME: Rgb = Rgb::hex(0x404040);
const TITLE: Font = Font::bold(22.0);
const TEXT: Font = Font::new(18.0);
const TICKS: Font = Font::new(16.0);
const PAD: i32 = 16;
const GAP: i32 = 24;
const BAR_W: i32 = 22;
const KEY_H: i32 = 16;
const TICK_LEN: i32 = 5;
/// Target length in pixels of the longer side of an upscaled map.
const TARGET_SIDE: f64 = 275.0;

/// Draws depth maps side by side, each under its title, with a shared colour bar in depth units
/// and a key for pixels without a return.
///
/// Each map holds depth bins, [`crate::lidar::NO_RETURN`] (−1) for pixels without a return
/// and [`crate::lidar::UNOBSERVED`] (−2) for pixels that were not observed; all maps must have
/// the same shape. Returns are coloured by [`viridis`] over the bin range (near is dark, far is
/// bright); pixels without a return are [`NO_RETURN_COLOUR`], unobserved ones
/// [`UNOBSERVED_COLOUR`] (with a key of their own when there are any).
///
/// ```
/// use ndarray::Array2;
/// use rdlidar::report::plot::{depth_panels, DepthOptions, NO_RETURN_COLOUR};
///
/// # fn main() -> rdlidar::Result<()> {
/// let truth = Array2::from_shape_fn((40, 50), |(i, j)| if i < 5 { -1 } else { (j / 5) as i32 });
/// let estimate = truth.mapv(|b| if b == 3 { -1 } else { b });
/// let fig = depth_panels(
///     &[("truth", &truth), ("estimate", &estimate)],
///     &DepthOptions::new(0.15, "m").title("Depth maps"),
/// )?;
/// assert_eq!(fig.colour_of(-1), NO_RETURN_COLOUR);
/// assert_eq!(fig.bin_range(), (0.0, 9.0));
/// # Ok(())
/// # }
/// ```
///
/// # Errors
/// [`Error::InvalidParameter`] for no maps (`panels`), an empty map or a depth below −1
/// (`depth`; −2 is allowed), a `units_per_bin` that is not finite and positive, a zero or oversized `upscale`,
/// a reversed `range`, or a figure too large (`width`, `height`); [`Error::ShapeMismatch`] when
/// the maps' shapes differ.
pub fn depth_panels(
    panels: &[(&str, &Array2<i32>)],
    options: &DepthOptions,
) -> Result<DepthFigure> {
    let ((m, n), bins) = check_maps(panels)?;
    let s = options.units_per_bin;
    if !(s.is_finite() && s > 0.0) {
        return Err(Error::param(
            "units_per_bin",
            format!("{s}: the size of a depth bin must be finite and positive"),
        ));
    }
    let (lo, hi) = bar_bins(options.range, bins)?;
    let range = if lo == hi {
        (lo as f64 - 0.5, hi as f64 + 0.5)
    } else {
        (lo as f64, hi as f64)
    };
    let (k, pw, ph) = panel_size(options.upscale, (m, n))?;
    if panels.len() > MAX_SIDE {
        return Err(Error::param(
            "width",
            format!("{} panels side by side are too wide", panels.len()),
        ));
    }

    // The colour bar's span, in depth units.
    let (v0, v1) = (range.0 * s, range.1 * s);
    if !(v1 - v0).is_finite() {
        return Err(Error::param(
            "units_per_bin",
            format!("{s} per bin over bins {lo} to {hi} overflows"),
        ));
    }
    // A key for pixels without a return, and one for unobserved pixels if there are any.
    let unobserved = panels
        .iter()
        .any(|(_, map)| map.iter().any(|&b| b == crate::lidar::UNOBSERVED));
    let bar_h_min = ph.max(180) - keys_height(unobserved) - 26;
    let bar = ColourBar::new(options, (v0, v1), bar_h_min);
    let layout = Layout::new(panels, &options.title, &bar, (pw, ph), k, unobserved)?;

    let image = Bitmap::draw(layout.width as usize, layout.height as usize, |root| {
        if !options.title.is_empty() {
            let at = (layout.width / 2, PAD);
            TITLE.put(root, &options.title, INK, at, HPos::Center)?;
        }
        for (p, (title, map)) in panels.iter().enumerate() {
            draw_panel(root, &layout, p, title, map, range)?;
        }
        draw_colour_bar(root, &layout, &bar)?;
        draw_keys(root, &layout)
    })?;
    Ok(DepthFigure {
        image,
        upscale: k,
        range,
    })
}

/// Checks that there is at least one map, that the maps are non-empty and all of one shape, and
/// that every depth is a bin, −1 or −2. Returns the shape and the lowest and highest bin of the
/// returns (`(i32::MAX, i32::MIN)` when there are none).
fn check_maps(panels: &[(&str, &Array2<i32>)]) -> Result<((usize, usize), (i32, i32))> {
    let Some(&(_, first)) = panels.first() else {
        return Err(Error::param("panels", "no depth maps to draw"));
    };
    let (m, n) = first.dim();
    if m == 0 || n == 0 {
        return Err(Error::param(
            "depth",
            format!("the maps are empty ({m} x {n})"),
        ));
    }
    let mut bins = (i32::MAX, i32::MIN);
    for (k, (title, map)) in panels.iter().enumerate() {
        if map.nrows() != m {
            let what = format!("rows of depth map {k} (`{title}`)");
            return Err(Error::shape(what, m, map.nrows()));
        }
        if map.ncols() != n {
            let what = format!("columns of depth map {k} (`{title}`)");
            return Err(Error::shape(what, n, map.ncols()));
        }
        for &b in map.iter() {
            if b < crate::lidar::UNOBSERVED {
                return Err(Error::param(
                    "depth",
                    format!(
                        "map {k} (`{title}`) has depth {b}; bins are >= 0, -1 for no return \
                         or -2 for unobserved"
                    ),
                ));
            }
            if b >= 0 {
                bins = (bins.0.min(b), bins.1.max(b));
            }
        }
    }
    Ok(((m, n), bins))
}

/// The lowest and highest bin the colour bar spans: the `requested` range if given, otherwise
/// the range of the returns' `bins` (0 to 1 when there are no returns).
fn bar_bins(requested: Option<(i32, i32)>, bins: (i32, i32)) -> Result<(i32, i32)> {
    match requested {
        Some((lo, hi)) if lo > hi => {
            Err(Error::param("range", format!("[{lo}, {hi}] is reversed")))
        }
        Some(r) => Ok(r),
        None if bins.0 > bins.1 => Ok((0, 1)), // no returns at all
        None => Ok(bins),
    }
}

/// The upscaling factor for `m × n` maps (the `requested` one, or one that makes the longer side
/// about [`TARGET_SIDE`] pixels), and the width and height in pixels of a map drawn with it.
fn panel_size(requested: Option<usize>, (m, n): (usize, usize)) -> Result<(usize, i32, i32)> {
    let k = match requested {
        Some(0) => return Err(Error::param("upscale", "the factor must be at least 1")),
        Some(k) => k,
        None => ((TARGET_SIDE / m.max(n) as f64).round() as usize).max(1),
    };
    let side = |len: usize| {
        len.checked_mul(k)
            .filter(|&v| v <= MAX_SIDE)
            .map(|v| v as i32)
            .ok_or_else(|| {
                Error::param(
                    "upscale",
                    format!("{m} x {n} maps scaled by {k} are too large"),
                )
            })
    };
    Ok((k, side(n)?, side(m)?))
}

/// The height in pixels of the keys under the colour bar: one for pixels without a return, and
/// one for unobserved pixels if there are any.
fn keys_height(unobserved: bool) -> i32 {
    if unobserved {
        2 * KEY_H + 6
    } else {
        KEY_H
    }
}

/// The colour bar's scale: the depths at its bottom and top, its ticks and their labels, and
/// the label along it.
struct ColourBar {
    /// The depths at the bottom and top of the bar.
    span: (f64, f64),
    /// The depths of the ticks.
    ticks: Vec<f64>,
    /// The ticks' labels.
    tick_labels: Vec<String>,
    /// The label along the bar.
    label: String,
}

impl ColourBar {
    /// A bar from depth `span.0` to `span.1`, with about one tick per 40 of its `min_h` pixels
    /// (2 to 10 ticks), labelled with the options' label and unit.
    fn new(options: &DepthOptions, span: (f64, f64), min_h: i32) -> ColourBar {
        let ticks =
            RangedCoordf64::from(span.0..span.1).key_points((min_h / 40).clamp(2, 10) as usize);
        let step = ticks
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min);
        let tick_labels: Vec<String> = ticks.iter().map(|&v| tick_text(v, step)).collect();
        let label = if options.unit.is_empty() {
            options.label.clone()
        } else {
            format!("{} ({})", options.label, options.unit)
        };
        ColourBar {
            span,
            ticks,
            tick_labels,
            label,
        }
    }
}

/// Where the parts of the figure go, in pixels.
struct Layout {
    /// The figure's width.
    width: i32,
    /// The figure's height.
    height: i32,
    /// The top of the maps and of the colour bar.
    top: i32,
    /// The width of a column: a map or its title, whichever is wider.
    col_w: i32,
    /// The size of a drawn map.
    panel: (i32, i32),
    /// The upscaling factor of the maps.
    k: usize,
    /// The left of the colour bar and the keys.
    bar_x: i32,
    /// The height of the colour bar.
    bar_h: i32,
    /// The height of the colour bar and the keys together.
    legend_h: i32,
    /// The width to the right of the colour bar for its ticks and label.
    label_area: i32,
    /// The width of the widest tick label.
    tick_w: i32,
    /// Whether there is a key for unobserved pixels.
    unobserved: bool,
}

impl Layout {
    /// Lays out a figure titled `title` with one column per panel, each map `panel` pixels wide
    /// and high (upscaled by `k`), followed by `bar` and the keys.
    fn new(
        panels: &[(&str, &Array2<i32>)],
        title: &str,
        bar: &ColourBar,
        panel: (i32, i32),
        k: usize,
        unobserved: bool,
    ) -> Result<Layout> {
        let (pw, ph) = panel;
        let keys_h = keys_height(unobserved);
        let title_w = TITLE.width(title)?;
        let bar_label_w = TEXT.width(&bar.label)?;
        let key_label_w = TEXT.width("no return")?.max(if unobserved {
            TEXT.width("unobserved")?
        } else {
            0
        });
        let tick_w = TICKS.widest(bar.tick_labels.iter().map(String::as_str))?;
        let col_w = TEXT.widest(panels.iter().map(|p| p.0))?.max(pw);

        let title_h = if title.is_empty() {
            0
        } else {
            TITLE.height() + 14
        };
        let top = PAD + title_h + TEXT.height() + 6;
        let legend_h = ph.max(180).max(bar_label_w + keys_h + 26 + 20);
        let bar_x = PAD + panels.len() as i32 * (col_w + GAP) - GAP + 30;
        let bar_h = legend_h - keys_h - 26;
        let label_area = TICK_LEN + 6 + tick_w + 10 + TEXT.height();
        let width = (bar_x + BAR_W + label_area)
            .max(bar_x + BAR_W + 8 + key_label_w)
            .max(title_w + PAD)
            + PAD;
        let height = top + legend_h.max(ph) + PAD;
        Ok(Layout {
            width,
            height,
            top,
            col_w,
            panel,
            k,
            bar_x,
            bar_h,
            legend_h,
            label_area,
            tick_w,
            unobserved,
        })
    }
}

/// Draws panel `p`: its title, then its map as a rectangle per run of equal bins along a row,
/// coloured over the bin `range`, then a frame around the map.
fn draw_panel(
    root: &Area,
    layout: &Layout,
    p: usize,
    title: &str,
    map: &Array2<i32>,
    range: (f64, f64),
) -> Result<()> {
    let (pw, ph) = layout.panel;
    let (top, col_w) = (layout.top, layout.col_w);
    let cx = PAD + p as i32 * (col_w + GAP) + col_w / 2;
    let (x0, y0) = (cx - pw / 2, top);
    TEXT.put(
        root,
        title,
        INK,
        (cx, top - 6 - TEXT.height()),
        HPos::Center,
    )?;
    let ku = layout.k as i32;
    let n = map.ncols();
    for (i, row) in map.outer_iter().enumerate() {
        let y = y0 + i as i32 * ku;
        let mut j = 0;
        while j < n {
            let b = row[j];
            let run = row.iter().skip(j).take_while(|&&v| v == b).count();
            let (xa, xb) = (x0 + j as i32 * ku, x0 + (j + run) as i32 * ku);
            let fill = RGBColor::from(colour_in(range, b)).filled();
            drawn(root.draw(&Rectangle::new([(xa, y), (xb, y + ku)], fill)))?;
            j += run;
        }
    }
    frame(root, (x0, y0), (pw, ph))
}

/// Draws the colour bar: a chart whose plotting area is the bar, filled with [`viridis`] from
/// bottom to top, with ticks and their labels on the right, a frame, and the bar's label
/// reading upwards beside the tick labels.
fn draw_colour_bar(root: &Area, layout: &Layout, bar: &ColourBar) -> Result<()> {
    let (top, bar_x, bar_h) = (layout.top, layout.bar_x, layout.bar_h);
    let label_area = layout.label_area;
    let (v0, v1) = bar.span;
    let bar_area = root
        .clone()
        .shrink((bar_x, top), (BAR_W + label_area, bar_h));
    let mut chart = drawn(
        ChartBuilder::on(&bar_area)
            .set_label_area_size(LabelAreaPosition::Right, label_area)
            .build_cartesian_2d(
                0.0..1.0,
                Scale {
                    lo: v0,
                    hi: v1,
                    bold: bar.ticks.clone(),
                    light: Vec::new(),
                },
            ),
    )?;
    for r in 0..bar_h {
        let t = 1.0 - r as f64 / (bar_h - 1).max(1) as f64;
        let fill = RGBColor::from(viridis(t)).filled();
        let row = Rectangle::new([(bar_x, top + r), (bar_x + BAR_W, top + r + 1)], fill);
        drawn(root.draw(&row))?;
    }
    let no_text = |_: &f64| String::new();
    drawn(
        chart
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .axis_style(RGBColor::from(FRAME))
            .set_tick_mark_size(LabelAreaPosition::Right, TICK_LEN)
            .label_style(TICKS.style(INK))
            .y_label_formatter(&no_text)
            .draw(),
    )?;
    for (v, text) in bar.ticks.iter().zip(&bar.tick_labels) {
        let r = chart.backend_coord(&(0.0, *v)).1;
        let at = (bar_x + BAR_W + TICK_LEN + 6, r - TICKS.cap() / 2);
        TICKS.put(root, text, INK, at, HPos::Left)?;
    }
    frame(root, (bar_x, top), (BAR_W, bar_h))?;
    let label_x = bar_x + BAR_W + TICK_LEN + 6 + layout.tick_w + 10;
    TEXT.put_upwards(root, &bar.label, INK, (label_x, top + bar_h / 2))
}

/// Draws the keys under the colour bar: a swatch and label for pixels without a return, then
/// one for unobserved pixels if there are any.
fn draw_keys(root: &Area, layout: &Layout) -> Result<()> {
    let bar_x = layout.bar_x;
    let mut key_y = layout.top + layout.legend_h - keys_height(layout.unobserved);
    let keys: &[(Rgb, &str)] = if layout.unobserved {
        &[
            (NO_RETURN_COLOUR, "no return"),
            (UNOBSERVED_COLOUR, "unobserved"),
        ]
    } else {
        &[(NO_RETURN_COLOUR, "no return")]
    };
    for &(colour, label) in keys {
        let fill = RGBColor::from(colour).filled();
        drawn(root.draw(&Rectangle::new(
            [(bar_x, key_y), (bar_x + BAR_W, key_y + KEY_H)],
            fill,
        )))?;
        frame(root, (bar_x, key_y), (BAR_W, KEY_H))?;
        let text_y = key_y + (KEY_H - TEXT.cap()) / 2;
        TEXT.put(root, label, INK, (bar_x + BAR_W + 8, text_y), HPos::Left)?;
        key_y += KEY_H + 6;
    }
    Ok(())
}

/// A one-pixel frame just outside the `size` box at `at`.
fn frame(area: &Area, at: (i32, i32), size: (i32, i32)) -> Result<()> {
    let (x0, y0, x1, y1) = (at.0 - 1, at.1 - 1, at.0 + size.0, at.1 + size.1);
    let style = RGBColor::from(FRAME).stroke_width(1);
    drawn(area.draw(&Rectangle::new([(x0, y0), (x1, y1)], style)))
}
