//! A terminal progress bar for the iterative solvers, as an [`Observer`].

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::{Control, IterationInfo, Observer};

/// The bar's layout: elapsed time, bar, iteration / limit, the message, the estimated time left.
const TEMPLATE: &str = "[{elapsed_precise}] {bar:30} {pos}/{len} {msg} (ETA {eta})";

/// Clears the bar when it goes out of scope without having been finished.
#[derive(Debug)]
struct Bar(ProgressBar);

impl Drop for Bar {
    fn drop(&mut self) {
        if !self.0.is_finished() {
            self.0.finish_and_clear();
        }
    }
}

/// A progress bar on stderr showing the iteration against the iteration limit, the relative
/// residual and the objective of the last iteration, and the estimated time left.
///
/// The bar is hidden when stderr is not a terminal (it then draws nothing) or when built with
/// [`quiet`](Self::quiet)`(true)`. It is cleared by [`finish`](Self::finish) or, at the latest,
/// when the observer is dropped. Another observer can be [`chain`](Self::chain)ed after it: it
/// sees every iteration too, and its [`Control::Stop`] ends the run.
///
/// # Example
/// ```
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{
///     fista, Control, FistaParams, IterationInfo, ProgressObserver, Stopping, Termination,
/// };
///
/// let a = DenseMatrix::new(ndarray::array![[1.0, 0.5], [0.0, 2.0], [1.0, 1.0]]).unwrap();
/// let y = [1.0, 1.0, 0.5];
/// let params = FistaParams { stopping: Stopping::iterations(50), ..FistaParams::default() };
/// // Show progress, and stop after 5 iterations.
/// let stop_early = |info: &IterationInfo<'_, f64>| {
///     if info.iteration >= 5 { Control::Stop } else { Control::Continue }
/// };
/// let mut progress = ProgressObserver::new(params.stopping.max_iter).chain(stop_early);
/// let mut x = vec![0.0; 2];
/// let report = fista(&a, &y, &mut x, &params, &mut progress).unwrap();
/// progress.finish();
/// assert_eq!(report.termination, Termination::Observer);
/// assert_eq!(progress.iteration(), 5);
/// ```
#[derive(Debug)]
pub struct ProgressObserver<O = ()> {
    bar: Bar,
    /// Whether the bar draws nothing (then the message is not formatted either).
    hidden: bool,
    /// The last iteration observed.
    iteration: usize,
    next: O,
}

impl ProgressObserver {
    /// A bar for a run of at most `max_iter` iterations (the `max_iter` of the solver's
    /// [`Stopping`](super::Stopping) rules), drawn on stderr if it is a terminal.
    pub fn new(max_iter: usize) -> Self {
        let style =
            ProgressStyle::with_template(TEMPLATE).unwrap_or_else(|_| ProgressStyle::default_bar());
        let bar = ProgressBar::new(max_iter as u64).with_style(style);
        let hidden = bar.is_hidden();
        ProgressObserver {
            bar: Bar(bar),
            hidden,
            iteration: 0,
            next: (),
        }
    }
}

impl<O> ProgressObserver<O> {
    /// Hides the bar when `quiet` (it still counts iterations).
    #[must_use]
    pub fn quiet(mut self, quiet: bool) -> Self {
        if quiet {
            self.bar.0.set_draw_target(ProgressDrawTarget::hidden());
            self.hidden = true;
        }
        self
    }

    /// Passes every iteration on to `next` after updating the bar; `next` decides whether the
    /// run goes on. Replaces any observer chained before.
    pub fn chain<P>(self, next: P) -> ProgressObserver<P> {
        ProgressObserver {
            bar: self.bar,
            hidden: self.hidden,
            iteration: self.iteration,
            next,
        }
    }

    /// The chained observer.
    pub fn chained(&self) -> &O {
        &self.next
    }

    /// The last iteration observed (0 before the first).
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Whether the bar draws nothing (stderr is not a terminal, or [`quiet`](Self::quiet)).
    pub fn is_hidden(&self) -> bool {
        self.hidden
    }

    /// Clears the bar from the terminal.
    pub fn finish(&self) {
        self.bar.0.finish_and_clear();
    }
}

impl<T, O: Observer<T>> Observer<T> for ProgressObserver<O> {
    fn observe(&mut self, info: &IterationInfo<'_, T>) -> Control {
        let bar = &self.bar.0;
        if !self.hidden {
            bar.set_message(format!(
                "residual {:.3e}  objective {:.4e}",
                info.residual, info.objective
            ));
        }
        bar.set_position(info.iteration as u64);
        self.iteration = info.iteration;
        self.next.observe(info)
    }
}
