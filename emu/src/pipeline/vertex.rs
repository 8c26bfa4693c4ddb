//! Vertex transform: a draw's positions into clip space, in parallel, into a recycled buffer.

use glam::Vec4;

use crate::sync::pool;

/// Clip-space positions of draws, reused from draw to draw (see [`crate::raster::pool`]).
pub(super) static CLIP: crate::raster::pool::Pool<Vec4> = crate::raster::pool::Pool::new();

/// A draw's clip-space positions, handed back to [`CLIP`] when the draw ends (on every path).
pub(super) struct ClipPositions(pub(super) Vec<Vec4>);

impl Drop for ClipPositions {
    fn drop(&mut self) {
        CLIP.give_dirty(std::mem::take(&mut self.0));
    }
}

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
