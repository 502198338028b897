//! `rdlidar forward`, run as a user would: on the files `simulate` writes it reproduces their
//! measurements, in every precision and from Fortran-order and float32 inputs.

use ndarray::{Array1, Array3};
use ndarray_npy::{read_npy, write_npy};

use crate::cli_support::{max_rel_diff, rdlidar, s, simulate_small, stderr, TempDir};

#[test]
fn forward_on_the_simulated_files_reproduces_the_measurements() {
    let tmp = TempDir::new("forward");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    for precision in [None, Some("f32"), Some("f64")] {
        let y = tmp.path("y.npy");
        let mut args = vec![
            "forward",
            "--pulse",
            s(&dir.join("pulse.npy")),
            "--codes",
            s(&dir.join("codes.npy")),
            "--scene",
            s(&dir.join("scene.npy")),
            "--out",
            s(&y),
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        if let Some(p) = precision {
            args.extend(["--precision".to_string(), p.to_string()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = rdlidar(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        let got: Array1<f64> = if precision == Some("f32") {
            read_npy::<_, Array1<f32>>(&y).unwrap().mapv(f64::from)
        } else {
            read_npy(&y).unwrap()
        };
        assert_eq!(got.len(), 55);
        let rel = max_rel_diff(&got, &meas);
        assert!(rel <= 1e-5, "{precision:?}: relative difference {rel}");
        std::fs::remove_file(&y).unwrap();
    }
}

#[test]
fn forward_reads_fortran_order_and_float32_inputs() {
    let tmp = TempDir::new("fortran");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let scene: Array3<f64> = read_npy(dir.join("scene.npy")).unwrap();
    // Same values, column-major in memory: written with fortran_order = True.
    let mut fortran = Array3::<f32>::zeros((6, 5, 4)).reversed_axes();
    fortran.assign(&scene.mapv(|v| v as f32));
    assert!(!fortran.is_standard_layout());
    let fscene = tmp.path("scene_f.npy");
    write_npy(&fscene, &fortran).unwrap();
    let head = std::fs::read(&fscene).unwrap();
    assert!(String::from_utf8_lossy(&head[..128]).contains("'fortran_order': True"));

    let y = tmp.path("y.npy");
    let out = rdlidar(&[
        "forward",
        "--pulse",
        s(&dir.join("pulse.npy")),
        "--codes",
        s(&dir.join("codes.npy")),
        "--scene",
        s(&fscene),
        "--out",
        s(&y),
        "--precision",
        "f64",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Array1<f64> = read_npy(&y).unwrap();
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert!(max_rel_diff(&got, &meas) <= 1e-6);
}
