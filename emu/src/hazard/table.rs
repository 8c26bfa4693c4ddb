//! The detector's address lookup: a fast hasher for addresses and sequence numbers, and an
//! index from address to slab index (direct-mapped per buffer, open addressing past that)
//! whose generations forget every address between two executions of an exploration in one
//! increment.

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

/// Address -> slab index. Indices below [`DENSE_MAX`] are direct-mapped: one
/// (generation, slab index) entry per word of each buffer, so that the addresses a pass
/// touches in order (a resolve reads every pixel's entries, buffer by buffer) are
/// neighbours in the index too, where a hash scattered them over the table (the first
/// probe of each fresh address was a cache miss: a quarter of the detector's time in a
/// `kb-interlock` campaign, docs/performance.md). Larger indices go to an open-addressing
/// table. Both carry a generation per entry, so that forgetting every address between two
/// executions of an exploration costs one increment, not a pass over the index.
pub(super) struct AddrTable {
    /// Per buffer, per word index: (generation, slab index); grown on demand.
    dense: Vec<Vec<(u32, u32)>>,
    /// Entries held by `dense`, over all buffers.
    dense_len: usize,
    /// The addresses past [`DENSE_MAX`].
    sparse: SparseTable,
    gen: u32,
}

/// Word indices below this are direct-mapped (a buffer's dense index then holds at most
/// 32 MiB).
const DENSE_MAX: u32 = 1 << 22;

impl AddrTable {
    pub(super) fn new() -> AddrTable {
        AddrTable {
            dense: Vec::new(),
            dense_len: 0,
            sparse: SparseTable::new(),
            gen: 1,
        }
    }

    /// Forgets every address.
    pub(super) fn clear(&mut self) {
        self.sparse.clear();
        self.gen = self.gen.wrapping_add(1);
        if self.gen == 0 {
            // Generations wrapped: stale entries could look live again.
            for d in &mut self.dense {
                d.fill((0, 0));
            }
            self.gen = 1;
        }
    }

    /// Entries the index holds (what [`AddrTable::clear`] would walk if generations wrap,
    /// and the memory it keeps).
    pub(super) fn retained(&self) -> usize {
        self.dense_len + self.sparse.entries.len()
    }

    /// The slab index of `addr`, inserting `fresh` if it is absent; second: inserted.
    #[inline]
    pub(super) fn get_or_insert(&mut self, addr: u64, fresh: u32) -> (u32, bool) {
        let (buffer, index) = ((addr >> 32) as usize, addr as u32);
        if index >= DENSE_MAX {
            return self.sparse.get_or_insert(addr, fresh);
        }
        let (index, gen) = (index as usize, self.gen);
        if let Some(e) = self.dense.get_mut(buffer).and_then(|d| d.get_mut(index)) {
            if e.0 == gen {
                return (e.1, false);
            }
            *e = (gen, fresh);
            return (fresh, true);
        }
        self.grow(buffer, index);
        self.dense[buffer][index] = (gen, fresh);
        (fresh, true)
    }

    /// Makes room for `index` in `buffer`'s dense index.
    #[cold]
    fn grow(&mut self, buffer: usize, index: usize) {
        if buffer >= self.dense.len() {
            self.dense.resize_with(buffer + 1, Vec::new);
        }
        let d = &mut self.dense[buffer];
        let len = (index + 1).next_power_of_two().max(64);
        self.dense_len += len - d.len();
        d.resize(len, (0, 0));
    }
}

/// Address -> slab index for word indices past [`DENSE_MAX`]: open addressing (linear
/// probing, power-of-two capacity) with a generation per entry.
struct SparseTable {
    /// (address, slab index, generation); an entry is live if its generation is `gen`.
    entries: Vec<(u64, u32, u32)>,
    gen: u32,
    len: usize,
}

impl SparseTable {
    fn new() -> SparseTable {
        SparseTable {
            entries: vec![(0, 0, 0); 16],
            gen: 1,
            len: 0,
        }
    }

    fn clear(&mut self) {
        self.len = 0;
        self.gen = self.gen.wrapping_add(1);
        if self.gen == 0 {
            // Generations wrapped: stale entries could look live again.
            self.entries.fill((0, 0, 0));
            self.gen = 1;
        }
    }

    #[inline]
    fn home(&self, addr: u64) -> usize {
        // Fibonacci hashing: the high bits of the product mix buffer and index.
        let bits = self.entries.len().trailing_zeros();
        (addr.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize
    }

    fn get_or_insert(&mut self, addr: u64, fresh: u32) -> (u32, bool) {
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

    fn grow(&mut self) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_and_sparse_addresses_map_to_what_was_inserted_until_cleared() {
        let mut t = AddrTable::new();
        let addrs = [
            0u64,
            1,
            63,
            64,
            (3u64 << 32) | 5,
            (1u64 << 32) | u64::from(DENSE_MAX - 1),
            (1u64 << 32) | u64::from(DENSE_MAX),
            (2u64 << 32) | 0xffff_ffff,
        ];
        for (n, &a) in addrs.iter().enumerate() {
            assert_eq!(t.get_or_insert(a, n as u32), (n as u32, true));
        }
        for (n, &a) in addrs.iter().enumerate() {
            assert_eq!(t.get_or_insert(a, 99), (n as u32, false));
        }
        t.clear();
        for (n, &a) in addrs.iter().enumerate().rev() {
            assert_eq!(t.get_or_insert(a, 7 + n as u32), (7 + n as u32, true));
        }
    }
}
