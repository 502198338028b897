//! `rdlidar adjoint`, run as a user would: a scene-shaped backprojection of the simulated
//! measurements, plain and debiased.

use ndarray::Array3;
use ndarray_npy::read_npy;

use crate::cli_support::{rdlidar, s, simulate_small, stderr, TempDir};

#[test]
fn adjoint_writes_a_scene_shaped_backprojection() {
    let tmp = TempDir::new("adjoint");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let (pulse, codes, meas) = (
        dir.join("pulse.npy"),
        dir.join("codes.npy"),
        dir.join("meas.npy"),
    );
    for debiased in [false, true] {
        let xt = tmp.path(if debiased { "xd.npy" } else { "xt.npy" });
        let mut args = vec![
            "adjoint",
            "--pulse",
            s(&pulse),
            "--codes",
            s(&codes),
            "--meas",
            s(&meas),
            "--depth-bins",
            "6",
            "--out",
            s(&xt),
        ];
        if debiased {
            args.push("--debiased");
        }
        let out = rdlidar(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        let x: Array3<f64> = read_npy(&xt).unwrap();
        assert_eq!(x.dim(), (4, 5, 6));
        assert!(x.iter().all(|v| v.is_finite()) && x.iter().any(|&v| v != 0.0));
    }
}
