//! Long work from Python: on a worker thread with the GIL released (so that other Python
//! threads run, and rayon's threads inside the work never wait for it), while the calling
//! thread wakes every [`TICK`] to run Python's signal handlers and report progress.
//!
//! Python runs its signal handlers (Ctrl-C's `KeyboardInterrupt`) only on the main thread and
//! only when that thread runs Python: a Rust loop that never returns to the interpreter cannot
//! be interrupted. Here the calling thread calls `check_signals` at every tick; when it raises,
//! the work's stop flag is set, the work ends within a few milliseconds (the transport looks at
//! the flag every [`lidarsim::transport::STOP_CHECK_PHOTONS`] photons), and the exception goes
//! to the caller. Progress is read from atomics the work updates and handed to the caller's
//! callback on the calling thread, where calling Python is allowed.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use pyo3::prelude::*;

use crate::errors::runtime_error;

/// How often the waiting thread looks for Ctrl-C and progress: well inside the second a user
/// waits for Ctrl-C to act, and a finished run is seen at once (the result wakes the waiter).
const TICK: Duration = Duration::from_millis(100);

/// What the work sees: the stop flag to honour and where to report progress.
pub struct Control {
    stop: AtomicBool,
    done: AtomicUsize,
    total: AtomicUsize,
}

impl Control {
    /// The flag the work stops at.
    pub fn stop(&self) -> &AtomicBool {
        &self.stop
    }

    /// Report `done` of `total` steps.
    pub fn report(&self, done: usize, total: usize) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(done, Ordering::Relaxed);
    }

    /// One more step done (of a total given by [`Self::report`]).
    pub fn tick(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }

    fn progress(&self) -> (usize, usize) {
        (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }
}

/// Run `work` with the GIL released, calling `progress(done, total)` (a Python callable) when
/// the work's count moves, and stopping it on Ctrl-C or any other exception a signal handler
/// raises (which is returned). `work` must return soon after its stop flag is set.
pub fn watch<T, F>(py: Python<'_>, progress: Option<&Bound<'_, PyAny>>, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&Control) -> T + Send,
{
    let control = Control {
        stop: AtomicBool::new(false),
        done: AtomicUsize::new(0),
        total: AtomicUsize::new(0),
    };
    let callback: Option<Py<PyAny>> = progress.map(|p| p.clone().unbind());
    let report = |py: Python<'_>, last: &mut (usize, usize)| -> PyResult<()> {
        let now = control.progress();
        if let Some(cb) = &callback
            && now != *last
        {
            cb.call1(py, now)?;
            *last = now;
        }
        Ok(())
    };
    let outcome = py.detach(|| {
        std::thread::scope(|s| {
            let (tx, rx) = mpsc::channel();
            let control = &control;
            let worker = s.spawn(move || {
                // The receiver outlives the worker unless the waiter failed first; then the
                // result is not wanted.
                let _ = tx.send(work(control));
            });
            let mut last = (0, 0);
            let mut raised = None;
            let result = loop {
                match rx.recv_timeout(TICK) {
                    Ok(r) => break Some(r),
                    Err(mpsc::RecvTimeoutError::Disconnected) => break None,
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                }
                if raised.is_none()
                    && let Err(e) =
                        Python::attach(|py| py.check_signals().and_then(|_| report(py, &mut last)))
                {
                    control.stop.store(true, Ordering::Relaxed);
                    raised = Some(e);
                }
            };
            let panicked = worker.join().is_err();
            (result, raised, panicked, last)
        })
    });
    let (result, raised, panicked, mut last) = outcome;
    if let Some(e) = raised {
        return Err(e);
    }
    if panicked {
        return Err(runtime_error(
            "lidarsim panicked (a bug in lidarsim; please report it)",
        ));
    }
    let result = result.ok_or_else(|| runtime_error("the work ended without a result"))?;
    // The last count (a run's 100 %), seen before the caller looks at the result.
    report(py, &mut last)?;
    Ok(result)
}
