//! Text in the embedded DejaVu Sans: the font's registration with plotters, and labels laid out
//! glyph by glyph from the font's metrics (advances, kerning, side bearings), placed by the top
//! of their capitals, level or reading upwards, with a combining circumflex (U+0302, as in X̂)
//! drawn over the letter before it. plotters rasterises each glyph.

use std::sync::OnceLock;

use ab_glyph::{Font as _, FontRef, ScaleFont};
use plotters::coord::Shift;
use plotters::drawing::DrawingArea;
use plotters::element::PathElement;
use plotters::prelude::BitMapBackend;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{
    register_font, Color, FontDesc, FontFamily, FontStyle, FontTransform, RGBColor, TextStyle,
};

use crate::error::{Error, Result};

use super::colour::Rgb;

/// A drawing area on a figure's pixel buffer.
pub(super) type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// The name the embedded font is registered under with plotters.
const FAMILY: &str = "rdlidar-dejavu-sans";

/// The combining circumflex accent.
const HAT: char = '\u{302}';

// DejaVu Sans's vertical metrics as fractions of the size plotters gives a font (the height from
// descender to ascender): plotters draws a line's baseline half a size below the point it places
// text at, and capitals (and digits) rise 0.626 of a size above the baseline.
const BASELINE: f64 = 0.5;
const CAP: f64 = 0.626;
/// How far descenders reach below the baseline.
const DESCENT: f64 = 0.21;
/// How far a circumflex drawn by [`label`] rises above the capitals.
const HAT_RISE: f64 = 0.22;

/// The regular and bold faces, parsed for their metrics.
pub(super) struct Faces {
    regular: FontRef<'static>,
    bold: FontRef<'static>,
}

/// Registers the embedded font with plotters, once, and returns its faces.
///
/// # Errors
/// [`Error::InvalidParameter`] (`font`) if the embedded font cannot be read (it always can).
pub(super) fn faces() -> Result<&'static Faces> {
    static FACES: OnceLock<Option<Faces>> = OnceLock::new();
    let faces = FACES.get_or_init(|| {
        let (regular, bold) = (dejavu::sans::regular(), dejavu::sans::bold());
        register_font(FAMILY, FontStyle::Normal, regular).ok()?;
        register_font(FAMILY, FontStyle::Bold, bold).ok()?;
        Some(Faces {
            regular: FontRef::try_from_slice(regular).ok()?,
            bold: FontRef::try_from_slice(bold).ok()?,
        })
    });
    faces
        .as_ref()
        .ok_or_else(|| Error::param("font", "the embedded DejaVu Sans could not be read"))
}

/// Turns a plotters drawing error into the crate's error.
pub(super) fn drawn<T, E: std::fmt::Display>(r: std::result::Result<T, E>) -> Result<T> {
    r.map_err(|e| Error::param("figure", format!("drawing failed: {e}")))
}

/// A text size and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Font {
    pub size: f64,
    pub bold: bool,
}

/// One glyph of a laid-out line: the character, where it starts along the line, where plotters
/// must place it (where its ink starts, to the pixel), and where the next one starts.
struct Placed {
    c: char,
    pen: f64,
    ink_x: f64,
    end: f64,
}

impl Font {
    pub const fn new(size: f64) -> Self {
        Font { size, bold: false }
    }

    pub const fn bold(size: f64) -> Self {
        Font { size, bold: true }
    }

    /// The plotters style, in `colour`.
    pub fn style(self, colour: Rgb) -> TextStyle<'static> {
        let weight = if self.bold {
            FontStyle::Bold
        } else {
            FontStyle::Normal
        };
        TextStyle {
            font: FontDesc::new(FontFamily::Name(FAMILY), self.size, weight),
            color: RGBColor::from(colour).to_backend_color(),
            pos: Pos::new(HPos::Left, VPos::Top),
        }
    }

    /// Pixels from the top of the capitals to the lowest descender.
    pub fn height(self) -> i32 {
        ((CAP + DESCENT) * self.size).ceil() as i32
    }

    /// Pixels from the top of the capitals to the baseline.
    pub fn cap(self) -> i32 {
        (CAP * self.size).round() as i32
    }

    /// Pixels a circumflex stands above the capitals.
    pub fn hat_rise(self) -> i32 {
        (HAT_RISE * self.size).ceil() as i32
    }

    /// The glyphs of `text` (circumflexes left out) laid out along a line from 0.
    fn layout(self, text: &str) -> Result<Vec<Placed>> {
        let faces = faces()?;
        let face = if self.bold {
            &faces.bold
        } else {
            &faces.regular
        };
        let font = face.as_scaled(self.size as f32);
        let mut pen = 0.0f64;
        let mut prev = None;
        let mut out = Vec::new();
        for c in text.chars().filter(|&c| c != HAT) {
            let id = font.glyph_id(c);
            if let Some(p) = prev {
                pen += font.kern(p, id) as f64;
            }
            let start = pen;
            let ink_x = pen.round() + (font.h_side_bearing(id) as f64).floor();
            pen += font.h_advance(id) as f64;
            out.push(Placed {
                c,
                pen: start,
                ink_x,
                end: pen,
            });
            prev = Some(id);
        }
        Ok(out)
    }

    /// The width of `text` in pixels (circumflexes over a letter take no room).
    pub fn width(self, text: &str) -> Result<i32> {
        Ok(self.layout(text)?.last().map_or(0, |g| g.end.ceil() as i32))
    }

    /// The width of the widest of `texts`.
    pub fn widest<'t>(self, texts: impl IntoIterator<Item = &'t str>) -> Result<i32> {
        texts
            .into_iter()
            .try_fold(0, |m, t| Ok(m.max(self.width(t)?)))
    }

    /// Draws `text` in `colour` with the top of its capitals at `at`, aligned there by `h`.
    pub fn put(self, area: &Area, text: &str, colour: Rgb, at: (i32, i32), h: HPos) -> Result<()> {
        label(area, text, self, colour, at, h, false)
    }

    /// Draws `text` in `colour` reading upwards (as a y axis label), centred on `at` along
    /// its length, the tops of its capitals on the column `at.0`.
    pub fn put_upwards(self, area: &Area, text: &str, colour: Rgb, at: (i32, i32)) -> Result<()> {
        label(area, text, self, colour, at, HPos::Center, true)
    }
}

/// Draws `text` in `font` and `colour` with the top of its capitals at `at`, aligned there by
/// `h` along the text; `upwards` turns it a quarter left (reading bottom to top, the capitals'
/// tops facing left). A combining circumflex after a letter is drawn as a chevron over that
/// letter.
fn label(
    area: &Area,
    text: &str,
    font: Font,
    colour: Rgb,
    at: (i32, i32),
    h: HPos,
    upwards: bool,
) -> Result<()> {
    let glyphs = font.layout(text)?;
    let Some(last) = glyphs.last() else {
        return Ok(());
    };
    let s = font.size;
    let start = match h {
        HPos::Left => 0.0,
        HPos::Center => -last.end / 2.0,
        HPos::Right => -last.end,
    };
    // Local coordinates: `along` the text from its aligned point, `down` from the capitals' top.
    let place = |along: f64, down: f64| -> (i32, i32) {
        let (a, d) = (along.round() as i32, down.round() as i32);
        if upwards {
            (at.0 + d, at.1 - a)
        } else {
            (at.0 + a, at.1 + d)
        }
    };
    let mut style = font.style(colour);
    if upwards {
        style = style.transform(FontTransform::Rotate270);
    }
    // plotters starts a glyph's ink where it is placed, so each glyph is placed at its ink.
    let mut buf = [0u8; 4];
    for g in &glyphs {
        let c: &str = g.c.encode_utf8(&mut buf);
        if !g.c.is_whitespace() {
            let pos = place(start + g.ink_x, (CAP - BASELINE) * s);
            drawn(area.draw_text(c, &style, pos))?;
        }
    }

    // Circumflexes, over the glyph before each.
    let mut k = 0usize;
    for c in text.chars() {
        if c != HAT {
            k += 1;
            continue;
        }
        let Some(base) = k.checked_sub(1).map(|i| &glyphs[i]) else {
            continue;
        };
        let centre = start + (base.pen + base.end) / 2.0;
        let half = 0.24 * s;
        let chevron = vec![
            place(centre - half, -0.05 * s),
            place(centre, -HAT_RISE * s),
            place(centre + half, -0.05 * s),
        ];
        let stroke = ((s / 14.0).round() as u32).max(1);
        let ink = RGBColor::from(colour).stroke_width(stroke);
        drawn(area.draw(&PathElement::new(chevron, ink)))?;
    }
    Ok(())
}
