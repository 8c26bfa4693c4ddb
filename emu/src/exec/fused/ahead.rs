//! What the fused path's shading loops prefetch a few covered runs ahead of the one they
//! shade ([`Ahead`]): a thread shades one fragment at a time, so the latency a GPU hides by
//! running other warps meanwhile is hidden by asking for the lines early.

use crate::invocation::PassEnv;
use crate::memory::{PixelArray, PixelPrefetcher};
use crate::raster::{SetupTriangle, Span};

/// Covered runs ahead of the one being shaded whose per-pixel slots are prefetched: far
/// enough for a miss to the last-level cache to land (about a dozen fragments of a dense
/// mesh), near enough for the line to still be there.
const PREFETCH_SPANS: usize = 8;

/// What a shading loop prefetches [`PREFETCH_SPANS`] covered runs ahead
/// ([`Ahead::of`]).
pub(super) struct Ahead<'e> {
    slots: Option<PixelPrefetcher<'e>>,
    /// The unit's setup records; empty when the kernel reads no interpolant.
    records: &'e [SetupTriangle],
}

/// Prefetches, for the covered run [`PREFETCH_SPANS`] after run `i` (runs are short on
/// dense meshes, and the hardware prefetcher follows a long one), the per-pixel slot of its
/// first pixel and its triangle's setup record. A binned pass over a large mesh sets up
/// every triangle before shading any, so a record is read from memory when its first
/// fragment interpolates its depth: on the 871K dragon at 2048 x 2048, binned, a third of
/// `ll`'s insert loop waited for it (`perf annotate`).
#[inline(always)]
pub(super) fn prefetch_ahead(ahead: &Ahead<'_>, spans: &[Span], i: usize) {
    if let Some(s) = spans.get(i + PREFETCH_SPANS) {
        if let Some(p) = &ahead.slots {
            p.pixel(s.x0, s.y);
        }
        // Full-screen runs have no record (`tri` is `u32::MAX`).
        if let Some(t) = ahead.records.get(s.tri as usize) {
            crate::hint::prefetch(t);
        }
    }
}

impl<'e> Ahead<'e> {
    /// What a unit's loop prefetches: the slots of the kernel's per-pixel array `array`
    /// (`None`: no hint, or no such buffer) and the setup records of a kernel that reads
    /// interpolants (`Fragment::depth` evaluates the plane of the fragment's record).
    #[inline]
    pub(super) fn of(array: Option<PixelArray>, env: &PassEnv<'e>) -> Ahead<'e> {
        Ahead {
            slots: array.and_then(|a| env.memory.pixel_prefetcher(a, env.width)),
            records: if env.no_interpolants { &[] } else { env.tris },
        }
    }
}
