//! [`Frag`], the general kernel context: it reads and writes the invocation's slot, and an
//! access may suspend the invocation until its executor lets it run.

use std::cell::Cell;
use std::future::Future;
use std::task::Poll;

use super::access::{
    enter_contended, out_of_bounds, spurious_cas_failure, watchdog, AccessState, Halt, Request,
    Route, Step, WaitUntil,
};
use super::{
    Access, CompareExchange, Invocation, Mode, PassEnv, RecordSpan, StepKind, Store, OP_KINDS,
};
use crate::fragment::{sealed, Fragment};
use crate::framebuffer::Image;
use crate::interlock::{Interlock, InterlockMode};
use crate::kernel::{FaultKind, FragInput};
use crate::memory::{Addr, Buf, MemOp, OpKind, Word};

/// The context of one kernel invocation. Cheap to copy.
#[derive(Clone, Copy)]
pub struct Frag<'a> {
    pub(crate) inv: &'a Invocation,
    pub(crate) env: &'a PassEnv<'a>,
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
            Some(t) => t.depth_at_center(i.x, i.y),
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

    /// An access to another pixel's slot of an array declared the pixels' own
    /// (`KernelInfo::with_own_pixel_array`), on a path that relies on the declaration.
    #[cold]
    #[inline(never)]
    pub(crate) fn not_own_slot(
        &self,
        buffer: u32,
        index: u32,
        (x, y): (u32, u32),
        declared_with: &str,
    ) {
        let name = self.env.memory.buffer_name(buffer);
        self.inv.set_fault(FaultKind::Misuse {
            message: format!(
                "the invocation at pixel ({x}, {y}) accessed word {index} of `{name}`, outside \
                 its own slot of the array the kernel declared with `{declared_with}`"
            ),
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
    // Inline: the resolves call it once a pixel, from the kernels' crate.
    #[inline]
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

    pub(super) fn step(&self, kind: StepKind) -> Step<'a> {
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
    pub(super) fn addr<T: Word>(&self, buf: Buf<T>, index: u32) -> Option<Addr> {
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
            Route::Owned(words) => words.apply_owned::<T>(env.memory, addr, op),
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

    /// Claims at once the steps and operation counts of a plain record access of `len`
    /// words at `base..base + len` of a buffer of `buf_len` words (the fused path's
    /// [`Fragment::load_record`] and [`Fragment::store_record`]): true when every word is in
    /// bounds, the step limit allows all of them and the invocation has not faulted, the
    /// steps and counts are then taken, as `len` calls of [`Frag::perform_counted`] would
    /// take them. False, with nothing taken, otherwise: the caller goes word by word, so a
    /// fault falls on the word it would fall on.
    ///
    /// [`Fragment::load_record`]: crate::Fragment::load_record
    /// [`Fragment::store_record`]: crate::Fragment::store_record
    #[inline(always)]
    pub(crate) fn claim_record(
        &self,
        steps: &Cell<u64>,
        ops: &[Cell<u32>; OP_KINDS],
        buf_len: u32,
        base: u32,
        len: u32,
        kind: OpKind,
    ) -> bool {
        let n = steps.get() + u64::from(len);
        if u64::from(base) + u64::from(len) > u64::from(buf_len)
            || n > self.env.max_steps
            || self.inv.faulted()
        {
            return false;
        }
        steps.set(n);
        let k = kind as usize;
        ops[k].set(ops[k].get() + len);
        true
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
        let Some(mode) = self.env.interlock_mode else {
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
        let Some(lock) = self.env.interlock else {
            // Interlock by ownership (`PassEnv::interlock`): this pixel's fragments run one
            // at a time in API order, so the section is free and this is its turn.
            self.inv.in_interlock.set(true);
            self.inv.entered_interlock.set(true);
            return;
        };
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
        let Some(mode) = self.env.interlock_mode else {
            return;
        };
        if !self.inv.in_interlock.get() {
            self.inv.set_fault(FaultKind::Misuse {
                message: "interlock_end outside the critical section".into(),
            });
            return Halt.await;
        }
        // Interlock by ownership holds no lock to leave.
        if let Some(lock) = self.env.interlock {
            if self.env.mode == Mode::Scheduled {
                self.step(StepKind::InterlockEnd).await;
            }
            if let Some((_, _, claim)) = self.claim() {
                lock.leave_claim(mode, &claim);
            }
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

impl sealed::Sealed for Frag<'_> {}

impl Fragment for Frag<'_> {
    getters!();
    word_accesses!(access_value, access_unit);

    #[inline(always)]
    fn atomic_compare_exchange<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>> {
        Frag::atomic_compare_exchange(self, buf, index, expected, new)
    }
    #[inline(always)]
    fn atomic_compare_exchange_weak<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>> {
        Frag::atomic_compare_exchange_weak(self, buf, index, expected, new)
    }
    #[inline(always)]
    fn load_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        out: &mut [T],
    ) -> impl Future<Output = ()> {
        Frag::load_record(self, buf, base, out)
    }
    #[inline(always)]
    fn store_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        values: &[T],
    ) -> impl Future<Output = ()> {
        Frag::store_record(self, buf, base, values)
    }
    #[inline(always)]
    fn yield_now(&self) -> impl Future<Output = ()> {
        Frag::yield_now(self)
    }
}

impl<'a> Frag<'a> {
    /// The general context behind either context (for what they share).
    #[inline(always)]
    fn as_frag(&self) -> &Frag<'a> {
        self
    }
    #[inline(always)]
    fn set_discarded(&self) {
        Frag::discard(self)
    }
    #[inline(always)]
    fn set_depth_out(&self, z: f32) {
        Frag::write_depth(self, z)
    }
}
