//! The detector's address lookup: a fast hasher for addresses and sequence numbers, and an
//! open-addressing table from address to slab index whose generations forget every address
//! between two executions of an exploration in one increment.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Fast multiplicative hasher for addresses and sequence numbers (no DoS concern here).
#[derive(Default, Clone, Copy)]
pub(super) struct AddrHasher(u64);
impl Hasher for AddrHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(5) ^ b as u64).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0 ^ v)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29);
    }
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
}
pub(super) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<AddrHasher>>;

/// Address -> slab index: open addressing (linear probing, power-of-two capacity) with a
/// generation per entry, so that forgetting every address between two executions of an
/// exploration costs one increment, not a pass over the table.
pub(super) struct AddrTable {
    /// (address, slab index, generation); an entry is live if its generation is `gen`.
    entries: Vec<(u64, u32, u32)>,
    gen: u32,
    len: usize,
}

impl AddrTable {
    pub(super) fn new() -> AddrTable {
        AddrTable {
            entries: vec![(0, 0, 0); 16],
            gen: 1,
            len: 0,
        }
    }

    pub(super) fn clear(&mut self) {
        self.len = 0;
        self.gen = self.gen.wrapping_add(1);
        if self.gen == 0 {
            // Generations wrapped: stale entries could look live again.
            self.entries.fill((0, 0, 0));
            self.gen = 1;
        }
    }

    #[inline]
    pub(super) fn home(&self, addr: u64) -> usize {
        // Fibonacci hashing: the high bits of the product mix buffer and index.
        let bits = self.entries.len().trailing_zeros();
        (addr.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize
    }

    /// The slab index of `addr`, inserting `fresh` if it is absent; second: inserted.
    #[inline]
    pub(super) fn get_or_insert(&mut self, addr: u64, fresh: u32) -> (u32, bool) {
        let mask = self.entries.len() - 1;
        let mut i = self.home(addr);
        loop {
            let e = self.entries[i];
            if e.2 != self.gen {
                self.entries[i] = (addr, fresh, self.gen);
                self.len += 1;
                if self.len * 2 > self.entries.len() {
                    self.grow();
                }
                return (fresh, true);
            }
            if e.0 == addr {
                return (e.1, false);
            }
            i = (i + 1) & mask;
        }
    }

    pub(super) fn grow(&mut self) {
        let doubled = vec![(0, 0, 0); self.entries.len() * 2];
        let old = std::mem::replace(&mut self.entries, doubled);
        let (gen, mask) = (self.gen, self.entries.len() - 1);
        for e in old.into_iter().filter(|e| e.2 == gen) {
            let mut i = self.home(e.0);
            while self.entries[i].2 == gen {
                i = (i + 1) & mask;
            }
            self.entries[i] = e;
        }
    }
}
