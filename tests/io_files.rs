//! The file readers and writers of `rdlidar::io`: codes, code sets, masked codes, depth maps and
//! measurement rows round trip through `.npy` and are checked when read, and atomic writes leave
//! the destination whole.

use ndarray::{Array1, Array3};
use ndarray_npy::{read_npy, write_npy};

use crate::cli_support::{listing, s, TempDir};

#[test]
fn io_codes_and_depth_round_trip_through_npy() {
    use rdlidar::io::{read_codes, read_depth, write_codes, write_depth, ShapeExpectation};
    use rdlidar::lidar::Codes;
    let tmp = TempDir::new("io-roundtrip");
    let expect = ShapeExpectation {
        pulse_len: 9,
        depth_bins: 4,
        grid: Some((3, 5)),
    };
    for codes in [
        Codes::random_binary(15, 12, 1).unwrap(),
        Codes::random_ternary(15, 12, 0.4, 2).unwrap(),
    ] {
        let p = tmp.path("codes.npy");
        write_codes(&p, (3, 5), &codes).unwrap();
        let dense: Array3<i8> = read_npy(&p).unwrap();
        assert_eq!(dense.dim(), (3, 5, 12));
        let ((m, n), back) = read_codes(&p, &expect).unwrap();
        assert_eq!((m, n), (3, 5));
        assert_eq!(back.to_dense(), codes.to_dense());
    }
    let depth = ndarray::array![[0i32, -1, 3], [2, 1, -1]];
    let p = tmp.path("depth.npy");
    write_depth(&p, &depth).unwrap();
    assert_eq!(read_depth(&p, Some(4)).unwrap(), depth);
    let err = read_depth(&p, Some(3)).unwrap_err().to_string();
    assert!(
        err.contains(s(&p)) && err.contains("depth bin 3 at index (0, 2)"),
        "{err}"
    );
    let err = read_depth(tmp.path("codes.npy"), None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("dtype int8") && err.contains("int32"), "{err}");
}

#[test]
fn io_atomic_writes_leave_the_destination_whole() {
    use rdlidar::io::{write_atomic, StagedFile};
    let tmp = TempDir::new("io-atomic");
    let dest = tmp.path("data.bin");
    std::fs::write(&dest, b"old").unwrap();
    // A writer that fails part-way: the old contents survive, no temporary file remains.
    let err = write_atomic(&dest, |w| {
        use std::io::Write;
        w.write_all(b"partial").unwrap();
        Err(rdlidar::Error::File {
            path: "data.bin".into(),
            reason: "simulated failure".into(),
        })
    });
    assert!(err.is_err());
    assert_eq!(std::fs::read(&dest).unwrap(), b"old");
    assert_eq!(listing(&tmp.0), ["data.bin"]);
    // A staged file dropped without commit leaves nothing.
    {
        let mut f = StagedFile::create(tmp.path("other.bin")).unwrap();
        std::io::Write::write_all(f.writer(), b"abc").unwrap();
    }
    assert_eq!(listing(&tmp.0), ["data.bin"]);
    // A committed one replaces the destination.
    write_atomic(&dest, |w| {
        std::io::Write::write_all(w, b"new").map_err(|e| rdlidar::Error::File {
            path: "data.bin".into(),
            reason: e.to_string(),
        })
    })
    .unwrap();
    assert_eq!(std::fs::read(&dest).unwrap(), b"new");
    assert_eq!(listing(&tmp.0), ["data.bin"]);
}

#[test]
fn io_code_sets_and_measurement_rows_are_read_only_when_asked() {
    use ndarray::{Array2, Array4};
    use rdlidar::io::{
        read_code_sets, read_codes, read_measurement_rows, read_measurements, write_code_sets,
        write_masked_codes, ShapeExpectation,
    };
    use rdlidar::lidar::Codes;
    let tmp = TempDir::new("io-arch");
    let expect = ShapeExpectation {
        pulse_len: 9,
        depth_bins: 4,
        grid: Some((3, 5)),
    };
    let sets = vec![
        Codes::random_binary(15, 12, 1).unwrap(),
        Codes::random_ternary(15, 12, 0.4, 2).unwrap(),
    ];
    let p = tmp.path("sets.npy");
    write_code_sets(&p, (3, 5), &sets).unwrap();
    let dense: Array4<i8> = read_npy(&p).unwrap();
    assert_eq!(dense.dim(), (2, 3, 5, 12));
    let ((m, n), back) = read_code_sets(&p, &expect).unwrap();
    assert_eq!((m, n), (3, 5));
    assert_eq!(back.len(), 2);
    for (a, b) in back.iter().zip(&sets) {
        assert_eq!(a.to_dense(), b.to_dense());
    }
    // The (M, N, K) reader does not take G sets, nor the (G, M, N, K) reader one set.
    let err = read_codes(&p, &expect).unwrap_err().to_string();
    assert!(err.contains(s(&p)) && err.contains("3 dimensions"), "{err}");
    let one = tmp.path("one.npy");
    rdlidar::io::write_codes(&one, (3, 5), &sets[0]).unwrap();
    let err = read_code_sets(&one, &expect).unwrap_err().to_string();
    assert!(
        err.contains(s(&one)) && err.contains("4 dimensions"),
        "{err}"
    );
    // Values, grid and K are checked in every set.
    let mut bad = dense.clone();
    bad[[1, 2, 4, 7]] = 3;
    write_npy(&p, &bad).unwrap();
    let err = read_code_sets(&p, &expect).unwrap_err().to_string();
    assert!(
        err.contains("value 3") && err.contains("(1, 2, 4, 7)"),
        "{err}"
    );
    let wrong_k = ShapeExpectation {
        pulse_len: 10,
        ..expect
    };
    write_code_sets(&p, (3, 5), &sets).unwrap();
    let err = read_code_sets(&p, &wrong_k).unwrap_err().to_string();
    assert!(
        err.contains("K = K_p + K_s − 1") && err.contains("found 12"),
        "{err}"
    );
    assert!(write_code_sets::<Codes>(&p, (3, 5), &[]).is_err());
    assert!(write_code_sets(&p, (5, 5), &sets).is_err());

    // Masked codes: zero rows outside the active pixels.
    let masked = tmp.path("masked.npy");
    write_masked_codes(&masked, (3, 5), &sets[0], &[0, 7, 14]).unwrap();
    let d: Array3<i8> = read_npy(&masked).unwrap();
    for (i, lane) in d.lanes(ndarray::Axis(2)).into_iter().enumerate() {
        assert_eq!(
            lane.iter().any(|&v| v != 0),
            [0, 7, 14].contains(&i),
            "pixel {i}"
        );
    }
    assert!(write_masked_codes(&masked, (3, 5), &sets[0], &[15]).is_err());

    // Measurement rows.
    let y = tmp.path("rows.npy");
    let rows = Array2::from_shape_fn((3, 12), |(i, k)| (i * 12 + k) as f32);
    write_npy(&y, &rows).unwrap();
    let got = read_measurement_rows::<f64>(&y, Some(&expect), Some(3)).unwrap();
    assert_eq!(got, rows.mapv(f64::from));
    let err = read_measurement_rows::<f64>(&y, Some(&expect), Some(4))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(s(&y)) && err.contains("3 rows, expected 4"),
        "{err}"
    );
    let err = read_measurement_rows::<f64>(&y, Some(&wrong_k), None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("13"), "{err}");
    let err = read_measurements::<f64>(&y, None).unwrap_err().to_string();
    assert!(err.contains(s(&y)) && err.contains("1 dimension"), "{err}");
    let mut nan = rows.mapv(f64::from);
    nan[[2, 5]] = f64::NAN;
    write_npy(&y, &nan).unwrap();
    let err = read_measurement_rows::<f64>(&y, None, None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("NaN") && err.contains("(2, 5)"), "{err}");
    let vec_file = tmp.path("vec.npy");
    write_npy(&vec_file, &Array1::<f64>::zeros(12)).unwrap();
    let err = read_measurement_rows::<f64>(&vec_file, None, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(s(&vec_file)) && err.contains("2 dimensions"),
        "{err}"
    );
}

#[test]
fn io_a_band_of_rows_of_any_codes_file_is_those_rows_of_the_whole() {
    use ndarray::{Array4, ShapeBuilder};
    use rdlidar::io::{
        read_code_band, read_code_sets, read_codes, write_code_sets, write_codes,
        write_packed_code_sets, write_packed_codes, ShapeExpectation,
    };
    use rdlidar::lidar::Codes;
    let tmp = TempDir::new("io-band");
    let (m, n, k) = (5, 3, 12);
    let expect = ShapeExpectation {
        pulse_len: 9,
        depth_bins: 4,
        grid: Some((m, n)),
    };
    let binary = Codes::random_binary(m * n, k, 1).unwrap();
    let ternary = Codes::random_ternary(m * n, k, 0.3, 2).unwrap();
    let second = Codes::random_binary(m * n, k, 3).unwrap();
    let dense = ternary.to_dense();
    let files: Vec<(&str, std::path::PathBuf)> = {
        let at = |name: &str| tmp.path(name);
        write_codes(at("int8.npy"), (m, n), &ternary).unwrap();
        write_packed_codes(at("packed.npy"), (m, n), &binary).unwrap();
        write_code_sets(at("sets.npy"), (m, n), &[&ternary, &second]).unwrap();
        write_packed_code_sets(at("packed-sets.npy"), (m, n), &[&binary, &second]).unwrap();
        let as_f32 = dense
            .mapv(f32::from)
            .into_shape_with_order((m, n, k))
            .unwrap();
        write_npy(at("float32.npy"), &as_f32).unwrap();
        // The same values in Fortran order (column-major on disk).
        let mut fortran = Array3::<i8>::zeros((m, n, k).f());
        fortran.assign(&dense.clone().into_shape_with_order((m, n, k)).unwrap());
        write_npy(at("fortran.npy"), &fortran).unwrap();
        [
            "int8",
            "packed",
            "sets",
            "packed-sets",
            "float32",
            "fortran",
        ]
        .iter()
        .map(|&f| (f, at(&format!("{f}.npy"))))
        .collect()
    };
    for (name, path) in &files {
        let whole = if name.contains("sets") {
            read_code_sets(path, &expect).unwrap().1
        } else {
            vec![read_codes(path, &expect).unwrap().1]
        };
        for rows in [0..1, 1..3, 4..5, 0..5] {
            let (grid, band) = read_code_band(path, &expect, rows.clone()).unwrap();
            assert_eq!(grid, (m, n), "{name}");
            assert_eq!(band.len(), whole.len(), "{name}");
            let pixels: Vec<usize> = (rows.start * n..rows.end * n).collect();
            for (b, w) in band.iter().zip(&whole) {
                assert_eq!(
                    b.to_dense(),
                    w.select_pixels(&pixels).unwrap().to_dense(),
                    "{name}, rows {rows:?}"
                );
            }
        }
        for bad in [2..2, 3..6] {
            let e = read_code_band(path, &expect, bad.clone())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("5 pixel rows") && e.contains(&format!("{}..{}", bad.start, bad.end)),
                "{e}"
            );
        }
    }
    // A bad value is named by its index in the whole file, and only the band's values are read.
    let mut bad = dense.into_shape_with_order((m, n, k)).unwrap();
    bad[[3, 1, 7]] = 2;
    write_npy(tmp.path("bad.npy"), &bad).unwrap();
    let e = read_code_band(tmp.path("bad.npy"), &expect, 2..4)
        .unwrap_err()
        .to_string();
    assert!(e.contains("(3, 1, 7)"), "{e}");
    assert!(read_code_band(tmp.path("bad.npy"), &expect, 0..3).is_ok());
    let mut sets = Array4::<i8>::ones((2, m, n, k));
    sets[[1, 4, 2, 0]] = -3;
    write_npy(tmp.path("bad-sets.npy"), &sets).unwrap();
    let e = read_code_band(tmp.path("bad-sets.npy"), &expect, 4..5)
        .unwrap_err()
        .to_string();
    assert!(e.contains("(1, 4, 2, 0)"), "{e}");
}

#[test]
fn io_a_band_of_whole_tile_rows_is_the_diagonal_block_of_its_tiles() {
    use rdlidar::acquisition::{AcquisitionFiles, InputNames, Streaming};
    use rdlidar::lidar::TileSize;
    let tmp = TempDir::new("io-tile-band");
    let (m, n, ks, kp) = (7, 5, 4, 40);
    let k = kp + ks - 1;
    let tile = TileSize { m: 3, n: 4 };
    for format in ["int8", "seed"] {
        let dir = tmp.path(format);
        let out = crate::cli_support::rdlidar(&[
            "simulate",
            "--scene",
            "paper",
            "--size",
            "7x5x4",
            "--pulse-len",
            "40",
            "--tiles",
            "3x4",
            "--codes-format",
            format,
            "--out",
            s(&dir),
        ]);
        assert!(out.status.success(), "{}", crate::cli_support::stderr(&out));
        let codes = dir.join(if format == "seed" {
            "meta.json"
        } else {
            "codes.npy"
        });
        let pulse: Array1<f64> = read_npy(dir.join("pulse.npy")).unwrap();
        let describe = || {
            AcquisitionFiles::describe(
                &codes,
                kp,
                ks,
                None,
                Some(tile),
                Streaming::Auto,
                InputNames::COMMAND_LINE,
            )
            .unwrap()
        };
        let whole = describe()
            .load(pulse.to_vec())
            .unwrap()
            .operator::<f64>()
            .unwrap();
        // Two tiles per row of tiles: rows 3..6 hold tiles 2 and 3, rows 6..7 tiles 4 and 5.
        for (rows, tiles) in [(3..6, 2..4), (6..7, 4..6), (0..7, 0..6), (0..3, 0..2)] {
            let band = describe().with_rows(rows.clone()).unwrap();
            let op = band
                .load(pulse.to_vec())
                .unwrap()
                .operator::<f64>()
                .unwrap();
            let cols = rows.len() * n * ks;
            assert_eq!(
                (op.nrows(), op.ncols()),
                (tiles.len() * k, cols),
                "{format}"
            );
            let x: Vec<f64> = (0..cols).map(|i| ((i * 7 + 3) % 11) as f64 - 5.0).collect();
            let mut x_whole = vec![0.0; m * n * ks];
            x_whole[rows.start * n * ks..rows.end * n * ks].copy_from_slice(&x);
            let (mut y, mut y_whole) = (vec![0.0; op.nrows()], vec![0.0; whole.nrows()]);
            op.apply(&x, &mut y);
            whole.apply(&x_whole, &mut y_whole);
            let mine = tiles.start * k..tiles.end * k;
            assert_eq!(y, y_whole[mine.clone()], "{format}, rows {rows:?}");
            assert!(
                y_whole[..mine.start]
                    .iter()
                    .chain(&y_whole[mine.end..])
                    .all(|v| *v == 0.0),
                "{format}, rows {rows:?}: other tiles measured the band"
            );
            let mut back = vec![0.0; cols];
            let mut back_whole = vec![0.0; m * n * ks];
            let mut y_in = vec![0.0; whole.nrows()];
            y_in[mine].copy_from_slice(&y);
            op.apply_adjoint(&y, &mut back);
            whole.apply_adjoint(&y_in, &mut back_whole);
            assert_eq!(back, back_whole[rows.start * n * ks..rows.end * n * ks]);
        }
        for bad in [1..3, 0..4, 3..5] {
            let e = describe().with_rows(bad.clone()).unwrap_err().to_string();
            assert!(
                e.contains(&format!(
                    "rows {}..{} cut through the tiles of 3x4",
                    bad.start, bad.end
                )),
                "{e}"
            );
        }
    }
}

#[test]
fn io_a_band_of_rows_of_a_scene_file_is_those_rows_of_the_whole() {
    use ndarray::ShapeBuilder;
    use rdlidar::io::{read_scene, read_scene_rows};
    let tmp = TempDir::new("io-scene-band");
    let (m, n, ks) = (5, 3, 4);
    let values = Array3::from_shape_fn((m, n, ks), |(i, j, k)| (i * 100 + j * 10 + k) as f64);
    write_npy(tmp.path("c.npy"), &values).unwrap();
    write_npy(tmp.path("c32.npy"), &values.mapv(|v| v as f32)).unwrap();
    let mut fortran = Array3::<f64>::zeros((m, n, ks).f());
    fortran.assign(&values);
    write_npy(tmp.path("f.npy"), &fortran).unwrap();
    for name in ["c.npy", "c32.npy", "f.npy"] {
        let path = tmp.path(name);
        let whole = read_scene::<f64>(&path).unwrap();
        for rows in [0..1, 1..4, 4..5, 0..5] {
            let (grid, band) = read_scene_rows::<f64>(&path, rows.clone()).unwrap();
            assert_eq!(grid, (m, n, ks), "{name}");
            assert_eq!(
                band.as_slice(),
                &whole.as_slice()[rows.start * n * ks..rows.end * n * ks],
                "{name}, rows {rows:?}"
            );
        }
        for bad in [2..2, 3..6] {
            let e = read_scene_rows::<f64>(&path, bad.clone())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(name) && e.contains(&format!("rows {}..{}", bad.start, bad.end)),
                "{e}"
            );
        }
    }
    // A bad value is named by its index in the whole file; other rows' values are not read.
    let mut bad = values.clone();
    bad[[3, 2, 1]] = f64::NAN;
    write_npy(tmp.path("nan.npy"), &bad).unwrap();
    let e = read_scene_rows::<f64>(tmp.path("nan.npy"), 2..5)
        .unwrap_err()
        .to_string();
    assert!(e.contains("NaN") && e.contains("(3, 2, 1)"), "{e}");
    assert!(read_scene_rows::<f64>(tmp.path("nan.npy"), 0..3).is_ok());
}
