//! A partition's strongly connected components carried from one round of cutting cycles
//! to the next, instead of building its occlusion graph again.
//!
//! A round ([`super::presort_with`]) cuts a few pieces of cycles seen whole from a viewpoint
//! ([`super::split::break_cycle`]): a piece keeps its index for its first part, and its
//! other parts are appended. Every other piece is unchanged, so are their graph nodes and
//! the edges among them. A part `A'` of a piece `A` lies in `A`'s plane, so it has `A`'s
//! facing half-space and rendering region, and its occlusion region over any `Y` lies in
//! `A`'s (`A' + cone(A' - Y)` is a subset of `A + cone(A - Y)`, and likewise for `Y` over
//! `A'`): the parts' edges are among `A`'s. So the previous round's draw order of the
//! components stays valid with each part in its piece's component, and only the edges
//! inside a component that touch a part must be decided again ([`Graph::pair_edges`], as
//! the graph decides them). A component whose edges are now fewer may no longer be
//! strongly connected: the cells split it into its components first ([`super::cells`]).
//!
//! For the 48K-triangle dragon a graph takes about an hour a partition on 2 cores; this
//! takes seconds.

use std::collections::HashMap;

use super::graph::Graph;

/// How the pieces of a round came from the previous round's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lineage {
    /// Per piece, the previous round's piece it is (a part of).
    pub origin: Vec<u32>,
    /// Per piece, whether it differs from that piece (a part of a piece that was cut).
    pub changed: Vec<bool>,
}

impl Lineage {
    /// The lineage of pieces that are the previous ones, `cut` of them cut (each keeping
    /// its index for its first part) and `parts` more appended, with the piece each came
    /// from.
    pub fn new(previous: usize, cut: &[usize], parts: &[usize]) -> Lineage {
        let mut origin: Vec<u32> = (0..previous as u32).collect();
        let mut changed = vec![false; previous];
        for &a in cut {
            changed[a] = true;
        }
        for &a in parts {
            origin.push(a as u32);
            changed.push(true);
        }
        Lineage { origin, changed }
    }
}

/// Components and the edges inside each, as [`super::cells::Components`] holds them.
pub type Carried = (Vec<Vec<usize>>, Vec<Vec<(u32, u32)>>);

/// The components of `g` (this round's nodes, no edges needed) carried from the previous
/// round's `comps` and `inner` edges (as [`super::cells::Components`] holds them) over the
/// previous round's nodes `previous` (triangle and facing of each). `None` when a node of
/// `g` has no node it comes from (its region met the partition only now): then the graph
/// must be built.
pub fn carry(
    comps: &[Vec<usize>],
    inner: &[Vec<(u32, u32)>],
    previous: &[(u32, bool)],
    g: &Graph,
    lineage: &Lineage,
) -> Option<Carried> {
    let id: HashMap<(u32, bool), usize> =
        previous.iter().enumerate().map(|(i, &k)| (k, i)).collect();
    // The nodes of `g` that each previous node became (none if its region is now empty).
    let mut became: Vec<Vec<usize>> = vec![Vec::new(); previous.len()];
    for (y, node) in g.nodes.iter().enumerate() {
        let from = *lineage.origin.get(node.tri as usize)?;
        became[*id.get(&(from, node.back))?].push(y);
    }
    let changed = |y: usize| lineage.changed[g.nodes[y].tri as usize];
    let mut out_comps = Vec::with_capacity(comps.len());
    let mut out_inner = Vec::with_capacity(comps.len());
    for (comp, edges) in comps.iter().zip(inner) {
        let members: Vec<usize> = comp.iter().flat_map(|&x| became[x].clone()).collect();
        if members.is_empty() {
            continue;
        }
        if !members.iter().any(|&y| changed(y)) && members.len() == comp.len() {
            // Untouched: the same nodes in the same places.
            out_comps.push(members);
            out_inner.push(edges.clone());
            continue;
        }
        // An unchanged previous node is one node here: its place in `members`.
        let mut place = vec![u32::MAX; comp.len()];
        let mut at = 0u32;
        for (i, &x) in comp.iter().enumerate() {
            if let [y] = became[x][..] {
                if !changed(y) {
                    place[i] = at;
                }
            }
            at += became[x].len() as u32;
        }
        let mut kept: Vec<(u32, u32)> = edges
            .iter()
            .map(|&(i, j)| (place[i as usize], place[j as usize]))
            .filter(|&(i, j)| i != u32::MAX && j != u32::MAX)
            .collect();
        // Every ordered pair with a part in it, decided again.
        let m = members.len();
        let parts: Vec<usize> = (0..m).filter(|&u| changed(members[u])).collect();
        let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(2 * parts.len() * m);
        for &u in &parts {
            for v in (0..m).filter(|&v| v != u) {
                pairs.push((u, v));
                if !changed(members[v]) {
                    pairs.push((v, u));
                }
            }
        }
        let graph_pairs: Vec<(usize, usize)> = pairs
            .iter()
            .map(|&(u, v)| (members[u], members[v]))
            .collect();
        let found = g.pair_edges(&graph_pairs);
        kept.extend(
            pairs
                .iter()
                .zip(found)
                .filter(|(_, edge)| *edge)
                .map(|(&(u, v), _)| (u as u32, v as u32)),
        );
        kept.sort_unstable();
        out_comps.push(members);
        out_inner.push(kept);
    }
    Some((out_comps, out_inner))
}
