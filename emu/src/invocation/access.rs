//! The futures of one step and of one shared-memory access, and the cold paths that record
//! faults (kept out of line so that the hot path stays in registers).

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use super::{Frag, Invocation, Mode, PassEnv, RecordSpan, StepKind};
use crate::kernel::FaultKind;
use crate::memory::{Addr, Buf, MemOp, Memory, Word, WordCache};

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
    /// Through a [`DirectState`]'s cache, to a word only this thread accesses during the
    /// pass (its pixel's own slot in an owned tile, `KernelInfo::with_own_pixel_array`):
    /// the operation as a plain load and store.
    Owned(&'s WordCache<'a>),
}

/// The future of one step: completes at once in direct mode, suspends until granted in
/// scheduled mode, and never completes once the invocation has faulted (the executor then
/// drops it, which ends the invocation).
pub(crate) struct Step<'a> {
    pub(super) frag: Frag<'a>,
    pub(super) kind: StepKind,
    pub(super) yielded: bool,
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
pub(super) struct WaitUntil<'a, F: Fn() -> bool> {
    pub(super) frag: Frag<'a>,
    pub(super) ready: F,
    pub(super) kind: StepKind,
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
pub struct Access<'a, T: Word>(pub(super) AccessState<'a, T>);

pub(super) enum AccessState<'a, T: Word> {
    /// Direct modes: performed when made; the outcome (`Pending`: the invocation faulted).
    Done(Poll<T>),
    /// Not performed yet (scheduled mode, or a lockstep lane that has used its turn).
    Waiting(Request<'a, T>),
}

/// An access that has not been performed yet.
pub(super) struct Request<'a, T: Word> {
    pub(super) frag: Frag<'a>,
    pub(super) buf: Buf<T>,
    pub(super) index: u32,
    pub(super) op: MemOp,
    pub(super) record: Option<RecordSpan>,
    /// Scheduled executor: the access has announced its step (at its first poll).
    pub(super) stepped: bool,
    /// Direct lockstep mode: the access has suspended once and runs when polled again.
    pub(super) resumed: bool,
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
    ///
    /// What [`Frag::step`] and [`Step::poll`] do, written out for a memory access: at the
    /// first poll, the bounds check and the step's announcement; at a later one, the grant.
    /// (The address is not checked again: a first poll that found it out of range faulted
    /// the invocation, which then never steps.)
    #[inline(never)]
    fn poll_scheduled(&mut self, _cx: &mut Context<'_>) -> Poll<T> {
        let frag = self.frag;
        let (inv, env) = (frag.inv, frag.env);
        let kind = self.op.kind();
        let addr = if self.stepped {
            Addr::new(self.buf.id, self.index)
        } else {
            let Some(addr) = frag.addr(self.buf, self.index) else {
                return Poll::Pending;
            };
            self.stepped = true;
            inv.pending.set(Some(StepKind::Mem {
                addr,
                op: kind,
                record: self.record,
            }));
            addr
        };
        if inv.faulted() || !inv.granted.get() {
            return Poll::Pending;
        }
        inv.granted.set(false);
        inv.pending.set(None);
        inv.steps.set(inv.steps.get() + 1);
        let k = kind as usize;
        inv.ops[k].set(inv.ops[k].get() + 1);
        // One thread runs every invocation: no locked instruction needed.
        let bits = env.memory.apply_exclusive::<T>(addr, self.op);
        // What the access read (the word before it), for the hazard detector.
        inv.read.set(bits);
        if let MemOp::CompareExchange(expected, _) = self.op {
            let wide = T::WIDE;
            inv.cas_failed.set(if wide {
                bits != expected
            } else {
                bits as u32 != expected as u32
            });
        }
        Poll::Ready(T::from_bits(bits))
    }
}

/// The future of a store ([`Frag::store`], [`Frag::atomic_store`]).
#[must_use = "a memory access does nothing unless awaited"]
pub struct Store<'a, T: Word>(pub(super) Access<'a, T>);

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
    pub(super) access: Access<'a, T>,
    pub(super) expected: u64,
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
pub(super) fn enter_contended(
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
pub(super) fn out_of_bounds(inv: &Invocation, memory: &Memory, buffer: u32, len: u32, index: u32) {
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
pub(super) fn watchdog(inv: &Invocation, steps: u64) {
    inv.set_fault(FaultKind::Watchdog { steps });
}

/// A future that never completes: the invocation has faulted and will be dropped.
pub(super) struct Halt;
impl Future for Halt {
    type Output = ();
    fn poll(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<()> {
        Poll::Pending
    }
}
