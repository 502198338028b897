//! Weighted total-variation denoising: closed-form cases, optimality against perturbations, the
//! primal-dual gap certificate, inpainting, denoising, invariances and typed errors.

use ndarray::{s, Array2, ShapeBuilder};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rdlidar::solver::{
    tv_denoise, Control, IterationInfo, Stopping, Termination, TvNorm, TvParams, TvSteps,
};
use rdlidar::Error;

use crate::common::random_vec;

/// P(u) = ½ Σ wᵢ(uᵢ − fᵢ)² + λ TV(u), with the forward differences written out directly.
fn objective(f: &Array2<f64>, w: &Array2<f64>, u: &Array2<f64>, lambda: f64, norm: TvNorm) -> f64 {
    let (m, n) = u.dim();
    let mut data = 0.0;
    let mut tv = 0.0;
    for i in 0..m {
        for j in 0..n {
            data += 0.5 * w[[i, j]] * (u[[i, j]] - f[[i, j]]).powi(2);
            let dv = if i + 1 < m {
                u[[i + 1, j]] - u[[i, j]]
            } else {
                0.0
            };
            let dh = if j + 1 < n {
                u[[i, j + 1]] - u[[i, j]]
            } else {
                0.0
            };
            tv += match norm {
                TvNorm::Isotropic => (dv * dv + dh * dh).sqrt(),
                TvNorm::Anisotropic => dv.abs() + dh.abs(),
            };
        }
    }
    data + lambda * tv
}

fn tight(lambda: f64, tol: f64, max_iter: usize) -> TvParams {
    TvParams::new(lambda)
        .unwrap()
        .with_stopping(Stopping {
            max_iter,
            rel_residual: Some(tol),
            ..Stopping::default()
        })
        .unwrap()
}

fn solve(
    f: &Array2<f64>,
    w: &Array2<f64>,
    params: &TvParams,
) -> (Array2<f64>, rdlidar::solver::Report) {
    let mut u = f.clone();
    let report = tv_denoise(f.view(), w.view(), &mut u, params, &mut ()).unwrap();
    (u, report)
}

fn rmse(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// A map of seeded values in [-1, 1).
fn random_map(m: usize, n: usize, seed: u64) -> Array2<f64> {
    Array2::from_shape_vec((m, n), random_vec(m * n, seed)).unwrap()
}

/// Weights in [0, 1], about a quarter of them zero.
fn random_weights(m: usize, n: usize, seed: u64) -> Array2<f64> {
    random_map(m, n, seed).mapv(|v| if v < -0.5 { 0.0 } else { 0.5 + 0.5 * v.abs() })
}

fn staircase(m: usize, n: usize) -> Array2<f64> {
    Array2::from_shape_fn((m, n), |(i, j)| ((i + 2 * j) * 4 / (m + 2 * n)) as f64)
}

fn add_noise(clean: &Array2<f64>, sigma: f64, seed: u64) -> Array2<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).unwrap();
    clean.mapv(|v| v + normal.sample(&mut rng))
}

#[test]
fn lambda_zero_returns_the_data() {
    let f = random_map(7, 9, 1);
    let w = random_map(7, 9, 2).mapv(|v| 0.1 + v.abs());
    let mut u = Array2::zeros((7, 9));
    let report = tv_denoise(
        f.view(),
        w.view(),
        &mut u,
        &TvParams::new(0.0).unwrap(),
        &mut (),
    )
    .unwrap();
    assert_eq!(u, f);
    assert_eq!(report.termination, Termination::Converged);
    assert_eq!(report.iterations, 0);

    // Where w = 0 the warm start is kept.
    let mut w0 = w.clone();
    w0[[3, 4]] = 0.0;
    let mut u = Array2::from_elem((7, 9), 42.0);
    tv_denoise(
        f.view(),
        w0.view(),
        &mut u,
        &TvParams::new(0.0).unwrap(),
        &mut (),
    )
    .unwrap();
    assert_eq!(u[[3, 4]], 42.0);
    assert_eq!(u[[3, 5]], f[[3, 5]]);
}

/// A two-level step constant along the columns direction: every row is the 1-D problem
/// min ½Σ(v_j − f_j)² + λΣ|v_{j+1} − v_j|, whose solution moves the level of each side towards
/// the other by λ / (its width) (the jump's length M over the side's area M·width), as long as
/// the levels do not cross. Stacking that row solution is optimal for the 2-D problem with
/// either TV, since ‖(0, d)‖ = |d| and the TV of any map is at least the sum of its rows' TVs.
#[test]
fn two_level_step_matches_the_closed_form() {
    let (m, n, k) = (6, 20, 8);
    let (a, b, lambda) = (1.0, 3.0, 2.0);
    let f = Array2::from_shape_fn((m, n), |(_, j)| if j < k { a } else { b });
    let w = Array2::ones((m, n));
    let want_left = a + lambda / k as f64;
    let want_right = b - lambda / (n - k) as f64;
    for norm in [TvNorm::Isotropic, TvNorm::Anisotropic] {
        for steps in [TvSteps::Adaptive, TvSteps::Accelerated, TvSteps::Fixed] {
            // The accelerated steps shrink and only converge sublinearly here.
            let tol = if steps == TvSteps::Accelerated {
                1e-9
            } else {
                1e-11
            };
            let params = tight(lambda, tol, 100_000)
                .with_norm(norm)
                .with_steps(steps);
            let (u, report) = solve(&f, &w, &params);
            assert_eq!(
                report.termination,
                Termination::Residual,
                "{norm:?} {steps:?}"
            );
            for ((_, j), &v) in u.indexed_iter() {
                let want = if j < k { want_left } else { want_right };
                assert!(
                    (v - want).abs() < 1e-4,
                    "{norm:?} {steps:?}: u[.., {j}] = {v}, want {want}"
                );
            }
        }
    }
}

#[test]
fn the_result_beats_the_data_and_perturbations_of_itself() {
    let (m, n) = (16, 21);
    let f = random_map(m, n, 10);
    let w = random_weights(m, n, 11);
    assert!(w.iter().any(|&v| v == 0.0));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
    let normal = Normal::new(0.0, 1.0).unwrap();
    for norm in [TvNorm::Isotropic, TvNorm::Anisotropic] {
        let lambda = 0.2;
        let params = tight(lambda, 1e-9, 50_000).with_norm(norm);
        let (u, report) = solve(&f, &w, &params);
        assert_eq!(report.termination, Termination::Residual);
        let best = objective(&f, &w, &u, lambda, norm);
        let reported = *report.objective_history.last().unwrap();
        assert!(
            (best - reported).abs() <= 1e-12 * best,
            "{best} vs {reported}"
        );
        assert!(best < objective(&f, &w, &f, lambda, norm));
        // The gap certifies P(u) − P* ≤ 1e-9·P(u); allow that much.
        let slack = 1e-9 * best;
        for eps in [1e-1, 1e-2, 1e-3] {
            for _ in 0..20 {
                let v = u.mapv(|x| x + eps * normal.sample(&mut rng));
                let pv = objective(&f, &w, &v, lambda, norm);
                assert!(best <= pv + slack, "{norm:?}, eps {eps}: {best} > {pv}");
            }
            // A perturbation of a single pixel, including pixels without data.
            for idx in [(0, 0), (5, 7), (m - 1, n - 1)] {
                for sign in [-1.0, 1.0] {
                    let mut v = u.clone();
                    v[idx] += sign * eps;
                    let pv = objective(&f, &w, &v, lambda, norm);
                    assert!(best <= pv + slack, "{norm:?}, eps {eps} at {idx:?}");
                }
            }
        }
    }
}

#[test]
fn the_gap_certifies_the_objective() {
    // Against a reference minimum, every iterate of a short run must be within its certified
    // gap.
    // Weights with zeros and positive weights (where the accelerated steps apply).
    let (m, n) = (12, 15);
    let f = random_map(m, n, 20);
    let lambda = 0.3;
    for w in [
        random_weights(m, n, 21),
        random_weights(m, n, 22).mapv(|v| v + 0.2),
    ] {
        // The best objective of a long run is at or above the minimum, so using it only
        // loosens the check, by far less than the gaps of the short runs.
        let (_, reference) = solve(&f, &w, &tight(lambda, 1e-10, 20_000));
        let p_star = reference
            .objective_history
            .iter()
            .fold(f64::INFINITY, |a, &b| a.min(b));
        certified_at_every_iteration(&f, &w, lambda, p_star);
    }
}

fn certified_at_every_iteration(f: &Array2<f64>, w: &Array2<f64>, lambda: f64, p_star: f64) {
    for steps in [TvSteps::Accelerated, TvSteps::Adaptive, TvSteps::Fixed] {
        let params = tight(lambda, 0.0, 60).with_steps(steps);
        let (_, report) = solve(f, w, &params);
        assert_eq!(report.iterations, 60);
        for (k, (&gap, &p)) in report
            .residual_history
            .iter()
            .zip(&report.objective_history)
            .enumerate()
        {
            assert!(gap >= 0.0);
            assert!(
                p - p_star <= gap * p + 1e-12 * p_star,
                "{steps:?}, iteration {}: P − P* = {} above the gap {}",
                k + 1,
                p - p_star,
                gap * p
            );
        }
    }
}

#[test]
fn a_hole_in_a_constant_map_is_filled_with_the_constant() {
    let (m, n) = (15, 18);
    let f = Array2::from_elem((m, n), 3.5);
    let mut w = Array2::ones((m, n));
    w.slice_mut(s![5..10, 6..12]).fill(0.0);
    // The warm start is far off inside the hole.
    let mut u = f.clone();
    u.slice_mut(s![5..10, 6..12]).fill(-100.0);
    tv_denoise(
        f.view(),
        w.view(),
        &mut u,
        &TvParams::new(0.5).unwrap(),
        &mut (),
    )
    .unwrap();
    assert!(u.iter().all(|&v| v == 3.5), "{u:?}");

    // With data elsewhere that is not constant (a bump in a corner), the background level moves
    // a little; the hole takes the level of its surroundings.
    let mut f = f;
    f[[0, 0]] = 4.5;
    let mut u = f.clone();
    u.slice_mut(s![5..10, 6..12]).fill(-100.0);
    tv_denoise(
        f.view(),
        w.view(),
        &mut u,
        &tight(0.5, 1e-10, 20_000),
        &mut (),
    )
    .unwrap();
    let level = u[[m - 1, n - 1]];
    assert!((level - 3.5).abs() < 0.01);
    for &v in u.slice(s![4..11, 5..13]).iter() {
        assert!((v - level).abs() < 1e-6, "{v} vs {level}");
    }
}

#[test]
fn holes_are_filled_between_their_neighbours() {
    // A ramp along the columns and a step along the rows, each with a hole that its values
    // must span.
    let (m, n) = (20, 24);
    let ramp = Array2::from_shape_fn((m, n), |(_, j)| j as f64);
    let step = Array2::from_shape_fn((m, n), |(i, _)| if i < 10 { 1.0 } else { 2.0 });
    let mut w = Array2::ones((m, n));
    w.slice_mut(s![7..13, 8..14]).fill(0.0);
    for (f, lo, hi) in [(ramp, 7.0, 14.0), (step, 1.0, 2.0)] {
        for norm in [TvNorm::Isotropic, TvNorm::Anisotropic] {
            let params = tight(0.05, 1e-9, 20_000).with_norm(norm);
            let mut u = Array2::zeros((m, n));
            tv_denoise(f.view(), w.view(), &mut u, &params, &mut ()).unwrap();
            for &v in u.slice(s![7..13, 8..14]).iter() {
                assert!(
                    v >= lo - 1e-6 && v <= hi + 1e-6,
                    "{norm:?}: {v} not in [{lo}, {hi}]"
                );
            }
        }
    }
}

#[test]
fn denoising_a_noisy_staircase_lowers_the_error() {
    let (m, n) = (40, 50);
    let clean = staircase(m, n);
    let noisy = add_noise(&clean, 0.3, 30);
    let mut w = Array2::ones((m, n));
    // Some pixels without a return: their noisy value is meaningless.
    let mut noisy_holes = noisy.clone();
    for (k, (wi, fi)) in w.iter_mut().zip(noisy_holes.iter_mut()).enumerate() {
        if k % 7 == 3 {
            *wi = 0.0;
            *fi = 1e3;
        }
    }
    let before = rmse(&noisy, &clean);
    for (f, w) in [(&noisy, Array2::ones((m, n))), (&noisy_holes, w)] {
        for norm in [TvNorm::Isotropic, TvNorm::Anisotropic] {
            let params = TvParams::new(0.3).unwrap().with_norm(norm);
            let (u, report) = solve(f, &w, &params);
            let after = rmse(&u, &clean);
            assert!(after < 0.6 * before, "{norm:?}: rmse {before} -> {after}");
            assert!(report.residual_history.last().unwrap() <= &1e-4);
        }
    }
}

#[test]
fn step_rules_reach_the_same_minimizer() {
    let (m, n) = (14, 17);
    let f = staircase(m, n) + random_map(m, n, 40).mapv(|v| 0.2 * v);
    for w in [
        random_weights(m, n, 41),
        random_weights(m, n, 42).mapv(|v| v + 0.1),
    ] {
        let results: Vec<Array2<f64>> = [TvSteps::Accelerated, TvSteps::Adaptive, TvSteps::Fixed]
            .into_iter()
            .map(|steps| solve(&f, &w, &tight(0.25, 1e-11, 50_000).with_steps(steps)).0)
            .collect();
        // Pixels without data may have several minimizers: compare where w > 0.
        for r in &results[1..] {
            for ((a, b), &wi) in r.iter().zip(&results[0]).zip(&w) {
                if wi > 0.0 {
                    assert!((a - b).abs() < 1e-4, "{a} vs {b}");
                }
            }
        }
    }
}

#[test]
fn units_do_not_matter() {
    // u(c·f + d, s·w, c·s·λ) = c·u(f, w, λ) + d.
    let (m, n) = (10, 13);
    let f = random_map(m, n, 50);
    let w = random_weights(m, n, 51);
    let lambda = 0.2;
    let (u, _) = solve(&f, &w, &tight(lambda, 1e-11, 50_000));
    let (c, d, sc) = (250.0, 1200.0, 1e-3);
    let f2 = f.mapv(|v| c * v + d);
    let w2 = w.mapv(|v| sc * v);
    let (u2, report) = solve(&f2, &w2, &tight(c * sc * lambda, 1e-11, 50_000));
    assert_eq!(report.termination, Termination::Residual);
    for ((a, b), &wi) in u2.iter().zip(&u).zip(&w) {
        if wi > 0.0 {
            assert!((a - (c * b + d)).abs() < 1e-4 * c, "{a} vs {}", c * b + d);
        }
    }
}

#[test]
fn views_of_any_layout_are_read_in_logical_order() {
    let f = random_map(9, 11, 60);
    let w = random_weights(9, 11, 61);
    let params = tight(0.2, 1e-9, 20_000);
    let (u, _) = solve(&f, &w, &params);
    // The transposed problem, through strided views and into a column-major output, is the
    // same computation as with contiguous copies.
    let mut ut = Array2::zeros((11, 9).f());
    ut.assign(&f.t());
    tv_denoise(f.t(), w.t(), &mut ut, &params, &mut ()).unwrap();
    let (ut_ref, _) = solve(&f.t().to_owned(), &w.t().to_owned(), &params);
    assert_eq!(ut, ut_ref);
    // Transposing swaps the two difference directions, which both TVs treat alike, so it
    // transposes the minimizer (compared where there is data: it may not be unique elsewhere).
    for ((a, b), &wi) in ut.t().iter().zip(&u).zip(&w) {
        if wi > 0.0 {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
    }
}

#[test]
fn reports_and_observers() {
    let f = staircase(12, 12) + random_map(12, 12, 70).mapv(|v| 0.1 * v);
    let w = random_weights(12, 12, 71);
    let mut seen = 0;
    let mut observer = |info: &IterationInfo<'_, f64>| {
        seen += 1;
        assert_eq!(info.x.len(), 144);
        assert!(info.residual >= 0.0 && info.objective.is_finite());
        // The observer sees the map in its own units (within the data's range).
        assert!(info.x.iter().all(|&v| (-0.2..=3.2).contains(&v)));
        if info.iteration == 7 {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    let mut u = f.clone();
    let params = TvParams::new(0.2).unwrap();
    let report = tv_denoise(f.view(), w.view(), &mut u, &params, &mut observer).unwrap();
    assert_eq!(seen, 7);
    assert_eq!(report.solver, "tv_denoise");
    assert_eq!(report.termination, Termination::Observer);
    assert_eq!(report.iterations, 7);
    assert_eq!(report.forward_applies, 8);
    assert_eq!(report.adjoint_applies, 7);
    assert_eq!(report.residual_history.len(), 7);
    assert_eq!(report.objective_history.len(), 7);

    let (_, report) = solve(
        &f,
        &w,
        &params.with_stopping(Stopping::iterations(5)).unwrap(),
    );
    assert_eq!(report.termination, Termination::MaxIterations);
    assert_eq!(report.iterations, 5);
}

#[test]
fn all_zero_weights_give_the_mean_of_the_warm_start() {
    let f = random_map(5, 6, 80);
    let w = Array2::zeros((5, 6));
    let mut u = random_map(5, 6, 81);
    let mean = u.mean().unwrap();
    let report = tv_denoise(
        f.view(),
        w.view(),
        &mut u,
        &TvParams::new(1.0).unwrap(),
        &mut (),
    )
    .unwrap();
    assert_eq!(report.termination, Termination::Converged);
    assert!(u.iter().all(|&v| v.is_finite() && (v - mean).abs() < 1e-15));
    // Even for huge warm starts.
    let mut u = Array2::from_elem((5, 6), f64::MAX);
    tv_denoise(
        f.view(),
        w.view(),
        &mut u,
        &TvParams::new(1.0).unwrap(),
        &mut (),
    )
    .unwrap();
    assert!(u.iter().all(|v| v.is_finite()));
}

#[test]
fn extreme_scales_stay_finite() {
    let f = random_map(8, 8, 90).mapv(|v| 1e200 * v);
    let w = random_weights(8, 8, 91);
    let (u, _) = solve(&f, &w, &TvParams::new(1e199).unwrap());
    assert!(u.iter().all(|v| v.is_finite()));
    // λ that overflows once normalized: the constant weighted mean.
    let f = random_map(8, 8, 92);
    let w = random_weights(8, 8, 93).mapv(|v| 1e-300 * v);
    let (u, report) = solve(&f, &w, &TvParams::new(1e300).unwrap());
    assert_eq!(report.termination, Termination::Converged);
    let mean = f.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() / w.sum();
    assert!(u.iter().all(|&v| (v - mean).abs() < 1e-12));
}

#[test]
fn a_large_lambda_gives_the_weighted_mean() {
    // From λ = Σ wᵢ|fᵢ − c| on the constant map c is returned directly; just below, the
    // iteration must find (nearly) the same.
    let (m, n) = (7, 9);
    let f = random_map(m, n, 95);
    let w = random_weights(m, n, 96);
    let c = f.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() / w.sum();
    let spread: f64 = f.iter().zip(&w).map(|(a, b)| b * (a - c).abs()).sum();
    let (u, report) = solve(&f, &w, &TvParams::new(spread).unwrap());
    assert_eq!(report.iterations, 0);
    assert!(u.iter().all(|&v| (v - c).abs() < 1e-12));
    for norm in [TvNorm::Isotropic, TvNorm::Anisotropic] {
        let params = tight(0.99 * spread, 1e-10, 50_000).with_norm(norm);
        let (u, report) = solve(&f, &w, &params);
        assert!(report.iterations > 0);
        let best = objective(&f, &w, &u, 0.99 * spread, norm);
        let constant = objective(&f, &w, &Array2::from_elem((m, n), c), 0.99 * spread, norm);
        assert!(best <= constant * (1.0 + 1e-9));
    }
}

fn param_err(r: rdlidar::Result<impl std::fmt::Debug>, name: &str) {
    match r {
        Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
        other => panic!("expected an invalid `{name}`, got {other:?}"),
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let f = Array2::<f64>::zeros((4, 5));
    let w = Array2::<f64>::ones((4, 5));
    let mut u = Array2::<f64>::zeros((4, 5));
    let ok = TvParams::new(0.1).unwrap();
    let run = |f: &Array2<f64>, w: &Array2<f64>, u: &mut Array2<f64>, p: &TvParams| {
        tv_denoise(f.view(), w.view(), u, p, &mut ())
    };

    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        param_err(TvParams::new(bad), "lambda");
        let p = TvParams { lambda: bad, ..ok };
        param_err(run(&f, &w, &mut u, &p), "lambda");
    }
    param_err(ok.with_stopping(Stopping::iterations(0)), "max_iter");
    let p = TvParams {
        stopping: Stopping {
            rel_residual: Some(-1.0),
            ..ok.stopping
        },
        ..ok
    };
    param_err(run(&f, &w, &mut u, &p), "rel_residual");

    for (wb, ub) in [
        ((3, 5), (4, 5)),
        ((4, 6), (4, 5)),
        ((4, 5), (5, 5)),
        ((4, 5), (4, 4)),
    ] {
        let r = run(&f, &Array2::ones(wb), &mut Array2::zeros(ub), &ok);
        assert!(
            matches!(r, Err(Error::ShapeMismatch { .. })),
            "{wb:?} {ub:?}: {r:?}"
        );
    }

    let mut wn = w.clone();
    wn[[1, 2]] = -0.5;
    param_err(run(&f, &wn, &mut u, &ok), "w");
    for bad in [f64::NAN, f64::INFINITY] {
        let mut wn = w.clone();
        wn[[2, 3]] = bad;
        assert!(matches!(
            run(&f, &wn, &mut u, &ok),
            Err(Error::NonFinite { .. })
        ));
        let mut fb = f.clone();
        fb[[0, 4]] = bad;
        assert!(matches!(
            run(&fb, &w, &mut u, &ok),
            Err(Error::NonFinite { .. })
        ));
        let mut ub = u.clone();
        ub[[3, 0]] = bad;
        assert!(matches!(
            run(&f, &w, &mut ub, &ok),
            Err(Error::NonFinite { .. })
        ));
    }

    for shape in [(0, 5), (4, 0), (0, 0)] {
        let e = Array2::<f64>::zeros(shape);
        param_err(run(&e, &e, &mut e.clone(), &ok), "f");
    }
}

proptest! {
    #![proptest_config(crate::common::config(24))]

    /// On random maps, weights with zeros, both TVs and λ: the certified gap is reached and no
    /// small perturbation of the result does better.
    #[test]
    fn random_problems_are_solved_to_their_certificate(
        m in 1..=9usize,
        n in 1..=9usize,
        seed in any::<u64>(),
        lambda in 0.01f64..2.0,
        aniso in any::<bool>(),
    ) {
        let norm = if aniso { TvNorm::Anisotropic } else { TvNorm::Isotropic };
        let f = random_map(m, n, seed);
        let w = random_weights(m, n, seed ^ 7);
        let params = tight(lambda, 1e-9, 100_000).with_norm(norm);
        let (u, report) = solve(&f, &w, &params);
        prop_assert!(u.iter().all(|v| v.is_finite()));
        let best = objective(&f, &w, &u, lambda, norm);
        prop_assert!(best <= objective(&f, &w, &f, lambda, norm) + 1e-12);
        if report.iterations > 0 {
            prop_assert_eq!(report.termination, Termination::Residual);
        }
        let d = random_map(m, n, seed ^ 8);
        for eps in [1e-2, 1e-3] {
            for sign in [-1.0, 1.0] {
                let v = &u + &d.mapv(|x| sign * eps * x);
                prop_assert!(best <= objective(&f, &w, &v, lambda, norm) + 1e-9 * best.max(1e-12));
            }
        }
    }
}
