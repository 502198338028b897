//! `rdlidar reconstruct`: a depth map and a scene from files, by any solver.

use std::path::PathBuf;

use ndarray_npy::WritableElement;
use rdlidar::acquisition::{
    at_top, observe_nothing, pulse_in, Acquisition, Censoring, Clipping, ReconstructRequest,
    Reconstructed, Use, RECONSTRUCT_SCENES,
};
use rdlidar::io::{self, StagedFile};
use rdlidar::lidar::{
    depth_bin_m, Camera, Response, Returns, Scene, TileSize, DEFAULT_TAU_S, UNOBSERVED,
};
use rdlidar::recon::{
    compare, compare_observed, Method, NoiseModel, PeakThreshold, ReconstructOptions,
    TileReconstruction, MAX_RETURNS_ESTIMATE,
};
use rdlidar::settings::FrontEnd;
use rdlidar::Real;

use crate::common::{
    architecture_note, at_pulse, check_distinct_outputs, check_out_file, errln, npy_dtype, outln,
    parse_positive, parse_tile, with_precision, CliResult, Globals, MeasurementFiles,
};
use crate::ranks::Ranks;

/// Reconstruct the scene from measurements: a depth map and the returns found.
///
/// Reads the pulse (K_p,), the codes (M, N, K) and the measurements (K,), with
/// K = K_p + K_s − 1, runs the solver and writes the depth map (M, N) int32 (−1 = no return)
/// to --out-depth (each pixel's strongest return) and the scene (M, N, K_s), with every return
/// the solver found, to --out-scene, with the dtype of --precision.
/// The files (and the --png image) are written together: on any error none is left behind.
///
/// Solvers: backprojection (the paper's: adjoint, per-pixel peak, --threshold),
/// backprojection-debiased (zero-mean pulse), cgls (least squares), fista (nonnegative lasso,
/// debiased by least squares on its support), iht and cosamp (sparsity estimated from the
/// debiased backprojection), support-ls (greedy support pursuit with least squares), amp
/// (message passing with the one-reflector prior), model-based (one reflector per pixel, or
/// --returns K), tv (TV on the depth map) and auto, which escalates from the cheapest:
/// support-ls; then, when K ≥ M·N·K_s, model-based and cgls; otherwise tv, then model-based;
/// and where several returns per pixel show (in the pursuit's support or in what the
/// one-reflector fit leaves), model-based with k returns and fista. It keeps the first fit
/// that explains the data (with noise, the best by an information criterion) and prints each
/// stage it ran and why.
///
/// Every architecture of `simulate`: G code sets (G, M, N, K) with measurements (G, K) are
/// reconstructed through the stacked operator of the G ADCs (every solver, auto too); with
/// --tiles AxB the measurements (T, K) hold one row per tile, and each tile is reconstructed
/// on its own grid, in parallel (a line per tile as it finishes), then stitched; a coded
/// aperture's codes (zero codes for blocked pixels) read as one code set, and its blocked
/// pixels are unobserved: −2 in the depth map, judged apart under --truth, and filled from
/// their neighbours with --fill-unobserved.
///
/// With --truth SCENE.npy the estimate is compared with the true scene (exact depths,
/// RMSE, misses, false detections, relative error; τ = 200 ps per bin).
///
/// Example: `rdlidar reconstruct --pulse run0/pulse.npy --codes run0/codes.npy --meas run0/meas.npy --depth-bins 40 --solver auto --out-depth d.npy --out-scene xh.npy --png d.png --truth run0/scene.npy`
#[derive(clap::Args, Debug)]
pub struct ReconstructArgs {
    #[command(flatten)]
    pub files: MeasurementFiles,
    /// Reconstruction method.
    #[arg(long, value_name = "NAME", value_parser = parse_method)]
    pub solver: Method,
    /// Output depth map (M, N), int32, −1 = no return, −2 = unobserved (a pixel with all-zero
    /// codes, blocked by a coded aperture).
    #[arg(long, value_name = "D")]
    pub out_depth: PathBuf,
    /// Output scene (M, N, K_s), float32 or float64 as --precision.
    #[arg(long, value_name = "XH")]
    pub out_scene: PathBuf,
    /// Overrides the solver's iteration limit.
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub max_iter: Option<usize>,
    /// The system's response g the scene was made with (a reflector of amplitude a at depth d
    /// fills its voxel column with a·g(k − d)): delta (depths on the grid, the default),
    /// triangle, gaussian:S or measured:O:FILE, as `simulate --kernel` takes it. With a kernel
    /// other than delta every return's amplitude and continuous depth are estimated under it
    /// (--out-range): model-based and tv pick each pixel's return from the response shifted by
    /// 1/8 bin (tv with its neighbours' surfaces), the other methods start from their grid
    /// estimate, auto runs tv and, where it leaves the data unexplained, the grid's start too.
    #[arg(long, value_name = "SPEC", value_parser = crate::simulate::parse_kernel)]
    pub kernel: Option<Response>,
    /// With --kernel: write the estimated depths in bins, float64 (M, N), NaN where there is no
    /// return (a leading axis of returns where a pixel has several).
    #[arg(long, value_name = "R.npy")]
    pub out_range: Option<PathBuf>,
    /// Also write the depth map as a PNG image (with the true one beside it under --truth).
    #[arg(long, value_name = "D.png")]
    pub png: Option<PathBuf>,
    /// The true scene (M, N, K_s): print how well the estimate matches it.
    #[arg(long, value_name = "SCENE")]
    pub truth: Option<PathBuf>,
    /// With --kernel: the true continuous depths (`simulate`'s range.npy: bins, NaN where there
    /// is no return, a leading axis of returns where there are several). Prints the depth
    /// error over the true returns, the returns missed and false and, with --truth for the
    /// true amplitudes, the Cramér–Rao bound beside it (RMSE/bound).
    #[arg(long, value_name = "R.npy")]
    pub truth_range: Option<PathBuf>,
    /// With --truth and --truth-range: the noise's standard deviation per sample that the bound
    /// assumes (`simulate`'s meta.json, noise.sigma); by default the one the estimate's residual
    /// shows.
    #[arg(long, value_name = "S", requires_all = ["truth_range", "truth"], allow_hyphen_values = true, value_parser = parse_noise_sigma)]
    pub noise_sigma: Option<f64>,
    /// Write every return as a point cloud: a binary PLY file of x, y, z in metres (a pinhole
    /// camera at the origin looking along +z, x right, y down) along each pixel's ray at the
    /// range its depth gives, intensity its amplitude, and its pixel row and column. Needs the
    /// camera: --fov, or --pixel-pitch and --focal-length. Continuous depths under --kernel,
    /// otherwise every nonzero voxel of the estimate at its bin.
    #[arg(long, value_name = "P.ply")]
    pub out_points: Option<PathBuf>,
    /// The field of view across the N pixel columns, in degrees, and down the M rows as HxV
    /// (square pixels when only H is given), for --out-points.
    #[arg(long, value_name = "H[xV]", value_parser = parse_fov, conflicts_with_all = ["pixel_pitch", "focal_length"])]
    pub fov: Option<(f64, Option<f64>)>,
    /// The pixel pitch, in the unit of --focal-length, for --out-points.
    #[arg(long, value_name = "P", requires = "focal_length", value_parser = parse_length)]
    pub pixel_pitch: Option<f64>,
    /// The focal length, in the unit of --pixel-pitch, for --out-points.
    #[arg(long, value_name = "F", requires = "pixel_pitch", value_parser = parse_length)]
    pub focal_length: Option<f64>,
    /// The sampling period τ (200ps by default): one depth bin is c·τ/2, the unit of the
    /// metres and millimetres that --truth and --truth-range print and of --out-points.
    #[arg(long, value_name = "T", value_parser = parse_tau_flag)]
    pub tau: Option<f64>,
    /// Which per-pixel peaks the backprojections keep: paper (0.4 times the 99th percentile of the
    /// per-pixel peaks, as in the paper's Fig. 2) or robust (median + 3σ of all values: fewer
    /// false returns on noisy or sparsely lit scenes).
    #[arg(long, value_name = "RULE", value_parser = parse_threshold, default_value = "paper")]
    pub threshold: PeakThreshold,
    /// Keep FISTA's lasso amplitudes: skip the least squares on its support that removes their
    /// shrinkage.
    #[arg(long)]
    pub no_debias: bool,
    /// Returns per pixel at most for the model-based solver: a count from 1 to 8 (1: the
    /// one-reflector model), or auto to estimate it from a support pursuit (the count that 99%
    /// of its lit pixels do not exceed).
    #[arg(long, value_name = "K|auto", value_parser = parse_returns, default_value = "1")]
    pub returns: MaxReturns,
    /// Fill the depth map's unobserved pixels (a coded aperture's blocked pixels, −2) from their
    /// neighbours: the median depth of their lit 8-neighbours where at least half of the
    /// decided neighbours are lit, no return (−1) otherwise, repeated inwards over larger
    /// holes. The scene keeps only the returns the solver found.
    #[arg(long)]
    pub fill_unobserved: bool,
    /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`): the measurements
    /// are (T, K), one row per tile, and the tiles are reconstructed independently.
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    pub tiles: Option<TileSize>,
    /// Codes described by a seed (meta.json) of one ADC: regenerate them block by block on every
    /// application instead of holding them (automatic when holding them would take over 1 GiB).
    #[arg(long)]
    pub stream_codes: bool,
    /// Samples the ADC clipped, left out of the data term (censored): those with |y| ≥ LEVEL
    /// (the ADC's top code, half a step below a mid-rise ADC's full scale), or with top those
    /// at each ADC's largest and smallest y (its top and bottom codes).
    /// A clipped sample only bounds the scene; fitting its value pulls the amplitudes down
    /// and leaves returns to explain the rest. The codes of the pixels each ADC sums become 0
    /// at its censored samples (ternary codes), held in memory.
    #[arg(long, value_name = "LEVEL|top", value_parser = parse_clipping)]
    pub clipped: Option<Clipping>,
    /// A false-detection rate α in (0, 1): after the solver, keep only the returns whose
    /// least-squares amplitude passes the test at which an empty pixel shows a false return
    /// with probability at most α under white Gaussian noise (the bar Q⁻¹(α/K_s) standard
    /// errors), refitted by least squares. It holds the rate where the residual is noise
    /// (several measurements per return); with a few per lit pixel it does not.
    #[arg(long, value_name = "ALPHA", value_parser = parse_false_rate)]
    pub false_rate: Option<f64>,
    /// The noise model that sets the data term: gaussian (one variance for every sample:
    /// least squares) or photon (each sample's variance proportional to the light it receives
    /// plus --background: the solver runs, its estimate gives every sample's light, and when its
    /// residual's variance grows with the light the estimate is refined (per-pixel solvers) or
    /// solved again (generic ones) on the samples weighted by 1/√variance; needs the codes in
    /// memory and the whole scene in one process).
    #[arg(long, value_name = "MODEL", value_parser = parse_noise, default_value = "gaussian")]
    pub noise: NoiseModel,
    /// With --noise photon: the ambient light and dark counts per sample, in the units of the
    /// scene's light (those of `simulate --background`; default 0).
    #[arg(long, value_name = "B", value_parser = parse_background)]
    pub background: Option<f64>,
}

/// A `--background` value: finite and ≥ 0.
fn parse_background(text: &str) -> Result<f64, String> {
    let b: f64 = text
        .parse()
        .map_err(|_| format!("expected a number >= 0, got {text:?}"))?;
    NoiseModel::Photon { background: b }
        .validate()
        .map_err(|e| FrontEnd::CommandLine.reason(&e))?;
    Ok(b)
}

/// A `--noise-sigma` value: finite and ≥ 0.
fn parse_noise_sigma(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && s >= 0.0 => Ok(s),
        _ => Err(format!("expected a finite number >= 0, got {text:?}")),
    }
}

/// A `--fov` value: H or HxV degrees, each in (0, 180).
fn parse_fov(text: &str) -> Result<(f64, Option<f64>), String> {
    let angle = |t: &str| -> Result<f64, String> {
        match t.trim().parse::<f64>() {
            Ok(v) if v > 0.0 && v < 180.0 => Ok(v),
            _ => Err(format!(
                "expected an angle in degrees between 0 and 180, or HxV, got {text:?}"
            )),
        }
    };
    match text.split_once('x') {
        Some((h, v)) => Ok((angle(h)?, Some(angle(v)?))),
        None => Ok((angle(text)?, None)),
    }
}

/// A `--pixel-pitch` or `--focal-length` value: finite and > 0.
fn parse_length(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a length > 0, got {text:?}")),
    }
}

const NO_CAMERA: &str = "--out-points: give the camera, --fov H[xV] (degrees) or \
                         --pixel-pitch and --focal-length";

/// The camera of `--fov` or `--pixel-pitch` and `--focal-length` for `--out-points`, on the
/// grid `g`.
fn camera_of(a: &ReconstructArgs, g: rdlidar::lidar::Geometry) -> CliResult<Camera> {
    let camera = match (a.fov, a.pixel_pitch, a.focal_length) {
        (Some((h, v)), _, _) => Camera::field_of_view(h, v, g.m, g.n),
        (None, Some(p), Some(f)) => Camera::pinhole(p, f),
        _ => return Err(NO_CAMERA.to_string().into()),
    };
    camera.map_err(|e| {
        let flag = match &e {
            rdlidar::Error::InvalidParameter { name: "fov", .. } => "--fov",
            _ => "--pixel-pitch",
        };
        format!("{flag}: {}", FrontEnd::CommandLine.reason(&e)).into()
    })
}

/// A `--tau` duration with its unit (200ps, 1ns).
fn parse_tau_flag(text: &str) -> Result<f64, String> {
    let tau = rdlidar::lidar::parse_tau(text).map_err(|e| FrontEnd::CommandLine.reason(&e))?;
    depth_bin_m(tau).map_err(|e| FrontEnd::CommandLine.reason(&e))?;
    Ok(tau)
}

/// A `--noise` model name.
fn parse_noise(text: &str) -> Result<NoiseModel, String> {
    text.parse::<NoiseModel>()
        .map_err(|e| FrontEnd::CommandLine.reason(&e))
}

/// A `--false-rate` value: a number strictly between 0 and 1.
fn parse_false_rate(text: &str) -> Result<f64, String> {
    let alpha: f64 = text
        .parse()
        .map_err(|_| format!("expected a number between 0 and 1, got {text:?}"))?;
    rdlidar::recon::check_false_rate(alpha).map_err(|e| FrontEnd::CommandLine.reason(&e))?;
    Ok(alpha)
}

/// A `--clipped` value: top or a level > 0.
fn parse_clipping(text: &str) -> Result<Clipping, String> {
    text.parse::<Clipping>()
        .map_err(|e| FrontEnd::CommandLine.reason(&e))
}

/// A `--returns` value: a count, or `None` for auto.
#[derive(Debug, Clone, Copy)]
pub struct MaxReturns(Option<usize>);

/// A `--returns` value: a count in 1 ..= 8, or auto.
fn parse_returns(text: &str) -> Result<MaxReturns, String> {
    if text == "auto" {
        return Ok(MaxReturns(None));
    }
    match text.parse::<usize>() {
        Ok(k) if (1..=MAX_RETURNS_ESTIMATE).contains(&k) => Ok(MaxReturns(Some(k))),
        _ => Err(format!(
            "expected a count from 1 to {MAX_RETURNS_ESTIMATE} or auto, got {text:?}"
        )),
    }
}

/// A `--threshold` rule name.
fn parse_threshold(text: &str) -> Result<PeakThreshold, String> {
    text.parse::<PeakThreshold>().map_err(|_| {
        format!(
            "unknown threshold rule {text:?}; valid rules: {}",
            PeakThreshold::NAMES.join(", ")
        )
    })
}

/// A `--solver` name, with the valid names listed on error.
fn parse_method(text: &str) -> Result<Method, String> {
    text.parse::<Method>().map_err(|_| {
        format!(
            "unknown solver {text:?}; valid solvers: {}",
            Method::NAMES.join(", ")
        )
    })
}

/// The request the flags make, checked (a progress bar where `progress`).
fn request_of(
    a: &ReconstructArgs,
    globals: &Globals,
    progress: bool,
) -> CliResult<ReconstructRequest> {
    let request = ReconstructRequest {
        method: a.solver,
        options: ReconstructOptions {
            max_iter: a.max_iter,
            progress,
            seed: globals.seed(),
            power_iterations: None,
            threshold: a.threshold,
            debias: !a.no_debias,
            max_returns: a.returns.0,
            false_rate: a.false_rate,
            noise: ReconstructRequest::noise_model(a.noise, a.background)?,
            response: a.kernel.clone().unwrap_or(Response::Delta),
        },
        clipped: a.clipped,
        fill_unobserved: a.fill_unobserved,
    };
    request.validate()?;
    Ok(request)
}

/// Runs `reconstruct`.
pub fn run(a: &ReconstructArgs, globals: &Globals, ranks: &Ranks) -> CliResult {
    request_of(a, globals, false)?;
    let mut inputs = a.files.inputs().to_vec();
    if let Some(t) = &a.truth {
        inputs.push((t, "--truth"));
    }
    let mut outputs = vec![
        ("--out-depth", a.out_depth.as_path()),
        ("--out-scene", a.out_scene.as_path()),
    ];
    if let Some(png) = &a.png {
        outputs.push(("--png", png.as_path()));
    }
    let continuous = [
        ("--out-range", a.out_range.is_some()),
        ("--truth-range", a.truth_range.is_some()),
    ];
    if let Some((flag, _)) = continuous.iter().find(|(_, given)| *given) {
        if a.kernel.as_ref().is_none_or(Response::is_delta) {
            return Err(format!(
                "{flag}: continuous depths are estimated under a --kernel other than delta \
                 (triangle, gaussian:S, measured:O:FILE)"
            )
            .into());
        }
    }
    if let Some(range) = &a.out_range {
        outputs.push(("--out-range", range.as_path()));
    }
    if let Some(points) = &a.out_points {
        if a.fov.is_none() && a.pixel_pitch.is_none() {
            return Err(NO_CAMERA.to_string().into());
        }
        outputs.push(("--out-points", points.as_path()));
    }
    if let Some(t) = &a.truth_range {
        inputs.push((t, "--truth-range"));
    }
    for (flag, out) in &outputs {
        check_out_file(out, flag, &inputs)?;
    }
    check_distinct_outputs(&outputs)?;
    with_precision!(
        globals.precision_of(&[&a.files.meas, &a.files.pulse])?,
        reconstruct_files(a, globals, ranks)
    )
}

/// The acquisition and measurements of `reconstruct`, and the true scene (read by the first
/// process only).
type Inputs<T> = (Acquisition, Vec<T>, Option<Scene<T>>);

/// Reads the inputs of `reconstruct`: this process's rows of the codes, the measurements and,
/// in the first process, the true scene.
fn read_inputs<T: Real>(a: &ReconstructArgs, ranks: &Ranks) -> CliResult<Inputs<T>> {
    // The solvers keep a few scenes: the estimate, iterates, gradients, the debiased twin's.
    let (acq, y) = ranks.load::<T>(
        &a.files,
        (a.tiles, a.stream_codes),
        ("reconstruct", RECONSTRUCT_SCENES, Use::Reconstruct),
    )?;
    pulse_in::<T>(acq.pulse()).map_err(at_pulse(&a.files.pulse))?;
    let g = acq.whole_geometry();
    let truth = match &a.truth {
        Some(path) if ranks.is_first() => {
            let t = io::read_scene::<T>(path)?;
            if t.geometry() != g {
                return Err(format!(
                    "{}: the true scene is {}, but the codes and --depth-bins give {g}",
                    path.display(),
                    t.geometry()
                )
                .into());
            }
            Some(t)
        }
        _ => None,
    };
    Ok((acq, y, truth))
}

fn reconstruct_files<T: Real + WritableElement>(
    a: &ReconstructArgs,
    globals: &Globals,
    ranks: &Ranks,
) -> CliResult {
    // Every process reads its inputs; they agree on any failure before solving together.
    let request = request_of(a, globals, !globals.quiet && ranks.is_first())?;
    let (acq, y, truth) = ranks.agree(read_inputs::<T>(a, ranks))?;
    let (acq, y, censoring) = censor_inputs(&request, ranks, acq, y)?;
    let g = acq.whole_geometry();
    let tau = a.tau.unwrap_or(DEFAULT_TAU_S);
    let truth_range = match &a.truth_range {
        Some(path) if ranks.is_first() => Some(read_truth_range(path, g)?),
        _ => None,
    };
    let count = acq.rows().unwrap_or(1);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let on_tile = |tile: &TileReconstruction<T>| {
        let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if !globals.quiet {
            errln!("{}", tile.describe(n, count));
        }
    };
    let never = std::sync::atomic::AtomicBool::new(false);
    let r = request
        .run(&acq, &y, &observe_nothing, &on_tile, &never)
        .map_err(|e| {
            format!(
                "--solver {}: {}",
                a.solver,
                FrontEnd::CommandLine.render(&e)
            )
            .into()
        });
    let r = match (ranks.agree(r)?, acq.share()) {
        (Reconstructed::Single(r), Some(share)) => {
            Reconstructed::Single(share.gather_reconstruction(r)?)
        }
        (r, _) => r,
    };
    if !ranks.is_first() {
        return Ok(());
    }
    // A coded aperture's blocked pixels reach no ADC: they are unobserved (−2 in the depth
    // map), judged apart from the observed ones, and filled from their neighbours on request.
    let observed: Vec<bool> = r.depth().depth.iter().map(|&d| d != UNOBSERVED).collect();
    let r = request.finish(r, &acq, censoring.as_ref());
    let mut metrics = truth_lines(a, &truth, &r, &observed)?;
    if let Some(range) = truth_range {
        let path = a
            .truth_range
            .as_deref()
            .unwrap_or(std::path::Path::new("--truth-range"));
        let c = acq
            .compare_range(
                &y,
                (
                    r.returns.as_ref().expect("estimated under a kernel"),
                    &r.scene,
                ),
                range,
                truth.as_ref(),
                a.kernel.as_ref().unwrap_or(&Response::Delta),
                a.noise_sigma,
                depth_bin_m(tau)?,
            )
            .map_err(|e| format!("{} (--truth-range): {e}", path.display()))?;
        metrics.push(format!("versus the true depths: {c}"));
    }
    // Stage every output, then rename them into place together; on an error the staged files
    // are dropped, which removes them.
    let mut staged: Vec<StagedFile> = vec![
        io::stage_array(&a.out_depth, &r.depth.depth)?,
        io::stage_array(&a.out_scene, r.scene.data())?,
    ];
    if let (Some(path), Some(returns)) = (&a.out_range, &r.returns) {
        staged.push(io::stage_array(path, &returns.range_map())?);
    }
    if let Some(path) = &a.out_points {
        let grid;
        let returns = match &r.returns {
            Some(returns) => returns,
            None => {
                grid = Returns::of_scene(&r.scene);
                &grid
            }
        };
        let cloud = rdlidar::lidar::points(returns, depth_bin_m(tau)?, &camera_of(a, g)?)?;
        staged.push(io::stage_points(path, &cloud)?);
    }
    if let Some(png) = &a.png {
        let bin_m = depth_bin_m(tau)?;
        let options = rdlidar::report::plot::DepthOptions::new(bin_m, "m")
            .title(format!("{} ({})", r.summary.run.method_used, g));
        let truth_depth = truth.as_ref().map(|t| t.depth_map().depth);
        let panels: Vec<(&str, &ndarray::Array2<i32>)> = match &truth_depth {
            Some(d) => vec![("truth", d), ("estimate", &r.depth.depth)],
            None => vec![("estimate", &r.depth.depth)],
        };
        let fig = rdlidar::report::plot::depth_panels(&panels, &options)
            .map_err(|e| format!("{}: {e}", png.display()))?;
        staged.push(io::stage_bytes(png, &fig.encode_png())?);
    }
    let written = io::commit_all(staged)?;

    let files: Vec<String> = written.iter().map(|f| f.display().to_string()).collect();
    outln!(
        "reconstruct {g} from {}: {}; wrote {} (depth int32, scene {}).",
        match acq.rows() {
            None => format!("K = {}{}", y.len(), architecture_note(&acq)),
            Some(rows) => format!(
                "{rows} × {} = {} measurements{}",
                acq.samples(),
                y.len(),
                architecture_note(&acq)
            ),
        },
        r.summary.headline,
        files.join(", "),
        npy_dtype::<T>()
    );
    outln!(
        "  asked: {}",
        FrontEnd::CommandLine.words(&request.summary())
    );
    if let Some(line) = clipping_line(censoring.as_ref(), &acq, &y) {
        outln!("  {line}");
    }
    for line in &r.summary.details {
        outln!("  {line}");
    }
    for line in &metrics {
        outln!("{line}");
    }
    Ok(())
}

/// The true depths of `--truth-range`, on the grid `g`.
fn read_truth_range(
    path: &std::path::Path,
    g: rdlidar::lidar::Geometry,
) -> CliResult<ndarray::ArrayD<f64>> {
    let range = io::read_range(path)?;
    let shape = range.shape();
    if shape[shape.len() - 2..] != [g.m, g.n] {
        return Err(format!(
            "{} (--truth-range): depths of shape {} do not fit the {} × {} pixels of the codes",
            path.display(),
            io::shape_text(shape),
            g.m,
            g.n
        )
        .into());
    }
    Ok(range)
}

/// The lines that compare the estimate with `--truth`'s scene: over every pixel, or over the
/// observed ones and apart the unobserved ones (with what filling them did).
fn truth_lines<T: Real>(
    a: &ReconstructArgs,
    truth: &Option<Scene<T>>,
    r: &rdlidar::acquisition::Outcome<T>,
    observed: &[bool],
) -> CliResult<Vec<String>> {
    let (Some(t), Some(path)) = (truth, &a.truth) else {
        return Ok(Vec::new());
    };
    let tau = a.tau.unwrap_or(DEFAULT_TAU_S);
    let at_truth = |e: rdlidar::Error| format!("{} (--truth): {e}", path.display());
    let unobserved = observed.iter().filter(|&&o| !o).count();
    if unobserved == 0 {
        let m = compare(t, &r.scene, tau).map_err(at_truth)?;
        return Ok(vec![format!("versus the truth: {m}")]);
    }
    let c = compare_observed(t, &r.scene, &r.depth.depth, observed, tau).map_err(at_truth)?;
    let mut line = format!(
        "{unobserved} pixels unobserved (all-zero codes), {} of them lit in the truth",
        c.unobserved_lit
    );
    if a.fill_unobserved {
        line.push_str(&format!(
            "; filled from their neighbours: {} of the {} lit at the exact depth, {} within a \
             bin, {} filled where the truth is empty",
            c.filled_exact, c.unobserved_lit, c.filled_near, c.filled_false
        ));
    }
    Ok(vec![
        format!(
            "versus the truth on the {} observed pixels: {}",
            c.observed_pixels, c.observed
        ),
        line,
    ])
}

/// The acquisition and measurements with the samples `--clipped` names censored (the
/// censored copies replace the originals), and what was censored; every process agrees.
fn censor_inputs<T: Real>(
    request: &ReconstructRequest,
    ranks: &Ranks,
    acq: Acquisition,
    y: Vec<T>,
) -> CliResult<(Acquisition, Vec<T>, Option<Censoring>)> {
    let Some(clipping) = request.clipped else {
        return Ok((acq, y, None));
    };
    let censored = request.censor(acq, y).map_err(|e| {
        format!(
            "--clipped ({clipping}): {}",
            FrontEnd::CommandLine.render(&e)
        )
        .into()
    });
    ranks.agree(censored)
}

/// The line on clipping: what was censored, or, without `--clipped`, a hint where many
/// samples sit at the top or bottom code (beyond the two extremes every row has): the ADC
/// probably saturated.
fn clipping_line<T: Real>(
    censoring: Option<&Censoring>,
    acq: &Acquisition,
    y: &[T],
) -> Option<String> {
    if let Some(c) = censoring {
        return Some(c.describe());
    }
    let top = at_top(y, acq.samples());
    let rows = acq.rows().unwrap_or(1);
    (top >= 2 * rows + (y.len() / 100).max(1)).then(|| {
        format!(
            "{top} of {} samples sit at their ADC's largest or smallest y: if it clipped, \
             --clipped top leaves them out of the fit",
            y.len()
        )
    })
}
