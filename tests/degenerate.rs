//! Every method of `reconstruct` on degenerate problems: all-zero data, data scaled by 10^±30
//! and 10^±300, K_p = 1, K_s = 1, a single pixel, a constant pulse. Each run must return finite
//! values (a scene and a depth map in range) or a typed error — never a panic, a NaN or an
//! infinity.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

use rdlidar::lidar::{simulate, Codes, Geometry, RdOperator, SimulationSpec};
use rdlidar::recon::{reconstruct, Method, ReconstructOptions};
use rdlidar::{LinearOperator, Real};

/// A degenerate problem: an operator and its measurements.
struct Case<T: Real> {
    name: String,
    op: RdOperator<T>,
    y: Vec<T>,
}

fn problems<T: Real>() -> Vec<Case<T>> {
    let mut cases = Vec::new();
    // Small simulated problems at the edges of the geometry.
    for (m, n, ks, kp) in [
        (1, 1, 1, 1),
        (1, 1, 6, 1),
        (4, 4, 1, 8),
        (3, 3, 4, 1),
        (1, 1, 8, 40),
    ] {
        let g = Geometry::new(m, n, ks).unwrap();
        let sim = simulate::<T>(&SimulationSpec::new(g, kp, 7)).unwrap();
        let op = sim.single_operator().unwrap();
        cases.push(Case {
            name: format!("{g} K_p {kp}"),
            op,
            y: sim.meas.clone(),
        });
    }
    // A constant pulse (all ones), whose zero-mean twin is all zero.
    let g = Geometry::new(3, 3, 4).unwrap();
    let kp = 16;
    let codes = Arc::new(Codes::random_binary(g.pixels(), kp + g.ks - 1, 3).unwrap());
    let op = RdOperator::new(g, vec![T::one(); kp], codes).unwrap();
    let mut x = vec![T::zero(); g.voxels()];
    x[5] = T::one();
    x[20] = T::of_f64(0.5);
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(&x, &mut y);
    cases.push(Case {
        name: "constant pulse".to_string(),
        op,
        y,
    });
    // The paper scene at 6x6x6, with all-zero data and data scaled across the range of T.
    let g = Geometry::new(6, 6, 6).unwrap();
    let sim = simulate::<T>(&SimulationSpec::new(g, 60, 1)).unwrap();
    let zero = vec![T::zero(); sim.meas.len()];
    let mut scales = vec![1e-30, 1e30];
    if T::NAME == "f64" {
        scales.extend([1e-300, 1e300]);
    }
    cases.push(Case {
        name: "all-zero data".to_string(),
        op: sim.single_operator().unwrap(),
        y: zero,
    });
    for s in scales {
        cases.push(Case {
            name: format!("data x {s:e}"),
            op: sim.single_operator().unwrap(),
            y: sim
                .meas
                .iter()
                .map(|&v| T::of_f64(v.as_f64() * s))
                .collect(),
        });
    }
    cases
}

fn check_all<T: Real>() {
    let options = ReconstructOptions {
        max_iter: Some(40),
        progress: false,
        seed: 0,
        power_iterations: Some(20),
        ..ReconstructOptions::default()
    };
    let mut failures = Vec::new();
    for case in problems::<T>() {
        assert!(case.y.iter().all(|v| v.is_finite()), "{}", case.name);
        for method in Method::ALL {
            let what = format!("{} {method} on {}", T::NAME, case.name);
            let run = catch_unwind(AssertUnwindSafe(|| {
                reconstruct(&case.op, &case.y, method, &options)
            }));
            match run {
                Err(_) => failures.push(format!("{what}: panicked")),
                Ok(Err(e)) => {
                    // A typed error is an acceptable outcome; its message is one line.
                    let msg = e.to_string();
                    if msg.contains('\n') || msg.is_empty() {
                        failures.push(format!("{what}: error message {msg:?}"));
                    }
                }
                Ok(Ok(r)) => {
                    let ks = case.op.geometry().ks as i32;
                    if let Some(v) = r.scene.as_slice().iter().find(|v| !v.is_finite()) {
                        failures.push(format!("{what}: non-finite value {v} in the scene"));
                    }
                    if r.depth.depth.iter().any(|&d| d < -1 || d >= ks) {
                        failures.push(format!("{what}: depth out of range"));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_method_survives_degenerate_problems_in_f64() {
    check_all::<f64>();
}

#[test]
fn every_method_survives_degenerate_problems_in_f32() {
    check_all::<f32>();
}
