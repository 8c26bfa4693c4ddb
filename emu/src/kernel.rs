//! The kernel API, the public contract between the emulator and an algorithm: what a
//! kernel declares about itself ([`KernelInfo`]), what it is ([`FragmentKernel`]), what a
//! fragment knows before shading ([`FragInput`]) and how an invocation can end early
//! ([`FaultKind`]). What a kernel sees while it runs is [`Fragment`]; the contexts that
//! implement it, and everything else an invocation needs at run time, are
//! [`crate::invocation`]'s.
//!
//! A kernel is written once, as an `async fn`, and runs under every executor. Each access
//! to shared memory is an `.await`: a point where another invocation may run. Under the
//! `ordered` and `parallel` executors an access completes at once; under `scheduled` the
//! invocation suspends before every access and a seeded policy picks who goes next.
//!
//! ```ignore
//! struct Count { counts: Buf<u32> }
//! impl FragmentKernel for Count {
//!     fn info(&self) -> KernelInfo { KernelInfo::new("count") }
//!     async fn shade(&self, f: impl Fragment) {
//!         f.atomic_add(self.counts, f.pixel_index(), 1).await;
//!     }
//! }
//! ```
//!
//! This module knows nothing of any algorithm, of executors, or of how an invocation runs.

use std::future::Future;

use crate::fragment::Fragment;
use crate::interlock::InterlockMode;
use crate::memory::{Buf, Word};

use crate::memory::BlockArray;
/// Moved to [`crate::memory`] (the layout of a buffer); kept here for older paths.
pub use crate::memory::PixelArray;

/// What a kernel declares about itself; the pipeline uses it to place depth tests and to
/// set up interlock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KernelInfo {
    pub name: &'static str,
    /// The kernel may call [`Fragment::discard`] (forces late depth tests under `EarlyTests::Auto`).
    pub may_discard: bool,
    /// The kernel may call [`Fragment::write_depth`].
    pub writes_depth: bool,
    /// The kernel uses [`Fragment::interlock_begin`] with this mode.
    pub interlock: Option<InterlockMode>,
    /// The kernel may read the interpolated values of its fragment: [`Fragment::depth`],
    /// [`Fragment::sample_depth`], [`Fragment::barycentrics`] (true unless declared
    /// otherwise with [`KernelInfo::without_interpolants`]).
    ///
    /// [`Fragment::depth`]: crate::Fragment::depth
    /// [`Fragment::sample_depth`]: crate::Fragment::sample_depth
    /// [`Fragment::barycentrics`]: crate::Fragment::barycentrics
    pub interpolants: bool,
    /// The per-pixel array the kernel accesses (see [`KernelInfo::with_pixel_array`]).
    pub pixel_array: Option<PixelArray>,
    /// The per-pixel array is the pixel's own: no invocation accesses another pixel's slot
    /// (see [`KernelInfo::with_own_pixel_array`]).
    pub pixel_array_own: bool,
    /// A per-block array whose blocks' slots are their pixels' own (see
    /// [`KernelInfo::with_own_block_array`]).
    pub own_block_array: Option<BlockArray>,
    /// What a full-screen invocation does at a pixel no geometry pass of the device
    /// rasterized (see [`KernelInfo::with_untouched_output`]).
    pub untouched_output: Option<[u32; 4]>,
    /// A full-screen kernel whose invocation at a pixel reads only what invocations at that
    /// pixel wrote (see [`KernelInfo::with_by_region_reads`]).
    pub by_region: bool,
}

impl KernelInfo {
    pub const fn new(name: &'static str) -> KernelInfo {
        KernelInfo {
            name,
            may_discard: false,
            writes_depth: false,
            interlock: None,
            interpolants: true,
            pixel_array: None,
            pixel_array_own: false,
            own_block_array: None,
            untouched_output: None,
            by_region: false,
        }
    }
    pub const fn with_discard(mut self) -> KernelInfo {
        self.may_discard = true;
        self
    }
    pub const fn with_depth_write(mut self) -> KernelInfo {
        self.writes_depth = true;
        self
    }
    pub const fn with_interlock(mut self, mode: InterlockMode) -> KernelInfo {
        self.interlock = Some(mode);
        self
    }
    /// Declares that the kernel reads no interpolated value (no depth, sample depth or
    /// barycentrics), as a GLSL shader without inputs: in a draw without a depth or stencil
    /// test, triangle setup then skips the depth and barycentric planes, as a GPU skips
    /// the interpolation of varyings nobody reads (a sixth of the setup instructions of a dense mesh;
    /// docs/performance.md). Reading one anyway is a [`FaultKind::Misuse`].
    pub const fn without_interpolants(mut self) -> KernelInfo {
        self.interpolants = false;
        self
    }
    /// Declares that invocations access their pixel's slot of a per-pixel array: word
    /// `pixel_index * stride` of `buf` (a counter, a list head, a k-buffer's slots).
    ///
    /// A performance hint only: it changes no result, and a wrong one costs only wasted
    /// prefetches. The `parallel` executor prefetches the slot of a fragment a few covered
    /// runs ahead of the one it shades, as a GPU hides memory latency by running other
    /// warps meanwhile. A thread shades one fragment at a time, and a pass that visits
    /// pixels in triangle order (an unbinned counting pass) otherwise waits on a cache miss
    /// at nearly every access: on the 871K dragon at 2048x2048, half of the shading loop's
    /// time (docs/performance.md).
    pub const fn with_pixel_array<T: Word>(mut self, buf: Buf<T>, stride: u32) -> KernelInfo {
        self.pixel_array = Some(PixelArray {
            buffer: buf.id,
            stride,
        });
        self
    }
    /// [`KernelInfo::with_pixel_array`], and a promise, checked: in this pass, every access
    /// to `buf` is to the invocation's own pixel's slot (words `pixel_index * stride ..
    /// pixel_index * stride + stride`), so a slot belongs to its pixel's fragments (a list
    /// head, a per-pixel counter), as tile memory belongs to its pixel on a tiled GPU.
    ///
    /// Where the `ordered` and `parallel` executors give a tile to one worker for the whole
    /// pass (a binned pass without segments: the `ordered` executor, a geometry pass run by
    /// region with its resolve) and the worker shades one fragment at a time (no lockstep)
    /// in a pass that neither tests nor writes targets (a capture pass, a count), only that
    /// worker reaches the tile's slots, so it performs the kernel's atomics on them as a
    /// plain load and store (no locked instruction, no full barrier): the same results,
    /// since nothing else accesses the word during the pass and the passes before and after
    /// are ordered by the pass barrier. There, an access to another pixel's slot of `buf` is a
    /// [`FaultKind::Misuse`] (not performed); elsewhere the atomics stay atomic and nothing
    /// is checked, so a wrong declaration shows as a difference between executors.
    pub const fn with_own_pixel_array<T: Word>(self, buf: Buf<T>, stride: u32) -> KernelInfo {
        let mut info = self.with_pixel_array(buf, stride);
        info.pixel_array_own = true;
        info
    }
    /// The promise of [`KernelInfo::with_own_pixel_array`] for a per-block array
    /// ([`BlockArray`]: blocks of `2^shift` pixels a side, `stride` words each): in this
    /// pass, every access to `buf` is to the slot of the invocation's own pixel's block (a
    /// counter per screen block, as `ll`'s node allocation by blocks). Where a worker owns
    /// a tile for the pass and the tiles are at least as large as the blocks (so that a
    /// block lies in one tile), only that worker reaches the slots of the tile's blocks, and
    /// it performs the kernel's atomics there as a plain load and store; an access to
    /// another block's slot of `buf` is then a [`FaultKind::Misuse`]. Elsewhere the atomics
    /// stay atomic and nothing is checked.
    pub const fn with_own_block_array<T: Word>(
        mut self,
        buf: Buf<T>,
        shift: u32,
        stride: u32,
    ) -> KernelInfo {
        self.own_block_array = Some(BlockArray {
            buffer: buf.id,
            shift,
            stride,
        });
        self
    }
}

impl KernelInfo {
    /// Declares, for a full-screen pass, that its invocation at a pixel where no geometry
    /// pass of the device has rasterized a fragment does nothing but write `bits` to target
    /// 0 (as [`Fragment::output_u32`] would; no other target, no discard, no fault, no
    /// memory write, and no read of a word another invocation of the pass may write: its
    /// pixel's own words, which nothing else in a resolve touches, are what it reads): a
    /// resolve at an empty pixel, which writes the background. The fused
    /// path of the `ordered` and `parallel` executors then writes `bits` to such pixels
    /// without running the kernel, by screen blocks of 8 x 8 pixels that no fragment
    /// reached (a coverage mask the geometry passes mark as they rasterize, as a GPU's
    /// hierarchical stencil; `crate::pipeline::BlockMask`), and counts them in
    /// [`Stats::skipped`](crate::Stats::skipped) instead of
    /// [`Stats::shaded`](crate::Stats::shaded). The general path (the scheduled executor,
    /// interlock without tile ownership, contention counting) marks and skips the same
    /// blocks: by the declaration the skipped invocation could take part in no hazard the
    /// scheduled executor's detector reports (it writes nothing, and reads nothing another
    /// invocation writes; docs/fuzzing.md). A device that does not track coverage runs
    /// every pixel, and the oracle
    /// checks every empty pixel's image against the declared output, so a wrong
    /// declaration shows there. Ignored by geometry passes, and by full-screen passes with
    /// more than one target, a depth or stencil test, or no covered sample.
    ///
    /// [`Fragment::output_u32`]: crate::Fragment::output_u32
    pub const fn with_untouched_output(mut self, bits: [u32; 4]) -> KernelInfo {
        self.untouched_output = Some(bits);
        self
    }
    /// Declares, for a full-screen pass, a by-region dependency on the geometry pass before
    /// it (Vulkan's `VK_DEPENDENCY_BY_REGION_BIT` between two subpasses, Metal's tile
    /// shaders, pixel local storage): its invocation at pixel `p` reads only words that
    /// invocations at `p` wrote, in that geometry pass or in passes before it, never a word
    /// an invocation at another pixel wrote (commutative updates of shared counters, whose
    /// value it does not read, are allowed). [`Device::draw_then_fullscreen`] may then run
    /// the two passes tile by tile on one worker (the tile's fragments, then the tile's
    /// full-screen invocations), while the tile's data is still in the cache; the results
    /// are those of the two passes one after the other, up to the order in which
    /// invocations of different pixels take shared counters, which the executors already
    /// leave free. Ignored by [`Device::fullscreen`].
    ///
    /// [`Device::draw_then_fullscreen`]: crate::Device::draw_then_fullscreen
    /// [`Device::fullscreen`]: crate::Device::fullscreen
    pub const fn with_by_region_reads(mut self) -> KernelInfo {
        self.by_region = true;
        self
    }
}

/// A fragment kernel (also used for full-screen passes, with one invocation per pixel).
pub trait FragmentKernel: Sync {
    fn info(&self) -> KernelInfo;
    /// Shades one fragment. Every shared-memory access goes through `f` and is awaited.
    /// Generic over the context, so that each executor runs the kernel with the one that
    /// fits ([`crate::fragment`]).
    fn shade(&self, f: impl Fragment) -> impl Future<Output = ()>;
}

/// Everything a fragment knows about itself before shading.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FragInput {
    /// Position of the invocation in API order within its pass (0, 1, ...).
    pub seq: u64,
    pub x: u32,
    pub y: u32,
    /// Index of the setup triangle (into the pass's triangles), `u32::MAX` in full-screen passes.
    pub tri: u32,
    pub primitive_id: u32,
    pub instance_id: u32,
    pub coverage: u8,
    pub front_facing: bool,
    /// Window depth at the pixel centre. Explicit invocations and full-screen passes take
    /// it from here; rasterized fragments compute it from their triangle
    /// ([`Fragment::depth`]), and the fused path leaves it NaN when no test needs it.
    pub depth: f32,
    /// Rank of this fragment among the shaded fragments of its pixel (API order), for
    /// ordered interlock.
    pub ticket: u32,
}

/// A fault that ended an invocation early. Never silent: every fault is in the pass report.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum FaultKind {
    /// An access past the end of a buffer.
    OutOfBounds {
        buffer: String,
        index: u64,
        len: u32,
    },
    /// The invocation took more steps than the watchdog allows (an endless loop, a
    /// spinlock that never gets its lock).
    Watchdog { steps: u64 },
    /// The invocation waited on interlock (or for its ordered turn) for too long, or every
    /// invocation in flight was blocked.
    Deadlock { waits: u64 },
    /// Lockstep forward-progress mode (`ScheduleConfig::simt`): lanes of one warp share a
    /// program counter, the `spinning` ones kept looping, and the `held` ones (past the
    /// loop, possibly holding what the spinners wait for) could not run until they leave
    /// it. Invocations by `seq`; the warp by its number in admission order (within the
    /// wave of tiles being shaded).
    SimtDeadlock {
        warp: u64,
        spinning: Vec<u64>,
        held: Vec<u64>,
    },
    /// The kernel panicked.
    Panic { message: String },
    /// Misuse of the kernel API (e.g. interlock without declaring it, nested interlock).
    Misuse { message: String },
}

impl std::fmt::Display for FaultKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FaultKind::OutOfBounds { buffer, index, len } => {
                write!(
                    f,
                    "out-of-bounds access: `{buffer}`[{index}] but it holds {len} words"
                )
            }
            FaultKind::Watchdog { steps } => {
                write!(
                    f,
                    "watchdog: the invocation ran {steps} steps without finishing"
                )
            }
            FaultKind::Deadlock { waits } => {
                write!(
                    f,
                    "deadlock: the invocation waited {waits} times without getting in"
                )
            }
            FaultKind::SimtDeadlock {
                warp,
                spinning,
                held,
            } => {
                write!(
                    f,
                    "SIMT deadlock in warp {warp}: invocations {spinning:?} spin in a loop while \
                     {held:?} of the same warp, past the loop, cannot run until they leave it \
                     (the lanes of a warp share one program counter)"
                )
            }
            FaultKind::Panic { message } => write!(f, "kernel panicked: {message}"),
            FaultKind::Misuse { message } => write!(f, "kernel API misuse: {message}"),
        }
    }
}
