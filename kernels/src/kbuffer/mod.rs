//! The k-buffers: the k nearest fragments per pixel in bounded memory, by every scheme the
//! seeds and public implementations use, from the racy read-modify-write original to
//! atomic, spinlock and interlock variants, plus weighted blended OIT as the baseline.
//!
//! The shared base of the k-buffers that keep `(depth, primitive)` slots, as `abuffer/` has
//! its own: `slots` (layout, order, sorted insertion, limits on k), `run` (one run: capture
//! pass, resolve, readback, result), `checks` (slot-shape invariants). Each other file is one
//! algorithm (or a pair of close variants) over that base.

mod checks;
mod run;
pub(crate) mod slots;

// `pub(crate)`: modules whose protocol kernels `crate::protocols` re-exports.
crate::registry::family! {
    pub(crate) rmw,
    multipass,
    srab,
    pub(crate) atomic,
    pub(crate) spinlock,
    pub(crate) interlock,
    kplus,
    wboit,
}
