//! Which screen blocks the geometry passes of a device have rasterized fragments in: a
//! GPU's coarse coverage mask (as a hierarchical stencil or a "tile touched" bit), so that
//! a full-screen pass whose kernel declares what it does on a pixel no geometry reached
//! ([`KernelInfo::untouched_output`]) writes that output there without running its kernel.
//! A resolve's empty pixels, most of a frame, then cost a texel write.
//!
//! The mask is conservative: a block is marked when the rasterizer produced a covered run in
//! it, before any test or sample mask, so a marked block may hold no shaded fragment, but an
//! unmarked one surely holds none. Geometry passes mark on every path (the fused path its
//! covered runs, the general path of the scheduled executor, interlock and contention
//! counting each rasterized fragment's block), and full-screen passes skip on both. Explicit
//! invocations, which reach pixels the rasterizer did not, make the mask unknown for the
//! rest of the device's life, and then no pass skips anything. This module knows no
//! algorithm.
//!
//! [`KernelInfo::untouched_output`]: crate::kernel::KernelInfo::untouched_output

use crate::sync::{Arc, AtomicU32, Ordering};

/// log2 of a block's side in pixels (8 x 8 blocks). On the 871K dragon at 512 x 512, 20.1 %
/// of the pixels are covered and 23.7 % of the 8 x 8 blocks touched (21.6 % of 4 x 4
/// blocks); at 2048 x 2048, 20.1 % and 21.0 % (the bunny: 21.0 % and 21.5 %). A mask of
/// 8 x 8 blocks at 2048 x 2048 is 8 KiB of bits, which stays in the cache while a capture
/// pass marks it.
pub const BLOCK_SHIFT: u32 = 3;

/// One bit per screen block of `2^BLOCK_SHIFT` pixels a side, row-major, set by the threads
/// of geometry passes as they rasterize.
pub struct BlockMask {
    width: u32,
    height: u32,
    /// Blocks per row of blocks.
    across: u32,
    bits: Vec<AtomicU32>,
}

impl BlockMask {
    /// A mask of a `width` x `height` frame with no block touched.
    pub fn new(width: u32, height: u32) -> BlockMask {
        let across = width.div_ceil(1 << BLOCK_SHIFT);
        let down = height.div_ceil(1 << BLOCK_SHIFT);
        let words = (across as usize * down as usize).div_ceil(32);
        BlockMask {
            width,
            height,
            across,
            bits: (0..words).map(|_| AtomicU32::new(0)).collect(),
        }
    }

    /// The frame size this mask covers.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Marks the blocks of the pixels `x0..x1` of row `y` (`x0 < x1 <= width`, `y < height`).
    /// A bit already set is only read, so the threads of a pass share the mask's lines
    /// instead of taking them from each other.
    #[inline(always)]
    pub fn mark_run(&self, y: u32, x0: u32, x1: u32) {
        debug_assert!(x0 < x1 && x1 <= self.width && y < self.height);
        let row = (y >> BLOCK_SHIFT) * self.across;
        for b in (x0 >> BLOCK_SHIFT)..=((x1 - 1) >> BLOCK_SHIFT) {
            let i = row + b;
            let (word, bit) = (&self.bits[(i >> 5) as usize], 1u32 << (i & 31));
            if word.load(Ordering::Relaxed) & bit == 0 {
                word.fetch_or(bit, Ordering::Relaxed);
            }
        }
    }

    /// Whether block (`bx`, `by`) (in blocks) was marked. Read after the marking passes
    /// ended (the pool's join orders their marks before this).
    #[inline(always)]
    pub fn touched(&self, bx: u32, by: u32) -> bool {
        let i = by * self.across + bx;
        self.bits[(i >> 5) as usize].load(Ordering::Relaxed) & (1 << (i & 31)) != 0
    }
}

/// What a device knows of the pixels its geometry passes reached.
#[derive(Default)]
enum State {
    /// No geometry pass and no explicit invocation yet: every pixel untouched.
    #[default]
    Nothing,
    /// The blocks every geometry pass so far marked (all of one frame size).
    Mask(Arc<BlockMask>),
    /// Some pass reached pixels without marking them, or passes of different sizes ran.
    Unknown,
}

/// Whether a device's geometry passes mark the screen blocks they reach
/// ([`Device::with_coverage`](crate::Device::with_coverage)). Marking costs a little in
/// every geometry pass (about 6 % of a `count` frame of the bunny at 2048 x 2048), and pays
/// only when a later full-screen pass declares its output at untouched pixels: a run whose
/// passes include one asks for it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coverage {
    /// Geometry passes mark nothing; after one, no full-screen pass skips a pixel.
    #[default]
    Untracked,
    /// Geometry passes mark their blocks, and a declaring full-screen pass skips the
    /// unmarked ones (under every executor).
    Tracked,
}

/// A device's [`BlockMask`], handed to the passes that mark or read it.
#[derive(Default)]
pub(crate) struct Touched {
    state: crate::sync::pool::Mutex<State>,
    /// Whether geometry passes mark (else the first one makes the mask unknown).
    pub(crate) coverage: Coverage,
}

impl Touched {
    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The mask a geometry pass on a `width` x `height` frame marks; `None` (and the mask
    /// unknown from now on) when coverage is untracked, an earlier pass ran on another size
    /// or the mask is unknown already.
    pub fn for_marking(&self, width: u32, height: u32) -> Option<Arc<BlockMask>> {
        let mut state = self.state();
        if self.coverage == Coverage::Untracked {
            *state = State::Unknown;
            return None;
        }
        match &*state {
            State::Nothing => {
                let mask = Arc::new(BlockMask::new(width, height));
                *state = State::Mask(mask.clone());
                Some(mask)
            }
            State::Mask(m) if m.size() == (width, height) => Some(m.clone()),
            State::Mask(_) | State::Unknown => {
                *state = State::Unknown;
                None
            }
        }
    }

    /// The mask a full-screen pass on a `width` x `height` frame may skip by: `None` when
    /// it is unknown or of another size (the pass then runs every pixel).
    pub fn for_reading(&self, width: u32, height: u32) -> Option<Arc<BlockMask>> {
        match &*self.state() {
            State::Nothing => Some(Arc::new(BlockMask::new(width, height))),
            State::Mask(m) if m.size() == (width, height) => Some(m.clone()),
            State::Mask(_) | State::Unknown => None,
        }
    }

    /// A pass reached pixels without marking them: nothing is skipped from now on.
    pub fn forget(&self) {
        *self.state() = State::Unknown;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_mark_their_blocks_and_no_other() {
        // 20 x 10 pixels: 3 x 2 blocks, the last column and row of blocks partial.
        let m = BlockMask::new(20, 10);
        m.mark_run(9, 7, 9); // blocks (0, 1) and (1, 1)
        m.mark_run(0, 19, 20); // block (2, 0)
        let marked: Vec<(u32, u32)> = (0..2)
            .flat_map(|by| (0..3).map(move |bx| (bx, by)))
            .filter(|&(bx, by)| m.touched(bx, by))
            .collect();
        assert_eq!(marked, [(2, 0), (0, 1), (1, 1)]);
    }

    #[test]
    fn a_pass_of_another_size_or_one_that_forgets_makes_the_mask_unknown() {
        let tracked = || Touched {
            coverage: Coverage::Tracked,
            ..Touched::default()
        };
        let t = tracked();
        assert!(t.for_reading(8, 8).is_some_and(|m| !m.touched(0, 0)));
        let m = t.for_marking(16, 8).unwrap();
        m.mark_run(3, 0, 1);
        assert!(t.for_reading(16, 8).unwrap().touched(0, 0));
        assert!(t.for_reading(8, 8).is_none());
        assert!(t.for_marking(8, 8).is_none());
        assert!(t.for_reading(16, 8).is_none());
        let t = tracked();
        t.for_marking(16, 8);
        t.forget();
        assert!(t.for_reading(16, 8).is_none());
        assert!(t.for_marking(16, 8).is_none());
    }

    #[test]
    fn untracked_coverage_marks_nothing_and_skips_nothing_after_geometry() {
        let t = Touched::default();
        assert!(
            t.for_reading(16, 8).is_some(),
            "no geometry yet: all untouched"
        );
        assert!(t.for_marking(16, 8).is_none());
        assert!(t.for_reading(16, 8).is_none());
    }
}
