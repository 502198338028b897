//! Colours: an sRGB triple, the viridis ramp for depths and a palette for series.

use plotters::style::RGBColor;

/// An sRGB colour with 8 bits per channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Rgb(pub u8, pub u8, pub u8);

impl Rgb {
    /// White.
    pub const WHITE: Rgb = Rgb(255, 255, 255);

    /// The colour `0xRRGGBB`.
    pub const fn hex(rgb: u32) -> Rgb {
        Rgb((rgb >> 16) as u8, (rgb >> 8) as u8, rgb as u8)
    }

    /// The colour a fraction `t` of the way from `self` to `other` (channel by channel, rounded;
    /// `t` is clamped to `[0, 1]`, NaN counts as 0).
    pub fn mix(self, other: Rgb, t: f64) -> Rgb {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let ch = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * t).round() as u8;
        Rgb(
            ch(self.0, other.0),
            ch(self.1, other.1),
            ch(self.2, other.2),
        )
    }

    /// Relative luminance in `[0, 1]` by the Rec. 709 weights on the 8-bit values (a quick
    /// lightness measure, e.g. to check that a ramp is ordered).
    pub fn luma(self) -> f64 {
        (0.2126 * self.0 as f64 + 0.7152 * self.1 as f64 + 0.0722 * self.2 as f64) / 255.0
    }
}

impl From<Rgb> for RGBColor {
    fn from(c: Rgb) -> RGBColor {
        RGBColor(c.0, c.1, c.2)
    }
}

/// Nine evenly spaced samples of matplotlib's viridis, dark purple to yellow.
const VIRIDIS: [u32; 9] = [
    0x440154, 0x472d7b, 0x3b528b, 0x2c728e, 0x21918c, 0x28ae80, 0x5ec962, 0xaddc30, 0xfde725,
];

/// The viridis colour at `t` in `[0, 1]` (clamped; NaN counts as 0), interpolated linearly
/// between nine samples: a perceptually ordered ramp from dark purple through blue and green to
/// yellow whose lightness increases monotonically, so it reads correctly in greyscale too. The
/// ends are exactly `0x440154` and `0xfde725`.
///
/// ```
/// use rdlidar::report::plot::{viridis, Rgb};
///
/// assert_eq!(viridis(0.0), Rgb::hex(0x440154));
/// assert_eq!(viridis(1.0), Rgb::hex(0xfde725));
/// assert!(viridis(0.3).luma() < viridis(0.6).luma());
/// ```
pub fn viridis(t: f64) -> Rgb {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let last = VIRIDIS.len() - 1;
    let pos = t * last as f64;
    let i = (pos.floor() as usize).min(last - 1);
    Rgb::hex(VIRIDIS[i]).mix(Rgb::hex(VIRIDIS[i + 1]), pos - i as f64)
}

/// Eight distinct colours for data series (the Okabe–Ito set, chosen to stay distinguishable
/// for the common forms of colour blindness), darkest and most saturated first; the yellow,
/// hard to see on white, is last.
pub const PALETTE: [Rgb; 8] = [
    Rgb::hex(0x0072b2), // blue
    Rgb::hex(0xd55e00), // vermilion
    Rgb::hex(0x009e73), // bluish green
    Rgb::hex(0xcc79a7), // reddish purple
    Rgb::hex(0xe69f00), // orange
    Rgb::hex(0x56b4e9), // sky blue
    Rgb::hex(0x000000), // black
    Rgb::hex(0xf0e442), // yellow
];

/// The colour of series `i`: [`PALETTE`], cycled.
pub fn series_colour(i: usize) -> Rgb {
    PALETTE[i % PALETTE.len()]
}
