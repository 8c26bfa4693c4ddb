//! Formats and blending: factors and equations, over compositing, RGBA8 quantization, logic
//! ops on integer targets, write masks.

use fragrace_emu::state::{
    quantize_unorm8, BlendEquation, BlendFactor, BlendState, Format, LogicOp, TargetState,
};

use super::common::*;

fn blend_target(format: Format, blend: BlendState) -> TargetState {
    TargetState {
        blend: Some(blend),
        ..TargetState::new(format)
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
