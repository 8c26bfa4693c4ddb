//! The tile-major framebuffer: outputs and targets, limits refused before any allocation
//! (proved by counting this thread's allocations), layouts, clears and readbacks.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use fragrace_emu::framebuffer::{Framebuffer, FramebufferError, MAX_SAMPLES_TOTAL};
use fragrace_emu::raster::SampleCount;
use fragrace_emu::state::{Format, FragmentState, TargetState};

use super::common::*;

// ---------------------------------------------------------------------------------------
// Allocation counting (per thread, so tests running in parallel do not disturb each other):
// lets the "too large" tests prove that validation happens before any allocation.

struct CountingAlloc;

thread_local! {
    static ALLOCATED: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged, so
// `System`'s guarantees hold; the only addition is a thread-local byte count.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATED.try_with(|a| a.set(a.get() + layout.size()));
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATED.try_with(|a| a.set(a.get() + layout.size()));
        System.alloc_zeroed(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATED.try_with(|a| a.set(a.get() + new_size));
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Bytes allocated by this thread while running `f`.
fn allocated_during<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let before = ALLOCATED.with(Cell::get);
    let r = f();
    (r, ALLOCATED.with(Cell::get) - before)
}

#[test]
fn write_outputs_only_to_min_of_targets_and_outputs() {
    let mut t = tile(2, 3);
    let mut st = FragmentState::new();
    st.targets = vec![
        TargetState::new(Format::R32UI),
        TargetState::new(Format::RGBA32UI),
        TargetState::new(Format::R32F),
    ];
    // Two outputs for three targets: the third target is untouched.
    t.write_outputs(&st, 1, 0, 0b10, &[[1, 0, 0, 0], [2, 3, 4, 5]]);
    let i = t.index(1, 0, 1);
    assert_eq!(t.color_at(0, i), [1, 0, 0, 0]);
    assert_eq!(t.color_at(1, i), [2, 3, 4, 5]);
    assert_eq!(t.color_at(2, i), [0; 4]);
    assert_eq!(t.color_at(0, i - 1), [0; 4], "sample 0 is not in the mask");
}

// ---------------------------------------------------------------------------------------
// Framebuffer

#[test]
fn framebuffer_errors() {
    use FramebufferError::*;
    let new = |w, h, s, ts, n: usize| Framebuffer::new(w, h, s, ts, &vec![Format::R32F; n]).err();
    assert_eq!(
        new(0, 0, SampleCount::X1, 64, 1),
        Some(Empty {
            width: 0,
            height: 0
        })
    );
    assert_eq!(
        new(0, 5, SampleCount::X1, 64, 1),
        Some(Empty {
            width: 0,
            height: 5
        })
    );
    assert_eq!(
        new(5, 0, SampleCount::X1, 64, 1),
        Some(Empty {
            width: 5,
            height: 0
        })
    );

    // Too large: checked before any allocation (the error itself is all that is built).
    let (err, bytes) = allocated_during(|| new(100_000, 100_000, SampleCount::X8, 64, 8));
    assert_eq!(
        err,
        Some(TooLarge {
            width: 100_000,
            height: 100_000,
            samples: 8,
            max: MAX_SAMPLES_TOTAL
        })
    );
    assert!(bytes < 4096, "allocated {bytes} bytes before rejecting");
    let (err, bytes) =
        allocated_during(|| Framebuffer::new(u32::MAX, u32::MAX, SampleCount::X8, 64, &[]).err());
    assert!(matches!(err, Some(TooLarge { .. })));
    assert_eq!(bytes, 0);
    // Each side within MAX_DIMENSION, but width*height*samples over the budget.
    let (err, bytes) = allocated_during(|| new(16384, 16384, SampleCount::X8, 64, 1));
    assert!(matches!(err, Some(TooLarge { samples: 8, .. })));
    assert!(bytes < 4096);
    assert!(matches!(
        new(16385, 1, SampleCount::X1, 64, 1),
        Some(TooLarge { .. })
    ));

    assert_eq!(new(64, 64, SampleCount::X1, 64, 9), Some(TooManyTargets(9)));
    assert!(new(64, 64, SampleCount::X1, 64, 8).is_none());
    for ts in [0, 4, 12, 100, 512] {
        assert_eq!(
            new(64, 64, SampleCount::X1, ts, 1),
            Some(BadTileSize(ts)),
            "tile {ts}"
        );
    }
    for ts in [8, 16, 32, 64, 128, 256] {
        assert!(new(64, 64, SampleCount::X1, ts, 1).is_none(), "tile {ts}");
    }
}

#[test]
fn framebuffer_layout_on_non_multiple_sizes() {
    let mut fb = Framebuffer::new(100, 37, SampleCount::X4, 64, &[Format::RGBA32F]).unwrap();
    assert_eq!((fb.tiles_x, fb.tiles_y), (2, 1));
    let tiles = fb.tiles();
    assert_eq!(tiles.len(), 2);
    assert_eq!(
        (tiles[0].x0, tiles[0].y0, tiles[0].w, tiles[0].h),
        (0, 0, 64, 37)
    );
    assert_eq!(
        (tiles[1].x0, tiles[1].y0, tiles[1].w, tiles[1].h),
        (64, 0, 36, 37)
    );
    for t in tiles {
        // Depth and stencil are lazy until first needed.
        assert!(t.depth.is_empty() && t.stencil.is_empty());
    }
    for t in fb.tiles_mut().iter_mut() {
        t.materialize();
    }
    for t in fb.tiles() {
        // Edge tiles keep full-size buffers.
        assert_eq!(t.plane_len(), 64 * 64 * 4);
        assert_eq!(t.depth.len(), 64 * 64 * 4);
        assert_eq!(t.stencil.len(), 64 * 64 * 4);
    }
    // Initial clear values.
    for (x, y) in [(0, 0), (99, 36), (64, 20)] {
        for s in 0..4 {
            assert_eq!(fb.color(0, x, y, s), [0; 4]);
            assert_eq!(fb.depth(x, y, s), 1.0);
            assert_eq!(fb.stencil(x, y, s), 0);
        }
    }
    let fb = Framebuffer::new(300, 17, SampleCount::X1, 128, &[]).unwrap();
    assert_eq!((fb.tiles_x, fb.tiles_y), (3, 1));
    assert_eq!(fb.tiles()[2].w, 300 - 256);
}

#[test]
fn clear_and_readback_round_trip() {
    let formats = [Format::R32UI, Format::RGBA8];
    let mut fb = Framebuffer::new(100, 37, SampleCount::X2, 64, &formats).unwrap();
    fb.clear_color(0, [7, 0, 0, 0]);
    fb.clear_color(1, bits([1.0, 0.0, 0.5, 1.0]));
    fb.clear_depth(0.25);
    fb.clear_stencil(9);
    for y in 0..37 {
        for x in 0..100 {
            for s in 0..2 {
                assert_eq!(fb.color(0, x, y, s), [7, 0, 0, 0]);
                assert_eq!(fb.color(1, x, y, s), bits([1.0, 0.0, 0.5, 1.0]));
                assert_eq!(fb.depth(x, y, s), 0.25);
                assert_eq!(fb.stencil(x, y, s), 9);
            }
        }
    }

    // Write a distinct value to every sample through the tiles (tile-local coordinates),
    // then read back in global coordinates and through the row-major image.
    let key = |x: u32, y: u32, s: u32| (y * 1000 + x) * 10 + s;
    let mut st = FragmentState::new();
    st.targets = vec![TargetState::new(Format::R32UI)];
    for t in fb.tiles_mut() {
        t.materialize();
        for ly in 0..t.h {
            for lx in 0..t.w {
                for s in 0..2 {
                    let v = key(t.x0 + lx, t.y0 + ly, s);
                    t.write_outputs(&st, lx, ly, 1 << s, &[[v, 1, 2, 3]]);
                    let i = t.index(lx, ly, s);
                    t.depth[i] = v as f32;
                    t.stencil[i] = (v % 251) as u8;
                }
            }
        }
    }
    let image = fb.image(0);
    assert_eq!((image.width, image.height, image.samples), (100, 37, 2));
    assert_eq!(image.format, Format::R32UI);
    assert_eq!(image.texels.len(), 100 * 37 * 2);
    for y in 0..37 {
        for x in 0..100 {
            for s in 0..2 {
                let v = key(x, y, s);
                assert_eq!(fb.color(0, x, y, s), [v, 0, 0, 0]);
                assert_eq!(fb.depth(x, y, s), v as f32);
                assert_eq!(fb.stencil(x, y, s), (v % 251) as u8);
                assert_eq!(image.texel(x, y, s), [v, 0, 0, 0]);
                assert_eq!(image.texel_f32(x, y, s), [v as f32, 0.0, 0.0, 0.0]);
            }
        }
    }
    // The other target was not touched; its image reads floats.
    let image = fb.image(1);
    assert_eq!(image.format, Format::RGBA8);
    assert_eq!(image.texel_f32(99, 36, 1), [1.0, 0.0, 0.5, 1.0]);
}

#[test]
#[should_panic(expected = "outside")]
fn readback_outside_the_framebuffer_panics_even_in_tile_padding() {
    let fb = Framebuffer::new(100, 37, SampleCount::X1, 64, &[Format::R32F]).unwrap();
    // (100, 0) lies in the padding of the edge tile, which is not a pixel.
    let _ = fb.color(0, 100, 0, 0);
}

/// A framebuffer takes the colour planes of dropped ones without clearing them, and clears
/// a tile's when it is first written: whatever planes it got, every texel reads 0 until
/// written, and a write to one texel leaves the rest of its tile at 0.
#[test]
fn kept_planes_read_as_cleared_until_written() {
    let formats = [Format::RGBA32UI];
    let mut old = Framebuffer::new(130, 70, SampleCount::X1, 64, &formats).unwrap();
    old.clear_color(0, [9, 9, 9, 9]);
    drop(old);
    let mut fb = Framebuffer::new(130, 70, SampleCount::X1, 64, &formats).unwrap();
    let image = fb.image(0);
    assert!(image.texels.iter().all(|t| *t == [0; 4]));
    for (x, y) in [(0, 0), (129, 69), (64, 3)] {
        assert_eq!(fb.color(0, x, y, 0), [0; 4]);
    }
    let mut st = FragmentState::new();
    st.targets = vec![TargetState::new(Format::RGBA32UI)];
    let t = &mut fb.tiles_mut()[1];
    t.write_outputs(&st, 2, 1, 1, &[[1, 2, 3, 4]]);
    assert_eq!(fb.color(0, 66, 1, 0), [1, 2, 3, 4]);
    let image = fb.image(0);
    let written = image.texels.iter().filter(|t| **t != [0; 4]).count();
    assert_eq!(written, 1);
}
