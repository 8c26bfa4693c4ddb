//! The k-buffers: the k nearest fragments per pixel in bounded memory, by every scheme the
//! seeds and public implementations use, from the racy read-modify-write original to
//! atomic, spinlock and interlock variants, plus weighted blended OIT as the baseline.

mod atomic;
mod interlock;
mod kplus;
mod multipass;
mod rmw;
mod spinlock;
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
