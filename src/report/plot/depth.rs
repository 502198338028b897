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
    let (pw, ph) = (side(n)?, side(m)?);
    if panels.len() > MAX_SIDE {
        return Err(Error::param(
            "width",
            format!("{} panels side by side are too wide", panels.len()),
        ));
    }

    // The colour bar's ticks, in depth units.
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
    let keys_h = if unobserved { 2 * KEY_H + 6 } else { KEY_H };
    let bar_h_min = ph.max(180) - keys_h - 26;
    let ticks = RangedCoordf64::from(v0..v1).key_points((bar_h_min / 40).clamp(2, 10) as usize);
    let step = ticks
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let tick_labels: Vec<String> = ticks.iter().map(|&v| tick_text(v, step)).collect();
    let bar_label = if options.unit.is_empty() {
        options.label.clone()
    } else {
        format!("{} ({})", options.label, options.unit)
    };

    // The sizes of the texts, then the layout.
    let title_w = TITLE.width(&options.title)?;
    let bar_label_w = TEXT.width(&bar_label)?;
    let key_label_w = TEXT.width("no return")?.max(if unobserved {
        TEXT.width("unobserved")?
    } else {
        0
    });
    let tick_w = TICKS.widest(tick_labels.iter().map(String::as_str))?;
    let col_w = TEXT.widest(panels.iter().map(|p| p.0))?.max(pw);

    let title_h = if options.title.is_empty() {
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

    let image = Bitmap::draw(width as usize, height as usize, |root| {
        if !options.title.is_empty() {
            TITLE.put(root, &options.title, INK, (width / 2, PAD), HPos::Center)?;
        }
        // The maps, a rectangle per run of equal bins along a row.
        for (p, (title, map)) in panels.iter().enumerate() {
            let cx = PAD + p as i32 * (col_w + GAP) + col_w / 2;
            let (x0, y0) = (cx - pw / 2, top);
            TEXT.put(
                root,
                title,
                INK,
                (cx, top - 6 - TEXT.height()),
                HPos::Center,
            )?;
            let ku = k as i32;
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
            frame(root, (x0, y0), (pw, ph))?;
        }

        // The colour bar: a chart whose plotting area is the bar, with ticks on the right.
        let bar_area = root
            .clone()
            .shrink((bar_x, top), (BAR_W + label_area, bar_h));
        let mut bar = drawn(
            ChartBuilder::on(&bar_area)
                .set_label_area_size(LabelAreaPosition::Right, label_area)
                .build_cartesian_2d(
                    0.0..1.0,
                    Scale {
                        lo: v0,
                        hi: v1,
                        bold: ticks.clone(),
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
            bar.configure_mesh()
                .disable_mesh()
                .disable_x_axis()
                .axis_style(RGBColor::from(FRAME))
                .set_tick_mark_size(LabelAreaPosition::Right, TICK_LEN)
                .label_style(TICKS.style(INK))
                .y_label_formatter(&no_text)
                .draw(),
        )?;
        for (v, text) in ticks.iter().zip(&tick_labels) {
            let r = bar.backend_coord(&(0.0, *v)).1;
            let at = (bar_x + BAR_W + TICK_LEN + 6, r - TICKS.cap() / 2);
            TICKS.put(root, text, INK, at, HPos::Left)?;
        }
        frame(root, (bar_x, top), (BAR_W, bar_h))?;
        let label_x = bar_x + BAR_W + TICK_LEN + 6 + tick_w + 10;
        TEXT.put_upwards(root, &bar_label, INK, (label_x, top + bar_h / 2))?;

        // The keys: pixels without a return, then unobserved pixels if any.
        let mut key_y = top + legend_h - keys_h;
        let keys: &[(Rgb, &str)] = if unobserved {
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
    })?;
    Ok(DepthFigure {
        image,
        upscale: k,
        range,
    })
}

/// A one-pixel frame just outside the `size` box at `at`.
fn frame(area: &Area, at: (i32, i32), size: (i32, i32)) -> Result<()> {
    let (x0, y0, x1, y1) = (at.0 - 1, at.1 - 1, at.0 + size.0, at.1 + size.1);
    let style = RGBColor::from(FRAME).stroke_width(1);
    drawn(area.draw(&Rectangle::new([(x0, y0), (x1, y1)], style)))
}
