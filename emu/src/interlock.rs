//! Pixel interlock (fragment shader interlock / rasterizer-ordered views): a per-pixel
//! critical section, entered either in API order (`ordered`) or in any order
//! (`unordered`).
//!
//! The protocol is made of atomics from [`crate::sync`] so that loom checks it:
//! - unordered: one lock word per pixel, taken with compare-exchange (acquire) and
//!   released with a store (release);
//! - ordered: one "now serving" word per pixel. Each fragment that reaches the shader has a
//!   ticket, its rank among the pixel's shaded fragments in API order (the rasterizer knows
//!   it). A fragment enters when `serving == ticket` and leaves by storing `ticket + 1`; a
//!   fragment that never enters must still pass its turn on, or its successors would wait
//!   forever (hardware does the same).
//!
//! This module knows nothing of executors: waiting is the caller's business (an executor
//! suspends the invocation and runs others).

use crate::sync::{AtomicU32, Ordering};

/// The flavour of critical section a kernel asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct InterlockMode {
    /// Enter in API (primitive) order (`pixel_interlock_ordered`); otherwise any order.
    pub ordered: bool,
}

impl InterlockMode {
    pub const ORDERED: InterlockMode = InterlockMode { ordered: true };
    pub const UNORDERED: InterlockMode = InterlockMode { ordered: false };
}

/// Per-pixel interlock state of one pass.
pub struct Interlock {
    width: u32,
    words: Box<[AtomicU32]>,
}

impl Interlock {
    pub fn new(width: u32, height: u32) -> Interlock {
        let n = width as usize * height as usize;
        Interlock {
            width,
            words: (0..n).map(|_| AtomicU32::new(0)).collect(),
        }
    }

    /// Frees every lock and restarts every pixel's turns at ticket 0.
    pub fn reset(&self) {
        for w in self.words.iter() {
            w.store(0, Ordering::Relaxed);
        }
    }

    /// The lock word of a pixel.
    pub fn key(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }

    /// Tries to enter; true on success (the caller is then inside).
    pub fn try_enter(&self, mode: InterlockMode, key: usize, ticket: u32) -> bool {
        let w = &self.words[key];
        if mode.ordered {
            w.load(Ordering::Acquire) == ticket
        } else {
            w.compare_exchange(0, 1, Ordering::Acquire, Ordering::Relaxed)
                .is_ok()
        }
    }

    /// Whether [`Interlock::try_enter`] would succeed now (no side effect).
    pub fn can_enter(&self, mode: InterlockMode, key: usize, ticket: u32) -> bool {
        let v = self.words[key].load(Ordering::Relaxed);
        if mode.ordered {
            v == ticket
        } else {
            v == 0
        }
    }

    /// Leaves the critical section.
    pub fn leave(&self, mode: InterlockMode, key: usize, ticket: u32) {
        let w = &self.words[key];
        if mode.ordered {
            w.store(ticket + 1, Ordering::Release);
        } else {
            w.store(0, Ordering::Release);
        }
    }

    /// Ordered mode: whether it is `ticket`'s turn.
    pub fn is_turn(&self, key: usize, ticket: u32) -> bool {
        self.words[key].load(Ordering::Acquire) == ticket
    }

    /// Ordered mode: a fragment that did not enter hands the turn to its successor.
    pub fn pass_turn(&self, key: usize, ticket: u32) {
        self.words[key].store(ticket + 1, Ordering::Release);
    }
}
