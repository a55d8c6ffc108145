//! numpy's memory handler while an analysis runs: large freed blocks are kept for the next array of
//! the same size instead of going back to the system.
//!
//! Why: an analysis of a long record makes many temporaries of one length (16 MB each at 2M
//! samples). Freed to the system, each comes back as fresh pages the kernel must zero, and in a
//! virtual machine that reports free pages to its host, map again: a third of the CPU time of a
//! 4M-sample analysis went there. A kept block is reused as it is.
//!
//! The handler is numpy's per-context allocator (NEP 49, numpy >= 1.22): `keep_array_blocks` sets
//! it in the caller's context and `release_array_blocks` puts the previous one back; when the last
//! scope ends, every kept block is freed. Blocks stay plain `malloc` blocks throughout, so an array
//! allocated here and freed after the scope (or by numpy's default handler's rules) is freed as
//! usual. Only Linux keeps blocks (the usable size of a block comes from glibc/musl's
//! `malloc_usable_size`); elsewhere the handler passes every call straight to the system.

use std::ffi::{c_char, c_void, CStr};
use std::sync::{Mutex, PoisonError};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyCapsule;

extern "C" {
    fn malloc(size: usize) -> *mut c_void;
    fn calloc(count: usize, size: usize) -> *mut c_void;
    fn realloc(block: *mut c_void, size: usize) -> *mut c_void;
    fn free(block: *mut c_void);
    #[cfg(target_os = "linux")]
    fn malloc_usable_size(block: *mut c_void) -> usize;
    #[cfg(target_os = "linux")]
    fn madvise(address: *mut c_void, length: usize, advice: i32) -> i32;
}

/// Fresh blocks from this size on are offered huge pages, as numpy's default handler does.
const HUGE_FROM: usize = 1 << 22;

/// Ask for transparent huge pages over the whole pages of a fresh block (numpy's default handler
/// does so from 4 MiB; without it a 16 MB array takes 4,096 faults instead of 8).
#[cfg(target_os = "linux")]
fn huge_pages(block: *mut c_void, size: usize) -> *mut c_void {
    const PAGE: usize = 4096;
    const MADV_HUGEPAGE: i32 = 14;
    if !block.is_null() && size >= HUGE_FROM {
        let start = (block as usize).next_multiple_of(PAGE);
        let end = (block as usize + size) / PAGE * PAGE;
        // SAFETY: the range lies inside the block; advice changes no contents. Its result is a
        // hint's: ignored.
        unsafe { madvise(start as *mut c_void, end - start, MADV_HUGEPAGE) };
    }
    block
}

#[cfg(not(target_os = "linux"))]
fn huge_pages(block: *mut c_void, _size: usize) -> *mut c_void {
    block
}

/// Blocks smaller than this go straight to the system (numpy's own cache and malloc's bins are
/// fast there; a kept block is worth the lock only when it spares fresh pages).
const SMALLEST: usize = 1 << 20;

/// A kept block serves a request up to this many bytes smaller than its usable size (requests of
/// one array size get one usable size; the slack never lets a block serve a much smaller array).
const SLACK: usize = 1 << 16;

/// At most this many blocks are kept (a bound on the list's length, and on a lookup's time).
const MAX_BLOCKS: usize = 64;

struct Kept {
    /// (address, usable bytes), oldest first.
    blocks: Vec<(usize, usize)>,
    bytes: usize,
    /// Bytes kept at most; 0 outside every scope.
    limit: usize,
    scopes: usize,
}

impl Kept {
    /// Takes the oldest kept block out of the list (there is one): its address and usable bytes.
    fn oldest(&mut self) -> (usize, usize) {
        let (address, usable) = self.blocks.remove(0);
        self.bytes -= usable;
        (address, usable)
    }
}

static KEPT: Mutex<Kept> = Mutex::new(Kept { blocks: Vec::new(), bytes: 0, limit: 0, scopes: 0 });

fn kept() -> std::sync::MutexGuard<'static, Kept> {
    KEPT.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A kept block that can hold `size` bytes (the newest that fits), taken out of the list. When
/// none fits, the oldest kept blocks of at least `size` bytes in all are freed first: the fresh
/// block then takes their place, and what the process holds (arrays and kept blocks) grows no
/// more than it would have without keeping.
fn take(size: usize) -> Option<*mut c_void> {
    if size < SMALLEST {
        return None;
    }
    let mut freed = Vec::new();
    let found = {
        let mut k = kept();
        match k.blocks.iter().rposition(|&(_, usable)| usable >= size && usable - size <= SLACK) {
            Some(at) => {
                let (address, usable) = k.blocks.remove(at);
                k.bytes -= usable;
                Some(address as *mut c_void)
            }
            None => {
                let mut room = 0;
                while room < size && !k.blocks.is_empty() {
                    let (address, usable) = k.oldest();
                    room += usable;
                    freed.push(address);
                }
                None
            }
        }
    };
    for address in freed {
        // SAFETY: a kept block is a malloc block no array owns.
        unsafe { free(address as *mut c_void) };
    }
    found
}

/// Keep `block` if the scope's limit allows, making room by freeing the oldest kept blocks; the
/// blocks to free are returned, to be freed outside the lock.
#[cfg(target_os = "linux")]
fn keep(block: *mut c_void, size: usize) -> Vec<usize> {
    if size < SMALLEST {
        return vec![block as usize];
    }
    // SAFETY: `block` is a live malloc block (numpy frees only what its handler allocated).
    let usable = unsafe { malloc_usable_size(block) };
    let mut k = kept();
    if usable > k.limit {
        return vec![block as usize];
    }
    let mut out = Vec::new();
    while k.bytes + usable > k.limit || k.blocks.len() >= MAX_BLOCKS {
        out.push(k.oldest().0);
    }
    k.blocks.push((block as usize, usable));
    k.bytes += usable;
    out
}

#[cfg(not(target_os = "linux"))]
fn keep(block: *mut c_void, _size: usize) -> Vec<usize> {
    vec![block as usize]
}

unsafe extern "C" fn kept_malloc(_: *mut c_void, size: usize) -> *mut c_void {
    take(size).unwrap_or_else(|| huge_pages(malloc(size), size))
}

unsafe extern "C" fn kept_calloc(_: *mut c_void, count: usize, size: usize) -> *mut c_void {
    match count.checked_mul(size).and_then(take) {
        Some(block) => {
            std::ptr::write_bytes(block.cast::<u8>(), 0, count * size);
            block
        }
        None => huge_pages(calloc(count, size), count.saturating_mul(size)),
    }
}

unsafe extern "C" fn kept_realloc(_: *mut c_void, block: *mut c_void, size: usize) -> *mut c_void {
    realloc(block, size)
}

unsafe extern "C" fn kept_free(_: *mut c_void, block: *mut c_void, size: usize) {
    if block.is_null() {
        return;
    }
    for address in keep(block, size) {
        free(address as *mut c_void);
    }
}

/// numpy's `PyDataMemAllocator`.
#[repr(C)]
struct Allocator {
    ctx: *mut c_void,
    malloc: unsafe extern "C" fn(*mut c_void, usize) -> *mut c_void,
    calloc: unsafe extern "C" fn(*mut c_void, usize, usize) -> *mut c_void,
    realloc: unsafe extern "C" fn(*mut c_void, *mut c_void, usize) -> *mut c_void,
    free: unsafe extern "C" fn(*mut c_void, *mut c_void, usize),
}

/// numpy's `PyDataMem_Handler` (version 1).
#[repr(C)]
struct Handler {
    name: [c_char; 127],
    version: u8,
    allocator: Allocator,
}

/// The handler numpy reads through the capsule; never written, so shared between threads.
struct Shared(Handler);
// SAFETY: the handler holds only function pointers and a null context, and is never written.
unsafe impl Sync for Shared {}

const fn handler_name() -> [c_char; 127] {
    let text = b"arxid_kept_blocks";
    let mut name = [0 as c_char; 127];
    let mut i = 0;
    while i < text.len() {
        name[i] = text[i] as c_char;
        i += 1;
    }
    name
}

static HANDLER: Shared = Shared(Handler {
    name: handler_name(),
    version: 1,
    allocator: Allocator {
        ctx: std::ptr::null_mut(),
        malloc: kept_malloc,
        calloc: kept_calloc,
        realloc: kept_realloc,
        free: kept_free,
    },
});

const CAPSULE_NAME: &CStr = c"mem_handler";

/// Slot of `PyDataMem_SetHandler` in numpy's C API table (numpy >= 1.22).
const SET_HANDLER: usize = 304;

type SetHandler = unsafe extern "C" fn(*mut pyo3::ffi::PyObject) -> *mut pyo3::ffi::PyObject;

/// numpy's `PyDataMem_SetHandler`, read from its C API table.
fn set_handler_fn(py: Python<'_>) -> PyResult<SetHandler> {
    let module = py.import("numpy._core.multiarray").or_else(|_| py.import("numpy.core.multiarray"))?;
    let capsule = module.getattr("_ARRAY_API")?;
    // SAFETY: `_ARRAY_API` is numpy's capsule of its C API table (an array of function pointers),
    // alive as long as numpy is imported; slot 304 is `PyDataMem_SetHandler` since numpy 1.22.
    unsafe {
        let table = pyo3::ffi::PyCapsule_GetPointer(capsule.as_ptr(), std::ptr::null()) as *const *const c_void;
        if table.is_null() {
            return Err(PyErr::fetch(py));
        }
        let slot = *table.add(SET_HANDLER);
        if slot.is_null() {
            return Err(PyRuntimeError::new_err("numpy has no memory handlers (numpy 1.22 or later is needed)"));
        }
        Ok(std::mem::transmute::<*const c_void, SetHandler>(slot))
    }
}

/// Set numpy's handler of this context to `handler` (None: numpy's default); the previous one.
fn swap_handler<'py>(py: Python<'py>, handler: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
    let set = set_handler_fn(py)?;
    let raw = handler.map_or(std::ptr::null_mut(), |h| h.as_ptr());
    // SAFETY: `set` is numpy's PyDataMem_SetHandler, called with the GIL held and a handler capsule
    // (or null); it returns a new reference to the previous handler, or null with an exception set.
    unsafe { Bound::from_owned_ptr_or_err(py, set(raw)) }
}

/// The capsule numpy takes as a handler, pointing at the static [`HANDLER`].
fn handler_capsule(py: Python<'_>) -> PyResult<Bound<'_, PyCapsule>> {
    let pointer = &HANDLER.0 as *const Handler as *mut c_void;
    // SAFETY: the capsule points at a static that outlives every array, and has no destructor.
    unsafe {
        let raw = pyo3::ffi::PyCapsule_New(pointer, CAPSULE_NAME.as_ptr(), None);
        Ok(Bound::from_owned_ptr_or_err(py, raw)?.cast_into_unchecked())
    }
}

/// Enter a scope that keeps numpy's freed blocks of 1 MiB or more, up to `limit` bytes in all
/// (the largest limit of the open scopes), for arrays of the same size: set as numpy's handler in
/// this context. Returns the previous handler, to give back to :func:`release_array_blocks`.
#[pyfunction]
pub(super) fn keep_array_blocks(py: Python<'_>, limit: usize) -> PyResult<Bound<'_, PyAny>> {
    let previous = swap_handler(py, Some(handler_capsule(py)?.as_any()))?;
    let mut k = kept();
    k.scopes += 1;
    k.limit = k.limit.max(limit);
    Ok(previous)
}

/// Leave the scope :func:`keep_array_blocks` entered: put back the ``previous`` handler; when no
/// scope is left, free every kept block.
#[pyfunction]
pub(super) fn release_array_blocks(py: Python<'_>, previous: Bound<'_, PyAny>) -> PyResult<()> {
    let restored = swap_handler(py, Some(&previous));
    let freed = {
        let mut k = kept();
        k.scopes = k.scopes.saturating_sub(1);
        if k.scopes > 0 {
            Vec::new()
        } else {
            k.limit = 0;
            k.bytes = 0;
            std::mem::take(&mut k.blocks)
        }
    };
    for (address, _) in freed {
        // SAFETY: every kept block is a malloc block no array owns any more.
        unsafe { free(address as *mut c_void) };
    }
    restored.map(|_| ())
}

/// `(blocks, bytes)` kept now (for tests).
#[pyfunction]
pub(super) fn kept_array_blocks() -> (usize, usize) {
    let k = kept();
    (k.blocks.len(), k.bytes)
}
