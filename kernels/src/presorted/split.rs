//! Splitting intersecting triangles before the graph ("Depth-Presorted Triangle Lists",
//! section 4: "we assume intersecting triangles have been split prior to invocation of our
//! preprocessing algorithm ... Additional preprocessing can break cycles by splitting
//! triangles when needed").
//!
//! Two triangles that cross each other are seen in both depth orders from one viewpoint
//! (each hides part of the other): no order of whole triangles is right for that view, and
//! the scan could never remove that cycle. Splitting one of them, `a`, by the other's
//! plane is enough: each piece lies in one closed half-space of `b`'s plane, and a triangle
//! `x` in a closed half-space of triangle `y`'s plane is never seen both in front of and
//! behind `y` from one viewpoint (from `x`'s side, the segment from the eye to `x` stays on
//! that side and cannot pass through `y`; from the other side, the segment to `y` cannot
//! reach `x`).
//!
//! Pieces are kept in `f64` for the graph. At run time a piece is not drawn from its own
//! corners (cut points rounded to `f32` would bend the input's edges: at a silhouette the
//! pixels in that sliver are gained or lost by both the front and the back triangle), but
//! as its whole input triangle with the piece's [`Clip`]s tested per fragment at the
//! fragment's position on the input triangle: the two sides of a cut test the same plane,
//! one `>= 0` and the other `< 0`, so every fragment of the input triangle belongs to
//! exactly one piece, whatever the rounding.

use std::collections::HashMap;

use glam::DVec3;

use super::geom::{Plane, EPS};
use super::graph::facing;

/// A half-space a piece keeps of its input triangle: the points `p` with
/// `plane.eval(p) >= 0` when `nonneg`, else those with `plane.eval(p) < 0` (the two pieces
/// of a cut share the plane, so they take complementary sets of points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    pub plane: Plane,
    pub nonneg: bool,
}

/// A piece of an input triangle (the whole triangle when it is not split).
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    pub tri: u32,
    /// The corners (normalized frame).
    pub pos: [DVec3; 3],
    /// What it keeps of its input triangle (empty: all of it).
    pub clips: Vec<Clip>,
}

/// What splitting did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SplitStats {
    /// Crossing pairs found (each cured by splitting one triangle of the pair).
    pub crossings: u64,
    /// Pieces beyond the input triangles.
    pub extra_pieces: u64,
    /// Cuts that broke cycles seen whole from a viewpoint ([`break_cycle`]).
    pub cycle_cuts: u64,
}

/// Why splitting failed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SplitError {
    #[error(
        "triangles {first} and {second} overlap in one plane: no viewpoint sees them in one \
         order (remove one, or cut them so that they no longer overlap)"
    )]
    Coplanar { first: u32, second: u32 },
    #[error("splitting intersecting triangles made more than {limit} pieces: the mesh intersects itself too much")]
    TooMany { limit: usize },
}

/// Pieces a mesh may grow to (per input triangle) before splitting gives up.
pub const MAX_PIECES_PER_TRIANGLE: usize = 16;

/// Signed distances below this (normalized frame) count as on a plane.
const ON: f64 = EPS;

/// Splits the triangles `tris` (normalized frame) until no two pieces cross.
pub fn split_crossing(tris: &[[DVec3; 3]]) -> Result<(Vec<Piece>, SplitStats), SplitError> {
    let mut pieces: Vec<Piece> = tris
        .iter()
        .enumerate()
        .map(|(t, p)| Piece {
            tri: t as u32,
            pos: *p,
            clips: Vec::new(),
        })
        .collect();
    let mut stats = SplitStats::default();
    let limit = MAX_PIECES_PER_TRIANGLE * tris.len().max(1);
    // A uniform grid over the pieces' bounding boxes; rebuilt each round (rounds are few).
    loop {
        let pairs = candidate_pairs(&pieces);
        let mut split: HashMap<usize, [DVec3; 3]> = HashMap::new();
        for (i, j) in pairs {
            if split.contains_key(&i) || split.contains_key(&j) {
                continue;
            }
            match crossing(&pieces[i].pos, &pieces[j].pos) {
                Cross::No => {}
                Cross::Coplanar => {
                    if pieces[i].tri != pieces[j].tri {
                        return Err(SplitError::Coplanar {
                            first: pieces[i].tri.min(pieces[j].tri),
                            second: pieces[i].tri.max(pieces[j].tri),
                        });
                    }
                }
                Cross::Yes => {
                    stats.crossings += 1;
                    split.insert(i, pieces[j].pos);
                }
            }
        }
        if split.is_empty() {
            break;
        }
        let mut next: Vec<Piece> = Vec::with_capacity(pieces.len() + 2 * split.len());
        for (i, p) in pieces.into_iter().enumerate() {
            match split.get(&i) {
                None => next.push(p),
                Some(by) => next.extend(cut(&p, by)),
            }
        }
        pieces = next;
        if pieces.len() > limit {
            return Err(SplitError::TooMany { limit });
        }
    }
    stats.extra_pieces = (pieces.len() - tris.len()) as u64;
    Ok((pieces, stats))
}

/// Breaks a cycle of pieces seen whole from some viewpoint ("Depth-Presorted Triangle
/// Lists", section 4: "additional preprocessing can break cycles by splitting triangles
/// when needed"): the first piece of the cycle (in cycle order, neighbours first) that
/// reaches across another's plane by more than [`CYCLE_CUT_MIN`] on both sides is cut by
/// that plane, as a crossing pair is. The pieces stay in place (the cut piece's first part
/// keeps its index, the others go last). Returns the piece cut, `None` when no piece
/// straddles another's plane.
pub fn break_cycle(pieces: &mut Vec<Piece>, cycle: &[u32]) -> Option<usize> {
    let k = cycle.len();
    let mut pairs: Vec<(usize, usize)> = (0..k)
        .flat_map(|i| (0..k).filter(move |&j| j != i).map(move |j| (i, j)))
        .collect();
    pairs.sort_by_key(|&(i, j)| (i + k - j) % k);
    for (i, j) in pairs {
        let (a, b) = (cycle[i] as usize, cycle[j] as usize);
        if a == b || a >= pieces.len() || b >= pieces.len() {
            continue;
        }
        let h = facing(&pieces[b].pos, false);
        let d = pieces[a].pos.map(|v| h.eval(v));
        let lo = d.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo < -CYCLE_CUT_MIN && hi > CYCLE_CUT_MIN {
            let by = pieces[b].pos;
            let mut parts = cut(&pieces[a], &by).into_iter();
            if let Some(first) = parts.next() {
                pieces[a] = first;
                pieces.extend(parts);
                return Some(a);
            }
        }
    }
    None
}

/// How far (normalized frame) a piece must reach to both sides of a plane for
/// [`break_cycle`] to cut it there (a thinner part would be a sliver).
pub const CYCLE_CUT_MIN: f64 = 1e-6;

/// Where the edge `a`-`b` meets the plane whose signed distances at `a` and `b` are `da`
/// and `db` (of opposite signs), computed from the endpoints in one fixed order: the pieces
/// on the two sides of an edge, cut by the same plane, get the same point bit for bit.
fn edge_point(a: DVec3, da: f64, b: DVec3, db: f64) -> DVec3 {
    let key = |v: DVec3| v.to_array().map(f64::to_bits);
    let ((a, da), (b, db)) = if key(a) <= key(b) {
        ((a, da), (b, db))
    } else {
        ((b, db), (a, da))
    };
    a + (b - a) * (da / (da - db))
}

/// Pairs of pieces whose bounding boxes overlap (`i < j`).
fn candidate_pairs(pieces: &[Piece]) -> Vec<(usize, usize)> {
    let boxes: Vec<(DVec3, DVec3)> = pieces
        .iter()
        .map(|p| {
            (
                p.pos[0].min(p.pos[1]).min(p.pos[2]) - DVec3::splat(ON),
                p.pos[0].max(p.pos[1]).max(p.pos[2]) + DVec3::splat(ON),
            )
        })
        .collect();
    // Cell size: the average box extent (at least a small absolute size).
    let avg = boxes
        .iter()
        .map(|(lo, hi)| (*hi - *lo).max_element())
        .sum::<f64>()
        / boxes.len().max(1) as f64;
    let cell = avg.max(1e-6);
    let key = |v: DVec3| (v / cell).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<usize>> = HashMap::new();
    for (i, (lo, hi)) in boxes.iter().enumerate() {
        let (a, b) = (key(*lo), key(*hi));
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                for z in a.z..=b.z {
                    grid.entry(glam::IVec3::new(x, y, z)).or_default().push(i);
                }
            }
        }
    }
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for ids in grid.values() {
        for (k, &i) in ids.iter().enumerate() {
            for &j in &ids[k + 1..] {
                let (bi, bj) = (&boxes[i], &boxes[j]);
                if bi.0.cmple(bj.1).all() && bj.0.cmple(bi.1).all() {
                    pairs.push((i.min(j), i.max(j)));
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

enum Cross {
    No,
    Yes,
    Coplanar,
}

/// Whether triangles `a` and `b` cross: each has corners strictly on both sides of the
/// other's plane, and the two segments where each meets the other's plane overlap (more
/// than a point). Coplanar triangles whose interiors overlap are reported as such.
fn crossing(a: &[DVec3; 3], b: &[DVec3; 3]) -> Cross {
    let pa = facing(a, false);
    let pb = facing(b, false);
    let da = b.map(|q| pa.eval(q));
    let db = a.map(|p| pb.eval(p));
    let straddles = |d: &[f64; 3]| d.iter().any(|x| *x > ON) && d.iter().any(|x| *x < -ON);
    if da.iter().all(|x| x.abs() <= ON) {
        return if coplanar_overlap(a, b, pa.n) {
            Cross::Coplanar
        } else {
            Cross::No
        };
    }
    if !straddles(&da) || !straddles(&db) {
        return Cross::No;
    }
    // The line of the two planes; each triangle's segment on it.
    let dir = pa.n.cross(pb.n);
    if dir.length_squared() < 1e-24 {
        return Cross::No;
    }
    let seg = |t: &[DVec3; 3], d: &[f64; 3]| {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for k in 0..3 {
            let l = (k + 1) % 3;
            let (x, y) = (d[k], d[l]);
            if x.abs() <= ON {
                let s = dir.dot(t[k]);
                lo = lo.min(s);
                hi = hi.max(s);
            }
            if (x > ON && y < -ON) || (x < -ON && y > ON) {
                let p = t[k] + (t[l] - t[k]) * (x / (x - y));
                let s = dir.dot(p);
                lo = lo.min(s);
                hi = hi.max(s);
            }
        }
        (lo, hi)
    };
    let (alo, ahi) = seg(a, &db);
    let (blo, bhi) = seg(b, &da);
    let overlap = ahi.min(bhi) - alo.max(blo);
    if overlap > ON * dir.length() {
        Cross::Yes
    } else {
        Cross::No
    }
}

/// Whether two coplanar triangles (normal `n`) overlap in more than a boundary: no edge of
/// either separates them (2D separating axes).
fn coplanar_overlap(a: &[DVec3; 3], b: &[DVec3; 3], n: DVec3) -> bool {
    for (t, o) in [(a, b), (b, a)] {
        for k in 0..3 {
            let e = t[(k + 1) % 3] - t[k];
            let axis = n.cross(e);
            let pt = t.map(|p| axis.dot(p));
            let po = o.map(|p| axis.dot(p));
            let (tlo, thi) = (
                pt.iter().copied().fold(f64::INFINITY, f64::min),
                pt.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            let (olo, ohi) = (
                po.iter().copied().fold(f64::INFINITY, f64::min),
                po.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            let tol = ON * axis.length();
            if thi <= olo + tol || ohi <= tlo + tol {
                return false;
            }
        }
    }
    true
}

/// The pieces of `p` on either side of `by`'s plane (a triangle and a quad, the quad in two
/// triangles; corners on the plane go to both sides). Each keeps `p`'s clips plus its side
/// of the cut, and a quad's triangles their side of the diagonal (a plane through it,
/// across the triangle).
fn cut(p: &Piece, by: &[DVec3; 3]) -> Vec<Piece> {
    let h = facing(by, false);
    let d = p.pos.map(|v| h.eval(v));
    let normal = (p.pos[1] - p.pos[0]).cross(p.pos[2] - p.pos[0]);
    let mut out = Vec::with_capacity(3);
    for sign in [1.0f64, -1.0] {
        let mut poly: Vec<DVec3> = Vec::with_capacity(4);
        for k in 0..3 {
            let l = (k + 1) % 3;
            let (x, y) = (d[k] * sign, d[l] * sign);
            if x >= -ON {
                poly.push(p.pos[k]);
            }
            if (x > ON && y < -ON) || (x < -ON && y > ON) {
                poly.push(edge_point(p.pos[k], d[k], p.pos[l], d[l]));
            }
        }
        let mut clips = p.clips.clone();
        clips.push(Clip {
            plane: h,
            nonneg: sign > 0.0,
        });
        match poly.len() {
            3 => out.push(Piece {
                tri: p.tri,
                pos: [poly[0], poly[1], poly[2]],
                clips,
            }),
            4 => {
                let diag = Plane::through((poly[2] - poly[0]).cross(normal), poly[0]);
                let Some(diag) = diag else {
                    continue;
                };
                let first_nonneg = diag.eval(poly[1]) >= 0.0;
                for (tri, nonneg) in [
                    ([poly[0], poly[1], poly[2]], first_nonneg),
                    ([poly[0], poly[2], poly[3]], !first_nonneg),
                ] {
                    let mut c = clips.clone();
                    c.push(Clip {
                        plane: diag,
                        nonneg,
                    });
                    out.push(Piece {
                        tri: p.tri,
                        pos: tri,
                        clips: c,
                    });
                }
            }
            _ => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A horizontal triangle and a vertical one through its middle.
    fn crossing_pair() -> [[DVec3; 3]; 2] {
        let a = [
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(1.0, -1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let b = [
            DVec3::new(0.0, -0.5, -1.0),
            DVec3::new(0.0, 0.5, -1.0),
            DVec3::new(0.1, 0.0, 1.0),
        ];
        [a, b]
    }

    #[test]
    fn two_crossing_triangles_are_split_into_non_crossing_pieces() {
        let [a, b] = crossing_pair();
        assert!(matches!(crossing(&a, &b), Cross::Yes));
        let (pieces, stats) = split_crossing(&[a, b]).unwrap();
        assert_eq!(stats.crossings, 1);
        assert!(pieces.len() >= 4, "{}", pieces.len());
        for i in 0..pieces.len() {
            for j in i + 1..pieces.len() {
                assert!(matches!(
                    crossing(&pieces[i].pos, &pieces[j].pos),
                    Cross::No
                ));
            }
        }
        // The pieces of a cover a's area.
        let area = |t: &[DVec3; 3]| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        let split_tri = pieces[0].tri;
        let total: f64 = pieces
            .iter()
            .filter(|p| p.tri == split_tri)
            .map(|p| area(&p.pos))
            .sum();
        let whole = area(if split_tri == 0 { &a } else { &b });
        assert!((total - whole).abs() < 1e-12, "{total} vs {whole}");
    }

    #[test]
    fn the_clips_of_the_pieces_take_every_point_of_the_triangle_once() {
        let [a, b] = crossing_pair();
        let (pieces, _) = split_crossing(&[a, b]).unwrap();
        let split_tri = pieces.iter().find(|p| !p.clips.is_empty()).unwrap().tri;
        let t = if split_tri == 0 { a } else { b };
        let of: Vec<&Piece> = pieces.iter().filter(|p| p.tri == split_tri).collect();
        assert!(of.len() >= 3, "{}", of.len());
        // Points of the triangle, on the cut and the diagonals included (the corners and
        // the midpoints of every piece's edges).
        let mut pts: Vec<DVec3> = t.to_vec();
        for p in &of {
            for k in 0..3 {
                pts.push(p.pos[k]);
                pts.push((p.pos[k] + p.pos[(k + 1) % 3]) * 0.5);
            }
            pts.push((p.pos[0] + p.pos[1] + p.pos[2]) / 3.0);
        }
        for q in pts {
            let n = of
                .iter()
                .filter(|p| p.clips.iter().all(|c| (c.plane.eval(q) >= 0.0) == c.nonneg))
                .count();
            assert_eq!(n, 1, "{q} is in {n} pieces");
        }
    }

    #[test]
    fn adjacent_and_touching_triangles_are_left_alone() {
        let a = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        // Shares an edge, folded up.
        let b = [
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.7),
        ];
        // Touches a's interior with one corner from above.
        let c = [
            DVec3::new(0.2, 0.2, 0.0),
            DVec3::new(0.2, 0.5, 1.0),
            DVec3::new(0.5, 0.2, 1.0),
        ];
        let (pieces, stats) = split_crossing(&[a, b, c]).unwrap();
        assert_eq!(stats.crossings, 0);
        assert_eq!(pieces.len(), 3);
        // Coplanar overlap is refused.
        let d = a.map(|p| p + DVec3::new(0.1, 0.1, 0.0));
        assert!(matches!(
            split_crossing(&[a, d]),
            Err(SplitError::Coplanar { .. })
        ));
    }
}
