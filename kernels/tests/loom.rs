//! loom models of the kernels' synchronisation protocols: the linked-list push (counter, head
//! exchange, node write), the atomic-min k-buffer chains (32- and 64-bit, and the 32-bit
//! claim pass), the spinlock k-buffer, the interlock k-buffer (ordered and unordered), the
//! count / allocate / store counters of DFB and the S-buffer, and the read-modify-write
//! k-buffer. Each model runs the algorithm's own capture kernel (re-exported by
//! `fragrace_kernels::protocols`) with one loom thread per invocation
//! (`fragrace_emu::exec::run_on_threads`) on 2 or 3 invocations, and checks the protocol's
//! invariant in every execution loom explores (loom also models weak memory: a relaxed load
//! may read a stale value, so publication through release/acquire is checked too).
//!
//! The `loom_finds_*` tests go the other way: they assert that loom *finds* a bug (the
//! planted bug of the linked list, the read-modify-write k-buffer losing a fragment, a
//! spinlock dropping a fragment at its cap, a spinlock released by a plain store) and print
//! after how many executions and how long.
//!
//! Passes a model does not explore run on the `ordered` executor on loom's main thread
//! (`Device::invocations`): loom allows 4 threads per execution besides the main one.
//!
//! Run with `RUSTFLAGS="--cfg loom" cargo test --release --target-dir target/loom
//! -p fragrace-kernels --test loom` (or `bash ci/loom.sh`); add `-- --nocapture` for the
//! figures.
#![cfg(loom)]

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use fragrace_emu::exec::{run_on_threads, ThreadOutcome};
use fragrace_emu::kernel::FragInput;
use fragrace_emu::sync::Arc;
use fragrace_emu::{Buf, Device, ExecConfig, Fragment, FragmentKernel, InterlockMode, KernelInfo};
use fragrace_kernels::common::EMPTY;
use fragrace_kernels::protocols::*;

/// Watchdog of the invocations (steps): far above what any of these kernels needs.
const MAX_STEPS: u64 = 10_000;

fn frag(x: u32, depth: f32, prim: u32, ticket: u32) -> FragInput {
    FragInput {
        seq: prim as u64,
        x,
        y: 0,
        tri: u32::MAX,
        primitive_id: prim,
        coverage: 1,
        front_facing: true,
        depth,
        ticket,
        ..Default::default()
    }
}

/// `depths` as fragments of pixel 0, primitive = position, tickets in API order.
fn stack(depths: &[f32]) -> Vec<FragInput> {
    depths
        .iter()
        .enumerate()
        .map(|(i, &d)| frag(0, d, i as u32, i as u32))
        .collect()
}

/// Explores `f` with the preemption bound pinned (the environment's LOOM_MAX_PREEMPTIONS is
/// overridden: each model states the bound its claim is made under), and prints how many
/// executions loom explored and how long it took.
fn model(preemption_bound: usize, f: impl Fn() + Sync + Send + 'static) {
    let mut b = loom::model::Builder::new();
    b.preemption_bound = Some(preemption_bound);
    b.max_branches = 1_000_000;
    let executions = std::sync::Arc::new(AtomicU64::new(0));
    let counter = executions.clone();
    let start = Instant::now();
    b.check(move || {
        counter.fetch_add(1, Relaxed);
        f()
    });
    println!(
        "{}: {} executions, preemption bound {preemption_bound}, {:.2} s",
        std::thread::current().name().unwrap_or("model"),
        executions.load(Relaxed),
        start.elapsed().as_secs_f64()
    );
}

/// Runs one pass of `kernel` with a loom thread per fragment on `dev`'s memory (pixels
/// `width x 1`) and gives the device back.
fn on_threads<K: FragmentKernel + Send + 'static>(
    dev: Device,
    kernel: K,
    frags: &[FragInput],
    width: u32,
) -> (Device, Vec<ThreadOutcome>) {
    let memory = Arc::new(dev.memory);
    let out = run_on_threads(
        Arc::new(kernel),
        memory.clone(),
        frags.to_vec(),
        width,
        1,
        MAX_STEPS,
    );
    let memory = Arc::try_unwrap(memory)
        .ok()
        .expect("every invocation thread has been joined");
    assert!(out.iter().all(|o| o.fault.is_none()), "{out:?}");
    (Device { memory }, out)
}

/// Runs one pass on the `ordered` executor (a pass this model does not explore).
fn ordered<K: FragmentKernel>(dev: &Device, kernel: &K, frags: &[FragInput], width: u32) {
    let r = dev.invocations(width, 1, frags, kernel, &ExecConfig::ordered());
    assert_eq!(r.stats.faulted, 0, "{:?}", r.faults);
}

fn read<T: fragrace_emu::Word>(dev: &Device, b: Buf<T>) -> Vec<T> {
    dev.memory.read(b).unwrap()
}

/// Counts the executions of a `loom_finds_*` model and when the bug first showed.
struct Hunt {
    name: &'static str,
    start: Instant,
    executions: AtomicU64,
    found: AtomicBool,
    first: Mutex<Option<(u64, Duration)>>,
}

impl Hunt {
    fn new(name: &'static str) -> std::sync::Arc<Hunt> {
        std::sync::Arc::new(Hunt {
            name,
            start: Instant::now(),
            executions: AtomicU64::new(0),
            found: AtomicBool::new(false),
            first: Mutex::new(None),
        })
    }
    fn execution(&self) {
        self.executions.fetch_add(1, Relaxed);
    }
    fn saw(&self, bug: bool) {
        if bug && !self.found.swap(true, Relaxed) {
            *self.first.lock().unwrap() =
                Some((self.executions.load(Relaxed), self.start.elapsed()));
        }
    }
    /// Asserts the bug was found and prints the figures.
    fn report(&self) {
        let total = self.executions.load(Relaxed);
        let first = *self.first.lock().unwrap();
        let Some((n, t)) = first else {
            panic!(
                "{}: loom explored {total} executions and never found the bug",
                self.name
            );
        };
        println!(
            "{}: loom found it at execution {n} after {:.3} s ({total} executions explored in {:.3} s)",
            self.name,
            t.as_secs_f64(),
            self.start.elapsed().as_secs_f64()
        );
    }
}

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

// ------------------------------------------------------------------------------------------
// Atomic-min k-buffers.
// ------------------------------------------------------------------------------------------

fn key32(d: f32) -> u32 {
    (d + 0.0).to_bits()
}

fn key64(d: f32, prim: u32) -> u64 {
    ((key32(d) as u64) << 32) | prim as u64
}

/// `kb-atomic32`'s depth pass (k = 2) on loom; returns the keys and the census count.
fn chain32(frags: &[FragInput]) -> (Vec<u32>, u32, u32) {
    let k = 2;
    let mut dev = Device::new();
    let key = dev.buffer::<u32>("kb-key", k as u64).unwrap();
    dev.memory.fill(key, EMPTY).unwrap();
    let census = Census {
        count: dev.buffer::<u32>("kb-count", 1).unwrap(),
        negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
    };
    let (dev, _) = on_threads(dev, Depth32 { key, k, census }, frags, 1);
    (
        read(&dev, key),
        read(&dev, census.count)[0],
        read(&dev, census.negative)[0],
    )
}

/// The k smallest of `keys`, ascending, padded with `empty`.
fn k_smallest<T: Ord + Copy>(mut keys: Vec<T>, k: usize, empty: T) -> Vec<T> {
    keys.sort();
    keys.resize(keys.len().max(k), empty);
    keys.truncate(k);
    keys
}

#[test]
fn atomic_min_chain_32_keeps_the_k_smallest_keys() {
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let (keys, count, negative) = chain32(&frags);
        assert_eq!(keys, vec![key32(0.25), key32(0.5)]);
        assert_eq!((count, negative), (3, 0));
    });
}

#[test]
fn atomic_min_chain_32_keeps_equal_depths_as_separate_slots() {
    model(3, || {
        let frags = stack(&[0.5, 0.75, 0.5]);
        let (keys, count, _) = chain32(&frags);
        assert_eq!(keys, vec![key32(0.5), key32(0.5)]);
        assert_eq!(count, 3);
    });
}

#[test]
fn atomic32_claim_pass_gives_each_kept_slot_one_coplanar_fragment() {
    // Depth pass on the ordered executor, claim pass on loom: three coplanar fragments race
    // for the two slots of their depth by compare-exchange. Each slot ends claimed by exactly
    // one of them, never the same one twice, and the third is counted as unclaimed.
    model(3, || {
        let k = 2;
        let frags = stack(&[0.5, 0.5, 0.5]);
        let mut dev = Device::new();
        let key = dev.buffer::<u32>("kb-key", k as u64).unwrap();
        let prim = dev.buffer::<u32>("kb-prim", k as u64).unwrap();
        let unclaimed = dev.buffer::<u32>("kb-unclaimed", 1).unwrap();
        dev.memory.fill(key, EMPTY).unwrap();
        dev.memory.fill(prim, EMPTY).unwrap();
        let census = Census {
            count: dev.buffer::<u32>("kb-count", 1).unwrap(),
            negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
        };
        ordered(&dev, &Depth32 { key, k, census }, &frags, 1);
        assert_eq!(read(&dev, key), vec![key32(0.5); 2]);
        let claim = Claim32 {
            key,
            prim,
            k,
            unclaimed,
        };
        let (dev, _) = on_threads(dev, claim, &frags, 1);
        let p = read(&dev, prim);
        assert!(p.iter().all(|&p| p < 3), "{p:?}");
        assert_ne!(p[0], p[1], "one fragment claimed two slots");
        assert_eq!(read(&dev, unclaimed)[0], 1);
    });
}

#[test]
fn atomic_min_chain_64_keeps_the_k_smallest_keys() {
    model(3, || {
        let k = 2;
        let frags = stack(&[0.5, 0.5, 0.25]);
        let mut dev = Device::new();
        let key = dev.buffer::<u64>("kb-key64", k as u64).unwrap();
        dev.memory.fill(key, u64::MAX).unwrap();
        let census = Census {
            count: dev.buffer::<u32>("kb-count", 1).unwrap(),
            negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
        };
        let (dev, _) = on_threads(dev, Store64 { key, k, census }, &frags, 1);
        let all = frags
            .iter()
            .map(|f| key64(f.depth, f.primitive_id))
            .collect();
        assert_eq!(read(&dev, key), k_smallest(all, k as usize, u64::MAX));
        assert_eq!(read(&dev, key), vec![key64(0.25, 2), key64(0.5, 0)]);
        assert_eq!(read(&dev, census.count)[0], 3);
    });
}

// ------------------------------------------------------------------------------------------
// Read-modify-write k-buffers: racy (kb-rmw), under a spinlock, under pixel interlock.
// ------------------------------------------------------------------------------------------

/// The occupied slots (depth, primitive) of pixel 0.
fn slots(dev: &Device, kb: SplitSlots) -> Vec<(f32, u32)> {
    read(dev, kb.depth)
        .into_iter()
        .zip(read(dev, kb.prim))
        .filter(|&(d, _)| d != f32::INFINITY)
        .collect()
}

/// The k nearest of `frags` by (depth, primitive), as k-buffer slots.
fn nearest(frags: &[FragInput], k: usize) -> Vec<(f32, u32)> {
    let mut v: Vec<(f32, u32)> = frags.iter().map(|f| (f.depth, f.primitive_id)).collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    v.truncate(k);
    v
}

#[test]
fn loom_finds_the_rmw_k_buffer_losing_a_fragment() {
    // Two fragments of one pixel both load the empty slots, insert themselves, and store all
    // k back: the second store overwrites the first (the read-modify-write hazard).
    let hunt = Hunt::new("kb-rmw lost fragment (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let k = 2;
        let frags = stack(&[0.5, 0.25]);
        let mut dev = Device::new();
        let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
        let (dev, _) = on_threads(dev, RmwStore { kb, k }, &frags, 1);
        let s = slots(&dev, kb);
        // Whatever survives is one of the fragments, in order.
        assert!(!s.is_empty() && s.len() <= 2);
        h.saw(s != nearest(&frags, 2));
    });
    hunt.report();
}

struct Spin {
    kb: SplitSlots,
    lock: Buf<u32>,
    gave_up: Buf<u32>,
    entries: Buf<u32>,
}

fn spin_setup(k: u32) -> (Device, Spin) {
    let mut dev = Device::new();
    let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
    let lock = dev.buffer::<u32>("kb-lock", 1).unwrap();
    let gave_up = dev.buffer::<u32>("kb-gave-up", 1).unwrap();
    let entries = dev.buffer::<u32>("kb-entries", 1).unwrap();
    (
        dev,
        Spin {
            kb,
            lock,
            gave_up,
            entries,
        },
    )
}

/// `kb-spinlock`'s capture on loom with spin cap `cap`; returns (slots, entries, give-ups).
fn spinlock(frags: &[FragInput], cap: u32) -> (Vec<(f32, u32)>, u32, u32) {
    let k = frags.len() as u32; // room for all: nothing is evicted
    let (dev, s) = spin_setup(k);
    let kernel = SpinStore {
        kb: s.kb,
        k,
        lock: s.lock,
        cap,
        gave_up: s.gave_up,
        entries: s.entries,
    };
    let (dev, _) = on_threads(dev, kernel, frags, 1);
    assert_eq!(read(&dev, s.lock)[0], 0, "the lock was left held");
    (
        slots(&dev, s.kb),
        read(&dev, s.entries)[0],
        read(&dev, s.gave_up)[0],
    )
}

#[test]
fn spinlock_excludes_and_loses_nothing_silently() {
    // Mutual exclusion: the plain read-modify-write of `entries` inside the lock never loses
    // an increment, and the slots (room for every fragment) hold exactly the fragments that
    // got the lock; every other fragment is counted as a give-up. (That no fragment gives up
    // cannot be claimed for any cap: loom's scheduler is not fair, and a lock holder that is
    // preempted lets the spinner burn its whole cap, which the next test shows.)
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let (s, entries, gave_up) = spinlock(&frags, 3);
        assert_eq!(entries + gave_up, 3);
        assert_eq!(s.len() as u32, entries, "{s:?}");
        let mut kept = s.clone();
        kept.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(kept, s, "slots out of order");
        for x in &s {
            assert!(nearest(&frags, 3).contains(x));
        }
    });
}

#[test]
fn loom_finds_a_spinlock_dropping_a_fragment_at_its_cap() {
    let hunt = Hunt::new("kb-spinlock drop at cap 1 (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let frags = stack(&[0.5, 0.25]);
        let (s, entries, gave_up) = spinlock(&frags, 1);
        assert_eq!(entries + gave_up, 2, "a fragment was lost silently");
        assert_eq!(s.len() as u32, entries);
        h.saw(gave_up > 0);
    });
    hunt.report();
}

/// `kb-spinlock`'s protocol with the release written as a plain (relaxed) store instead of
/// a release store: the next holder's compare-exchange reads the 0 but does not
/// synchronise with the previous holder's writes, so its plain loads may see stale values
/// (a known hazard, docs/hazards.md: "release by a plain store with no barrier"). Not one of the algorithms: the
/// bug, written out for loom (the counter inside the lock is `kb-spinlock`'s `entries`).
struct PlainReleaseSpin {
    s: Spin,
    cap: u32,
}

impl FragmentKernel for PlainReleaseSpin {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("spinlock-plain-release")
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let mut attempts = 0;
        while f.atomic_compare_exchange(s.lock, 0, 0, 1).await.is_err() {
            attempts += 1;
            if attempts >= self.cap {
                f.atomic_add(s.gave_up, 0, 1).await;
                return;
            }
        }
        let e = f.load(s.entries, 0).await;
        f.store(s.entries, 0, e + 1).await;
        f.store(s.lock, 0, 0).await; // the bug: `atomic_store` (release) in kb-spinlock
    }
}

#[test]
fn loom_finds_the_lost_update_of_a_spinlock_released_by_a_plain_store() {
    let hunt = Hunt::new("spinlock with a plain release (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let (dev, s) = spin_setup(1);
        let (entries, gave_up) = (s.entries, s.gave_up);
        let kernel = PlainReleaseSpin { s, cap: 3 };
        let (dev, _) = on_threads(dev, kernel, &stack(&[0.5, 0.25]), 1);
        h.saw(read(&dev, entries)[0] + read(&dev, gave_up)[0] != 2);
    });
    hunt.report();
}

fn interlock_k_buffer(mode: InterlockMode) {
    model(3, move || {
        let k = 2;
        let frags = stack(&[0.5, 0.25]);
        let mut dev = Device::new();
        let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
        let last = dev.buffer::<u32>("kb-last", 1).unwrap();
        let entries = dev.buffer::<u32>("kb-entries", 1).unwrap();
        let out_of_order = dev.buffer::<u32>("kb-out-of-order", 1).unwrap();
        let kernel = InterlockStore {
            kb,
            k,
            mode,
            last,
            entries,
            out_of_order,
        };
        let (dev, _) = on_threads(dev, kernel, &frags, 1);
        assert_eq!(slots(&dev, kb), nearest(&frags, k as usize));
        assert_eq!(read(&dev, entries)[0], 2, "mutual exclusion");
        if mode.ordered {
            assert_eq!(read(&dev, out_of_order)[0], 0, "entered out of API order");
            assert_eq!(
                read(&dev, last)[0],
                2,
                "the last entrant is the last primitive"
            );
        }
    });
}

#[test]
fn ordered_interlock_k_buffer_is_exact_and_in_api_order() {
    interlock_k_buffer(InterlockMode::ORDERED);
}

#[test]
fn unordered_interlock_k_buffer_is_exact() {
    interlock_k_buffer(InterlockMode::UNORDERED);
}

// ------------------------------------------------------------------------------------------
// Count-scan-store A-buffers: DFB and the S-buffer.
// ------------------------------------------------------------------------------------------

/// Three fragments: two on pixel 0, one on pixel 1 (of a 2 x 1 viewport).
fn two_pixels() -> Vec<FragInput> {
    vec![frag(0, 0.5, 0, 0), frag(1, 0.25, 1, 0), frag(0, 0.75, 2, 1)]
}

/// Checks a count-scan-store result: per pixel the store pass filled exactly what the count
/// pass counted, the ranges `(start, count)` are disjoint and cover `[0, total)`, and each
/// range holds exactly its pixel's fragments.
fn assert_ranges(
    frags: &[FragInput],
    counts: &[u32],
    fill: &[u32],
    starts: &[u32],
    depth: &[f32],
    prim: &[u32],
    overflow: u32,
) {
    assert_eq!(counts, fill, "count pass and store pass disagree");
    assert_eq!(overflow, 0);
    let total: u32 = counts.iter().sum();
    assert_eq!(total as usize, frags.len());
    let mut ranges: Vec<(u32, u32)> = starts
        .iter()
        .zip(counts)
        .filter(|r| *r.1 > 0)
        .map(|(&s, &c)| (s, c))
        .collect();
    ranges.sort();
    let mut next = 0;
    for &(s, c) in &ranges {
        assert_eq!(s, next, "ranges overlap or leave a gap: {ranges:?}");
        next = s + c;
    }
    assert_eq!(next, total);
    for (p, (&s, &c)) in starts.iter().zip(counts).enumerate() {
        let mut got: Vec<(u32, u32)> = (s..s + c)
            .map(|i| (depth[i as usize].to_bits(), prim[i as usize]))
            .collect();
        got.sort();
        let mut want: Vec<(u32, u32)> = frags
            .iter()
            .filter(|f| f.x as usize == p)
            .map(|f| (f.depth.to_bits(), f.primitive_id))
            .collect();
        want.sort();
        assert_eq!(got, want, "pixel {p}'s range");
    }
}

/// Exclusive prefix sum.
fn scan(v: &[u32]) -> Vec<u32> {
    v.iter()
        .scan(0, |s, &c| {
            let o = *s;
            *s += c;
            Some(o)
        })
        .collect()
}

/// DFB with the count pass (`concurrent_count`) or the store pass explored by loom.
fn dfb(concurrent_count: bool) {
    model(3, move || {
        let frags = two_pixels();
        let n = 2;
        let mut dev = Device::new();
        let counts = dev.buffer::<u32>("dfb-counts", n).unwrap();
        let offsets = dev.buffer::<u32>("dfb-offsets", n).unwrap();
        let fill = dev.buffer::<u32>("dfb-fill", n).unwrap();
        let depth = dev.buffer::<f32>("dfb-depth", 3).unwrap();
        let prim = dev.buffer::<u32>("dfb-prim", 3).unwrap();
        let overflow = dev.buffer::<u32>("dfb-overflow", 1).unwrap();
        let count = CountKernel { counts };
        if concurrent_count {
            dev = on_threads(dev, count, &frags, 2).0;
        } else {
            ordered(&dev, &count, &frags, 2);
        }
        // The device scan is one invocation per row: nothing to interleave; done on the host.
        let starts = scan(&read(&dev, counts));
        dev.memory.write(offsets, 0, &starts).unwrap();
        let store = DfbStore {
            counts,
            offsets,
            fill,
            depth,
            prim,
            overflow,
        };
        if concurrent_count {
            ordered(&dev, &store, &frags, 2);
        } else {
            dev = on_threads(dev, store, &frags, 2).0;
        }
        assert_ranges(
            &frags,
            &read(&dev, counts),
            &read(&dev, fill),
            &starts,
            &read(&dev, depth),
            &read(&dev, prim),
            read(&dev, overflow)[0],
        );
    });
}

#[test]
fn dfb_count_pass_counts_every_fragment() {
    dfb(true);
}

#[test]
fn dfb_store_pass_fills_exactly_the_counted_ranges() {
    dfb(false);
}

/// The S-buffer on 3 pixels in 2 groups (pixels 0 and 2 share group 0's counter), with the
/// allocate pass or the store pass explored by loom.
fn sbuffer(concurrent_allocate: bool) {
    model(3, move || {
        // Two fragments on pixel 0, one each on pixels 1 and 2 (store pass: 3 of them).
        let mut frags = two_pixels();
        if concurrent_allocate {
            frags.push(frag(2, 0.125, 3, 0));
        }
        let (n, groups) = (3u32, 2u32);
        let mut dev = Device::new();
        let counts = dev.buffer::<u32>("sb-counts", n as u64).unwrap();
        let offsets = dev.buffer::<u32>("sb-offsets", n as u64).unwrap();
        dev.memory.fill(offsets, EMPTY).unwrap();
        let fill = dev.buffer::<u32>("sb-fill", n as u64).unwrap();
        let group_total = dev.buffer::<u32>("sb-group-totals", groups as u64).unwrap();
        let group_base = dev.buffer::<u32>("sb-group-bases", groups as u64).unwrap();
        let depth = dev.buffer::<f32>("sb-depth", frags.len() as u64).unwrap();
        let prim = dev.buffer::<u32>("sb-prim", frags.len() as u64).unwrap();
        let overflow = dev.buffer::<u32>("sb-overflow", 1).unwrap();
        ordered(&dev, &CountKernel { counts }, &frags, n);
        // Full-screen allocate pass: one invocation per pixel.
        let pixels: Vec<FragInput> = (0..n).map(|x| frag(x, 0.5, 0, 0)).collect();
        let allocate = SparseAllocate {
            counts,
            offsets,
            group_total,
            groups,
        };
        if concurrent_allocate {
            dev = on_threads(dev, allocate, &pixels, n).0;
        } else {
            ordered(&dev, &allocate, &pixels, n);
        }
        // The group scan is one invocation: nothing to interleave; done on the host.
        let bases = scan(&read(&dev, group_total));
        dev.memory.write(group_base, 0, &bases).unwrap();
        let store = SbStore {
            counts,
            offsets,
            group_base,
            fill,
            depth,
            prim,
            overflow,
            groups,
        };
        if concurrent_allocate {
            ordered(&dev, &store, &frags, n);
        } else {
            dev = on_threads(dev, store, &frags, n).0;
        }
        let c = read(&dev, counts);
        let o = read(&dev, offsets);
        let starts: Vec<u32> = (0..n as usize)
            .map(|p| {
                if c[p] == 0 {
                    0
                } else {
                    bases[p % groups as usize] + o[p]
                }
            })
            .collect();
        assert_ranges(
            &frags,
            &c,
            &read(&dev, fill),
            &starts,
            &read(&dev, depth),
            &read(&dev, prim),
            read(&dev, overflow)[0],
        );
    });
}

#[test]
fn sbuffer_allocate_pass_gives_disjoint_ranges() {
    sbuffer(true);
}

#[test]
fn sbuffer_store_pass_fills_exactly_the_counted_ranges() {
    sbuffer(false);
}

// ---------------------------------------------------------------------------------------
// Occupancy culling ("Improving k-buffer methods via occupancy maps", section 2): concurrent
// fills of one pixel's map, then the count. The count's arithmetic is the same function the
// count kernel runs (`occupancy::bits`), applied here to the map the fills left.

use fragrace_kernels::occupancy::bits::{bucket, pixel_bound, BITS_PER_WORD};
use fragrace_kernels::occupancy::FillMode;

/// Fills one pixel's map (`d` words, range `[zn, zf]`) with one loom thread per fragment,
/// and returns the map and the count's bound for `k`.
fn occupancy_fill(frags: &[FragInput], d: u32, k: u32, mode: FillMode) -> (Vec<u32>, f32) {
    let (zn, zf) = (0.0, 1.0);
    let mut dev = Device::new();
    let map = dev.buffer::<u32>("occupancy-map", d as u64).unwrap();
    let near = dev.buffer::<f32>("occupancy-near", 1).unwrap();
    let far = dev.buffer::<f32>("occupancy-far", 1).unwrap();
    dev.memory.fill(near, zn).unwrap();
    dev.memory.fill(far, zf).unwrap();
    let fill = OccupancyFill {
        map,
        near,
        far,
        d,
        mode,
    };
    let (dev, _) = on_threads(dev, fill, frags, 1);
    let words = read(&dev, map);
    let bound = pixel_bound(&words, k, zn, zf);
    (words, bound)
}

/// The bits an exact fill sets.
fn exact_bits(frags: &[FragInput], d: u32) -> Vec<u32> {
    let mut w = vec![0u32; d as usize];
    for f in frags {
        let j = bucket(f.depth, 0.0, 1.0, d * BITS_PER_WORD);
        w[(j / BITS_PER_WORD) as usize] |= 1 << (j % BITS_PER_WORD);
    }
    w
}

#[test]
fn occupancy_atomic_fill_sets_every_bit_and_keeps_the_k_nearest() {
    // Three fragments in three sub-intervals of one word, one pair in the same word as
    // the third: the atomic ORs of every interleaving leave exactly the three bits, and the
    // count's bound passes the k = 2 nearest.
    model(3, || {
        let frags = stack(&[0.9, 0.05, 0.5]);
        let (words, bound) = occupancy_fill(&frags, 1, 2, FillMode::Atomic);
        assert_eq!(words, exact_bits(&frags, 1));
        for f in nearest(&frags, 2) {
            assert!(f.0 <= bound, "Lemma 2.1: {} culled by {bound}", f.0);
        }
        assert!(0.9 > bound, "the farthest fragment is culled");
    });
}

#[test]
fn loom_finds_the_plain_fill_losing_a_bit_and_lemma_2_1_still_holds() {
    // A plain read-OR-write fill loses a bit when two fragments of one word interleave;
    // the map then holds a subset of the true bits, so the k-th bit is at or beyond the
    // true one and the bound can only be farther: Lemma 2.1 holds in every interleaving.
    let hunt = Hunt::new("occupancy plain fill lost bit (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let frags = stack(&[0.3, 0.1]);
        let (words, bound) = occupancy_fill(&frags, 1, 1, FillMode::Plain);
        let exact = exact_bits(&frags, 1);
        assert_eq!(words[0] & !exact[0], 0, "a plain fill never invents a bit");
        for f in nearest(&frags, 1) {
            assert!(f.0 <= bound, "Lemma 2.1: {} culled by {bound}", f.0);
        }
        h.saw(words != exact);
    });
    hunt.report();
}
