//! An invocation's latest load per address, for the hazard detector's lost-update rule.

use super::Load;
use crate::memory::Addr;

/// An invocation's latest load per address: a short list while it has loaded at most
/// [`LIST_MAX`] addresses (most invocations: a scan of a few entries is cheaper than
/// hashing), then an open-addressing table (linear probing, power-of-two capacity) with a
/// generation per entry, so that forgetting them all when the invocation finishes costs one
/// increment. A kernel that loads many words (a k-buffer's slots, a record at a time) made
/// the scan of one list of them, at every access, an eighth of the detector's time in a
/// `kb-interlock` campaign.
pub(super) struct Loads {
    /// The loads while there are at most [`LIST_MAX`] (and `len == 0`).
    list: Vec<Load>,
    /// The loads past that (all of them: the list is moved in).
    entries: Vec<Entry>,
    gen: u32,
    /// Live entries of the table.
    len: usize,
}

/// Addresses an invocation's loads are kept in a list for.
const LIST_MAX: usize = 8;

/// A load and the generation it was made in (live iff it is the table's).
#[derive(Clone, Copy)]
struct Entry {
    load: Load,
    gen: u32,
}

const EMPTY: Entry = Entry {
    load: Load {
        addr: Addr(0),
        step: 0,
        value: 0,
        plain: false,
    },
    gen: 0,
};

impl Default for Loads {
    fn default() -> Loads {
        Loads {
            list: Vec::new(),
            entries: Vec::new(),
            gen: 1,
            len: 0,
        }
    }
}

impl Loads {
    #[inline]
    pub(super) fn is_empty(&self) -> bool {
        self.len == 0 && self.list.is_empty()
    }

    /// Forgets every load.
    #[inline]
    pub(super) fn clear(&mut self) {
        self.list.clear();
        if self.len == 0 {
            return;
        }
        self.len = 0;
        self.gen = self.gen.wrapping_add(1);
        if self.gen == 0 {
            // Generations wrapped: stale entries could look live again.
            self.entries.fill(EMPTY);
            self.gen = 1;
        }
    }

    #[inline]
    fn home(&self, addr: Addr) -> usize {
        // Fibonacci hashing, as the detector's address table.
        let bits = self.entries.len().trailing_zeros();
        (addr.0.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize
    }

    /// The latest load of `addr`, if any.
    #[inline]
    pub(super) fn get(&self, addr: Addr) -> Option<&Load> {
        if self.len == 0 {
            return self.list.iter().find(|l| l.addr == addr);
        }
        self.get_hashed(addr)
    }

    /// [`Loads::get`] from the table (out of line: the list is the common case, and the
    /// detector's hot loop keeps its registers for it).
    #[inline(never)]
    fn get_hashed(&self, addr: Addr) -> Option<&Load> {
        let mask = self.entries.len() - 1;
        let mut i = self.home(addr);
        loop {
            let e = &self.entries[i];
            if e.gen != self.gen {
                return None;
            }
            if e.load.addr == addr {
                return Some(&e.load);
            }
            i = (i + 1) & mask;
        }
    }

    /// Records `load` as the latest of its address (replacing the earlier one).
    #[inline]
    pub(super) fn set(&mut self, load: Load) {
        if self.len == 0 {
            if let Some(l) = self.list.iter_mut().find(|l| l.addr == load.addr) {
                *l = load;
            } else if self.list.len() < LIST_MAX {
                self.list.push(load);
            } else {
                self.spill();
                self.set_hashed(load);
            }
            return;
        }
        self.set_hashed(load);
    }

    /// Moves the full list into the table.
    #[cold]
    fn spill(&mut self) {
        let list = std::mem::take(&mut self.list);
        // (`len` is 0: the table holds nothing live.)
        if self.entries.len() < 4 * LIST_MAX {
            self.entries = vec![EMPTY; 4 * LIST_MAX];
            self.gen = 1;
        }
        for &l in &list {
            self.set_hashed(l);
        }
        self.list = list;
        self.list.clear();
    }

    /// [`Loads::set`] into the table (out of line, as [`Loads::get_hashed`]).
    #[inline(never)]
    fn set_hashed(&mut self, load: Load) {
        if (self.len + 1) * 2 > self.entries.len() {
            self.grow();
        }
        let mask = self.entries.len() - 1;
        let mut i = self.home(load.addr);
        loop {
            let e = &mut self.entries[i];
            if e.gen != self.gen {
                *e = Entry {
                    load,
                    gen: self.gen,
                };
                self.len += 1;
                return;
            }
            if e.load.addr == load.addr {
                e.load = load;
                return;
            }
            i = (i + 1) & mask;
        }
    }

    #[cold]
    fn grow(&mut self) {
        let doubled = vec![EMPTY; (self.entries.len() * 2).max(8)];
        let old = std::mem::replace(&mut self.entries, doubled);
        let (gen, mask) = (self.gen, self.entries.len() - 1);
        for e in old.into_iter().filter(|e| e.gen == gen) {
            let mut i = self.home(e.load.addr);
            while self.entries[i].gen == gen {
                i = (i + 1) & mask;
            }
            self.entries[i] = e;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(addr: u64, step: u64) -> Load {
        Load {
            addr: Addr(addr),
            step,
            value: step * 3,
            plain: step.is_multiple_of(2),
        }
    }

    #[test]
    fn keeps_the_latest_load_of_each_address_until_cleared() {
        let mut t = Loads::default();
        assert!(t.is_empty() && t.get(Addr(5)).is_none());
        // Enough addresses to grow the table several times, colliding ones among them.
        let addrs: Vec<u64> = (0..300u64)
            .map(|i| if i % 3 == 0 { i << 32 } else { i * 7 })
            .collect();
        for (n, &a) in addrs.iter().enumerate() {
            t.set(load(a, n as u64));
        }
        for (n, &a) in addrs.iter().enumerate().step_by(2) {
            t.set(load(a, 1000 + n as u64));
        }
        for (n, &a) in addrs.iter().enumerate() {
            let want = if n % 2 == 0 {
                1000 + n as u64
            } else {
                n as u64
            };
            let got = t.get(Addr(a)).expect("loaded");
            assert_eq!((got.addr, got.step, got.value, got.plain), {
                let l = load(a, want);
                (l.addr, l.step, l.value, l.plain)
            });
        }
        assert!(t.get(Addr(1 << 40)).is_none());
        t.clear();
        assert!(t.is_empty());
        assert!(addrs.iter().all(|&a| t.get(Addr(a)).is_none()));
        t.set(load(addrs[3], 9));
        assert_eq!(t.get(Addr(addrs[3])).map(|l| l.step), Some(9));
        assert!(t.get(Addr(addrs[4])).is_none());
    }
}
