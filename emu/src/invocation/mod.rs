//! The per-invocation runtime: everything one kernel invocation needs while it runs, and
//! the two contexts through which it sees its fragment ([`crate::Fragment`]).
//!
//! - `slot`: an invocation's mutable state ([`Invocation`], one per in-flight slot of an
//!   executor) and the fused path's register-resident [`DirectState`];
//! - `frag`: [`Frag`], the general context, where an access may suspend the invocation
//!   (the scheduled executor before every access, lockstep lanes after their turn,
//!   interlock waits), and the access path every context shares (`Frag::perform_counted`:
//!   bounds check, watchdog step, operation counter, the operation);
//! - `access`: the futures of a step and of an access ([`Access`], [`Store`],
//!   [`CompareExchange`]) and the cold paths of faults;
//! - `direct`: [`DirectFrag`], the fused path's context, where an access is performed when
//!   it is made and never suspends. Its futures are values already computed
//!   ([`Performed`]), so once the compiler inlines the kernel, its state machine folds away
//!   into the executor's loop: the `count` kernel went from about 84 instructions per
//!   fragment through [`Frag`] to a handful (docs/performance.md).
//!
//! Both contexts perform an access the same way, so a kernel computes the same thing under
//! either; the differential oracle checks that on every algorithm. They differ in where the
//! fragment's state lives: [`Frag`] reads and writes the invocation's slot, [`DirectFrag`] a
//! [`DirectState`] that the executor keeps in a local, so that it stays in registers.
//!
//! This module knows nothing of any algorithm, and nothing of how executors pick
//! invocations: it only suspends (`Pending`) where the executor asked it to.

use crate::interlock::{Interlock, InterlockMode};
use crate::memory::{Addr, Memory, OpKind};
use crate::raster::SetupTriangle;

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
    /// The per-pixel critical sections of a kernel that declares interlock
    /// (`interlock_mode`). `None` with a mode is interlock by ownership: the executor runs
    /// each pixel's fragments one at a time, to their end, in API order, on the one thread
    /// that owns the pixel's tile (the fused path without lockstep), so a section is
    /// always free and entered in order, and there is no lock to take.
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

/// The getters both contexts share (they read the same invocation state).
macro_rules! getters {
    () => {
        #[inline(always)]
        fn x(&self) -> u32 {
            self.view().x()
        }
        #[inline(always)]
        fn y(&self) -> u32 {
            self.view().y()
        }
        #[inline(always)]
        fn pixel_index(&self) -> u32 {
            self.view().pixel_index()
        }
        #[inline(always)]
        fn width(&self) -> u32 {
            self.view().width()
        }
        #[inline(always)]
        fn height(&self) -> u32 {
            self.view().height()
        }
        #[inline(always)]
        fn samples(&self) -> u32 {
            self.view().samples()
        }
        #[inline(always)]
        fn primitive_id(&self) -> u32 {
            self.view().primitive_id()
        }
        #[inline(always)]
        fn instance_id(&self) -> u32 {
            self.view().instance_id()
        }
        #[inline(always)]
        fn front_facing(&self) -> bool {
            self.view().front_facing()
        }
        #[inline(always)]
        fn depth(&self) -> f32 {
            self.as_frag().check_interpolants();
            self.view().depth()
        }
        #[inline(always)]
        fn coverage(&self) -> u8 {
            self.view().coverage()
        }
        #[inline(always)]
        fn invocation_id(&self) -> u64 {
            self.view().invocation_id()
        }
        #[inline(always)]
        fn barycentrics(&self) -> [f32; 3] {
            self.as_frag().check_interpolants();
            self.view().barycentrics()
        }
        #[inline(always)]
        fn sample_depth(&self, s: u32) -> f32 {
            self.as_frag().check_interpolants();
            self.view().sample_depth(s)
        }
        #[inline(always)]
        fn output(&self, target: usize, value: [f32; 4]) {
            Frag::output(self.as_frag(), target, value)
        }
        #[inline(always)]
        fn output_u32(&self, target: usize, value: [u32; 4]) {
            Frag::output_u32(self.as_frag(), target, value)
        }
        #[inline(always)]
        fn discard(&self) {
            self.set_discarded()
        }
        #[inline(always)]
        fn write_depth(&self, z: f32) {
            self.set_depth_out(z)
        }
        #[inline(always)]
        fn texel(&self, image: &Image, x: u32, y: u32, sample: u32) -> [u32; 4] {
            Frag::texel(self.as_frag(), image, x, y, sample)
        }
        #[inline(always)]
        fn interlock_begin(&self) -> impl Future<Output = ()> {
            Frag::interlock_begin(self.as_frag())
        }
        #[inline(always)]
        fn interlock_end(&self) -> impl Future<Output = ()> {
            Frag::interlock_end(self.as_frag())
        }
    };
}

/// The one-word accesses, in terms of the context's `$value(buf, index, op)` (a future of
/// the previous value) and `$unit(buf, index, op)` (a future of `()`, for stores).
macro_rules! word_accesses {
    ($value:ident, $unit:ident) => {
        #[inline(always)]
        fn load<T: Word>(&self, buf: Buf<T>, index: u32) -> impl Future<Output = T> {
            self.$value(buf, index, MemOp::Load)
        }
        #[inline(always)]
        fn store<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = ()> {
            self.$unit(buf, index, MemOp::Store(value.to_bits()))
        }
        #[inline(always)]
        fn atomic_load<T: Word>(&self, buf: Buf<T>, index: u32) -> impl Future<Output = T> {
            self.$value(buf, index, MemOp::AtomicLoad)
        }
        #[inline(always)]
        fn atomic_store<T: Word>(
            &self,
            buf: Buf<T>,
            index: u32,
            value: T,
        ) -> impl Future<Output = ()> {
            self.$unit(buf, index, MemOp::AtomicStore(value.to_bits()))
        }
        word_accesses!(@rmw $value: atomic_add Add, atomic_sub Sub, atomic_min Min,
            atomic_max Max, atomic_and And, atomic_or Or, atomic_xor Xor,
            atomic_exchange Exchange);
    };
    (@rmw $value:ident: $($name:ident $op:ident),*) => {
        $(
            #[inline(always)]
            fn $name<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T> {
                self.$value(buf, index, MemOp::$op(value.to_bits()))
            }
        )*
    };
}

mod access;
mod direct;
mod frag;
mod slot;

pub(crate) use access::{spurious_cas_failure, Route};
pub use access::{Access, CompareExchange, Store};
pub(crate) use direct::DirectCtx;
pub(crate) use direct::Halted;
pub use direct::{DirectFrag, Performed};
pub use frag::Frag;
pub(crate) use frag::FragView;
pub(crate) use slot::{DirectState, Invocation, OP_KINDS};
