//! What the fixed-function tests share: value helpers and a one-tile framebuffer.

use fragrace_emu::framebuffer::TileMemory;

// ---------------------------------------------------------------------------------------
// Helpers

pub fn bits(v: [f32; 4]) -> [u32; 4] {
    v.map(f32::to_bits)
}

pub fn floats(v: [u32; 4]) -> [f32; 4] {
    v.map(f32::from_bits)
}

pub fn assert_close(got: [f32; 4], want: [f32; 4]) {
    for c in 0..4 {
        assert!(
            (got[c] - want[c]).abs() <= 1e-6,
            "channel {c}: got {got:?}, want {want:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Depth / stencil on tiles

pub fn tile(samples: u32, targets: usize) -> TileMemory {
    TileMemory::new(0, 0, 8, 8, 8, samples, targets)
}
