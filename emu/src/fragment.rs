//! [`Fragment`]: what a kernel sees of its invocation, and the two contexts that provide it.
//!
//! A kernel is generic over its context (`async fn shade(&self, f: impl Fragment)`), so
//! that each executor runs it with the context that fits:
//!
//! - [`Frag`] serves every executor. An access may suspend the invocation (the scheduled
//!   executor before every access, lockstep lanes after their turn, interlock waits), so its
//!   future can carry the request until it is performed.
//! - [`DirectFrag`] serves the fused path of the direct executors (`ordered`, and
//!   `parallel` without lockstep), where an access is performed when it is made and never
//!   suspends. Its futures are values already computed ([`Performed`]), so once the compiler
//!   inlines the kernel, its state machine folds away into the executor's loop: the `count`
//!   kernel went from about 84 instructions per fragment through [`Frag`] to a handful
//!   (docs/performance.md).
//!
//! Both perform an access the same way (`Frag::perform_counted`: bounds check, watchdog
//! step, operation counter, the operation), so a kernel computes the same thing under
//! either; the differential oracle checks that on every algorithm. They differ in where the
//! fragment's state lives: [`Frag`] reads and writes the invocation's slot, [`DirectFrag`] a
//! `DirectState` that the executor keeps in a local, so that it stays in registers.
//!
//! The trait is sealed: kernels use it, only this crate implements it.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use crate::framebuffer::Image;
use crate::kernel::{DirectState, Frag, FragView, Route};
use crate::memory::{Buf, MemOp, Word};

mod sealed {
    pub trait Sealed {}
    impl Sealed for super::Frag<'_> {}
    impl Sealed for super::DirectFrag<'_> {}
}

/// What a kernel invocation sees: its fragment, its outputs, and shared memory. Every
/// shared-memory access returns a future to await at once: a point where, under some
/// executors, another invocation runs.
pub trait Fragment: Copy + sealed::Sealed {
    /// Pixel column (0 = left).
    fn x(&self) -> u32;
    /// Pixel row (0 = top).
    fn y(&self) -> u32;
    /// `y * width + x`: the index of this pixel in a row-major per-pixel buffer.
    fn pixel_index(&self) -> u32;
    fn width(&self) -> u32;
    fn height(&self) -> u32;
    /// Samples per pixel of the pass.
    fn samples(&self) -> u32;
    /// Triangle index within the draw (GL's `gl_PrimitiveID`); 0 in full-screen passes.
    fn primitive_id(&self) -> u32;
    fn instance_id(&self) -> u32;
    fn front_facing(&self) -> bool;
    /// Window depth in \[0, 1\] at the pixel centre (`gl_FragCoord.z`).
    fn depth(&self) -> f32;
    /// Covered samples (bit s = sample s).
    fn coverage(&self) -> u8;
    /// Position of this invocation in API order within the pass.
    fn invocation_id(&self) -> u64;
    /// Perspective-correct barycentrics at the pixel centre; `[1/3; 3]` in full-screen passes.
    fn barycentrics(&self) -> [f32; 3];
    /// Depth at sample `s` of this pixel (the centre depth in full-screen passes).
    fn sample_depth(&self, s: u32) -> f32;
    /// Writes colour output `target` as floats (float and RGBA8 targets).
    fn output(&self, target: usize, value: [f32; 4]);
    /// Writes colour output `target` as unsigned integers (R32UI, RGBA32UI targets).
    fn output_u32(&self, target: usize, value: [u32; 4]);
    /// Discards the fragment: no colour, depth or stencil write after the shader (memory
    /// writes already made stay, as on a GPU).
    fn discard(&self);
    /// Replaces the fragment's depth for the late depth test (`gl_FragDepth`).
    fn write_depth(&self, z: f32);
    /// A read-only image from an earlier pass (not shared memory: no step).
    fn texel(&self, image: &Image, x: u32, y: u32, sample: u32) -> [u32; 4];

    /// Plain load (no atomicity, no ordering: as a GLSL load from a buffer).
    fn load<T: Word>(&self, buf: Buf<T>, index: u32) -> impl Future<Output = T>;
    /// Plain store.
    fn store<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = ()>;
    /// Atomic load (acquire).
    fn atomic_load<T: Word>(&self, buf: Buf<T>, index: u32) -> impl Future<Output = T>;
    /// Atomic store (release).
    fn atomic_store<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = ()>;
    /// Atomic add; returns the previous value (wrapping for integers).
    fn atomic_add<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic subtract; returns the previous value.
    fn atomic_sub<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic minimum (as `T`: signed for i32, float order for f32); returns the previous value.
    fn atomic_min<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic maximum; returns the previous value.
    fn atomic_max<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic bitwise and; returns the previous value.
    fn atomic_and<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic bitwise or; returns the previous value.
    fn atomic_or<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic bitwise xor; returns the previous value.
    fn atomic_xor<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> impl Future<Output = T>;
    /// Atomic exchange; returns the previous value.
    fn atomic_exchange<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        value: T,
    ) -> impl Future<Output = T>;
    /// Atomic compare-exchange: `Ok(previous)` if the word held `expected` and now holds
    /// `new`, `Err(current)` otherwise (bitwise comparison, as GLSL's `atomicCompSwap`).
    fn atomic_compare_exchange<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>>;
    /// Weak compare-exchange: may fail spuriously (`ExecConfig::spurious_cas_per_mille`;
    /// the decision hashes the invocation and its step count, so a schedule replays
    /// exactly). Loops written for weak CAS must retry.
    fn atomic_compare_exchange_weak<T: Word>(
        &self,
        buf: Buf<T>,
        index: u32,
        expected: T,
        new: T,
    ) -> impl Future<Output = Result<T, T>>;
    /// Loads a multi-word record `buf[base .. base + out.len()]` with plain loads, one step
    /// per word. The hazard detector reports it *torn* if another invocation writes any of
    /// its words between the first and the last load.
    fn load_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        out: &mut [T],
    ) -> impl Future<Output = ()>;
    /// Stores a multi-word record with plain stores, one step per word.
    fn store_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        values: &[T],
    ) -> impl Future<Output = ()>;
    /// A scheduling point with no memory access (in spin loops: lets others run and counts
    /// towards the watchdog).
    fn yield_now(&self) -> impl Future<Output = ()>;
    /// Enters the per-pixel critical section declared in `KernelInfo::interlock`
    /// (`beginInvocationInterlockARB`). Ordered mode enters in API order.
    fn interlock_begin(&self) -> impl Future<Output = ()>;
    /// Leaves the critical section (`endInvocationInterlockARB`).
    fn interlock_end(&self) -> impl Future<Output = ()>;
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

/// The context of the fused path of the direct executors: every access is performed when
/// it is made and never suspends (see the module docs). The fragment's input, step count,
/// discard flag, depth output and operation counters are a `DirectState` (crate-private)
/// the executor keeps in a local (in registers, once the kernel is inlined); colour outputs
/// and faults go to the invocation's slot, as under [`Frag`].
#[derive(Clone, Copy)]
pub struct DirectFrag<'a> {
    frag: Frag<'a>,
    state: &'a DirectState<'a>,
}

/// An access already performed: its outcome (`Pending` when the invocation faulted; the
/// executor then drops it).
#[must_use = "a memory access is awaited at once"]
pub struct Performed<T>(Poll<T>);

impl<T: Copy> Future for Performed<T> {
    type Output = T;
    #[inline(always)]
    fn poll(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<T> {
        self.0
    }
}

impl<'a> DirectFrag<'a> {
    /// The context of the invocation in `frag`'s slot, whose per-fragment state is `state`.
    #[inline(always)]
    pub(crate) fn new(frag: Frag<'a>, state: &'a DirectState<'a>) -> Self {
        DirectFrag { frag, state }
    }
    #[inline(always)]
    fn as_frag(&self) -> &Frag<'a> {
        &self.frag
    }
    #[inline(always)]
    fn view(&self) -> FragView<'a> {
        FragView {
            input: self.state.input.get(),
            env: self.frag.env,
        }
    }
    #[inline(always)]
    fn set_discarded(&self) {
        self.state.discarded.set(true);
    }
    #[inline(always)]
    fn set_depth_out(&self, z: f32) {
        self.state.depth_out.set(Some(z));
    }
    #[inline(always)]
    fn perform<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Poll<T> {
        let st = self.state;
        // The fused path never keeps the contention table (`shade_direct` checks).
        self.frag
            .perform_counted::<T>(&st.steps, &st.ops, Route::Cached(&st.words), buf, index, op)
    }
    #[inline(always)]
    fn op<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Performed<T> {
        Performed(self.perform::<T>(buf, index, op))
    }
    #[inline(always)]
    fn unit<T: Word>(&self, buf: Buf<T>, index: u32, op: MemOp) -> Performed<()> {
        Performed(self.perform::<T>(buf, index, op).map(|_| ()))
    }
}

impl Fragment for DirectFrag<'_> {
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
        Performed(self.perform::<T>(buf, index, op).map(|prev: T| {
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
        if crate::kernel::spurious_cas_failure(
            self.frag.env,
            self.state.input.get().seq,
            self.state.steps.get(),
        ) {
            // A failed attempt reads the word, as a real failed CAS does.
            return Performed(self.perform::<T>(buf, index, MemOp::AtomicLoad).map(Err));
        }
        let op = MemOp::CompareExchange(expected.to_bits(), new.to_bits());
        Performed(self.perform::<T>(buf, index, op).map(|prev: T| {
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
        Performed(done)
    }
    #[inline(always)]
    fn store_record<T: Word>(
        &self,
        buf: Buf<T>,
        base: u32,
        values: &[T],
    ) -> impl Future<Output = ()> {
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
        Performed(done)
    }
    #[inline(always)]
    fn yield_now(&self) -> impl Future<Output = ()> {
        Performed(self.frag.count_step(&self.state.steps))
    }
}
