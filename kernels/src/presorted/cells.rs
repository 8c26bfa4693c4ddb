//! Cycles resolved by subdividing viewpoint space (in place of the back-edge scan of
//! "Depth-Presorted Triangle Lists", section 4.1, whose copies multiply on the teapot).
//!
//! The occlusion graph's strongly connected components ([`super::scc`]) are drawn in the
//! order of the condensation: an acyclic component is one instance without test planes.
//! A cyclic component is split by a cutting plane into two cells of viewpoint space; in
//! each cell only the instances and edges whose regions reach into it remain, and the cell
//! is resolved the same way. A component's list is the concatenation of its cells' lists,
//! each instance carrying its cell's planes: from any viewpoint exactly one cell's
//! instances pass (the cells partition the component's cell), so each triangle and facing
//! is drawn once, in an order valid for that cell.
//!
//! The cutting plane comes from one cycle of the component (the shortest through one
//! instance): two edges of the cycle whose reduced occlusion regions (eq. 1, within the
//! cell) separate give a plane with one edge missing on each side, so the cycle is gone
//! from both cells (the paper's section 4.1: "as long as we manage to separate at least one
//! of the edges ... we have made progress"). The paper's proof that some pair separates
//! assumes that regions which meet pairwise meet all together, which does not hold for
//! three or more convex regions (Helly's theorem needs every four to meet in 3D): around a
//! fan of triangles sharing a vertex the regions are cones from that vertex that overlap
//! pairwise with no common viewpoint. Then the regions are intersected in cycle order
//! until the intersection `I` misses the next region `C`: `I` and `C` are convex and
//! disjoint, and the plane between them leaves `C` out of one cell and a shorter
//! non-empty intersection prefix in the other, so the cycle is cut after finitely many
//! planes. A cycle whose regions all meet is seen whole from one viewpoint, the input the
//! method excludes: an error.

use glam::DVec3;

use super::geom::{Plane, Region};
use super::graph::Graph;
use super::scc;
use super::separate::{self, Shape};

/// Deepest subdivision (planes per instance) before giving up.
pub const MAX_DEPTH: usize = 48;
/// Instances per graph node after which the subdivision gives up.
pub const MAX_COPIES: usize = 64;

/// What the subdivision did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellStats {
    /// Cyclic strongly connected components of the partition's graph.
    pub cyclic_components: u64,
    /// Instances in the largest of them.
    pub largest_component: u64,
    /// Cutting planes placed (cells split).
    pub cuts: u64,
    /// Of those, found by the intersection of a cycle's regions (pairwise separation
    /// failed).
    pub prefix_cuts: u64,
    /// Deepest cell (planes on one instance).
    pub max_depth: u64,
    /// Cycles seen whole from some viewpoint (then the result is an error).
    pub visible: Vec<VisibleCycle>,
}

/// A cycle seen whole from the viewpoints where its edges' regions meet.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VisibleCycle {
    /// Its pieces, in cycle order.
    pub tris: Vec<u32>,
    /// A viewpoint that sees it (normalized frame).
    pub at: [f32; 3],
    /// The diameter of the region of such viewpoints.
    pub size: f64,
}

/// The subdivision could not resolve a cycle.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CellError {
    #[error(
        "{count} cycle(s) of occlusions are seen whole from the viewpoints where their \
         regions meet, the first of pieces {tris:?} around {at:?} (bounding-sphere radii \
         from its centre, a region {size:e} across): no order of these triangles is right \
         there (the method assumes no cycle is visible from one viewpoint; triangles that \
         cross are split first, and pieces of such cycles are split by one another's planes \
         for a few rounds, see `presort`)"
    )]
    Visible {
        count: usize,
        tris: Vec<u32>,
        at: [f32; 3],
        size: f64,
        /// Every such cycle's pieces, in cycle order.
        cycles: Vec<Vec<u32>>,
    },
    #[error("cells nested deeper than {MAX_DEPTH} planes (triangles {tris:?} still in a cycle)")]
    TooDeep { tris: Vec<u32> },
    #[error("more than {MAX_COPIES} instances per instance of the graph ({instances} instances)")]
    TooMany { instances: usize },
}

/// One instance of the result: a graph node and the planes of its cell.
pub type Placed = (usize, Vec<Plane>);

/// An edge of a cell: endpoints (indices into the cell's nodes) and its reduced occlusion
/// region within the cell.
struct CellEdge {
    from: usize,
    to: usize,
    region: Region,
}

/// The draw order of `g`'s nodes with the planes of each instance's cell.
pub fn resolve(
    g: &Graph,
    stats: &mut CellStats,
    tick: &dyn Fn(u64, u64),
) -> Result<Vec<Placed>, CellError> {
    let n = g.nodes.len();
    let comps = scc::components(n, |x| g.out_edges(x).map(|e| e.to as usize));
    let tri: Vec<u32> = g.nodes.iter().map(|x| x.tri).collect();
    let mut out: Vec<Placed> = Vec::with_capacity(n);
    let limit = MAX_COPIES * n.max(1);
    let mut done = 0u64;
    for comp in comps {
        done += comp.len() as u64;
        if comp.len() == 1 {
            out.push((comp[0], Vec::new()));
            continue;
        }
        stats.cyclic_components += 1;
        stats.largest_component = stats.largest_component.max(comp.len() as u64);
        // The component's edges with their reduced regions (eq. 1).
        let mut idx = vec![usize::MAX; n];
        for (i, &x) in comp.iter().enumerate() {
            idx[x] = i;
        }
        let mut edges: Vec<CellEdge> = Vec::new();
        for (i, &x) in comp.iter().enumerate() {
            for e in g.out_edges(x) {
                let j = idx[e.to as usize];
                if j == usize::MAX {
                    continue;
                }
                let region = g.nodes[x]
                    .region
                    .cut(&g.occl(e))
                    .intersect(&g.nodes[e.to as usize].region);
                if !region.is_empty() {
                    edges.push(CellEdge {
                        from: i,
                        to: j,
                        region,
                    });
                }
            }
        }
        let regions: Vec<Region> = comp.iter().map(|&x| g.nodes[x].region.clone()).collect();
        let cell = Cell {
            nodes: comp.clone(),
            regions,
            edges,
        };
        subdivide(&cell, &tri, &mut Vec::new(), &mut out, stats, limit)?;
        tick(done, n as u64);
    }
    tick(n as u64, n as u64);
    if let Some(first) = stats.visible.first() {
        return Err(CellError::Visible {
            count: stats.visible.len(),
            tris: first.tris.clone(),
            at: first.at,
            size: first.size,
            cycles: stats.visible.iter().map(|v| v.tris.clone()).collect(),
        });
    }
    Ok(out)
}

/// The instances of a cyclic component restricted to one cell of viewpoint space.
struct Cell {
    /// Graph nodes.
    nodes: Vec<usize>,
    /// Their rendering regions within the cell.
    regions: Vec<Region>,
    edges: Vec<CellEdge>,
}

impl Cell {
    /// The part on the positive side of `p`: instances and edges whose regions reach there.
    fn cut(&self, p: Plane) -> Cell {
        let mut keep = vec![usize::MAX; self.nodes.len()];
        let mut nodes = Vec::new();
        let mut regions = Vec::new();
        for (i, r) in self.regions.iter().enumerate() {
            let c = r.cut(&[p]);
            if !c.is_empty() {
                keep[i] = nodes.len();
                nodes.push(self.nodes[i]);
                regions.push(c);
            }
        }
        let edges = self
            .edges
            .iter()
            .filter(|e| keep[e.from] != usize::MAX && keep[e.to] != usize::MAX)
            .filter_map(|e| {
                let region = e.region.cut(&[p]);
                (!region.is_empty()).then(|| CellEdge {
                    from: keep[e.from],
                    to: keep[e.to],
                    region,
                })
            })
            .collect();
        Cell {
            nodes,
            regions,
            edges,
        }
    }
}

/// Resolves `cell` (the instances of one cyclic component, within the cell cut by
/// `planes`), appending its instances in draw order to `out`. `tri` names each graph
/// node's triangle (for errors).
fn subdivide(
    cell: &Cell,
    tri: &[u32],
    planes: &mut Vec<Plane>,
    out: &mut Vec<Placed>,
    stats: &mut CellStats,
    limit: usize,
) -> Result<(), CellError> {
    let m = cell.nodes.len();
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); m];
    let mut eout: Vec<Vec<usize>> = vec![Vec::new(); m];
    for (k, e) in cell.edges.iter().enumerate() {
        adj[e.from].push(e.to);
        eout[e.from].push(k);
    }
    for comp in scc::components(m, |v| adj[v].iter().copied()) {
        if comp.len() == 1 {
            out.push((cell.nodes[comp[0]], planes.clone()));
            if out.len() > limit {
                return Err(CellError::TooMany {
                    instances: out.len(),
                });
            }
            continue;
        }
        let names = || {
            let mut t: Vec<u32> = comp.iter().map(|&i| tri[cell.nodes[i]]).collect();
            t.sort_unstable();
            t.dedup();
            t
        };
        if planes.len() >= MAX_DEPTH {
            return Err(CellError::TooDeep { tris: names() });
        }
        let cycle = shortest_cycle(&comp, &cell.edges, &eout);
        let regions: Vec<&Region> = cycle.iter().map(|&k| &cell.edges[k].region).collect();
        let Some((p, prefix)) = cutting_plane(&regions) else {
            let t: Vec<u32> = cycle
                .iter()
                .map(|&k| tri[cell.nodes[cell.edges[k].from]])
                .collect();
            let common = regions
                .iter()
                .skip(1)
                .fold(regions[0].clone(), |r, o| r.intersect(o));
            let lo = common.verts.iter().fold(DVec3::INFINITY, |a, v| a.min(*v));
            let hi = common
                .verts
                .iter()
                .fold(DVec3::NEG_INFINITY, |a, v| a.max(*v));
            let at = common.verts.iter().sum::<DVec3>() / common.verts.len().max(1) as f64;
            // Recorded; the rest is still resolved, so that one round finds them all.
            stats.visible.push(VisibleCycle {
                tris: t,
                at: at.as_vec3().to_array(),
                size: (hi - lo).length(),
            });
            continue;
        };
        stats.cuts += 1;
        stats.prefix_cuts += u64::from(prefix);
        // The component alone, then each side of the plane.
        let sub = restrict(cell, &comp);
        for side in [p, p.flip()] {
            planes.push(side);
            stats.max_depth = stats.max_depth.max(planes.len() as u64);
            subdivide(&sub.cut(side), tri, planes, out, stats, limit)?;
            planes.pop();
        }
    }
    Ok(())
}

/// The cell's instances `comp` (indices into the cell) with the edges among them.
fn restrict(cell: &Cell, comp: &[usize]) -> Cell {
    let mut keep = vec![usize::MAX; cell.nodes.len()];
    for (k, &i) in comp.iter().enumerate() {
        keep[i] = k;
    }
    Cell {
        nodes: comp.iter().map(|&i| cell.nodes[i]).collect(),
        regions: comp.iter().map(|&i| cell.regions[i].clone()).collect(),
        edges: cell
            .edges
            .iter()
            .filter(|e| keep[e.from] != usize::MAX && keep[e.to] != usize::MAX)
            .map(|e| CellEdge {
                from: keep[e.from],
                to: keep[e.to],
                region: e.region.clone(),
            })
            .collect(),
    }
}

/// The edges of a shortest cycle through the component's first instance (breadth-first
/// search back to it; every instance of a strongly connected component is on a cycle).
fn shortest_cycle(comp: &[usize], edges: &[CellEdge], eout: &[Vec<usize>]) -> Vec<usize> {
    let start = comp[0];
    let mut member = vec![false; eout.len()];
    for &i in comp {
        member[i] = true;
    }
    // via[v] = the edge that reached v.
    let mut via = vec![usize::MAX; eout.len()];
    let mut queue = std::collections::VecDeque::from([start]);
    let mut seen = vec![false; eout.len()];
    seen[start] = true;
    while let Some(v) = queue.pop_front() {
        for &k in &eout[v] {
            let w = edges[k].to;
            if !member[w] {
                continue;
            }
            if w == start {
                let mut cycle = vec![k];
                let mut u = v;
                while u != start {
                    let e = via[u];
                    cycle.push(e);
                    u = edges[e].from;
                }
                cycle.reverse();
                return cycle;
            }
            if !seen[w] {
                seen[w] = true;
                via[w] = k;
                queue.push_back(w);
            }
        }
    }
    unreachable!("a strongly connected component of two or more instances has a cycle")
}

/// A plane with one of the cycle's regions on its positive side and another wholly on its
/// negative side, or (when every pair meets) with the intersection of the first regions in
/// cycle order on one side and the next region on the other. The flag says which.
fn cutting_plane(regions: &[&Region]) -> Option<(Plane, bool)> {
    let shape = |r: &Region| Shape {
        verts: r.verts.clone(),
        normals: r.normals(),
        edges: r.edge_dirs(),
    };
    let sep = |a: &Region, b: &Region| {
        separate::separate(&a.verts, &b.verts)
            .or_else(|| separate::separate_touching(&shape(a), &shape(b)))
    };
    // Every pair, neighbours in the cycle first (x -> b against f -> x, the paper's pair
    // at x).
    let k = regions.len();
    let mut pairs: Vec<(usize, usize)> = (0..k)
        .flat_map(|i| (i + 1..k).map(move |j| (i, j)))
        .collect();
    pairs.sort_by_key(|&(i, j)| (j - i).min(k - (j - i)));
    for (i, j) in pairs {
        if let Some(p) = sep(regions[i], regions[j]) {
            return Some((p, false));
        }
    }
    let mut inter: Region = regions[0].clone();
    for r in &regions[1..] {
        let next = inter.intersect(r);
        if next.is_empty() {
            return sep(&inter, r).map(|p| (p, true));
        }
        inter = next;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_acyclic_graph_keeps_one_instance_per_node() {
        let g = super::super::graph::tests::stacked_pair();
        let mut stats = CellStats::default();
        let out = resolve(&g, &mut stats, &|_, _| {}).unwrap();
        // b (occluded) is drawn before a.
        let order: Vec<u32> = out.iter().map(|(x, _)| g.nodes[*x].tri).collect();
        assert_eq!(order, vec![1, 0]);
        assert!(out.iter().all(|(_, p)| p.is_empty()));
        assert_eq!(stats.cuts, 0);
    }
}
