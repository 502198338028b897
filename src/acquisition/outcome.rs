//! What a reconstruction produced, told once for every front end: the estimate, and a
//! serializable [`Summary`] of what ran with the lines that describe it (the Python package
//! returns the summary as a dict, the command line prints its lines).

use serde::Serialize;

use super::*;
use crate::lidar::Returns;
use crate::operator::Applies;
use crate::recon::{DetectionTest, PhotonWeighting, Stage, TilePlace};
use crate::solver::{Report, Termination};

/// A finished reconstruction: the estimate and what ran.
#[derive(Debug, Clone)]
pub struct Outcome<T> {
    /// Every return found.
    pub scene: Scene<T>,
    /// The depth map (unobserved pixels filled when the request asked for it).
    pub depth: DepthMap<T>,
    /// Every return's amplitude and continuous depth, under a response other than delta (a
    /// tiled array's tiles stitched).
    pub returns: Option<Returns>,
    /// What ran, and its lines.
    pub summary: Summary,
}

/// What a reconstruction ran, whatever the architecture. It serializes with its fields' names,
/// [`Run`]'s beside the others (a tiled array's run sums its tiles').
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// The method asked for.
    pub method: Method,
    /// `"single"`, `"multi_adc"` or `"tiles"`.
    pub architecture: &'static str,
    /// Unobserved pixels filled with a return from their neighbours.
    pub filled: usize,
    /// Samples left out of the fit as clipped, when the request named clipped samples.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub censored: Option<usize>,
    /// Per ADC row, the bounds at and beyond which samples were left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub censored_levels: Option<Vec<(f64, f64)>>,
    /// What ran: for a tiled array, the tiles' methods, with their iterations and
    /// applications summed.
    #[serde(flatten)]
    pub run: Run,
    /// Every tile's run, for a tiled array.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tiles: Option<Vec<TileRun>>,
    /// One line: the method and its regime, the work, the time and the pixels with a return.
    pub headline: String,
    /// The lines that follow it: auto's stages, the photon-noise weighting, the
    /// false-detection test, the filled pixels.
    pub details: Vec<String>,
}

/// What one reconstruction (of the whole array or of a tile) ran.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Run {
    /// The method that produced the estimate (for a tiled array: `"cgls on 4, …"`).
    pub method_used: String,
    /// The regime of the pulse length.
    pub regime: String,
    /// Wall-clock time of the whole reconstruction.
    pub seconds: f64,
    /// The iterative solver's name (none for a backprojection or a tiled array).
    pub solver: Option<&'static str>,
    /// Iterations (summed over the stages of auto and over the tiles).
    pub iterations: usize,
    /// Why the solver stopped (none for a backprojection or a tiled array).
    pub termination: Option<Termination>,
    /// Relative residual after each iteration.
    pub residual_history: Vec<f64>,
    /// Objective after each iteration (NaN where not computed).
    pub objective_history: Vec<f64>,
    /// The solvers' time.
    pub solver_seconds: f64,
    /// Forward applications of the operator.
    pub forward_applies: usize,
    /// Adjoint applications.
    pub adjoint_applies: usize,
    /// Applications restricted to a few columns.
    pub support_applies: usize,
    /// What auto tried, in order.
    pub stages: Vec<Stage>,
    /// What the false-detection test did, when it was asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detection: Option<DetectionTest>,
    /// What the photon-noise weighting found, under the photon-noise model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub photon: Option<PhotonWeighting>,
}

/// A tile's place and run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TileRun {
    /// The tile's number, row by row.
    pub index: usize,
    /// Its first pixel row.
    pub row: usize,
    /// Its first pixel column.
    pub col: usize,
    /// Its pixel rows and columns.
    pub shape: (usize, usize),
    /// What ran on it.
    #[serde(flatten)]
    pub run: Run,
}

impl Run {
    /// What `r` ran.
    fn of<T: Real>(r: &Reconstruction<T>) -> Run {
        let applies = single_applies(r);
        let report = r.report.as_ref();
        Run {
            method_used: r.method_used.name().to_string(),
            regime: r.regime.to_string(),
            seconds: r.elapsed.as_secs_f64(),
            solver: report.map(|rep| rep.solver),
            iterations: report.map_or(0, |rep| rep.iterations),
            termination: report.map(|rep| rep.termination),
            residual_history: report.map_or_else(Vec::new, |rep| rep.residual_history.clone()),
            objective_history: report.map_or_else(Vec::new, |rep| rep.objective_history.clone()),
            solver_seconds: report.map_or(0.0, |rep| rep.elapsed.as_secs_f64()),
            forward_applies: applies.forward,
            adjoint_applies: applies.adjoint,
            support_applies: applies.support,
            stages: r.stages.clone(),
            detection: r.detection.clone(),
            photon: r.photon.as_deref().cloned(),
        }
    }

    /// The line's work: iterations and applications.
    fn work(&self, tiled: bool) -> String {
        let counts = format!(
            "{} forward, {} adjoint and {} support applications",
            self.forward_applies, self.adjoint_applies, self.support_applies
        );
        match self.termination {
            _ if tiled => format!("{counts} in all"),
            Some(t) => format!(
                "{} iterations, termination {t:?}, {counts}",
                self.iterations
            ),
            None => "one adjoint application".to_string(),
        }
    }
}

/// The applications of one reconstruction: its report's, one adjoint for a backprojection.
pub(super) fn single_applies<T>(r: &Reconstruction<T>) -> Applies {
    r.report.as_ref().map_or(
        Applies {
            adjoint: 1,
            ..Applies::default()
        },
        Report::applies,
    )
}

impl<T: Real> TileReconstruction<T> {
    /// The line told as the tile finishes, the `done`-th of `count`: where it lies, what ran,
    /// how long it took.
    pub fn describe(&self, done: usize, count: usize) -> String {
        let (p, r) = (&self.place, &self.reconstruction);
        format!(
            "tile {done}/{count} (#{}, rows {}..{}, columns {}..{}): {}, {} of {} pixels with a \
             return, {:.2} s",
            p.index,
            p.row,
            p.row + p.geometry.m,
            p.col,
            p.col + p.geometry.n,
            r.method_used,
            r.depth.lit(),
            p.geometry.pixels(),
            r.elapsed.as_secs_f64()
        )
    }
}

impl ReconstructRequest {
    /// Completes the reconstruction `r` of `acq` as the request asks (fills its unobserved
    /// pixels from their neighbours under [`fill_unobserved`](Self::fill_unobserved)) and
    /// tells what ran; `censoring` is what [`censor`](Self::censor) left out.
    pub fn finish<T: Real>(
        &self,
        r: Reconstructed<T>,
        acq: &Acquisition,
        censoring: Option<&Censoring>,
    ) -> Outcome<T> {
        let kp = acq.pulse_len();
        let returns = match &r {
            Reconstructed::Single(r) => r.returns.as_deref().cloned(),
            Reconstructed::Tiled(t) => stitched_returns(t),
        };
        let (scene, mut depth, run, tiles, chosen, mut details) = match r {
            Reconstructed::Single(r) => {
                let run = Run::of(&r);
                let chosen = if r.stages.is_empty() {
                    format!("{} ({} regime)", r.method_used, r.regime)
                } else {
                    format!(
                        "{} (auto: {} regime, K_p {kp}, critical K_p {})",
                        r.method_used,
                        r.regime,
                        r.scene.geometry().critical_pulse_len()
                    )
                };
                let details = single_details(&run);
                (r.scene, r.depth, run, None, chosen, details)
            }
            Reconstructed::Tiled(r) => {
                let tile = match acq.architecture() {
                    Architecture::Tiles(t) => t,
                    _ => TileSize { m: 1, n: 1 },
                };
                let (run, tiles, chosen, details) = tiled_run(&r, tile, kp);
                (r.scene, r.depth, run, Some(tiles), chosen, details)
            }
        };
        let unobserved = depth.unobserved();
        let filled = if self.fill_unobserved && unobserved > 0 {
            let n = depth.fill_unobserved();
            details.push(format!(
                "filled {n} of the {unobserved} unobserved pixels with a return from their \
                 neighbours"
            ));
            n
        } else {
            0
        };
        let headline = format!(
            "solver {chosen}; {}; {:.3} s; {} of {} pixels with a return",
            run.work(tiles.is_some()),
            run.seconds,
            depth.lit(),
            depth.depth.len()
        );
        let summary = Summary {
            method: self.method,
            architecture: acq.architecture().kind(),
            filled,
            censored: censoring.map(Censoring::total),
            censored_levels: censoring.map(|c| c.levels.clone()),
            run,
            tiles,
            headline,
            details,
        };
        Outcome {
            scene,
            depth,
            returns,
            summary,
        }
    }
}

/// The tiles' returns in the whole array (`None` when a tile has none).
fn stitched_returns<T>(t: &TiledReconstruction<T>) -> Option<Returns> {
    let (m, n) = t.depth.depth.dim();
    let parts: Vec<(&TilePlace, &Returns)> = t
        .tiles
        .iter()
        .map(|tile| Some((&tile.place, tile.reconstruction.returns.as_deref()?)))
        .collect::<Option<_>>()?;
    let layers = parts.iter().map(|p| p.1.layers()).max().unwrap_or(1);
    let mut depth = ndarray::Array3::from_elem((layers, m, n), f64::NAN);
    let mut amplitude = ndarray::Array3::zeros((layers, m, n));
    for (place, r) in parts {
        let (q, tm, tn) = r.depth.dim();
        for l in 0..q {
            for i in 0..tm {
                for j in 0..tn {
                    depth[[l, place.row + i, place.col + j]] = r.depth[[l, i, j]];
                    amplitude[[l, place.row + i, place.col + j]] = r.amplitude[[l, i, j]];
                }
            }
        }
    }
    Some(Returns { depth, amplitude })
}

/// The lines after the headline of one reconstruction: auto's stages, the photon-noise
/// weighting, the false-detection test.
fn single_details(run: &Run) -> Vec<String> {
    run.stages
        .iter()
        .enumerate()
        .map(|(i, stage)| format!("auto stage {}: {stage}", i + 1))
        .chain(run.photon.as_ref().map(PhotonWeighting::describe))
        .chain(run.detection.as_ref().map(DetectionTest::describe))
        .collect()
}

/// A tiled array's run (the tiles' summed), its tiles' runs, the method chosen and the lines
/// on the tiles' tests.
fn tiled_run<T: Real>(
    r: &TiledReconstruction<T>,
    tile: TileSize,
    kp: usize,
) -> (Run, Vec<TileRun>, String, Vec<String>) {
    let used: Vec<String> = r
        .methods_used()
        .iter()
        .map(|(m, n)| format!("{m} on {n}"))
        .collect();
    let method = used.join(", ");
    let largest = r
        .tiles
        .iter()
        .map(|t| t.place.geometry)
        .max_by_key(|g| g.pixels());
    let chosen = format!(
        "{method} of {} tiles of {tile} ({} regime per tile, K_p {kp}{})",
        r.tiles.len(),
        r.regime(),
        largest.map_or(String::new(), |g| format!(
            ", critical K_p {} for the largest tile",
            g.critical_pulse_len()
        ))
    );
    let tiles: Vec<TileRun> = r
        .tiles
        .iter()
        .map(|t| TileRun {
            index: t.place.index,
            row: t.place.row,
            col: t.place.col,
            shape: (t.place.geometry.m, t.place.geometry.n),
            run: Run::of(&t.reconstruction),
        })
        .collect();
    let applies = r.applies();
    let run = Run {
        method_used: method,
        regime: r.regime().to_string(),
        seconds: r.elapsed.as_secs_f64(),
        solver: None,
        iterations: tiles.iter().map(|t| t.run.iterations).sum(),
        termination: None,
        residual_history: Vec::new(),
        objective_history: Vec::new(),
        solver_seconds: tiles.iter().map(|t| t.run.solver_seconds).sum(),
        forward_applies: applies.forward,
        adjoint_applies: applies.adjoint,
        support_applies: applies.support,
        stages: Vec::new(),
        detection: None,
        photon: None,
    };
    // The tests ran in each tile: their sums over the tiles that report them.
    let tests: Vec<&DetectionTest> = tiles
        .iter()
        .filter_map(|t| t.run.detection.as_ref())
        .collect();
    let weighted: Vec<&PhotonWeighting> =
        tiles.iter().filter_map(|t| t.run.photon.as_ref()).collect();
    let mut details = Vec::new();
    if let Some(first) = tests.first() {
        details.push(format!(
            "false-detection test at α = {} in {} of {} tiles: dropped {} of {} returns ({} \
             tiles not tested)",
            first.false_rate,
            tests.len(),
            tiles.len(),
            tests.iter().map(|t| t.dropped).sum::<usize>(),
            tests.iter().map(|t| t.tested).sum::<usize>(),
            tests.iter().filter(|t| t.skipped.is_some()).count()
        ));
    }
    if !weighted.is_empty() {
        details.push(format!(
            "photon-noise weighting in {} of {} tiles: reweighted {}",
            weighted.len(),
            tiles.len(),
            weighted.iter().filter(|p| p.skipped.is_none()).count()
        ));
    }
    (run, tiles, chosen, details)
}
