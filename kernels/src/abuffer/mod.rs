//! The A-buffers: every fragment per pixel, in unbounded (linked lists) or exactly sized
//! (count, scan, store) memory.

mod bun;
pub(crate) mod dfb; // pub(crate): protocol kernels re-exported by crate::protocols
mod fab;
pub(crate) mod ll;
pub(crate) mod sb;

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
