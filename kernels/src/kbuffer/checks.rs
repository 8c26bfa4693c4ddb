//! The invariants of k-buffer slots after the passes ([`Shape`]): sorted, no gaps, no
//! duplicates, the expected count.

use super::slots::key_less;
use crate::algo::{CapturedFrag, Check};
use crate::common::{self, EMPTY};

/// The shape of a pixel's slots after the passes, tallied over pixels.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Shape {
    /// Pixels whose occupied slots are not in ascending order.
    pub unsorted: u64,
    /// Pixels with an empty slot before an occupied one.
    pub gaps: u64,
    /// Pixels holding the same `(depth, primitive)` twice (a fragment counted twice).
    pub duplicates: u64,
    /// Pixels whose occupied slots are not `min(k, fragments)` (when counts are known).
    pub wrong_count: u64,
    pub first_bad: Option<usize>,
}

impl Shape {
    /// Tallies `raw` (slots per pixel, in slot order). `by_prim`: slots are ordered by
    /// `(depth, primitive)`; otherwise by depth only (primitives attached afterwards).
    /// `counts`: fragments per pixel, to check that exactly `min(k, n)` slots are occupied.
    pub(super) fn of(
        raw: &[Vec<Option<CapturedFrag>>],
        by_prim: bool,
        counts: Option<&[u32]>,
    ) -> Shape {
        let mut s = Shape::default();
        for (p, slots) in raw.iter().enumerate() {
            let mut bad = false;
            let occupied: Vec<CapturedFrag> = slots.iter().flatten().copied().collect();
            if slots.windows(2).any(|w| w[0].is_none() && w[1].is_some()) {
                s.gaps += 1;
                bad = true;
            }
            let out_of_order = occupied.windows(2).any(|w| {
                if by_prim {
                    key_less(w[1].depth, w[1].prim, w[0].depth, w[0].prim)
                } else {
                    w[1].depth < w[0].depth
                }
            });
            if out_of_order {
                s.unsorted += 1;
                bad = true;
            }
            let mut sorted = occupied.clone();
            sorted.sort_by(common::depth_order);
            if sorted
                .windows(2)
                .any(|w| w[0].depth == w[1].depth && w[0].prim == w[1].prim && w[0].prim != EMPTY)
            {
                s.duplicates += 1;
                bad = true;
            }
            if let Some(c) = counts {
                if occupied.len() != (c[p] as usize).min(slots.len()) {
                    s.wrong_count += 1;
                    bad = true;
                }
            }
            if bad && s.first_bad.is_none() {
                s.first_bad = Some(p);
            }
        }
        s
    }

    pub(super) fn ok(&self) -> bool {
        self.unsorted == 0 && self.gaps == 0 && self.duplicates == 0 && self.wrong_count == 0
    }

    pub(super) fn detail(&self, width: u32) -> String {
        let first = match self.first_bad {
            Some(p) => format!("; first at ({}, {})", p as u32 % width, p as u32 / width),
            None => String::new(),
        };
        format!(
            "pixels unsorted {}, with gaps {}, with a fragment twice {}, with a wrong slot count {}{first}",
            self.unsorted, self.gaps, self.duplicates, self.wrong_count
        )
    }

    /// The check "slots sorted, no gaps, no fragment twice (and min(k, n) occupied)".
    pub(super) fn check(&self, width: u32, counted: bool) -> Check {
        let name = if counted {
            "slots sorted ascending, empties last, no fragment twice, min(k, n) occupied"
        } else {
            "slots sorted ascending, empties last, no fragment twice"
        };
        Check::new(name, self.ok(), self.detail(width))
    }
}
