//! The host's walk of the per-pixel linked lists after a frame (`ll` and the bucketed
//! lists that share its pool, [`super::ll::ListPool`]): every list followed from its head,
//! its fragments gathered as a capture, and what a broken list looks like (a link out of
//! its region of the pool, a node reached twice) counted and described for the self-check.
//! The lists are read as the frame left them, in insertion order; the capture sorts each
//! one into the order the resolve must composite it (with the standard library's sort, an
//! independent reference for the resolve's own).

use super::ll::{NEXT, NODE_WORDS};
use crate::algo::{Capture, CapturedFrag, Check, Frame};
use crate::common::{depth_order, EMPTY};

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

    /// Per pixel, its lists each sorted front to back (`depth_order`) and concatenated in
    /// bucket order, as a capture: the fragments in the order the resolve composites them
    /// ([`ListResolve`](super::list_resolve::ListResolve) sorts each list it gathers and writes
    /// nothing back, so the lists themselves stay in insertion order).
    pub fn capture(&self, frame: &Frame<'_>, lists: u32) -> Capture {
        self.capture_sized(frame.width, frame.height, lists)
    }

    /// [`Walk::capture`] for a frame of `width` x `height` pixels.
    pub fn capture_sized(&self, width: u32, height: u32, lists: u32) -> Capture {
        let per = lists.max(1) as usize;
        Capture::from_lists(
            width,
            height,
            self.lists.chunks(per).map(|c| {
                let mut pixel = Vec::with_capacity(c.iter().map(Vec::len).sum());
                for list in c {
                    let start = pixel.len();
                    pixel.extend_from_slice(list);
                    // The standard library's sort, not the resolve's own (`sort_fragments`):
                    // this order is the reference the resolve's image is checked against.
                    pixel[start..].sort_by(depth_order);
                }
                pixel
            }),
        )
    }

    /// "Lists acyclic and every next index in range", from this walk and the resolve's
    /// own counts (`faults` of [`ListResolve`](super::list_resolve::ListResolve)).
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

    /// The lists stay in insertion order (the resolve writes nothing back); the capture is
    /// sorted by the host, so a resolve that composited a list in its stored order, not
    /// front to back, fails the image check, and one that sorted passes it.
    #[test]
    fn the_capture_is_sorted_and_the_image_check_sees_an_unsorted_resolve() {
        use super::super::checks::{capture_checks, CaptureOrder};
        use crate::algo::Params;
        use crate::common::composite_frags;
        use fragrace_emu::PassReport;
        // Pixel 0: head 2 -> 1 -> 0, depths 0.25, 0.75, 0.5 (prepended: the last inserted
        // first). Pixel 1: empty.
        let (a, b, c) = (0.5f32.to_bits(), 0.75f32.to_bits(), 0.25f32.to_bits());
        let nodes = [a, 7, EMPTY, b, 8, 0, c, 9, 1];
        let walk = Walk::new(&[2, EMPTY], &nodes, 1, &[(0, 3)]);
        let stored: Vec<f32> = walk.lists[0].iter().map(|f| f.depth).collect();
        assert_eq!(stored, [0.25, 0.75, 0.5]);
        let capture = walk.capture_sized(2, 1, 1);
        let sorted: Vec<f32> = capture.pixel(0).iter().map(|f| f.depth).collect();
        assert_eq!(sorted, [0.25, 0.5, 0.75]);
        assert!(capture.pixel(1).is_empty());

        let params = Params::default();
        let image_of = |pixel: &[CapturedFrag]| {
            vec![
                composite_frags(pixel, params.alpha, params.background),
                composite_frags(&[], params.alpha, params.background),
            ]
        };
        let report = PassReport::default();
        let good = capture_checks(
            &capture,
            CaptureOrder::Host,
            &image_of(capture.pixel(0)),
            &params,
            &report,
        );
        assert!(good.iter().all(|c| c.passed), "{good:?}");
        assert!(good
            .iter()
            .all(|c| c.name != "resolve order is front to back"));
        let unsorted = capture_checks(
            &capture,
            CaptureOrder::Host,
            &image_of(&walk.lists[0]),
            &params,
            &report,
        );
        let image = unsorted
            .iter()
            .find(|c| c.name == "resolve image is the composite of the captured fragments")
            .unwrap();
        assert!(!image.passed, "{}", image.detail);
    }
}
