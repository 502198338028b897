//! Figures: PNG output, pixel colours at known places, text boxes, ticks and input checks.

use std::io::Cursor;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::plot::{
    depth_panels, line_plot, linear_ticks, log_ticks, scatter_plot, text_size, Align, Canvas,
    Chart, ColourMap, DepthOptions, LegendPosition, Marker, Rect, Rgb, Series, SeriesStyle,
    TextStyle, NO_RETURN_COLOUR, PALETTE,
};
use rdlidar::Error;

/// Decodes a PNG into (width, height, RGB bytes).
fn decode(png_bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(Cursor::new(png_bytes.to_vec()));
    let mut reader = decoder.read_info().expect("a readable PNG");
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut buf).expect("image data");
    assert_eq!(frame.color_type, png::ColorType::Rgb);
    assert_eq!(frame.bit_depth, png::BitDepth::Eight);
    buf.truncate(frame.buffer_size());
    (frame.width, frame.height, buf)
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
fn depth_panels_colour_pixels_by_bin_with_a_distinct_no_return_colour() {
    let a = ramp_map();
    let b = a.mapv(|v| if v == 10 { -1 } else { v });
    let fig = depth_panels(
        &[("truth", &a), ("estimate", &b)],
        &DepthOptions::new(0.5, "m"),
    )
    .unwrap();
    let k = fig.upscale() as i64;
    assert_eq!(k, 9, "30 columns scaled to about 275 pixels");
    let c = fig.canvas();
    let (w, h, raw) = decode(&fig.encode_png());
    assert_eq!((w as usize, h as usize), (c.width(), c.height()));
    assert_eq!(raw, c.as_raw());

    let viridis = ColourMap::viridis();
    for (p, area) in fig.panel_areas().iter().enumerate() {
        assert_eq!((area.width, area.height), (30 * k, 20 * k));
        // Every screen pixel of map pixel (i, j), corners included.
        let at = |i: i64, j: i64| {
            let (x, y) = (area.x + j * k, area.y + i * k);
            let colours = [
                c.pixel(x, y),
                c.pixel(x + k - 1, y),
                c.pixel(x, y + k - 1),
                c.pixel(x + k - 1, y + k - 1),
            ];
            assert!(
                colours.iter().all(|q| *q == colours[0]),
                "pixel ({i}, {j}) is one colour"
            );
            colours[0].unwrap()
        };
        assert_eq!(at(0, 0), NO_RETURN_COLOUR, "panel {p}");
        assert_eq!(
            at(4, 0),
            viridis.at(0.0),
            "the nearest bin takes the map's first colour"
        );
        assert_eq!(
            at(19, 29),
            viridis.at(1.0),
            "the farthest bin takes its last colour"
        );
        assert_eq!(at(10, 15), fig.colour_of(20));
        assert_eq!(
            at(10, 5),
            if p == 0 {
                fig.colour_of(10)
            } else {
                NO_RETURN_COLOUR
            }
        );
    }
    assert_eq!(fig.bin_range(), (5.0, 34.0));

    // The colour bar runs from the far colour at the top to the near one at the bottom.
    let bar = fig.colour_bar();
    assert!(bar.height >= 100);
    for x in bar.x..bar.right() {
        assert_eq!(c.pixel(x, bar.y), Some(viridis.at(1.0)));
        assert_eq!(c.pixel(x, bar.bottom() - 1), Some(viridis.at(0.0)));
    }
    let luma = |y| c.pixel(bar.x + bar.width / 2, y).unwrap().luma();
    assert!(
        (bar.y..bar.bottom() - 1).all(|y| luma(y) >= luma(y + 1)),
        "bright far, dark near"
    );
    let key = fig.no_return_key();
    assert_eq!(
        c.pixel(key.x + key.width / 2, key.y + key.height / 2),
        Some(NO_RETURN_COLOUR)
    );
    assert!(key.y > bar.bottom(), "the key sits under the colour bar");
    // Labels (ticks, "depth (m)", "no return") are drawn to the right of the bar.
    let ink_right_of_bar = (bar.y..key.bottom())
        .flat_map(|y| (bar.right() + 2..c.width() as i64).map(move |x| (x, y)))
        .filter(|&(x, y)| c.pixel(x, y).unwrap().luma() < 0.5)
        .count();
    assert!(ink_right_of_bar > 200);
}

#[test]
fn depth_panel_options_set_scale_range_and_title() {
    let a = ramp_map();
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
    let area = fig.panel_areas()[0];
    assert_eq!((area.width, area.height), (60, 40));
    let viridis = ColourMap::viridis();
    assert_eq!(fig.colour_of(50), viridis.at(0.5));
    assert_eq!(
        fig.canvas().pixel(area.x, area.y + 4 * 2),
        Some(viridis.at(0.05))
    );

    // A 100 x 100 map is drawn about 300 pixels wide.
    let big = Array2::from_elem((100, 100), 3);
    let fig = depth_panels(&[("flat", &big)], &DepthOptions::new(0.15, "m")).unwrap();
    assert_eq!(fig.upscale(), 3);
    // One depth only: the bar spans half a bin either way and the map takes its middle colour.
    assert_eq!(fig.bin_range(), (2.5, 3.5));
    let area = fig.panel_areas()[0];
    assert_eq!(
        fig.canvas().pixel(area.x + 150, area.y + 150),
        Some(viridis.at(0.5))
    );

    // No returns at all is a valid (if empty) figure.
    let none = Array2::from_elem((10, 10), -1);
    let fig = depth_panels(&[("nothing", &none)], &DepthOptions::default()).unwrap();
    let area = fig.panel_areas()[0];
    assert_eq!(fig.canvas().pixel(area.x, area.y), Some(NO_RETURN_COLOUR));
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
    let negative = a.mapv(|v| if v == 7 { -2 } else { v });
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
}

// ---------------------------------------------------------------------------------------------
// Canvas, text and colours

#[test]
fn canvas_size_is_checked_and_png_round_trips() {
    param_err(Canvas::new(0, 10, Rgb::WHITE), "width");
    param_err(Canvas::new(10, 0, Rgb::WHITE), "height");
    param_err(Canvas::new(100_000, 10, Rgb::WHITE), "width");
    param_err(Canvas::new(16_000, 16_000, Rgb::WHITE), "height");

    let mut c = Canvas::new(7, 5, Rgb(1, 2, 3)).unwrap();
    c.fill_rect(Rect::new(5, 3, 10, 10), Rgb(200, 100, 50));
    let (w, h, raw) = decode(&c.encode_png());
    assert_eq!((w, h), (7, 5));
    assert_eq!(&raw[..3], &[1, 2, 3]);
    assert_eq!(&raw[(3 * 7 + 5) * 3..(3 * 7 + 6) * 3], &[200, 100, 50]);
    assert_eq!(c.pixel(7, 0), None);
}

/// The bounding box of the pixels that differ from `background`.
fn ink_box(c: &Canvas, background: Rgb) -> Option<Rect> {
    let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
    for y in 0..c.height() as i64 {
        for x in 0..c.width() as i64 {
            if c.pixel(x, y) != Some(background) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
        }
    }
    (x0 <= x1).then(|| Rect::new(x0, y0, x1 - x0 + 1, y1 - y0 + 1))
}

fn inside(inner: Rect, outer: Rect) -> bool {
    inner.x >= outer.x
        && inner.y >= outer.y
        && inner.right() <= outer.right()
        && inner.bottom() <= outer.bottom()
}

#[test]
fn text_ink_stays_inside_its_box() {
    let texts = [
        "Hg",
        "relative error",
        "K_p = 4000",
        "{|}~ @#$",
        "0.25",
        "i",
        "gjpqy",
    ];
    for text in texts {
        for style in [
            TextStyle::new(1, Rgb::BLACK),
            TextStyle::new(2, Rgb::BLACK),
            TextStyle::new(3, Rgb::BLACK).bold(),
        ] {
            let (w, h) = text_size(text, style);
            let mut c = Canvas::new(400, 400, Rgb::WHITE).unwrap();
            let r = c.text(20, 30, text, style);
            assert_eq!(r, Rect::new(20, 30, w, h));
            let ink = ink_box(&c, Rgb::WHITE).expect("some ink");
            assert!(
                inside(ink, r),
                "{text:?} at {style:?}: ink {ink:?} outside {r:?}"
            );
            // The text's ends reach the box's left and right edges.
            assert_eq!((ink.x, ink.right()), (r.x, r.right()), "{text:?}");
            if text.chars().any(|ch| "gjpqy".contains(ch)) {
                assert_eq!(
                    ink.bottom(),
                    r.bottom(),
                    "descenders reach the bottom of {text:?}"
                );
            }

            let mut c = Canvas::new(400, 400, Rgb::WHITE).unwrap();
            let r = c.text_vertical(50, 20, text, style);
            assert_eq!(r, Rect::new(50, 20, h, w));
            let ink = ink_box(&c, Rgb::WHITE).expect("some ink");
            assert!(
                inside(ink, r),
                "vertical {text:?}: ink {ink:?} outside {r:?}"
            );
            assert_eq!((ink.y, ink.bottom()), (r.y, r.bottom()));
        }
    }
    // Reading upwards: the first letter is at the bottom.
    let style = TextStyle::new(2, Rgb::BLACK);
    let mut c = Canvas::new(100, 200, Rgb::WHITE).unwrap();
    let r = c.text_vertical(10, 10, "L.", style);
    let bottom_rows =
        (r.bottom() - 10..r.bottom()).flat_map(|y| (r.x..r.right()).map(move |x| (x, y)));
    assert!(
        bottom_rows
            .filter(|&(x, y)| c.pixel(x, y) == Some(Rgb::BLACK))
            .count()
            > 10
    );

    let mut c = Canvas::new(200, 100, Rgb::WHITE).unwrap();
    let r = c.text_aligned(100, 50, "centred", style, Align::Centre, Align::Centre);
    assert!((r.x + r.width / 2 - 100).abs() <= 1 && (r.y + r.height / 2 - 50).abs() <= 1);
    // Characters outside ASCII fall back to '?', with the same width.
    assert_eq!(text_size("\u{3bb}", style), text_size("?", style));
    assert_eq!(text_size("", style).0, 0);
}

#[test]
fn markers_differ_in_shape_and_shapes_are_anti_aliased() {
    let masks: Vec<Vec<bool>> = Marker::ALL
        .iter()
        .map(|&m| {
            let mut c = Canvas::new(21, 21, Rgb::WHITE).unwrap();
            c.marker(10.5, 10.5, 6.0, m, Rgb::BLACK);
            assert_eq!(
                c.pixel(10, 10),
                Some(Rgb::BLACK),
                "{m:?} is inked at its centre"
            );
            c.as_raw().chunks(3).map(|p| p[0] < 128).collect()
        })
        .collect();
    for i in 0..masks.len() {
        for j in i + 1..masks.len() {
            let differ = masks[i]
                .iter()
                .zip(&masks[j])
                .filter(|(a, b)| a != b)
                .count();
            assert!(
                differ >= 12,
                "{:?} and {:?} differ in {differ} pixels",
                Marker::ALL[i],
                Marker::ALL[j]
            );
        }
    }
    let mut c = Canvas::new(40, 40, Rgb::WHITE).unwrap();
    c.line(2.0, 3.0, 37.0, 30.0, 2.0, Rgb::BLACK);
    let greys = c
        .as_raw()
        .chunks(3)
        .filter(|p| p[0] > 0 && p[0] < 255)
        .count();
    assert!(greys > 20, "edges are blended");
    c.circle(20.0, 20.0, 5.0, Rgb(255, 0, 0));
    assert_eq!(c.pixel(20, 20), Some(Rgb(255, 0, 0)));
    assert_eq!(c.pixel(20, 27), Some(Rgb::WHITE));

    // Dashes alternate along the line.
    let mut c = Canvas::new(60, 10, Rgb::WHITE).unwrap();
    c.dashed_hline(0, 59, 4, 1, 5, 3, Rgb::BLACK);
    let row: Vec<bool> = (0..60).map(|x| c.pixel(x, 4) == Some(Rgb::BLACK)).collect();
    assert_eq!(
        &row[..9],
        &[true, true, true, true, true, false, false, false, true]
    );
    let mut c = Canvas::new(10, 60, Rgb::WHITE).unwrap();
    c.dashed_vline(4, 0, 59, 2, 5, 3, Rgb::BLACK);
    assert_eq!(c.pixel(5, 4), Some(Rgb::BLACK));
    assert_eq!(c.pixel(5, 6), Some(Rgb::WHITE));
}

#[test]
fn colour_maps_are_ordered_and_the_palette_is_distinct() {
    let v = ColourMap::viridis();
    let l: Vec<f64> = (0..=100).map(|i| v.at(i as f64 / 100.0).luma()).collect();
    assert!(
        l.windows(2).all(|w| w[1] >= w[0] - 1e-9),
        "viridis brightens monotonically"
    );
    assert_eq!(v.at(-3.0), v.at(0.0));
    assert_eq!(v.at(7.0), v.at(1.0));
    let g = ColourMap::greys();
    assert!(g.at(0.0).luma() < 0.1 && g.at(1.0).luma() > 0.9);
    for (i, a) in PALETTE.iter().enumerate() {
        for b in &PALETTE[i + 1..] {
            let d = (a.0 as i32 - b.0 as i32).abs()
                + (a.1 as i32 - b.1 as i32).abs()
                + (a.2 as i32 - b.2 as i32).abs();
            assert!(d > 80, "{a:?} and {b:?} are too close");
        }
    }
    let map = ColourMap::new(vec![(0.0, Rgb::BLACK), (1.0, Rgb::WHITE)]).unwrap();
    assert_eq!(map.at(0.5), Rgb(128, 128, 128));
    param_err(ColourMap::new(vec![(0.0, Rgb::BLACK)]), "stops");
    param_err(
        ColourMap::new(vec![(0.0, Rgb::BLACK), (0.5, Rgb::WHITE)]),
        "stops",
    );
    param_err(
        ColourMap::new(vec![
            (0.0, Rgb::BLACK),
            (0.0, Rgb::WHITE),
            (1.0, Rgb::WHITE),
        ]),
        "stops",
    );
    param_err(
        ColourMap::new(vec![
            (0.0, Rgb::BLACK),
            (f64::NAN, Rgb::WHITE),
            (1.0, Rgb::WHITE),
        ]),
        "stops",
    );
}

// ---------------------------------------------------------------------------------------------
// Ticks

fn is_nice_step(step: f64) -> bool {
    let e = step.log10().floor();
    let m = step / 10f64.powf(e);
    [1.0, 2.0, 5.0, 10.0].iter().any(|n| (m - n).abs() < 1e-6)
}

#[test]
fn linear_ticks_are_one_two_five_steps_covering_the_range() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..2000 {
        let scale = 10f64.powi(rng.random_range(-8..9));
        let lo = (rng.random::<f64>() - 0.5) * 10.0 * scale;
        let hi = lo + rng.random::<f64>() * 7.0 * scale + 1e-3 * scale;
        let max = rng.random_range(2..12usize);
        let t = linear_ticks(lo, hi, max).unwrap();
        assert!(
            t.len() >= 2 && t.len() <= max + 1,
            "[{lo}, {hi}] / {max}: {t:?}"
        );
        assert!(
            t[0] <= lo && *t.last().unwrap() >= hi,
            "[{lo}, {hi}]: {t:?}"
        );
        let step = t[1] - t[0];
        assert!(is_nice_step(step), "step {step} of {t:?}");
        for w in t.windows(2) {
            assert!(((w[1] - w[0]) - step).abs() <= 1e-9 * step, "{t:?}");
        }
        // A multiple of the step, and not more than one step beyond each end.
        assert!((t[0] / step - (t[0] / step).round()).abs() < 1e-6);
        assert!(t[1] > lo && t[t.len() - 2] < hi, "[{lo}, {hi}]: {t:?}");
    }
    assert_eq!(
        linear_ticks(0.0, 10.0, 5).unwrap(),
        vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    );
    assert_eq!(
        linear_ticks(-0.3, 0.3, 6).unwrap(),
        vec![-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3]
    );
    assert_eq!(linear_ticks(5.0, 5.0, 4).unwrap(), vec![4.5, 5.0, 5.5]);
    param_err(linear_ticks(2.0, 1.0, 5), "range");
    param_err(linear_ticks(0.0, 1.0, 0), "max_intervals");
    param_err(linear_ticks(0.0, 1.0, 1), "max_intervals");
    assert!(matches!(
        linear_ticks(f64::NAN, 1.0, 5),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        linear_ticks(0.0, f64::INFINITY, 5),
        Err(Error::NonFinite { .. })
    ));
    param_err(linear_ticks(-f64::MAX, f64::MAX, 5), "range");
}

#[test]
fn log_ticks_are_the_decades_covering_the_range() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    for _ in 0..2000 {
        let lo = 10f64.powf(rng.random::<f64>() * 40.0 - 20.0);
        let hi = lo * 10f64.powf(rng.random::<f64>() * 8.0);
        let t = log_ticks(lo, hi).unwrap();
        assert!(
            t[0] <= lo && *t.last().unwrap() >= hi,
            "[{lo}, {hi}]: {t:?}"
        );
        for (i, v) in t.iter().enumerate() {
            let k = v.log10().round() as i32;
            assert_eq!(
                *v,
                format!("1e{k}").parse::<f64>().unwrap(),
                "a power of ten"
            );
            if i > 0 {
                assert_eq!(
                    k,
                    t[i - 1].log10().round() as i32 + 1,
                    "consecutive decades"
                );
            }
        }
        assert!(t.len() < 2 || (t[1] > lo && t[t.len() - 2] < hi));
    }
    assert_eq!(
        log_ticks(1.0, 1000.0).unwrap(),
        vec![1.0, 10.0, 100.0, 1000.0]
    );
    assert_eq!(log_ticks(0.002, 0.002).unwrap(), vec![0.001, 0.01]);
    assert_eq!(log_ticks(0.01, 0.01).unwrap(), vec![0.01]);
    param_err(log_ticks(0.0, 1.0), "range");
    param_err(log_ticks(-1.0, 1.0), "range");
    param_err(log_ticks(10.0, 1.0), "range");
    assert!(matches!(
        log_ticks(1.0, f64::NAN),
        Err(Error::NonFinite { .. })
    ));
    param_err(log_ticks(1.0, f64::MAX), "range");
    param_err(log_ticks(5e-324, 1.0), "range");
}

// ---------------------------------------------------------------------------------------------
// Charts

fn three_series_chart() -> Chart {
    Chart::new("Error against run time")
        .x_label("run time (s)")
        .y_label("relative error")
        .log_x(true)
        .log_y(true)
        .series(Series::new("A", [(0.01, 0.5), (0.1, 0.2), (1.0, 0.1)]))
        .series(Series::new("B", [(0.03, 0.05), (0.3, 0.02)]))
        .series(Series::new("C", [(2.0, 0.001), (20.0, 0.0005)]))
}

#[test]
fn scatter_plot_draws_each_series_in_its_colour_on_log_axes() {
    let fig = scatter_plot(&three_series_chart()).unwrap();
    let c = fig.canvas();
    let (w, h, raw) = decode(&fig.encode_png());
    assert_eq!((w, h), (800, 520));
    assert_eq!(raw, c.as_raw());

    let plot = fig.plot_area();
    assert!(plot.width > 500 && plot.height > 300);
    for (i, pts) in [
        vec![(0.01, 0.5), (0.1, 0.2), (1.0, 0.1)],
        vec![(0.03, 0.05), (0.3, 0.02)],
        vec![(2.0, 0.001), (20.0, 0.0005)],
    ]
    .iter()
    .enumerate()
    {
        for &(x, y) in pts {
            let (px, py) = fig.to_pixel(x, y).unwrap();
            assert!(plot.inflate(-1).contains(px as i64, py as i64));
            assert_eq!(
                c.pixel(px as i64, py as i64),
                Some(PALETTE[i]),
                "series {i} at ({x}, {y})"
            );
        }
    }
    // Decade ticks, labelled, covering the data; the shown range holds every point.
    let xt = fig.x_ticks();
    assert_eq!(xt, vec![0.01, 0.1, 1.0, 10.0]);
    let yt = fig.y_ticks();
    assert!(
        yt.iter()
            .all(|v| (v.log10() - v.log10().round()).abs() < 1e-12),
        "{yt:?}"
    );
    let (x0, x1) = fig.x_range();
    assert!(x0 < 0.01 && x1 > 20.0);
    // Log scale: equal ratios are equal distances.
    let d1 = fig.to_pixel(0.01, 1.0).unwrap().0 - fig.to_pixel(0.1, 1.0).unwrap().0;
    let d2 = fig.to_pixel(1.0, 1.0).unwrap().0 - fig.to_pixel(10.0, 1.0).unwrap().0;
    assert!((d1 - d2).abs() < 1e-9);
    assert_eq!(fig.to_pixel(-1.0, 1.0), None);
    // The legend sits inside the plot, clear of every point.
    let legend = fig.legend_area().unwrap();
    assert!(inside(legend, plot));
    for s in [
        (0.01, 0.5),
        (0.1, 0.2),
        (1.0, 0.1),
        (0.03, 0.05),
        (0.3, 0.02),
        (2.0, 0.001),
        (20.0, 0.0005),
    ] {
        let (px, py) = fig.to_pixel(s.0, s.1).unwrap();
        assert!(!legend.contains(px as i64, py as i64));
    }
}

#[test]
fn line_plot_joins_points_and_marks_reference_lines() {
    let chart = Chart::new("Phase transition")
        .x_label("pulse length K_p")
        .y_label("error")
        .series(Series::new(
            "flat",
            [(0.0, 0.5), (100.0, 0.5), (200.0, 0.5)],
        ))
        .series(Series::new("falling", [(0.0, 1.0), (200.0, 0.0)]).style(SeriesStyle::Lines))
        .vline(150.0, "critical K_p")
        .legend(LegendPosition::BottomLeft);
    let fig = line_plot(&chart).unwrap();
    let c = fig.canvas();
    // Between two markers of the horizontal series the line has the series' colour.
    let (px, py) = fig.to_pixel(50.0, 0.5).unwrap();
    assert_eq!(c.pixel(px as i64, py as i64), Some(PALETTE[0]));
    let (px, py) = fig.to_pixel(25.0, 0.875).unwrap();
    assert_eq!(c.pixel(px as i64, py as i64), Some(PALETTE[1]));
    // The same chart as a scatter plot leaves the gap empty (series style still applies).
    let scatter = scatter_plot(&chart).unwrap();
    let (px, py) = scatter.to_pixel(50.0, 0.5).unwrap();
    assert_ne!(
        scatter.canvas().pixel(px as i64, py as i64),
        Some(PALETTE[0])
    );
    let (px, py) = scatter.to_pixel(25.0, 0.875).unwrap();
    assert_eq!(
        scatter.canvas().pixel(px as i64, py as i64),
        Some(PALETTE[1])
    );

    // The vertical line is dashed: along its column, runs of one grey alternate with gaps.
    let plot = fig.plot_area();
    let col = fig.to_pixel(150.0, 0.0).unwrap().0 as i64;
    // Rows between y = 0.55 and 0.95, where no series crosses the line.
    let (top, bottom) = (
        fig.to_pixel(150.0, 0.95).unwrap().1 as i64,
        fig.to_pixel(150.0, 0.55).unwrap().1 as i64,
    );
    assert!(top > plot.y && bottom - top > 100);
    let column: Vec<Rgb> = (top..bottom).map(|y| c.pixel(col, y).unwrap()).collect();
    let dash = column
        .iter()
        .copied()
        .filter(|p| p.luma() < 0.5)
        .collect::<Vec<_>>();
    assert!(!dash.is_empty() && dash.iter().all(|p| *p == dash[0]));
    let switches = column
        .windows(2)
        .filter(|w| (w[0] == dash[0]) != (w[1] == dash[0]))
        .count();
    assert!(switches >= 10, "{switches} dash edges");

    // Linear ticks follow the 1-2-5 rule and the legend went where it was asked.
    let xt = fig.x_ticks();
    assert!(is_nice_step(xt[1] - xt[0]), "{xt:?}");
    let legend = fig.legend_area().unwrap();
    assert!(legend.x - plot.x < 20 && plot.bottom() - legend.bottom() < 20);
    let hidden = line_plot(&chart.clone().legend(LegendPosition::Hidden)).unwrap();
    assert_eq!(hidden.legend_area(), None);
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
    param_err(
        line_plot(&Chart::new("zero").series(ok.clone()).size(0, 400)),
        "width",
    );
    param_err(
        line_plot(&Chart::new("zero").series(ok.clone()).size(400, 0)),
        "height",
    );
    param_err(
        line_plot(&Chart::new("tiny").series(ok.clone()).size(80, 60)),
        "size",
    );
    // Values at the ends of the floating-point range cannot be given an axis.
    let huge = Chart::new("huge").series(Series::new("s", [(0.0, -f64::MAX), (1.0, f64::MAX)]));
    param_err(line_plot(&huge), "range");
    let extreme = Chart::new("log")
        .log_y(true)
        .series(Series::new("s", [(0.0, 1e-320), (1.0, 1e308)]));
    param_err(line_plot(&extreme), "range");
}

#[test]
fn explicit_ranges_clip_and_degenerate_data_still_plot() {
    let chart = Chart::new("")
        .series(Series::new("", [(0.0, 0.0), (10.0, 10.0)]))
        .x_range(0.0, 5.0)
        .y_range(-1.0, 1.0);
    let fig = line_plot(&chart).unwrap();
    assert_eq!(fig.x_range(), (0.0, 5.0));
    assert_eq!(
        fig.legend_area(),
        None,
        "unnamed series have no legend entry"
    );
    let plot = fig.plot_area();
    // Nothing is drawn outside the frame's right edge although the line runs on.
    let (_, py) = fig.to_pixel(5.0, 1.0).unwrap();
    for x in plot.right()..plot.right() + 5 {
        assert_eq!(fig.canvas().pixel(x, py as i64 + 20), Some(Rgb::WHITE));
    }
    // One point, one value: axes widen around it.
    for log in [false, true] {
        let single = Chart::new("one")
            .log_x(log)
            .log_y(log)
            .series(Series::new("p", [(3.0, 3.0)]));
        let fig = scatter_plot(&single).unwrap();
        let (x0, x1) = fig.x_range();
        assert!(x0 < 3.0 && x1 > 3.0);
        assert!(fig.x_ticks().len() >= 2, "{:?}", fig.x_ticks());
    }
}

#[test]
fn log_axes_label_decades_or_one_two_five_within_a_decade() {
    let pts = Series::new("s", [(1.0, 2.0), (2.0, 8.0)]);
    let fitted = scatter_plot(&Chart::new("").log_y(true).series(pts.clone())).unwrap();
    assert_eq!(
        fitted.y_ticks(),
        vec![1.0, 10.0],
        "widened to the enclosing decades"
    );
    let narrow = Chart::new("")
        .log_y(true)
        .y_range(2.0, 8.0)
        .series(pts.clone());
    assert_eq!(scatter_plot(&narrow).unwrap().y_ticks(), vec![2.0, 5.0]);
    // A short axis over three decades still labels two of them.
    let short = Chart::new("")
        .log_y(true)
        .size(400, 240)
        .series(Series::new("s", [(1.0, 0.1), (2.0, 10.0)]));
    let t = scatter_plot(&short).unwrap().y_ticks();
    assert!(t.len() >= 2, "{t:?}");
    // Many decades: labelled every few, evenly.
    let wide = Chart::new("")
        .log_y(true)
        .series(Series::new("s", [(1.0, 1e-14), (2.0, 1.0)]));
    let t = scatter_plot(&wide).unwrap().y_ticks();
    let k: Vec<i32> = t.iter().map(|v| v.log10().round() as i32).collect();
    assert!(k.len() >= 3 && k.len() <= 10, "{k:?}");
    assert!(k.windows(3).all(|w| w[2] - w[1] == w[1] - w[0]), "{k:?}");
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
    for _ in 0..300 {
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
                    assert_eq!(decode(&fig.encode_png()).0 as usize, fig.canvas().width());
                    ok += 1;
                }
                Err(_) => err += 1,
            }
        }
    }
    assert!(ok > 50 && err > 50, "{ok} figures, {err} errors");

    for _ in 0..60 {
        let (m, n) = (rng.random_range(0..40), rng.random_range(0..40));
        let map = Array2::from_shape_fn((m, n), |_| rng.random_range(-2..60));
        let other = Array2::from_shape_fn((m, n), |_| rng.random_range(-1..3));
        let opts =
            DepthOptions::new(rng.random::<f64>() * 2.0, "m").upscale(rng.random_range(0..5));
        if let Ok(fig) = depth_panels(&[("a", &map), ("b", &other)], &opts) {
            assert_eq!(fig.panel_areas().len(), 2);
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
    assert_eq!(decode(&bytes).0, 800);

    let maps = depth_panels(&[("a", &ramp_map())], &DepthOptions::default()).unwrap();
    let depth_path = dir.0.join("depth.png");
    maps.save_png(&depth_path).unwrap();
    assert_eq!(
        decode(&std::fs::read(&depth_path).unwrap()).0 as usize,
        maps.canvas().width()
    );

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
