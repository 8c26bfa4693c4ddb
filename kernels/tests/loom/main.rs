//! loom models of the kernels' synchronisation protocols: the linked-list push (counter, head
//! exchange, node write), the atomic-min k-buffer chains (32- and 64-bit, and the 32-bit
//! claim pass), the spinlock k-buffer, the interlock k-buffer (ordered and unordered), the
//! count / allocate / store counters of DFB and the S-buffer, and the read-modify-write
//! k-buffer. Each model runs the algorithm's own capture kernel (re-exported by
//! `fragrace_kernels::protocols`) with one loom thread per invocation
//! (`fragrace_emu::exec::run_on_threads`) on 2 or 3 invocations, and checks the protocol's
//! invariant in every execution loom explores (loom also models weak memory: a relaxed load
//! may read a stale value, so publication through release/acquire is checked too).
//!
//! The `loom_finds_*` tests go the other way: they assert that loom *finds* a bug (the
//! planted bug of the linked list, the read-modify-write k-buffer losing a fragment, a
//! spinlock dropping a fragment at its cap, a spinlock released by a plain store) and print
//! after how many executions and how long.
//!
//! Passes a model does not explore run on the `ordered` executor on loom's main thread
//! (`Device::invocations`): loom allows 4 threads per execution besides the main one.
//!
//! Run with `RUSTFLAGS="--cfg loom" cargo test --release --target-dir target/loom
//! -p fragrace-kernels --test loom` (or `bash ci/loom.sh`); add `-- --nocapture` for the
//! figures.
//!
//! One binary, a module per protocol family; `common` holds what the models share.
#![cfg(loom)]

mod atomic_min;
mod common;
mod count_scan_store;
mod lists;
mod occupancy;
mod rmw;
