//! The A-buffers: every fragment per pixel, in unbounded (linked lists) or exactly sized
//! (count, scan, store) memory.
//!
//! Each algorithm has its module; what they share has one module per concept: `run` (the
//! scaffolding of a run: device, passes, result), `checks` (the invariants every
//! A-buffer checks), `array` (the fixed-array and count-scan-store storage and its
//! resolve), `sizing` (`ll`'s pool sized by a count pass), `list_resolve` (the lists' resolve),
//! `walk` (the host's walk of the lists after a frame). The count pass is `basic::CountKernel`.

mod array;
mod checks;
mod list_resolve;
mod run;
mod sizing;
mod walk;

// `pub(crate)`: modules whose protocol kernels `crate::protocols` re-exports.
crate::registry::family! {
    pub(crate) ll,
    fab,
    pub(crate) sb,
    pub(crate) dfb,
    bun,
}

pub use ll::LinkedList;
