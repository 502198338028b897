//! The experiments' figures: depth maps side by side, error against run time, the Pareto plot
//! and the phase-transition plot.

use crate::error::Result;
use crate::lidar::{depth_bin_m, DEFAULT_TAU_S};
use crate::report::plot::{
    depth_panels, line_plot, scatter_plot, Chart, ChartFigure, DepthFigure, DepthOptions,
    LegendPosition, Marker, Rgb, Series, SeriesStyle,
};

use super::config::{noise_text, ExperimentConfig, NoiseLevel};
use super::table::medians;
use super::{CaseDepths, Row};

/// Errors and times are drawn on logarithmic axes: values below this floor (an exact
/// reconstruction's error of 0) are drawn at it.
pub const ERROR_FLOOR: f64 = 1e-12;

/// Run times below this (seconds) are drawn at it.
const TIME_FLOOR: f64 = 1e-4;

/// Checks, before a sweep, that the demo's depth figure (the true map and one panel per solver
/// side by side, at least one figure pixel per scene pixel) fits within the figure limits of
/// [`crate::report::plot`]: about 16384 / (solvers + 1) pixel columns at most.
///
/// # Errors
/// [`crate::Error::InvalidParameter`] `size` when it would not.
pub fn check_depth_figure(config: &ExperimentConfig) -> Result<()> {
    let panels = config.solvers.len() + 1;
    let (m, n) = (config.size.m, config.size.n);
    // Each panel is at least n pixels wide, with a gap of 24; the colour bar and margins take
    // about 300 more. Rows: the panels' height, with the title and legend, about 200 more.
    let width = panels.saturating_mul(n + 24).saturating_add(300);
    if width > crate::report::plot::MAX_SIDE || m + 200 > crate::report::plot::MAX_SIDE {
        return Err(crate::Error::param(
            "size",
            format!(
                "{}: the demo's depth figure of {panels} maps side by side would be about \
                 {width} x {} pixels, more than the {} a figure may have on a side; use fewer \
                 solvers, a smaller size, or `compare` (which draws no depth maps)",
                config.size,
                m + 200,
                crate::report::plot::MAX_SIDE
            ),
        ));
    }
    Ok(())
}

fn describe(config: &ExperimentConfig) -> String {
    format!("{} {}", config.scene_names(), config.size)
}

/// The true depth map and every solver's estimate of one problem, side by side with one colour
/// bar in metres (τ = 200 ps per bin) over the scene's full depth range and a key for pixels
/// without a return. Each estimate's title gives the percentage of lit pixels recovered at the
/// exact depth (from `rows`, the rows of the same problem).
///
/// # Errors
/// The errors of [`depth_panels`] (no map, mismatched shapes, an image too large).
pub fn depth_figure(
    config: &ExperimentConfig,
    depths: &CaseDepths,
    rows: &[&Row],
) -> Result<DepthFigure> {
    let g = config.size;
    let c = &depths.case;
    let titles: Vec<String> = std::iter::once("truth".to_string())
        .chain(depths.estimates.iter().map(|(m, _)| {
            let pct = rows
                .iter()
                .find(|r| r.solver == m.name())
                .and_then(|r| r.exact_pct);
            match pct {
                Some(p) => format!("{m} {p:.0}%"),
                None => m.to_string(),
            }
        }))
        .collect();
    let panels: Vec<(&str, &ndarray::Array2<i32>)> = std::iter::once(&depths.truth)
        .chain(depths.estimates.iter().map(|(_, d)| d))
        .zip(&titles)
        .map(|(d, t)| (t.as_str(), d))
        .collect();
    let title = format!(
        "{}, Kₚ = {} ({}), {}, seed {}: depth maps",
        describe(config),
        c.pulse_len,
        g.regime(c.pulse_len),
        noise_text(c.snr_db),
        c.seed
    );
    let ks = i32::try_from(g.ks).unwrap_or(i32::MAX);
    let options = DepthOptions::new(depth_bin_m(DEFAULT_TAU_S)?, "m")
        .title(title)
        .range(0, (ks - 1).max(0));
    depth_panels(&panels, &options)
}

fn floor(v: f64, lo: f64) -> f64 {
    if v.is_finite() {
        v.max(lo)
    } else {
        lo
    }
}

/// One series per solver of `(x, y)` points from the finished rows, in the configured solver
/// order.
fn per_solver(
    config: &ExperimentConfig,
    rows: &[Row],
    point: impl Fn(&Row) -> Option<(f64, f64)>,
) -> Vec<Series> {
    config
        .solvers
        .iter()
        .filter_map(|m| {
            let mut pts: Vec<(usize, (f64, f64))> = rows
                .iter()
                .filter(|r| r.solver == m.name())
                .filter_map(|r| point(r).map(|p| (r.pulse_len, p)))
                .collect();
            pts.sort_by_key(|(kp, _)| *kp);
            (!pts.is_empty()).then(|| Series::new(m.name(), pts.into_iter().map(|(_, p)| p)))
        })
        .collect()
}

/// The demo's error against run time: ‖X − X̂‖/‖X‖ against wall time (logarithmic axis), one
/// line per solver joining its runs in increasing K_p. The error axis is logarithmic when the
/// errors span more than a decade, linear otherwise.
///
/// # Errors
/// The errors of [`line_plot`] (e.g. no finished run).
pub fn error_vs_time(config: &ExperimentConfig, rows: &[Row]) -> Result<ChartFigure> {
    let mut kps = config.pulse_lens.clone();
    kps.sort_unstable();
    let kps: Vec<String> = kps.iter().map(usize::to_string).collect();
    let series = per_solver(config, rows, |r| {
        r.relative_error
            .map(|e| (floor(r.time_s, TIME_FLOOR), floor(e, ERROR_FLOOR)))
    });
    // A logarithmic error axis only when the errors span more than a decade.
    let (lo, hi) = series
        .iter()
        .flat_map(|s| s.points().iter().map(|p| p.1))
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), e| {
            (lo.min(e), hi.max(e))
        });
    let log_y = hi > 10.0 * lo;
    let mut chart = Chart::new(format!(
        "Error against run time: {}, Kₚ = {}",
        describe(config),
        kps.join(", ")
    ))
    .x_label("wall time (s), log scale")
    .y_label(if log_y {
        "relative error ‖X − X̂‖/‖X‖ (floor 10⁻¹²), log scale"
    } else {
        "relative error ‖X − X̂‖/‖X‖"
    })
    .log_x(true)
    .log_y(log_y)
    .size(1100, 620)
    .legend(LegendPosition::Outside);
    for s in series {
        chart = chart.series(s);
    }
    line_plot(&chart)
}

/// The points of `pts` not dominated by another (no other is both faster and more accurate),
/// in increasing time.
fn pareto_front(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for p in pts {
        if front.last().is_none_or(|l| p.1 < l.1) {
            front.push(p);
        }
    }
    front
}

/// The compare sweep's Pareto plot: wall time against ‖X − X̂‖/‖X‖ for every finished run (log
/// axes), one marker per solver, and the Pareto front (the runs no other run beats in both) as
/// a grey line.
///
/// # Errors
/// The errors of [`scatter_plot`] (e.g. no finished run).
pub fn pareto_chart(config: &ExperimentConfig, rows: &[Row]) -> Result<ChartFigure> {
    let point = |r: &Row| {
        r.relative_error
            .map(|e| (floor(e, ERROR_FLOOR), floor(r.time_s, TIME_FLOOR)))
    };
    let mut chart = Chart::new(format!(
        "Time against error: {}, every run ({} seed(s), {} noise level(s))",
        describe(config),
        config.seeds,
        config.snr_db.len()
    ))
    .x_label("relative error ‖X − X̂‖/‖X‖ (floor 10⁻¹²), log scale")
    .y_label("wall time (s)")
    .log_x(true)
    .log_y(true)
    .size(1100, 620)
    .legend(LegendPosition::Outside);
    for s in per_solver(config, rows, point) {
        chart = chart.series(s);
    }
    // Front: least time for a given error, i.e. the non-dominated (error, time) points.
    let front = pareto_front(rows.iter().filter_map(point).collect());
    if !front.is_empty() {
        chart = chart.series(
            Series::new("Pareto front", front)
                .colour(Rgb::hex(0x9a9a9a))
                .marker(Marker::Plus)
                .style(SeriesStyle::Lines),
        );
    }
    scatter_plot(&chart)
}

/// The compare sweep's phase-transition plot for one noise level: the median over seeds of
/// ‖X − X̂‖/‖X‖ against K_p (both on logarithmic axes), one line per solver, with the critical
/// K_p = (M·N − 1)·K_s + 1 as a dashed vertical line.
///
/// # Errors
/// The errors of [`line_plot`] (e.g. no finished run at this noise level).
pub fn phase_chart(
    config: &ExperimentConfig,
    level: NoiseLevel,
    rows: &[Row],
) -> Result<ChartFigure> {
    let critical = config.size.critical_pulse_len();
    let mut kps = config.pulse_lens.clone();
    kps.sort_unstable();
    let mut chart = Chart::new(format!(
        "Error against Kₚ: {}, {}, median of {} seed(s)",
        describe(config),
        noise_text(level),
        config.seeds
    ))
    .x_label("pulse length Kₚ, log scale")
    .y_label("relative error ‖X − X̂‖/‖X‖ (floor 10⁻¹²)")
    .log_x(true)
    .log_y(true)
    .size(1100, 620)
    .legend(LegendPosition::Outside)
    .vline(critical as f64, format!("critical Kₚ = {critical}"));
    for m in &config.solvers {
        let pts: Vec<(f64, f64)> = kps
            .iter()
            .filter_map(|&kp| {
                medians(rows, level, m.name(), kp, |r| r.relative_error)
                    .map(|e| (kp as f64, floor(e, ERROR_FLOOR)))
            })
            .collect();
        if !pts.is_empty() {
            chart = chart.series(Series::new(m.name(), pts));
        }
    }
    line_plot(&chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_front_keeps_only_undominated_points() {
        let front = pareto_front(vec![
            (1.0, 5.0),
            (2.0, 6.0),
            (3.0, 1.0),
            (0.5, 9.0),
            (3.0, 0.5),
        ]);
        assert_eq!(front, [(0.5, 9.0), (1.0, 5.0), (3.0, 0.5)]);
    }
}
