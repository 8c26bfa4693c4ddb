//! Triangle setup (snap to fixed point, edge functions, planes) and tile binning.
use super::{Fragment, RasterState, Viewport};
use glam::Vec4;

/// A triangle after clipping and snapping, ready to rasterize.
#[derive(Clone, Debug)]
pub struct SetupTriangle {
    /// Index of the input triangle (into `indices`) this comes from (several setup triangles share one
    /// source when clipping split it).
    pub source: u32,
    pub front_facing: bool,
}

impl SetupTriangle {
    /// Window depth in [0,1] at a screen position (pixels, y down), linear in screen space.
    pub fn depth_at(&self, x: f32, y: f32) -> f32 {
        let _ = (x, y);
        todo!()
    }
    /// Perspective-correct barycentrics of the *source* triangle's vertices at a screen position.
    pub fn bary_at(&self, x: f32, y: f32) -> [f32; 3] {
        let _ = (x, y);
        todo!()
    }
}

/// Triangles set up and binned into tiles.
pub struct Binned {
    pub tris: Vec<SetupTriangle>,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub tile_size: u32,
    /// Input triangles dropped for non-finite coordinates.
    pub rejected: u64,
}

impl Binned {
    pub fn tile_count(&self) -> usize {
        (self.tiles_x * self.tiles_y) as usize
    }
    /// Pixel rectangle `(x0, y0, x1, y1)` (exclusive ends, clamped to the viewport) of a tile.
    pub fn tile_rect(&self, tile: usize) -> (u32, u32, u32, u32) {
        let _ = tile;
        todo!()
    }
    /// Emits the fragments of one tile in API order (by `tri`); within one triangle in
    /// row-major order.
    pub fn raster_tile(&self, tile: usize, mut emit: impl FnMut(Fragment)) {
        let _ = (tile, &mut emit);
        todo!()
    }
}

/// Clips, culls, snaps and bins triangles. Uses up to `threads` threads.
/// `positions` are clip-space vertex positions, `indices` the triangles in API order.
/// Triangles with a NaN or infinite coordinate are dropped (and counted in [`Binned::rejected`]).
pub fn bin_triangles(
    positions: &[Vec4],
    indices: &[[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
) -> Binned {
    let _ = (positions, indices, state, viewport, threads);
    todo!()
}
