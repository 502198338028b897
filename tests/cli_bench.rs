//! `rdlidar bench`, run as a user would: the timings, memory, ISA and threads it reports, as JSON
//! and as text.

use crate::cli_support::{rdlidar, stderr, stdout};

#[test]
fn bench_json_has_the_four_timings() {
    let out = rdlidar(&[
        "bench",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--repeats",
        "3",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    for key in ["forward", "adjoint", "sparse_forward", "restricted_adjoint"] {
        for stat in ["median_s", "min_s"] {
            let t = v[key][stat].as_f64().unwrap_or(-1.0);
            assert!(t >= 0.0, "{key}.{stat} in {v}");
        }
        assert!(v[key]["min_s"].as_f64() <= v[key]["median_s"].as_f64());
    }
    assert!(v["memory_bytes"].as_u64().unwrap() > 0);
    // The rates are the work over the median time, and the limits are positive.
    for key in ["forward", "adjoint"] {
        let t = v[key]["median_s"].as_f64().unwrap();
        for (work, rate) in [
            ("additions", "additions_per_s"),
            ("table_bytes", "table_bytes_per_s"),
        ] {
            let w = v["work"][key][work].as_f64().unwrap();
            let r = v["rates"][key][rate].as_f64().unwrap();
            assert!(
                w > 0.0 && (r * t - w).abs() <= 1e-9 * w,
                "{key}.{rate} in {v}"
            );
        }
    }
    // On AVX-512 the probe reads rows of whole 512-bit vectors, as the wide kernels do.
    let row = if v["isa"].as_str() == Some("avx512") {
        64
    } else {
        32
    };
    for level in ["l1", "l2"] {
        let l = &v["limits"][level];
        assert!(l["bytes_per_s"].as_f64().unwrap() > 0.0, "{level} in {v}");
        assert_eq!(
            l["row_bytes"].as_u64(),
            Some(row),
            "{level}: one chunk of 8 f32 at K_s 6, {row} bytes a row in {v}"
        );
    }
}

#[test]
fn bench_text_reports_memory_isa_and_threads() {
    let out = rdlidar(&[
        "--threads",
        "1",
        "bench",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--repeats",
        "1",
        "--precision",
        "f64",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for needle in [
        "threads 1",
        "memory",
        "forward",
        "adjoint",
        "sparse forward",
        "restricted adj.",
    ] {
        assert!(text.contains(needle), "{needle} missing from\n{text}");
    }
}

/// `rdlidar ARGS` with `RDLIDAR_ISA` set to `isa`.
fn with_isa(isa: &str, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .env("RDLIDAR_ISA", isa)
        .args(args)
        .output()
        .expect("the binary runs")
}

#[test]
fn rdlidar_isa_caps_the_kernels_and_every_path_gives_the_same_products() {
    let bench = [
        "bench",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--repeats",
        "1",
        "--json",
    ];
    let isa_of = |isa: &str| -> String {
        let out = with_isa(isa, &bench);
        assert!(out.status.success(), "{isa}: {}", stderr(&out));
        let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
        v["isa"].as_str().unwrap().to_string()
    };
    let best = isa_of("native");
    let order = ["generic", "avx2+fma", "avx512"];
    let rank = |name: &str| order.iter().position(|o| *o == name).unwrap();
    assert_eq!(isa_of(""), best);
    assert_eq!(isa_of("generic"), "generic");
    // A cap above what the CPU has gives the best it has.
    assert_eq!(rank(&isa_of("avx2")), rank(&best).min(1));
    assert_eq!(isa_of(" AVX512 "), best);
    // The same forward and adjoint products on every path (f64; the sums' order differs).
    let tmp = crate::cli_support::TempDir::new("isa-paths");
    let sim = tmp.path("sim");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "9x7x12",
        "--pulse-len",
        "90",
        "--out",
        crate::cli_support::s(&sim),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let file = |name: &str| sim.join(name).display().to_string();
    let mut outputs: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    for isa in ["generic", "avx2", "avx512"] {
        let (y, x) = (
            tmp.path(&format!("y-{isa}.npy")),
            tmp.path(&format!("x-{isa}.npy")),
        );
        let (ys, xs) = (y.display().to_string(), x.display().to_string());
        let fwd = with_isa(
            isa,
            &[
                "--precision",
                "f64",
                "forward",
                "--pulse",
                &file("pulse.npy"),
                "--codes",
                &file("codes.npy"),
                "--scene",
                &file("scene.npy"),
                "--out",
                &ys,
            ],
        );
        assert!(fwd.status.success(), "{isa}: {}", stderr(&fwd));
        let adj = with_isa(
            isa,
            &[
                "--precision",
                "f64",
                "adjoint",
                "--pulse",
                &file("pulse.npy"),
                "--codes",
                &file("codes.npy"),
                "--meas",
                &ys,
                "--depth-bins",
                "12",
                "--out",
                &xs,
            ],
        );
        assert!(adj.status.success(), "{isa}: {}", stderr(&adj));
        let y: ndarray::Array1<f64> = ndarray_npy::read_npy(&y).unwrap();
        let x: ndarray::Array3<f64> = ndarray_npy::read_npy(&x).unwrap();
        outputs.push((y.to_vec(), x.iter().copied().collect()));
    }
    let close = |a: &[f64], b: &[f64]| {
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        a.iter().zip(b).all(|(u, v)| (u - v).abs() <= 1e-12 * scale)
    };
    for (i, (y, x)) in outputs.iter().enumerate().skip(1) {
        assert!(close(&outputs[0].0, y), "forward of path {i}");
        assert!(close(&outputs[0].1, x), "adjoint of path {i}");
    }
    // A value that names no instruction set: one line naming the variable.
    let out = with_isa("sse9", &bench);
    crate::cli_support::assert_one_line_error(&out, &["RDLIDAR_ISA", "sse9", "generic"]);
}
