//! Per-pixel arrays declared the pixels' own (`KernelInfo::with_own_pixel_array`): where a
//! worker owns its tiles for the pass, the kernel's atomics on its fragments' slots are plain
//! loads and stores, with the same results as everywhere else; an access to another
//! pixel's slot is a misuse there.

use fragrace_emu::{
    Buf, Device, ExecConfig, FaultKind, Fragment, FragmentKernel, Framebuffer, KernelInfo,
    PassReport, PassState, SampleCount,
};

use super::common::*;

/// Three words a pixel, each read-modify-written by every fragment of the pixel: a count, a
/// hash chained through exchanges (the order of a pixel's fragments shows), and a maximum.
struct Slots {
    slots: Buf<u32>,
    own: bool,
}

impl FragmentKernel for Slots {
    fn info(&self) -> KernelInfo {
        let info = KernelInfo::new("own-slots");
        if self.own {
            info.with_own_pixel_array(self.slots, 3)
        } else {
            info
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index() * 3;
        let n = f.atomic_add(self.slots, p, 1).await;
        let id = f.primitive_id().wrapping_mul(2_654_435_761) ^ n;
        let prev = f.atomic_exchange(self.slots, p + 1, id).await;
        f.atomic_xor(self.slots, p + 1, prev.rotate_left(9)).await;
        f.atomic_max(self.slots, p + 2, f.primitive_id() + 1).await;
    }
}

/// Reaches past its slot at column 3 (the next pixel's word).
struct Neighbour {
    counts: Buf<u32>,
}

impl FragmentKernel for Neighbour {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("own-slot-neighbour").with_own_pixel_array(self.counts, 1)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let at = if f.x() == 3 { p + 1 } else { p };
        f.atomic_add(self.counts, at, 1).await;
    }
}

fn draw<K: FragmentKernel>(dev: &Device, kernel: &K, e: &ExecConfig) -> PassReport {
    let mesh = two_layers();
    let mut fb = Framebuffer::new(16, 8, SampleCount::X1, 8, &[]).unwrap();
    let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
    dev.draw(&mut fb, &draw, &PassState::default(), kernel, e)
        .unwrap()
}

/// The ordered executor (one lane, no lockstep) gives each tile to its one worker for the
/// whole pass: the path that performs atomics on own slots plainly.
fn owning() -> ExecConfig {
    ExecConfig {
        lockstep: false,
        max_steps: 10_000,
        ..ExecConfig::ordered()
    }
}

#[test]
fn own_slots_hold_what_atomics_leave_under_every_executor() {
    let run = |e: &ExecConfig, own: bool| {
        let mut dev = Device::new();
        let slots = dev.buffer::<u32>("slots", 16 * 8 * 3).unwrap();
        let r = draw(&dev, &Slots { slots, own }, e);
        assert!(r.faults.is_empty(), "{e:?}: {:?}", r.faults);
        assert_eq!(r.stats.shaded, 256, "{e:?}");
        dev.memory.read(slots).unwrap()
    };
    let want = run(&ExecConfig::ordered(), false);
    // Two fragments a pixel, one of each layer (primitives 0-1 and 2-3).
    assert!(want
        .chunks(3)
        .all(|s| s[0] == 2 && (s[2] == 3 || s[2] == 4)));
    // In API order per pixel (one worker a tile, one fragment at a time) every word is as
    // the atomic path leaves it, the exchanged one too.
    assert_eq!(run(&owning(), true), want);
    // Elsewhere a pixel's fragments may interleave: the count and the maximum commute.
    let commuting = |v: &[u32]| v.chunks(3).map(|s| (s[0], s[2])).collect::<Vec<_>>();
    for e in direct_execs().iter().chain(&all_execs()) {
        assert_eq!(commuting(&run(e, true)), commuting(&want), "{e:?}");
    }
}

#[test]
fn another_pixels_slot_is_misuse_where_tiles_are_owned_and_unchecked_elsewhere() {
    let run = |e: &ExecConfig| {
        let mut dev = Device::new();
        let counts = dev.buffer::<u32>("counts", 16 * 8).unwrap();
        let r = draw(&dev, &Neighbour { counts }, e);
        (r, dev.memory.read(counts).unwrap())
    };
    let (r, counts) = run(&owning());
    // Column 3, eight rows, two layers: faulted before their access.
    assert_eq!(r.stats.faulted, 16);
    for f in &r.faults {
        assert_eq!(f.invocation.x, 3);
        assert!(
            matches!(&f.kind, FaultKind::Misuse { message }
                if message.contains("with_own_pixel_array") && message.contains("`counts`")),
            "{:?}",
            f.kind
        );
    }
    assert_eq!(counts.iter().sum::<u32>(), 256 - 16);
    // Segments share tiles between threads: the atomics stay atomic and nothing is checked.
    let segmented = ExecConfig {
        lockstep: false,
        segment: 1,
        max_steps: 10_000,
        ..ExecConfig::parallel(2)
    };
    let (r, counts) = run(&segmented);
    assert!(r.faults.is_empty(), "{:?}", r.faults);
    assert_eq!(counts.iter().sum::<u32>(), 256);
    assert_eq!(
        counts[4 + 16],
        4,
        "column 4 counts column 3's fragments too"
    );
}

/// A counter per screen block of 2 x 2 pixels (`with_own_block_array`, 16 words a block so
/// that blocks' counters are apart): every fragment takes a ticket from its block's counter
/// and writes it to its own pixel's word; `wrong` also takes one from the block to the
/// right at column 4 (another block's slot).
struct BlockTickets {
    counters: Buf<u32>,
    tickets: Buf<u32>,
    wrong: bool,
}

/// log2 of [`BlockTickets`]' block side, and its words per block.
const SHIFT: u32 = 1;
const STRIDE: u32 = 16;

impl FragmentKernel for BlockTickets {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("own-block-tickets").with_own_block_array(self.counters, SHIFT, STRIDE)
    }
    async fn shade(&self, f: impl Fragment) {
        let across = 16u32.div_ceil(1 << SHIFT);
        let block = |x: u32| ((f.y() >> SHIFT) * across + (x >> SHIFT)) * STRIDE;
        let n = f.atomic_add(self.counters, block(f.x()), 1).await;
        f.atomic_max(self.tickets, f.pixel_index(), n + 1).await;
        if self.wrong && f.x() == 4 {
            f.atomic_add(self.counters, block(f.x() + 2), 1).await;
        }
    }
}

#[test]
fn own_block_counters_count_their_blocks_under_every_executor_and_check_where_owned() {
    let run = |e: &ExecConfig, wrong: bool| {
        let mut dev = Device::new();
        let counters = dev
            .buffer::<u32>("counters", 8 * 4 * STRIDE as u64)
            .unwrap();
        let tickets = dev.buffer::<u32>("tickets", 16 * 8).unwrap();
        let kernel = BlockTickets {
            counters,
            tickets,
            wrong,
        };
        let r = draw(&dev, &kernel, e);
        let m = &dev.memory;
        (r, m.read(counters).unwrap(), m.read(tickets).unwrap())
    };
    // Two layers over every pixel: each block of 4 pixels counts 8 fragments, and every
    // pixel's last ticket is one of its block's 8.
    let check = |e: &ExecConfig, counters: &[u32], tickets: &[u32]| {
        for (b, c) in counters.chunks(STRIDE as usize).enumerate() {
            assert_eq!(c[0], 8, "{e:?}: block {b}");
            assert!(c[1..].iter().all(|&w| w == 0), "{e:?}: block {b}");
        }
        assert!(
            tickets.iter().all(|&t| (2..=8).contains(&t)),
            "{e:?}: {tickets:?}"
        );
    };
    for e in std::iter::once(owning())
        .chain(direct_execs())
        .chain(all_execs())
    {
        let (r, counters, tickets) = run(&e, false);
        assert!(r.faults.is_empty(), "{e:?}: {:?}", r.faults);
        check(&e, &counters, &tickets);
    }
    // Where the tiles (8 x 8) are owned, another block's counter is a misuse: column 4's
    // fragments fault at that access (after their own block's ticket).
    let (r, counters, _) = run(&owning(), true);
    assert_eq!(r.stats.faulted, 16);
    for f in &r.faults {
        assert_eq!(f.invocation.x, 4);
        assert!(
            matches!(&f.kind, FaultKind::Misuse { message }
                if message.contains("with_own_block_array") && message.contains("`counters`")),
            "{:?}",
            f.kind
        );
    }
    assert_eq!(counters.iter().sum::<u32>(), 256);
}

/// Stores a record of `len` words at its own slot of two words a pixel.
struct OwnRecord {
    slots: Buf<u32>,
    len: usize,
}

impl FragmentKernel for OwnRecord {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("own-record").with_own_pixel_array(self.slots, 2)
    }
    async fn shade(&self, f: impl Fragment) {
        let words = [f.primitive_id() + 1; 3];
        f.store_record(self.slots, f.pixel_index() * 2, &words[..self.len])
            .await;
    }
}

#[test]
fn a_record_past_its_own_slot_faults_at_the_first_word_outside() {
    let run = |len: usize| {
        let mut dev = Device::new();
        // One spare word, so that the last pixel's third word is in bounds.
        let slots = dev.buffer::<u32>("slots", 16 * 8 * 2 + 1).unwrap();
        let r = draw(&dev, &OwnRecord { slots, len }, &owning());
        (r, dev.memory.read(slots).unwrap())
    };
    // Within the slot: no fault, both words the last fragment's (API order per pixel).
    let (r, words) = run(2);
    assert!(r.faults.is_empty(), "{:?}", r.faults);
    assert!(words[..256].chunks(2).all(|s| s[0] == s[1] && s[0] >= 3));
    // Three words: the first two stored, the third (the next pixel's) a misuse.
    let (r, words) = run(3);
    assert_eq!(r.stats.faulted, 256);
    assert!(r
        .faults
        .iter()
        .all(|f| matches!(&f.kind, FaultKind::Misuse { message }
        if message.contains("with_own_pixel_array"))));
    assert!(words[..256].chunks(2).all(|s| s[0] == s[1] && s[0] >= 3));
    assert_eq!(words[256], 0, "no third word stored");
}
