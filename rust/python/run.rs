//! How a call runs in the core: without the GIL, on a rayon pool of the asked size, polling for
//! Ctrl-C, with a panic caught and turned into an error.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

use pyo3::prelude::*;
use rayon::ThreadPool;

use super::errors::{from_panic, to_pyerr, ArxidError};
use crate::error::ArxError;
use crate::sweep::least_squares::clamp_threads;

/// The pool for `n_threads = 0` (all cores) and the process it was built in. rayon's worker
/// threads do not survive `fork`: a child that used the parent's pool would wait for ever, so a
/// child (another pid) builds its own.
static ALL_CORES: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// How often the thread that waits for the core looks for a pending signal (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// A rayon pool of `n_threads` threads (0 = all cores, shared by the calls of this process).
fn pool(n_threads: usize) -> Result<Arc<ThreadPool>, String> {
    let build = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map(Arc::new)
            .map_err(|e| format!("cannot start {n} threads ({e}); use n_threads=1 or raise the process limit"))
    };
    if n_threads != 0 {
        return build(n_threads);
    }
    let pid = std::process::id();
    let mut slot = ALL_CORES.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((owner, p)) = slot.as_ref() {
        if *owner == pid {
            return Ok(p.clone());
        }
    }
    let fresh = build(0)?;
    if let Some((_, inherited)) = slot.replace((pid, fresh.clone())) {
        // The parent's pool: its threads are not in this process, so dropping it could wait for them.
        std::mem::forget(inherited);
    }
    Ok(fresh)
}

type Outcome<T> = std::thread::Result<Result<T, ArxError>>;

/// Runs `f(cancel)` without the GIL on `n_threads` threads (0 = all), turning a panic into an
/// error. Results do not depend on the thread count, so the count is capped by [`clamp_threads`].
///
/// The calling thread waits and polls for signals every [`SIGNAL_POLL`]: on Ctrl-C it sets
/// `cancel`, which the core checks between blocks of work, and raises `KeyboardInterrupt` once
/// the core has stopped.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    n_threads: usize,
    f: impl FnOnce(&AtomicBool) -> Result<T, ArxError> + Send,
) -> PyResult<T> {
    let pool = pool(clamp_threads(n_threads)).map_err(ArxidError::new_err)?;
    let cancel = AtomicBool::new(false);
    let (out, interrupt) = py.detach(|| {
        std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel::<Outcome<T>>();
            let (cancel, pool) = (&cancel, &pool);
            let spawned = std::thread::Builder::new().spawn_scoped(scope, move || {
                let _ = tx.send(catch_unwind(AssertUnwindSafe(|| pool.install(|| f(cancel)))));
            });
            if let Err(e) = spawned {
                return (Err(Box::new(format!("cannot start a thread ({e})")) as Box<dyn std::any::Any + Send>), None);
            }
            let mut interrupt = None;
            loop {
                match rx.recv_timeout(SIGNAL_POLL) {
                    Ok(outcome) => return (outcome, interrupt),
                    Err(mpsc::RecvTimeoutError::Timeout) if interrupt.is_none() => {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            cancel.store(true, Ordering::Relaxed);
                            interrupt = Some(e);
                        }
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        let lost: Box<dyn std::any::Any + Send> = Box::new("the worker thread ended without a result");
                        return (Err(lost), interrupt);
                    }
                }
            }
        })
    });
    if let Some(e) = interrupt {
        return Err(e);
    }
    match out {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_pyerr(py, e)),
        Err(panic) => Err(from_panic(py, panic)),
    }
}
