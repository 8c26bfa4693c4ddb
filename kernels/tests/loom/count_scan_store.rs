//! Count-scan-store A-buffers: DFB and the S-buffer.

use fragrace_emu::kernel::FragInput;
use fragrace_emu::{Device, Fragment};
use fragrace_kernels::common::EMPTY;
use fragrace_kernels::protocols::*;

use super::common::*;

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
