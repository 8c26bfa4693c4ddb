//! [`Fragment`]: what a kernel sees of its invocation (part of the kernel API, with
//! [`crate::kernel`]).
//!
//! A kernel is generic over its context (`async fn shade(&self, f: impl Fragment)`), so
//! that each executor runs it with the context that fits: [`crate::Frag`] under every
//! executor (an access may suspend the invocation), [`crate::DirectFrag`] on the fused path
//! of the direct executors (an access never suspends). Both are
//! [`crate::invocation`]'s; this module knows neither.
//!
//! The trait is sealed: kernels use it, only this crate implements it.

use std::future::Future;

use crate::framebuffer::Image;
use crate::memory::{Buf, Word};

/// The seal: only this crate's contexts implement [`Fragment`].
pub(crate) mod sealed {
    pub trait Sealed {}
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
    /// A hint that the kernel will soon read the words `words` of `buf`: on the fused path
    /// of the direct executors their cache lines are requested now (a range past the
    /// buffer's end is cut to it; a buffer past the first 32, or of 64-bit words, is not
    /// prefetched); under the other contexts nothing happens. It is not an access: no step,
    /// no operation count, nothing the hazard detector sees, never a fault, no value
    /// changes. For words a kernel will reach by following links, whose loads wait one on
    /// another (a linked list's nodes), so that their misses overlap instead.
    #[inline(always)]
    fn prefetch<T: Word>(&self, buf: Buf<T>, words: std::ops::Range<u32>) {
        let _ = (buf, words);
    }
}
