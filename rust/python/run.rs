//! How a call runs in the core: without the GIL, on a rayon pool of the asked size, polling for
//! Ctrl-C, with a panic caught and turned into an error.

use std::cell::RefCell;
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

thread_local! {
    /// The pools of a given size this thread asked for, each with the process it was built in:
    /// kept, since starting threads was most of a short call (a diagnosis makes hundreds). Per
    /// calling thread, so that two Python threads asking for one thread each still run side by side.
    static SIZED: RefCell<Vec<(usize, u32, Arc<ThreadPool>)>> = const { RefCell::new(Vec::new()) };
}

/// Pool sizes a thread keeps (a caller rarely asks for more than one or two).
const SIZES_KEPT: usize = 4;

/// How often the thread that waits for the core looks for a pending signal (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Samples (times parameters) below which a call runs on the calling thread ([`run_short`]): a
/// millisecond or so, well within [`SIGNAL_POLL`].
pub(crate) const SHORT_CALL: usize = 1 << 18;

fn build(n: usize) -> Result<Arc<ThreadPool>, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map(Arc::new)
        .map_err(|e| format!("cannot start {n} threads ({e}); use n_threads=1 or raise the process limit"))
}

/// A rayon pool of `n_threads` threads (0 = all cores, shared by the calls of this process; else
/// this thread's own, kept for its next call).
fn pool(n_threads: usize) -> Result<Arc<ThreadPool>, String> {
    let pid = std::process::id();
    if n_threads != 0 {
        return SIZED.with(|sized| {
            let mut sized = sized.borrow_mut();
            if let Some(i) = sized.iter().position(|(n, _, _)| *n == n_threads) {
                if sized[i].1 == pid {
                    return Ok(sized[i].2.clone());
                }
                // Inherited through fork: its threads are not in this process (see ALL_CORES).
                std::mem::forget(sized.remove(i));
            }
            let fresh = build(n_threads)?;
            if sized.len() == SIZES_KEPT {
                sized.remove(0);
            }
            sized.push((n_threads, pid, fresh.clone()));
            Ok(fresh)
        });
    }
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
        // The core runs on a worker of the pool (where its own parallel loops run), and this
        // thread polls for signals meanwhile: no thread is started for a call.
        pool.in_place_scope(|scope| {
            let (tx, rx) = mpsc::channel::<Outcome<T>>();
            let cancel = &cancel;
            scope.spawn(move |_| {
                let _ = tx.send(catch_unwind(AssertUnwindSafe(|| f(cancel))));
            });
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

/// [`run`] for a call known to be short (about [`SHORT_CALL`] samples or less, computed
/// sequentially): on the calling thread, without the GIL, its panic caught. Handing it to a
/// pool's worker and waking that thread cost more than such a call (a diagnosis makes hundreds);
/// a Ctrl-C meanwhile is seen as soon as it returns.
pub(crate) fn run_short<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&AtomicBool) -> Result<T, ArxError> + Send,
) -> PyResult<T> {
    let cancel = AtomicBool::new(false);
    match py.detach(|| catch_unwind(AssertUnwindSafe(|| f(&cancel)))) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_pyerr(py, e)),
        Err(panic) => Err(from_panic(py, panic)),
    }
}
