//! Triangle setup (snap to fixed point, edge functions, planes) and tile binning.
//!
//! Pipeline of [`bin_triangles`], each step parallel over `threads` threads
//! (`sync::pool::broadcast`):
//! 1. every vertex is classified against the clip planes once and, when inside all of them,
//!    snapped to 8-bit sub-pixel fixed point (a vertex shared by many triangles is projected
//!    once, and shared vertices are bit-identical in all of them: the basis of watertightness);
//! 2. triangles, in chunks: the snapped bounding box is tested for a sample first (most
//!    triangles of a dense mesh are sub-pixel and end here), then area, facing and culling, an
//!    exact sample test for tiny ones, the depth and barycentric planes, and the tile bins.
//!    Triangles with a vertex outside a plane go through homogeneous clipping ([`super::clip`]);
//! 3. chunk results are concatenated in chunk order, so setup indices follow API order; each
//!    chunk keeps its own per-tile lists (a stable counting sort done by its worker), and
//!    [`Binned::raster_tile`] walks the chunks in order.
//!
//! Step 1 is [`prepare`]; steps 2 and 3 are [`Prepared::bin`]. [`Prepared::setup_flat`] runs
//! step 2's setup code on one chunk without bins, its covered runs coming out of setup
//!
//! Files: this one (the steps' drivers and limits), `triangle` (setup records and planes),
//! `ctx` (step 2, per chunk), `bins` (tile bins and their walk), `prepared` (step 1's
//! result, binned or set up flat).

mod bins;
mod ctx;
mod prepared;
mod triangle;

pub use bins::{Binned, PlaneSetup, Segment};
pub use prepared::{prepare, prepare_projected, FlatChunk, Prepared, Projected};
pub use triangle::SetupTriangle;

use bins::*;
use ctx::*;
use prepared::*;
use triangle::*;

use super::clip::{Planes, NON_FINITE};
use super::{RasterState, Viewport};
use glam::Vec4;

/// Largest magnitude of a snapped coordinate (sub-pixel units). The guard band keeps real
/// coordinates below 2^28; the clamp only makes absurd inputs (viewports wider than the guard
/// band) harmless.
const COORD_LIMIT: f64 = (1u32 << 29) as f64;

/// Largest viewport side handled (pixels); pixels beyond are never covered.
const MAX_VIEWPORT: u32 = 1 << 20;

/// Runs `f(i)` for `i in 0..n` on up to `threads` threads (the calling thread included),
/// item `i` going to thread `i % threads`, and returns the results in index order.
fn par_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = threads.clamp(1, n.max(1));
    if threads == 1 {
        return (0..n).map(f).collect();
    }
    let f = &f;
    let work = move |k: usize| {
        (k..n)
            .step_by(threads)
            .map(|i| (i, f(i)))
            .collect::<Vec<_>>()
    };
    let mut parts: Vec<Vec<(usize, T)>> = crate::sync::pool::broadcast(threads, work);
    let mut slots: Vec<Option<T>> = (0..n).map(|_| None).collect();
    for part in parts.iter_mut() {
        for (i, t) in part.drain(..) {
            slots[i] = Some(t);
        }
    }
    slots
        .into_iter()
        .map(|t| t.expect("every item computed"))
        .collect()
}

/// Step 1 for a slice of vertices.
fn project_vertices(
    planes: &Planes,
    xf: &Xform,
    src: &[Vec4],
    xy: &mut [[i32; 2]],
    zw: &mut [[f32; 2]],
) -> bool {
    let mut non_finite = false;
    for ((xy, zw), &p) in xy.iter_mut().zip(zw.iter_mut()).zip(src) {
        // Finite as f32 iff finite as f64: tested on the f32 bits (exponent not all ones),
        // a few instructions for the four instead of a few each.
        let finite = p.to_array().iter().fold(true, |ok, c| {
            ok & (c.to_bits() & 0x7f80_0000 != 0x7f80_0000)
        });
        non_finite |= !finite;
        let p = vec4_f64(p);
        let oc = if finite {
            planes.outcode_finite(&p)
        } else {
            NON_FINITE
        };
        if oc != 0 {
            *xy = [OUT, oc as i32];
            *zw = [0.0; 2];
        } else {
            let s = xf.project(&p);
            *xy = [s.x, s.y];
            *zw = [s.z, s.iw];
        }
    }
    non_finite
}

/// The tile size used for a requested one: rounded up to a power of two within
/// [`MIN_TILE`]..=[`MAX_TILE`] (so tile coordinates are shifts, and a pixel's position in its
/// tile fits in a byte of a bin entry).
pub fn effective_tile_size(requested: u32) -> u32 {
    requested.clamp(MIN_TILE, MAX_TILE).next_power_of_two()
}

/// Smallest tile size.
pub const MIN_TILE: u32 = 8;
/// Largest tile size.
pub const MAX_TILE: u32 = 256;

/// Clips, culls, snaps and bins triangles, with their planes ([`bin_triangles_with`] and
/// [`PlaneSetup::Compute`]). Uses up to `threads` threads.
pub fn bin_triangles(
    positions: &[Vec4],
    indices: &[[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
) -> Binned {
    bin_triangles_with(
        positions,
        indices,
        state,
        viewport,
        threads,
        PlaneSetup::Compute,
    )
}

/// Clips, culls, snaps and bins triangles. Uses up to `threads` threads.
/// `positions` are clip-space vertex positions, `indices` the triangles in API order.
/// Triangles with a NaN or infinite coordinate are dropped (and counted in [`Binned::rejected`]),
/// so are triangles with an index out of range (the caller should validate meshes first).
pub fn bin_triangles_with(
    positions: &[Vec4],
    indices: &[[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
    plane_setup: PlaneSetup,
) -> Binned {
    prepare(positions, indices, state, viewport, threads, plane_setup).bin(threads)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_fixed_is_round_half_up_and_clamped() {
        assert_eq!(round_fixed(0.49), 0);
        assert_eq!(round_fixed(0.5), 1);
        assert_eq!(round_fixed(-0.5), 0);
        assert_eq!(round_fixed(-0.51), -1);
        assert_eq!(round_fixed(-1.5), -1);
        assert_eq!(round_fixed(1e300), COORD_LIMIT as i32);
        assert_eq!(round_fixed(-1e300), -(COORD_LIMIT as i32));
        assert_eq!(round_fixed(f64::NAN), -(COORD_LIMIT as i32));
    }

    #[test]
    fn planes_are_order_independent() {
        let v = [[100, 7], [900, 300], [-50, 800]];
        let a = [
            [0.25f32, 1.0, 0.0, 0.0],
            [0.75, 0.0, 0.5, 0.0],
            [0.5, 0.0, 0.0, 2.0],
        ];
        let p = planes(&v, &a, 0, 0);
        let q = planes(&[v[2], v[0], v[1]], &[a[2], a[0], a[1]], 0, 0);
        assert_eq!(p, q);
    }

    #[test]
    fn plane_values_match_scalar() {
        let mut seed = 3u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let m = ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 4.0;
            // Zeros of both signs too (their sign survives into the planes).
            match seed % 7 {
                0 => 0.0,
                1 => -0.0,
                _ => m * 10f64.powi((seed >> 3) as i32 % 9 - 4),
            }
        };
        for _ in 0..20000 {
            let a: [[f32; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rnd() as f32));
            let c: [f64; 6] = std::array::from_fn(|_| rnd());
            let (p, q) = (
                plane_values([&a[0], &a[1], &a[2]], c),
                plane_values_scalar([&a[0], &a[1], &a[2]], c),
            );
            assert_eq!(
                p.map(|p| p.map(f32::to_bits)),
                q.map(|q| q.map(f32::to_bits))
            );
        }
    }

    #[test]
    fn setup_triangle_is_compact() {
        assert_eq!(std::mem::size_of::<SetupTriangle>(), 64);
    }
}
