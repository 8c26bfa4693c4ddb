//! Executors, faults and the hazard detector, one binary: mostly full-screen passes (one
//! invocation per pixel, no rasterizer involved), and draws for the fused path of the direct
//! executors.

mod by_region;
mod common;
mod draws;
mod faults;
mod memory_ops;
mod own_array;
mod schedules;
