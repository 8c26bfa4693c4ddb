//! What "exact" means for depth-presorted triangle lists ([`super::presorted`]): the truth
//! orders a pixel's fragments by rasterized depths, which carry the error of the
//! rasterizer's snapped vertices, while the lists order by the exact geometry. So the draw
//! order is checked against the exact (f64) depth order at every pixel centre, and the
//! image against the truth's composite up to the order of fragments whose rasterized depths
//! tie within their error bounds.

use fragrace_emu::Mesh;
use fragrace_kernels::algo::{Capture, CapturedFrag};
use fragrace_kernels::presorted;
use glam::{DMat4, DVec3, DVec4, Vec3};

/// Bound on the error of a triangle's rasterized window depth at a pixel it covers. The
/// rasterizer snaps vertices to 1/256 pixel (round to nearest: each moves by at most
/// `sqrt(2) / 512` pixel) and interpolates the depths of the snapped vertices; the snapped
/// and the exact depth planes differ by an affine function, largest at a snapped vertex,
/// where it is `|grad z| * sqrt(2) / 512`, and a covered pixel centre lies in the snapped
/// triangle. Plus 8 ulps of the depth for the f32 plane evaluation. (At 40 x 40 the
/// gradients reach tenths of the depth range per pixel: bounds of 1e-4 and more, largest
/// for triangles seen edge-on.)
pub fn tie_bound(view_proj: &DMat4, tri: [Vec3; 3], width: u32, height: u32, depth: f32) -> f64 {
    let s = tri.map(|p| {
        let c = *view_proj * p.as_dvec3().extend(1.0);
        DVec3::new(
            (c.x / c.w + 1.0) * 0.5 * f64::from(width),
            (1.0 - c.y / c.w) * 0.5 * f64::from(height),
            (c.z / c.w + 1.0) * 0.5,
        )
    });
    let n = (s[1] - s[0]).cross(s[2] - s[0]);
    // z = z0 - (n.x (x - x0) + n.y (y - y0)) / n.z
    let grad = if n.z.abs() > 0.0 {
        (n.x * n.x + n.y * n.y).sqrt() / n.z.abs()
    } else {
        f64::INFINITY
    };
    let snap = 2f64.sqrt() / f64::from(1u32 << (fragrace_emu::raster::SUBPIXEL_BITS + 1));
    grad * snap + 8.0 * f64::from(f32::EPSILON) * f64::from(depth.abs().max(f32::MIN_POSITIVE))
}

/// Whether `got` is, within 1/255 per channel, the composite of `frags` (front to back, as
/// the truth sorts them) in some order that only exchanges fragments whose rasterized
/// depths tie: consecutive fragments whose depths differ by at most the sum of their
/// [`tie_bound`]s form a group, and only the order inside a group is free (groups of up to
/// 6 fragments; a larger one counts as a mismatch).
pub fn matches_up_to_ties(
    got: [f32; 4],
    frags: &[CapturedFrag],
    bounds: &[f64],
    alpha: f32,
    background: [f32; 3],
) -> bool {
    let close = |c: [f32; 4]| (0..4).all(|k| (got[k] - c[k]).abs() <= 1.0 / 255.0);
    let mut groups: Vec<std::ops::Range<usize>> = Vec::new();
    for i in 0..frags.len() {
        let tied = i > 0
            && f64::from(frags[i].depth) - f64::from(frags[i - 1].depth)
                <= bounds[i] + bounds[i - 1];
        match groups.last_mut() {
            Some(g) if tied => g.end = i + 1,
            _ => groups.push(i..i + 1),
        }
    }
    if groups.iter().any(|g| g.len() > 6) {
        return false;
    }
    // Every order: the product of each group's permutations (lexicographic enumeration).
    let mut order: Vec<usize> = (0..frags.len()).collect();
    loop {
        let seq: Vec<CapturedFrag> = order.iter().map(|&i| frags[i]).collect();
        if close(fragrace_kernels::common::composite_frags(
            &seq, alpha, background,
        )) {
            return true;
        }
        // The next permutation of the last group that has one; earlier groups reset.
        let mut advanced = false;
        for g in groups.iter().rev() {
            if next_permutation(&mut order[g.clone()]) {
                advanced = true;
                break;
            }
        }
        if !advanced {
            return false;
        }
    }
}

/// The next lexicographic permutation (false, and the slice sorted again, after the last).
fn next_permutation(v: &mut [usize]) -> bool {
    let Some(i) = (1..v.len()).rev().find(|&i| v[i - 1] < v[i]) else {
        v.sort_unstable();
        return false;
    };
    let j = (i..v.len())
        .rev()
        .find(|&j| v[j] > v[i - 1])
        .expect("exists");
    v.swap(i - 1, j);
    v[i..].reverse();
    true
}

/// The draw order of the lists against the exact depth order at every pixel centre: for
/// each pair of the truth's fragments of one pixel whose triangles the pixel centre's ray
/// meets inside (f64, not the rasterizer's snapped triangles), the instance selected for
/// the piece hit (host evaluation of its tests) is drawn first iff it is the farther.
/// Panics naming the pixel and triangles of the first inversion.
pub fn draw_order_is_exact(
    prep: &presorted::runtime::Prepared,
    mesh: &Mesh,
    view_proj: glam::Mat4,
    cap: &Capture,
    what: &str,
) {
    let eye = presorted::runtime::eye_of(view_proj).unwrap();
    // A viewpoint inside the bounding polyhedron is refused by the run (counted there).
    let Ok(k) = prep.lists.locate(eye) else {
        return;
    };
    let seg = &prep.segments[k];
    let mut selected = vec![usize::MAX; prep.lists.pieces.len()];
    for i in 0..seg.piece.len() {
        if seg.passes(i, eye.as_vec3()) {
            selected[seg.piece[i] as usize] = i;
        }
    }
    let mut pieces_of: Vec<Vec<usize>> = vec![Vec::new(); mesh.indices.len()];
    for (i, p) in prep.lists.pieces.iter().enumerate() {
        pieces_of[p.tri as usize].push(i);
    }
    let inv = DMat4::from_cols_array(&view_proj.to_cols_array().map(f64::from)).inverse();
    let (w, h) = (f64::from(cap.width), f64::from(cap.height));
    for p in 0..cap.pixels() {
        let (x, y) = (
            (p % cap.width as usize) as f64,
            (p / cap.width as usize) as f64,
        );
        let far = inv
            * DVec4::new(
                2.0 * (x + 0.5) / w - 1.0,
                1.0 - 2.0 * (y + 0.5) / h,
                1.0,
                1.0,
            );
        let dir = far.truncate() / far.w - eye;
        // (draw position, distance along the ray, triangle) of the hits inside.
        let mut hits: Vec<(usize, f64, u32)> = Vec::new();
        for f in cap.pixel(p) {
            let t = mesh.indices[f.prim as usize].map(|i| mesh.positions[i as usize].as_dvec3());
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            let s = n.dot(t[0] - eye) / n.dot(dir);
            let hit = eye + dir * s;
            let inside = (0..3).all(|e| (t[(e + 1) % 3] - t[e]).cross(hit - t[e]).dot(n) >= 0.0);
            if !inside {
                continue;
            }
            let at = hit.as_vec3();
            let piece = pieces_of[f.prim as usize].iter().copied().find(|&pc| {
                prep.lists.pieces[pc].clips.iter().all(|c| {
                    let q = c.plane;
                    (q[0] * at.x + q[1] * at.y + q[2] * at.z - q[3] >= 0.0) == c.nonneg
                })
            });
            if let Some(pc) = piece {
                hits.push((selected[pc], s, f.prim));
            }
        }
        hits.sort_by_key(|h| h.0);
        for pair in hits.windows(2) {
            assert!(
                pair[0].1 >= pair[1].1,
                "{what}: pixel ({x}, {y}): instance {} (triangle {}) is drawn before instance \
                 {} (triangle {}) but is nearer along the pixel centre's ray ({} < {})",
                pair[0].0,
                pair[0].2,
                pair[1].0,
                pair[1].2,
                pair[0].1,
                pair[1].1
            );
        }
    }
}
