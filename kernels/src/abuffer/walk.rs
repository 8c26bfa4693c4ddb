//! The host's walk of the per-pixel linked lists after a frame (`ll` and the bucketed
//! lists that share its pool, [`super::ll::ListPool`]): every list followed from its head,
//! its fragments gathered as a capture, and what a broken list looks like (a link out of
//! its region of the pool, a node reached twice) counted and described for the self-check.

use super::ll::{NEXT, NODE_WORDS};
use crate::algo::{Capture, CapturedFrag, Check, Frame};
use crate::common::EMPTY;

/// The lists as the host finds them after the resolve.
pub(super) struct Walk {
    /// Fragments of list `p * lists + b`, in list order.
    pub lists: Vec<Vec<CapturedFrag>>,
    /// Nodes reached from some head.
    pub stored: u64,
    /// Links to a node outside the list's region of allocated nodes.
    pub bad_links: u64,
    /// Nodes reached twice (a cycle, or two lists sharing a tail).
    pub revisits: u64,
    /// The first problem, described.
    pub first_problem: Option<String>,
}

impl Walk {
    /// Walks every list. List `i` (pixel `i / lists`, bucket `i % lists`) may only link
    /// nodes of `regions[i % lists]` (`[start, end)`: the allocated nodes of its region).
    pub fn new(heads: &[u32], nodes: &[u32], lists: u32, regions: &[(u32, u32)]) -> Walk {
        let pool = nodes.len() / NODE_WORDS as usize;
        let mut visited = vec![false; pool];
        let mut w = Walk {
            lists: Vec::with_capacity(heads.len()),
            stored: 0,
            bad_links: 0,
            revisits: 0,
            first_problem: None,
        };
        for (i, &h) in heads.iter().enumerate() {
            let (lo, hi) = regions[i % lists as usize];
            let mut list = Vec::new();
            let mut cur = h;
            while cur != EMPTY {
                if cur < lo || cur >= hi {
                    w.bad_links += 1;
                    w.first_problem
                        .get_or_insert(format!("list {i} links node {cur} outside [{lo}, {hi})"));
                    break;
                }
                if visited[cur as usize] {
                    w.revisits += 1;
                    w.first_problem
                        .get_or_insert(format!("list {i} reaches node {cur} a second time"));
                    break;
                }
                visited[cur as usize] = true;
                let at = (cur * NODE_WORDS) as usize;
                list.push(CapturedFrag::from_bits(nodes[at], nodes[at + 1]));
                w.stored += 1;
                cur = nodes[at + NEXT as usize];
            }
            w.lists.push(list);
        }
        w
    }

    /// Per pixel, its lists concatenated in bucket order, as a capture.
    pub fn capture(&self, frame: &Frame<'_>, lists: u32) -> Capture {
        self.capture_sized(frame.width, frame.height, lists)
    }

    /// [`Walk::capture`] for a frame of `width` x `height` pixels.
    pub fn capture_sized(&self, width: u32, height: u32, lists: u32) -> Capture {
        let per = lists.max(1) as usize;
        Capture::from_lists(width, height, self.lists.chunks(per).map(|c| c.concat()))
    }

    /// "Lists acyclic and every next index in range", from this walk and the resolve's
    /// own counts (`faults` of [`ListResolve`](super::ll::ListResolve)).
    pub fn integrity_check(&self, resolve_faults: &[u32]) -> Check {
        let ok =
            self.bad_links == 0 && self.revisits == 0 && resolve_faults.iter().all(|&c| c == 0);
        Check::new(
            "lists acyclic, disjoint, and every next index in range",
            ok,
            format!(
                "{} bad links, {} nodes reached twice; resolve: {} links out of the pool, {} walks cut{}",
                self.bad_links,
                self.revisits,
                resolve_faults.first().copied().unwrap_or(0),
                resolve_faults.get(1).copied().unwrap_or(0),
                self.first_problem.as_ref().map(|s| format!("; first: {s}")).unwrap_or_default()
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_walk_reports_cycles_and_bad_links() {
        // Pixel 0: 0 -> 1 -> 0 (cycle). Pixel 1: 2 -> 7 (out of the allocated region).
        let nodes = [0, 0, 1, 0, 0, 0, 0, 0, 7];
        let heads = [0, 2];
        let w = Walk::new(&heads, &nodes, 1, &[(0, 3)]);
        assert_eq!((w.revisits, w.bad_links, w.stored), (1, 1, 3));
        assert!(!w.integrity_check(&[0, 0]).passed);
        let ok = Walk::new(&[1, EMPTY], &[0, 0, EMPTY, 0, 0, 0], 1, &[(0, 2)]);
        assert!(ok.integrity_check(&[0, 0]).passed);
        assert!(!ok.integrity_check(&[0, 1]).passed);
    }
}
