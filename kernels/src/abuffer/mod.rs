//! The A-buffers: every fragment per pixel, in unbounded (linked lists) or exactly sized
//! (count, scan, store) memory.
//!
//! Each algorithm has its module; what they share has one module per concept: `run` (the
//! scaffolding of a run: device, passes, result), `checks` (the invariants every
//! A-buffer checks), `array` (the fixed-array and count-scan-store storage and its
//! resolve). The count pass is `basic::CountKernel`.

mod array;
mod bun;
mod checks;
pub(crate) mod dfb; // pub(crate): protocol kernels re-exported by crate::protocols
mod fab;
pub(crate) mod ll;
mod run;
pub(crate) mod sb;
#[cfg(test)]
mod test_support;

pub use ll::LinkedList;

use crate::algo::Algorithm;

/// The algorithms of this family.
pub fn algorithms() -> Vec<Box<dyn Algorithm>> {
    let mut v = Vec::new();
    v.extend(ll::algorithms());
    v.extend(fab::algorithms());
    v.extend(sb::algorithms());
    v.extend(dfb::algorithms());
    v.extend(bun::algorithms());
    v
}
