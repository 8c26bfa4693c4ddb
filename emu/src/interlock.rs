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
//! - per-sample scope: the same, on one word per (pixel, sample); a fragment claims the
//!   samples it covers (so fragments conflict only where their coverage overlaps, as with
//!   `sample_interlock_ordered`), with a ticket per sample. Unordered claims take every
//!   covered sample's lock or none (release and retry), so claims never deadlock.
//!
//! - per-sample scope: the same on one word per (pixel, sample); a fragment claims the
//!   samples it covers, so fragments conflict only where their coverage overlaps (as
//!   `sample_interlock_*`), with one ticket per sample. An unordered claim takes every
//!   covered sample's lock or none (release and retry), so claims never deadlock.
//!
//! This module knows nothing of executors: waiting is the caller's business (an executor
//! suspends the invocation and runs others).

use crate::sync::{AtomicU32, Ordering};

/// The flavour of critical section a kernel asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct InterlockMode {
    /// Enter in API (primitive) order (`pixel_interlock_ordered`); otherwise any order.
    pub ordered: bool,
    /// Critical sections per sample (`sample_interlock_*`) rather than per pixel.
    #[serde(default)]
    pub per_sample: bool,
}

impl InterlockMode {
    pub const ORDERED: InterlockMode = InterlockMode {
        ordered: true,
        per_sample: false,
    };
    pub const UNORDERED: InterlockMode = InterlockMode {
        ordered: false,
        per_sample: false,
    };
    pub const SAMPLE_ORDERED: InterlockMode = InterlockMode {
        ordered: true,
        per_sample: true,
    };
    pub const SAMPLE_UNORDERED: InterlockMode = InterlockMode {
        ordered: false,
        per_sample: true,
    };
}

/// The lock words (and tickets) one fragment claims.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Claim {
    pub keys: [usize; 8],
    pub tickets: [u32; 8],
    pub n: usize,
}

impl Claim {
    fn iter(&self) -> impl Iterator<Item = (usize, u32)> + '_ {
        self.keys[..self.n]
            .iter()
            .copied()
            .zip(self.tickets[..self.n].iter().copied())
    }
}

/// Per-pixel (or per-sample) interlock state of one pass.
pub struct Interlock {
    width: u32,
    samples: u32,
    words: Box<[AtomicU32]>,
}

impl Interlock {
    /// Per-pixel interlock (one word per pixel).
    pub fn new(width: u32, height: u32) -> Interlock {
        Interlock::with_samples(width, height, 1)
    }

    /// One word per (pixel, sample).
    pub fn with_samples(width: u32, height: u32, samples: u32) -> Interlock {
        let samples = samples.max(1);
        let n = width as usize * height as usize * samples as usize;
        Interlock {
            width,
            samples,
            words: (0..n).map(|_| AtomicU32::new(0)).collect(),
        }
    }

    /// What a fragment at (x, y) with `coverage` claims. Per pixel: the pixel's word with
    /// `tickets[0]`; per sample: each covered sample's word with its ticket.
    pub fn claim(
        &self,
        mode: InterlockMode,
        x: u32,
        y: u32,
        coverage: u8,
        tickets: [u32; 8],
    ) -> Claim {
        let pixel = self.key(x, y);
        let mut c = Claim {
            keys: [0; 8],
            tickets: [0; 8],
            n: 0,
        };
        if mode.per_sample && self.samples > 1 {
            for (s, &ticket) in tickets
                .iter()
                .enumerate()
                .take(self.samples.min(8) as usize)
            {
                if coverage & (1 << s) != 0 {
                    c.keys[c.n] = pixel * self.samples as usize + s;
                    c.tickets[c.n] = ticket;
                    c.n += 1;
                }
            }
        } else {
            c.keys[0] = pixel * self.samples as usize;
            c.tickets[0] = tickets[0];
            c.n = 1;
        }
        c
    }

    /// Tries to enter with a whole claim (all words or none).
    pub fn try_enter_claim(&self, mode: InterlockMode, c: &Claim) -> bool {
        if mode.ordered {
            return c
                .iter()
                .all(|(k, t)| self.words[k].load(Ordering::Acquire) == t);
        }
        for (i, (k, _)) in c.iter().enumerate() {
            if self.words[k]
                .compare_exchange(0, 1, Ordering::Acquire, Ordering::Relaxed)
                .is_err()
            {
                for (k, _) in c.iter().take(i) {
                    self.words[k].store(0, Ordering::Release);
                }
                return false;
            }
        }
        true
    }

    /// Whether [`Interlock::try_enter_claim`] would succeed now.
    pub fn can_enter_claim(&self, mode: InterlockMode, c: &Claim) -> bool {
        c.iter().all(|(k, t)| self.can_enter(mode, k, t))
    }

    /// Leaves with a whole claim.
    pub fn leave_claim(&self, mode: InterlockMode, c: &Claim) {
        for (k, t) in c.iter() {
            self.leave(mode, k, t);
        }
    }

    /// Ordered: whether it is the claim's turn on every word.
    pub fn is_turn_claim(&self, c: &Claim) -> bool {
        c.iter().all(|(k, t)| self.is_turn(k, t))
    }

    /// Ordered: a fragment that did not enter hands every turn on.
    pub fn pass_turn_claim(&self, c: &Claim) {
        for (k, t) in c.iter() {
            self.pass_turn(k, t);
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
