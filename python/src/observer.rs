//! What Python sees of a solver's iterations: its callback, Ctrl-C, and the work on a thread
//! of its own while the interpreter's thread watches for signals.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use rdlidar::solver::{Control, IterationInfo};

/// What Python sees of the iterations of a solver: the callback, and the first exception
/// raised (in the callback, or Ctrl-C), after which `cancel` is raised: every solver then ends
/// within one operator application (see [`rdlidar::lidar::Cancellable`]).
pub(crate) struct PyObserver {
    callback: Option<Py<PyAny>>,
    failure: Mutex<Option<PyErr>>,
    pub(crate) cancel: AtomicBool,
}

impl PyObserver {
    pub(crate) fn new(callback: Option<Py<PyAny>>) -> Self {
        PyObserver {
            callback,
            failure: Mutex::new(None),
            cancel: AtomicBool::new(false),
        }
    }

    /// Keeps the first exception and cancels the work.
    pub(crate) fn fail(&self, e: PyErr) {
        if let Ok(mut f) = self.failure.lock() {
            f.get_or_insert(e);
        }
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// One iteration (of tile `tile` for a tiled acquisition): takes the GIL back and calls the
    /// callback with the iteration's numbers; a true return value stops the solver, an
    /// exception is kept and cancels every solver.
    pub(crate) fn observe<T>(&self, tile: Option<usize>, info: &IterationInfo<'_, T>) -> Control {
        if self.cancel.load(Ordering::Relaxed) {
            return Control::Stop;
        }
        let Some(cb) = &self.callback else {
            return Control::Continue;
        };
        Python::attach(|py| {
            let go_on = (|| -> PyResult<bool> {
                let d = PyDict::new(py);
                d.set_item("iteration", info.iteration)?;
                d.set_item("residual", info.residual)?;
                d.set_item("objective", info.objective)?;
                d.set_item("change", info.change)?;
                d.set_item("seconds", info.elapsed.as_secs_f64())?;
                if let Some(t) = tile {
                    d.set_item("tile", t)?;
                }
                let stop = cb.call1(py, (d,))?;
                Ok(!stop.bind(py).is_truthy()?)
            })();
            match go_on {
                Ok(true) => Control::Continue,
                Ok(false) => Control::Stop,
                Err(e) => {
                    self.fail(e);
                    Control::Stop
                }
            }
        })
    }

    /// Runs `work` on a worker thread, the GIL released, while this thread (the interpreter's
    /// main thread, where Python handles signals) looks for Ctrl-C every 50 ms and cancels the
    /// work when one comes.
    pub(crate) fn watch<R: Send>(&self, py: Python<'_>, work: impl FnOnce() -> R + Send) -> R {
        py.detach(|| {
            std::thread::scope(|s| {
                let me = std::thread::current();
                let worker = s.spawn(move || {
                    let r = work();
                    me.unpark();
                    r
                });
                while !worker.is_finished() {
                    std::thread::park_timeout(std::time::Duration::from_millis(50));
                    if !self.cancel.load(Ordering::Relaxed) {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            self.fail(e);
                        }
                    }
                }
                worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
        })
    }

    /// The exception raised in the callback or by Ctrl-C, if any.
    pub(crate) fn failure(self) -> Option<PyErr> {
        self.failure.into_inner().ok().flatten()
    }
}
