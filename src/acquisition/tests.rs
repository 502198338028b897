//! Unit tests of the acquisition.

use super::*;
use crate::operator::LinearOperator;

fn codes(g: Geometry, k: usize, sets: u64) -> Vec<Arc<Codes>> {
    (0..sets)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), k, 7 + s).unwrap()))
        .collect()
}

#[test]
fn pulses_are_refused_for_what_they_are() {
    assert!(check_pulse(&[]).is_err());
    assert!(check_pulse(&[0.0, 0.0])
        .unwrap_err()
        .to_string()
        .contains("zero"));
    assert!(check_pulse(&[1.0, -1.0])
        .unwrap_err()
        .to_string()
        .contains("negative"));
    assert!(check_pulse(&[1.0, f64::NAN])
        .unwrap_err()
        .to_string()
        .contains("finite"));
    assert!(check_pulse(&[1.0, 0.5]).is_ok());
    let tiny = [1e-300, 2e-300];
    assert!(pulse_in::<f64>(&tiny).is_ok());
    let e = pulse_in::<f32>(&tiny).unwrap_err().to_string();
    assert!(e.contains("underflows f32"), "{e}");
    let e = pulse_in::<f32>(&[1e300]).unwrap_err().to_string();
    assert!(e.contains("overflows f32"), "{e}");
}

#[test]
fn the_architecture_follows_the_code_sets_and_tiles() {
    let g = Geometry::new(4, 6, 3).unwrap();
    let p = vec![1.0, 0.0, 1.0, 1.0];
    let k = g.samples(4);
    let build = |sets: Vec<Arc<Codes>>, tiles, streaming| {
        Acquisition::new(g, p.clone(), CodeStore::Held(sets), tiles, streaming)
    };
    let one = build(codes(g, k, 1), None, Streaming::Auto).unwrap();
    assert_eq!(one.architecture(), Architecture::Single);
    assert_eq!(one.rows(), None);
    assert_eq!(one.measurements(), k);
    let two = build(codes(g, k, 2), None, Streaming::Auto).unwrap();
    assert_eq!(two.architecture(), Architecture::MultiAdc(2));
    assert_eq!(two.operator::<f64>().unwrap().nrows(), 2 * k);
    let t = TileSize { m: 2, n: 4 };
    let tiled = build(codes(g, k, 1), Some(t), Streaming::Auto).unwrap();
    assert_eq!(tiled.rows(), Some(4));
    assert_eq!(tiled.operator::<f32>().unwrap().nrows(), 4 * k);
    assert!(tiled.lidar_operator::<f32>().is_err());
    let e = build(codes(g, k, 2), Some(t), Streaming::Auto).unwrap_err();
    assert!(e.to_string().contains("tiles"), "{e}");
    let e = build(codes(g, k + 1, 1), None, Streaming::Auto).unwrap_err();
    assert!(e.to_string().contains("code set 0"), "{e}");
    let e = build(codes(g, k, 1), None, Streaming::Always).unwrap_err();
    assert!(e.to_string().contains("seed"), "{e}");
}

#[test]
fn a_tile_is_the_acquisition_of_its_rows() {
    let g = Geometry::new(6, 7, 3).unwrap();
    let p = vec![1.0, 0.0, 1.0, 1.0, 0.5];
    let k = g.samples(p.len());
    let t = TileSize { m: 4, n: 3 };
    let seeded = CodeStore::Seeded(SeededCodes::new(5, 1, g.pixels(), k).unwrap());
    for store in [CodeStore::Held(codes(g, k, 1)), seeded] {
        let acq = Acquisition::new(g, p.clone(), store, Some(t), Streaming::Auto).unwrap();
        let x: Vec<f64> = (0..g.voxels())
            .map(|i| ((i * 7) % 5) as f64 - 1.5)
            .collect();
        let mut y = vec![0.0; acq.measurements()];
        acq.operator::<f64>().unwrap().apply(&x, &mut y);
        let places = acq.tile_places();
        assert_eq!(places.len(), 6);
        for place in &places {
            let sub = acq.tile(place).unwrap();
            assert_eq!(sub.architecture(), Architecture::Single);
            assert_eq!(sub.geometry(), place.geometry);
            let xs: Vec<f64> = place
                .pixels(g)
                .iter()
                .flat_map(|&px| x[px * 3..px * 3 + 3].to_vec())
                .collect();
            let mut ys = vec![0.0; k];
            sub.operator::<f64>().unwrap().apply(&xs, &mut ys);
            let rows = &y[place.index * k..(place.index + 1) * k];
            for (a, b) in ys.iter().zip(rows) {
                assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
            }
        }
    }
    let one =
        Acquisition::new(g, p, CodeStore::Held(codes(g, k, 1)), None, Streaming::Auto).unwrap();
    assert!(one.tile_places().is_empty());
}

#[test]
fn a_tiled_operator_is_planned_with_the_whole_array_s_codes() {
    // Applying the whole operator holds every tile's codes; reconstructing seeded tiles
    // holds one tile per thread.
    let g = Geometry::new(256, 256, 8).unwrap();
    let p = vec![1.0; 2000];
    let k = g.samples(p.len());
    let seeded = CodeStore::Seeded(SeededCodes::new(5, 1, g.pixels(), k).unwrap());
    let t = TileSize { m: 8, n: 8 };
    let acq = Acquisition::new(g, p, seeded, Some(t), Streaming::Auto).unwrap();
    let whole = acq.memory_plan::<f32>(2, Use::Operator).total();
    let tiles = acq.memory_plan::<f32>(2, Use::Reconstruct).total();
    let codes = (g.pixels() as u128 / 8) * k as u128;
    assert!(whole >= 2 * codes, "{whole} vs codes {codes}");
    assert!(tiles < whole / 2, "{tiles} vs {whole}");
}

#[test]
fn measurements_are_checked_for_count_and_finiteness() {
    let g = Geometry::new(2, 2, 3).unwrap();
    let p = vec![1.0, 1.0];
    let k = g.samples(2);
    let a = Acquisition::new(
        g,
        p,
        CodeStore::Held(codes(g, k, 3)),
        None,
        Streaming::Never,
    )
    .unwrap();
    assert!(a.check_measurements(&vec![0.0f32; 3 * k], "meas").is_ok());
    let e = a.check_measurements(&vec![0.0f32; k], "meas").unwrap_err();
    assert!(e.to_string().contains("3 code sets"), "{e}");
    let mut y = vec![0.0f64; 3 * k];
    y[5] = f64::INFINITY;
    let e = a.check_measurements(&y, "meas").unwrap_err();
    assert!(e.to_string().contains("entry 5"), "{e}");
}

/// A small scene with one return per pixel, measured by `acq`.
fn measured(acq: &Acquisition) -> Vec<f64> {
    let g = acq.geometry();
    let mut x = vec![0.0; g.m * g.n * g.ks];
    for p in 0..g.pixels() {
        x[p * g.ks + (p * 3) % g.ks] = 1.0 + (p % 4) as f64;
    }
    let op = acq.operator::<f64>().unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(&x, &mut y);
    y
}

#[test]
fn the_outcome_tells_what_ran_in_lines_and_fields() {
    let g = Geometry::new(4, 6, 5).unwrap();
    let p = vec![
        1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0,
    ];
    let k = g.samples(p.len());
    let one = Acquisition::new(
        g,
        p.clone(),
        CodeStore::Held(codes(g, k, 1)),
        None,
        Streaming::Never,
    )
    .unwrap();
    let never = AtomicBool::new(false);
    let request = ReconstructRequest::new(Method::Auto);
    let y = measured(&one);
    let r = request
        .run(
            &one,
            &y,
            &observe_nothing,
            &|_: &TileReconstruction<f64>| {},
            &never,
        )
        .unwrap();
    let out = request.finish(r, &one, None);
    let s = &out.summary;
    assert_eq!(s.architecture, "single");
    assert!(
        s.headline
            .starts_with(&format!("solver {} (auto: ", s.run.method_used)),
        "{}",
        s.headline
    );
    assert!(s
        .headline
        .ends_with(&format!("{} of 24 pixels with a return", out.depth.lit())));
    assert!(!s.run.stages.is_empty());
    assert_eq!(s.details.len(), s.run.stages.len());
    assert!(s.details.iter().all(|l| l.starts_with("auto stage ")));
    let json = serde_json::to_value(s).unwrap();
    assert_eq!(json["method"], "auto");
    assert_eq!(json["stages"][0]["method"], s.run.stages[0].method.name());
    assert!(json.get("tiles").is_none() && json.get("censored").is_none());
    assert!(json["iterations"].as_u64().unwrap() > 0);

    // Tiles: the tiles' runs, their applications summed, the tiles' count in the headline.
    let t = TileSize { m: 2, n: 3 };
    let tiled = Acquisition::new(
        g,
        p,
        CodeStore::Held(codes(g, k, 1)),
        Some(t),
        Streaming::Never,
    )
    .unwrap();
    let y = measured(&tiled);
    let request = ReconstructRequest::new(Method::Cgls);
    let r = request
        .run(
            &tiled,
            &y,
            &observe_nothing,
            &|_: &TileReconstruction<f64>| {},
            &never,
        )
        .unwrap();
    let out = request.finish(r, &tiled, None);
    let s = &out.summary;
    let tiles = s.tiles.as_ref().unwrap();
    assert_eq!(tiles.len(), 4);
    assert_eq!(
        s.run.forward_applies,
        tiles.iter().map(|t| t.run.forward_applies).sum::<usize>()
    );
    assert!(s.headline.contains("of 4 tiles of 2x3"), "{}", s.headline);
    assert!(s.headline.contains("applications in all"), "{}", s.headline);
    let json = serde_json::to_value(s).unwrap();
    assert_eq!(json["tiles"][3]["shape"], serde_json::json!([2, 3]));
}
