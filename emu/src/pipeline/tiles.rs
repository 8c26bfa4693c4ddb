//! The fixed-function stages of one tile: rasterization and early tests before shading
//! ([`RasterFront`]), late tests, blending and writes after ([`RasterBack`]), in API order.

use crate::exec::fused::{block_end, FusedCounts, Untouched};
use crate::exec::FragOut;
use crate::framebuffer::TileMemory;
use crate::kernel::FragInput;
use crate::state::FragmentState;
use crate::sync::pool;

use super::touched::{BlockMask, BLOCK_SHIFT};
use super::waves::Geometry;

/// Runs `f` on every (tile, item) pair with up to `threads` threads; returns the results
/// in tile order.
pub(super) fn for_each_tile<T: Send, R: Send + Default + Clone>(
    tiles: &mut [TileMemory],
    items: &mut [T],
    threads: usize,
    f: impl Fn(usize, &mut TileMemory, &mut T) -> R + Sync,
) -> Vec<R> {
    let n = tiles.len();
    let mut results = vec![R::default(); n];
    let threads = threads.max(1).min(n.max(1));
    if threads == 1 {
        for (i, ((t, it), r)) in tiles
            .iter_mut()
            .zip(items.iter_mut())
            .zip(results.iter_mut())
            .enumerate()
        {
            *r = f(i, t, it);
        }
        return results;
    }
    let work: Vec<(usize, &mut TileMemory, &mut T, &mut R)> = tiles
        .iter_mut()
        .zip(items.iter_mut())
        .zip(results.iter_mut())
        .enumerate()
        .map(|(i, ((t, it), r))| (i, t, it, r))
        .collect();
    let queue = pool::Mutex::new(work.into_iter());
    pool::broadcast(threads, |_| loop {
        let next = queue.lock().unwrap_or_else(|e| e.into_inner()).next();
        let Some((i, t, it, r)) = next else { break };
        *r = f(i, t, it);
    });
    results
}

/// Rasterization and early tests of one tile.
pub(super) struct RasterFront<'a> {
    pub(super) geo: &'a Geometry<'a>,
    pub(super) state: &'a FragmentState,
    pub(super) early: bool,
    pub(super) samples: u32,
    /// Geometry: the device's coverage mask, in which the rasterizer's fragments mark their
    /// blocks before any test or sample mask, as the fused path marks its covered runs.
    pub(super) marks: Option<&'a BlockMask>,
    /// Full screen: the blocks no geometry reached and the kernel's declared output there
    /// (`KernelInfo::untouched_output`; only where the pass tests nothing and covers a
    /// sample: `fused::fullscreen_fuses`). Their pixels get the output, written as the
    /// fused path writes it ([`Untouched`]), instead of an invocation.
    pub(super) skip: Option<(&'a BlockMask, [u32; 4])>,
    pub(super) targets: usize,
}

impl RasterFront<'_> {
    /// Returns the counts of fragments generated, early-culled and, full screen, of the
    /// invocations skipped (with their samples, as passed).
    pub(super) fn tile(
        &self,
        tile_index: usize,
        tile: &mut TileMemory,
        list: &mut Vec<FragInput>,
    ) -> FusedCounts {
        let mut counts = FusedCounts::default();
        let mut generated = 0u64;
        let mut culled = 0u64;
        let ts = tile.tile_size;
        // Tickets: per-pixel rank among shaded fragments (ordered interlock).
        let mut tickets = vec![0u32; (ts * ts) as usize];
        let tests = self.early && (self.state.depth.test || self.state.stencil.enabled);
        let all = if self.samples >= 8 {
            0xff
        } else {
            (1u8 << self.samples) - 1
        };
        let sample_mask = self.state.sample_mask & all;
        match self.geo {
            Geometry::Binned {
                binned,
                instance,
                first,
                single,
            } => {
                let positions = crate::raster::SampleCount::from_count(self.samples)
                    .map(|c| c.positions())
                    .unwrap_or(&[(0.5, 0.5)]);
                let per_sample_depth = self.samples > 1 && !*single;
                // The block last marked (fragments come in runs along rows).
                let mut marked = (u32::MAX, u32::MAX);
                binned.raster_tile(tile_index, |f| {
                    if let Some(mask) = self.marks {
                        let block = (f.x >> BLOCK_SHIFT, f.y >> BLOCK_SHIFT);
                        if block != marked {
                            mask.mark_run(f.y, f.x, f.x + 1);
                            marked = block;
                        }
                    }
                    let f_cov = if *single && f.coverage & 1 != 0 {
                        all
                    } else {
                        f.coverage
                    };
                    let cov = f_cov & sample_mask;
                    if cov == 0 {
                        return;
                    }
                    generated += 1;
                    let t = binned.tris.get(f.tri as usize);
                    let (fx, fy) = (f.x as f32, f.y as f32);
                    // No planes: nothing reads a depth (no depth test, no interpolants).
                    let depth = t.map_or(f32::NAN, |t| t.depth_at(fx + 0.5, fy + 0.5));
                    let (lx, ly) = (f.x - tile.x0, f.y - tile.y0);
                    let mut cov = cov;
                    if tests {
                        let mut depths = [depth; 8];
                        if let (true, Some(t)) = (per_sample_depth, t) {
                            for (s, p) in positions.iter().enumerate() {
                                depths[s] = t.depth_at(fx + p.0, fy + p.1);
                            }
                        }
                        cov = tile.depth_stencil(
                            self.state,
                            lx,
                            ly,
                            cov,
                            &depths,
                            f.front_facing,
                            true,
                        );
                        if cov == 0 {
                            culled += 1;
                            return;
                        }
                    }
                    let slot = &mut tickets[(ly * ts + lx) as usize];
                    let ticket = *slot;
                    *slot += 1;
                    list.push(FragInput {
                        seq: 0,
                        x: f.x,
                        y: f.y,
                        tri: f.tri,
                        primitive_id: f.source + *first,
                        instance_id: *instance,
                        coverage: cov,
                        front_facing: f.front_facing,
                        depth,
                        ticket,
                    });
                });
            }
            Geometry::Unbinned { .. } => {
                unreachable!("unbinned geometry runs on the fused path only (Device::draw)")
            }
            Geometry::FullScreen => {
                let untouched = self.skip.map(|(mask, bits)| {
                    let untouched = Untouched {
                        state: self.state,
                        cov: sample_mask,
                        bits,
                        targets: self.targets.min(8),
                    };
                    (mask, untouched)
                });
                if let Some((mask, untouched)) = untouched {
                    if untouched.fast_clear(tile, mask, &mut counts) {
                        return counts;
                    }
                }
                for ly in 0..tile.h {
                    let mut lx = 0;
                    while lx < tile.w {
                        // The pixels up to the next block boundary: skipped together or run.
                        let end = block_end(tile.x0, lx, tile.w);
                        if let Some((mask, untouched)) = untouched {
                            let (bx, by) =
                                ((tile.x0 + lx) >> BLOCK_SHIFT, (tile.y0 + ly) >> BLOCK_SHIFT);
                            if !mask.touched(bx, by) {
                                untouched.skip_run(tile, ly, lx..end, &mut counts);
                                lx = end;
                                continue;
                            }
                        }
                        let run = lx..end;
                        lx = end;
                        for lx in run {
                            // Full-screen invocations are not rasterized fragments: not counted as generated.
                            let mut cov = sample_mask;
                            if tests {
                                cov = tile
                                    .depth_stencil(self.state, lx, ly, cov, &[0.5; 8], true, true);
                                if cov == 0 {
                                    culled += 1;
                                    continue;
                                }
                            }
                            list.push(FragInput {
                                seq: 0,
                                x: tile.x0 + lx,
                                y: tile.y0 + ly,
                                tri: u32::MAX,
                                primitive_id: 0,
                                instance_id: 0,
                                coverage: cov,
                                front_facing: true,
                                depth: 0.5,
                                ticket: 0,
                            });
                        }
                    }
                }
            }
        }
        counts.generated += generated;
        counts.early_culled += culled;
        counts
    }
}

/// Late tests and target writes of one tile.
pub(super) struct RasterBack<'a> {
    pub(super) geo: &'a Geometry<'a>,
    pub(super) state: &'a FragmentState,
    pub(super) early: bool,
    pub(super) samples: u32,
    pub(super) targets: usize,
}

impl RasterBack<'_> {
    /// Returns (late-culled fragments, samples passed).
    pub(super) fn tile(
        &self,
        tile: &mut TileMemory,
        (ins, outs, colors): &mut (&[FragInput], &[FragOut], &[[u32; 4]]),
    ) -> (u64, u64) {
        let mut culled = 0;
        let mut passed_samples = 0u64;
        let late_tests = !self.early && (self.state.depth.test || self.state.stencil.enabled);
        let positions = crate::raster::SampleCount::from_count(self.samples)
            .map(|c| c.positions())
            .unwrap_or(&[(0.5, 0.5)]);
        for (i, (f, o)) in ins.iter().zip(outs.iter()).enumerate() {
            if o.faulted || o.discarded {
                continue;
            }
            let (lx, ly) = (f.x - tile.x0, f.y - tile.y0);
            let mut mask = f.coverage;
            if late_tests {
                let mut depths = [o.depth.unwrap_or(f.depth); 8];
                if o.depth.is_none() && self.samples > 1 {
                    if let Geometry::Binned {
                        binned,
                        single: false,
                        ..
                    } = self.geo
                    {
                        let t = &binned.tris[f.tri as usize];
                        for (s, p) in positions.iter().enumerate() {
                            depths[s] = t.depth_at(f.x as f32 + p.0, f.y as f32 + p.1);
                        }
                    }
                }
                mask = tile.depth_stencil(self.state, lx, ly, mask, &depths, f.front_facing, true);
                if mask == 0 {
                    culled += 1;
                    continue;
                }
            }
            passed_samples += mask.count_ones() as u64;
            if self.targets > 0 {
                tile.write_outputs(
                    self.state,
                    lx,
                    ly,
                    mask,
                    &colors[i * self.targets..(i + 1) * self.targets],
                );
            }
        }
        (culled, passed_samples)
    }
}
