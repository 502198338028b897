//! An RGB raster with crisp rectangles and lines on the pixel grid, anti-aliased shapes and
//! bitmap text.

use std::path::Path;

use crate::error::{Error, Result};

use super::colour::Rgb;
use super::font;

/// Largest width or height of a canvas, in pixels.
pub const MAX_SIDE: usize = 16_384;
/// Largest number of pixels of a canvas.
pub const MAX_PIXELS: usize = 1 << 25;

/// A rectangle of pixels: columns `x .. x + width`, rows `y .. y + height` (row 0 at the top).
///
/// Coordinates may lie outside a canvas; drawing is clipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Rect {
    /// Leftmost column.
    pub x: i64,
    /// Top row.
    pub y: i64,
    /// Number of columns.
    pub width: i64,
    /// Number of rows.
    pub height: i64,
}

impl Rect {
    /// The rectangle with top-left pixel `(x, y)` and the given size.
    pub const fn new(x: i64, y: i64, width: i64, height: i64) -> Self {
        Rect {
            x,
            y,
            width,
            height,
        }
    }

    /// One past the rightmost column.
    pub const fn right(&self) -> i64 {
        self.x + self.width
    }

    /// One past the bottom row.
    pub const fn bottom(&self) -> i64 {
        self.y + self.height
    }

    /// Whether the rectangle holds no pixel.
    pub const fn is_empty(&self) -> bool {
        self.width <= 0 || self.height <= 0
    }

    /// Whether pixel `(x, y)` lies inside.
    pub const fn contains(&self, x: i64, y: i64) -> bool {
        x >= self.x && x < self.right() && y >= self.y && y < self.bottom()
    }

    /// The common part of two rectangles (possibly empty).
    pub fn intersect(&self, other: &Rect) -> Rect {
        let (x0, y0) = (self.x.max(other.x), self.y.max(other.y));
        let (x1, y1) = (
            self.right().min(other.right()),
            self.bottom().min(other.bottom()),
        );
        Rect::new(x0, y0, (x1 - x0).max(0), (y1 - y0).max(0))
    }

    /// The rectangle grown by `d` pixels on every side (shrunk for negative `d`).
    pub const fn inflate(&self, d: i64) -> Rect {
        Rect::new(
            self.x - d,
            self.y - d,
            self.width + 2 * d,
            self.height + 2 * d,
        )
    }
}

/// The shape of a data marker. All are filled except [`Marker::Cross`] and [`Marker::Plus`],
/// and they differ in outline, so series stay apart in greyscale prints.
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
    /// Two crossed diagonal strokes (×).
    Cross,
    /// A horizontal and a vertical stroke (+).
    Plus,
}

impl Marker {
    /// The markers in the order series receive them.
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
}

/// Where a piece of text sits relative to its anchor point, along one direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Align {
    /// The anchor is the left (top) edge.
    Start,
    /// The anchor is the centre.
    Centre,
    /// The anchor is the right (bottom) edge.
    End,
}

impl Align {
    fn offset(self, size: i64) -> i64 {
        match self {
            Align::Start => 0,
            Align::Centre => size / 2,
            Align::End => size,
        }
    }
}

/// How text is drawn: the pixel size of one font unit, the colour and the weight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TextStyle {
    /// Pixels per font unit (the font is 5 × 7 units for a capital letter); at least 1.
    pub scale: u32,
    /// The ink colour.
    pub colour: Rgb,
    /// Bold: strokes one pixel wider per two units of scale (at least one).
    pub bold: bool,
}

impl TextStyle {
    /// Regular text at `scale` in `colour`.
    pub const fn new(scale: u32, colour: Rgb) -> Self {
        TextStyle {
            scale,
            colour,
            bold: false,
        }
    }

    /// The same style, bold.
    pub const fn bold(self) -> Self {
        TextStyle { bold: true, ..self }
    }

    fn unit(&self) -> i64 {
        self.scale.max(1) as i64
    }

    /// Extra pixels of stroke (and advance) per glyph for bold text.
    fn embolden(&self) -> i64 {
        if self.bold {
            (self.unit() / 2).max(1)
        } else {
            0
        }
    }
}

/// The size in pixels, `(width, height)`, of `text` drawn on one line in `style`. The height is
/// the full glyph cell: capitals and descenders included.
pub fn text_size(text: &str, style: TextStyle) -> (i64, i64) {
    let (w, h) = font::measure(text);
    let s = style.unit();
    let n = text.chars().count() as i64;
    let w = if n == 0 {
        0
    } else {
        w as i64 * s + n * style.embolden()
    };
    (w, h as i64 * s)
}

/// An RGB image with 8 bits per channel, row 0 at the top.
///
/// Pixel `(x, y)` covers the square `[x, x + 1) × [y, y + 1)`: rectangles and the crisp line
/// methods work on whole pixels, while anti-aliased shapes take real coordinates and blend each
/// pixel by the fraction of it they cover. All drawing is clipped to the canvas and to an optional
/// clip rectangle ([`Canvas::set_clip`]).
///
/// ```
/// use rdlidar::plot::{Canvas, Marker, Rect, Rgb, TextStyle};
///
/// # fn main() -> rdlidar::Result<()> {
/// let mut c = Canvas::new(120, 60, Rgb::WHITE)?;
/// c.fill_rect(Rect::new(0, 0, 10, 10), Rgb::BLACK);
/// c.line(10.0, 50.0, 110.0, 10.0, 2.0, Rgb::hex(0x0072b2));
/// c.marker(60.0, 30.0, 5.0, Marker::TriangleUp, Rgb::hex(0xd55e00));
/// c.text(14, 2, "K_p = 40", TextStyle::new(1, Rgb::BLACK));
/// assert_eq!(c.pixel(5, 5), Some(Rgb::BLACK));
/// let png = c.encode_png();
/// assert_eq!(&png[1..4], b"PNG");
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    width: usize,
    height: usize,
    data: Vec<u8>,
    clip: Rect,
}

impl Canvas {
    /// A `width × height` canvas filled with `background`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`width` or `height`) for a zero side, a side above
    /// [`MAX_SIDE`] or more than [`MAX_PIXELS`] pixels.
    pub fn new(width: usize, height: usize, background: Rgb) -> Result<Self> {
        for (name, side) in [("width", width), ("height", height)] {
            if side == 0 || side > MAX_SIDE {
                return Err(Error::param(
                    name,
                    format!("{side} pixels: a canvas side must be between 1 and {MAX_SIDE}"),
                ));
            }
        }
        if width * height > MAX_PIXELS {
            return Err(Error::param(
                "height",
                format!("{width} x {height} is more than {MAX_PIXELS} pixels"),
            ));
        }
        let mut data = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            data.extend_from_slice(&[background.0, background.1, background.2]);
        }
        Ok(Canvas {
            width,
            height,
            data,
            clip: Rect::new(0, 0, width as i64, height as i64),
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The whole canvas as a rectangle.
    pub fn bounds(&self) -> Rect {
        Rect::new(0, 0, self.width as i64, self.height as i64)
    }

    /// The pixels, row by row, three bytes (R, G, B) each.
    pub fn as_raw(&self) -> &[u8] {
        &self.data
    }

    /// The colour of pixel `(x, y)`, or `None` outside the canvas.
    pub fn pixel(&self, x: i64, y: i64) -> Option<Rgb> {
        if !self.bounds().contains(x, y) {
            return None;
        }
        let i = (y as usize * self.width + x as usize) * 3;
        Some(Rgb(self.data[i], self.data[i + 1], self.data[i + 2]))
    }

    /// Restricts drawing to `rect` (within the canvas) until [`Canvas::reset_clip`].
    pub fn set_clip(&mut self, rect: Rect) {
        self.clip = rect.intersect(&self.bounds());
    }

    /// Allows drawing on the whole canvas again.
    pub fn reset_clip(&mut self) {
        self.clip = self.bounds();
    }

    /// Sets pixel `(x, y)` to `colour`, if it lies inside the clip rectangle.
    pub fn set_pixel(&mut self, x: i64, y: i64, colour: Rgb) {
        if self.clip.contains(x, y) {
            let i = (y as usize * self.width + x as usize) * 3;
            self.data[i..i + 3].copy_from_slice(&[colour.0, colour.1, colour.2]);
        }
    }

    /// Mixes `colour` into pixel `(x, y)` with opacity `alpha` in `[0, 1]`.
    pub fn blend_pixel(&mut self, x: i64, y: i64, colour: Rgb, alpha: f64) {
        if alpha <= 0.0 || !self.clip.contains(x, y) {
            return;
        }
        let i = (y as usize * self.width + x as usize) * 3;
        let old = Rgb(self.data[i], self.data[i + 1], self.data[i + 2]);
        let new = old.mix(colour, alpha);
        self.data[i..i + 3].copy_from_slice(&[new.0, new.1, new.2]);
    }

    /// Fills the pixels of `rect` with `colour`.
    pub fn fill_rect(&mut self, rect: Rect, colour: Rgb) {
        let r = rect.intersect(&self.clip);
        for y in r.y..r.bottom() {
            let row = y as usize * self.width;
            for x in r.x..r.right() {
                let i = (row + x as usize) * 3;
                self.data[i..i + 3].copy_from_slice(&[colour.0, colour.1, colour.2]);
            }
        }
    }

    /// Draws the outline of `rect`, `thickness` pixels wide, inside the rectangle.
    pub fn stroke_rect(&mut self, rect: Rect, thickness: i64, colour: Rgb) {
        let t = thickness.max(1).min(rect.width).min(rect.height);
        if rect.is_empty() {
            return;
        }
        self.fill_rect(Rect::new(rect.x, rect.y, rect.width, t), colour);
        self.fill_rect(Rect::new(rect.x, rect.bottom() - t, rect.width, t), colour);
        self.fill_rect(Rect::new(rect.x, rect.y, t, rect.height), colour);
        self.fill_rect(Rect::new(rect.right() - t, rect.y, t, rect.height), colour);
    }

    /// A horizontal line over columns `x0 ..= x1` whose top row is `y`.
    pub fn hline(&mut self, x0: i64, x1: i64, y: i64, thickness: i64, colour: Rgb) {
        let (a, b) = (x0.min(x1), x0.max(x1));
        self.fill_rect(Rect::new(a, y, b - a + 1, thickness.max(1)), colour);
    }

    /// A vertical line over rows `y0 ..= y1` whose left column is `x`.
    pub fn vline(&mut self, x: i64, y0: i64, y1: i64, thickness: i64, colour: Rgb) {
        let (a, b) = (y0.min(y1), y0.max(y1));
        self.fill_rect(Rect::new(x, a, thickness.max(1), b - a + 1), colour);
    }

    /// A dashed horizontal line over columns `x0 ..= x1`: dashes of `dash` pixels, `gap` pixels
    /// apart, starting with a dash at the left end.
    #[allow(clippy::too_many_arguments)]
    pub fn dashed_hline(
        &mut self,
        x0: i64,
        x1: i64,
        y: i64,
        thickness: i64,
        dash: i64,
        gap: i64,
        colour: Rgb,
    ) {
        let (a, b) = (x0.min(x1), x0.max(x1));
        let (dash, period) = (dash.max(1), dash.max(1) + gap.max(0));
        let mut x = a;
        while x <= b {
            self.hline(x, (x + dash - 1).min(b), y, thickness, colour);
            x += period;
        }
    }

    /// A dashed vertical line over rows `y0 ..= y1`, starting with a dash at the top.
    #[allow(clippy::too_many_arguments)]
    pub fn dashed_vline(
        &mut self,
        x: i64,
        y0: i64,
        y1: i64,
        thickness: i64,
        dash: i64,
        gap: i64,
        colour: Rgb,
    ) {
        let (a, b) = (y0.min(y1), y0.max(y1));
        let (dash, period) = (dash.max(1), dash.max(1) + gap.max(0));
        let mut y = a;
        while y <= b {
            self.vline(x, y, (y + dash - 1).min(b), thickness, colour);
            y += period;
        }
    }

    /// An anti-aliased straight line of `width` pixels with round ends, from `(x0, y0)` to
    /// `(x1, y1)` in real pixel coordinates (pixel `(i, j)` has its centre at `(i + 0.5, j + 0.5)`).
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width: f64, colour: Rgb) {
        self.polyline(&[(x0, y0), (x1, y1)], width, colour);
    }

    /// Anti-aliased connected line segments through `points`, `width` pixels wide, with round
    /// joins and ends. Each pixel is blended once, by the largest coverage of any segment, so
    /// the joins show no overlap. Non-finite points are skipped (their neighbours are joined).
    pub fn polyline(&mut self, points: &[(f64, f64)], width: f64, colour: Rgb) {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        if pts.is_empty() || width.is_nan() || width <= 0.0 {
            return;
        }
        let r = width / 2.0;
        let reach = r + 1.0;
        let (mut xa, mut ya, mut xb, mut yb) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for &(x, y) in &pts {
            xa = xa.min(x);
            ya = ya.min(y);
            xb = xb.max(x);
            yb = yb.max(y);
        }
        let area = self
            .clip
            .intersect(&span_rect(xa - reach, ya - reach, xb + reach, yb + reach));
        if area.is_empty() {
            return;
        }
        let mut mask = vec![0f32; (area.width * area.height) as usize];
        let segments: Vec<((f64, f64), (f64, f64))> = if pts.len() == 1 {
            vec![(pts[0], pts[0])]
        } else {
            pts.windows(2).map(|w| (w[0], w[1])).collect()
        };
        for (p, q) in segments {
            let rows = area.intersect(&span_rect(
                p.0.min(q.0) - reach,
                p.1.min(q.1) - reach,
                p.0.max(q.0) + reach,
                p.1.max(q.1) + reach,
            ));
            for py in rows.y..rows.bottom() {
                let yc = py as f64 + 0.5;
                // The columns the thickened segment can touch on this row.
                let (mut lo, mut hi) = (p.0.min(q.0), p.0.max(q.0));
                let dy = q.1 - p.1;
                if dy.abs() > 1e-9 {
                    let t0 = ((yc - reach - p.1) / dy).clamp(0.0, 1.0);
                    let t1 = ((yc + reach - p.1) / dy).clamp(0.0, 1.0);
                    let (xa, xb) = (p.0 + t0 * (q.0 - p.0), p.0 + t1 * (q.0 - p.0));
                    lo = xa.min(xb);
                    hi = xa.max(xb);
                }
                let x0 = ((lo - reach).floor() as i64).max(rows.x);
                let x1 = ((hi + reach).ceil() as i64).min(rows.right() - 1);
                for px in x0..=x1 {
                    let d = segment_distance((px as f64 + 0.5, yc), p, q);
                    let cov = (r + 0.5 - d).clamp(0.0, 1.0) as f32;
                    let m = &mut mask[((py - area.y) * area.width + px - area.x) as usize];
                    *m = m.max(cov);
                }
            }
        }
        for py in area.y..area.bottom() {
            for px in area.x..area.right() {
                let cov = mask[((py - area.y) * area.width + px - area.x) as usize];
                self.blend_pixel(px, py, colour, cov as f64);
            }
        }
    }

    /// An anti-aliased filled disc of radius `r` centred on `(cx, cy)`.
    pub fn circle(&mut self, cx: f64, cy: f64, r: f64, colour: Rgb) {
        self.fill_sdf(cx, cy, r + 1.0, colour, |x, y| (x * x + y * y).sqrt() - r);
    }

    /// An anti-aliased data marker of the given `radius` (half its nominal extent) centred on
    /// `(cx, cy)`.
    pub fn marker(&mut self, cx: f64, cy: f64, radius: f64, kind: Marker, colour: Rgb) {
        self.marker_grown(cx, cy, radius, 0.0, kind, colour);
    }

    /// A marker whose outline is pushed out by `grow` pixels (a halo for `grow > 0`).
    pub(crate) fn marker_grown(
        &mut self,
        cx: f64,
        cy: f64,
        radius: f64,
        grow: f64,
        kind: Marker,
        colour: Rgb,
    ) {
        if radius.is_nan() || radius <= 0.0 || !cx.is_finite() || !cy.is_finite() {
            return;
        }
        let r = radius;
        let reach = 1.5 * r + grow + 1.0;
        let stroke = (0.28 * r).max(1.0);
        match kind {
            Marker::Circle => self.fill_sdf(cx, cy, reach, colour, |x, y| {
                (x * x + y * y).sqrt() - r - grow
            }),
            Marker::Square => {
                let a = 0.86 * r;
                self.fill_sdf(cx, cy, reach, colour, |x, y| {
                    x.abs().max(y.abs()) - a - grow
                })
            }
            Marker::Diamond => {
                let a = 1.2 * r;
                self.fill_sdf(cx, cy, reach, colour, |x, y| {
                    (x.abs() + y.abs() - a) / std::f64::consts::SQRT_2 - grow
                })
            }
            Marker::TriangleUp | Marker::TriangleDown => {
                // An equilateral triangle around its centroid, circumradius 1.3·r.
                let s = if kind == Marker::TriangleUp {
                    1.0
                } else {
                    -1.0
                };
                let inner = 0.65 * r; // distance from the centroid to each side
                let normals = [
                    (0.0, s),
                    (0.866_025_403_784_438_6, -0.5 * s),
                    (-0.866_025_403_784_438_6, -0.5 * s),
                ];
                self.fill_sdf(cx, cy + 0.12 * r * s, reach, colour, move |x, y| {
                    normals
                        .iter()
                        .map(|(nx, ny)| nx * x + ny * y - inner)
                        .fold(f64::MIN, f64::max)
                        - grow
                })
            }
            Marker::Cross | Marker::Plus => {
                let (a, b) = if kind == Marker::Cross {
                    let d = r * std::f64::consts::FRAC_1_SQRT_2 * 1.15;
                    ((d, d), (d, -d))
                } else {
                    ((1.1 * r, 0.0), (0.0, 1.1 * r))
                };
                let half = stroke / 2.0 + 0.3;
                self.fill_sdf(cx, cy, reach, colour, move |x, y| {
                    let d1 = segment_distance((x, y), (-a.0, -a.1), a);
                    let d2 = segment_distance((x, y), (-b.0, -b.1), b);
                    d1.min(d2) - half - grow
                })
            }
        }
    }

    /// Blends `colour` over the pixels within `reach` of `(cx, cy)` by the coverage implied by
    /// the signed distance `sdf(x − cx, y − cy)` of each pixel centre (negative inside).
    fn fill_sdf(
        &mut self,
        cx: f64,
        cy: f64,
        reach: f64,
        colour: Rgb,
        sdf: impl Fn(f64, f64) -> f64,
    ) {
        let area = self
            .clip
            .intersect(&span_rect(cx - reach, cy - reach, cx + reach, cy + reach));
        for py in area.y..area.bottom() {
            for px in area.x..area.right() {
                let d = sdf(px as f64 + 0.5 - cx, py as f64 + 0.5 - cy);
                self.blend_pixel(px, py, colour, (0.5 - d).clamp(0.0, 1.0));
            }
        }
    }

    /// Draws `text` on one line with the top-left corner of its box at `(x, y)`; returns the box
    /// (see [`text_size`]).
    pub fn text(&mut self, x: i64, y: i64, text: &str, style: TextStyle) -> Rect {
        let (w, h) = text_size(text, style);
        let (s, extra) = (style.unit(), style.embolden());
        let mut pen = x;
        for c in text.chars() {
            let g = font::glyph(c);
            for row in 0..font::CELL_H {
                for col in g.first_col..g.first_col + g.width {
                    if g.ink(row, col) {
                        let gx = pen + (col - g.first_col) as i64 * s;
                        self.fill_rect(
                            Rect::new(gx, y + row as i64 * s, s + extra, s),
                            style.colour,
                        );
                    }
                }
            }
            pen += g.width as i64 * s + extra + font::SPACING as i64 * s;
        }
        Rect::new(x, y, w, h)
    }

    /// Draws `text` placed relative to the anchor `(x, y)`: `h` aligns the anchor with the left
    /// edge, centre or right edge of the text, `v` with the top, middle or bottom of its box.
    /// Returns the box.
    pub fn text_aligned(
        &mut self,
        x: i64,
        y: i64,
        text: &str,
        style: TextStyle,
        h: Align,
        v: Align,
    ) -> Rect {
        let (w, ht) = text_size(text, style);
        self.text(x - h.offset(w), y - v.offset(ht), text, style)
    }

    /// Draws `text` turned a quarter turn anticlockwise (reading upwards, as a y-axis label),
    /// with the top-left corner of its box at `(x, y)`; the box is [`text_size`] with width and
    /// height swapped. Returns the box.
    pub fn text_vertical(&mut self, x: i64, y: i64, text: &str, style: TextStyle) -> Rect {
        let (w, h) = text_size(text, style);
        let (s, extra) = (style.unit(), style.embolden());
        let mut pen = 0;
        for c in text.chars() {
            let g = font::glyph(c);
            for row in 0..font::CELL_H {
                for col in g.first_col..g.first_col + g.width {
                    if g.ink(row, col) {
                        // (u, v) in the unrotated box maps to (v, w − u) in the turned one.
                        let u = pen + (col - g.first_col) as i64 * s;
                        let v = row as i64 * s;
                        let rect = Rect::new(x + v, y + w - u - s - extra, s, s + extra);
                        self.fill_rect(rect, style.colour);
                    }
                }
            }
            pen += g.width as i64 * s + extra + font::SPACING as i64 * s;
        }
        Rect::new(x, y, h, w)
    }

    /// The canvas as a PNG file (8-bit RGB), in memory.
    pub fn encode_png(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Balanced);
        // Writing to memory cannot fail for the sizes `Canvas::new` accepts.
        let mut writer = encoder
            .write_header()
            .expect("a PNG header for a valid size");
        writer
            .write_image_data(&self.data)
            .expect("RGB data of the canvas's size");
        writer.finish().expect("a complete PNG stream");
        out
    }

    /// Writes the canvas to `path` as a PNG file, atomically (see [`crate::io::write_atomic`]):
    /// on error no file is left at `path`, or the one there is left as it was.
    ///
    /// # Errors
    /// [`Error::File`] naming `path` when it cannot be written.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::io::write_bytes_atomic(path, &self.encode_png())
    }
}

/// The pixels touched by the real box `[x0, x1] × [y0, y1]`, saturating far outside.
fn span_rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Rect {
    const FAR: f64 = 1e9;
    let (a, b) = (
        x0.clamp(-FAR, FAR).floor() as i64,
        y0.clamp(-FAR, FAR).floor() as i64,
    );
    let (c, d) = (
        x1.clamp(-FAR, FAR).ceil() as i64,
        y1.clamp(-FAR, FAR).ceil() as i64,
    );
    Rect::new(a, b, (c - a + 1).max(0), (d - b + 1).max(0))
}

/// The distance from `p` to the segment `a`–`b`.
fn segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (p.0 - a.0 - t * dx, p.1 - a.1 - t * dy);
    (ex * ex + ey * ey).sqrt()
}
