//! The reads of an address since its last write, for the hazard detector.

use super::Access;

/// The reads of an address since its last write, one per invocation (its latest), in the
/// order they were made: the first in the address's state itself, the others on the heap
/// (most addresses have one reader at a time, and a read then touches no other cache line:
/// pushing onto a vector of its own was a sixth of the detector's time in a `kb-interlock`
/// campaign).
#[derive(Default)]
pub(super) struct Reads {
    pub(super) first: Option<Access>,
    pub(super) rest: Vec<Access>,
}

impl Reads {
    #[inline]
    pub(super) fn clear(&mut self) {
        self.first = None;
        self.rest.clear();
    }

    /// Drops `me.seq`'s earlier read, if any, and adds `me` last.
    #[inline]
    pub(super) fn replace(&mut self, me: Access) {
        if self.rest.is_empty() {
            // (The common case: at most one reader so far.)
            match self.first {
                Some(r) if r.seq != me.seq => self.rest.push(me),
                _ => self.first = Some(me),
            }
            return;
        }
        if self.first.is_some_and(|r| r.seq == me.seq) {
            self.first = None;
        }
        if !self.rest.is_empty() {
            self.rest.retain(|r| r.seq != me.seq);
            if self.first.is_none() && !self.rest.is_empty() {
                self.first = Some(self.rest.remove(0));
            }
        }
        if self.first.is_none() {
            self.first = Some(me);
        } else {
            self.rest.push(me);
        }
    }
}
