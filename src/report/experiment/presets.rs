//! The experiments' presets: the demo, the compare sweeps (full, quick, research-size) and their
//! small versions for tests.

use std::path::PathBuf;

use crate::lidar::Geometry;
use crate::recon::Method;

use super::config::{ExperimentConfig, IterationBudgets, Precision, SceneKind, DEFAULT_SOLVERS};

impl ExperimentConfig {
    /// The main job (`rdlidar demo`): the paper's scene 100×100×40, K_p = 10000, 20000, 30000,
    /// noise-free, one seed, the nine methods of [`DEFAULT_SOLVERS`] in f32 with the demo's
    /// budgets ([`ExperimentConfig::demo_budgets`]) and FISTA's step from 15 Lanczos iterations,
    /// written to `out/`.
    pub fn demo() -> Self {
        ExperimentConfig {
            out: PathBuf::from("out"),
            scenes: vec![SceneKind::Paper],
            size: Geometry {
                m: 100,
                n: 100,
                ks: 40,
            },
            lit_fraction: 0.5,
            pulse_lens: vec![10_000, 20_000, 30_000],
            solvers: DEFAULT_SOLVERS.to_vec(),
            snr_db: vec![None],
            seeds: 1,
            seed: 0,
            precision: Precision::F32,
            max_iter: ExperimentConfig::demo_budgets(),
            power_iterations: Some(15),
        }
    }

    /// The demo's iteration budgets: CGLS 15, FISTA 15 (and IHT 15, if added), CoSaMP 1 (each
    /// of its iterations solves a least-squares problem on the merged support), model-based 6
    /// and, for TV and auto, 4 (the limit of each of their model-based fits; TV's neighbourhood
    /// rounds of message passing have their own limits). The backprojections have no
    /// iterations. They keep the demo to a few minutes on two cores (docs/experiments.md has the
    /// timings).
    pub fn demo_budgets() -> IterationBudgets {
        IterationBudgets::from_pairs(&[
            (Method::Cgls, 15),
            (Method::Fista, 15),
            (Method::Iht, 15),
            (Method::Cosamp, 1),
            (Method::ModelBased, 6),
            (Method::Tv, 4),
            (Method::Auto, 4),
        ])
    }

    /// The demo at a size a test runs in seconds: the paper scene 8×8×8 (critical K_p 505) with
    /// K_p = 100, 300 and 1000 (compressive to redundant), written to `out-tiny/`.
    pub fn demo_tiny() -> Self {
        ExperimentConfig {
            out: PathBuf::from("out-tiny"),
            size: Geometry { m: 8, n: 8, ks: 8 },
            pulse_lens: vec![100, 300, 1000],
            ..ExperimentConfig::demo()
        }
    }

    /// The full sweep (`rdlidar compare`): the paper scene 16×16×16 (critical K_p 4081), K_p
    /// from 256 to 32768 (compressive, critical, redundant), 3 seeds, noise-free and 20 and
    /// 10 dB SNR, the nine methods with their default iteration limits, in f64, written to
    /// `out-compare/`.
    pub fn compare() -> Self {
        ExperimentConfig {
            out: PathBuf::from("out-compare"),
            scenes: vec![SceneKind::Paper],
            size: Geometry {
                m: 16,
                n: 16,
                ks: 16,
            },
            lit_fraction: 0.5,
            pulse_lens: vec![256, 512, 1024, 2048, 3072, 4081, 6144, 8192, 16384, 32768],
            solvers: DEFAULT_SOLVERS.to_vec(),
            snr_db: vec![None, Some(20.0), Some(10.0)],
            seeds: 3,
            seed: 0,
            precision: Precision::F64,
            max_iter: IterationBudgets::none(),
            power_iterations: None,
        }
    }

    /// `compare --quick`: the same scene and solvers, K_p = 512 … 16384 (6 lengths around the
    /// critical 4081), 2 seeds, noise-free and 20 dB.
    pub fn compare_quick() -> Self {
        ExperimentConfig {
            pulse_lens: vec![512, 1024, 2048, 4081, 8192, 16384],
            snr_db: vec![None, Some(20.0)],
            seeds: 2,
            ..ExperimentConfig::compare()
        }
    }

    /// `compare --research`: the sweep at a research size. The paper scene and a
    /// semi-transparent one (1 to 3 returns per pixel) on 32×32×40 (critical K_p 40921), K_p =
    /// 2000, 4000, 8000, 16000 (compressive), 40921 (critical) and 81842 (2× redundant),
    /// noise-free and 20 and 10 dB SNR, 2 seeds, the nine methods of [`DEFAULT_SOLVERS`] and
    /// support-ls, in f64, written to `out-research/`.
    pub fn compare_research() -> Self {
        let size = Geometry {
            m: 32,
            n: 32,
            ks: 40,
        };
        let critical = size.critical_pulse_len();
        let mut solvers = DEFAULT_SOLVERS.to_vec();
        solvers.insert(solvers.len() - 1, Method::SupportLs);
        ExperimentConfig {
            out: PathBuf::from("out-research"),
            scenes: vec![SceneKind::Paper, SceneKind::Transparent],
            size,
            pulse_lens: vec![2000, 4000, 8000, 16_000, critical, 2 * critical],
            solvers,
            snr_db: vec![None, Some(20.0), Some(10.0)],
            seeds: 2,
            ..ExperimentConfig::compare()
        }
    }

    /// `compare --tiny`, for tests: the paper scene 6×6×6 (critical K_p 211), K_p = 50, 211 and
    /// 800, 2 seeds, noise-free and 20 dB, written to `out-compare-tiny/`.
    pub fn compare_tiny() -> Self {
        ExperimentConfig {
            out: PathBuf::from("out-compare-tiny"),
            size: Geometry { m: 6, n: 6, ks: 6 },
            pulse_lens: vec![50, 211, 800],
            ..ExperimentConfig::compare_quick()
        }
    }
}
