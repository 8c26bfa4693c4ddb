//! [`DirectFrag`], the fused path's kernel context: every access is performed when it is
//! made and never suspends.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use super::{DirectState, Frag, FragView, Route};
use crate::fragment::{sealed, Fragment};
use crate::framebuffer::Image;
use crate::memory::{Buf, MemOp, OpKind, Word};

/// The context of the fused path of the direct executors: every access is performed when
/// it is made and never suspends (see the module docs). The fragment's input, step count,
/// discard flag, depth output and operation counters are a `DirectState` (crate-private)
/// the executor keeps in a local (in registers, once the kernel is inlined); colour outputs
/// and faults go to the invocation's slot, as under [`Frag`].
///
/// `OWN`: the worker owns the fragment's tile for the whole pass, so the fragment's slot of
/// an array the kernel declared its pixels' own is reached by no other thread
/// ([`KernelInfo::with_own_pixel_array`](crate::KernelInfo::with_own_pixel_array)). A
/// constant, so that a context without it carries no code for it (the kernel's state
/// machine is then small enough to be inlined into the shading loop).
///
/// It is one pointer: a kernel's future copies its context on its first poll, and a copy
/// of a wider context (three pointers, stored one by one just before) was a 16-byte load
/// of two 8-byte stores, which the store buffer cannot forward: a stall of about 15 cycles
/// per fragment, in each nested `async fn` that takes the context (docs/performance.md).
#[derive(Clone, Copy)]
pub struct DirectFrag<'c, 'a, const OWN: bool = false> {
    ctx: &'c DirectCtx<'a>,
}

/// What a [`DirectFrag`] points to: the invocation and its pass, and the per-fragment
/// state. The executor keeps it on its stack for the invocation.
pub(crate) struct DirectCtx<'a> {
    pub frag: Frag<'a>,
    pub state: &'a DirectState<'a>,
}

/// An access already performed: its value. It is always ready: an access that faults does
/// not return (see [`Halted`]).
#[must_use = "a memory access is awaited at once"]
pub struct Performed<T>(T);

impl<T: Copy> Future for Performed<T> {
    type Output = T;
    #[inline(always)]
    fn poll(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<T> {
        Poll::Ready(self.0)
    }
}

impl<T> Performed<T> {
    /// The access's outcome as a [`Performed`]: its value, or, when the invocation faulted
    /// (the fault already recorded in its slot), no return at all ([`halt`]).
    #[inline(always)]
    fn of(outcome: Poll<T>) -> Self {
        match outcome {
            Poll::Ready(v) => Performed(v),
            Poll::Pending => halt(),
        }
    }
}

/// The payload with which a fused-path invocation that faulted leaves its kernel: the
/// executor's `catch_unwind` around the kernel takes it, and the fault is already recorded.
///
/// Why not `Pending`, as under [`Frag`]: an await that may return `Pending` is a point where
/// the kernel's state machine may stop, so the locals that live across it are kept in the
/// state machine's memory, a store and a load for each use. An access that is always ready
/// leaves the compiler free to keep them in registers (`ll` at 2048 x 2048 on one thread,
/// with the word table of `memory::WordCache`: insert 32.0 -> 29.7 ms, resolve 35.4 -> 33.7
/// ms, docs/performance.md).
pub(crate) struct Halted;

/// Leaves the kernel of an invocation that faulted (see [`Halted`]). `resume_unwind`, not
/// `panic!`: the panic hook is not called, so nothing is printed.
#[cold]
#[inline(never)]
fn halt() -> ! {
    std::panic::resume_unwind(Box::new(Halted))
}

impl<'c, 'a, const OWN: bool> DirectFrag<'c, 'a, OWN> {
    /// The context of the invocation in `ctx.frag`'s slot, whose per-fragment state is
    /// `ctx.state`.
    #[inline(always)]
    pub(crate) fn new(ctx: &'c DirectCtx<'a>) -> Self {
        DirectFrag { ctx }
    }
    #[inline(always)]
    fn as_frag(&self) -> &Frag<'a> {
        &self.ctx.frag
    }
    #[inline(always)]
    fn view(&self) -> FragView<'a> {
        FragView {
            input: self.ctx.state.input.get(),
            env: self.ctx.frag.env,
        }
    }
    #[inline(always)]
    fn set_discarded(&self) {
        self.ctx.state.discarded.set(true);
    }
    #[inline(always)]
    fn set_depth_out(&self, z: f32) {
        self.ctx.state.depth_out.set(Some(z));
    }
    /// The fragment's own slot of `buf` when this worker owns the tile and `buf` is the
    /// kernel's own per-pixel or per-block array (`DirectState::owning`): its first word,
    /// its words, and the declaration that made it own.
    #[inline(always)]
    fn own_slot<T: Word>(&self, buf: Buf<T>) -> Option<(u64, u64, &'static str)> {
        if !OWN {
            return None;
        }
        let st = self.ctx.state;
        let own = &st.own;
        if buf.id == own.pixel_buffer {
            let input = st.input.get();
            let width = self.ctx.frag.env.width;
            Some((
                (input.y as u64 * width as u64 + input.x as u64) * own.pixel_stride as u64,
                own.pixel_stride as u64,
                "with_own_pixel_array",
            ))
        } else if buf.id == own.block_buffer {
            let input = st.input.get();
            Some((
                own.block_first_word(input.x, input.y),
                own.block_stride as u64,
                "with_own_block_array",
            ))
        } else {
            None
        }
    }
    #[inline(always)]
    fn perform<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Poll<T> {
        let st = self.ctx.state;
        // The fused path never keeps the contention table (`shade_direct` checks).
        // Where the tile is this worker's for the pass, the fragment's own slot (of its
        // pixel, or of its block, which lies in the tile) is reached by no other thread
        // (`DirectState::owning`): its first word, its words and the declaration.
        let route = match self.own_slot(buf) {
            Some((first, stride, declared)) => {
                // Out of bounds is reported as such, below.
                if (index as u64).wrapping_sub(first) >= stride && index < buf.len {
                    let input = st.input.get();
                    self.ctx
                        .frag
                        .not_own_slot(buf.id, index, (input.x, input.y), declared);
                    return Poll::Pending;
                }
                Route::Owned(&st.words)
            }
            None => Route::Cached(&st.words),
        };
        self.ctx
            .frag
            .perform_counted::<T>(&st.steps, &st.ops, route, buf, index, op)
    }
    /// The fast path of a plain record access of `len` words at `base..` (fewer words than
    /// `u32::MAX`): one bounds check, one step claim and one count for the record
    /// ([`Frag::claim_record`]), when the words lie in bounds, the step limit allows them all
    /// and, for the kernel's own array, all lie in the fragment's own slot. Then every word
    /// is what [`DirectFrag::perform`] would have loaded or stored, one by one, on the same
    /// route: a plain load or store, the same on an owned slot as on any word. False, with
    /// nothing done, otherwise (the word-by-word path then faults where it would).
    #[inline(always)]
    fn claim_record<T: Word>(&self, buf: Buf<T>, base: u32, len: usize, kind: OpKind) -> bool {
        let st = self.ctx.state;
        let Ok(len) = u32::try_from(len) else {
            return false;
        };
        if len == 0 {
            return false;
        }
        if let Some((first, stride, _)) = self.own_slot(buf) {
            let (lo, hi) = (u64::from(base), u64::from(base) + u64::from(len));
            if lo < first || hi > first + stride {
                return false;
            }
        }
        self.ctx
            .frag
            .claim_record(&st.steps, &st.ops, buf.len, base, len, kind)
    }
    #[inline(always)]
    fn op<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Performed<T> {
        Performed::of(self.perform::<T>(buf, index, op))
    }
    #[inline(always)]
    fn unit<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Performed<()> {
        Performed::of(self.perform::<T>(buf, index, op).map(|_| ()))
    }
}

impl<const OWN: bool> Fragment for DirectFrag<'_, '_, OWN> {
    getters!();
    word_accesses!(op, unit);

    #[inline(always)]
    fn atomic_compare_exchange<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>> {
        let op = MemOp::CompareExchange(expected.to_bits(), new.to_bits());
        Performed::of(self.perform::<T>(buf, index, op).map(|prev: T| {
            if prev.to_bits() == expected.to_bits() {
                Ok(prev)
            } else {
                Err(prev)
            }
        }))
    }
    #[inline(always)]
    fn atomic_compare_exchange_weak<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>> {
        if super::spurious_cas_failure(
            self.ctx.frag.env,
            self.ctx.state.input.get().seq,
            self.ctx.state.steps.get(),
        ) {
            // A failed attempt reads the word, as a real failed CAS does.
            return Performed::of(self.perform::<T>(buf, index, MemOp::AtomicLoad).map(Err));
        }
        let op = MemOp::CompareExchange(expected.to_bits(), new.to_bits());
        Performed::of(self.perform::<T>(buf, index, op).map(|prev: T| {
            if prev.to_bits() == expected.to_bits() {
                Ok(prev)
            } else {
                Err(prev)
            }
        }))
    }
    #[inline(always)]
    fn load_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        out: &mut [T],
    ) -> impl Future<Output = ()> {
        if self.claim_record(buf, base, out.len(), OpKind::Load) {
            let st = self.ctx.state;
            st.words
                .load_record(self.ctx.frag.env.memory, buf.id, base, out);
            return Performed(());
        }
        let mut done = Poll::Ready(());
        for (w, slot) in out.iter_mut().enumerate() {
            match self.perform::<T>(buf, base.wrapping_add(w as u32), MemOp::Load) {
                Poll::Ready(v) => *slot = v,
                Poll::Pending => {
                    done = Poll::Pending;
                    break;
                }
            }
        }
        Performed::of(done)
    }
    #[inline(always)]
    fn store_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        values: &[T],
    ) -> impl Future<Output = ()> {
        if self.claim_record(buf, base, values.len(), OpKind::Store) {
            let st = self.ctx.state;
            st.words
                .store_record(self.ctx.frag.env.memory, buf.id, base, values);
            return Performed(());
        }
        let mut done = Poll::Ready(());
        for (w, v) in values.iter().enumerate() {
            let op = MemOp::Store(v.to_bits());
            if self
                .perform::<T>(buf, base.wrapping_add(w as u32), op)
                .is_pending()
            {
                done = Poll::Pending;
                break;
            }
        }
        Performed::of(done)
    }
    #[inline(always)]
    fn yield_now(&self) -> impl Future<Output = ()> {
        Performed::of(self.ctx.frag.count_step(&self.ctx.state.steps))
    }
    #[inline(always)]
    fn prefetch<T: Word>(&self, buf: Buf<T>, words: std::ops::Range<u32>) {
        if !T::WIDE {
            self.ctx.state.words.prefetch32(buf.id, words);
        }
    }
}

impl<const OWN: bool> sealed::Sealed for DirectFrag<'_, '_, OWN> {}
