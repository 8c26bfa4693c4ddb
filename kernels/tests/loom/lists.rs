//! The linked-list push: `atomicAdd(counter)` -> node, node write, `atomicExchange(head)`.

use fragrace_emu::kernel::FragInput;
use fragrace_emu::{Device, Fragment};
use fragrace_kernels::common::EMPTY;
use fragrace_kernels::protocols::*;

use super::common::*;

// ------------------------------------------------------------------------------------------
// Linked list: atomicAdd(counter) -> node, node write, atomicExchange(head).
// ------------------------------------------------------------------------------------------

struct LlOutcome {
    /// (depth bits, primitive) of every node reachable from the head, in list order.
    list: Vec<(u32, u32)>,
    /// A node reached twice or a link out of the pool.
    corrupt: bool,
    counter: u32,
    dropped: u32,
    /// Half-written payloads the in-pass readers saw.
    half_written: u32,
}

fn ll_push(frags: &[FragInput], publish_before_write: bool, reader: bool) -> LlOutcome {
    let n = frags.len() as u32;
    let mut dev = Device::new();
    let pool = ListPool::new(&mut dev, "ll", 1, n as u64, 1).unwrap();
    let seen = dev.buffer::<u32>("seen", 1).unwrap();
    let kernel = LlInsert {
        pool,
        cap: n,
        blocks: None,
        publish_before_write,
        reader: reader.then_some(seen),
    };
    let (dev, _) = on_threads(dev, kernel, frags, 1);
    let nodes = read(&dev, pool.nodes);
    let mut list = Vec::new();
    let mut visited = vec![false; n as usize];
    let mut corrupt = false;
    let mut cur = read(&dev, pool.heads)[0];
    while cur != EMPTY {
        if cur >= n || visited[cur as usize] {
            corrupt = true;
            break;
        }
        visited[cur as usize] = true;
        let at = (cur * NODE_WORDS) as usize;
        list.push((nodes[at], nodes[at + 1]));
        cur = nodes[at + 2];
    }
    LlOutcome {
        list,
        corrupt,
        counter: read(&dev, pool.counters)[0],
        dropped: read(&dev, pool.dropped)[0],
        half_written: read(&dev, seen)[0],
    }
}

/// The list holds exactly the pushed fragments, each once.
fn assert_list_complete(o: &LlOutcome, frags: &[FragInput]) {
    assert!(!o.corrupt, "a node reached twice or a link out of the pool");
    assert_eq!(o.counter as usize, frags.len());
    assert_eq!(o.dropped, 0);
    let mut got = o.list.clone();
    got.sort();
    let mut want: Vec<(u32, u32)> = frags
        .iter()
        .map(|f| (f.depth.to_bits(), f.primitive_id))
        .collect();
    want.sort();
    assert_eq!(got, want, "the list must hold exactly the pushed nodes");
}

#[test]
fn ll_push_keeps_exactly_n_distinct_nodes() {
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let o = ll_push(&frags, false, false);
        assert_list_complete(&o, &frags);
    });
}

#[test]
fn ll_push_never_shows_a_reader_a_half_written_node() {
    // The correct order (payload, then the exchange that publishes it) with an in-pass reader
    // walking the list after its own push: under every interleaving, and with loom's weak
    // memory (the payload's plain stores reach the reader through the exchanges'
    // release/acquire), every node the reader reaches is complete.
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let o = ll_push(&frags, false, true);
        assert_list_complete(&o, &frags);
        assert_eq!(o.half_written, 0, "a reader followed a half-written node");
    });
}

#[test]
fn loom_finds_the_planted_bug_of_the_linked_list() {
    // `publish_before_write`: the head exchange publishes the node before it is written. Some
    // interleaving lets the other invocation's reader follow the head to it meanwhile. The
    // lists are still complete once the pass is over (the bug is latent to the oracle).
    let hunt = Hunt::new("ll publish-before-write (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let frags = stack(&[0.5, 0.25]);
        let o = ll_push(&frags, true, true);
        assert_list_complete(&o, &frags);
        h.saw(o.half_written > 0);
    });
    hunt.report();
}
