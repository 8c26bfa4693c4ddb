//! Fixed-function per-fragment state (`state`) and the tile-major framebuffer
//! (`framebuffer`): compare funcs, stencil ops, blending, RGBA8 quantization, logic ops,
//! write masks, per-sample depth/stencil with MSAA, stencil routing, framebuffer limits and
//! readback round trips.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use fragrace_emu::framebuffer::{Framebuffer, FramebufferError, TileMemory, MAX_SAMPLES_TOTAL};
use fragrace_emu::raster::SampleCount;
use fragrace_emu::state::{
    quantize_unorm8, BlendEquation, BlendFactor, BlendState, CompareFunc, DepthState, Format,
    FragmentState, LogicOp, StencilFace, StencilOp, StencilState, TargetState,
};

// ---------------------------------------------------------------------------------------
// Allocation counting (per thread, so tests running in parallel do not disturb each other):
// lets the "too large" tests prove that validation happens before any allocation.

struct CountingAlloc;

thread_local! {
    static ALLOCATED: Cell<usize> = const { Cell::new(0) };
}

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

// ---------------------------------------------------------------------------------------
// Helpers

fn bits(v: [f32; 4]) -> [u32; 4] {
    v.map(f32::to_bits)
}

fn floats(v: [u32; 4]) -> [f32; 4] {
    v.map(f32::from_bits)
}

fn assert_close(got: [f32; 4], want: [f32; 4]) {
    for c in 0..4 {
        assert!(
            (got[c] - want[c]).abs() <= 1e-6,
            "channel {c}: got {got:?}, want {want:?}"
        );
    }
}

fn blend_target(format: Format, blend: BlendState) -> TargetState {
    TargetState {
        blend: Some(blend),
        ..TargetState::new(format)
    }
}

// ---------------------------------------------------------------------------------------
// Compare functions

#[test]
fn compare_funcs_follow_gl_incoming_func_stored() {
    use CompareFunc::*;
    // (func, incoming<stored, incoming==stored, incoming>stored)
    let table = [
        (Never, false, false, false),
        (Less, true, false, false),
        (Equal, false, true, false),
        (LessEqual, true, true, false),
        (Greater, false, false, true),
        (NotEqual, true, false, true),
        (GreaterEqual, false, true, true),
        (Always, true, true, true),
    ];
    for (f, lt, eq, gt) in table {
        assert_eq!(f.test(1.0f32, 2.0), lt, "{f:?} 1 vs 2");
        assert_eq!(f.test(2.0f32, 2.0), eq, "{f:?} 2 vs 2");
        assert_eq!(f.test(3.0f32, 2.0), gt, "{f:?} 3 vs 2");
        // Integers (stencil) too.
        assert_eq!(f.test(1u8, 2), lt, "{f:?} 1u8 vs 2");
        assert_eq!(f.test(2u8, 2), eq, "{f:?} 2u8 vs 2");
        assert_eq!(f.test(3u8, 2), gt, "{f:?} 3u8 vs 2");
    }
    // NaN is unordered: only NotEqual and Always pass.
    for (f, ..) in table {
        let want = matches!(f, NotEqual | Always);
        assert_eq!(f.test(f32::NAN, 0.5), want, "{f:?} NaN");
    }
    assert_eq!(CompareFunc::default(), Less);
}

// ---------------------------------------------------------------------------------------
// Stencil ops

#[test]
fn stencil_ops_full_mask() {
    use StencilOp::*;
    let r = 0x5a;
    let cases = [
        (Keep, 7, 7),
        (Zero, 7, 0),
        (Replace, 7, r),
        (IncrClamp, 7, 8),
        (IncrClamp, 255, 255),
        (DecrClamp, 7, 6),
        (DecrClamp, 0, 0),
        (Invert, 0b1010_0101, 0b0101_1010),
        (IncrWrap, 7, 8),
        (IncrWrap, 255, 0),
        (DecrWrap, 7, 6),
        (DecrWrap, 0, 255),
    ];
    for (op, v, want) in cases {
        assert_eq!(op.apply(v, r, 0xff), want, "{op:?} on {v}");
    }
    assert_eq!(StencilOp::default(), Keep);
}

#[test]
fn stencil_ops_respect_write_mask() {
    use StencilOp::*;
    // Only the low nibble may change.
    let wm = 0x0f;
    assert_eq!(Zero.apply(0xab, 0, wm), 0xa0);
    assert_eq!(Replace.apply(0xab, 0x34, wm), 0xa4);
    assert_eq!(Invert.apply(0xab, 0, wm), 0xa4);
    // IncrWrap of 0x0f is 0x10; only the masked bits of 0x10 land: 0x00.
    assert_eq!(IncrWrap.apply(0x0f, 0, wm), 0x00);
    // IncrClamp at 255 stays 255 whatever the mask.
    assert_eq!(IncrClamp.apply(0xff, 0, wm), 0xff);
    // DecrWrap of 0x00 is 0xff; masked: 0x0f.
    assert_eq!(DecrWrap.apply(0x00, 0, wm), 0x0f);
    assert_eq!(DecrClamp.apply(0x10, 0, wm), 0x1f);
    // A zero write mask freezes the value.
    for op in [
        Keep, Zero, Replace, IncrClamp, DecrClamp, Invert, IncrWrap, DecrWrap,
    ] {
        assert_eq!(op.apply(0x3c, 0xc3, 0), 0x3c, "{op:?}");
    }
}

// ---------------------------------------------------------------------------------------
// Formats, defaults

#[test]
fn formats_channels_and_integer() {
    use Format::*;
    let table = [
        (R32F, 1, false),
        (RG32F, 2, false),
        (RGBA32F, 4, false),
        (R32UI, 1, true),
        (RGBA32UI, 4, true),
        (RGBA8, 4, false),
    ];
    for (f, n, int) in table {
        assert_eq!(f.channels(), n, "{f:?}");
        assert_eq!(f.is_integer(), int, "{f:?}");
    }
}

#[test]
fn fragment_state_default_is_new_with_all_samples() {
    let d = FragmentState::default();
    assert_eq!(d, FragmentState::new());
    assert_eq!(d.sample_mask, 0xff);
    assert!(!d.depth.test && !d.depth.write && !d.stencil.enabled);
    assert!(d.targets.is_empty());
}

// ---------------------------------------------------------------------------------------
// Blending

#[test]
fn blend_factor_table() {
    use BlendFactor::*;
    let src = [0.2, 0.3, 0.4, 0.5];
    let dst = [0.6, 0.7, 0.8, 0.25];
    let constant = [0.1, 0.15, 0.35, 0.45];
    // (factor, factor on channel 0, factor on alpha)
    let table = [
        (Zero, 0.0, 0.0),
        (One, 1.0, 1.0),
        (SrcColor, 0.2, 0.5),
        (OneMinusSrcColor, 0.8, 0.5),
        (DstColor, 0.6, 0.25),
        (OneMinusDstColor, 0.4, 0.75),
        (SrcAlpha, 0.5, 0.5),
        (OneMinusSrcAlpha, 0.5, 0.5),
        (DstAlpha, 0.25, 0.25),
        (OneMinusDstAlpha, 0.75, 0.75),
        (ConstantColor, 0.1, 0.45),
        (OneMinusConstantColor, 0.9, 0.55),
        (ConstantAlpha, 0.45, 0.45),
        (OneMinusConstantAlpha, 0.55, 0.55),
        // min(As, 1 - Ad) = min(0.5, 0.75) on colour, 1 on alpha.
        (SrcAlphaSaturate, 0.5, 1.0),
    ];
    for (f, rgb, a) in table {
        // As a source factor (dst factor Zero): out = src * f.
        let b = BlendState {
            color_eq: BlendEquation::Add,
            alpha_eq: BlendEquation::Add,
            src_color: f,
            dst_color: Zero,
            src_alpha: f,
            dst_alpha: Zero,
            constant,
        };
        let out = b.blend(src, dst);
        assert!(
            (out[0] - src[0] * rgb).abs() < 1e-6,
            "{f:?} as src, rgb: {out:?}"
        );
        assert!(
            (out[3] - src[3] * a).abs() < 1e-6,
            "{f:?} as src, alpha: {out:?}"
        );
        // As a destination factor (src factor Zero): out = dst * f.
        let b = BlendState {
            src_color: Zero,
            dst_color: f,
            src_alpha: Zero,
            dst_alpha: f,
            ..b
        };
        let out = b.blend(src, dst);
        assert!(
            (out[0] - dst[0] * rgb).abs() < 1e-6,
            "{f:?} as dst, rgb: {out:?}"
        );
        assert!(
            (out[3] - dst[3] * a).abs() < 1e-6,
            "{f:?} as dst, alpha: {out:?}"
        );
    }
}

#[test]
fn blend_equations_with_separate_color_and_alpha_factors() {
    use BlendEquation::*;
    use BlendFactor::*;
    let src = [0.8, 0.4, 0.2, 0.5];
    let dst = [0.3, 0.6, 0.9, 0.4];
    // Colour: src*As (0.5) and dst*Ad (0.4); alpha: src*1 and dst*(1-As) (0.5).
    let base = BlendState {
        color_eq: Add,
        alpha_eq: Add,
        src_color: SrcAlpha,
        dst_color: DstAlpha,
        src_alpha: One,
        dst_alpha: OneMinusSrcAlpha,
        constant: [0.0; 4],
    };
    let sc = src.map(|s| s * 0.5);
    let dc = dst.map(|d| d * 0.4);
    let sa = src[3];
    let da = dst[3] * 0.5;
    let rgb = |f: fn(f32, f32) -> f32| [f(sc[0], dc[0]), f(sc[1], dc[1]), f(sc[2], dc[2])];

    let add = base.blend(src, dst);
    let want = rgb(|s, d| s + d);
    assert_close(add, [want[0], want[1], want[2], sa + da]);

    let sub = BlendState {
        color_eq: Subtract,
        alpha_eq: Subtract,
        ..base
    }
    .blend(src, dst);
    let want = rgb(|s, d| s - d);
    assert_close(sub, [want[0], want[1], want[2], sa - da]);

    let rsub = BlendState {
        color_eq: ReverseSubtract,
        alpha_eq: ReverseSubtract,
        ..base
    }
    .blend(src, dst);
    let want = rgb(|s, d| d - s);
    assert_close(rsub, [want[0], want[1], want[2], da - sa]);

    // MIN and MAX ignore the factors.
    let min = BlendState {
        color_eq: Min,
        alpha_eq: Min,
        ..base
    }
    .blend(src, dst);
    assert_close(min, [0.3, 0.4, 0.2, 0.4]);
    let max = BlendState {
        color_eq: Max,
        alpha_eq: Max,
        ..base
    }
    .blend(src, dst);
    assert_close(max, [0.8, 0.6, 0.9, 0.5]);

    // Separate equations: colour MAX, alpha ADD with its own factors.
    let mixed = BlendState {
        color_eq: Max,
        alpha_eq: Add,
        ..base
    }
    .blend(src, dst);
    assert_close(mixed, [0.8, 0.6, 0.9, sa + da]);
    // Colour REVERSE_SUBTRACT, alpha MIN.
    let mixed = BlendState {
        color_eq: ReverseSubtract,
        alpha_eq: Min,
        ..base
    }
    .blend(src, dst);
    let want = rgb(|s, d| d - s);
    assert_close(mixed, [want[0], want[1], want[2], 0.4]);
}

#[test]
fn blend_state_equation_is_additive_with_unit_factors() {
    use BlendEquation::*;
    let src = [1.0, 2.0, 3.0, 4.0];
    let dst = [10.0, 20.0, 30.0, 40.0];
    assert_close(
        BlendState::equation(Add).blend(src, dst),
        [11.0, 22.0, 33.0, 44.0],
    );
    assert_close(
        BlendState::equation(Subtract).blend(src, dst),
        [-9.0, -18.0, -27.0, -36.0],
    );
    assert_close(
        BlendState::equation(ReverseSubtract).blend(src, dst),
        [9.0, 18.0, 27.0, 36.0],
    );
    assert_close(BlendState::equation(Min).blend(src, dst), src);
    assert_close(BlendState::equation(Max).blend(src, dst), dst);
    let b = BlendState::equation(Max);
    assert_eq!((b.color_eq, b.alpha_eq), (Max, Max));

    // Counting with additive blending on an R32F target: 5 fragments, count 5.
    let t = blend_target(Format::R32F, BlendState::equation(Add));
    let mut stored = [0u32; 4];
    for _ in 0..5 {
        stored = t.combine(bits([1.0, 0.0, 0.0, 0.0]), stored);
    }
    assert_eq!(floats(stored), [5.0, 0.0, 0.0, 0.0]);
}

#[test]
fn over_compositing_back_to_front() {
    let over = BlendState::over();
    assert_eq!(over.src_color, BlendFactor::SrcAlpha);
    assert_eq!(over.dst_color, BlendFactor::OneMinusSrcAlpha);
    assert_eq!(over.src_alpha, BlendFactor::One);
    assert_eq!(over.dst_alpha, BlendFactor::OneMinusSrcAlpha);

    let t = blend_target(Format::RGBA32F, over);
    // Opaque-ish background, then two translucent layers back to front.
    let bg = [0.0, 0.0, 1.0, 1.0];
    let l1 = [1.0, 0.0, 0.0, 0.5];
    let l2 = [0.0, 1.0, 0.0, 0.25];
    let mut stored = bits(bg);
    stored = t.combine(bits(l1), stored);
    assert_close(floats(stored), [0.5, 0.0, 0.5, 1.0]);
    stored = t.combine(bits(l2), stored);
    assert_close(floats(stored), [0.375, 0.25, 0.375, 1.0]);

    // On a transparent background the alpha accumulates coverage: 1 - (1-0.5)(1-0.25).
    let mut stored = [0u32; 4];
    stored = t.combine(bits(l1), stored);
    stored = t.combine(bits(l2), stored);
    assert_close(floats(stored), [0.375, 0.25, 0.0, 0.625]);
}

#[test]
fn float_target_with_fewer_channels_reads_missing_alpha_as_one() {
    // R32F has no alpha: destination alpha is 1, and the shader's alpha still drives
    // source-alpha factors. Channels beyond the format stay 0.
    let b = BlendState {
        color_eq: BlendEquation::Add,
        alpha_eq: BlendEquation::Add,
        src_color: BlendFactor::SrcAlpha,
        dst_color: BlendFactor::DstAlpha,
        src_alpha: BlendFactor::One,
        dst_alpha: BlendFactor::One,
        constant: [0.0; 4],
    };
    let t = blend_target(Format::R32F, b);
    let out = t.combine(bits([0.25, 9.0, 9.0, 0.5]), bits([0.5, 0.0, 0.0, 0.0]));
    assert_eq!(floats(out), [0.125 + 0.5, 0.0, 0.0, 0.0]);

    let t = blend_target(Format::RG32F, BlendState::equation(BlendEquation::Add));
    let out = t.combine(bits([1.0, 2.0, 3.0, 4.0]), bits([0.5, 0.5, 0.0, 0.0]));
    assert_eq!(floats(out), [1.5, 2.5, 0.0, 0.0]);

    // Without blending the bits are copied exactly (even NaN payloads), channels masked.
    let t = TargetState::new(Format::RG32F);
    let nan = 0x7fc0_1234;
    assert_eq!(t.combine([nan, 5, 6, 7], [0; 4]), [nan, 5, 0, 0]);
}

// ---------------------------------------------------------------------------------------
// RGBA8

#[test]
fn rgba8_clamps_and_quantizes_to_k_over_255() {
    let t = TargetState::new(Format::RGBA8);
    let out = t.combine(bits([0.5, 1.7, -0.3, f32::NAN]), [0; 4]);
    let want = [128.0 / 255.0, 1.0, 0.0, 0.0];
    assert_eq!(out, bits(want));
    assert_eq!(quantize_unorm8(0.5), 128.0 / 255.0);
    assert_eq!(quantize_unorm8(0.3), 77.0 / 255.0); // 76.5 rounds up

    // Every stored value is exactly k/255 and reads back as itself.
    for k in 0..=255u32 {
        let v = k as f32 / 255.0;
        let out = t.combine(bits([v, v + 0.001, v - 0.001, v]), [0; 4]);
        assert_eq!(out, bits([v; 4]), "k = {k}");
    }
}

#[test]
fn rgba8_blending_is_in_float_then_quantized() {
    // Additive blending of a small value is lost to quantization on RGBA8 (order-dependent
    // rounding the hazard catalogue mentions) but accumulates on RGBA32F.
    let add = BlendState::equation(BlendEquation::Add);
    let t8 = blend_target(Format::RGBA8, add);
    let t32 = blend_target(Format::RGBA32F, add);
    let small = bits([0.001; 4]);
    let (mut s8, mut s32) = ([0u32; 4], [0u32; 4]);
    for _ in 0..100 {
        s8 = t8.combine(small, s8);
        s32 = t32.combine(small, s32);
    }
    assert_eq!(floats(s8), [0.0; 4]);
    assert!((floats(s32)[0] - 0.1).abs() < 1e-4);

    // "over" on RGBA8: dst 200/255, src 0.5 with alpha 0.5: 0.25 + 100/255 -> round.
    let t = blend_target(Format::RGBA8, BlendState::over());
    let dst = bits([200.0 / 255.0, 0.0, 0.0, 1.0]);
    let out = floats(t.combine(bits([0.5, 0.0, 2.0, 0.5]), dst));
    let want_r = ((0.25f32 + 100.0 / 255.0) * 255.0).round() / 255.0;
    // Source blue is clamped to 1 before blending: 1 * 0.5 + 0 = 0.5 -> 128/255.
    assert_eq!(out, [want_r, 0.0, 128.0 / 255.0, 1.0]);

    // Blended results are clamped: ADD of 0.8 + 0.8 stores 1.0.
    let out = floats(t8.combine(bits([0.8; 4]), bits([204.0 / 255.0; 4])));
    assert_eq!(out, [1.0; 4]);
}

// ---------------------------------------------------------------------------------------
// Logic ops, integer targets, write masks

#[test]
fn logic_ops_on_r32ui() {
    let dst = [0b1100, 0, 0, 0];
    let src = [0b1010, 77, 88, 99];
    let with = |op| TargetState {
        logic_op: Some(op),
        ..TargetState::new(Format::R32UI)
    };
    assert_eq!(with(LogicOp::Or).combine(src, dst), [0b1110, 0, 0, 0]);
    assert_eq!(with(LogicOp::And).combine(src, dst), [0b1000, 0, 0, 0]);
    assert_eq!(with(LogicOp::Xor).combine(src, dst), [0b0110, 0, 0, 0]);
    assert_eq!(with(LogicOp::Copy).combine(src, dst), [0b1010, 0, 0, 0]);
    assert_eq!(
        TargetState::new(Format::R32UI).combine(src, dst),
        [0b1010, 0, 0, 0]
    );
    assert_eq!(LogicOp::Xor.apply(u32::MAX, 1), u32::MAX - 1);

    // Bucket histogram: OR-ing one bit per fragment.
    let t = with(LogicOp::Or);
    let mut stored = [0u32; 4];
    for b in [3, 7, 3, 31] {
        stored = t.combine([1 << b, 0, 0, 0], stored);
    }
    assert_eq!(stored[0], (1 << 3) | (1 << 7) | (1 << 31));
}

#[test]
fn blending_is_ignored_on_integer_targets() {
    let t = TargetState {
        blend: Some(BlendState::equation(BlendEquation::Add)),
        ..TargetState::new(Format::RGBA32UI)
    };
    assert_eq!(t.combine([1, 2, 3, 4], [10, 20, 30, 40]), [1, 2, 3, 4]);
    let t = TargetState {
        logic_op: Some(LogicOp::Xor),
        ..t
    };
    assert_eq!(t.combine([1, 2, 3, 4], [1, 0, 3, 0]), [0, 2, 0, 4]);
}

#[test]
fn write_masks_select_channels() {
    let dst = [10, 20, 30, 40];
    let src = [1, 2, 3, 4];
    let t = TargetState {
        write_mask: 0b0101,
        ..TargetState::new(Format::RGBA32UI)
    };
    assert_eq!(t.combine(src, dst), [1, 20, 3, 40]);
    let t = TargetState { write_mask: 0, ..t };
    assert_eq!(t.combine(src, dst), dst);

    // Float target with blending: masked channels keep dst bits exactly.
    let t = TargetState {
        write_mask: 0b1000,
        ..blend_target(Format::RGBA32F, BlendState::equation(BlendEquation::Add))
    };
    let out = t.combine(bits([1.0; 4]), bits([0.5, 0.25, 0.125, 2.0]));
    assert_eq!(floats(out), [0.5, 0.25, 0.125, 3.0]);

    // RGBA8 masked channels keep their stored (quantized) value.
    let t = TargetState {
        write_mask: 0b0010,
        ..TargetState::new(Format::RGBA8)
    };
    let dst = bits([1.0 / 255.0, 0.0, 2.0 / 255.0, 1.0]);
    let out = floats(t.combine(bits([0.5; 4]), dst));
    assert_eq!(out, [1.0 / 255.0, 128.0 / 255.0, 2.0 / 255.0, 1.0]);

    // Mask bits beyond the format's channels write nothing there.
    let t = TargetState::new(Format::R32UI);
    assert_eq!(t.combine([5, 6, 7, 8], [0; 4]), [5, 0, 0, 0]);
}

// ---------------------------------------------------------------------------------------
// Depth / stencil on tiles

fn tile(samples: u32, targets: usize) -> TileMemory {
    TileMemory::new(0, 0, 8, 8, 8, samples, targets)
}

fn depth_state(func: CompareFunc, write: bool) -> FragmentState {
    FragmentState {
        depth: DepthState {
            test: true,
            func,
            write,
        },
        ..FragmentState::new()
    }
}

#[test]
fn depth_test_every_func_and_write_mask() {
    use CompareFunc::*;
    for func in [
        Never,
        Less,
        Equal,
        LessEqual,
        Greater,
        NotEqual,
        GreaterEqual,
        Always,
    ] {
        for incoming in [0.25f32, 0.5, 0.75] {
            let mut t = tile(1, 0);
            t.depth.fill(0.5);
            let st = depth_state(func, true);
            let passed = t.depth_stencil(&st, 3, 4, 1, &[incoming; 8], true, true);
            let want = func.test(incoming, 0.5);
            assert_eq!(passed == 1, want, "{func:?} {incoming}");
            let i = t.index(3, 4, 0);
            assert_eq!(t.depth[i], if want { incoming } else { 0.5 });
        }
    }
    // Depth write disabled in the state, or not requested by the caller: no write.
    let mut t = tile(1, 0);
    let st = depth_state(Less, false);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.1; 8], true, true), 1);
    assert_eq!(t.depth[0], 1.0);
    let st = depth_state(Less, true);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.1; 8], true, false), 1);
    assert_eq!(t.depth[0], 1.0);
}

#[test]
fn depth_test_disabled_never_writes_depth() {
    let mut t = tile(4, 0);
    let st = FragmentState {
        depth: DepthState {
            test: false,
            func: CompareFunc::Less,
            write: true,
        },
        ..FragmentState::new()
    };
    assert_eq!(
        t.depth_stencil(&st, 1, 1, 0b1011, &[0.2; 8], true, true),
        0b1011
    );
    assert!(t.depth.iter().all(|&d| d == 1.0));
}

#[test]
fn msaa_partial_coverage_and_sample_mask() {
    let mut t = tile(4, 1);
    let mut st = depth_state(CompareFunc::Less, true);
    st.targets.push(TargetState::new(Format::R32UI));
    let i0 = t.index(2, 5, 0);
    // Per-sample stored depths: sample 2 is nearer than the fragment there.
    t.depth[i0..i0 + 4].copy_from_slice(&[1.0, 1.0, 0.1, 1.0]);
    let depths = [0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0];
    // Coverage 0b0111 and bits beyond the 4 samples (ignored); sample 3 uncovered.
    let passed = t.depth_stencil(&st, 2, 5, 0b1111_0111, &depths, true, true);
    assert_eq!(passed, 0b0011);
    assert_eq!(&t.depth[i0..i0 + 4], &[0.5, 0.5, 0.1, 1.0]);
    t.write_outputs(&st, 2, 5, passed, &[[42, 0, 0, 0]]);
    let got: Vec<u32> = (0..4).map(|s| t.color[0][i0 + s][0]).collect();
    assert_eq!(got, [42, 42, 0, 0]);
    // Neighbouring pixels untouched.
    assert!(t.color[0][..i0]
        .iter()
        .chain(&t.color[0][i0 + 4..])
        .all(|c| *c == [0; 4]));

    // The sample mask removes samples before any test.
    st.sample_mask = 0b0010;
    let passed = t.depth_stencil(&st, 2, 5, 0b1111, &[0.25; 8], true, true);
    assert_eq!(passed, 0b0010);
    assert_eq!(&t.depth[i0..i0 + 4], &[0.5, 0.25, 0.1, 1.0]);
}

fn stencil_state(front: StencilFace, back: StencilFace) -> FragmentState {
    FragmentState {
        stencil: StencilState {
            enabled: true,
            front,
            back,
        },
        ..FragmentState::new()
    }
}

#[test]
fn stencil_test_ops_and_masks() {
    use StencilOp::*;
    // Test (ref & read_mask) EQUAL (stored & read_mask) with only the low nibble compared.
    let face = StencilFace {
        func: CompareFunc::Equal,
        fail_op: Invert,
        depth_fail_op: IncrWrap,
        pass_op: Replace,
        reference: 0x13,
        read_mask: 0x0f,
        write_mask: 0xf0,
    };
    let mut st = stencil_state(face, face);
    st.depth = DepthState {
        test: true,
        func: CompareFunc::Less,
        write: true,
    };
    let mut t = tile(4, 0);
    let i0 = t.index(0, 0, 0);
    // Sample 0: low nibble 3 (test passes), depth passes -> Replace under mask 0xf0: 0x13.
    // Sample 1: low nibble 4 (test fails) -> Invert (0x5b) under mask 0xf0: 0x54.
    // Sample 2: test passes, depth fails -> IncrWrap (0xf4) under mask 0xf0: stays 0xf3.
    // Sample 3: would fail the test, but is not covered: untouched.
    t.stencil[i0..i0 + 4].copy_from_slice(&[0xa3, 0xa4, 0xf3, 0x2f]);
    t.depth[i0 + 2] = 0.1;
    let passed = t.depth_stencil(&st, 0, 0, 0b0111, &[0.5; 8], true, true);
    assert_eq!(passed, 0b0001);
    assert_eq!(&t.stencil[i0..i0 + 4], &[0x13, 0x54, 0xf3, 0x2f]);
    assert_eq!(&t.depth[i0..i0 + 4], &[0.5, 1.0, 0.1, 1.0]);

    // With the full write mask the depth-fail op lands whole.
    let face = StencilFace {
        write_mask: 0xff,
        ..face
    };
    let mut st = stencil_state(face, face);
    st.depth = DepthState {
        test: true,
        func: CompareFunc::Never,
        write: true,
    };
    assert_eq!(t.depth_stencil(&st, 0, 0, 0b0100, &[0.5; 8], true, true), 0);
    assert_eq!(t.stencil[i0 + 2], 0xf4);
    // A sample passing both tests takes the pass op (Replace): 0xe3 passes (the read mask
    // ignores the high nibble) and becomes the reference 0x13.
    st.depth.func = CompareFunc::Always;
    t.stencil[i0] = 0xe3;
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.75; 8], true, true), 1);
    assert_eq!(t.stencil[i0], 0x13);
    assert_eq!(t.depth[i0], 0.75);

    // Stencil ops do nothing when the stencil test is disabled.
    let mut st = st.clone();
    st.depth.func = CompareFunc::Never;
    st.stencil.enabled = false;
    t.stencil[i0] = 0x77;
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], true, true), 0);
    assert_eq!(t.stencil[i0], 0x77);
}

#[test]
fn front_and_back_faces_use_their_own_stencil_state() {
    use StencilOp::*;
    let front = StencilFace {
        func: CompareFunc::Always,
        pass_op: IncrClamp,
        ..Default::default()
    };
    let back = StencilFace {
        func: CompareFunc::Always,
        pass_op: Replace,
        reference: 200,
        ..Default::default()
    };
    let st = stencil_state(front, back);
    let mut t = tile(1, 0);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], true, true), 1);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], true, true), 1);
    assert_eq!(t.stencil[0], 2);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], false, true), 1);
    assert_eq!(t.stencil[0], 200);

    // A back-only test: front faces pass, back faces fail (and take the back fail op).
    let front = StencilFace::default();
    let back = StencilFace {
        func: CompareFunc::Never,
        fail_op: Zero,
        ..Default::default()
    };
    let st = stencil_state(front, back);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], true, true), 1);
    assert_eq!(t.stencil[0], 200);
    assert_eq!(t.depth_stencil(&st, 0, 0, 1, &[0.5; 8], false, true), 0);
    assert_eq!(t.stencil[0], 0);
}

#[test]
fn stencil_routing_sends_each_fragment_to_one_sample() {
    use StencilOp::*;
    // Bavoil & Myers' stencil-routed A-buffer on 8 samples: initialise sample s's stencil to
    // s + 2 (one full-screen pass per sample through the sample mask), then draw with
    // EQUAL 2 and DECR on pass and fail: fragment k lands in sample k, the rest are lost.
    let mut fb = Framebuffer::new(8, 8, SampleCount::X8, 8, &[Format::R32F]).unwrap();
    let init_face = StencilFace {
        func: CompareFunc::Always,
        pass_op: Replace,
        ..Default::default()
    };
    for s in 0..8u8 {
        let mut st = stencil_state(init_face, init_face);
        st.stencil.front.reference = s + 2;
        st.sample_mask = 1 << s;
        let t = &mut fb.tiles_mut()[0];
        assert_eq!(
            t.depth_stencil(&st, 3, 3, 0xff, &[0.5; 8], true, false),
            1 << s
        );
    }
    for s in 0..8 {
        assert_eq!(fb.stencil(3, 3, s), s as u8 + 2);
    }

    let route = StencilFace {
        func: CompareFunc::Equal,
        fail_op: DecrClamp,
        depth_fail_op: Keep,
        pass_op: DecrClamp,
        reference: 2,
        read_mask: 0xff,
        write_mask: 0xff,
    };
    let mut st = stencil_state(route, route);
    st.targets.push(TargetState::new(Format::R32F));
    for k in 0..10u32 {
        let t = &mut fb.tiles_mut()[0];
        let passed = t.depth_stencil(&st, 3, 3, 0xff, &[0.5; 8], k % 2 == 0, false);
        if k < 8 {
            assert_eq!(passed, 1 << k, "fragment {k} routed to one sample");
        } else {
            assert_eq!(
                passed, 0,
                "fragment {k} exceeds the sample count and is lost"
            );
        }
        t.write_outputs(
            &st,
            3,
            3,
            passed,
            &[bits([k as f32 + 100.0, 0.0, 0.0, 0.0])],
        );
    }
    let image = fb.image(0);
    for s in 0..8 {
        assert_eq!(image.texel_f32(3, 3, s)[0], s as f32 + 100.0);
        assert_eq!(fb.stencil(3, 3, s), 0);
    }
    // Other pixels untouched.
    assert_eq!(image.texel(2, 3, 0), [0; 4]);
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
    assert_eq!(t.color[0][i], [1, 0, 0, 0]);
    assert_eq!(t.color[1][i], [2, 3, 4, 5]);
    assert_eq!(t.color[2][i], [0; 4]);
    assert_eq!(t.color[0][i - 1], [0; 4], "sample 0 is not in the mask");
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
        assert_eq!(t.color[0].len(), 64 * 64 * 4);
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
