//! Scene generators: the paper scene, random opaque and semi-transparent scenes, PNG input and
//! inverse-square attenuation.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use ndarray::Array2;
use rdlidar::io::scene_from_pngs;
use rdlidar::lidar::{
    attenuate, composite_nearest, paper_scene, paper_surfaces, random_opaque_scene,
    semi_transparent_scene, DepthMap, Geometry, Scene, NO_RETURN,
};
use rdlidar::{Error, Real};

use crate::common::random_vec;

fn geom(m: usize, n: usize, ks: usize) -> Geometry {
    Geometry::new(m, n, ks).unwrap()
}

/// The nonzero voxels of each pixel as (bin, value) pairs, in depth order.
fn returns<T: Real>(s: &Scene<T>) -> Vec<Vec<(usize, f64)>> {
    s.data()
        .lanes(ndarray::Axis(2))
        .into_iter()
        .map(|col| {
            col.iter()
                .enumerate()
                .filter(|(_, v)| **v != T::zero())
                .map(|(j, v)| (j, v.as_f64()))
                .collect()
        })
        .collect()
}

fn lit_pixels<T: Real>(s: &Scene<T>) -> usize {
    returns(s).iter().filter(|r| !r.is_empty()).count()
}

fn param_name<T: std::fmt::Debug>(r: rdlidar::Result<T>) -> &'static str {
    match r {
        Err(Error::InvalidParameter { name, .. }) => name,
        other => panic!("expected an invalid parameter, got {other:?}"),
    }
}

fn check_paper<T: Real>(g: Geometry) -> Scene<T> {
    let s = paper_scene::<T>(g).unwrap();
    assert_eq!(s.geometry(), g);
    let per_pixel = returns(&s);
    assert!(per_pixel.iter().all(|r| r.len() <= 1), "{g}: not opaque");

    // All three reflectivities occur, at the expected depths.
    let tol = 1e-6;
    let of = |refl: f64| -> BTreeSet<usize> {
        per_pixel
            .iter()
            .flatten()
            .filter(|(_, v)| (v - refl).abs() < tol)
            .map(|(j, _)| *j)
            .collect()
    };
    let (sq, disk, plane) = (of(0.9), of(0.6), of(0.4));
    let top = (g.ks - 1) as f64;
    assert_eq!(sq, BTreeSet::from([(0.3 * top).round() as usize]), "{g}");
    assert_eq!(disk, BTreeSet::from([(0.6 * top).round() as usize]), "{g}");
    assert!(!plane.is_empty(), "{g}: no slanted plane");
    let (lo, hi) = (*plane.first().unwrap(), *plane.last().unwrap());
    assert!(lo as f64 >= (0.2 * top).round() && hi as f64 <= (0.9 * top).round());
    if g.ks >= 10 {
        assert!(plane.len() >= 3, "{g}: plane not slanted: {plane:?}");
    }
    let all: BTreeSet<usize> = per_pixel.iter().flatten().map(|(j, _)| *j).collect();
    assert!(all.len() >= 3, "{g}: depths {all:?}");
    assert!(per_pixel
        .iter()
        .flatten()
        .all(|(_, v)| [0.9, 0.6, 0.4].iter().any(|r| (v - r).abs() < tol)));
    s
}

#[test]
fn paper_scene_is_opaque_with_three_surfaces() {
    let s = check_paper::<f64>(geom(100, 100, 40));
    let lit = lit_pixels(&s);
    // The reference experiment lights 5283 of 10 000 pixels.
    assert!((4500..=6000).contains(&lit), "lit {lit}");
    assert_eq!(lit, 5547);
    assert_eq!(s.depth_map().lit(), lit);
}

#[test]
fn paper_scene_scales() {
    for g in [
        geom(32, 32, 40),
        geom(16, 16, 16),
        geom(20, 50, 8),
        geom(64, 48, 100),
    ] {
        let s = check_paper::<f32>(g);
        let frac = lit_pixels(&s) as f64 / g.pixels() as f64;
        assert!((0.4..0.7).contains(&frac), "{g}: lit fraction {frac}");
    }
    // Degenerate sizes do not panic.
    for g in [geom(1, 1, 1), geom(1, 7, 2), geom(3, 1, 1)] {
        paper_scene::<f64>(g).unwrap();
    }
    assert_eq!(
        paper_scene::<f64>(geom(40, 40, 20)).unwrap(),
        paper_scene::<f64>(geom(40, 40, 20)).unwrap()
    );
}

#[test]
fn paper_scene_nearest_surface_wins() {
    let g = geom(100, 100, 40);
    let layers = paper_surfaces::<f64>(g).unwrap();
    let dm = paper_scene::<f64>(g).unwrap().depth_map();
    let mut overlaps = 0;
    let mut front = [0usize; 3];
    for ((i, j), &d) in dm.depth.indexed_iter() {
        let lit: Vec<(usize, i32)> = layers
            .iter()
            .enumerate()
            .map(|(k, l)| (k, l.depth[[i, j]]))
            .filter(|&(_, d)| d != NO_RETURN)
            .collect();
        match lit.iter().min_by_key(|&&(k, d)| (d, k)) {
            None => assert_eq!(d, NO_RETURN),
            Some(&(k, dk)) => {
                assert_eq!(d, dk, "pixel ({i}, {j})");
                assert_eq!(dm.amplitude[[i, j]], layers[k].amplitude[[i, j]]);
                if lit.len() > 1 {
                    overlaps += 1;
                    front[k] += 1;
                }
            }
        }
    }
    assert!(overlaps > 100, "overlaps {overlaps}");
    // The plane is in front of the square somewhere, and behind it elsewhere.
    assert!(front[0] > 0 && front[2] > 0, "{front:?}");
}

#[test]
fn composite_nearest_rules_and_errors() {
    let a = DepthMap {
        depth: Array2::from_shape_vec((1, 3), vec![2, NO_RETURN, 1]).unwrap(),
        amplitude: Array2::from_shape_vec((1, 3), vec![0.5f64, 0.0, 0.7]).unwrap(),
    };
    let b = DepthMap {
        depth: Array2::from_shape_vec((1, 3), vec![1, 3, 1]).unwrap(),
        amplitude: Array2::from_shape_vec((1, 3), vec![0.2f64, 0.3, 0.9]).unwrap(),
    };
    let c = composite_nearest(&[a.clone(), b.clone()]).unwrap();
    assert_eq!(c.depth.as_slice().unwrap(), &[1, 3, 1]);
    // Equal depths: the earlier layer wins.
    assert_eq!(c.amplitude.as_slice().unwrap(), &[0.2, 0.3, 0.7]);

    assert_eq!(param_name(composite_nearest::<f64>(&[])), "layers");
    let mut bad = a.clone();
    bad.depth[[0, 0]] = -3;
    assert_eq!(param_name(composite_nearest(&[bad])), "depth");
    let small = DepthMap {
        depth: Array2::from_elem((1, 2), NO_RETURN),
        amplitude: Array2::<f64>::zeros((1, 2)),
    };
    assert!(matches!(
        composite_nearest(&[a, small]),
        Err(Error::ShapeMismatch {
            expected: 3,
            found: 2,
            ..
        })
    ));
}

#[test]
fn random_opaque_scene_fraction_and_seeds() {
    let g = geom(100, 100, 40);
    for (p, seed) in [(0.1, 1u64), (0.5, 2), (0.9, 3)] {
        let s = random_opaque_scene::<f64>(g, p, seed).unwrap();
        let per_pixel = returns(&s);
        assert!(per_pixel.iter().all(|r| r.len() <= 1));
        let lit = lit_pixels(&s) as f64;
        let n = g.pixels() as f64;
        let sd = (n * p * (1.0 - p)).sqrt();
        assert!((lit - n * p).abs() < 5.0 * sd, "p {p}: lit {lit}");
        assert!(per_pixel
            .iter()
            .flatten()
            .all(|&(j, v)| j < g.ks && (0.2..=1.0).contains(&v)));
        // Depth bins spread over the whole range.
        let bins: BTreeSet<usize> = per_pixel.iter().flatten().map(|(j, _)| *j).collect();
        assert_eq!(bins.len(), g.ks);
    }
    assert_eq!(
        random_opaque_scene::<f32>(g, 0.3, 7).unwrap(),
        random_opaque_scene::<f32>(g, 0.3, 7).unwrap()
    );
    assert_ne!(
        random_opaque_scene::<f32>(g, 0.3, 7).unwrap(),
        random_opaque_scene::<f32>(g, 0.3, 8).unwrap()
    );
    assert_eq!(random_opaque_scene::<f64>(g, 0.0, 1).unwrap().nnz(), 0);
    assert_eq!(
        random_opaque_scene::<f64>(g, 1.0, 1).unwrap().nnz(),
        g.pixels()
    );
}

#[test]
fn random_opaque_scene_rejects_bad_fractions() {
    let g = geom(4, 4, 4);
    for p in [-0.1, 1.5, f64::NAN, f64::INFINITY] {
        assert_eq!(
            param_name(random_opaque_scene::<f64>(g, p, 0)),
            "lit_fraction"
        );
    }
    let zero = Geometry { m: 0, n: 4, ks: 4 };
    assert_eq!(param_name(random_opaque_scene::<f64>(zero, 0.5, 0)), "size");
    assert_eq!(param_name(paper_scene::<f64>(zero)), "size");
}

#[test]
fn semi_transparent_scene_returns_and_order() {
    let g = geom(30, 40, 20);
    let s = semi_transparent_scene::<f64>(g, 2..=3, 11).unwrap();
    let mut counts = [0usize; 4];
    for r in returns(&s) {
        assert!((2..=3).contains(&r.len()), "{r:?}");
        counts[r.len()] += 1;
        for w in r.windows(2) {
            assert!(w[0].0 < w[1].0 && w[0].1 > w[1].1, "{r:?}");
        }
        assert!(r.iter().all(|&(_, v)| (0.1..=1.0).contains(&v)));
    }
    assert!(counts[2] > 400 && counts[3] > 400, "{counts:?}");

    // Other ranges, including every bin filled, and f32.
    let s = semi_transparent_scene::<f32>(geom(5, 5, 4), 4..=4, 3).unwrap();
    assert_eq!(s.nnz(), 100);
    for r in returns(&s) {
        assert!(r.windows(2).all(|w| w[0].1 >= w[1].1));
    }
    let s = semi_transparent_scene::<f64>(geom(8, 8, 10), 1..=1, 3).unwrap();
    assert!(returns(&s).iter().all(|r| r.len() == 1));

    assert_eq!(
        semi_transparent_scene::<f64>(g, 2..=3, 5).unwrap(),
        semi_transparent_scene::<f64>(g, 2..=3, 5).unwrap()
    );
    assert_ne!(
        semi_transparent_scene::<f64>(g, 2..=3, 5).unwrap(),
        semi_transparent_scene::<f64>(g, 2..=3, 6).unwrap()
    );

    #[allow(clippy::reversed_empty_ranges)]
    for r in [0..=2, 3..=2, 2..=21, 0..=0] {
        assert_eq!(
            param_name(semi_transparent_scene::<f64>(g, r, 0)),
            "returns"
        );
    }
}

/// A unique path in the system's temporary directory, removed on drop.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str) -> Self {
        TempFile(std::env::temp_dir().join(format!("rdlidar-scenes-{}-{name}", std::process::id())))
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn write_png(path: &Path, width: u32, height: u32, color: png::ColorType, bits: u8, data: &[u8]) {
    let file = std::fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(color);
    enc.set_depth(png::BitDepth::from_u8(bits).unwrap());
    let mut w = enc.write_header().unwrap();
    w.write_image_data(data).unwrap();
    w.finish().unwrap();
}

fn to_be16(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_be_bytes()).collect()
}

#[test]
fn png_round_trip_16_and_8_bit() {
    let ks = 40;
    // 3 rows × 4 columns, 16-bit depth with one pixel of no return, seeded values elsewhere.
    let noise = random_vec(12, 21);
    let depth16: Vec<u16> = noise
        .iter()
        .enumerate()
        .map(|(k, v)| {
            if k == 5 {
                0
            } else {
                (1.0 + (v + 1.0) / 2.0 * 65534.0) as u16
            }
        })
        .collect();
    let refl8: Vec<u8> = (0..12).map(|k| (k * 20 + 15) as u8).collect();
    let dpath = TempFile::new("depth16.png");
    let rpath = TempFile::new("refl8.png");
    write_png(
        &dpath.0,
        4,
        3,
        png::ColorType::Grayscale,
        16,
        &to_be16(&depth16),
    );
    write_png(&rpath.0, 4, 3, png::ColorType::Grayscale, 8, &refl8);

    let s = scene_from_pngs::<f64>(&dpath.0, Some(&rpath.0), ks).unwrap();
    assert_eq!(s.geometry(), geom(3, 4, ks));
    let dm = s.depth_map();
    for y in 0..3 {
        for x in 0..4 {
            let k = y * 4 + x;
            if depth16[k] == 0 {
                assert_eq!(dm.depth[[y, x]], NO_RETURN);
                assert_eq!(dm.amplitude[[y, x]], 0.0);
            } else {
                let bin = (depth16[k] as f64 / 65535.0 * (ks - 1) as f64).round() as i32;
                assert_eq!(dm.depth[[y, x]], bin);
                assert!((dm.amplitude[[y, x]] - refl8[k] as f64 / 255.0).abs() < 1e-12);
            }
        }
    }
    assert_eq!(s.nnz(), 11);

    // 8-bit depth, no reflectivity: amplitude 1.0, the extremes at bins 0 and ks − 1.
    let depth8: Vec<u8> = vec![0, 1, 128, 255, 64, 0];
    let d8 = TempFile::new("depth8.png");
    write_png(&d8.0, 3, 2, png::ColorType::Grayscale, 8, &depth8);
    let s = scene_from_pngs::<f32>(&d8.0, None, ks).unwrap();
    let dm = s.depth_map();
    let expect: Vec<i32> = vec![-1, 0, 20, 39, 10, -1];
    assert_eq!(dm.depth.iter().copied().collect::<Vec<_>>(), expect);
    for (&d, &a) in dm.depth.iter().zip(dm.amplitude.iter()) {
        assert_eq!(a, if d == NO_RETURN { 0.0 } else { 1.0 });
    }

    // RGB reads the first (red) channel; RGBA ignores alpha.
    let rgb: Vec<u8> = depth8.iter().flat_map(|&v| [v, 255 - v, 7]).collect();
    let prgb = TempFile::new("rgb.png");
    write_png(&prgb.0, 3, 2, png::ColorType::Rgb, 8, &rgb);
    assert_eq!(scene_from_pngs::<f32>(&prgb.0, None, ks).unwrap(), s);
    let rgba: Vec<u8> = depth8.iter().flat_map(|&v| [v, 3, 9, 0]).collect();
    let prgba = TempFile::new("rgba.png");
    write_png(&prgba.0, 3, 2, png::ColorType::Rgba, 8, &rgba);
    assert_eq!(scene_from_pngs::<f32>(&prgba.0, None, ks).unwrap(), s);

    // 1-bit grayscale is expanded to full range: set pixels land in the last bin.
    let p1 = TempFile::new("gray1.png");
    write_png(&p1.0, 8, 1, png::ColorType::Grayscale, 1, &[0b1010_0000]);
    let dm = scene_from_pngs::<f64>(&p1.0, None, 5).unwrap().depth_map();
    assert_eq!(
        dm.depth.iter().copied().collect::<Vec<_>>(),
        vec![4, -1, 4, -1, -1, -1, -1, -1]
    );
}

fn names_file(e: &Error, path: &Path) -> bool {
    e.to_string().contains(&path.display().to_string())
}

#[test]
fn png_errors_are_typed_and_name_the_file() {
    let good = TempFile::new("good.png");
    write_png(&good.0, 4, 3, png::ColorType::Grayscale, 8, &[50u8; 12]);

    // Missing file.
    let missing = TempFile::new("missing.png");
    let e = scene_from_pngs::<f64>(&missing.0, None, 8).unwrap_err();
    assert!(
        matches!(e, Error::InvalidParameter { name: "png", .. }) && names_file(&e, &missing.0),
        "{e}"
    );

    // Not a PNG.
    let text = TempFile::new("text.png");
    std::fs::write(&text.0, b"this is not an image").unwrap();
    let e = scene_from_pngs::<f64>(&text.0, None, 8).unwrap_err();
    assert!(
        matches!(e, Error::InvalidParameter { name: "png", .. }) && names_file(&e, &text.0),
        "{e}"
    );

    // Truncated PNGs, as depth and as reflectivity.
    let bytes = std::fs::read(&good.0).unwrap();
    for cut in [bytes.len() - 20, 40, 8, 3] {
        let t = TempFile::new(&format!("trunc{cut}.png"));
        std::fs::write(&t.0, &bytes[..cut]).unwrap();
        let e = scene_from_pngs::<f64>(&t.0, None, 8).unwrap_err();
        assert!(
            matches!(e, Error::InvalidParameter { name: "png", .. }) && names_file(&e, &t.0),
            "cut {cut}: {e}"
        );
        let e = scene_from_pngs::<f64>(&good.0, Some(&t.0), 8).unwrap_err();
        assert!(names_file(&e, &t.0), "cut {cut}: {e}");
    }

    // Size mismatch: width, then height.
    let wide = TempFile::new("wide.png");
    write_png(&wide.0, 5, 3, png::ColorType::Grayscale, 8, &[9u8; 15]);
    let e = scene_from_pngs::<f64>(&good.0, Some(&wide.0), 8).unwrap_err();
    assert!(
        matches!(
            e,
            Error::ShapeMismatch {
                expected: 4,
                found: 5,
                ..
            }
        ) && names_file(&e, &wide.0)
            && names_file(&e, &good.0),
        "{e}"
    );
    let tall = TempFile::new("tall.png");
    write_png(&tall.0, 4, 2, png::ColorType::Grayscale, 16, &[1u8; 16]);
    let e = scene_from_pngs::<f64>(&good.0, Some(&tall.0), 8).unwrap_err();
    assert!(
        matches!(
            e,
            Error::ShapeMismatch {
                expected: 3,
                found: 2,
                ..
            }
        ) && names_file(&e, &tall.0),
        "{e}"
    );

    // ks = 0.
    assert_eq!(param_name(scene_from_pngs::<f64>(&good.0, None, 0)), "size");
}

#[test]
fn attenuation_scales_by_inverse_square() {
    let g = geom(6, 7, 12);
    let s = semi_transparent_scene::<f64>(g, 1..=3, 4).unwrap();
    for near in [1.0, 2.5, 0.01] {
        let a = attenuate(&s, near).unwrap();
        assert_eq!(a.geometry(), g);
        for ((idx, &v), &w) in s.data().indexed_iter().zip(a.data().iter()) {
            let j = idx.2 as f64;
            let f = (near / (near + j)).powi(2);
            assert_eq!(v != 0.0, w != 0.0, "support changed at {idx:?}");
            assert!(w.is_finite());
            assert!(
                (w - v * f).abs() <= 1e-14 * v.abs(),
                "{idx:?}: {w} vs {v}·{f}"
            );
            assert!(w.abs() <= v.abs());
        }
    }
    // near = 1: factor 1/(j + 1)²; bin 0 unchanged.
    let mut x = ndarray::Array3::<f32>::zeros((1, 1, 4));
    x[[0, 0, 0]] = 0.8;
    x[[0, 0, 3]] = 0.8;
    let a = attenuate(&Scene::new(x).unwrap(), 1.0).unwrap();
    assert_eq!(a.as_slice(), &[0.8, 0.0, 0.0, 0.05]);

    for near in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(param_name(attenuate(&s, near)), "near");
    }
    // A value that would underflow is reported, not silently dropped.
    let mut x = ndarray::Array3::<f32>::zeros((1, 1, 3));
    x[[0, 0, 2]] = f32::from_bits(1);
    let tiny = Scene::new(x).unwrap();
    assert_eq!(param_name(attenuate(&tiny, 1.0)), "scene");
}
