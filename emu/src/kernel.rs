//! The kernel API: what a fragment (or full-screen) kernel is, and [`Frag`], the general
//! context ([`crate::fragment::Fragment`]) through which one invocation sees its fragment,
//! writes its outputs and touches shared memory, and may be suspended at any access.
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
//! This module knows nothing of any algorithm, and nothing of how executors pick
//! invocations: it only suspends (`Pending`) where the executor asked it to.

use std::cell::{Cell, RefCell};
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use crate::fragment::Fragment;
use crate::framebuffer::Image;
use crate::interlock::{Interlock, InterlockMode};
use crate::memory::{Addr, Buf, MemOp, Memory, OpKind, Word, WordCache};
use crate::raster::SetupTriangle;

/// What a kernel declares about itself; the pipeline uses it to place depth tests and to
/// set up interlock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KernelInfo {
    pub name: &'static str,
    /// The kernel may call [`Frag::discard`] (forces late depth tests under `EarlyTests::Auto`).
    pub may_discard: bool,
    /// The kernel may call [`Frag::write_depth`].
    pub writes_depth: bool,
    /// The kernel uses [`Frag::interlock_begin`] with this mode.
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
}

/// A per-pixel array of a storage buffer: pixel `p`'s slot starts at word `p * stride`
/// (`p` as [`Fragment::pixel_index`]).
///
/// [`Fragment::pixel_index`]: crate::Fragment::pixel_index
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelArray {
    /// The buffer's id ([`Buf::id`]).
    pub buffer: u32,
    /// Words per pixel.
    pub stride: u32,
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
    /// ([`Frag::depth`]), and the fused path leaves it NaN when no test needs it.
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
    /// Lockstep forward-progress mode (`ExecConfig::simt`): lanes of one warp share a
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

/// What an invocation is about to do at its next step (known to the scheduler before it
/// decides who runs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepKind {
    /// A memory access.
    Mem {
        addr: Addr,
        op: OpKind,
        record: Option<RecordSpan>,
    },
    /// Entering the interlock critical section.
    InterlockBegin,
    /// Leaving it.
    InterlockEnd,
    /// Waiting for the ordered-interlock turn of a fragment that never entered the
    /// critical section (it must still pass its turn on, as on hardware).
    PassTurn,
    /// A voluntary yield (spin loops).
    Yield,
}

/// A multi-word record access: the word range and the position of this word in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordSpan {
    pub base: Addr,
    pub len: u32,
    pub word: u32,
}

/// Whether accesses suspend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Complete at once (ordered, parallel); every `yield_every` steps suspend once
    /// (lockstep warps in the parallel executor), 0 = never.
    Direct { yield_every: u32 },
    /// Suspend before every step until the scheduler grants it.
    Scheduled,
}

/// What every invocation of a pass shares.
#[derive(Clone)]
pub(crate) struct PassEnv<'a> {
    pub memory: &'a Memory,
    pub tris: &'a [SetupTriangle],
    pub width: u32,
    pub height: u32,
    pub samples: u32,
    pub interlock: Option<&'a Interlock>,
    pub interlock_mode: Option<InterlockMode>,
    /// Per-sample ordered interlock: each fragment's per-sample tickets, indexed by its
    /// `ticket` field (empty otherwise: explicit fragments use `ticket` for every sample).
    pub sample_tickets: &'a [[u32; 8]],
    pub mode: Mode,
    pub max_steps: u64,
    pub max_waits: u64,
    /// Per-mille probability of a spurious weak compare-exchange failure.
    pub spurious_cas: u32,
    /// Collect per-address contention (costs three atomics per access).
    pub contention: Option<&'a crate::stats::ContentionTable>,
    /// The kernel declared [`KernelInfo::without_interpolants`]: reading one is a misuse
    /// (whether or not the draw set up planes, so the declaration is checked everywhere).
    pub no_interpolants: bool,
}

/// Per-invocation mutable state, owned by the executor (one per in-flight slot) and shared
/// with the invocation's future through [`Frag`]. Single-threaded (`Cell`s).
//
// Laid out by hand (`repr(C)`, cache-line aligned): what every fragment writes or reads
// (the input, the step count, the flags) fills the first line and the operation counters
// the second, so that a warp of 64 slots touches 8 KiB rather than three scattered lines
// per slot (the fused path's profiles showed the slot writes store-bound).
#[repr(C, align(64))]
pub(crate) struct Invocation {
    // Line 0: per-fragment state every invocation touches (64 bytes).
    pub input: Cell<FragInput>,
    pub steps: Cell<u64>,
    pub since_yield: Cell<u32>,
    /// Bit i set: `outputs[i]` was written since the last reset.
    pub outputs_written: Cell<u8>,
    pub discarded: Cell<bool>,
    has_fault: Cell<bool>,
    pub granted: Cell<bool>,
    pub depth_out: Cell<Option<f32>>,
    // Line 1: the operation counters (52 bytes).
    pub ops: [Cell<u32>; OP_KINDS],
    pub in_interlock: Cell<bool>,
    pub entered_interlock: Cell<bool>,
    // Cold: what only some kernels or executors use.
    pub waits: Cell<u64>,
    pub pending: Cell<Option<StepKind>>,
    /// Why the invocation ended early; `None` while it runs. Read through [`Self::faulted`]
    /// (a flag, so the hot path never touches the `RefCell`).
    fault: RefCell<Option<FaultKind>>,
    pub outputs: [Cell<[u32; 4]>; 8],
}

// The layout above, checked.
const _: () = {
    assert!(std::mem::offset_of!(Invocation, ops) == 64);
    assert!(std::mem::offset_of!(Invocation, depth_out) < 64);
};

/// Kinds of memory operation ([`OpKind::ALL`]): one counter each.
pub(crate) const OP_KINDS: usize = OpKind::ALL.len();

/// What every fragment of the fused path without lockstep reads and writes, kept apart from
/// its slot ([`Invocation`]): the executor holds it in a local that no out-of-line code ever
/// sees, so the compiler keeps it in registers. In the slot (memory shared with cold paths)
/// every field was a store per fragment, and each `lock`ed instruction of the kernel waited
/// for those stores to drain (docs/performance.md). The slot still holds what is rare:
/// colour outputs and faults; the executor copies this state into it when a fragment needs
/// the slot's path after shading ([`DirectState::spill`]).
pub(crate) struct DirectState<'m> {
    pub input: Cell<FragInput>,
    pub steps: Cell<u64>,
    pub discarded: Cell<bool>,
    pub depth_out: Cell<Option<f32>>,
    /// Operation counters of every fragment shaded with this state (not reset per
    /// fragment; the executor adds them to the slot's at the end of a unit).
    pub ops: [Cell<u32>; OP_KINDS],
    /// The words of the buffers last accessed (kept across fragments, as the counters).
    pub words: WordCache<'m>,
}

impl DirectState<'_> {
    #[inline(always)]
    pub fn new() -> Self {
        DirectState {
            input: Cell::new(FragInput::default()),
            steps: Cell::new(0),
            discarded: Cell::new(false),
            depth_out: Cell::new(None),
            ops: Default::default(),
            words: WordCache::new(),
        }
    }

    /// A new fragment: its input, and no results yet.
    #[inline(always)]
    pub fn reset(&self, input: FragInput) {
        self.input.set(input);
        self.reset_results();
    }

    /// A new fragment on the same row as the last one: only what differs is written.
    #[inline(always)]
    pub fn reset_next(&self, seq: u64, x: u32, coverage: u8, depth: f32) {
        let mut input = self.input.get();
        input.seq = seq;
        input.x = x;
        input.coverage = coverage;
        input.depth = depth;
        self.input.set(input);
        self.reset_results();
    }

    /// The next pixel of the same span (same coverage, no depth): only its id and x change.
    #[inline(always)]
    pub fn next_pixel(&self, seq: u64, x: u32) {
        let mut input = self.input.get();
        input.seq = seq;
        input.x = x;
        self.input.set(input);
        self.reset_results();
    }

    #[inline(always)]
    fn reset_results(&self) {
        self.steps.set(0);
        self.discarded.set(false);
        self.depth_out.set(None);
    }

    /// Copies the fragment's state into `slot`, for the executor's slot-based path (late
    /// tests and target writes, faults). The operation counters stay here.
    // Inlined, as every method here: a call taking `&self` out of line would make the
    // executor's local escape, and keep it in memory.
    #[inline(always)]
    pub fn spill(&self, slot: &Invocation) {
        self.spill_results(slot, self.input.get());
    }

    /// [`Self::spill`] with the fragment's input given (it equals this state's).
    #[inline(always)]
    pub fn spill_results(&self, slot: &Invocation, input: FragInput) {
        slot.input.set(input);
        slot.steps.set(self.steps.get());
        slot.discarded.set(self.discarded.get());
        slot.depth_out.set(self.depth_out.get());
    }

    /// Adds the operation counters to `slot`'s and clears them.
    #[inline(always)]
    pub fn drain_ops(&self, slot: &Invocation) {
        for (o, s) in self.ops.iter().zip(&slot.ops) {
            s.set(s.get().saturating_add(o.replace(0)));
        }
    }
}

impl Invocation {
    pub fn new() -> Invocation {
        Invocation {
            input: Cell::new(FragInput::default()),
            outputs: Default::default(),
            outputs_written: Cell::new(0),
            discarded: Cell::new(false),
            depth_out: Cell::new(None),
            pending: Cell::new(None),
            granted: Cell::new(false),
            steps: Cell::new(0),
            waits: Cell::new(0),
            since_yield: Cell::new(0),
            fault: RefCell::new(None),
            has_fault: Cell::new(false),
            in_interlock: Cell::new(false),
            entered_interlock: Cell::new(false),
            ops: Default::default(),
        }
    }

    /// Resets the slot for a new fragment (every executor but the fused path).
    pub fn reset(&self, input: FragInput) {
        if self.has_fault.get() {
            self.take_fault();
        }
        self.reset_fragment(input);
        self.pending.set(None);
        self.granted.set(false);
        self.waits.set(0);
        self.in_interlock.set(false);
        self.entered_interlock.set(false);
        for o in &self.ops {
            o.set(0);
        }
    }

    /// [`Self::reset`] for the fused path of the direct executors, which uses no interlock
    /// and no scheduler: the state only those touch (`granted`, `waits`, the interlock flags)
    /// is never set there, so it is left alone; `pending` only marks a suspended lockstep
    /// lane and is rewritten before it is read. The operation counters run on (the fused
    /// path sums them once per worker).
    // Always inlined: the caller builds `input` field by field, and a call would pass it
    // through the stack, where the wide loads of the copy stall on store forwarding (27 %
    // of the fused pass's time in profiles of `count`).
    #[inline(always)]
    pub fn reset_direct(&self, input: FragInput) {
        debug_assert!(!self.granted.get() && self.waits.get() == 0);
        debug_assert!(!self.in_interlock.get() && !self.entered_interlock.get());
        // The fused path counts every invocation (`Acc::count`, which takes the fault)
        // before its slot is reused.
        debug_assert!(!self.has_fault.get());
        self.reset_fragment(input);
    }

    /// What every reset does: the new input, and the previous fragment's results cleared
    /// (its fault has been taken already).
    #[inline(always)]
    fn reset_fragment(&self, input: FragInput) {
        self.input.set(input);
        self.reset_results();
    }

    /// Clears the colour outputs the last fragment wrote (only those: most write none, and
    /// then this is a load). The fused path without lockstep calls it alone: the rest of
    /// its per-fragment state is a [`DirectState`]'s.
    #[inline(always)]
    pub(crate) fn clear_outputs(&self) {
        let mut written = self.outputs_written.get();
        if written == 0 {
            return;
        }
        self.outputs_written.set(0);
        while written != 0 {
            let i = written.trailing_zeros() as usize;
            self.outputs[i].set([0; 4]);
            written &= written - 1;
        }
    }

    /// Clears the previous fragment's results (its fault has been taken already) but not
    /// its input.
    #[inline(always)]
    pub(crate) fn reset_results(&self) {
        debug_assert!(!self.has_fault.get());
        self.clear_outputs();
        self.discarded.set(false);
        self.depth_out.set(None);
        self.steps.set(0);
        self.since_yield.set(0);
    }

    /// Lockstep warps (`Mode::Direct { yield_every }`, `yield_every > 0`): an invocation
    /// makes `yield_every` steps per turn. True, and the step counted, if one more fits in
    /// this turn; false if the invocation must suspend first (it then calls
    /// [`Self::resume_turn`] when polled again). Always true without lockstep.
    #[inline]
    fn take_turn(&self, yield_every: u32) -> bool {
        let n = self.since_yield.get();
        if yield_every == 0 || n < yield_every {
            self.since_yield.set(n + 1);
            true
        } else {
            false
        }
    }

    /// A suspended lockstep step runs: it is the first step of the invocation's new turn.
    #[inline]
    fn resume_turn(&self) {
        self.since_yield.set(1);
        self.pending.set(None);
    }

    #[inline]
    pub fn faulted(&self) -> bool {
        self.has_fault.get()
    }

    /// Records why the invocation ends; the first fault wins.
    #[cold]
    pub fn set_fault(&self, f: FaultKind) {
        let mut slot = self.fault.borrow_mut();
        if slot.is_none() {
            *slot = Some(f);
            self.has_fault.set(true);
        }
    }

    /// Records a fault that replaces any earlier one (the executor's verdict).
    #[cold]
    pub fn replace_fault(&self, f: FaultKind) {
        *self.fault.borrow_mut() = Some(f);
        self.has_fault.set(true);
    }

    /// Takes the fault out (the slot can then be reused).
    #[inline]
    pub fn take_fault(&self) -> Option<FaultKind> {
        if !self.has_fault.replace(false) {
            return None;
        }
        self.fault.borrow_mut().take()
    }
}

/// The context of one kernel invocation. Cheap to copy.
#[derive(Clone, Copy)]
pub struct Frag<'a> {
    pub(crate) inv: &'a Invocation,
    pub(crate) env: &'a PassEnv<'a>,
}

/// How [`Frag::perform_counted`] reaches an access's word, past the bounds and step checks.
/// Each context passes a constant variant, so the others fold away.
#[derive(Clone, Copy)]
pub(crate) enum Route<'s, 'a> {
    /// Through the buffer table.
    Table,
    /// Through the buffer table, inside the contention table's count of the address (the
    /// pass keeps the table).
    Contended(&'s crate::stats::ContentionTable),
    /// Through a [`DirectState`]'s cache of buffer words (the fused path, which never keeps
    /// the contention table).
    Cached(&'s WordCache<'a>),
}

/// The future of one step: completes at once in direct mode, suspends until granted in
/// scheduled mode, and never completes once the invocation has faulted (the executor then
/// drops it, which ends the invocation).
pub(crate) struct Step<'a> {
    frag: Frag<'a>,
    kind: StepKind,
    yielded: bool,
}

impl Future for Step<'_> {
    type Output = ();
    #[inline]
    fn poll(mut self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<()> {
        let inv = self.frag.inv;
        let env = self.frag.env;
        if inv.faulted() {
            return Poll::Pending;
        }
        match env.mode {
            Mode::Direct { yield_every } => {
                let steps = inv.steps.get() + 1;
                if steps > env.max_steps {
                    inv.set_fault(FaultKind::Watchdog { steps: steps - 1 });
                    return Poll::Pending;
                }
                if self.yielded {
                    inv.resume_turn();
                } else if !inv.take_turn(yield_every) {
                    self.yielded = true;
                    inv.pending.set(Some(self.kind));
                    return Poll::Pending;
                }
                inv.pending.set(None);
                inv.steps.set(steps);
                Poll::Ready(())
            }
            Mode::Scheduled => {
                if inv.granted.get() {
                    inv.granted.set(false);
                    inv.pending.set(None);
                    inv.steps.set(inv.steps.get() + 1);
                    Poll::Ready(())
                } else {
                    // `pending` was set when the step was made (`Frag::step`).
                    debug_assert_eq!(inv.pending.get(), Some(self.kind));
                    Poll::Pending
                }
            }
        }
    }
}

/// Waits for a condition in direct mode (interlock), counting waits for the watchdog.
struct WaitUntil<'a, F: Fn() -> bool> {
    frag: Frag<'a>,
    ready: F,
    kind: StepKind,
}

impl<F: Fn() -> bool> Future for WaitUntil<'_, F> {
    type Output = ();
    fn poll(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<()> {
        let inv = self.frag.inv;
        if inv.faulted() {
            return Poll::Pending;
        }
        if (self.ready)() {
            inv.pending.set(None);
            return Poll::Ready(());
        }
        let w = inv.waits.get() + 1;
        inv.waits.set(w);
        if w > self.frag.env.max_waits {
            inv.set_fault(FaultKind::Deadlock { waits: w });
        }
        inv.pending.set(Some(self.kind));
        Poll::Pending
    }
}

/// The future of one shared-memory access ([`Frag::load`], [`Frag::atomic_add`], ...).
///
/// Written by hand rather than as an `async fn`: under the `ordered` and `parallel`
/// executors an access completes at its first poll, and this keeps that path to a bounds
/// check, a step count and the atomic (an `async fn` would copy its arguments into its
/// state first). Await it at once: an access that is never polled never happens.
///
/// An enum so that an access performed when it was made (the common case) writes two
/// words into the kernel's state machine rather than the whole request (the state is
/// written for every access the kernel awaits).
#[must_use = "a memory access does nothing unless awaited"]
pub struct Access<'a, T: Word>(AccessState<'a, T>);

enum AccessState<'a, T: Word> {
    /// Direct modes: performed when made; the outcome (`Pending`: the invocation faulted).
    Done(Poll<T>),
    /// Not performed yet (scheduled mode, or a lockstep lane that has used its turn).
    Waiting(Request<'a, T>),
}

/// An access that has not been performed yet.
struct Request<'a, T: Word> {
    frag: Frag<'a>,
    buf: Buf<T>,
    index: u32,
    op: MemOp,
    record: Option<RecordSpan>,
    /// Scheduled executor: the access has announced its step (at its first poll).
    stepped: bool,
    /// Direct lockstep mode: the access has suspended once and runs when polled again.
    resumed: bool,
}

impl<T: Word> Future for Access<'_, T> {
    type Output = T;
    #[inline(always)]
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<T> {
        // `Access` is `Unpin` (references and plain data only).
        let this = self.get_mut();
        let req = match &mut this.0 {
            // Performed when it was made (see `Frag::access`), or faulted.
            AccessState::Done(done) => return *done,
            AccessState::Waiting(req) => req,
        };
        let Mode::Direct { yield_every } = req.frag.env.mode else {
            return req.poll_scheduled(cx);
        };
        // Lockstep warps: an invocation makes `yield_every` accesses per turn. An access
        // made after those is run lazily: it suspends at its first poll (in one turn every
        // lane makes its next access, in lane order) and runs at the next.
        let inv = req.frag.inv;
        if yield_every > 0 && !req.resumed {
            req.resumed = true;
            inv.pending.set(Some(StepKind::Mem {
                addr: Addr::new(req.buf.id, req.index),
                op: req.op.kind(),
                record: req.record,
            }));
            return Poll::Pending;
        }
        inv.resume_turn();
        let done = req.frag.perform::<T>(req.buf, req.index, req.op);
        this.0 = AccessState::Done(done);
        done
    }
}

impl<T: Word> Request<'_, T> {
    /// The scheduled executor's path: suspend at a step until the scheduler grants it.
    #[inline(never)]
    fn poll_scheduled(&mut self, cx: &mut Context<'_>) -> Poll<T> {
        let frag = self.frag;
        let (inv, env) = (frag.inv, frag.env);
        let Some(addr) = frag.addr(self.buf, self.index) else {
            return Poll::Pending;
        };
        let kind = self.op.kind();
        let record = self.record;
        let step_kind = StepKind::Mem {
            addr,
            op: kind,
            record,
        };
        let mut step = if self.stepped {
            // The step was announced at the first poll; its future holds no other state
            // in scheduled mode, so it is rebuilt rather than kept in the access.
            Step {
                frag,
                kind: step_kind,
                yielded: false,
            }
        } else {
            self.stepped = true;
            frag.step(step_kind)
        };
        if Pin::new(&mut step).poll(cx).is_pending() {
            return Poll::Pending;
        }
        let k = kind as usize;
        inv.ops[k].set(inv.ops[k].get() + 1);
        // One thread runs every invocation: no locked instruction needed.
        let bits = env.memory.apply_exclusive::<T>(addr, self.op);
        Poll::Ready(T::from_bits(bits))
    }
}

/// The future of a store ([`Frag::store`], [`Frag::atomic_store`]).
#[must_use = "a memory access does nothing unless awaited"]
pub struct Store<'a, T: Word>(Access<'a, T>);

impl<T: Word> Future for Store<'_, T> {
    type Output = ();
    #[inline]
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        Pin::new(&mut self.get_mut().0).poll(cx).map(|_| ())
    }
}

/// The future of [`Frag::atomic_compare_exchange`].
#[must_use = "a memory access does nothing unless awaited"]
pub struct CompareExchange<'a, T: Word> {
    access: Access<'a, T>,
    expected: u64,
}

impl<T: Word> Future for CompareExchange<'_, T> {
    type Output = Result<T, T>;
    #[inline]
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Result<T, T>> {
        let this = self.get_mut();
        let expected = this.expected;
        Pin::new(&mut this.access).poll(cx).map(|prev| {
            if prev.to_bits() == expected {
                Ok(prev)
            } else {
                Err(prev)
            }
        })
    }
}

/// Enters an access into the contention table (`ExecConfig::contention`); the guard leaves
/// it. Out of line, and the operation stays in the caller: an out-of-line function taking
/// the operation would have it written to memory before every access, table or not.
#[cold]
#[inline(never)]
fn enter_contended(
    table: &crate::stats::ContentionTable,
    addr: Addr,
) -> crate::stats::ContentionGuard<'_> {
    table.enter(addr)
}

/// Records an out-of-range access. A free function of plain values: were it a method of
/// [`Frag`], the hot path would keep a copy of the context in memory for its sake (stores
/// before every access, which a locked operation then waits for).
#[cold]
#[inline(never)]
fn out_of_bounds(inv: &Invocation, memory: &Memory, buffer: u32, len: u32, index: u32) {
    inv.set_fault(FaultKind::OutOfBounds {
        buffer: memory.buffer_name(buffer).to_string(),
        index: index as u64,
        len,
    });
}

/// Whether a weak compare-exchange fails spuriously: a hash of the invocation and its step
/// count against `ExecConfig::spurious_cas_per_mille`, so that a schedule replays exactly.
pub(crate) fn spurious_cas_failure(env: &PassEnv<'_>, seq: u64, steps: u64) -> bool {
    let p = env.spurious_cas;
    if p == 0 {
        return false;
    }
    let mut h = seq ^ (steps << 40) ^ 0x9E37_79B9_7F4A_7C15;
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h % 1000 < p as u64
}

/// Records a watchdog fault (see [`out_of_bounds`] for why a free function).
#[cold]
#[inline(never)]
fn watchdog(inv: &Invocation, steps: u64) {
    inv.set_fault(FaultKind::Watchdog { steps });
}

/// A future that never completes: the invocation has faulted and will be dropped.
struct Halt;
impl Future for Halt {
    type Output = ();
    fn poll(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<()> {
        Poll::Pending
    }
}

/// A fragment's input with the pass it belongs to: what the getters of both kernel
/// contexts read (both keep the input in the invocation's slot), written once here.
#[derive(Clone, Copy)]
pub(crate) struct FragView<'a> {
    pub input: FragInput,
    pub env: &'a PassEnv<'a>,
}

impl FragView<'_> {
    #[inline(always)]
    pub fn x(&self) -> u32 {
        self.input.x
    }
    #[inline(always)]
    pub fn y(&self) -> u32 {
        self.input.y
    }
    #[inline(always)]
    pub fn pixel_index(&self) -> u32 {
        self.input.y * self.env.width + self.input.x
    }
    #[inline(always)]
    pub fn width(&self) -> u32 {
        self.env.width
    }
    #[inline(always)]
    pub fn height(&self) -> u32 {
        self.env.height
    }
    #[inline(always)]
    pub fn samples(&self) -> u32 {
        self.env.samples
    }
    #[inline(always)]
    pub fn primitive_id(&self) -> u32 {
        self.input.primitive_id
    }
    #[inline(always)]
    pub fn instance_id(&self) -> u32 {
        self.input.instance_id
    }
    #[inline(always)]
    pub fn front_facing(&self) -> bool {
        self.input.front_facing
    }
    #[inline]
    pub fn depth(&self) -> f32 {
        let i = self.input;
        match self.env.tris.get(i.tri as usize) {
            Some(t) => t.depth_at(i.x as f32 + 0.5, i.y as f32 + 0.5),
            None => i.depth,
        }
    }
    #[inline(always)]
    pub fn coverage(&self) -> u8 {
        self.input.coverage
    }
    #[inline(always)]
    pub fn invocation_id(&self) -> u64 {
        self.input.seq
    }
    #[inline]
    pub fn barycentrics(&self) -> [f32; 3] {
        let i = self.input;
        match self.env.tris.get(i.tri as usize) {
            Some(t) => t.bary_at(i.x as f32 + 0.5, i.y as f32 + 0.5),
            None => [1.0 / 3.0; 3],
        }
    }
    #[inline]
    pub fn sample_depth(&self, s: u32) -> f32 {
        let i = self.input;
        match self.env.tris.get(i.tri as usize) {
            Some(t) => {
                let pos = crate::raster::SampleCount::from_count(self.env.samples)
                    .map(|c| c.positions()[s as usize % c.count()])
                    .unwrap_or((0.5, 0.5));
                t.depth_at(i.x as f32 + pos.0, i.y as f32 + pos.1)
            }
            None => i.depth,
        }
    }
}

impl<'a> Frag<'a> {
    #[inline(always)]
    pub(crate) fn input(&self) -> FragInput {
        self.inv.input.get()
    }
    #[inline(always)]
    pub(crate) fn view(&self) -> FragView<'a> {
        FragView {
            input: self.input(),
            env: self.env,
        }
    }
    // The getters (`x`, `depth`, ...) are `Fragment`'s, through `Self::view`.

    /// Before an interpolated value is read: a misuse if the kernel declared it reads none
    /// (a draw may then have set up no planes).
    #[inline(always)]
    pub(crate) fn check_interpolants(&self) {
        if self.env.no_interpolants {
            self.interpolants_skipped();
        }
    }
    #[cold]
    #[inline(never)]
    fn interpolants_skipped(&self) {
        self.inv.set_fault(FaultKind::Misuse {
            message: "the kernel read an interpolated value (depth, sample depth or \
                      barycentrics) but declared `without_interpolants`"
                .into(),
        });
    }

    /// Writes colour output `target` as floats (float and RGBA8 targets).
    #[inline]
    pub fn output(&self, target: usize, value: [f32; 4]) {
        self.output_bits(target, value.map(f32::to_bits));
    }
    /// Writes colour output `target` as unsigned integers (R32UI, RGBA32UI targets).
    #[inline]
    pub fn output_u32(&self, target: usize, value: [u32; 4]) {
        self.output_bits(target, value);
    }
    fn output_bits(&self, target: usize, value: [u32; 4]) {
        if let Some(o) = self.inv.outputs.get(target) {
            o.set(value);
            self.inv
                .outputs_written
                .set(self.inv.outputs_written.get() | 1 << target);
        } else {
            self.inv.set_fault(FaultKind::Misuse {
                message: format!("output to target {target}; at most 8 exist"),
            });
        }
    }
    /// Discards the fragment: no colour, depth or stencil write after the shader (memory
    /// writes already made stay, as on a GPU).
    #[inline]
    pub fn discard(&self) {
        self.inv.discarded.set(true);
    }
    /// Replaces the fragment's depth for the late depth test (`gl_FragDepth`).
    #[inline]
    pub fn write_depth(&self, z: f32) {
        self.inv.depth_out.set(Some(z));
    }

    fn step(&self, kind: StepKind) -> Step<'a> {
        if self.env.mode == Mode::Scheduled {
            // Announced here, from registers: copying it out of the future's state in
            // `Step::poll` stalled on store forwarding (the hottest instruction of the
            // access path in profiles of the scheduled executor).
            self.inv.pending.set(Some(kind));
        }
        Step {
            frag: *self,
            kind,
            yielded: false,
        }
    }

    /// Checks bounds; on failure records the fault (the invocation ends at its next await).
    fn addr<T: Word>(&self, buf: Buf<T>, index: u32) -> Option<Addr> {
        if index < buf.len {
            Some(Addr::new(buf.id, index))
        } else {
            self.out_of_bounds(buf, index);
            None
        }
    }

    #[inline(always)]
    fn out_of_bounds<T: Word>(&self, buf: Buf<T>, index: u32) {
        out_of_bounds(self.inv, self.env.memory, buf.id, buf.len, index);
    }

    /// The future of one access: bounds are checked when it is first polled (an
    /// out-of-range access faults and ends the invocation).
    ///
    /// Under the direct executors (`ordered`, `parallel`) the access is performed here, when
    /// it is made, unless a lockstep lane has used its turn: here the operation is a
    /// constant of the kernel's code (inside the future's `poll` it would be read back from
    /// the kernel's state machine and dispatched at run time). Awaited at once, as the
    /// kernel API asks, this is the same as performing it at its first poll.
    #[inline(always)]
    fn access<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        op: MemOp,
        record: Option<RecordSpan>,
    ) -> Access<'a, T> {
        if let Mode::Direct { yield_every } = self.env.mode {
            if self.inv.take_turn(yield_every) {
                return Access(AccessState::Done(self.perform::<T>(buf, index, op)));
            }
        }
        // Left for later: scheduled mode, or a lockstep lane past its turn.
        Access(AccessState::Waiting(Request {
            frag: *self,
            buf,
            index,
            op,
            record,
            stepped: false,
            resumed: false,
        }))
    }

    /// Performs one access under a direct executor: a bounds check, a step count for the
    /// watchdog, the operation counter and the operation itself. `Pending` when the
    /// invocation faults (the executor then drops it).
    #[inline(always)]
    pub(crate) fn perform<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Poll<T> {
        let route = match self.env.contention {
            Some(table) => Route::Contended(table),
            None => Route::Table,
        };
        self.perform_counted(&self.inv.steps, &self.inv.ops, route, buf, index, op)
    }

    /// [`Self::perform`] counting into `steps` and `ops` (the slot's, or a
    /// [`DirectState`]'s), reaching the word by `route`. Both contexts perform an access
    /// here, so they compute the same.
    #[inline(always)]
    pub(crate) fn perform_counted<T: Word>(
        &self,
        steps: &Cell<u64>,
        ops: &[Cell<u32>; OP_KINDS],
        route: Route<'_, 'a>,
        buf: Buf<T>,
        index: u32,
        op: MemOp,
    ) -> Poll<T> {
        let env = self.env;
        if index >= buf.len {
            self.out_of_bounds(buf, index);
            return Poll::Pending;
        }
        if self.count_step(steps).is_pending() {
            return Poll::Pending;
        }
        let kind = op.kind();
        let k = kind as usize;
        ops[k].set(ops[k].get() + 1);
        let addr = Addr::new(buf.id, index);
        let ordering = if kind.is_plain() {
            crate::sync::Ordering::Relaxed
        } else {
            crate::sync::Ordering::AcqRel
        };
        let bits = match route {
            Route::Table => env.memory.apply::<T>(addr, op, ordering),
            Route::Cached(words) => words.apply::<T>(env.memory, addr, op, ordering),
            Route::Contended(table) => {
                let guard = enter_contended(table, addr);
                let bits = env.memory.apply::<T>(addr, op, ordering);
                drop(guard);
                bits
            }
        };
        Poll::Ready(T::from_bits(bits))
    }

    /// A one-word access ([`Fragment::load`], [`Fragment::atomic_add`], ...).
    #[inline(always)]
    pub(crate) fn access_value<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        op: MemOp,
    ) -> Access<'a, T> {
        self.access(buf, index, op, None)
    }
    /// A one-word store ([`Fragment::store`], [`Fragment::atomic_store`]).
    #[inline(always)]
    pub(crate) fn access_unit<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Store<'a, T> {
        Store(self.access(buf, index, op, None))
    }
    /// Atomic compare-exchange: `Ok(previous)` if the word held `expected` and now holds
    /// `new`, `Err(current)` otherwise (bitwise comparison, as GLSL's `atomicCompSwap`).
    #[inline(always)]
    pub fn atomic_compare_exchange<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> CompareExchange<'a, T> {
        CompareExchange {
            access: self.access(
                buf,
                index,
                MemOp::CompareExchange(expected.to_bits(), new.to_bits()),
                None,
            ),
            expected: expected.to_bits(),
        }
    }

    /// Weak compare-exchange: as [`Frag::atomic_compare_exchange`], but may fail
    /// spuriously (returning `Err(current)` even when the word held `expected`), as
    /// `compare_exchange_weak` may on LL/SC hardware. How often is
    /// `ExecConfig::spurious_cas_per_mille`; the decision hashes the invocation and its step
    /// count, so a schedule replays exactly. Loops written for weak CAS must retry.
    pub async fn atomic_compare_exchange_weak<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> Result<T, T> {
        if self.spurious_cas_failure() {
            // A failed attempt reads the word, as a real failed CAS does.
            let cur: T = self.access(buf, index, MemOp::AtomicLoad, None).await;
            return Err(cur);
        }
        self.atomic_compare_exchange(buf, index, expected, new)
            .await
    }

    /// Whether this weak compare-exchange fails spuriously: a hash of the invocation and
    /// its step count, so that a schedule replays exactly.
    #[inline]
    pub(crate) fn spurious_cas_failure(&self) -> bool {
        spurious_cas_failure(self.env, self.input().seq, self.inv.steps.get())
    }

    /// One step of the invocation counted into `steps` for the watchdog: an access (see
    /// [`Self::perform_counted`]) or, under a direct executor without lockstep, a yield.
    /// `Pending` when the invocation faults (the watchdog's limit, or an earlier fault).
    #[inline(always)]
    pub(crate) fn count_step(&self, steps: &Cell<u64>) -> Poll<()> {
        let inv = self.inv;
        let n = steps.get() + 1;
        if n > self.env.max_steps || inv.faulted() {
            watchdog(inv, n - 1);
            return Poll::Pending;
        }
        steps.set(n);
        Poll::Ready(())
    }

    /// Loads a multi-word record `buf[base .. base + out.len()]` with plain loads, one step
    /// per word. The hazard detector reports it *torn* if another invocation writes any of
    /// its words between the first and the last load.
    pub async fn load_record<T: Word>(&self, buf: Buf<T>, base: u32, out: &mut [T]) {
        let len = out.len() as u32;
        let span_base = Addr::new(buf.id, base);
        for (w, slot) in out.iter_mut().enumerate() {
            let record = Some(RecordSpan {
                base: span_base,
                len,
                word: w as u32,
            });
            *slot = self
                .access(buf, base.wrapping_add(w as u32), MemOp::Load, record)
                .await;
        }
    }
    /// Stores a multi-word record with plain stores, one step per word.
    pub async fn store_record<T: Word>(&self, buf: Buf<T>, base: u32, values: &[T]) {
        let len = values.len() as u32;
        let span_base = Addr::new(buf.id, base);
        for (w, v) in values.iter().enumerate() {
            let record = Some(RecordSpan {
                base: span_base,
                len,
                word: w as u32,
            });
            self.access(
                buf,
                base.wrapping_add(w as u32),
                MemOp::Store(v.to_bits()),
                record,
            )
            .await;
        }
    }

    /// A scheduling point with no memory access (in spin loops: lets others run and counts
    /// towards the watchdog).
    pub async fn yield_now(&self) {
        self.step(StepKind::Yield).await;
    }

    /// The interlock words this invocation claims.
    pub(crate) fn claim(&self) -> Option<(&'a Interlock, InterlockMode, crate::interlock::Claim)> {
        let (lock, mode) = (self.env.interlock?, self.env.interlock_mode?);
        let i = self.input();
        let tickets = if mode.per_sample {
            self.env
                .sample_tickets
                .get(i.ticket as usize)
                .copied()
                .unwrap_or([i.ticket; 8])
        } else {
            [i.ticket; 8]
        };
        Some((lock, mode, lock.claim(mode, i.x, i.y, i.coverage, tickets)))
    }

    /// Enters the per-pixel critical section declared in [`KernelInfo::interlock`]
    /// (`beginInvocationInterlockARB`). Ordered mode enters in API order.
    pub async fn interlock_begin(&self) {
        let (Some(lock), Some(mode)) = (self.env.interlock, self.env.interlock_mode) else {
            self.inv.set_fault(FaultKind::Misuse {
                message: "interlock_begin without declaring interlock in KernelInfo".into(),
            });
            return Halt.await;
        };
        if self.inv.in_interlock.get() || self.inv.entered_interlock.get() {
            self.inv.set_fault(FaultKind::Misuse {
                message: "interlock entered twice".into(),
            });
            return Halt.await;
        }
        let Some((_, _, claim)) = self.claim() else {
            return Halt.await;
        };
        match self.env.mode {
            Mode::Scheduled => {
                // The scheduler grants this step only when the lock can be taken.
                self.step(StepKind::InterlockBegin).await;
                let ok = lock.try_enter_claim(mode, &claim);
                debug_assert!(ok, "scheduler granted an interlock that was not free");
            }
            Mode::Direct { .. } => {
                WaitUntil {
                    frag: *self,
                    ready: || lock.try_enter_claim(mode, &claim),
                    kind: StepKind::InterlockBegin,
                }
                .await;
            }
        }
        self.inv.in_interlock.set(true);
        self.inv.entered_interlock.set(true);
    }

    /// Leaves the critical section (`endInvocationInterlockARB`).
    pub async fn interlock_end(&self) {
        let (Some(lock), Some(mode)) = (self.env.interlock, self.env.interlock_mode) else {
            return;
        };
        if !self.inv.in_interlock.get() {
            self.inv.set_fault(FaultKind::Misuse {
                message: "interlock_end outside the critical section".into(),
            });
            return Halt.await;
        }
        if self.env.mode == Mode::Scheduled {
            self.step(StepKind::InterlockEnd).await;
        }
        if let Some((_, _, claim)) = self.claim() {
            lock.leave_claim(mode, &claim);
        }
        self.inv.in_interlock.set(false);
    }

    /// Called by the executor after the kernel returns: leaves a critical section still
    /// held, and in ordered mode passes the turn of a fragment that never entered.
    pub(crate) async fn retire(&self) {
        if self.inv.in_interlock.get() {
            self.interlock_end().await;
            return;
        }
        let (Some(lock), Some(mode)) = (self.env.interlock, self.env.interlock_mode) else {
            return;
        };
        if self.inv.entered_interlock.get() || !mode.ordered {
            return;
        }
        let _ = lock;
        let Some((lock, _, claim)) = self.claim() else {
            return;
        };
        match self.env.mode {
            Mode::Scheduled => {
                self.step(StepKind::PassTurn).await;
                lock.pass_turn_claim(&claim);
            }
            Mode::Direct { .. } => {
                WaitUntil {
                    frag: *self,
                    ready: || lock.is_turn_claim(&claim),
                    kind: StepKind::PassTurn,
                }
                .await;
                lock.pass_turn_claim(&claim);
            }
        }
    }

    /// A read-only image from an earlier pass (not shared memory: no step).
    #[inline]
    pub fn texel(&self, image: &Image, x: u32, y: u32, sample: u32) -> [u32; 4] {
        image.texel(
            x.min(image.width.saturating_sub(1)),
            y.min(image.height.saturating_sub(1)),
            sample % image.samples.max(1),
        )
    }
}
