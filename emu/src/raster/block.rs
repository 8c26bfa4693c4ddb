//! Coverage of small triangles a block of pixels at a time: the samples of up to 4x4 (or
//! 8x8) pixels tested against the three edge functions at once (SSE2 on x86_64, a scalar
//! loop elsewhere), with the same integer edge functions and fill rule as
//! [`super::coverage`], so the same samples are covered.

#[cfg(any(test, not(target_arch = "x86_64")))]
use super::coverage::is_top_left;
use super::coverage::{bbox, Edges, SampleInfo, ONE};
use super::SUBPIXEL_BITS;

/// Largest bounding box extent (sub-pixel units, exclusive) of a triangle that
/// [`block_mask`] takes: a box narrower than 5 pixels reaches the samples of at most 4
/// columns of pixels. A triangle whose pixel rectangle is at most 4x4 and was not clamped
/// to the viewport has such a box ([`block_fits`]).
// Read by the SSE2 block tests' debug checks (and their docs) only.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) const BLOCK_EXTENT: i32 = 5 * ONE;

/// [`BLOCK_EXTENT`] for [`block_mask8`]: a box narrower than 9 pixels.
// As BLOCK_EXTENT.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) const BLOCK8_EXTENT: i32 = 9 * ONE;

/// Whether a one-sample triangle with pixel rectangle `r` (at most 8x8, inside a viewport
/// of `w` x `h` pixels) can take [`block_mask`] or [`block_mask8`]: `r` touches no viewport
/// border, so it was not clamped, and the box it came from ([`SampleInfo::pixel_rect`]: at
/// most `n ONE + ONE - 1` wide for `n + 1` columns of pixel centres) is below
/// [`BLOCK_EXTENT`] (at most 4x4) or [`BLOCK8_EXTENT`]. Four comparisons, where the box's
/// extent took a dozen instructions to recompute.
#[inline(always)]
pub(crate) fn block_fits(r: [i32; 4], w: i32, h: i32) -> bool {
    (r[0] > 0) & (r[1] > 0) & (r[2] < w - 1) & (r[3] < h - 1)
}

/// Bit mask of the pixels of the inclusive rectangle `r` (at most 8x8) in a block mask:
/// bit `8 j + i` is pixel `(r[0] + i, r[1] + j)`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn rect_bits(r: [i32; 4]) -> u64 {
    let cols = (1u64 << (r[2] - r[0] + 1)) - 1;
    let rows = (r[3] - r[1] + 1) as u32;
    let all = cols * 0x0101_0101_0101_0101;
    // `rows` is 1..=8: shifting by 64 would overflow.
    all & (u64::MAX >> (64 - 8 * rows))
}

/// One-sample coverage of the pixels of the inclusive rectangle `r`, at most 4x4 pixels:
/// bit `8 j + i` is pixel `(r[0] + i, r[1] + j)` (the layout of [`block_mask8`]), for a
/// positively oriented triangle whose bounding box is less than [`BLOCK_EXTENT`] wide and
/// high. The same edge functions as [`raster`], evaluated exactly relative to the block's
/// first sample: the vertices lie within 2 [`BLOCK_EXTENT`] of it and the edge deltas below
/// [`BLOCK_EXTENT`], so the products that make up an edge function and its values at the
/// 16 samples stay below 2^24 in magnitude, which lets the block be evaluated as 16
/// independent `i32` lanes, and the products be taken in `f32` (exact below 2^24) where
/// SSE2 has no 32-bit multiply.
///
/// The bound is on the box, not on `r`: `r` is clamped to the viewport, so a small `r` can
/// belong to a sliver reaching far off screen, whose edge functions need [`Edges`]' `i64`.
///
/// On x86_64 the whole test is SSE2, one register per edge and row of four samples, with no
/// scalar setup: the three edges are set up side by side in the lanes of one register and
/// then spread out ([`BlockEdges`]). A 4x4 block took 218 instructions with a scalar setup
/// (callgrind, the 871K dragon @2048); now about 115, its selection included.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn block_mask(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> u64 {
    use std::arch::x86_64::{_mm_movemask_epi8, _mm_packs_epi16, _mm_packs_epi32};
    debug_check_block(v, si, r, 4, BLOCK_EXTENT);
    let mut e = BlockEdges::new(v, si, r);
    // SAFETY: SSE2 only (x86_64 baseline); no memory is touched.
    let outside = unsafe {
        let (r0, r1, r2, r3) = (e.row(), e.row(), e.row(), e.row());
        // Sign-preserving packs: each row's four lanes, then four zero lanes (the block's
        // columns 4..8, masked off below), so that row `j` lands in byte `j`'s low bits.
        let z = std::arch::x86_64::_mm_setzero_si128();
        let lo = _mm_packs_epi16(_mm_packs_epi32(r0, z), _mm_packs_epi32(r1, z));
        let hi = _mm_packs_epi16(_mm_packs_epi32(r2, z), _mm_packs_epi32(r3, z));
        (_mm_movemask_epi8(lo) as u32 as u64) | (_mm_movemask_epi8(hi) as u32 as u64) << 16
    };
    !outside & rect_bits(r)
}

/// [`block_mask`] for rectangles of at most 8x8 pixels, of triangles whose bounding box is
/// less than [`BLOCK8_EXTENT`] wide and high: two registers per edge and row, eight columns.
/// The bound keeps the products and the 64 samples' edge functions below 2^24 (the
/// vertices lie within 2 [`BLOCK8_EXTENT`] of the first sample, the edge deltas below
/// [`BLOCK8_EXTENT`]). Most triangles too large for [`block_mask`] on a dense mesh are of
/// this size (95 % on the 871K dragon @2048); row by row, with three exact divisions a row,
/// they took about twice the instructions.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn block_mask8(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> u64 {
    use std::arch::x86_64::{
        _mm_add_epi32, _mm_movemask_epi8, _mm_packs_epi16, _mm_packs_epi32, _mm_slli_epi32,
    };
    debug_check_block(v, si, r, 8, BLOCK8_EXTENT);
    let mut lo = BlockEdges::new(v, si, r);
    // SAFETY: SSE2 only (x86_64 baseline); no memory is touched.
    let outside = unsafe {
        // Columns 4..8: four steps along the row further.
        let right = |e, s| _mm_add_epi32(e, _mm_slli_epi32::<2>(s));
        let mut hi = BlockEdges {
            e: [
                right(lo.e[0], lo.sx[0]),
                right(lo.e[1], lo.sx[1]),
                right(lo.e[2], lo.sx[2]),
            ],
            ..lo
        };
        let mut bits = 0u64;
        // Two rows (16 bytes of signs) at a time, as many pairs as the rectangle has.
        let pairs = ((r[3] - r[1]) / 2 + 1) as u32;
        for p in 0..pairs {
            let a = _mm_packs_epi32(lo.row(), hi.row());
            let b = _mm_packs_epi32(lo.row(), hi.row());
            let m = _mm_movemask_epi8(_mm_packs_epi16(a, b)) as u32 as u64;
            bits |= m << (16 * p);
        }
        bits
    };
    !outside & rect_bits(r)
}

/// The preconditions of a block test of at most `n` x `n` pixels (debug builds): one
/// sample, and a box below `extent`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn debug_check_block(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4], n: i32, extent: i32) {
    debug_assert!(si.offs.len() == 1 && r[2] - r[0] < n && r[3] - r[1] < n);
    debug_assert!({
        let b = bbox(v);
        b[2] - b[0] < extent && b[3] - b[1] < extent
    });
}

/// [`block_mask`] and [`block_mask8`] with a scalar setup and evaluation, one sample at a
/// time in `i32` (exact under the same bounds): off x86_64, and the reference the SSE2
/// versions are tested against.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline]
pub(crate) fn block_mask_scalar(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> u64 {
    debug_assert!(si.offs.len() == 1 && r[2] - r[0] < 8 && r[3] - r[1] < 8);
    let (ox, oy) = si.offs[0];
    let (bx, by) = ((r[0] << SUBPIXEL_BITS) + ox, (r[1] << SUBPIXEL_BITS) + oy);
    let x = [v[0][0] - bx, v[1][0] - bx, v[2][0] - bx];
    let y = [v[0][1] - by, v[1][1] - by, v[2][1] - by];
    let mut base = [0i32; 3];
    let mut sx = [0i32; 3];
    let mut sy = [0i32; 3];
    for i in 0..3 {
        let j = (i + 1) % 3;
        let (dx, dy) = (x[j] - x[i], y[j] - y[i]);
        // E(s) = dx (s_y - y_i) - dy (s_x - x_i), at s = 0, minus one off the top-left edges.
        let bias = i32::from(is_top_left(dx as i64, dy as i64)) - 1;
        base[i] = dy * x[i] - dx * y[i] + bias;
        sx[i] = -dy << SUBPIXEL_BITS;
        sy[i] = dx << SUBPIXEL_BITS;
    }
    let mut bits = 0u64;
    for j in 0..=r[3] - r[1] {
        for i in 0..=r[2] - r[0] {
            let e = [0, 1, 2].map(|k| base[k] + i * sx[k] + j * sy[k]);
            bits |= u64::from((e[0] | e[1] | e[2]) >= 0) << (8 * j + i);
        }
    }
    bits
}

/// [`block_mask`] off x86_64.
#[cfg(not(target_arch = "x86_64"))]
#[inline]
pub(crate) fn block_mask(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> u64 {
    block_mask_scalar(v, si, r)
}

/// [`block_mask8`] off x86_64.
#[cfg(not(target_arch = "x86_64"))]
#[inline]
pub(crate) fn block_mask8(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> u64 {
    block_mask_scalar(v, si, r)
}

/// [`block_mask`] for any triangle (edge functions in `i64`), one sample at a time, for
/// rectangles of at most 8x8: for the rare small pixel rectangle of a large triangle (a
/// sliver reaching off screen).
#[cold]
pub(crate) fn block_mask_wide(e: &Edges, si: &SampleInfo, r: [i32; 4]) -> u64 {
    debug_assert!(si.offs.len() == 1 && r[2] - r[0] < 8 && r[3] - r[1] < 8);
    let mut bits = 0u64;
    for y in r[1]..=r[3] {
        for x in r[0]..=r[2] {
            let m = e.mask_at(si, (x as i64) << SUBPIXEL_BITS, (y as i64) << SUBPIXEL_BITS);
            bits |= u64::from(m) << (8 * (y - r[1]) + (x - r[0]));
        }
    }
    bits
}

/// The edge functions of a block test ([`block_mask`], [`block_mask8`]): for each edge, its
/// values at a row of four samples starting at the block's first, and its steps per pixel
/// along a row and down a column, in SSE2 registers.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct BlockEdges {
    e: [std::arch::x86_64::__m128i; 3],
    /// Step per pixel along a row, in every lane.
    sx: [std::arch::x86_64::__m128i; 3],
    /// Step per pixel down a column, in every lane.
    sy: [std::arch::x86_64::__m128i; 3],
}

#[cfg(target_arch = "x86_64")]
impl BlockEdges {
    /// Sets up the three edges side by side in the lanes of one register (lane 3 repeats
    /// edge 2), products in `f32` (exact: see [`block_mask8`]'s bounds), then spreads each
    /// edge over a register of four columns.
    #[inline(always)]
    fn new(v: &[[i32; 2]; 3], si: &SampleInfo, r: [i32; 4]) -> BlockEdges {
        use std::arch::x86_64::{
            _mm_add_epi32, _mm_and_si128, _mm_castps_si128, _mm_castsi128_ps, _mm_cmpeq_epi32,
            _mm_cmpgt_epi32, _mm_cmplt_epi32, _mm_cvtepi32_ps, _mm_cvtps_epi32, _mm_loadl_epi64,
            _mm_loadu_si128, _mm_mul_ps, _mm_or_si128, _mm_set1_epi32, _mm_setr_epi32, _mm_setr_ps,
            _mm_setzero_si128, _mm_shuffle_epi32, _mm_shuffle_ps, _mm_slli_epi32, _mm_sub_epi32,
            _mm_sub_ps, _mm_xor_si128,
        };
        const SHIFT: i32 = SUBPIXEL_BITS as i32;
        let (ox, oy) = si.offs[0];
        let (bx, by) = ((r[0] << SUBPIXEL_BITS) + ox, (r[1] << SUBPIXEL_BITS) + oy);
        // SAFETY: these intrinsics need SSE2 only, which is part of the x86_64 baseline. The
        // two loads read the six `i32` of `v` (16 bytes from its start, 8 from its fifth).
        unsafe {
            let p = v.as_ptr().cast::<i32>();
            let origin = _mm_setr_epi32(bx, by, bx, by);
            let a = _mm_castsi128_ps(_mm_sub_epi32(_mm_loadu_si128(p.cast()), origin));
            let b = _mm_castsi128_ps(_mm_sub_epi32(_mm_loadl_epi64(p.add(4).cast()), origin));
            // Vertex coordinates by lane (x0 x1 x2 x2, y0 y1 y2 y2), and those of each
            // lane's next vertex: lane i is edge i, and lane 3 repeats edge 2.
            let x = _mm_castps_si128(_mm_shuffle_ps::<0b00_00_10_00>(a, b));
            let y = _mm_castps_si128(_mm_shuffle_ps::<0b01_01_11_01>(a, b));
            let dx = _mm_sub_epi32(_mm_shuffle_epi32::<0b00_00_10_01>(x), x);
            let dy = _mm_sub_epi32(_mm_shuffle_epi32::<0b00_00_10_01>(y), y);
            // E(s) = dx (s_y - y_i) - dy (s_x - x_i): at the first sample `dy x_i - dx y_i`,
            // minus one off the edges that are not top-left ([`is_top_left`]).
            let zero = _mm_setzero_si128();
            let top_left = _mm_or_si128(
                _mm_cmplt_epi32(dy, zero),
                _mm_and_si128(_mm_cmpeq_epi32(dy, zero), _mm_cmpgt_epi32(dx, zero)),
            );
            let f = _mm_cvtepi32_ps;
            let e = _mm_sub_ps(_mm_mul_ps(f(dy), f(x)), _mm_mul_ps(f(dx), f(y)));
            let base = _mm_add_epi32(
                _mm_cvtps_epi32(e),
                _mm_xor_si128(top_left, _mm_set1_epi32(-1)),
            );
            // Steps per pixel: `-dy ONE` along a row (times 0..3 for the four columns, in
            // f32 as well), `dx ONE` down a column.
            let sx = _mm_sub_epi32(zero, _mm_slli_epi32::<SHIFT>(dy));
            let sxf = f(sx);
            let sy = _mm_slli_epi32::<SHIFT>(dx);
            let columns = _mm_setr_ps(0.0, 1.0, 2.0, 3.0);
            macro_rules! edge {
                ($k:literal) => {{
                    const K: i32 = $k * 0b01_01_01_01;
                    let along = _mm_mul_ps(_mm_shuffle_ps::<K>(sxf, sxf), columns);
                    (
                        _mm_add_epi32(_mm_shuffle_epi32::<K>(base), _mm_cvtps_epi32(along)),
                        _mm_shuffle_epi32::<K>(sx),
                        _mm_shuffle_epi32::<K>(sy),
                    )
                }};
            }
            let (e0, sx0, sy0) = edge!(0);
            let (e1, sx1, sy1) = edge!(1);
            let (e2, sx2, sy2) = edge!(2);
            BlockEdges {
                e: [e0, e1, e2],
                sx: [sx0, sx1, sx2],
                sy: [sy0, sy1, sy2],
            }
        }
    }

    /// The current row's four samples, whose sign bits are set where a sample is outside
    /// (the sign of `E0 | E1 | E2`: one negative edge function puts a sample outside);
    /// then steps down to the next row.
    #[inline(always)]
    fn row(&mut self) -> std::arch::x86_64::__m128i {
        use std::arch::x86_64::{_mm_add_epi32, _mm_or_si128};
        // SAFETY: SSE2 only (x86_64 baseline); no memory is touched.
        unsafe {
            let [e0, e1, e2] = self.e;
            let out = _mm_or_si128(_mm_or_si128(e0, e1), e2);
            for (e, sy) in self.e.iter_mut().zip(self.sy) {
                *e = _mm_add_epi32(*e, sy);
            }
            out
        }
    }
}
