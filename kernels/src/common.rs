//! Pieces every algorithm uses: the fragment colour, front-to-back compositing, the pass
//! state that captures every fragment, and depth-order sorting.

use fragrace_emu::{
    Device, Draw, ExecConfig, FragmentKernel, FragmentState, Framebuffer, PassReport, PassState,
    RasterState, SampleCount,
};

use crate::algo::{AlgoError, CapturedFrag, Frame};

/// Marks an empty list head / empty slot.
pub const EMPTY: u32 = u32::MAX;

/// The llvmpipe peer's `hash32` (a 32-bit integer hash).
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Colour of a primitive, exactly as the llvmpipe peer's `prim_color` (hash of the
/// primitive id, each channel `0.2 + 0.8 * c`), packed RGBA8 with alpha 255.
pub fn prim_color_packed(prim: u32) -> u32 {
    let h = hash32(prim);
    let ch = |c: u32| CHANNEL[(c & 255) as usize];
    ch(h) | (ch(h >> 8) << 8) | (ch(h >> 16) << 16) | (255 << 24)
}

/// One channel of [`prim_color_packed`] for each byte of the hash: `0.2 + 0.8 c / 255`,
/// scaled to 0..=255 and rounded, computed once (the resolve colours every fragment it
/// composites, and `f32::round` is a library call on baseline x86-64).
const CHANNEL: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut c = 0;
    while c < 256 {
        t[c] = channel(c as u32);
        c += 1;
    }
    t
};

/// [`CHANNEL`] as the floats [`unpack_color`] makes of it (`CHANNEL[c] / 255`, the same
/// division, so the same bits): the resolves colour every fragment they composite, and a
/// table lookup is cheaper than three divisions (`ll`'s resolve of the bunny at 2048 x 2048
/// on one thread: 824 M -> 774 M instructions, callgrind).
const UNIT: [f32; 256] = {
    let mut t = [0f32; 256];
    let mut c = 0;
    while c < 256 {
        t[c] = CHANNEL[c] as f32 / 255.0;
        c += 1;
    }
    t
};

/// The RGB of primitive `prim` as floats: `unpack_color(prim_color_packed(prim))`'s first
/// three channels, bit for bit.
pub fn prim_rgb(prim: u32) -> [f32; 3] {
    let h = hash32(prim);
    [
        UNIT[(h & 255) as usize],
        UNIT[((h >> 8) & 255) as usize],
        UNIT[((h >> 16) & 255) as usize],
    ]
}

/// The peer's channel value of hash byte `c`.
const fn channel(c: u32) -> u32 {
    let v = 0.2 + 0.8 * c as f32 / 255.0;
    (v * 255.0).round() as u32
}

/// Unpacks an RGBA8 colour to floats.
pub fn unpack_color(c: u32) -> [f32; 4] {
    [
        (c & 255) as f32 / 255.0,
        ((c >> 8) & 255) as f32 / 255.0,
        ((c >> 16) & 255) as f32 / 255.0,
        (c >> 24) as f32 / 255.0,
    ]
}

/// Front-to-back "over" of `colors` (nearest first), each with opacity `alpha`, onto
/// `background`: `C = sum_i c_i a prod_{j<i} (1 - a) + bg prod (1 - a)`.
pub fn composite(
    colors: impl IntoIterator<Item = [f32; 3]>,
    alpha: f32,
    background: [f32; 3],
) -> [f32; 4] {
    let mut acc = [0.0f32; 3];
    let mut t = 1.0f32;
    for c in colors {
        for i in 0..3 {
            acc[i] += c[i] * alpha * t;
        }
        t *= 1.0 - alpha;
    }
    [
        acc[0] + background[0] * t,
        acc[1] + background[1] * t,
        acc[2] + background[2] * t,
        1.0 - t,
    ]
}

/// Composites captured fragments (already in front-to-back order) by primitive colour.
pub fn composite_frags(frags: &[CapturedFrag], alpha: f32, background: [f32; 3]) -> [f32; 4] {
    composite(frags.iter().map(|f| prim_rgb(f.prim)), alpha, background)
}

/// Depth order: depth, then primitive id (the ground truth's order).
pub fn depth_order(a: &CapturedFrag, b: &CapturedFrag) -> std::cmp::Ordering {
    a.depth.total_cmp(&b.depth).then(a.prim.cmp(&b.prim))
}

/// Sorts a pixel's fragments the way the DFB resolve does (seeds: z-thickness paper):
/// insertion sort under 16 fragments ([`sort_keys_changed`] on their [`sort_key`]s), shell
/// sort above.
pub fn sort_fragments(v: &mut [CapturedFrag]) {
    if v.len() >= 16 {
        shell_sort(v);
        return;
    }
    let mut keys = [0u64; 16];
    let keys = &mut keys[..v.len()];
    for (k, f) in keys.iter_mut().zip(v.iter()) {
        *k = sort_key(f.depth.to_bits(), f.prim);
    }
    if sort_keys_changed(keys) {
        for (f, &k) in v.iter_mut().zip(keys.iter()) {
            *f = CapturedFrag::from_bits(key_depth_bits(k), k as u32);
        }
    }
}

/// A fragment's place in [`depth_order`] as one integer, from the two words a fragment is
/// stored as (its depth's bits and its primitive): keys compare as `depth_order` compares
/// the fragments (the depth by `f32::total_cmp`, then the primitive), and
/// [`key_depth_bits`] and the low word give the two words back.
///
/// Why: a resolve that sorts its pixel's fragments as `CapturedFrag`s writes each one as two
/// 4-byte stores and reads it back as one 8-byte load, which the store buffer cannot
/// forward (a stall of about 15 cycles per fragment written back); a key is one word.
#[inline]
pub fn sort_key(depth_bits: u32, prim: u32) -> u64 {
    // `total_cmp`'s map: a negative float's magnitude bits flipped, then the sign flipped
    // so that the signed order becomes the unsigned one.
    let ordered = depth_bits ^ ((((depth_bits as i32) >> 31) as u32) >> 1) ^ 0x8000_0000;
    (u64::from(ordered) << 32) | u64::from(prim)
}

/// The depth bits of a [`sort_key`] (its primitive is the low word).
#[inline]
pub fn key_depth_bits(key: u64) -> u32 {
    let t = ((key >> 32) as u32) ^ 0x8000_0000;
    t ^ ((((t as i32) >> 31) as u32) >> 1)
}

/// Sorts [`sort_key`]s in increasing order (front to back) by insertion, saying whether it
/// changed the order: false when `v` was already sorted (then nothing was moved). For a
/// resolve's short lists: inline, so that they are sorted in the resolve's own code, and a
/// pixel already in order costs one comparison a fragment.
#[inline]
pub fn sort_keys_changed(v: &mut [u64]) -> bool {
    let mut changed = false;
    for i in 1..v.len() {
        let x = v[i];
        if v[i - 1] <= x {
            continue;
        }
        changed = true;
        let mut j = i;
        while j > 0 && v[j - 1] > x {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
    changed
}

/// The shell sort of [`sort_fragments`] (gaps 1, 4, 13, ...), for 16 fragments and more.
fn shell_sort(v: &mut [CapturedFrag]) {
    let mut gap = 1;
    while gap < v.len() / 3 {
        gap = gap * 3 + 1;
    }
    while gap >= 1 {
        for i in gap..v.len() {
            let x = v[i];
            let mut j = i;
            while j >= gap && depth_order(&v[j - gap], &x) == std::cmp::Ordering::Greater {
                v[j] = v[j - gap];
                j -= gap;
            }
            v[j] = x;
        }
        gap /= 3;
    }
}

/// Pass state that lets every fragment through: no culling, no depth test, no targets
/// (the capture passes of the A-buffers, k-buffers and the peer's shaders).
pub fn capture_state() -> PassState {
    PassState {
        raster: RasterState::default(),
        fragment: FragmentState::new(),
        condition: None,
    }
}

/// A framebuffer for a frame with the given targets and samples.
pub fn framebuffer(
    frame: &Frame<'_>,
    samples: SampleCount,
    formats: &[fragrace_emu::Format],
) -> Result<Framebuffer, AlgoError> {
    Ok(Framebuffer::new(
        frame.width,
        frame.height,
        samples,
        64,
        formats,
    )?)
}

/// Runs one geometry pass of `frame` with `kernel`.
pub fn geometry_pass<K: FragmentKernel>(
    device: &Device,
    fb: &mut Framebuffer,
    frame: &Frame<'_>,
    state: &PassState,
    kernel: &K,
    exec: &ExecConfig,
) -> Result<PassReport, AlgoError> {
    let draw = Draw::new(frame.mesh, frame.view_proj);
    Ok(device.draw(fb, &draw, state, kernel, exec)?)
}

/// Number of pixels of a frame.
pub fn pixels(frame: &Frame<'_>) -> usize {
    frame.width as usize * frame.height as usize
}

/// A fresh device for one run (its buffers zeroed with the run's threads).
pub fn fresh(exec: &ExecConfig) -> Device {
    Device::with_threads(exec.threads)
}

/// Fewest values per thread of [`parallel_sum`]: below this a thread costs more than it
/// saves.
pub const SUM_MIN_PER_THREAD: usize = 1 << 18;

/// The sum of `values`, split over `threads` threads: checks that read every pixel's count
/// are bound by memory bandwidth (16 MB at 2048x2048), which one core does not saturate.
pub fn parallel_sum(values: &[u32], threads: usize) -> u64 {
    fragrace_emu::sync::pool::map_parts(values, threads, SUM_MIN_PER_THREAD, |part| {
        part.iter().map(|&c| u64::from(c)).sum::<u64>()
    })
    .into_iter()
    .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorting_as_the_standard_library_by_fragments_and_by_keys() {
        // Lists of 0 to 20 fragments with ties in depth (broken by primitive), from a
        // fixed generator, among them negative, signed-zero, infinite and NaN depths: sorted
        // as the standard library sorts them, by `sort_fragments` and, as keys, by
        // `sort_keys_changed`, which says "changed" exactly when the input was out of order.
        let special = [
            -0.0f32,
            0.0,
            -1.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        let mut x = 12345u32;
        for len in 0..21 {
            for _ in 0..200 {
                let v: Vec<CapturedFrag> = (0..len)
                    .map(|_| {
                        x = hash32(x);
                        let depth = if x.is_multiple_of(11) {
                            special[(x >> 4) as usize % special.len()]
                        } else {
                            (x % 7) as f32 / 7.0
                        };
                        CapturedFrag {
                            depth,
                            prim: (x >> 8) % 5,
                        }
                    })
                    .collect();
                // The reference: the standard library's sort (depth_order is total on
                // (depth bits, primitive), so equal keys are equal fragments). Compared by
                // bits, as NaN is not equal to itself.
                let bits = |v: &[CapturedFrag]| -> Vec<(u32, u32)> {
                    v.iter().map(|f| (f.depth.to_bits(), f.prim)).collect()
                };
                let mut want = v.clone();
                want.sort_by(depth_order);
                let mut plain = v.clone();
                sort_fragments(&mut plain);
                assert_eq!(bits(&plain), bits(&want));
                let mut keys: Vec<u64> = v
                    .iter()
                    .map(|f| sort_key(f.depth.to_bits(), f.prim))
                    .collect();
                let changed = sort_keys_changed(&mut keys);
                let got: Vec<(u32, u32)> = keys
                    .iter()
                    .map(|&k| (key_depth_bits(k), k as u32))
                    .collect();
                assert_eq!(got, bits(&want));
                assert_eq!(changed, got != bits(&v), "{v:?}");
            }
        }
    }

    #[test]
    fn prim_rgb_is_the_unpacked_packed_colour_bit_for_bit() {
        // Every hash byte is reached many times over these primitives.
        for prim in (0..200_000).chain([u32::MAX - 1, u32::MAX]) {
            let want = unpack_color(prim_color_packed(prim));
            let got = prim_rgb(prim);
            for c in 0..3 {
                assert_eq!(
                    got[c].to_bits(),
                    want[c].to_bits(),
                    "prim {prim} channel {c}"
                );
            }
        }
    }
}
