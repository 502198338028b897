//! Depth maps side by side, sharing one colour bar.

use std::path::Path;

use ndarray::Array2;

use crate::error::{Error, Result};

use super::canvas::{text_size, Align, Canvas, Rect, TextStyle};
use super::colour::{ColourMap, Rgb};
use super::ticks::{format_tick, ticks_within};

/// The colour of pixels without a return (depth −1): a light grey that no colour of
/// [`ColourMap::viridis`] comes near.
pub const NO_RETURN_COLOUR: Rgb = Rgb::hex(0xd4d4d4);

/// The colour bar and layout of [`depth_panels`].
#[derive(Debug, Clone, PartialEq)]
pub struct DepthOptions {
    units_per_bin: f64,
    unit: String,
    label: String,
    title: String,
    upscale: Option<usize>,
    range: Option<(i32, i32)>,
    colour_map: ColourMap,
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
            colour_map: ColourMap::viridis(),
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

    /// Colours bins `lo ..= hi` from one end of the colour map to the other (bins outside take
    /// the end colours). By default the range is that of all the maps' returns.
    pub fn range(mut self, lo: i32, hi: i32) -> Self {
        self.range = Some((lo, hi));
        self
    }

    /// The colour map (default [`ColourMap::viridis`]: near is dark, far is bright).
    pub fn colour_map(mut self, map: ColourMap) -> Self {
        self.colour_map = map;
        self
    }
}

impl Default for DepthOptions {
    /// Depths in bins.
    fn default() -> Self {
        DepthOptions::new(1.0, "bins")
    }
}

/// A rendered set of depth panels: the image and where its parts lie.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFigure {
    canvas: Canvas,
    panels: Vec<Rect>,
    colour_bar: Rect,
    no_return_key: Rect,
    upscale: usize,
    range: (f64, f64),
    colour_map: ColourMap,
}

impl DepthFigure {
    /// The image.
    pub fn canvas(&self) -> &Canvas {
        &self.canvas
    }

    /// The image, for further drawing.
    pub fn into_canvas(self) -> Canvas {
        self.canvas
    }

    /// Where each map is drawn: map pixel `(i, j)` (row, column) fills the `upscale ×
    /// upscale` square at `(x + j·upscale, y + i·upscale)`.
    pub fn panel_areas(&self) -> &[Rect] {
        &self.panels
    }

    /// The upscaling factor used.
    pub fn upscale(&self) -> usize {
        self.upscale
    }

    /// The colour bar: its top row has the colour of the far end of the range, its bottom row
    /// that of the near end.
    pub fn colour_bar(&self) -> Rect {
        self.colour_bar
    }

    /// The legend's swatch for pixels without a return.
    pub fn no_return_key(&self) -> Rect {
        self.no_return_key
    }

    /// The range of bins spanned by the colour bar, bottom to top (widened by half a bin each
    /// way when all returns have the same depth).
    pub fn bin_range(&self) -> (f64, f64) {
        self.range
    }

    /// The colour of depth bin `bin` ([`NO_RETURN_COLOUR`] for −1).
    pub fn colour_of(&self, bin: i32) -> Rgb {
        if bin < 0 {
            NO_RETURN_COLOUR
        } else {
            let (lo, hi) = self.range;
            self.colour_map.at((bin as f64 - lo) / (hi - lo))
        }
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

const INK: Rgb = Rgb::hex(0x262626);
const FRAME: Rgb = Rgb::hex(0x404040);
const TEXT: TextStyle = TextStyle::new(2, INK);
const TITLE: TextStyle = TextStyle::new(2, Rgb::hex(0x111111)).bold();
const PAD: i64 = 16;
const GAP: i64 = 24;
const BAR_W: i64 = 22;
const KEY_H: i64 = 16;
/// Target length in pixels of the longer side of an upscaled map.
const TARGET_SIDE: f64 = 275.0;

/// Draws depth maps side by side, each under its title, with a shared colour bar in depth units
/// and a key for pixels without a return.
///
/// Each map holds depth bins, [`crate::lidar::NO_RETURN`] (−1) for pixels without a return;
/// all maps must have the same shape. Returns are coloured by [`DepthOptions::colour_map`] over
/// the bin range; pixels without a return are [`NO_RETURN_COLOUR`].
///
/// ```
/// use ndarray::Array2;
/// use rdlidar::plot::{depth_panels, DepthOptions, NO_RETURN_COLOUR};
///
/// # fn main() -> rdlidar::Result<()> {
/// let truth = Array2::from_shape_fn((40, 50), |(i, j)| if i < 5 { -1 } else { (j / 5) as i32 });
/// let estimate = truth.mapv(|b| if b == 3 { -1 } else { b });
/// let fig = depth_panels(
///     &[("truth", &truth), ("estimate", &estimate)],
///     &DepthOptions::new(0.15, "m").title("Depth maps"),
/// )?;
/// let map = fig.panel_areas()[0];
/// assert_eq!(fig.canvas().pixel(map.x, map.y), Some(NO_RETURN_COLOUR));
/// # Ok(())
/// # }
/// ```
///
/// # Errors
/// [`Error::InvalidParameter`] for no maps (`panels`), an empty map or a depth below −1
/// (`depth`), a `units_per_bin` that is not finite and positive, a zero or oversized `upscale`,
/// or a reversed `range`; [`Error::ShapeMismatch`] when the maps' shapes differ.
pub fn depth_panels(
    panels: &[(&str, &Array2<i32>)],
    options: &DepthOptions,
) -> Result<DepthFigure> {
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
            return Err(Error::shape(
                format!("rows of depth map {k} (`{title}`)"),
                m,
                map.nrows(),
            ));
        }
        if map.ncols() != n {
            return Err(Error::shape(
                format!("columns of depth map {k} (`{title}`)"),
                n,
                map.ncols(),
            ));
        }
        for &b in map.iter() {
            if b < -1 {
                return Err(Error::param(
                    "depth",
                    format!(
                        "map {k} (`{title}`) has depth {b}; bins are >= 0, or -1 for no return"
                    ),
                ));
            }
            if b >= 0 {
                bins = (bins.0.min(b), bins.1.max(b));
            }
        }
    }
    let s = options.units_per_bin;
    if !(s.is_finite() && s > 0.0) {
        return Err(Error::param(
            "units_per_bin",
            format!("{s}: the size of a depth bin must be finite and positive"),
        ));
    }
    let (lo, hi) = match options.range {
        Some((lo, hi)) if lo > hi => {
            return Err(Error::param("range", format!("[{lo}, {hi}] is reversed")))
        }
        Some(r) => r,
        None if bins.0 > bins.1 => (0, 1), // no returns at all
        None => bins,
    };
    let range = if lo == hi {
        (lo as f64 - 0.5, hi as f64 + 0.5)
    } else {
        (lo as f64, hi as f64)
    };
    let k = match options.upscale {
        Some(0) => return Err(Error::param("upscale", "the factor must be at least 1")),
        Some(k) => k,
        None => ((TARGET_SIDE / m.max(n) as f64).round() as usize).max(1),
    };
    let too_big = || {
        Error::param(
            "upscale",
            format!("{m} x {n} maps scaled by {k} are too large"),
        )
    };
    let pw = n
        .checked_mul(k)
        .filter(|&v| v <= super::canvas::MAX_SIDE)
        .ok_or_else(too_big)? as i64;
    let ph = m
        .checked_mul(k)
        .filter(|&v| v <= super::canvas::MAX_SIDE)
        .ok_or_else(too_big)? as i64;

    // Layout.
    let line_h = text_size("X", TEXT).1;
    let title_h = if options.title.is_empty() {
        0
    } else {
        text_size(&options.title, TITLE).1 + 14
    };
    let col_w = panels
        .iter()
        .map(|(t, _)| text_size(t, TEXT).0)
        .max()
        .unwrap_or(0)
        .max(pw);
    let top = PAD + title_h + line_h + 6;
    let bar_label = if options.unit.is_empty() {
        options.label.clone()
    } else {
        format!("{} ({})", options.label, options.unit)
    };
    let bar_label_w = text_size(&bar_label, TEXT).0;
    let legend_h = ph.max(180).max(bar_label_w + KEY_H + 26 + 20);
    let bar = Rect::new(
        PAD + panels.len() as i64 * (col_w + GAP) - GAP + 30,
        top,
        BAR_W,
        legend_h - KEY_H - 26,
    );
    let key = Rect::new(bar.x, top + legend_h - KEY_H, BAR_W, KEY_H);

    let (v0, v1) = (range.0 * s, range.1 * s);
    let target = (bar.height / 35).clamp(2, 10) as usize;
    let (ticks, e) = ticks_within(v0, v1, target);
    let largest = ticks.iter().fold(0f64, |a, t| a.max(t.abs()));
    let labels: Vec<String> = ticks.iter().map(|&t| format_tick(t, e, largest)).collect();
    let label_w = labels
        .iter()
        .map(|l| text_size(l, TEXT).0)
        .max()
        .unwrap_or(0);
    let labels_x = bar.right() + 1 + 5 + 5;
    let key_label = "no return";
    let width = ((labels_x + label_w + 12 + line_h)
        .max(key.right() + 8 + text_size(key_label, TEXT).0)
        + PAD)
        .max(text_size(&options.title, TITLE).0 + 2 * PAD);
    let height = top + legend_h.max(ph) + PAD;
    let mut canvas = Canvas::new(width as usize, height as usize, Rgb::WHITE)?;

    // Titles and maps.
    if !options.title.is_empty() {
        canvas.text_aligned(
            width / 2,
            PAD,
            &options.title,
            TITLE,
            Align::Centre,
            Align::Start,
        );
    }
    let colour_of = |b: i32| {
        if b < 0 {
            NO_RETURN_COLOUR
        } else {
            options
                .colour_map
                .at((b as f64 - range.0) / (range.1 - range.0))
        }
    };
    let mut areas = Vec::with_capacity(panels.len());
    let ku = k as i64;
    for (p, (title, map)) in panels.iter().enumerate() {
        let cx = PAD + p as i64 * (col_w + GAP) + col_w / 2;
        let area = Rect::new(cx - pw / 2, top, pw, ph);
        canvas.text_aligned(cx, top - 6, title, TEXT, Align::Centre, Align::End);
        for ((i, j), &b) in map.indexed_iter() {
            let px = Rect::new(area.x + j as i64 * ku, area.y + i as i64 * ku, ku, ku);
            canvas.fill_rect(px, colour_of(b));
        }
        canvas.stroke_rect(area.inflate(1), 1, FRAME);
        areas.push(area);
    }

    // Colour bar, ticks in depth units, and the no-return key.
    for r in 0..bar.height {
        let t = 1.0 - r as f64 / (bar.height - 1).max(1) as f64;
        canvas.hline(
            bar.x,
            bar.right() - 1,
            bar.y + r,
            1,
            options.colour_map.at(t),
        );
    }
    canvas.stroke_rect(bar.inflate(1), 1, FRAME);
    for (v, label) in ticks.iter().zip(&labels) {
        let f = (v - v0) / (v1 - v0);
        let r = bar.bottom() - 1 - (f * (bar.height - 1) as f64).round() as i64;
        canvas.hline(bar.right() + 1, bar.right() + 5, r, 1, FRAME);
        canvas.text(labels_x, r - 6, label, TEXT);
    }
    canvas.text_vertical(
        labels_x + label_w + 12,
        bar.y + bar.height / 2 - bar_label_w / 2,
        &bar_label,
        TEXT,
    );
    canvas.fill_rect(key, NO_RETURN_COLOUR);
    canvas.stroke_rect(key.inflate(1), 1, FRAME);
    canvas.text(key.right() + 8, key.y + KEY_H / 2 - 6, key_label, TEXT);

    Ok(DepthFigure {
        canvas,
        panels: areas,
        colour_bar: bar,
        no_return_key: key,
        upscale: k,
        range,
        colour_map: options.colour_map.clone(),
    })
}
