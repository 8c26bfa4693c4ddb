//! The machine's floor under a frame of `count`: what its atomic adds cost with nothing
//! around them (no rasterizer, no kernel, no executor), on the same threads.
//!
//! `fragrace bench` measures a frame; this measures the part no implementation of the frame
//! can avoid, so that the frame's time splits into what the machine charges for the
//! kernel's atomics and what fragrace adds. The adds are the frame's own: every pixel gets
//! as many `fetch_add(1, AcqRel)` as its count (the fragments that covered it), into one
//! word per pixel, tile by tile (the tiles handed out to the threads as the executor
//! does). Inside a tile they go in the cheapest order we know, planned before the timing:
//! layer by layer (every covered pixel once, row-major, then every pixel covered twice once
//! more, ...), so that consecutive adds go to consecutive words and none waits for the one
//! before it on the same word (an earlier replay took each pixel's adds in a row and
//! scanned every pixel of the frame for its count, which charged the floor for both).

use std::time::Instant;

use fragrace_emu::memory::zeroed_u32;
use fragrace_emu::sync::pool::{broadcast, map_parts};
use fragrace_emu::sync::split::SplitRange;
use fragrace_emu::sync::{AtomicU32, Ordering};
use fragrace_kernels::common::SUM_MIN_PER_THREAD;

/// The floor of one frame, in milliseconds (medians over the frames timed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// The atomic adds alone, into a buffer already allocated and zeroed.
    pub atomics_ms: f64,
    /// A fresh zeroed buffer of one word per pixel and the adds: the part of the `count`
    /// frame that is memory and atomics (the sum read back to check them is untimed, as
    /// the frame's self-check).
    pub frame_ms: f64,
}

/// What to replay.
pub struct FloorConfig<'a> {
    /// Per-pixel counts of a frame (row-major, `width * height`).
    pub counts: &'a [u32],
    pub width: u32,
    pub height: u32,
    /// Square tile size in pixels (the rasterizer's).
    pub tile: u32,
    pub threads: usize,
    /// Frames timed (the median is reported).
    pub frames: usize,
}

/// Measures the floor of the frame whose counts are `cfg.counts`. Returns `None` when the
/// counts do not match the size (or, which would be a bug, when the sum read back is not
/// the sum of the counts).
pub fn count_floor(cfg: &FloorConfig<'_>) -> Option<Floor> {
    let pixels = cfg.width as usize * cfg.height as usize;
    if cfg.counts.len() != pixels || cfg.tile == 0 {
        return None;
    }
    let frames = cfg.frames.max(1);
    let expected: u64 = cfg.counts.iter().map(|&c| u64::from(c)).sum();
    let plan = Plan::new(cfg, expected);
    let warm = zeroed_u32(pixels, cfg.threads);
    let mut atomics = Vec::with_capacity(frames);
    let mut frame = Vec::with_capacity(frames);
    for _ in 0..frames {
        for w in warm.iter() {
            w.store(0, Ordering::Relaxed);
        }
        let t = Instant::now();
        replay(&plan, cfg.threads, &warm);
        atomics.push(t.elapsed().as_secs_f64() * 1e3);

        let t = Instant::now();
        let fresh = zeroed_u32(pixels, cfg.threads);
        replay(&plan, cfg.threads, &fresh);
        frame.push(t.elapsed().as_secs_f64() * 1e3);
        // Read back, untimed as the frame's check (on the same threads and in the same parts:
        // `fragrace_kernels::common::parallel_sum`).
        let sum: u64 = map_parts(&fresh, cfg.threads, SUM_MIN_PER_THREAD, |part| {
            part.iter()
                .map(|w| u64::from(w.load(Ordering::Relaxed)))
                .sum::<u64>()
        })
        .into_iter()
        .sum();
        drop(fresh);
        // The replay is exact: a floor that dropped adds would be no floor.
        if sum != expected {
            return None;
        }
    }
    Some(Floor {
        atomics_ms: median(&mut atomics),
        frame_ms: median(&mut frame),
    })
}

/// The words each tile adds to, in the order replayed: `order[starts[t]..starts[t + 1]]`
/// for tile `t` (one entry per add).
struct Plan {
    order: Vec<u32>,
    starts: Vec<usize>,
}

impl Plan {
    /// The plan of `cfg`'s counts, which add up to `total`.
    fn new(cfg: &FloorConfig<'_>, total: u64) -> Plan {
        let (w, h, ts) = (cfg.width, cfg.height, cfg.tile);
        let mut order = Vec::with_capacity(usize::try_from(total).unwrap_or(0));
        let mut starts = vec![0];
        for ty in (0..h).step_by(ts as usize) {
            for tx in (0..w).step_by(ts as usize) {
                let pixels = || {
                    (ty..(ty + ts).min(h))
                        .flat_map(move |y| (tx..(tx + ts).min(w)).map(move |x| y * w + x))
                };
                let layers = pixels().map(|p| cfg.counts[p as usize]).max().unwrap_or(0);
                for layer in 0..layers {
                    order.extend(pixels().filter(|&p| cfg.counts[p as usize] > layer));
                }
                starts.push(order.len());
            }
        }
        Plan { order, starts }
    }
}

/// The planned adds, tile by tile, on `threads` threads.
fn replay(plan: &Plan, threads: usize, words: &[AtomicU32]) {
    let tiles = plan.starts.len() - 1;
    let threads = threads.max(1);
    let queue = SplitRange::new(tiles, threads);
    broadcast(threads, |me| {
        while let Some(t) = queue.next(me) {
            for &p in &plan.order[plan.starts[t]..plan.starts[t + 1]] {
                words[p as usize].fetch_add(1, Ordering::AcqRel);
            }
        }
    });
}

/// The median of timings (the upper one of an even count); sorts `v`.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_replays_every_add_on_any_thread_count() {
        let (w, h) = (37, 23);
        let counts: Vec<u32> = (0..w * h).map(|i| i * 7 % 5).collect();
        for threads in [1, 3] {
            let cfg = FloorConfig {
                counts: &counts,
                width: w,
                height: h,
                tile: 8,
                threads,
                frames: 2,
            };
            // `None` if the sum read back differs from the counts' (or the sizes differ).
            let f = count_floor(&cfg).expect("every add replayed");
            assert!(f.atomics_ms >= 0.0 && f.frame_ms >= 0.0);
        }
    }

    #[test]
    fn floor_refuses_counts_of_another_size() {
        let counts = vec![1u32; 10];
        let cfg = FloorConfig {
            counts: &counts,
            width: 4,
            height: 4,
            tile: 8,
            threads: 1,
            frames: 1,
        };
        assert!(count_floor(&cfg).is_none());
    }
}
