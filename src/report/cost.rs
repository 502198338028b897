//! What a configuration costs before anything is simulated: its regime and critical pulse
//! length, its physical scales for a sampling period τ, the memory of its arrays and of the
//! fused operator, and the estimated time of one application of the operator.
//!
//! The time estimate is a throughput model. The dense forward and the adjoint of
//! [`RdOperator`] do the work of a matrix product of 2·M·N·K·K_s flops (the matrix form
//! Z = S₂ᵀX₂, X̃₂ = S₂W of docs/math.md §5); the sparse forward over one return in every
//! pixel costs M·N·K_p voxel-samples. A
//! [`Throughput`] gives the rate of each, either the documented rates measured on the
//! reference machine ([`Throughput::documented`]) or rates measured on this machine by timing
//! a small problem ([`Throughput::calibrate`]); the estimate is work divided by rate.

use std::sync::Arc;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::real::Real;
use crate::report::timing::time_operator;
use crate::report::units::{bytes, frames_per_second, metres, seconds, si};
use crate::units::number;

use crate::lidar::sampling::check_tau;
use crate::lidar::{
    depth_bin_m, random_opaque_scene, CodeAlphabet, Codes, Geometry, Pulse, RdOperator, Regime,
    Seeds,
};

/// One value for each precision of the operator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PerPrecision<V> {
    /// Single precision.
    pub f32: V,
    /// Double precision.
    pub f64: V,
}

/// Physical scales of a configuration at a sampling period τ (the paper's §4 and §5.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhysicalScales {
    /// The sampling period τ, seconds.
    pub tau_s: f64,
    /// Depth resolution τc/2, metres: the length of one depth bin.
    pub depth_resolution_m: f64,
    /// Range K_s·τc/2, metres: the depth the K_s bins span.
    pub range_m: f64,
    /// Pulse duration K_p·τ, seconds.
    pub pulse_duration_s: f64,
    /// Acquisition time of one frame, K·τ with K = K_p + K_s − 1 samples, seconds.
    pub frame_duration_s: f64,
    /// The maximum frame rate 1/(K·τ), frames per second.
    pub max_frame_rate_hz: f64,
    /// Duration of the critical pulse, (M·N − 1)·K_s + 1 samples of τ, seconds.
    pub critical_pulse_duration_s: f64,
}

/// Bytes of the arrays of a configuration and of its fused operator (±1 codes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MemoryCost {
    /// The codes bit-packed as the operator holds them: ⌈M·N/8⌉·K bytes (one bit per ±1
    /// entry; ternary codes take twice as much).
    pub codes_packed_bytes: u64,
    /// The codes as int8, one byte per entry (`codes.npy`): M·N·K bytes.
    pub codes_int8_bytes: u64,
    /// The codes as `np.packbits` writes them (`codes.npy` of `simulate --codes-format
    /// packed`): M·N·⌈K/8⌉ bytes.
    pub codes_packbits_bytes: u64,
    /// The codes as a dense float matrix, the operand of a general matrix product.
    pub codes_dense_bytes: PerPrecision<u64>,
    /// The pulse, K_p values.
    pub pulse_bytes: PerPrecision<u64>,
    /// The measurements, K values.
    pub measurements_bytes: PerPrecision<u64>,
    /// A dense scene, M·N·K_s values.
    pub scene_bytes: PerPrecision<u64>,
    /// The fused operator with ±1 codes ([`RdOperator::estimated_memory_bytes`]): packed codes,
    /// pulse and the working buffers of `operator_threads` threads.
    pub operator_bytes: PerPrecision<u64>,
    /// The worker threads the operator's memory is counted for.
    pub operator_threads: usize,
}

/// Rates of the fused operator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OperatorRates {
    /// Dense forward, in GEMM-equivalent flops per second (2·M·N·K·K_s per application).
    pub forward_flops_per_s: f64,
    /// Adjoint, in GEMM-equivalent flops per second.
    pub adjoint_flops_per_s: f64,
    /// Sparse forward, in voxel-samples per second (nnz·K_p per application).
    pub sparse_voxel_samples_per_s: f64,
}

/// Where a [`Throughput`]'s rates come from.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ThroughputSource {
    /// The documented rates of [`Throughput::documented`].
    Documented {
        /// What they were measured on.
        measured_on: &'static str,
    },
    /// Measured on this machine by [`Throughput::calibrate`].
    Calibrated {
        /// The calibration grid, `MxNxKS`.
        size: String,
        /// Its pulse length.
        pulse_len: usize,
        /// Timed runs of each operation after a warm-up (the median is used).
        repeats: usize,
        /// Worker threads.
        threads: usize,
        /// The kernels' instruction set.
        isa: &'static str,
    },
}

impl std::fmt::Display for ThroughputSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ThroughputSource::Documented { measured_on } => {
                write!(f, "the documented rates, measured on {measured_on}")
            }
            ThroughputSource::Calibrated {
                size,
                pulse_len,
                repeats,
                threads,
                isa,
            } => write!(
                f,
                "a calibration on this machine: {size}, K_p {pulse_len}, median of {repeats} runs, \
                 {threads} threads, {isa} kernels"
            ),
        }
    }
}

/// The rates a time estimate divides the work by.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Throughput {
    /// Where the rates come from.
    pub source: ThroughputSource,
    /// The rates in each precision.
    pub rates: PerPrecision<OperatorRates>,
}

/// Largest calibration grid: pixels per side, depth bins, pulse length.
const CALIBRATION_CAP: (usize, usize, usize) = (64, 64, 16_384);

impl Throughput {
    /// The documented rates: those of one `cargo bench --bench lidar` run at 100×100×40,
    /// K_p = 30 000 with the paper scene for the sparse forward, on the two-core machine whose
    /// figures docs/lidar.md lists (criterion medians). Another or a loaded machine differs;
    /// [`Throughput::calibrate`] measures the one at hand.
    pub fn documented() -> Self {
        let flops = 2.0 * 10_000.0 * 30_039.0 * 40.0;
        let voxel_samples = 5_547.0 * 30_000.0;
        let rates = |fwd: f64, adj: f64, sparse: f64| OperatorRates {
            forward_flops_per_s: flops / fwd,
            adjoint_flops_per_s: flops / adj,
            sparse_voxel_samples_per_s: voxel_samples / sparse,
        };
        Throughput {
            source: ThroughputSource::Documented {
                measured_on: "the 2-core AVX-512 reference machine at 100x100x40, K_p 30000, \
                              2 threads (docs/lidar.md)",
            },
            rates: PerPrecision {
                f32: rates(0.0725, 0.0667, 0.0097),
                f64: rates(0.1228, 0.1200, 0.0169),
            },
        }
    }

    /// The grid and pulse length [`Throughput::calibrate`] times for a configuration: the
    /// configuration itself, capped at 64×64 pixels, 64 depth bins and K_p = 16 384 so that a
    /// calibration takes a second or two.
    pub fn calibration_problem(geometry: Geometry, pulse_len: usize) -> Result<(Geometry, usize)> {
        if pulse_len == 0 {
            return Err(Error::param("pulse_len", "must be at least 1"));
        }
        let (side, ks, kp) = CALIBRATION_CAP;
        let g = Geometry::new(
            geometry.m.min(side),
            geometry.n.min(side),
            geometry.ks.min(ks),
        )?;
        Ok((g, pulse_len.min(kp)))
    }

    /// Measures the rates on this machine: builds the operator of
    /// [`Throughput::calibration_problem`] in f32 and f64 (Bernoulli pulse, ±1 codes, a scene
    /// with one return in every pixel, all seeded), runs the dense forward, the adjoint and the
    /// sparse forward after a warm-up ([`time_runs`](crate::report::timing::time_runs))
    /// `repeats` times each, and divides each operation's work by its median time. Uses the
    /// current rayon thread pool.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pulse_len` or `repeats` is zero.
    pub fn calibrate(geometry: Geometry, pulse_len: usize, repeats: usize) -> Result<Self> {
        if repeats == 0 {
            return Err(Error::param("repeats", "must be at least 1"));
        }
        let (g, kp) = Self::calibration_problem(geometry, pulse_len)?;
        let (f32_rates, isa) = measure::<f32>(g, kp, repeats)?;
        let (f64_rates, _) = measure::<f64>(g, kp, repeats)?;
        Ok(Throughput {
            source: ThroughputSource::Calibrated {
                size: g.to_string(),
                pulse_len: kp,
                repeats,
                threads: rayon::current_num_threads(),
                isa,
            },
            rates: PerPrecision {
                f32: f32_rates,
                f64: f64_rates,
            },
        })
    }
}

/// The rates of the operator on `g` with a pulse of `kp`, and its instruction set.
fn measure<T: Real>(
    g: Geometry,
    kp: usize,
    repeats: usize,
) -> Result<(OperatorRates, &'static str)> {
    let k = g.samples(kp);
    // The draws of a simulation with base seed 0.
    let seeds = Seeds::new(0);
    let pulse = Pulse::<T>::bernoulli(kp, seeds.pulse())?;
    let codes = Codes::random_binary(g.pixels(), k, seeds.code_set(0))?;
    let op = RdOperator::new(g, pulse.into_inner(), Arc::new(codes))?;
    let scene = random_opaque_scene::<T>(g, 1.0, seeds.scene())?;
    let t = time_operator(&op, scene.as_slice(), repeats);
    // At least 1 ns, so that the rates stay finite.
    let [forward, adjoint, sparse] =
        [t.forward, t.adjoint, t.sparse_forward].map(|t| t.median_s.max(1e-9));
    let flops = 2.0 * g.pixels() as f64 * k as f64 * g.ks as f64;
    let voxel_samples = scene.nnz() as f64 * kp as f64;
    Ok((
        OperatorRates {
            forward_flops_per_s: flops / forward,
            adjoint_flops_per_s: flops / adjoint,
            sparse_voxel_samples_per_s: voxel_samples / sparse,
        },
        op.isa(),
    ))
}

/// Estimated seconds per application of the fused operator.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimeCost {
    /// Work of the dense forward and of the adjoint: 2·M·N·K·K_s GEMM-equivalent flops.
    pub flops_per_apply: f64,
    /// Work of the sparse forward over one return in every pixel: M·N·K_p voxel-samples (an
    /// opaque scene has at most this many).
    pub sparse_voxel_samples: f64,
    /// Dense forward.
    pub forward_s: PerPrecision<f64>,
    /// Adjoint (backprojection).
    pub adjoint_s: PerPrecision<f64>,
    /// One forward and one adjoint: the operator cost of one iteration of CGLS or FISTA.
    pub iteration_s: PerPrecision<f64>,
    /// Sparse forward over one return in every pixel.
    pub sparse_forward_s: PerPrecision<f64>,
    /// The rates used.
    pub throughput: Throughput,
}

/// Everything `rdlidar info` reports about a configuration.
///
/// # Example
/// ```
/// use rdlidar::lidar::{Geometry, Regime, DEFAULT_TAU_S};
/// use rdlidar::report::cost::{Cost, Throughput};
///
/// let g = Geometry::parse("500x500x100")?;
/// let b = Cost::new(g, 25_000_000, DEFAULT_TAU_S, 2, Throughput::documented())?;
/// assert_eq!(b.regime, Regime::Redundant);           // just above (MN − 1)·K_s + 1
/// assert!((b.physical.range_m - 2.998).abs() < 1e-3); // 100 bins of 3 cm
/// assert!((b.physical.pulse_duration_s - 5e-3).abs() < 1e-12); // the paper's 5 ms pulse
/// assert_eq!(b.memory.codes_int8_bytes, 250_000 * 25_000_099);
/// println!("{b}");
/// # Ok::<(), rdlidar::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cost {
    /// The grid, `MxNxKS`.
    pub size: String,
    /// Pixel rows M.
    pub m: usize,
    /// Pixel columns N.
    pub n: usize,
    /// Depth bins K_s.
    pub ks: usize,
    /// Pulse length K_p.
    pub pulse_len: usize,
    /// Measurements K = K_p + K_s − 1.
    pub samples: usize,
    /// Unknowns M·N·K_s.
    pub unknowns: usize,
    /// Compressive, critical or redundant (eq. 8–9).
    pub regime: Regime,
    /// The critical pulse length (M·N − 1)·K_s + 1.
    pub critical_pulse_len: usize,
    /// K / (M·N·K_s): below 1 compressive, above 1 redundant.
    pub measurements_per_unknown: f64,
    /// Physical scales at τ.
    pub physical: PhysicalScales,
    /// Memory of the arrays and of the operator.
    pub memory: MemoryCost,
    /// Estimated time per application of the operator.
    pub time: TimeCost,
}

impl Cost {
    /// The cost of a grid with a pulse of `pulse_len` samples at sampling period `tau_s`
    /// seconds, the operator's memory counted for `threads` worker threads, times estimated
    /// with `throughput`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pulse_len` or `threads` is zero, if τ is not a finite
    /// positive number (`tau`), if the physical scales overflow or underflow at that τ, if a
    /// sample or byte count does not fit in 64 bits, or if a rate of `throughput` is not a
    /// finite positive number.
    pub fn new(
        geometry: Geometry,
        pulse_len: usize,
        tau_s: f64,
        threads: usize,
        throughput: Throughput,
    ) -> Result<Self> {
        let g = geometry;
        if pulse_len == 0 {
            return Err(Error::param("pulse_len", "must be at least 1"));
        }
        if threads == 0 {
            return Err(Error::param("threads", "must be at least 1"));
        }
        let tau_s = check_tau(tau_s)?;
        let r = &throughput.rates;
        let rates = [r.f32, r.f64].map(|q| {
            [
                q.forward_flops_per_s,
                q.adjoint_flops_per_s,
                q.sparse_voxel_samples_per_s,
            ]
        });
        if let Some(bad) = rates
            .iter()
            .flatten()
            .find(|v| !(v.is_finite() && **v > 0.0))
        {
            return Err(Error::param(
                "throughput",
                format!("every rate must be finite and > 0, got {}", number(*bad)),
            ));
        }
        let overflow = |what: &str| {
            Error::param(
                "pulse_len",
                format!("{what} of {g} with K_p = {pulse_len}: the count overflows 64 bits"),
            )
        };
        let samples = pulse_len
            .checked_add(g.ks - 1)
            .ok_or_else(|| overflow("the samples K"))?;
        let (pixels, k, kp) = (g.pixels() as u64, samples as u64, pulse_len as u64);
        let mul = |a: u64, b: u64, what: &str| a.checked_mul(b).ok_or_else(|| overflow(what));
        let both = |count: u64, what: &str| -> Result<PerPrecision<u64>> {
            Ok(PerPrecision {
                f32: mul(count, 4, what)?,
                f64: mul(count, 8, what)?,
            })
        };
        let codes_int8 = mul(pixels, k, "the codes")?;
        let operator = |bytes: Result<usize>| -> Result<u64> {
            bytes
                .map(|b| b as u64)
                .map_err(|_| overflow("the operator's memory"))
        };
        let memory = MemoryCost {
            codes_packed_bytes: mul(pixels.div_ceil(8), k, "the packed codes")?,
            codes_int8_bytes: codes_int8,
            codes_packbits_bytes: mul(pixels, k.div_ceil(8), "the packed codes file")?,
            codes_dense_bytes: both(codes_int8, "the dense codes")?,
            pulse_bytes: both(kp, "the pulse")?,
            measurements_bytes: both(k, "the measurements")?,
            scene_bytes: both(g.voxels() as u64, "the scene")?,
            operator_bytes: PerPrecision {
                f32: operator(RdOperator::<f32>::estimated_memory_bytes(
                    g,
                    pulse_len,
                    CodeAlphabet::Binary,
                    threads,
                ))?,
                f64: operator(RdOperator::<f64>::estimated_memory_bytes(
                    g,
                    pulse_len,
                    CodeAlphabet::Binary,
                    threads,
                ))?,
            },
            operator_threads: threads,
        };

        let critical = g.critical_pulse_len();
        let bin = depth_bin_m(tau_s)?;
        let frame = samples as f64 * tau_s;
        let physical = PhysicalScales {
            tau_s,
            depth_resolution_m: bin,
            range_m: g.ks as f64 * bin,
            pulse_duration_s: pulse_len as f64 * tau_s,
            frame_duration_s: frame,
            max_frame_rate_hz: 1.0 / frame,
            critical_pulse_duration_s: critical as f64 * tau_s,
        };
        let scales = [
            physical.depth_resolution_m,
            physical.range_m,
            physical.pulse_duration_s,
            physical.frame_duration_s,
            physical.max_frame_rate_hz,
            physical.critical_pulse_duration_s,
        ];
        if scales.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(Error::param(
                "tau",
                format!(
                    "τ = {tau_s:e} s puts the physical scales of {g} with K_p = {pulse_len} out of \
                     the range of f64"
                ),
            ));
        }

        let flops = 2.0 * g.pixels() as f64 * samples as f64 * g.ks as f64;
        let sparse_work = g.pixels() as f64 * pulse_len as f64;
        let per = |f: &dyn Fn(&OperatorRates) -> f64| PerPrecision {
            f32: f(&r.f32),
            f64: f(&r.f64),
        };
        let forward_s = per(&|q| flops / q.forward_flops_per_s);
        let adjoint_s = per(&|q| flops / q.adjoint_flops_per_s);
        let time = TimeCost {
            flops_per_apply: flops,
            sparse_voxel_samples: sparse_work,
            forward_s,
            adjoint_s,
            iteration_s: PerPrecision {
                f32: forward_s.f32 + adjoint_s.f32,
                f64: forward_s.f64 + adjoint_s.f64,
            },
            sparse_forward_s: per(&|q| sparse_work / q.sparse_voxel_samples_per_s),
            throughput,
        };

        Ok(Cost {
            size: g.to_string(),
            m: g.m,
            n: g.n,
            ks: g.ks,
            pulse_len,
            samples,
            unknowns: g.voxels(),
            regime: g.regime(pulse_len),
            critical_pulse_len: critical,
            measurements_per_unknown: samples as f64 / g.voxels() as f64,
            physical,
            memory,
            time,
        })
    }
}

impl std::fmt::Display for Cost {
    /// A table for people: the configuration and its regime, the physical scales at τ, memory
    /// and estimated times in f32 and f64, and where the rates come from.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = &self.physical;
        let m = &self.memory;
        let t = &self.time;
        writeln!(
            f,
            "{} (M×N×K_s), K_p {}: K = K_p + K_s − 1 = {} measurements for M·N·K_s = {} unknowns",
            self.size, self.pulse_len, self.samples, self.unknowns
        )?;
        writeln!(
            f,
            "regime {} (K / unknowns = {:.4}); critical K_p = (M·N − 1)·K_s + 1 = {}",
            self.regime, self.measurements_per_unknown, self.critical_pulse_len
        )?;
        writeln!(f)?;
        writeln!(f, "physical scales at τ = {}", si(p.tau_s, "s"))?;
        let rows = [
            ("depth resolution τc/2", metres(p.depth_resolution_m)),
            ("range K_s·τc/2", metres(p.range_m)),
            ("pulse duration K_p·τ", seconds(p.pulse_duration_s)),
            ("frame K·τ", seconds(p.frame_duration_s)),
            (
                "max frame rate 1/(K·τ)",
                frames_per_second(p.max_frame_rate_hz),
            ),
            (
                "critical pulse duration",
                seconds(p.critical_pulse_duration_s),
            ),
        ];
        for (name, value) in rows {
            writeln!(f, "  {name:<36} {value}")?;
        }
        writeln!(f)?;
        writeln!(f, "memory {:>42} {:>12}", "f32", "f64")?;
        let one = |name: &str, b: u64| format!("  {name:<36} {:>12}\n", bytes(b));
        let two = |name: &str, b: PerPrecision<u64>| {
            format!("  {name:<36} {:>12} {:>12}\n", bytes(b.f32), bytes(b.f64))
        };
        f.write_str(&one(
            "codes, packed bits (the operator)",
            m.codes_packed_bytes,
        ))?;
        f.write_str(&one("codes, int8 (codes.npy)", m.codes_int8_bytes))?;
        f.write_str(&one(
            "codes, packed (codes.npy, packbits)",
            m.codes_packbits_bytes,
        ))?;
        f.write_str(&two(
            "codes, dense float (a GEMM operand)",
            m.codes_dense_bytes,
        ))?;
        f.write_str(&two("pulse (K_p)", m.pulse_bytes))?;
        f.write_str(&two("measurements (K)", m.measurements_bytes))?;
        f.write_str(&two("scene, dense (M·N·K_s)", m.scene_bytes))?;
        f.write_str(&two(
            &format!("operator, {} threads", m.operator_threads),
            m.operator_bytes,
        ))?;
        writeln!(f)?;
        writeln!(f, "time per apply, estimated {:>23} {:>12}", "f32", "f64")?;
        let time = |name: &str, s: PerPrecision<f64>| {
            format!(
                "  {name:<36} {:>12} {:>12}\n",
                seconds(s.f32),
                seconds(s.f64)
            )
        };
        f.write_str(&time("forward", t.forward_s))?;
        f.write_str(&time("adjoint", t.adjoint_s))?;
        f.write_str(&time("forward + adjoint (one iteration)", t.iteration_s))?;
        f.write_str(&time(
            "sparse forward, 1 return per pixel",
            t.sparse_forward_s,
        ))?;
        writeln!(
            f,
            "  work: 2·M·N·K·K_s = {:.3e} flops (forward, adjoint); M·N·K_p = {:.3e} \
             voxel-samples (sparse)",
            t.flops_per_apply, t.sparse_voxel_samples
        )?;
        let r = &t.throughput.rates;
        writeln!(
            f,
            "  rates: f32 {:.0}/{:.0} GFLOP/s, f64 {:.0}/{:.0} GFLOP/s (forward/adjoint), \
             sparse {:.3e}/{:.3e} voxel-samples/s",
            r.f32.forward_flops_per_s / 1e9,
            r.f32.adjoint_flops_per_s / 1e9,
            r.f64.forward_flops_per_s / 1e9,
            r.f64.adjoint_flops_per_s / 1e9,
            r.f32.sparse_voxel_samples_per_s,
            r.f64.sparse_voxel_samples_per_s,
        )?;
        write!(f, "  from {}", t.throughput.source)
    }
}
