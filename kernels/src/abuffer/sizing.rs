//! How `ll` sizes its pool from a count pass: a range of the pool and a counter per screen
//! block ([`Blocks`]), and the count of the last draw kept for the next frame of the same
//! draw ([`sized_by_count`]).
//!
//! The llvmpipe peer sizes its pool once, before its timed frames (`oit.py`:
//! `depth_complexity`, untimed): its frame is a clear, the capture and the resolve. A frame
//! of `ll` on a direct executor (ordered, parallel) does the same from its second frame of
//! one draw on: the counts of the last draw (the mesh's positions and triangles, the
//! matrix and the frame size: [`DrawKey`]) are kept, and a frame of the same draw takes
//! them instead of running its count pass again. Under the scheduled executor every frame
//! runs its count pass, so that an exploration schedules every pass.

use std::sync::{Arc, Mutex};

use fragrace_emu::{ExecConfig, ExecMode, PassReport, Values};

use super::run::AbRun;
use crate::algo::{AlgoError, Frame};
use crate::basic::CountKernel;

use super::ll::MAX_POOL_NODES;

/// Words between two blocks' counters: one 64-byte cache line each, so that threads in
/// neighbouring blocks do not share one.
pub const COUNTER_STRIDE: u32 = 16;

/// log2 of a [`Blocks`] block's side in pixels (32).
pub const BLOCK_SHIFT: u32 = 5;

/// The pool cut into screen blocks of `2^BLOCK_SHIFT` pixels a side, row-major: block `b`
/// allocates nodes `[first[b], first[b + 1])` with counter `b * COUNTER_STRIDE` (the sizes
/// are what a count pass counted in the block).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Blocks {
    /// Blocks per row of blocks.
    across: u32,
    /// Prefix sums of the blocks' sizes (one more than the blocks).
    first: Vec<u32>,
}

impl Blocks {
    /// Blocks of a `width` x `height` frame sized by its per-pixel `counts` (row-major),
    /// summed on `threads` threads. Fails when the pool would not fit a buffer.
    pub fn from_counts(
        counts: &[u32],
        width: u32,
        height: u32,
        threads: usize,
    ) -> Result<Blocks, AlgoError> {
        let side = 1u32 << BLOCK_SHIFT;
        let across = width.div_ceil(side);
        let bands: Vec<u32> = (0..height.div_ceil(side)).collect();
        let w = width as usize;
        // Each thread sums whole bands of block rows (4 bands: at least 128 rows apiece).
        let sums = fragrace_emu::sync::pool::map_parts(&bands, threads, 4, |part| {
            let mut out = vec![0u64; part.len() * across as usize];
            for (k, &band) in part.iter().enumerate() {
                let row = &mut out[k * across as usize..(k + 1) * across as usize];
                let y0 = (band << BLOCK_SHIFT) as usize;
                let y1 = (y0 + side as usize).min(height as usize);
                for line in counts[y0 * w..y1 * w].chunks_exact(w) {
                    for (b, run) in line.chunks(side as usize).enumerate() {
                        row[b] += run.iter().map(|&c| u64::from(c)).sum::<u64>();
                    }
                }
            }
            out
        });
        let mut first = Vec::with_capacity(bands.len() * across as usize + 1);
        let mut total = 0u64;
        first.push(0);
        for size in sums.into_iter().flatten() {
            total += size;
            if total > MAX_POOL_NODES {
                return Err(AlgoError::Invalid(format!(
                    "ll: a pool of {total} or more nodes is larger than a buffer can hold"
                )));
            }
            // MAX_POOL_NODES < 2^32: the cast keeps the value.
            first.push(total as u32);
        }
        Ok(Blocks { across, first })
    }

    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.first.len() - 1
    }

    /// Whether there is no block (an empty frame).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Nodes of every block together.
    pub fn total(&self) -> u64 {
        u64::from(*self.first.last().unwrap_or(&0))
    }

    /// The nodes of block `b`: `(first, count)`.
    pub fn range(&self, b: usize) -> (u32, u32) {
        (self.first[b], self.first[b + 1] - self.first[b])
    }

    /// The block of pixel `(x, y)`.
    #[inline]
    pub fn of(&self, x: u32, y: u32) -> usize {
        ((y >> BLOCK_SHIFT) * self.across + (x >> BLOCK_SHIFT)) as usize
    }
}

/// What a count pass of one draw gives `ll`: the per-pixel counts (for the list-length check)
/// and the blocks.
pub struct Sized {
    pub counts: Values<u32>,
    pub blocks: Blocks,
}

/// What a draw's count is computed from: the frame's matrix and size, and the mesh (its
/// vertex and triangle counts and a hash of its positions' and indices' bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrawKey {
    matrix: [u32; 16],
    size: (u32, u32),
    vertices: usize,
    triangles: usize,
    hash: [u64; 4],
}

impl DrawKey {
    /// The key of `frame`'s draw.
    pub fn of(frame: &Frame<'_>) -> DrawKey {
        let mesh = frame.mesh;
        // Four independent lanes (word `i` of a run into lane `i % 4`) so that the
        // multiplies overlap; each step is a bijection of a lane's state for a given word,
        // so two inputs that differ in one word always hash differently.
        const K: u64 = 0x517c_c1b7_2722_0a95;
        let mix = |h: u64, w: u64| (h.rotate_left(5) ^ w).wrapping_mul(K);
        let mut lanes = [0u64; 4];
        for quad in mesh.positions.chunks(4) {
            for (lane, p) in lanes.iter_mut().zip(quad) {
                let xy = u64::from(p.x.to_bits()) | (u64::from(p.y.to_bits()) << 32);
                *lane = mix(mix(*lane, xy), u64::from(p.z.to_bits()));
            }
        }
        for quad in mesh.indices.chunks(4) {
            for (lane, t) in lanes.iter_mut().zip(quad) {
                let ab = u64::from(t[0]) | (u64::from(t[1]) << 32);
                *lane = mix(mix(*lane, ab), u64::from(t[2]));
            }
        }
        DrawKey {
            matrix: frame.view_proj.to_cols_array().map(f32::to_bits),
            size: (frame.width, frame.height),
            vertices: mesh.positions.len(),
            triangles: mesh.indices.len(),
            hash: lanes,
        }
    }
}

/// The last draw's count. Plain `std` mutex: bookkeeping outside the modelled protocols.
static LAST: Mutex<Option<(DrawKey, Arc<Sized>)>> = Mutex::new(None);

/// The counts and blocks of `run`'s frame: the last draw's when it was the same draw and
/// the executor is a direct one, otherwise from a count pass (whose report is merged into
/// `report`), kept for the next frame.
pub fn sized_by_count(
    run: &mut AbRun<'_>,
    report: &mut PassReport,
) -> Result<Arc<Sized>, AlgoError> {
    let exec: &ExecConfig = run.exec;
    let reuse = !matches!(exec.mode, ExecMode::Scheduled(_));
    let key = DrawKey::of(&run.frame);
    if reuse {
        let last = LAST.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, sized)) = last.as_ref() {
            if *k == key {
                // The kept counts are this frame's count buffer: its storage still.
                run.kept_bytes += sized.counts.len() as u64 * 4;
                return Ok(Arc::clone(sized));
            }
        }
    }
    let counts = run.device.buffer::<u32>("ll-counts", run.n as u64)?;
    report.merge(&run.capture(&CountKernel { counts })?);
    let counts = run.device.memory.take(counts)?;
    let blocks = Blocks::from_counts(&counts, run.frame.width, run.frame.height, exec.threads)?;
    let sized = Arc::new(Sized { counts, blocks });
    if reuse {
        *LAST.lock().unwrap_or_else(|e| e.into_inner()) = Some((key, Arc::clone(&sized)));
    }
    Ok(sized)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_hold_exactly_their_pixels_counts() {
        // 70 x 40 pixels: blocks of 32 cut both sides unevenly (3 x 2 blocks).
        let (w, h) = (70u32, 40u32);
        let counts: Vec<u32> = (0..w * h).map(|p| (p * 7 + p / 13) % 5).collect();
        for threads in [1, 3] {
            let b = Blocks::from_counts(&counts, w, h, threads).unwrap();
            assert_eq!(b.len(), 6);
            let mut want = [0u32; 6];
            for y in 0..h {
                for x in 0..w {
                    let k = b.of(x, y);
                    assert_eq!(k as u32, (y / 32) * 3 + x / 32);
                    want[k] += counts[(y * w + x) as usize];
                }
            }
            let mut next = 0;
            for (k, &n) in want.iter().enumerate() {
                assert_eq!(b.range(k), (next, n), "block {k}, {threads} threads");
                next += n;
            }
            assert_eq!(b.total(), u64::from(next));
            assert_eq!(b.total(), counts.iter().map(|&c| u64::from(c)).sum::<u64>());
        }
    }

    #[test]
    fn a_changed_vertex_index_matrix_or_size_changes_the_key() {
        use fragrace_emu::Mesh;
        use glam::{Mat4, Vec3};
        let mesh = Mesh {
            positions: (0..9).map(|i| Vec3::splat(i as f32 * 0.5)).collect(),
            normals: None,
            indices: vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]],
        };
        let frame = |mesh: &Mesh, m: Mat4, w: u32| {
            DrawKey::of(&Frame {
                mesh,
                objects: &[],
                view_proj: m,
                width: w,
                height: 8,
            })
        };
        let m = Mat4::from_scale(Vec3::splat(2.0));
        let key = frame(&mesh, m, 8);
        assert_eq!(key, frame(&mesh.clone(), m, 8));
        assert_ne!(key, frame(&mesh, Mat4::IDENTITY, 8));
        assert_ne!(key, frame(&mesh, m, 9));
        for i in 0..mesh.positions.len() {
            let mut q = mesh.clone();
            q.positions[i].y = f32::from_bits(q.positions[i].y.to_bits() ^ 1);
            assert_ne!(key, frame(&q, m, 8), "vertex {i}");
        }
        let mut q = mesh.clone();
        q.indices[1] = [3, 5, 4];
        assert_ne!(key, frame(&q, m, 8));
    }
}
