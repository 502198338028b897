//! Scenes from images: an opaque scene from a PNG depth map (feature `images`).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use ndarray::Array2;

use crate::error::{Error, Result};
use crate::lidar::{checked, DepthMap, Geometry, Returns, Scene, NO_RETURN};
use crate::real::Real;

/// The error for an unusable PNG file, naming it.
fn png_error(path: &Path, what: impl std::fmt::Display) -> Error {
    Error::param("png", format!("{}: {}", path.display(), what))
}

/// Refuses an image wider or higher than a scene can be ([`crate::limits::MAX_SIDE`]) before
/// its pixels are decoded.
fn check_sides(path: &Path, width: usize, height: usize) -> Result<()> {
    let max = crate::limits::MAX_SIDE;
    if width > max || height > max {
        return Err(png_error(
            path,
            format!("{width}×{height} pixels: a scene has at most {max} rows and {max} columns"),
        ));
    }
    Ok(())
}

/// The height and width of a PNG image, from its header alone.
///
/// # Errors
/// [`Error::InvalidParameter`] with name `"png"` and a reason starting with the file's path if
/// the file cannot be opened or has no readable PNG header.
pub fn png_dimensions(path: &Path) -> Result<(usize, usize)> {
    let file = File::open(path).map_err(|e| png_error(path, format!("cannot open: {e}")))?;
    let reader = png::Decoder::new(BufReader::new(file))
        .read_info()
        .map_err(|e| png_error(path, format!("not a readable PNG: {e}")))?;
    Ok((reader.info().height as usize, reader.info().width as usize))
}

/// A decoded single-channel image: `values[y·width + x]` in `[0, max]`.
struct GrayImage {
    width: usize,
    height: usize,
    values: Vec<u16>,
    max: u16,
}

/// Reads a PNG as one channel: grayscale as is, grayscale+alpha and RGB(A) by their first
/// channel (gray, resp. red), palette images through their palette's red channel; alpha is
/// ignored. Bit depths below 8 are expanded to 8 bits (scaled to full range); 16-bit stays 16-bit.
fn read_png(path: &Path) -> Result<GrayImage> {
    let file = File::open(path).map_err(|e| png_error(path, format!("cannot open: {e}")))?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| png_error(path, format!("not a readable PNG: {e}")))?;
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    check_sides(path, w, h)?;
    let len = reader
        .output_buffer_size()
        .ok_or_else(|| png_error(path, "image too large"))?;
    let mut buf = vec![0u8; len];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| png_error(path, format!("cannot decode image data: {e}")))?;
    let channels = frame.color_type.samples();
    let (bytes, max) = match frame.bit_depth {
        png::BitDepth::Eight => (1, u8::MAX as u16),
        png::BitDepth::Sixteen => (2, u16::MAX),
        other => {
            return Err(png_error(
                path,
                format!("unsupported bit depth {other:?} after expansion"),
            ))
        }
    };
    let (width, height) = (frame.width as usize, frame.height as usize);
    let stride = frame.line_size;
    if stride < width * channels * bytes || buf.len() < stride * height {
        return Err(png_error(path, "decoded rows are shorter than the image"));
    }
    let mut values = Vec::with_capacity(width * height);
    for y in 0..height {
        let row = &buf[y * stride..];
        for x in 0..width {
            let at = x * channels * bytes;
            values.push(if bytes == 1 {
                row[at] as u16
            } else {
                u16::from_be_bytes([row[at], row[at + 1]])
            });
        }
    }
    Ok(GrayImage {
        width,
        height,
        values,
        max,
    })
}

/// An opaque scene from a PNG depth map and an optional PNG reflectivity map.
///
/// Image row y, column x becomes scene pixel (m, n) = (y, x), so the scene is height × width × `ks`.
///
/// - Depth: a value v > 0 gives depth bin `round(v / max · (ks − 1))`, where max is the full scale
///   of the bit depth (255 for 8-bit, 65 535 for 16-bit; 1-, 2- and 4-bit grayscale is first
///   expanded to 8 bits). **v = 0 means no return.**
/// - Reflectivity: amplitude `v / max` from `reflectivity_png` (same size as the depth map), or 1.0
///   for every lit pixel if it is `None`. A lit pixel with reflectivity 0 gives an all-zero column.
/// - Colour: grayscale is read as is; for grayscale+alpha, RGB and RGBA images the FIRST channel
///   (gray, resp. red) is used, not the luminance; palette images use their palette's red channel;
///   alpha is ignored.
///
/// # Errors
/// [`Error::InvalidParameter`] with name `"png"` and a reason starting with the file's path if a
/// file cannot be opened or is not a decodable PNG; [`Error::ShapeMismatch`] naming both files if
/// the reflectivity map's width or height differs from the depth map's;
/// [`Error::InvalidParameter`] if `ks` is zero or exceeds `i32::MAX`.
pub fn scene_from_pngs<T: Real>(
    depth_png: &Path,
    reflectivity_png: Option<&Path>,
    ks: usize,
) -> Result<Scene<T>> {
    let (g, depth, reflectivity) = read_maps(depth_png, reflectivity_png, ks)?;
    let depth_bins = depth.mapv(|d| {
        if d.is_nan() {
            NO_RETURN
        } else {
            d.round().clamp(0.0, (g.ks - 1) as f64) as i32
        }
    });
    DepthMap {
        depth: depth_bins,
        amplitude: reflectivity.mapv(T::of_f64),
    }
    .to_scene(g.ks)
}

/// The returns of [`scene_from_pngs`] at continuous depths: a value v > 0 is depth
/// v / max · (ks − 1) bins, unrounded.
///
/// # Errors
/// As [`scene_from_pngs`].
pub fn returns_from_pngs(
    depth_png: &Path,
    reflectivity_png: Option<&Path>,
    ks: usize,
) -> Result<Returns> {
    let (_, depth, reflectivity) = read_maps(depth_png, reflectivity_png, ks)?;
    Returns::single(depth, reflectivity)
}

/// The grid of the maps, the depth in continuous bins (NaN for no return) and the amplitude
/// (0 where there is no return).
fn read_maps(
    depth_png: &Path,
    reflectivity_png: Option<&Path>,
    ks: usize,
) -> Result<(Geometry, Array2<f64>, Array2<f64>)> {
    let depth = read_png(depth_png)?;
    let g = checked(Geometry {
        m: depth.height,
        n: depth.width,
        ks,
    })?;
    let reflectivity = match reflectivity_png {
        None => None,
        Some(path) => {
            let r = read_png(path)?;
            for (what, expected, found) in [
                ("width", depth.width, r.width),
                ("height", depth.height, r.height),
            ] {
                if expected != found {
                    return Err(Error::shape(
                        format!(
                            "{}: reflectivity PNG {what} vs depth PNG {}",
                            path.display(),
                            depth_png.display()
                        ),
                        expected,
                        found,
                    ));
                }
            }
            Some(r)
        }
    };
    let dmax = depth.max as f64;
    let top = (g.ks - 1) as f64;
    let depth_bins = Array2::from_shape_fn((g.m, g.n), |(i, j)| match depth.values[i * g.n + j] {
        0 => f64::NAN,
        v => v as f64 / dmax * top,
    });
    let amplitude = Array2::from_shape_fn((g.m, g.n), |(i, j)| {
        if depth_bins[[i, j]].is_nan() {
            0.0
        } else {
            match &reflectivity {
                None => 1.0,
                Some(r) => r.values[i * g.n + j] as f64 / r.max as f64,
            }
        }
    });
    Ok((g, depth_bins, amplitude))
}
