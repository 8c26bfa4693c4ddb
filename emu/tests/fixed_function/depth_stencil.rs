//! Compare funcs, depth and stencil tests and ops with their masks, per-sample depth and
//! stencil with MSAA, two-sided stencil, stencil routing.

use fragrace_emu::framebuffer::Framebuffer;
use fragrace_emu::raster::SampleCount;
use fragrace_emu::state::{
    CompareFunc, DepthState, Format, FragmentState, StencilFace, StencilOp, StencilState,
    TargetState,
};

use super::common::*;

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

#[test]
fn fragment_state_default_is_new_with_all_samples() {
    let d = FragmentState::default();
    assert_eq!(d, FragmentState::new());
    assert_eq!(d.sample_mask, 0xff);
    assert!(!d.depth.test && !d.depth.write && !d.stencil.enabled);
    assert!(d.targets.is_empty());
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
    let got: Vec<u32> = (0..4).map(|s| t.color_at(0, i0 + s)[0]).collect();
    assert_eq!(got, [42, 42, 0, 0]);
    // Neighbouring pixels untouched.
    assert!((0..t.plane_len())
        .filter(|i| !(i0..i0 + 4).contains(i))
        .all(|i| t.color_at(0, i) == [0; 4]));

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
