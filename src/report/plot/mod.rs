//! Figures as PNG images, drawn with `plotters` in pure Rust: depth maps side by side with a
//! colour bar, and XY charts (scatter and line plots, linear or logarithmic axes) for
//! comparisons such as error against run time or against pulse length.
//!
//! Figures are drawn into an RGB buffer (`plotters`' bitmap backend), with text in DejaVu Sans
//! embedded in the binary (no system fonts), so labels can say ‖X − X̂‖/‖X‖, Kₚ or τ. Colours
//! come from [`viridis`] for depths and [`PALETTE`] for series. Images are encoded with the
//! `png` crate and written atomically through [`crate::io::write_bytes_atomic`].
//!
//! Invalid input (no data, mismatched map shapes, non-finite values, a logarithmic axis with a
//! value ≤ 0, a zero-size or oversized image) is reported as an [`Error`], never a
//! panic.
//!
//! ```
//! use ndarray::Array2;
//! use rdlidar::report::plot::{depth_panels, line_plot, Chart, DepthOptions, Series};
//!
//! # fn main() -> rdlidar::Result<()> {
//! // Two 60 x 80 depth maps (bins, -1 where there is no return), 0.15 m per bin.
//! let truth = Array2::from_shape_fn((60, 80), |(i, j)| if i < 10 { -1 } else { (j / 4) as i32 });
//! let estimate = truth.mapv(|b| if b == 7 { -1 } else { b });
//! let maps = depth_panels(
//!     &[("truth", &truth), ("estimate", &estimate)],
//!     &DepthOptions::new(0.15, "m").title("Reconstructed depth"),
//! )?;
//! assert_eq!(maps.upscale(), 3); // 80 columns drawn 240 pixels wide
//!
//! // Error against pulse length on a log scale, with the critical length marked.
//! let chart = Chart::new("Phase transition")
//!     .x_label("pulse length Kₚ")
//!     .y_label("‖X − X̂‖/‖X‖")
//!     .log_y(true)
//!     .series(Series::new("FISTA", [(100.0, 0.8), (300.0, 0.2), (1000.0, 0.01)]))
//!     .series(Series::new("CoSaMP", [(100.0, 0.9), (300.0, 0.5), (1000.0, 0.002)]))
//!     .vline(400.0, "critical Kₚ");
//! let fig = line_plot(&chart)?;
//! assert_eq!((fig.width(), fig.height()), (800, 520));
//!
//! let png = fig.encode_png(); // or fig.save_png("phase.png")?, written atomically
//! assert_eq!(&png[..4], b"\x89PNG");
//! # let _ = maps.encode_png();
//! # Ok(())
//! # }
//! ```

mod axis;
mod chart;
mod colour;
mod depth;
mod draw;
mod text;

use std::path::Path;

use plotters::prelude::{BitMapBackend, IntoDrawingArea, WHITE};

use crate::error::{Error, Result};

pub use chart::{Chart, ChartFigure, LegendPosition, Marker, Series, SeriesStyle};
pub use colour::{series_colour, viridis, Rgb, PALETTE};
pub use depth::{depth_panels, DepthFigure, DepthOptions, NO_RETURN_COLOUR, UNOBSERVED_COLOUR};
pub use draw::{line_plot, scatter_plot};

/// The largest side of a figure, in pixels.
pub const MAX_SIDE: usize = 16_384;
/// The largest number of pixels in a figure (32 Mi, 96 MiB of RGB).
pub const MAX_PIXELS: usize = 1 << 25;

/// Checks the size of a figure.
///
/// # Errors
/// [`Error::InvalidParameter`] (`width` or `height`) for a zero side, a side above
/// [`MAX_SIDE`] or more than [`MAX_PIXELS`] pixels.
fn check_size(width: usize, height: usize) -> Result<()> {
    for (name, side) in [("width", width), ("height", height)] {
        if side == 0 || side > MAX_SIDE {
            return Err(Error::param(
                name,
                format!("{side} pixels: a figure's side must be between 1 and {MAX_SIDE}"),
            ));
        }
    }
    if width * height > MAX_PIXELS {
        return Err(Error::param(
            "height",
            format!("{width} x {height} is more than {MAX_PIXELS} pixels"),
        ));
    }
    Ok(())
}

/// A drawn image: 8-bit RGB, row by row.
#[derive(Debug, Clone, PartialEq)]
struct Bitmap {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Bitmap {
    /// Draws a white `width × height` image with `draw`.
    ///
    /// # Errors
    /// The errors of [`check_size`] and of `draw`.
    fn draw(
        width: usize,
        height: usize,
        draw: impl FnOnce(&text::Area) -> Result<()>,
    ) -> Result<Self> {
        check_size(width, height)?;
        text::faces()?;
        let mut rgb = vec![0u8; width * height * 3];
        {
            // Both sides are at most MAX_SIDE, so they fit in u32 and the buffer is exact.
            let root = BitMapBackend::with_buffer(&mut rgb, (width as u32, height as u32))
                .into_drawing_area();
            text::drawn(root.fill(&WHITE))?;
            draw(&root)?;
            text::drawn(root.present())?;
        }
        Ok(Bitmap { width, height, rgb })
    }

    fn encode_png(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Balanced);
        // Writing to memory cannot fail for the sizes `Bitmap::draw` accepts.
        let mut writer = encoder
            .write_header()
            .expect("a PNG header for a valid size");
        writer
            .write_image_data(&self.rgb)
            .expect("RGB data of the image's size");
        writer.finish().expect("a complete PNG stream");
        out
    }

    fn save_png(&self, path: &Path) -> Result<()> {
        crate::io::write_bytes_atomic(path, &self.encode_png())
    }
}
