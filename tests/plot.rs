//! Figures: the decoded PNGs' sizes and colours, ticks, text and input checks.

use std::io::Cursor;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::report::plot::{
    depth_panels, line_plot, scatter_plot, series_colour, viridis, Chart, DepthOptions,
    LegendPosition, Marker, Rgb, Series, SeriesStyle, NO_RETURN_COLOUR, PALETTE, UNOBSERVED_COLOUR,
};
use rdlidar::Error;

/// A decoded RGB image.
struct Image {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Image {
    fn decode(png_bytes: &[u8]) -> Image {
        let decoder = png::Decoder::new(Cursor::new(png_bytes.to_vec()));
        let mut reader = decoder.read_info().expect("a readable PNG");
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let frame = reader.next_frame(&mut buf).expect("image data");
        assert_eq!(frame.color_type, png::ColorType::Rgb);
        assert_eq!(frame.bit_depth, png::BitDepth::Eight);
        buf.truncate(frame.buffer_size());
        Image {
            width: frame.width as usize,
            height: frame.height as usize,
            rgb: buf,
        }
    }

    fn at(&self, x: usize, y: usize) -> Rgb {
        let i = 3 * (y * self.width + x);
        Rgb(self.rgb[i], self.rgb[i + 1], self.rgb[i + 2])
    }

    /// The pixels for which `f(x, y, colour)` holds.
    fn count(&self, f: impl Fn(usize, usize, Rgb) -> bool) -> usize {
        (0..self.height)
            .flat_map(|y| (0..self.width).map(move |x| (x, y)))
            .filter(|&(x, y)| f(x, y, self.at(x, y)))
            .count()
    }

    /// The pixels of exactly `colour`.
    fn count_of(&self, colour: Rgb) -> usize {
        self.count(|_, _, c| c == colour)
    }

    /// Dark pixels (text, frames, ticks).
    fn ink(&self) -> usize {
        self.count(|_, _, c| c.luma() < 0.5)
    }
}

fn param_err<T>(r: rdlidar::Result<T>, name: &str) {
    match r {
        Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
        Err(other) => panic!("expected an invalid `{name}`, got {other}"),
        Ok(_) => panic!("expected an invalid `{name}`, got Ok"),
    }
}

/// A fresh directory under the system temporary directory, removed when dropped.
struct TempDir(PathBuf);

static DIRS: AtomicUsize = AtomicUsize::new(0);

impl TempDir {
    fn new(tag: &str) -> Self {
        let n = DIRS.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("rdlidar-plot-{}-{tag}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }

    fn listing(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A 20 × 30 map: no return in the top 4 rows, then bins growing with the column, 5 to 34.
fn ramp_map() -> Array2<i32> {
    Array2::from_shape_fn((20, 30), |(i, j)| if i < 4 { -1 } else { 5 + j as i32 })
}

// ---------------------------------------------------------------------------------------------
// Depth panels

#[test]
fn unobserved_pixels_have_their_own_colour_and_key() {
    let a = ramp_map();
    // Bin 10's column unobserved in the estimate.
    let b = a.mapv(|v| {
        if v == 10 {
            rdlidar::lidar::UNOBSERVED
        } else {
            v
        }
    });
    let opts = DepthOptions::new(0.5, "m");
    let fig = depth_panels(&[("truth", &a), ("estimate", &b)], &opts).unwrap();
    assert_eq!(fig.colour_of(-2), UNOBSERVED_COLOUR);
    assert_ne!(UNOBSERVED_COLOUR, NO_RETURN_COLOUR);
    let img = Image::decode(&fig.encode_png());
    // 16 pixels of the column, drawn 9 x 9, and the key (22 x 16).
    let unobserved = img.count_of(UNOBSERVED_COLOUR);
    assert_eq!(unobserved, 16 * 81 + 22 * 16);
    // Without unobserved pixels there is no such key.
    let plain = depth_panels(&[("truth", &a)], &opts).unwrap();
    let img = Image::decode(&plain.encode_png());
    assert_eq!(img.count_of(UNOBSERVED_COLOUR), 0);
}

#[test]
fn depth_panels_draw_near_far_and_no_return_colours() {
    let a = ramp_map();
    let b = a.mapv(|v| if v == 10 { -1 } else { v });
    let fig = depth_panels(
        &[("truth", &a), ("estimate", &b)],
        &DepthOptions::new(0.5, "m"),
    )
    .unwrap();
    assert_eq!(fig.upscale(), 9, "30 columns scaled to about 275 pixels");
    assert_eq!(fig.bin_range(), (5.0, 34.0));
    assert_eq!(fig.colour_of(5), viridis(0.0));
    assert_eq!(fig.colour_of(34), viridis(1.0));
    assert_eq!(fig.colour_of(-1), NO_RETURN_COLOUR);
    let img = Image::decode(&fig.encode_png());
    assert_eq!((img.width, img.height), (fig.width(), fig.height()));
    assert!(img.width > 2 * 270 && img.height > 180, "{}", img.width);

    // One column of 16 returns per map and bin, drawn 9 x 9, plus at most a few rows of the
    // colour bar (22 pixels wide).
    let block = 16 * 81;
    let near = img.count_of(viridis(0.0));
    let far = img.count_of(viridis(1.0));
    for n in [near, far] {
        assert!((2 * block..2 * block + 3 * 22).contains(&n), "{n}");
    }
    // Bin 10 is missing from the estimate: one map's worth only.
    let missing = img.count_of(fig.colour_of(10));
    assert!((block..block + 3 * 22).contains(&missing), "{missing}");
    // No return: 4 rows of each map, the estimate's missing column and the key (22 x 16).
    let none = img.count_of(NO_RETURN_COLOUR);
    let expected = (2 * 4 * 30 + 16) * 81 + 22 * 16;
    assert!(
        (expected..expected + 40).contains(&none),
        "{none} vs {expected}"
    );

    // The colour bar: one column runs from the far colour down to the near one, its lightness
    // never increasing on the way; no column of a map holds both.
    let bar_x = (0..img.width)
        .find(|&x| {
            let top = (0..img.height).find(|&y| img.at(x, y) == viridis(1.0));
            let bottom = (0..img.height)
                .rev()
                .find(|&y| img.at(x, y) == viridis(0.0));
            matches!((top, bottom), (Some(t), Some(b)) if b > t + 100)
        })
        .expect("a colour bar");
    assert!(bar_x > 2 * 270, "the bar is right of the maps");
    let column: Vec<Rgb> = (0..img.height)
        .map(|y| img.at(bar_x, y))
        .skip_while(|&c| c != viridis(1.0))
        .take_while(|&c| c != NO_RETURN_COLOUR && c.luma() > 0.2 || c == viridis(0.0))
        .collect();
    assert!(column.len() > 100);
    assert!(
        column.windows(2).all(|w| w[0].luma() >= w[1].luma() - 1e-9),
        "bright far, dark near"
    );
    // Tick labels, "depth (m)" and "no return" to the right of the bar.
    let text = img.count(|x, _, c| x > bar_x + 20 && c.luma() < 0.5);
    assert!(text > 300, "{text}");
}

#[test]
fn depth_options_set_scale_range_and_title() {
    let a = ramp_map();
    let plain = depth_panels(&[("only", &a)], &DepthOptions::default().upscale(2)).unwrap();
    let fig = depth_panels(
        &[("only", &a)],
        &DepthOptions::default()
            .upscale(2)
            .range(0, 100)
            .title("A title"),
    )
    .unwrap();
    assert_eq!(fig.upscale(), 2);
    assert_eq!(fig.bin_range(), (0.0, 100.0));
    assert_eq!(fig.colour_of(50), viridis(0.5));
    assert_eq!(
        fig.colour_of(200),
        viridis(1.0),
        "bins beyond the range take its end"
    );
    assert!(fig.height() >= plain.height() + 20, "room for the title");
    let img = Image::decode(&fig.encode_png());
    // Bin 5 at 5% of the range: a 16 x 1 column of 2 x 2 pixels.
    assert!(img.count_of(viridis(0.05)) >= 16 * 4);
    assert_eq!(
        img.count_of(viridis(0.0)),
        22,
        "only the bar's bottom row is that near"
    );

    // A 100 x 100 map is drawn about 300 pixels wide; one depth only: the bar spans half a bin
    // either way and the map takes its middle colour.
    let flat = Array2::from_elem((100, 100), 3);
    let fig = depth_panels(&[("flat", &flat)], &DepthOptions::new(0.15, "m")).unwrap();
    assert_eq!(fig.upscale(), 3);
    assert_eq!(fig.bin_range(), (2.5, 3.5));
    let img = Image::decode(&fig.encode_png());
    assert!(img.count_of(viridis(0.5)) >= 300 * 300);

    // No returns at all is a valid (if empty) figure.
    let none = Array2::from_elem((10, 10), -1);
    let fig = depth_panels(&[("nothing", &none)], &DepthOptions::default()).unwrap();
    let k = fig.upscale();
    assert_eq!(k, 28);
    let img = Image::decode(&fig.encode_png());
    assert!(img.count_of(NO_RETURN_COLOUR) >= 280 * 280);
}

#[test]
fn depth_panels_reject_bad_input() {
    let a = ramp_map();
    let opts = DepthOptions::new(0.15, "m");
    param_err(depth_panels(&[], &opts), "panels");
    let empty = Array2::<i32>::zeros((0, 5));
    param_err(depth_panels(&[("e", &empty)], &opts), "depth");
    let tall = Array2::from_elem((21, 30), 1);
    match depth_panels(&[("a", &a), ("b", &tall)], &opts) {
        Err(Error::ShapeMismatch {
            expected, found, ..
        }) => assert_eq!((expected, found), (20, 21)),
        other => panic!("expected a shape mismatch, got {other:?}"),
    }
    let wide = Array2::from_elem((20, 31), 1);
    match depth_panels(&[("a", &a), ("b", &wide)], &opts) {
        Err(Error::ShapeMismatch {
            expected, found, ..
        }) => assert_eq!((expected, found), (30, 31)),
        other => panic!("expected a shape mismatch, got {other:?}"),
    }
    let negative = a.mapv(|v| if v == 7 { -3 } else { v });
    param_err(depth_panels(&[("n", &negative)], &opts), "depth");
    for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        param_err(
            depth_panels(&[("a", &a)], &DepthOptions::new(s, "m")),
            "units_per_bin",
        );
    }
    param_err(
        depth_panels(&[("a", &a)], &opts.clone().upscale(0)),
        "upscale",
    );
    param_err(
        depth_panels(&[("a", &a)], &opts.clone().upscale(usize::MAX)),
        "upscale",
    );
    param_err(
        depth_panels(&[("a", &a)], &opts.clone().range(9, 3)),
        "range",
    );
    // Too many panels side by side for one image.
    let many: Vec<(&str, &Array2<i32>)> = (0..100).map(|_| ("a", &a)).collect();
    param_err(depth_panels(&many, &opts), "width");
}

// ---------------------------------------------------------------------------------------------
// Charts

fn three_series_chart() -> Chart {
    Chart::new("Error against run time")
        .x_label("run time (s)")
        .y_label("relative error ‖X − X̂‖/‖X‖")
        .log_x(true)
        .log_y(true)
        .series(Series::new("A", [(0.01, 0.5), (0.1, 0.2), (1.0, 0.1)]))
        .series(Series::new("B", [(0.03, 0.05), (0.3, 0.02)]))
        .series(Series::new("C", [(2.0, 0.001), (20.0, 0.0005)]))
}

#[test]
fn charts_have_the_size_asked_for_and_reject_bad_sizes() {
    let fig = scatter_plot(&three_series_chart()).unwrap();
    let img = Image::decode(&fig.encode_png());
    assert_eq!((img.width, img.height), (800, 520));
    assert_eq!((fig.width(), fig.height()), (800, 520));
    let fig = line_plot(&three_series_chart().size(1100, 620)).unwrap();
    let img = Image::decode(&fig.encode_png());
    assert_eq!((img.width, img.height), (1100, 620));
    // A white margin all round: no text runs off the image.
    let edge = img.count(|x, y, c| {
        (x < 3 || y < 3 || x + 3 >= img.width || y + 3 >= img.height) && c != Rgb::WHITE
    });
    assert_eq!(edge, 0);

    let chart = three_series_chart();
    param_err(line_plot(&chart.clone().size(0, 400)), "width");
    param_err(line_plot(&chart.clone().size(400, 0)), "height");
    param_err(line_plot(&chart.clone().size(100_000, 400)), "width");
    param_err(line_plot(&chart.clone().size(16_000, 16_000)), "height");
    param_err(line_plot(&chart.clone().size(80, 60)), "size");
}

#[test]
fn scatter_plot_draws_each_series_in_its_colour() {
    let chart = three_series_chart();
    let scatter = Image::decode(&scatter_plot(&chart).unwrap().encode_png());
    let lines = Image::decode(&line_plot(&chart).unwrap().encode_png());
    let points = [3, 2, 2];
    for (i, n) in points.into_iter().enumerate() {
        // Each marker (and its legend sample) fills a disc, square or triangle about 10
        // pixels across.
        let dots = scatter.count_of(PALETTE[i]);
        assert!(dots >= 40 * (n + 1), "series {i}: {dots} pixels");
        assert!(dots <= 150 * (n + 1), "series {i}: {dots} pixels");
        // Lines join them in the line plot.
        let joined = lines.count_of(PALETTE[i]);
        assert!(joined > dots + 100, "series {i}: {joined} vs {dots}");
    }
    // No fourth series, no fourth colour.
    assert_eq!(scatter.count_of(PALETTE[3]), 0);
    assert_eq!(lines.count_of(PALETTE[3]), 0);
    assert_eq!(series_colour(3), PALETTE[3]);
    assert_eq!(series_colour(PALETTE.len()), PALETTE[0]);

    // A series' own colour and style win over the plot's.
    let own = Rgb::hex(0x123456);
    let styled = chart.clone().series(
        Series::new("D", [(0.05, 0.01), (5.0, 0.01)])
            .colour(own)
            .style(SeriesStyle::Lines),
    );
    let img = Image::decode(&scatter_plot(&styled).unwrap().encode_png());
    assert!(img.count_of(own) > 300, "a line across the plot");
}

#[test]
fn markers_differ_in_shape() {
    // The pixels of the series' colour, for each marker at the same two points.
    let masks: Vec<Vec<bool>> = Marker::ALL
        .iter()
        .map(|&m| {
            let chart = Chart::new("")
                .legend(LegendPosition::Hidden)
                .series(Series::new("m", [(0.0, 0.0), (1.0, 1.0)]).marker(m));
            let img = Image::decode(&scatter_plot(&chart).unwrap().encode_png());
            img.rgb.chunks(3).map(|p| p == [0x00, 0x72, 0xb2]).collect()
        })
        .collect();
    for (i, a) in masks.iter().enumerate() {
        let n = a.iter().filter(|&&b| b).count();
        assert!((2 * 40..2 * 150).contains(&n), "{:?}: {n}", Marker::ALL[i]);
        for (j, b) in masks.iter().enumerate().skip(i + 1) {
            assert_ne!(a, b, "{:?} and {:?}", Marker::ALL[i], Marker::ALL[j]);
        }
    }
    assert_eq!(PALETTE[0], Rgb::hex(0x0072b2));
    assert_eq!(Marker::nth(Marker::ALL.len() + 1), Marker::ALL[1]);
}

#[test]
fn line_plot_draws_dashed_reference_lines_and_a_legend_where_asked() {
    let chart = Chart::new("Phase transition")
        .x_label("pulse length Kₚ")
        .y_label("error")
        .series(Series::new(
            "flat",
            [(0.0, 0.5), (100.0, 0.5), (200.0, 0.5)],
        ))
        .series(Series::new("falling", [(0.0, 1.0), (200.0, 0.0)]).style(SeriesStyle::Lines))
        .vline(150.0, "critical Kₚ")
        .hline(0.8, "")
        .legend(LegendPosition::BottomLeft);
    let fig = line_plot(&chart).unwrap();
    assert_eq!(fig.x_ticks(), [0.0, 50.0, 100.0, 150.0, 200.0]);
    let img = Image::decode(&fig.encode_png());
    let grey = Rgb::hex(0x595959);
    // The vertical line is dashed: down the column with the most of its grey, runs of the grey
    // alternate with gaps.
    let col = (0..img.width)
        .max_by_key(|&x| (0..img.height).filter(|&y| img.at(x, y) == grey).count())
        .unwrap();
    let run: Vec<bool> = (0..img.height).map(|y| img.at(col, y) == grey).collect();
    let dashes = run.windows(2).filter(|w| !w[0] && w[1]).count();
    assert!(dashes >= 15, "{dashes} dashes");
    // The horizontal line too, along a row.
    let row = (0..img.height)
        .max_by_key(|&y| (0..img.width).filter(|&x| img.at(x, y) == grey).count())
        .unwrap();
    let run: Vec<bool> = (0..img.width).map(|x| img.at(x, row) == grey).collect();
    let dashes = run.windows(2).filter(|w| !w[0] && w[1]).count();
    assert!(dashes >= 20, "{dashes} dashes");
    // The legend sits in the bottom left corner: that is where the image differs from the
    // same chart without one.
    let hidden = line_plot(&chart.clone().legend(LegendPosition::Hidden)).unwrap();
    let img_hidden = Image::decode(&hidden.encode_png());
    let changed = |a: &Image, b: &Image| -> Vec<(usize, usize)> {
        (0..a.height)
            .flat_map(|y| (0..a.width).map(move |x| (x, y)))
            .filter(|&(x, y)| a.at(x, y) != b.at(x, y))
            .collect()
    };
    let diff = changed(&img, &img_hidden);
    assert!(diff.len() > 500, "{}", diff.len());
    assert!(
        diff.iter()
            .all(|&(x, y)| x < img.width / 3 && y > img.height / 2),
        "{diff:?}"
    );
    let top_right = line_plot(&chart.clone().legend(LegendPosition::TopRight)).unwrap();
    let diff = changed(&Image::decode(&top_right.encode_png()), &img_hidden);
    assert!(diff
        .iter()
        .all(|&(x, y)| x > img.width / 2 && y < img.height / 2));

    // Hidden, the legend's samples are gone.
    assert!(img_hidden.count_of(PALETTE[0]) + 40 < img.count_of(PALETTE[0]));
    // Beside the plot, the legend makes the plot narrower: its grid lines move.
    let outside = line_plot(&chart.clone().legend(LegendPosition::Outside)).unwrap();
    let img_outside = Image::decode(&outside.encode_png());
    let grid_cols = |img: &Image| -> Vec<usize> {
        (0..img.width)
            .filter(|&x| img.at(x, img.height / 2 + 3) == Rgb::hex(0xe3e3e3))
            .collect()
    };
    assert_ne!(grid_cols(&img), grid_cols(&img_outside));
    assert!(grid_cols(&img_outside).last() < grid_cols(&img).last());
}

#[test]
fn charts_reject_bad_input() {
    let ok = Series::new("s", [(1.0, 1.0), (2.0, 3.0)]);
    param_err(scatter_plot(&Chart::new("empty")), "series");
    param_err(
        scatter_plot(&Chart::new("no points").series(Series::new("s", []))),
        "series",
    );
    for bad in [(f64::NAN, 1.0), (1.0, f64::INFINITY)] {
        let r = line_plot(&Chart::new("nan").series(Series::new("s", [(0.5, 1.0), bad])));
        assert!(matches!(r, Err(Error::NonFinite { .. })), "{r:?}");
    }
    // Logarithmic axes take positive values only.
    let zero_x = Chart::new("log")
        .log_x(true)
        .series(Series::new("s", [(0.0, 1.0)]));
    param_err(scatter_plot(&zero_x), "log_x");
    let neg_y = Chart::new("log")
        .log_y(true)
        .series(Series::new("s", [(1.0, -1e-3)]));
    param_err(line_plot(&neg_y), "log_y");
    let line_at_zero = Chart::new("log")
        .log_x(true)
        .series(ok.clone())
        .vline(0.0, "K");
    param_err(line_plot(&line_at_zero), "log_x");
    let hline_below = Chart::new("log")
        .log_y(true)
        .series(ok.clone())
        .hline(-2.0, "h");
    param_err(line_plot(&hline_below), "log_y");
    let nan_line = Chart::new("nan").series(ok.clone()).hline(f64::NAN, "h");
    assert!(matches!(line_plot(&nan_line), Err(Error::NonFinite { .. })));
    param_err(
        line_plot(&Chart::new("r").series(ok.clone()).x_range(3.0, 3.0)),
        "x_range",
    );
    param_err(
        line_plot(&Chart::new("r").series(ok.clone()).y_range(3.0, 1.0)),
        "y_range",
    );
    param_err(
        line_plot(
            &Chart::new("r")
                .log_y(true)
                .series(ok.clone())
                .y_range(0.0, 1.0),
        ),
        "y_range",
    );
    let inf_range = Chart::new("r")
        .series(ok.clone())
        .x_range(0.0, f64::INFINITY);
    assert!(matches!(
        line_plot(&inf_range),
        Err(Error::NonFinite { .. })
    ));
    // Values at the ends of the floating-point range cannot be given an axis.
    let huge = Chart::new("huge").series(Series::new("s", [(0.0, -f64::MAX), (1.0, f64::MAX)]));
    param_err(line_plot(&huge), "range");
    let extreme = Chart::new("log")
        .log_y(true)
        .series(Series::new("s", [(0.0, 1e-320), (1.0, 1e308)]));
    param_err(line_plot(&extreme), "range");
}

#[test]
fn explicit_ranges_clip_what_lies_outside() {
    let (inside, across, outside) = (Rgb::hex(0x112233), Rgb::hex(0x445566), Rgb::hex(0x778899));
    let chart = Chart::new("")
        .series(Series::new("", [(1.0, 0.0), (4.0, 0.5)]).colour(inside))
        .series(Series::new("", [(-5.0, -0.5), (10.0, -0.5)]).colour(across))
        .series(Series::new("", [(6.0, 5.0), (10.0, 10.0)]).colour(outside))
        .x_range(0.0, 5.0)
        .y_range(-1.0, 1.0);
    let fig = line_plot(&chart).unwrap();
    assert_eq!(fig.x_range(), (0.0, 5.0));
    assert_eq!(fig.y_range(), (-1.0, 1.0));
    let img = Image::decode(&fig.encode_png());
    assert!(img.count_of(inside) > 200);
    // The line across the range is cut at the frame: it spans the plot area only.
    let xs: Vec<usize> = (0..img.width)
        .filter(|&x| (0..img.height).any(|y| img.at(x, y) == across))
        .collect();
    assert!(xs.len() > 500, "{}", xs.len());
    let first = *xs.first().unwrap();
    assert!(
        first > 40,
        "the line starts at the frame, not at the image's edge: {first}"
    );
    // Entirely outside: not drawn at all (nor squeezed onto the frame).
    assert_eq!(img.count_of(outside), 0);
    // Without the ranges, it is.
    let mut all = chart.clone();
    all = all.x_range(-5.0, 10.0).y_range(-1.0, 10.0);
    let img = Image::decode(&line_plot(&all).unwrap().encode_png());
    assert!(img.count_of(outside) > 100);
}

#[test]
fn fitted_axes_hold_the_data_and_single_values_widen() {
    let fig = scatter_plot(&three_series_chart()).unwrap();
    let (x0, x1) = fig.x_range();
    assert!(x0 < 0.01 && x1 > 20.0);
    assert_eq!(fig.x_ticks(), [0.01, 0.1, 1.0, 10.0]);
    for log in [false, true] {
        let single = Chart::new("one")
            .log_x(log)
            .log_y(log)
            .series(Series::new("p", [(3.0, 3.0)]));
        let fig = scatter_plot(&single).unwrap();
        let (x0, x1) = fig.x_range();
        assert!(x0 < 3.0 && x1 > 3.0);
        assert!(fig.x_ticks().len() >= 2, "{:?}", fig.x_ticks());
        assert!(fig.y_ticks().len() >= 2, "{:?}", fig.y_ticks());
    }
    // Linear ticks are round numbers covering the data.
    let lin =
        scatter_plot(&Chart::new("").series(Series::new("s", [(0.13, 2.0), (0.91, 7.0)]))).unwrap();
    let t = lin.x_ticks();
    assert!(t.len() >= 3 && t[0] >= lin.x_range().0 && *t.last().unwrap() <= lin.x_range().1);
    let step = t[1] - t[0];
    assert!(t.windows(2).all(|w| (w[1] - w[0] - step).abs() < 1e-9));
    let mantissa = step / 10f64.powf(step.log10().floor());
    assert!(
        [1.0, 2.0, 2.5, 5.0]
            .iter()
            .any(|m| (mantissa - m).abs() < 1e-9),
        "{step}"
    );
}

#[test]
fn log_axes_are_labelled_by_powers_of_ten() {
    let is_power = |v: f64| (v.log10() - v.log10().round()).abs() < 1e-12;
    let pts = Series::new("s", [(1.0, 2.0), (2.0, 8.0)]);
    let fitted = scatter_plot(&Chart::new("").log_y(true).series(pts.clone())).unwrap();
    assert_eq!(
        fitted.y_ticks(),
        [1.0, 10.0],
        "widened to the enclosing decades"
    );
    // An explicit range within a decade: 1, 2 and 5 times powers of ten.
    let narrow = Chart::new("")
        .log_y(true)
        .y_range(2.0, 8.0)
        .series(pts.clone());
    assert_eq!(scatter_plot(&narrow).unwrap().y_ticks(), [2.0, 5.0]);
    // A short axis over three decades still labels two of them.
    let short = Chart::new("")
        .log_y(true)
        .size(400, 300)
        .series(Series::new("s", [(1.0, 0.1), (2.0, 10.0)]));
    let t = scatter_plot(&short).unwrap().y_ticks();
    assert!(t.len() >= 2 && t.iter().all(|&v| is_power(v)), "{t:?}");
    // Many decades: every few labelled, evenly.
    let wide = Chart::new("")
        .log_x(true)
        .log_y(true)
        .series(Series::new("s", [(1e-12, 1e-14), (1.0, 1.0)]));
    let fig = scatter_plot(&wide).unwrap();
    for t in [fig.x_ticks(), fig.y_ticks()] {
        let k: Vec<i32> = t.iter().map(|v| v.log10().round() as i32).collect();
        assert!(t.iter().all(|&v| is_power(v)), "{t:?}");
        assert!(k.len() >= 3 && k.len() <= 10, "{k:?}");
        assert!(k.windows(3).all(|w| w[2] - w[1] == w[1] - w[0]), "{k:?}");
    }
}

#[test]
fn unicode_labels_are_drawn() {
    let ink = |y_label: &str| {
        let chart = three_series_chart().y_label(y_label);
        Image::decode(&scatter_plot(&chart).unwrap().encode_png()).ink()
    };
    let plain = ink("X");
    // The circumflex over X is drawn, and takes no room of its own.
    let hat = ink("X\u{302}");
    assert!(hat > plain + 5, "{hat} vs {plain}");
    // Subscripts, double bars, minus signs and Greek letters have glyphs of their own (the
    // label keeps its place, so only its ink changes).
    let base = ink("a");
    let mut seen = vec![base];
    for text in ["K", "Kₚ", "‖X‖", "|X|", "τ", "−"] {
        let n = ink(&format!("a{text}"));
        assert!(n > base, "{text}: {n}");
        assert!(!seen.contains(&n), "{text}: {n} as another label");
        seen.push(n);
    }
}

#[test]
fn random_inputs_give_a_figure_or_an_error_never_a_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let value = |rng: &mut ChaCha8Rng| -> f64 {
        match rng.random_range(0..10) {
            0 => 0.0,
            1 => -rng.random::<f64>(),
            2 => 10f64.powi(rng.random_range(-300..300)),
            3 => [f64::MAX, f64::MIN_POSITIVE, 5e-324, -f64::MAX][rng.random_range(0..4)],
            4 => 1.0,
            _ => rng.random::<f64>() * 10f64.powi(rng.random_range(-5..6)),
        }
    };
    let (mut ok, mut err) = (0, 0);
    for _ in 0..150 {
        let mut chart = Chart::new("t")
            .x_label("x")
            .y_label("y")
            .log_x(rng.random::<f64>() < 0.3)
            .log_y(rng.random::<f64>() < 0.3)
            .size(rng.random_range(1..900), rng.random_range(1..700));
        for s in 0..rng.random_range(0..4) {
            let n = rng.random_range(0..6);
            let pts: Vec<(f64, f64)> = (0..n).map(|_| (value(&mut rng), value(&mut rng))).collect();
            chart = chart.series(Series::new(format!("s{s}"), pts));
        }
        if rng.random::<f64>() < 0.3 {
            chart = chart.vline(value(&mut rng), "v");
        }
        if rng.random::<f64>() < 0.2 {
            chart = chart.y_range(value(&mut rng), value(&mut rng));
        }
        for r in [scatter_plot(&chart), line_plot(&chart)] {
            match r {
                Ok(fig) => {
                    assert_eq!(Image::decode(&fig.encode_png()).width, fig.width());
                    ok += 1;
                }
                Err(_) => err += 1,
            }
        }
    }
    assert!(ok > 30 && err > 30, "{ok} figures, {err} errors");

    for _ in 0..40 {
        let (m, n) = (rng.random_range(0..40), rng.random_range(0..40));
        let map = Array2::from_shape_fn((m, n), |_| rng.random_range(-2..60));
        let other = Array2::from_shape_fn((m, n), |_| rng.random_range(-1..3));
        let opts =
            DepthOptions::new(rng.random::<f64>() * 2.0, "m").upscale(rng.random_range(0..5));
        if let Ok(fig) = depth_panels(&[("a", &map), ("b", &other)], &opts) {
            assert_eq!(Image::decode(&fig.encode_png()).height, fig.height());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Files

#[test]
fn figures_are_saved_atomically() {
    let dir = TempDir::new("save");
    let path = dir.0.join("fig.png");
    std::fs::write(&path, b"old contents").unwrap();
    let fig = scatter_plot(&three_series_chart()).unwrap();
    fig.save_png(&path).unwrap();
    assert_eq!(dir.listing(), vec!["fig.png"], "no temporary file is left");
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes, fig.encode_png());
    assert_eq!(Image::decode(&bytes).width, 800);

    let maps = depth_panels(&[("a", &ramp_map())], &DepthOptions::default()).unwrap();
    let depth_path = dir.0.join("depth.png");
    maps.save_png(&depth_path).unwrap();
    let saved = Image::decode(&std::fs::read(&depth_path).unwrap());
    assert_eq!((saved.width, saved.height), (maps.width(), maps.height()));

    // A missing directory or a directory in the way is an error naming the path, and leaves
    // nothing behind.
    let missing = dir.0.join("missing").join("fig.png");
    match fig.save_png(&missing) {
        Err(Error::File { path, .. }) => assert!(path.ends_with("fig.png")),
        other => panic!("expected a file error, got {other:?}"),
    }
    std::fs::create_dir(dir.0.join("sub")).unwrap();
    assert!(matches!(
        fig.save_png(dir.0.join("sub")),
        Err(Error::File { .. })
    ));
    assert_eq!(dir.listing(), vec!["depth.png", "fig.png", "sub"]);
    assert!(std::fs::read_dir(dir.0.join("sub"))
        .unwrap()
        .next()
        .is_none());
    // The earlier file is untouched by the failed writes.
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
}
