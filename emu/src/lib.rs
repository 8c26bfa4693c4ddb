//! # fragrace-emu: a software GPU for multi-fragment rendering under races
//!
//! A [`Device`] owns shared memory ([`Memory`], typed [`Buf`] handles) and runs passes:
//! geometry passes ([`Device::draw`]) that rasterize a [`Draw`] into a [`Framebuffer`] and
//! run a [`FragmentKernel`] once per fragment, and full-screen passes
//! ([`Device::fullscreen`]) that run it once per pixel. Kernels are `async fn`s over a
//! [`Fragment`] context: every shared-memory access is awaited, a place where another
//! invocation may run. The executor picks the context ([`invocation`]): [`Frag`] where an
//! invocation can be suspended, [`DirectFrag`] where accesses complete at once. An
//! [`ExecConfig`] picks the executor: `ordered` (the reference), `parallel` (real threads,
//! fragments of one pixel at once on different threads) or `scheduled` (a seeded [`Policy`]
//! interleaves invocations at every access, a hazard detector watches).
//!
//! Fixed-function state ([`state`]) is applied in API order whatever order the shaders
//! ran in. Nothing in this crate knows about any multi-fragment algorithm.
//!
//! Module map: [`kernel`] and [`fragment`] (the kernel API, the contract with algorithms),
//! [`invocation`] (the per-invocation runtime: slots, contexts, access futures), [`memory`]
//! (buffers, words, operations), [`raster`] (clipping, setup, binning, coverage), [`state`]
//! (depth, stencil, blending), [`framebuffer`] (tile-major targets), [`exec`] (executors,
//! policies and every shading loop), [`interlock`], [`hazard`] (the detector), [`stats`],
//! [`pipeline`] (devices and passes), [`sync`] (std or loom).

// Every unsafe block states why it is sound (house rule); clippy holds us to it.
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod exec;
pub mod fragment;
pub mod framebuffer;
pub mod geometry;
pub mod hazard;
mod hint;
pub mod interlock;
pub mod invocation;
pub mod kernel;
pub mod memory;
pub mod pipeline;
pub mod raster;
pub mod state;
pub mod stats;
pub mod sync;

pub use exec::{Binning, ExecConfig, ExecMode, Policy, ScheduleConfig};
pub use fragment::Fragment;
pub use framebuffer::{Framebuffer, Image};
pub use geometry::{Draw, Mesh, MeshError};
pub use hazard::{Hazard, HazardCounts, HazardKind};
pub use interlock::InterlockMode;
pub use invocation::{Access, CompareExchange, DirectFrag, Frag, Performed, Store};
pub use kernel::{FaultKind, FragInput, FragmentKernel, KernelInfo};
pub use memory::{BlockArray, Buf, Memory, PixelArray, Values, Word};
pub use pipeline::{
    Coverage, Device, Fault, OcclusionQuery, PassError, PassReport, PassState, PassTime,
};
pub use raster::{CullMode, FrontFace, RasterState, SampleCount, Viewport};
pub use state::{
    BlendEquation, BlendFactor, BlendState, CompareFunc, DepthState, EarlyTests, Format,
    FragmentState, LogicOp, StencilFace, StencilOp, StencilState, TargetState,
};
pub use stats::Stats;
