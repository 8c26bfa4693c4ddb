//! The k-buffers: the k nearest fragments per pixel in bounded memory, by every scheme the
//! seeds and public implementations use, from the racy read-modify-write original to
//! atomic, spinlock and interlock variants, plus weighted blended OIT as the baseline.

pub(crate) mod atomic; // pub(crate): protocol kernels re-exported by crate::protocols
pub(crate) mod interlock;
mod kplus;
mod multipass;
pub(crate) mod rmw;
pub(crate) mod spinlock;
mod srab;
mod wboit;

use crate::algo::Algorithm;

/// The algorithms of this family.
pub fn algorithms() -> Vec<Box<dyn Algorithm>> {
    let mut v = Vec::new();
    v.extend(rmw::algorithms());
    v.extend(multipass::algorithms());
    v.extend(srab::algorithms());
    v.extend(atomic::algorithms());
    v.extend(spinlock::algorithms());
    v.extend(interlock::algorithms());
    v.extend(kplus::algorithms());
    v.extend(wboit::algorithms());
    v
}
