//! Colours: an sRGB triple, a colour ramp for continuous values and a palette for series.

use crate::error::{Error, Result};

/// An sRGB colour with 8 bits per channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Rgb(pub u8, pub u8, pub u8);

impl Rgb {
    /// White.
    pub const WHITE: Rgb = Rgb(255, 255, 255);
    /// Black.
    pub const BLACK: Rgb = Rgb(0, 0, 0);

    /// The colour `0xRRGGBB`.
    pub const fn hex(rgb: u32) -> Rgb {
        Rgb((rgb >> 16) as u8, (rgb >> 8) as u8, rgb as u8)
    }

    /// The colour a fraction `t` of the way from `self` to `other` (channel by channel, rounded;
    /// `t` is clamped to `[0, 1]`).
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

/// A continuous colour map: colours at a few positions in `[0, 1]`, linearly interpolated in
/// between.
///
/// ```
/// use rdlidar::plot::{ColourMap, Rgb};
///
/// let map = ColourMap::viridis();
/// assert_eq!(map.at(0.0), Rgb::hex(0x440154));
/// assert_eq!(map.at(1.0), Rgb::hex(0xfde725));
/// assert!(map.at(0.3).luma() < map.at(0.6).luma());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ColourMap {
    stops: Vec<(f64, Rgb)>,
}

impl ColourMap {
    /// A map through `stops` (position, colour).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`stops`) unless there are at least two stops, the first at
    /// 0 and the last at 1, with finite, strictly increasing positions.
    pub fn new(stops: Vec<(f64, Rgb)>) -> Result<Self> {
        let bad = |why: &str| Err(Error::param("stops", why.to_string()));
        if stops.len() < 2 {
            return bad("a colour map needs at least two stops");
        }
        if stops.iter().any(|(p, _)| !p.is_finite()) {
            return bad("stop positions must be finite");
        }
        if stops.windows(2).any(|w| w[0].0 >= w[1].0) {
            return bad("stop positions must increase strictly");
        }
        if stops[0].0 != 0.0 || stops[stops.len() - 1].0 != 1.0 {
            return bad("the stops must run from 0 to 1");
        }
        Ok(ColourMap { stops })
    }

    /// A perceptually ordered ramp from dark purple through blue and green to yellow, through
    /// nine evenly spaced samples of matplotlib's viridis. Lightness increases monotonically, so
    /// it reads correctly in greyscale too.
    pub fn viridis() -> Self {
        const SAMPLES: [u32; 9] = [
            0x440154, 0x472d7b, 0x3b528b, 0x2c728e, 0x21918c, 0x28ae80, 0x5ec962, 0xaddc30,
            0xfde725,
        ];
        let last = (SAMPLES.len() - 1) as f64;
        ColourMap {
            stops: SAMPLES
                .iter()
                .enumerate()
                .map(|(i, &c)| (i as f64 / last, Rgb::hex(c)))
                .collect(),
        }
    }

    /// A ramp from near-black to near-white.
    pub fn greys() -> Self {
        ColourMap {
            stops: vec![(0.0, Rgb::hex(0x141414)), (1.0, Rgb::hex(0xf0f0f0))],
        }
    }

    /// The colour at `t`, clamped to `[0, 1]` (NaN counts as 0). The ends are exactly the first
    /// and last stops.
    pub fn at(&self, t: f64) -> Rgb {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let i = self.stops.partition_point(|(p, _)| *p <= t);
        if i == 0 {
            return self.stops[0].1;
        }
        if i == self.stops.len() {
            return self.stops[i - 1].1;
        }
        let ((p0, c0), (p1, c1)) = (self.stops[i - 1], self.stops[i]);
        c0.mix(c1, (t - p0) / (p1 - p0))
    }
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
