//! The back-edge scan (section 4.1): walk the preliminary order in draw order; at each
//! instance `x` with back-edges (it occludes instances `b*` drawn after it), place a copy
//! of `x` right after the last `b`, and choose a cutting plane that leaves the original `x`
//! the viewpoints of the forward edges from the instances `f*` in between (eq. 2-5).
//!
//! Regions are convex ([`super::geom::Region`]); unions are approximated by the convex hull
//! of their vertices, and the cutting plane separates the two hulls
//! ([`super::separate::separate`]: the plane halfway between them).
//!
//! When no forward-edge region separates from all of `R_b` (`R_f` stays empty), `x` moves
//! whole after the last `b`, as the paper's `R_f^(0)` (the plane of `x` separates); the
//! `f -> x` edges become back-edges of the `f*`, handled when the scan reaches them. An
//! instance that has already been moved whole [`FREE_WHOLE_MOVES`] times (moves that may go
//! round a cycle) tries the progress steps first, in order:
//! 1. the paper's pairwise progress step (section 4.1, "at least one of the edges between
//!    `f*` and `x` from at least one of edges between `x` and `b*`"): a plane separating one
//!    `O_{f->x}` from one `O_{x->b}` splits `x`; the original keeps fewer back-edges and is
//!    scanned again;
//! 2. the `b` and `f` duplications of section 4.1 (the edge `b -> f` separated from
//!    `x -> b`, or from `f -> x`);
//! 3. moving `x` whole again.
//!
//! Separations allow touching regions ([`separate::separate_touching`]): the occlusion
//! regions of triangles that share an edge or a vertex meet along the shared feature's line,
//! and only a plane through it separates them.
//!
//! The scan gives up with an error when it cannot progress, so a cycle that the input's
//! assumptions exclude (a cycle visible from one viewpoint) ends in an error, never a
//! hang: past a step budget proportional to the graph, when one instance has been moved
//! whole [`MAX_WHOLE_MOVES`] times (the moves ping-pong), or when the instances outnumber
//! [`MAX_COPIES`] per initial instance.

use glam::DVec3;

use super::geom::{Plane, EPS};
use super::graph::Graph;
use super::separate;

/// What the scan did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ScanStats {
    pub moves: u64,
    pub splits: u64,
    pub pairwise: u64,
    pub bf_dups: u64,
    pub whole_moves: u64,
    pub lp_calls: u64,
    /// Separations decided by the touching test (hulls at distance zero).
    pub touching_tests: u64,
    pub touching_planes: u64,
}

/// The scan could not progress.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "the back-edge scan made no progress ({limit}) after {steps} steps ({nodes} instances, {edges} \
     occlusion edges left): the mesh has a cycle of triangles visible from one viewpoint \
     (crossing triangles are split first; three or more that overlap cyclically are not), \
     which the method assumes away, or cycles whose regions the progress steps cut into too \
     many copies"
)]
pub struct ScanError {
    /// Which limit was reached.
    pub limit: &'static str,
    pub steps: u64,
    pub nodes: usize,
    pub edges: usize,
}

/// A cutting plane with every `pos` point on the positive side and every `neg` point on the
/// negative side (section 4.1.2), if the hulls of the two sets have disjoint interiors.
///
/// `prev`, the plane that separated the previous, smaller set in the greedy growth of
/// `R_f`, is tried first (one check of every point); then the hulls' distance decides
/// ([`separate::separate`]) and gives the plane halfway between them. When the hulls touch
/// (distance zero), the paper's candidates decide ([`separate::separate_touching`]: face
/// planes, then planes through an edge of each): `shapes` gives the two polytopes' faces
/// and edges, computed only then.
fn cutting_plane(
    pos: &[DVec3],
    neg: &[DVec3],
    prev: Option<Plane>,
    shapes: impl FnOnce() -> (separate::Shape, separate::Shape),
    stats: &mut ScanStats,
) -> Option<Plane> {
    if let Some(p) = prev {
        // (Within the touching tolerance: the previous plane may be a touching one.)
        let t = separate::TOUCH;
        if pos.iter().all(|v| p.eval(*v) >= -t) && neg.iter().all(|v| p.eval(*v) <= t) {
            return Some(p);
        }
    }
    stats.lp_calls += 1;
    // A point both sets share (regions meeting at a corner of the partition): the hulls
    // touch or intersect, GJK would only find a zero distance.
    if !shares_point(pos, neg) {
        if let Some(p) = separate::separate(pos, neg) {
            return Some(p);
        }
    }
    stats.touching_tests += 1;
    let (a, b) = shapes();
    let p = separate::separate_touching(&a, &b);
    stats.touching_planes += u64::from(p.is_some());
    p
}

/// Whether two point sets have a point in common (within [`EPS`]).
fn shares_point(a: &[DVec3], b: &[DVec3]) -> bool {
    let key = |p: &DVec3| (p.x / 1e-6).round() as i64;
    let mut xs: Vec<(i64, usize)> = a.iter().enumerate().map(|(i, p)| (key(p), i)).collect();
    xs.sort_unstable();
    b.iter().any(|q| {
        let k = key(q);
        let from = xs.partition_point(|e| e.0 < k - 1);
        xs[from..]
            .iter()
            .take_while(|e| e.0 <= k + 1)
            .any(|e| (a[e.1] - *q).length_squared() < EPS * EPS)
    })
}

/// Whole moves of one instance after which the scan gives up (fallback 3 moved it back and
/// forth with the instances it is in a cycle with).
pub const MAX_WHOLE_MOVES: u32 = 256;
/// Whole moves of one instance before the progress steps (pairwise split, `b`/`f`
/// duplication) are tried ahead of moving it again.
pub const FREE_WHOLE_MOVES: u32 = 2;
/// Instances per initial instance after which the scan gives up.
pub const MAX_COPIES: usize = 64;

/// Most separability tests the pairwise progress step runs for one instance (over all its
/// `f` and `b` pairs, the nearest first).
const PAIR_LPS: u64 = 256;

/// Most LPs the greedy growth of `R_f` runs for one instance before it stops adding
/// forward edges (the rest go with the copy, as the paper's unaccounted edges do).
const GREEDY_LPS: u64 = 12;

/// Runs the scan over `order` (draw order, back to front), duplicating instances in `g`.
/// Returns the final draw order.
pub fn scan(
    g: &mut Graph,
    mut order: Vec<usize>,
    stats: &mut ScanStats,
    tick: &dyn Fn(u64, u64),
) -> Result<Vec<usize>, ScanError> {
    g.index_in_edges();
    let budget = 200 * (g.nodes.len() as u64 + g.edge_count() as u64) + 10_000;
    let max_nodes = MAX_COPIES * g.nodes.len().max(1);
    let mut whole = vec![0u32; g.nodes.len()];
    let mut steps = 0u64;
    let mut pos = vec![0usize; g.nodes.len()];
    // Positions of the instances from `from` on (every change of the order is at or after
    // the current instance: the ones before keep their positions).
    let reindex = |order: &[usize], pos: &mut Vec<usize>, n: usize, from: usize| {
        pos.resize(n, usize::MAX);
        for (i, &x) in order.iter().enumerate().skip(from) {
            pos[x] = i;
        }
    };
    // Moves x whole from `idx` to `b_last`: only the positions in between change.
    let move_whole = |order: &mut Vec<usize>, pos: &mut Vec<usize>, idx: usize, b_last: usize| {
        let x = order.remove(idx);
        order.insert(b_last, x);
        for (i, &y) in order.iter().enumerate().take(b_last + 1).skip(idx) {
            pos[y] = i;
        }
    };
    reindex(&order, &mut pos, g.nodes.len(), 0);
    let mut idx = 0usize;
    while idx < order.len() {
        steps += 1;
        if steps > budget || g.nodes.len() > max_nodes {
            return Err(ScanError {
                limit: if steps > budget {
                    "step budget"
                } else {
                    "copies per instance"
                },
                steps,
                nodes: g.nodes.len(),
                edges: g.edge_count(),
            });
        }
        if steps.is_multiple_of(256) {
            tick(idx as u64, order.len() as u64);
        }
        let x = order[idx];
        let backs: Vec<usize> = g.out[x]
            .iter()
            .map(|&e| e as usize)
            .filter(|&e| g.is_alive(e) && pos[g.edges[e].to as usize] > idx)
            .collect();
        if backs.is_empty() {
            idx += 1;
            continue;
        }
        let b_last = backs
            .iter()
            .map(|&e| pos[g.edges[e].to as usize])
            .max()
            .expect("non-empty");
        // The forward edges a move of x after the last b would turn: those from the
        // instances in between, and from the last b itself (x and b may occlude each other
        // from different viewpoints of the partition; leaving b -> x out made the two swap
        // places forever).
        let mut fs: Vec<usize> = g
            .in_ids(x)
            .iter()
            .map(|&e| e as usize)
            .filter(|&e| {
                let p = pos[g.edges[e].from as usize];
                g.is_alive(e) && p > idx && p <= b_last
            })
            .collect();
        fs.sort_by_key(|&e| pos[g.edges[e].from as usize]);
        if fs.is_empty() {
            // Moving x after the last b breaks no forward edge.
            move_whole(&mut order, &mut pos, idx, b_last);
            stats.moves += 1;
            continue;
        }
        let rb: Vec<DVec3> = backs.iter().flat_map(|&e| g.edge_verts(e)).collect();
        // Greedy growth of R_f (eq. 3-5).
        let mut rf: Vec<DVec3> = Vec::new();
        let mut rf_edges: Vec<usize> = Vec::new();
        let mut plane: Option<Plane> = None;
        let lps_before = stats.lp_calls;
        let mut rb_shape: Option<separate::Shape> = None;
        for &e in &fs {
            if stats.lp_calls - lps_before >= GREEDY_LPS {
                break;
            }
            let mut cand = rf.clone();
            cand.extend(g.edge_verts(e));
            let shapes = || {
                let rbs = rb_shape
                    .get_or_insert_with(|| {
                        separate::Shape::union(
                            backs
                                .iter()
                                .map(|&b| g.edge_shape(b))
                                .collect::<Vec<_>>()
                                .iter(),
                        )
                    })
                    .clone();
                let parts: Vec<separate::Shape> = rf_edges
                    .iter()
                    .chain([&e])
                    .map(|&f| g.edge_shape(f))
                    .collect();
                (separate::Shape::union(parts.iter()), rbs)
            };
            if let Some(p) = cutting_plane(&cand, &rb, plane, shapes, stats) {
                rf = cand;
                rf_edges.push(e);
                plane = Some(p);
            }
        }
        if let Some(p) = plane {
            split_and_place(g, &mut order, &mut pos, idx, b_last, x, p);
            reindex(&order, &mut pos, g.nodes.len(), idx);
            whole.resize(g.nodes.len(), whole[x]);
            stats.splits += 1;
            continue;
        }
        // No forward edge separates from all of R_b: R_f stays empty, and the plane of x
        // itself separates, i.e. x moves whole after the last b (the paper's R_f^(0)); the
        // f -> x edges become back-edges of the f*, handled when the scan reaches them.
        // Only an instance moved whole before (the moves may go round a cycle) tries the
        // progress steps below first: each of them cuts x into more copies.
        if whole[x] < FREE_WHOLE_MOVES {
            whole[x] += 1;
            move_whole(&mut order, &mut pos, idx, b_last);
            stats.whole_moves += 1;
            continue;
        }
        // Fallback 1: one forward edge against one back edge, the nearest f and b first,
        // every pair up to a bound on the separability tests.
        let mut pair: Option<Plane> = None;
        let mut near_backs = backs.clone();
        near_backs.sort_by_key(|&e| pos[g.edges[e].to as usize]);
        let lps_before = stats.lp_calls;
        'pairs: for &f in fs.iter().rev() {
            for &b in &near_backs {
                if stats.lp_calls - lps_before >= PAIR_LPS {
                    break 'pairs;
                }
                let shapes = || (g.edge_shape(f), g.edge_shape(b));
                if let Some(p) =
                    cutting_plane(&g.edge_verts(f), &g.edge_verts(b), None, shapes, stats)
                {
                    pair = Some(p);
                    break 'pairs;
                }
            }
        }
        if let Some(p) = pair {
            split_and_place(g, &mut order, &mut pos, idx, b_last, x, p);
            reindex(&order, &mut pos, g.nodes.len(), idx);
            whole.resize(g.nodes.len(), whole[x]);
            stats.pairwise += 1;
            continue;
        }
        // Fallback 2: duplicate b or f (section 4.1's three configurations).
        if dup_b_or_f(g, &mut order, &pos, x, &backs, &fs, stats) {
            reindex(&order, &mut pos, g.nodes.len(), idx);
            whole.resize(g.nodes.len(), whole[x]);
            stats.bf_dups += 1;
            continue;
        }
        // Fallback 3: move x whole anyway.
        whole[x] += 1;
        if whole[x] > MAX_WHOLE_MOVES {
            return Err(ScanError {
                limit: "one instance moved whole too often",
                steps,
                nodes: g.nodes.len(),
                edges: g.edge_count(),
            });
        }
        move_whole(&mut order, &mut pos, idx, b_last);
        stats.whole_moves += 1;
    }
    tick(order.len() as u64, order.len() as u64);
    Ok(order)
}

/// Splits `x` (at `idx`) by `p`: `x` keeps the positive side and stays; the copy with the
/// negative side goes right after position `b_last`.
fn split_and_place(
    g: &mut Graph,
    order: &mut Vec<usize>,
    pos: &mut [usize],
    idx: usize,
    b_last: usize,
    x: usize,
    p: Plane,
) {
    let (new, keep) = g.split(x, p);
    let _ = pos;
    if let Some(n) = new {
        order.insert(b_last + 1, n);
    }
    if !keep {
        order.remove(idx);
    }
}

/// The `b` and `f` duplications of section 4.1, for the last `b` and the last `f` before
/// it, when an edge `b -> f` closes the cycle `x -> b -> f -> x`: a copy of `b` restricted
/// to `O_{x->b}`'s side placed before `x` (the original keeps `O_{b->f}`'s side), or `x`
/// moved after `b` followed by a copy of `f` restricted to `O_{f->x}`'s side (the original
/// keeps `O_{b->f}`'s side).
fn dup_b_or_f(
    g: &mut Graph,
    order: &mut Vec<usize>,
    pos: &[usize],
    x: usize,
    backs: &[usize],
    fs: &[usize],
    stats: &mut ScanStats,
) -> bool {
    let b_edge = *backs
        .iter()
        .max_by_key(|&&e| pos[g.edges[e].to as usize])
        .expect("non-empty");
    let f_edge = *fs.last().expect("non-empty");
    let (b, f) = (g.edges[b_edge].to as usize, g.edges[f_edge].from as usize);
    let Some(bf) = g.out[b]
        .iter()
        .map(|&e| e as usize)
        .find(|&e| g.is_alive(e) && g.edges[e].to as usize == f)
    else {
        return false;
    };
    let xb = g.edge_verts(b_edge);
    let bf_v = g.edge_verts(bf);
    let fx = g.edge_verts(f_edge);
    // Duplicate b: the copy that serves x -> b goes before x.
    let shapes = || (g.edge_shape(bf), g.edge_shape(b_edge));
    if let Some(p) = cutting_plane(&bf_v, &xb, None, shapes, stats) {
        let (new, keep) = g.split(b, p);
        if let Some(n) = new {
            order.insert(pos[x], n);
        }
        if !keep {
            order.retain(|&y| y != b);
        }
        return true;
    }
    // Duplicate f: x moves after b, and the copy of f that serves f -> x follows it; the
    // original f keeps the viewpoints of b -> f.
    let shapes = || (g.edge_shape(bf), g.edge_shape(f_edge));
    if let Some(p) = cutting_plane(&bf_v, &fx, None, shapes, stats) {
        let (new, keep) = g.split(f, p);
        order.retain(|&y| y != x);
        let at = order.iter().position(|&y| y == b).expect("b placed") + 1;
        order.insert(at, x);
        if let Some(n) = new {
            order.insert(at + 1, n);
        }
        if !keep {
            order.retain(|&y| y != f);
        }
        return true;
    }
    false
}
