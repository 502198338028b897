//! The experiment runner as a library: events, the stop flag, the partial files and the
//! outputs of a stopped sweep.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use rdlidar::recon::Method;
use rdlidar::report::experiment::{
    run_compare, run_demo, Event, ExperimentConfig, ExperimentObserver, Row, SceneKind,
};

fn temp_dir(tag: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("rdlidar-exp-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    p
}

/// Records the events, checks the partial CSV as rows finish, and raises the stop flag after
/// `stop_after` rows.
struct Recorder<'a> {
    stop: &'a AtomicBool,
    stop_after: usize,
    partial: PathBuf,
    planned: Option<usize>,
    started: usize,
    rows: Vec<Row>,
}

impl ExperimentObserver for Recorder<'_> {
    fn event(&mut self, event: &Event<'_>) {
        match event {
            Event::Planned { runs, work, .. } => {
                assert!(*work > 0.0);
                self.planned = Some(*runs);
            }
            Event::RunStarted { index, .. } => {
                assert_eq!(*index, self.started);
                self.started += 1;
            }
            Event::RunFinished { row, .. } => {
                self.rows.push((*row).clone());
                // The row is already in the partial file, flushed.
                let text = std::fs::read_to_string(&self.partial).unwrap();
                assert_eq!(text.lines().count(), self.rows.len() + 1);
                if self.rows.len() == self.stop_after {
                    self.stop.store(true, Ordering::SeqCst);
                }
            }
            _ => {}
        }
    }
}

#[test]
fn a_stopped_sweep_writes_the_finished_rows_and_reports_it() {
    let dir = temp_dir("stop");
    let config = ExperimentConfig {
        out: dir.clone(),
        solvers: vec![Method::Backprojection, Method::Cgls, Method::ModelBased],
        ..ExperimentConfig::compare_tiny()
    };
    let stop = AtomicBool::new(false);
    let mut rec = Recorder {
        stop: &stop,
        stop_after: 5,
        // Rows go to the staging folder beside the output folder until the end.
        partial: dir
            .parent()
            .unwrap()
            .join(format!(
                ".{}.staging-{}",
                dir.file_name().unwrap().to_string_lossy(),
                std::process::id()
            ))
            .join("results.csv.partial"),
        planned: None,
        started: 0,
        rows: Vec::new(),
    };
    let outcome = run_compare(&config, false, &mut rec, &stop).unwrap();
    assert_eq!(rec.planned, Some(36));
    assert_eq!(outcome.planned, 36);
    assert!(outcome.interrupted);
    assert_eq!(outcome.rows.len(), 5);
    assert_eq!(outcome.rows, rec.rows);
    assert_eq!(rec.started, 5);
    let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 6);
    assert!(dir.join("pareto.png").is_file() && dir.join("phase_noise-free.png").is_file());
    // Only the first noise level had finished runs.
    assert!(!dir.join("phase_20db.png").exists());
    assert!(!dir.join("results.csv.partial").exists());
    for f in &outcome.files {
        assert!(f.is_file(), "{}", f.display());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn runs_are_reproducible_and_follow_the_configured_order() {
    let dir = temp_dir("order");
    let config = ExperimentConfig {
        out: dir.clone(),
        pulse_lens: vec![300, 100],
        solvers: vec![Method::ModelBased, Method::BackprojectionDebiased],
        ..ExperimentConfig::demo_tiny()
    };
    let never = AtomicBool::new(false);
    let a = run_demo(&config, false, &mut (), &never).unwrap();
    let order: Vec<(usize, &str)> = a
        .rows
        .iter()
        .map(|r| (r.pulse_len, r.solver.as_str()))
        .collect();
    assert_eq!(
        order,
        [
            (300, "model-based"),
            (300, "backprojection-debiased"),
            (100, "model-based"),
            (100, "backprojection-debiased")
        ]
    );
    // Without force an existing folder is refused; with it the same rows come back.
    assert!(run_demo(&config, false, &mut (), &never).is_err());
    let b = run_demo(&config, true, &mut (), &never).unwrap();
    let strip = |rows: &[Row]| -> Vec<Row> {
        rows.iter()
            .map(|r| Row {
                time_s: 0.0,
                ..r.clone()
            })
            .collect()
    };
    assert_eq!(strip(&a.rows), strip(&b.rows));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_invalid_configuration_is_refused_before_the_folder_is_made() {
    let dir = temp_dir("invalid");
    let config = ExperimentConfig {
        out: dir.clone(),
        solvers: vec![],
        ..ExperimentConfig::demo_tiny()
    };
    let e = run_demo(&config, false, &mut (), &AtomicBool::new(false)).unwrap_err();
    assert!(e.to_string().contains("solvers"), "{e}");
    assert!(!dir.exists());
}

#[test]
fn several_scenes_get_their_own_rows_summaries_and_figures() {
    let dir = temp_dir("scenes");
    let config = ExperimentConfig {
        out: dir.clone(),
        scenes: vec![SceneKind::Transparent, SceneKind::Paper],
        pulse_lens: vec![211, 800],
        snr_db: vec![None],
        seeds: 1,
        solvers: vec![Method::BackprojectionDebiased, Method::Cgls],
        ..ExperimentConfig::compare_tiny()
    };
    let outcome = run_compare(&config, false, &mut (), &AtomicBool::new(false)).unwrap();
    assert_eq!(outcome.planned, 8);
    // Scenes in the configured order, each with every pulse length and solver.
    let scenes: Vec<&str> = outcome.rows.iter().map(|r| r.scene.as_str()).collect();
    assert_eq!(scenes[..4], ["transparent"; 4]);
    assert_eq!(scenes[4..], ["paper"; 4]);
    for r in &outcome.rows {
        let returns = r.returns_exact.unwrap() + r.returns_false.unwrap();
        assert!(returns > 0, "{r:?}");
        if r.scene == "paper" {
            assert_eq!(r.true_returns, r.lit, "{r:?}");
        } else {
            // 1 to 3 returns on every pixel of 6×6.
            assert!(r.true_returns > r.lit && r.lit == 36, "{r:?}");
        }
    }
    // CGLS is exact in the redundant regime: every return at its voxel.
    let cgls = outcome
        .rows
        .iter()
        .find(|r| r.scene == "transparent" && r.pulse_len == 800 && r.solver == "cgls")
        .unwrap();
    assert_eq!(cgls.returns_exact, Some(cgls.true_returns), "{cgls:?}");
    for f in [
        "pareto_paper.png",
        "pareto_transparent.png",
        "phase_paper_noise-free.png",
        "phase_transparent_noise-free.png",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    assert!(!dir.join("pareto.png").exists());
    let summary = std::fs::read_to_string(dir.join("summary.md")).unwrap();
    let transparent = summary.find("# compare: transparent scene").unwrap();
    let paper = summary.find("# compare: paper scene").unwrap();
    assert!(transparent < paper, "{summary}");
    // Only the semi-transparent scene has the table of returns.
    let returns = summary.find("returns found at their voxel").unwrap();
    assert!(returns > transparent && returns < paper, "{summary}");
    assert_eq!(summary.matches("returns found at their voxel").count(), 1);
    // The resolved configuration lists both scenes and loads again.
    let toml = std::fs::read_to_string(dir.join("config.toml")).unwrap();
    assert!(
        toml.contains(r#"scene = ["transparent", "paper"]"#),
        "{toml}"
    );
    let file = rdlidar::report::experiment::ConfigFile::parse(&toml).unwrap();
    let again = ExperimentConfig::compare_tiny().patched(file.compare.as_ref().unwrap());
    assert_eq!(again.scenes, config.scenes);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn scene_lists_are_checked() {
    let config = ExperimentConfig {
        scenes: vec![SceneKind::Paper, SceneKind::Paper],
        ..ExperimentConfig::compare_tiny()
    };
    let e = config.validate().unwrap_err().to_string();
    assert!(e.contains("scene") && e.contains("twice"), "{e}");
    let config = ExperimentConfig {
        scenes: vec![],
        ..config
    };
    assert!(config.validate().unwrap_err().to_string().contains("empty"));
    let e = rdlidar::report::experiment::parse_scenes("paper,glass").unwrap_err();
    assert!(e.to_string().contains("glass"), "{e}");
    let research = ExperimentConfig::compare_research();
    assert_eq!(research.size.critical_pulse_len(), 40921);
    assert!(research.pulse_lens.contains(&81842) && research.snr_db.len() == 3);
    assert!(research.solvers.contains(&Method::SupportLs));
}
