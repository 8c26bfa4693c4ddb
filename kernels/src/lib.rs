//! # fragrace-kernels: multi-fragment rendering algorithms as fragrace kernels
//!
//! Every algorithm is an [`Algorithm`]: its passes (geometry and
//! full-screen kernels over `fragrace_emu`'s public kernel API), its resolve, its declared
//! properties ([`AlgoInfo`]: passes, memory per pixel, hazard class, source), and its
//! invariants, checked on every run ([`AlgoResult::checks`]).
//!
//! An algorithm's result is compared with [`truth`](basic::Truth), the exact A-buffer
//! (every fragment captured under the `ordered` executor, sorted by depth then primitive
//! id), by one differential oracle ([`oracle`]).

#![forbid(unsafe_code)]

pub mod abuffer;
pub mod algo;
pub mod basic;
pub mod bucket;
pub mod common;
pub mod kbuffer;
pub mod limits;
pub mod merging;
pub mod occupancy;
pub mod oracle;
pub mod peeling;
pub mod presorted;
pub mod protocols;
pub mod racebench;
pub mod registry;
pub(crate) mod resolve;
#[cfg(test)]
mod testing;

pub use algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Capture, Check, Deferred, Frame,
    HazardClass, Param, Params,
};
pub use registry::{algorithm, algorithms, names};
