//! An invocation's mutable state: its executor slot ([`Invocation`]) and the fused path's
//! register-resident copy of what every fragment touches ([`DirectState`]).

use std::cell::{Cell, RefCell};

use super::StepKind;
use crate::kernel::{FaultKind, FragInput};
use crate::memory::{BlockArray, Memory, OpKind, PixelArray, WordCache};

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
    /// Scheduled executor: the last compare-exchange performed failed (wrote nothing), for
    /// the hazard detector, which counts it as an atomic load.
    pub cas_failed: Cell<bool>,
    /// Scheduled executor: what the last memory access performed read (the word's bits
    /// before it; the loaded value of a load, the compared one of a compare-exchange), for
    /// the hazard detector.
    pub read: Cell<u64>,
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
    /// The kernel's own per-pixel and per-block arrays when this worker owns the tile for
    /// the pass ([`DirectState::owning`]): their atomics at the fragment's slot are plain.
    pub own: OwnArrays,
}

/// The kernel's own arrays as an access tests them: a compare of the buffer id for each
/// (`NONE` when the kernel declared none), and what the slot's first word is computed from.
/// Plain fields rather than two `Option`s of the declarations, so that an access that is
/// not to an own array costs two compares, and the blocks a row holds are divided out once.
#[derive(Clone, Copy)]
pub(crate) struct OwnArrays {
    pub pixel_buffer: u32,
    pub pixel_stride: u32,
    pub block_buffer: u32,
    pub block_shift: u32,
    pub block_stride: u32,
    /// Blocks in a row of the frame.
    pub blocks_across: u32,
}

impl OwnArrays {
    /// No buffer has this id (ids index the device's buffers).
    pub const NONE: u32 = u32::MAX;

    /// No own array.
    pub const fn none() -> OwnArrays {
        OwnArrays {
            pixel_buffer: Self::NONE,
            pixel_stride: 0,
            block_buffer: Self::NONE,
            block_shift: 0,
            block_stride: 0,
            blocks_across: 0,
        }
    }

    /// The declarations, for a frame `width` pixels wide.
    pub fn new(pixel: Option<PixelArray>, block: Option<BlockArray>, width: u32) -> OwnArrays {
        let mut o = OwnArrays::none();
        if let Some(p) = pixel {
            o.pixel_buffer = p.buffer;
            o.pixel_stride = p.stride;
        }
        if let Some(b) = block {
            o.block_buffer = b.buffer;
            o.block_shift = b.shift.min(31);
            o.block_stride = b.stride;
            o.blocks_across = width.div_ceil(1 << o.block_shift);
        }
        o
    }

    /// The first word of pixel `(x, y)`'s slot of the per-block array: what
    /// [`BlockArray::first_word`] computes.
    #[inline(always)]
    pub fn block_first_word(&self, x: u32, y: u32) -> u64 {
        (u64::from(y >> self.block_shift) * u64::from(self.blocks_across)
            + u64::from(x >> self.block_shift))
            * u64::from(self.block_stride)
    }
}

impl<'m> DirectState<'m> {
    /// The state of a pass over `memory`.
    #[inline(always)]
    pub fn new(memory: &'m Memory) -> Self {
        DirectState {
            input: Cell::new(FragInput::default()),
            steps: Cell::new(0),
            discarded: Cell::new(false),
            depth_out: Cell::new(None),
            ops: Default::default(),
            words: WordCache::new(memory),
            own: OwnArrays::none(),
        }
    }

    /// [`DirectState::new`] for a worker that owns its tiles for the whole pass and shades
    /// one fragment at a time: `array` is the kernel's per-pixel array if it declared it its
    /// pixels' own (`KernelInfo::with_own_pixel_array`). Only that worker then reaches a
    /// slot of its tile during the pass, so an operation on it needs no atomic instruction.
    #[inline(always)]
    pub fn owning(
        memory: &'m Memory,
        array: Option<PixelArray>,
        block: Option<BlockArray>,
        width: u32,
    ) -> Self {
        let mut state = Self::new(memory);
        state.own = OwnArrays::new(array, block, width);
        state
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
            cas_failed: Cell::new(false),
            read: Cell::new(0),
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

    /// Forgets the critical section of the slot's previous fragment: the fused path keeps
    /// one slot for all its fragments and resets only their state (`DirectState`), so a
    /// pass under interlock by ownership calls this before each fragment.
    #[inline(always)]
    pub fn reset_interlock(&self) {
        self.in_interlock.set(false);
        self.entered_interlock.set(false);
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
    pub(super) fn take_turn(&self, yield_every: u32) -> bool {
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
    pub(super) fn resume_turn(&self) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_block_slots_are_the_declarations_first_words() {
        for (shift, stride, width) in [
            (5, 16, 2048),
            (0, 1, 7),
            (3, 2, 33),
            (31, 4, 100),
            (40, 1, 9),
        ] {
            let decl = BlockArray {
                buffer: 3,
                shift,
                stride,
            };
            let own = OwnArrays::new(None, Some(decl), width);
            assert_eq!(own.pixel_buffer, OwnArrays::NONE);
            assert_eq!(own.block_buffer, 3);
            for y in [0, 1, 31, 32, 95, 4000] {
                for x in [0, 1, width / 2, width - 1] {
                    assert_eq!(
                        own.block_first_word(x, y),
                        decl.first_word(x, y, width),
                        "shift {shift} width {width} at ({x}, {y})"
                    );
                }
            }
        }
    }
}
