//! Vertex transform: a draw's positions into clip space, in parallel, into a recycled buffer;
//! and the device's cache of its last draw's vertices ([`VertexCache`]).

use std::sync::Mutex;

use glam::{Mat4, Vec3, Vec4};

use crate::raster::Projected;
use crate::sync::pool;

/// Clip-space positions of draws, reused from draw to draw (see [`crate::raster::pool`]).
pub(super) static CLIP: crate::raster::pool::Pool<Vec4> = crate::raster::pool::Pool::new();

/// Transforms positions to clip space (in parallel). `out` may hold stale positions: it
/// is cut or grown to size (only the growth is cleared) and every element overwritten.
pub(super) fn transform(
    positions: &[glam::Vec3],
    m: glam::Mat4,
    threads: usize,
    out: &mut Vec<Vec4>,
) {
    out.truncate(positions.len());
    out.resize(positions.len(), Vec4::ZERO);
    let chunk = positions.len().div_ceil(threads.max(1)).max(4096);
    let parts: Vec<_> = positions.chunks(chunk).zip(out.chunks_mut(chunk)).collect();
    pool::broadcast_each(parts, |(src, dst)| {
        for (p, o) in src.iter().zip(dst.iter_mut()) {
            *o = m * p.extend(1.0);
        }
    });
}

/// The vertices of a device's last draw, in clip space and projected, kept for its next
/// draw of the same positions through the same matrix (into the same viewport: see
/// [`crate::raster::prepare_projected`]), so that the passes of a frame over one mesh (a
/// count pass and a capture pass, a k-buffer's depth and claim passes) transform and project
/// it once, as a GPU's vertex cache or a renderer's transform feedback would. On the 871K
/// dragon that work was 15-20 % of the instructions of a geometry pass (callgrind).
///
/// The key is the matrix and the positions' values (their bits, hashed: a draw of a mesh
/// changed in place since the last one, even by one coordinate, does not match), never the
/// address alone. Plain `std` mutex: bookkeeping outside the modelled protocols.
#[derive(Default)]
pub(super) struct VertexCache {
    last: Mutex<Option<Kept>>,
}

/// A draw's vertices and what they were computed from.
pub(super) struct Kept {
    key: VertexKey,
    pub(super) clip: Vec<Vec4>,
    pub(super) projected: Option<Projected>,
}

impl Drop for Kept {
    fn drop(&mut self) {
        CLIP.give_dirty(std::mem::take(&mut self.clip));
    }
}

/// What a draw's vertices are computed from: the model-view-projection matrix and the
/// positions (their count and a hash of their bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct VertexKey {
    matrix: [u32; 16],
    count: usize,
    hash: [u64; 4],
}

impl VertexKey {
    pub(super) fn new(positions: &[Vec3], m: Mat4) -> VertexKey {
        VertexKey {
            matrix: m.to_cols_array().map(f32::to_bits),
            count: positions.len(),
            hash: hash_positions(positions),
        }
    }
}

/// A hash of the positions' bits in four independent lanes (vertex `i` into lane `i % 4`),
/// so that the multiplies of different lanes overlap. Each step of a lane is a bijection of
/// its state for a given input word, so two position lists that differ in one word always
/// hash differently.
fn hash_positions(positions: &[Vec3]) -> [u64; 4] {
    const K: u64 = 0x517c_c1b7_2722_0a95;
    let mix = |h: u64, w: u64| (h.rotate_left(5) ^ w).wrapping_mul(K);
    let mut lanes = [0u64; 4];
    for quad in positions.chunks(4) {
        for (lane, p) in lanes.iter_mut().zip(quad) {
            let xy = u64::from(p.x.to_bits()) | (u64::from(p.y.to_bits()) << 32);
            *lane = mix(mix(*lane, xy), u64::from(p.z.to_bits()));
        }
    }
    lanes
}

impl VertexCache {
    /// The kept vertices if they were computed from `key`; otherwise fresh clip-space
    /// positions (`positions` through `m`, transformed on `threads` threads) and no
    /// projection yet.
    pub(super) fn vertices(
        &self,
        key: VertexKey,
        positions: &[Vec3],
        m: Mat4,
        threads: usize,
    ) -> Kept {
        let kept = self.last.lock().unwrap_or_else(|e| e.into_inner()).take();
        match kept {
            Some(k) if k.key == key => k,
            _ => {
                let mut clip = CLIP.take();
                transform(positions, m, threads, &mut clip);
                Kept {
                    key,
                    clip,
                    projected: None,
                }
            }
        }
    }

    /// Keeps a draw's vertices for the next draw (the previous ones are given back).
    pub(super) fn keep(&self, kept: Kept) {
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some(kept);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_changed_coordinate_or_matrix_changes_the_key() {
        let mut p: Vec<Vec3> = (0..11).map(|i| Vec3::splat(i as f32 * 0.25)).collect();
        let m = Mat4::from_scale(Vec3::splat(2.0));
        let key = VertexKey::new(&p, m);
        assert_eq!(key, VertexKey::new(&p.clone(), m));
        for i in 0..p.len() {
            let mut q = p.clone();
            q[i].z = f32::from_bits(q[i].z.to_bits() ^ 1);
            assert_ne!(key, VertexKey::new(&q, m), "vertex {i}");
        }
        assert_ne!(key, VertexKey::new(&p, Mat4::IDENTITY));
        p.pop();
        assert_ne!(key, VertexKey::new(&p, m));
    }
}
