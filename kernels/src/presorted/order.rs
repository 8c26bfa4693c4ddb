//! The preliminary order (sections 4 and 4.2): a depth sort of the instances from a
//! viewpoint of the partition, refined by a feedback-arc-set heuristic so that few edges
//! point backwards.
//!
//! The heuristic is Eades, Lin and Smyth's greedy one ("A fast and effective heuristic for
//! the feedback arc set problem", 1993), with the depth sort breaking every tie: instances
//! nothing must follow are placed last (nearest first), instances nothing must precede
//! first (farthest first), and otherwise the instance with the most "must precede" minus
//! "must follow" relations goes next. On an acyclic graph it is a topological sort.
//!
//! Draw order is back to front: an edge `x -> y` (`x` occludes `y`) asks for `y` before `x`.

use std::collections::BTreeSet;

use glam::DVec3;

use super::graph::Graph;

/// Draw order (back to front) of the graph's nodes.
pub fn preliminary(g: &Graph, eye: DVec3) -> Vec<usize> {
    let n = g.nodes.len();
    // Depth sort: farthest centroid first. rank[x] = position in that sort.
    let dist: Vec<f64> = g
        .nodes
        .iter()
        .map(|x| {
            let t = &g.tris[x.tri as usize];
            ((t[0] + t[1] + t[2]) / 3.0 - eye).length()
        })
        .collect();
    let mut by_depth: Vec<usize> = (0..n).collect();
    by_depth.sort_by(|&a, &b| dist[b].total_cmp(&dist[a]).then(a.cmp(&b)));
    let mut rank = vec![0usize; n];
    for (r, &x) in by_depth.iter().enumerate() {
        rank[x] = r;
    }
    // before[x]: instances that must come before x (x occludes them): its out-edges.
    // after[x]: instances that must come after x (they occlude x): its in-edges.
    let mut before = vec![0i64; n];
    let mut after = vec![0i64; n];
    for x in 0..n {
        before[x] = g.out_edges(x).count() as i64;
        after[x] = g.in_edges(x).count() as i64;
    }
    let mut removed = vec![false; n];
    let mut first: Vec<usize> = Vec::with_capacity(n);
    let mut last: Vec<usize> = Vec::new();
    // Candidates keyed by rank (sources: nothing left before them; sinks: nothing after).
    let mut sources: BTreeSet<usize> = BTreeSet::new();
    let mut sinks: BTreeSet<usize> = BTreeSet::new();
    let mut delta: BTreeSet<(i64, usize)> = BTreeSet::new();
    for x in 0..n {
        if before[x] == 0 {
            sources.insert(rank[x]);
        } else if after[x] == 0 {
            sinks.insert(rank[x]);
        }
        delta.insert((before[x] - after[x], rank[x]));
    }
    let take = |x: usize,
                removed: &mut Vec<bool>,
                before: &mut Vec<i64>,
                after: &mut Vec<i64>,
                sources: &mut BTreeSet<usize>,
                sinks: &mut BTreeSet<usize>,
                delta: &mut BTreeSet<(i64, usize)>| {
        removed[x] = true;
        sources.remove(&rank[x]);
        sinks.remove(&rank[x]);
        delta.remove(&(before[x] - after[x], rank[x]));
        // x's out-edge targets y: y had x after it.
        for e in g.out_edges(x) {
            let y = e.to as usize;
            if removed[y] {
                continue;
            }
            delta.remove(&(before[y] - after[y], rank[y]));
            after[y] -= 1;
            delta.insert((before[y] - after[y], rank[y]));
            if after[y] == 0 && before[y] != 0 {
                sinks.insert(rank[y]);
            }
        }
        for e in g.in_edges(x) {
            let y = e.from as usize;
            if removed[y] {
                continue;
            }
            delta.remove(&(before[y] - after[y], rank[y]));
            before[y] -= 1;
            delta.insert((before[y] - after[y], rank[y]));
            if before[y] == 0 {
                sinks.remove(&rank[y]);
                sources.insert(rank[y]);
            }
        }
    };
    let mut left = n;
    while left > 0 {
        let x = if let Some(&r) = sources.iter().next() {
            first.push(by_depth[r]);
            by_depth[r]
        } else if let Some(&r) = sinks.iter().next_back() {
            last.push(by_depth[r]);
            by_depth[r]
        } else {
            // Most "must precede" relations left: the largest after - before, i.e. the
            // smallest before - after; ties to the farthest.
            let &(_, r) = delta.iter().next().expect("nodes left");
            first.push(by_depth[r]);
            by_depth[r]
        };
        take(
            x,
            &mut removed,
            &mut before,
            &mut after,
            &mut sources,
            &mut sinks,
            &mut delta,
        );
        left -= 1;
    }
    last.reverse();
    first.extend(last);
    first
}

/// Edges pointing backwards in `order` (`x -> y` with `y` drawn after `x`).
pub fn back_edges(g: &Graph, order: &[usize]) -> usize {
    let mut pos = vec![usize::MAX; g.nodes.len()];
    for (i, &x) in order.iter().enumerate() {
        pos[x] = i;
    }
    g.live_edges()
        .filter(|(_, e)| pos[e.to as usize] > pos[e.from as usize])
        .count()
}
