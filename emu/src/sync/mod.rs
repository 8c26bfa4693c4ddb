//! The one place atomics and threads come from: `std`, or `loom` under `--cfg loom`
//! (as crossbeam does), so the same memory and interlock code is model-checked.

#[cfg(not(loom))]
pub use std::sync::atomic::{fence, AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
#[cfg(not(loom))]
pub use std::sync::{Arc, Mutex};
#[cfg(not(loom))]
pub use std::thread;

#[cfg(loom)]
pub use loom::sync::atomic::{fence, AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
#[cfg(loom)]
pub use loom::sync::{Arc, Mutex};
#[cfg(loom)]
pub use loom::thread;

/// A value on its own cache line (128 bytes on x86-64 and aarch64, where the prefetcher
/// pairs lines): crossbeam's, under loom too (it is only alignment).
pub use crossbeam_utils::CachePadded;

/// Exponential backoff for spin-waits, yielding the thread once spinning has gone on long
/// enough: crossbeam's (under loom too: it spins and calls `std::thread::yield_now`, which
/// the direct executors' waits use outside any model).
pub use crossbeam_utils::Backoff;

pub mod pool;
pub mod split;
