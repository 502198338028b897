//! Figures as PNG images, drawn in pure Rust: depth maps side by side with a colour bar, and XY
//! charts (scatter and line plots, linear or logarithmic axes) for comparisons such as error
//! against run time or against pulse length.
//!
//! Everything is drawn here, on a [`Canvas`] of RGB pixels: rectangles and grid lines on whole
//! pixels, anti-aliased lines and markers, and text in a built-in bitmap font (printable ASCII,
//! scaled by whole factors; no system fonts). Colours come from [`ColourMap::viridis`] for
//! values and [`PALETTE`] for series. Images are encoded with the `png` crate and written
//! atomically through [`crate::io::write_bytes_atomic`].
//!
//! Invalid input (no data, mismatched map shapes, non-finite values, a logarithmic axis with a
//! value ≤ 0, a zero-size image) is reported as an [`Error`](crate::Error), never a panic.
//!
//! ```
//! use ndarray::Array2;
//! use rdlidar::plot::{depth_panels, line_plot, Chart, DepthOptions, Series};
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
//!     .x_label("pulse length K_p")
//!     .y_label("relative error")
//!     .log_y(true)
//!     .series(Series::new("FISTA", [(100.0, 0.8), (300.0, 0.2), (1000.0, 0.01)]))
//!     .series(Series::new("CoSaMP", [(100.0, 0.9), (300.0, 0.5), (1000.0, 0.002)]))
//!     .vline(400.0, "critical K_p");
//! let fig = line_plot(&chart)?;
//!
//! let png = fig.encode_png(); // or fig.save_png("phase.png")?, written atomically
//! assert_eq!(&png[..4], b"\x89PNG");
//! # let _ = maps.encode_png();
//! # Ok(())
//! # }
//! ```

mod canvas;
mod chart;
mod colour;
mod depth;
mod font;
mod ticks;

pub use canvas::{text_size, Align, Canvas, Marker, Rect, TextStyle, MAX_PIXELS, MAX_SIDE};
pub use chart::{line_plot, scatter_plot, Chart, ChartFigure, LegendPosition, Series, SeriesStyle};
pub use colour::{series_colour, ColourMap, Rgb, PALETTE};
pub use depth::{depth_panels, DepthFigure, DepthOptions, NO_RETURN_COLOUR};
pub use ticks::{linear_ticks, log_ticks};
