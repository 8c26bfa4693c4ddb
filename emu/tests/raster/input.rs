//! Bad input: non-finite coordinates, out-of-range indices and degenerate triangles give
//! nothing (never a panic), and `well_formed` names them.

use fragrace_emu::raster::*;
use glam::Vec4;

use super::common::*;

#[test]
fn non_finite_coordinates_are_rejected() {
    let v = vp(32, 32);
    let mut pos = vec![
        Vec4::new(-0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.0, 0.5, 0.0, 1.0),
    ];
    pos.push(Vec4::new(f32::NAN, 0.0, 0.0, 1.0));
    pos.push(Vec4::new(0.0, f32::INFINITY, 0.0, 1.0));
    pos.push(Vec4::new(0.0, 0.0, 0.0, f32::NEG_INFINITY));
    let idx = [[0u32, 1, 3], [0, 1, 2], [4, 1, 2], [0, 5, 2], [3, 4, 5]];
    for threads in [1, 3] {
        let b = bin_triangles(&pos, &idx, &RasterState::default(), v, threads);
        assert_eq!(b.rejected, 4);
        assert_eq!(b.tris.len(), 1);
        assert_eq!(b.tris[0].source, 1);
        assert!(!all_frags(&b).is_empty());
    }
}

#[test]
fn out_of_range_indices_do_not_panic() {
    let v = vp(32, 32);
    let pos = [
        Vec4::new(-0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.0, 0.5, 0.0, 1.0),
    ];
    let b = bin(
        &pos,
        &[[0, 1, 7], [0, 1, 2], [u32::MAX, 0, 1]],
        &RasterState::default(),
        v,
    );
    assert_eq!(b.rejected, 2);
    assert_eq!(b.tris.len(), 1);
    let b = bin(&[], &[[0, 1, 2]], &RasterState::default(), v);
    assert_eq!(b.rejected, 1);
    assert!(all_frags(&b).is_empty());
    // No triangles at all.
    let b = bin(&pos, &[], &RasterState::default(), v);
    assert!(b.tris.is_empty() && all_frags(&b).is_empty());
    // Empty viewport.
    let b = bin(&pos, &[[0, 1, 2]], &RasterState::default(), vp(0, 0));
    assert_eq!(b.tile_count(), 0);
    assert!(all_frags(&b).is_empty());
}

#[test]
fn degenerate_triangles_produce_nothing() {
    let v = vp(32, 32);
    let pos = [
        px(2.5, 2.5, v),
        px(20.5, 20.5, v),
        px(11.5, 11.5, v), // collinear with the first two
        px(2.5, 2.5, v),   // duplicate of the first
        px(2.5 + 1.0 / 1024.0, 2.5, v),
    ];
    for samples in [SampleCount::X1, SampleCount::X8] {
        let b = bin(
            &pos,
            &[[0, 1, 2], [0, 3, 1], [0, 4, 3], [2, 2, 2]],
            &state(samples),
            v,
        );
        assert!(all_frags(&b).is_empty());
        assert!(b.tris.is_empty());
        assert_eq!(b.rejected, 0);
    }
}

/// A mesh with a non-finite vertex or an index out of range is not well formed (the
/// unbinned path leaves it to binning, which counts and drops its triangles).
#[test]
fn well_formed_sees_bad_vertices_and_indices() {
    let v = vp(32, 32);
    let st = state(X1);
    let pos = [px(1.0, 1.0, v), px(30.0, 2.0, v), px(3.0, 30.0, v)];
    let ok = prepare(&pos, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip);
    assert!(ok.well_formed(1));
    let bad_index = prepare(&pos, &[[0, 1, 3]], &st, v, 1, PlaneSetup::Skip);
    assert!(!bad_index.well_formed(1));
    let mut nan = pos;
    nan[1].x = f32::NAN;
    assert!(!prepare(&nan, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    let mut inf = pos;
    inf[2].w = f32::INFINITY;
    assert!(!prepare(&inf, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    assert!(prepare(&pos, &[], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    // Many triangles, checked on several threads: a bad index in any part is found.
    let mut many = vec![[0u32, 1, 2]; 300_000];
    assert!(prepare(&pos, &many, &st, v, 4, PlaneSetup::Skip).well_formed(4));
    for at in [0, 150_000, 299_999] {
        many[at] = [0, 3, 2];
        {
            let bad = prepare(&pos, &many, &st, v, 4, PlaneSetup::Skip);
            assert!(!bad.well_formed(1) && !bad.well_formed(2) && !bad.well_formed(4));
        }
        many[at] = [0, 1, 2];
    }
}
