//! One way to run core work from Python: `run` releases the GIL, runs the work on its own
//! thread with panics guarded, and meanwhile watches on the calling thread: every `POLL` it
//! takes the GIL to check for Ctrl-C, and calls the Python progress callback (at the start,
//! then every `GAP`, and once at the end) with the latest fraction the core stored. The core's
//! own callback only stores that fraction and reads the stop flag, so Python is never called
//! from rayon's workers. A callback returning False raises `Cancelled`; Ctrl-C raises
//! KeyboardInterrupt; a callback's exception is re-raised; each once the core has returned
//! (within a second: docs/api.md, "Long calls").

use crate::convert::{guard, to_py, Cancelled, GuardError};
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::{Duration, Instant};
use translucent_core::progress::ProgressFn;
use translucent_core::Error;

/// How often the watcher wakes to check for Ctrl-C and the time.
const POLL: Duration = Duration::from_millis(50);
/// The least time between two calls of the Python callback (the most is GAP + POLL).
const GAP: Duration = Duration::from_millis(250);

/// What the work thread and the watcher share.
struct Shared {
    /// The latest fraction the core reported (f32 bits).
    fraction: AtomicU32,
    /// Set by the watcher: the core's callback returns false from now on.
    stop: AtomicBool,
    finished: AtomicBool,
}

/// A progress callable checked up front (TypeError naming `progress` otherwise).
pub fn callback(progress: Option<Py<PyAny>>, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
    match progress {
        Some(p) if p.is_none(py) => Ok(None),
        Some(p) if !p.bind(py).is_callable() => Err(PyTypeError::new_err(format!(
            "progress must be a callable taking a fraction in [0, 1] (or None), got {}",
            p.bind(py).get_type().name()?
        ))),
        p => Ok(p),
    }
}

/// Runs `work` (given the core's progress callback) as described in the module's head.
pub fn run<T, F>(py: Python<'_>, progress: Option<Py<PyAny>>, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&ProgressFn) -> Result<T, Error> + Send,
{
    let progress = callback(progress, py)?;
    let shared = Shared {
        fraction: AtomicU32::new(0f32.to_bits()),
        stop: AtomicBool::new(false),
        finished: AtomicBool::new(false),
    };
    let watcher = std::thread::current();
    std::thread::scope(|s| {
        let mut raised: Option<PyErr> = None;
        let mut cancelled = false;
        // The bar only moves forward, whatever order the core's stages report in.
        let mut shown = -1f32;
        let call = |raised: &mut Option<PyErr>, cancelled: &mut bool, shown: &mut f32| {
            let Some(cb) = &progress else { return };
            let f = f32::from_bits(shared.fraction.load(Ordering::Relaxed)).max(*shown);
            *shown = f;
            match cb.call1(py, (f,)) {
                Ok(r) if matches!(r.extract::<bool>(py), Ok(false)) => *cancelled = true,
                Ok(_) => {}
                Err(e) => *raised = Some(e),
            }
        };
        // The first call before the work starts: 0.0; a refusal stops the work at its first tick.
        call(&mut raised, &mut cancelled, &mut shown);
        if raised.is_some() || cancelled {
            shared.stop.store(true, Ordering::Relaxed);
        }
        let sh = &shared;
        let handle = s.spawn(move || {
            // A NaN fraction only asks whether to go on (`progress::cancel_only`).
            let core = |f: f32| {
                if f.is_finite() {
                    sh.fraction
                        .store(f.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
                }
                !sh.stop.load(Ordering::Relaxed)
            };
            let result = guard(|| work(&core));
            sh.finished.store(true, Ordering::Release);
            watcher.unpark();
            result
        });
        let mut last_call = Instant::now();
        loop {
            if raised.is_some() || cancelled {
                shared.stop.store(true, Ordering::Relaxed);
            }
            py.detach(|| {
                let until = Instant::now() + POLL;
                while !shared.finished.load(Ordering::Acquire) {
                    let now = Instant::now();
                    if now >= until {
                        break;
                    }
                    std::thread::park_timeout(until - now);
                }
            });
            if shared.finished.load(Ordering::Acquire) {
                break;
            }
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    raised = Some(e); // KeyboardInterrupt, or a handler's own exception
                    continue;
                }
            }
            if raised.is_none() && !cancelled && last_call.elapsed() >= GAP {
                call(&mut raised, &mut cancelled, &mut shown);
                last_call = Instant::now();
            }
        }
        let result = handle
            .join()
            .unwrap_or_else(|_| Err(GuardError::Panic("the work thread panicked".into())));
        if let Some(e) = raised.take() {
            return Err(e);
        }
        if cancelled {
            return Err(Cancelled::new_err(Error::Cancelled.to_string()));
        }
        match result {
            Ok(v) => {
                // The end: the bar full, and a last chance to refuse the result.
                shared.fraction.store(1f32.to_bits(), Ordering::Relaxed);
                call(&mut raised, &mut cancelled, &mut shown);
                match (raised, cancelled) {
                    (Some(e), _) => Err(e),
                    (None, true) => Err(Cancelled::new_err(Error::Cancelled.to_string())),
                    (None, false) => Ok(v),
                }
            }
            Err(e) => Err(into_py(e)),
        }
    })
}

/// A core error as its Python exception; a caught panic as a RuntimeError naming it.
pub fn into_py(err: GuardError) -> PyErr {
    match err {
        GuardError::Core(e) => to_py(e),
        GuardError::Panic(m) => PyRuntimeError::new_err(format!(
            "internal error in translucent (please report): {m}"
        )),
    }
}

/// The error for an object whose lock another thread holds.
pub fn busy(what: &str) -> PyErr {
    PyRuntimeError::new_err(format!(
        "this {what} is busy in another thread (a precompute, an update or a backend change); \
         call it again when that returns"
    ))
}
