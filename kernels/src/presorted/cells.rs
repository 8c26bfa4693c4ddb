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

use std::sync::atomic::{AtomicU64, Ordering};

use super::geom::{Plane, Region, EPS, MIN_WIDTH};
use super::graph::{Graph, GraphError, MemoryBudget};
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
    #[error(
        "resolving a cyclic component of {instances} instances ({edges} edges among them) \
         needs more than the memory limit of {1} (refused when preprocessing would hold {0}, \
         the component's cells not all made): use \
         --threads 1 (one partition at a time), more partitions (smaller regions, fewer \
         edges), a simpler mesh, or a higher --memory-limit if the machine has the memory",
        super::graph::gib(*bytes),
        super::graph::gib(*limit)
    )]
    Memory {
        instances: usize,
        edges: usize,
        bytes: u64,
        limit: u64,
    },
}

/// One instance of the result: a graph node and the planes of its cell.
pub type Placed = (usize, Vec<Plane>);

/// An edge of a cell: endpoints (indices into the cell's nodes) and the bounding box of its
/// reduced occlusion region within the cell (eq. 1), rounded outward to `f32`: 32 bytes. The
/// region itself is not kept (a cyclic component of the 48K dragon has 14.7 M edges, and a
/// region takes about 2 KB): [`edge_region`] recomputes it where it is needed, for the
/// cycle being cut and the edges a cutting plane may cross, and the box decides the rest
/// ([`Cell::cut`]).
#[derive(Clone, Copy)]
struct CellEdge {
    from: u32,
    to: u32,
    lo: [f32; 3],
    hi: [f32; 3],
}

impl CellEdge {
    /// The edge `from -> to` with the box of `region`'s vertices.
    fn new(from: usize, to: usize, region: &Region) -> CellEdge {
        let (lo, hi) = region
            .verts
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
        // Rounded outward, so that the box still holds every vertex.
        let down = |x: f64| {
            let y = x as f32;
            if f64::from(y) > x {
                y.next_down()
            } else {
                y
            }
        };
        let up = |x: f64| {
            let y = x as f32;
            if f64::from(y) < x {
                y.next_up()
            } else {
                y
            }
        };
        let id = |x: usize| u32::try_from(x).expect("a cell's nodes are graph nodes (u32 ids)");
        CellEdge {
            from: id(from),
            to: id(to),
            lo: lo.to_array().map(down),
            hi: hi.to_array().map(up),
        }
    }

    fn ends(&self) -> (usize, usize) {
        (self.from as usize, self.to as usize)
    }

    /// The smallest and largest value of `p` over the box (rounding aside: [`BOX_SLACK`]).
    fn range(&self, p: &Plane) -> (f64, f64) {
        let (mut a, mut b) = (p.d, p.d);
        for c in 0..3 {
            let x = p.n[c] * f64::from(self.lo[c]);
            let y = p.n[c] * f64::from(self.hi[c]);
            a += x.min(y);
            b += x.max(y);
        }
        (a, b)
    }
}

/// Absolute error allowed for a plane evaluated at a box's corner instead of at the
/// region's vertices (coordinates in the viewpoint box are below 100, so rounding is about
/// 1e-14): [`Cell::cut`] decides from the box only beyond it.
const BOX_SLACK: f64 = 1e-12;

/// The reduced occlusion region of graph nodes `x -> y` (eq. 1) within the cell cut by
/// `path`: computed as the cells have always computed it, the region of the whole
/// partition cut by each plane in turn, so that the same plane is found for every cycle as
/// when regions were kept.
fn edge_region(g: &Graph, x: usize, y: usize, path: &[Plane]) -> Region {
    let edge = super::graph::Edge {
        from: x as u32,
        to: y as u32,
    };
    let mut r = g.nodes[x]
        .region
        .cut(&g.occl(&edge))
        .intersect(&g.nodes[y].region);
    for p in path {
        if r.is_empty() {
            break;
        }
        r = r.cut(std::slice::from_ref(p));
    }
    r
}

/// The draw order of `g`'s nodes with the planes of each instance's cell:
/// [`components`], then [`resolve_components`].
///
/// Memory: the cells' structures are charged to `budget` while they live, so that a
/// component too large for the limit stops with [`CellError::Memory`] instead of being
/// killed. Once the strongly connected components are known, the edges inside the cyclic
/// ones are kept (8 bytes each) and the graph's own edges are dropped
/// ([`Graph::drop_edges`]; their bytes, which the graph's builder charged, are returned
/// in [`Resolved::freed`] for the caller to release): the cells need no other edge.
pub fn resolve(
    g: &mut Graph,
    budget: &MemoryBudget,
    stats: &mut CellStats,
    tick: &dyn Fn(u64, u64),
) -> Result<Resolved, CellError> {
    let (parts, freed) = components(g, budget)?;
    let placed = resolve_components(g, parts, stats, tick)?;
    Ok(Resolved { placed, freed })
}

/// The strongly connected components of a partition's graph, in the draw order of the
/// condensation, with the edges inside each: all the cells need of the graph's edges
/// (a checkpoint can hold them, [`super::checkpoint`]). Their bytes stay charged while
/// they live.
pub struct Components<'b> {
    /// Graph nodes of each component.
    pub comps: Vec<Vec<usize>>,
    /// The edges inside each component, as indices into it (none for one instance).
    pub inner: Vec<Vec<(u32, u32)>>,
    held: Charge<'b>,
}

impl<'b> Components<'b> {
    /// Components read back (from a checkpoint), their edges' bytes charged to `budget`.
    pub fn charged(
        comps: Vec<Vec<usize>>,
        inner: Vec<Vec<(u32, u32)>>,
        budget: &'b MemoryBudget,
    ) -> Result<Components<'b>, CellError> {
        let held = Charge::new(budget);
        for (comp, edges) in comps.iter().zip(&inner) {
            held.add(Components::bytes(edges), comp.len(), edges.len())?;
        }
        Ok(Components { comps, inner, held })
    }

    fn bytes(edges: &[(u32, u32)]) -> u64 {
        std::mem::size_of_val(edges) as u64
    }
}

/// The strongly connected components of `g` ([`Components`]); then `g`'s edges are
/// dropped, their bytes returned for the caller to release.
pub fn components<'b>(
    g: &mut Graph,
    budget: &'b MemoryBudget,
) -> Result<(Components<'b>, u64), CellError> {
    let n = g.nodes.len();
    let comps = scc::components(n, |x| g.out_edges(x).map(|e| e.to as usize));
    // The edges inside each cyclic component, as indices into it.
    let mut local = vec![u32::MAX; n];
    let mut inner: Vec<Vec<(u32, u32)>> = Vec::with_capacity(comps.len());
    // (Held until the end: an upper bound of what the lists take as they are dropped.)
    let held = Charge::new(budget);
    for comp in &comps {
        if comp.len() == 1 {
            inner.push(Vec::new());
            continue;
        }
        for (i, &x) in comp.iter().enumerate() {
            local[x] = i as u32;
        }
        let mut edges: Vec<(u32, u32)> = Vec::new();
        for (i, &x) in comp.iter().enumerate() {
            edges.extend(
                g.out_edges(x)
                    .map(|e| local[e.to as usize])
                    .filter(|&j| j != u32::MAX)
                    .map(|j| (i as u32, j)),
            );
        }
        for &x in comp {
            local[x] = u32::MAX;
        }
        edges.shrink_to_fit();
        held.add(Components::bytes(&edges), comp.len(), edges.len())?;
        inner.push(edges);
    }
    drop(local);
    let freed = g.drop_edges();
    Ok((Components { comps, inner, held }, freed))
}

/// The draw order of the nodes of `parts` (every node of `g`) with the planes of each
/// instance's cell: each cyclic component subdivided ([`subdivide`]), its cells charged
/// to the budget `parts` is charged to. `g` needs its nodes only.
pub fn resolve_components(
    g: &Graph,
    parts: Components<'_>,
    stats: &mut CellStats,
    tick: &dyn Fn(u64, u64),
) -> Result<Vec<Placed>, CellError> {
    let n = g.nodes.len();
    let Components { comps, inner, held } = parts;
    let budget = held.budget;
    let tri: Vec<u32> = g.nodes.iter().map(|x| x.tri).collect();
    let mut out: Vec<Placed> = Vec::with_capacity(n);
    let limit = MAX_COPIES * n.max(1);
    let mut done = 0u64;
    for (comp, edges) in comps.into_iter().zip(inner) {
        done += comp.len() as u64;
        if comp.len() == 1 {
            out.push((comp[0], Vec::new()));
            continue;
        }
        stats.cyclic_components += 1;
        stats.largest_component = stats.largest_component.max(comp.len() as u64);
        let cell = component_cell(g, &comp, &edges, budget)?;
        drop(edges);
        subdivide(g, cell, &tri, &mut Vec::new(), &mut out, stats, limit)?;
        tick(done, n as u64);
    }
    drop(held);
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

/// What [`resolve`] returns: the instances in draw order, and the bytes of the graph's
/// edges it dropped (charged by the graph's builder, released by its caller).
pub struct Resolved {
    pub placed: Vec<Placed>,
    pub freed: u64,
}

/// The cell of a whole cyclic component: its instances, and its edges (`edges`, indices
/// into `comp`) whose reduced regions (eq. 1) have an interior, with their bounding boxes,
/// computed on the current rayon pool. Its bytes are charged to `budget` (at most every
/// edge kept) before the regions are computed.
fn component_cell<'b>(
    g: &Graph,
    comp: &[usize],
    edges: &[(u32, u32)],
    budget: &'b MemoryBudget,
) -> Result<Cell<'b>, CellError> {
    use rayon::prelude::*;
    let regions: Vec<Region> = comp.iter().map(|&x| g.nodes[x].region.clone()).collect();
    let charge = Charge::new(budget);
    charge.add(
        Cell::bytes_of(comp.len(), &regions, edges.len()),
        comp.len(),
        edges.len(),
    )?;
    // (`filter_map` collects each thread's edges in order, then joins them.)
    let kept: Vec<CellEdge> = edges
        .par_iter()
        .filter_map(|&(i, j)| {
            let (i, j) = (i as usize, j as usize);
            let region = edge_region(g, comp[i], comp[j], &[]);
            (!region.is_empty()).then(|| CellEdge::new(i, j, &region))
        })
        .collect();
    Ok(Cell {
        nodes: comp.to_vec(),
        regions,
        edges: kept,
        charge,
    })
}

/// Bytes of the cells' structures charged to a [`MemoryBudget`], given back when dropped.
struct Charge<'b> {
    budget: &'b MemoryBudget,
    bytes: AtomicU64,
}

impl<'b> Charge<'b> {
    fn new(budget: &'b MemoryBudget) -> Charge<'b> {
        Charge {
            budget,
            bytes: AtomicU64::new(0),
        }
    }

    /// Charges `bytes` more, for a cell of `instances` instances and `edges` edges (named
    /// in the error).
    fn add(&self, bytes: u64, instances: usize, edges: usize) -> Result<(), CellError> {
        match self.budget.charge(bytes) {
            Ok(()) => {
                self.bytes.fetch_add(bytes, Ordering::Relaxed);
                Ok(())
            }
            Err(GraphError::Memory { bytes, limit }) => Err(CellError::Memory {
                instances,
                edges,
                bytes,
                limit,
            }),
            Err(GraphError::TooManyEdges) => unreachable!("a charge only fails for memory"),
        }
    }
}

impl Drop for Charge<'_> {
    fn drop(&mut self) {
        self.budget.release(*self.bytes.get_mut());
    }
}

/// The instances of a cyclic component restricted to one cell of viewpoint space.
struct Cell<'b> {
    /// Graph nodes.
    nodes: Vec<usize>,
    /// Their rendering regions within the cell.
    regions: Vec<Region>,
    edges: Vec<CellEdge>,
    /// Its bytes, charged while it lives.
    charge: Charge<'b>,
}

impl<'b> Cell<'b> {
    /// A cell of nothing, charging nothing.
    fn empty(budget: &'b MemoryBudget) -> Cell<'b> {
        Cell {
            nodes: Vec::new(),
            regions: Vec::new(),
            edges: Vec::new(),
            charge: Charge::new(budget),
        }
    }

    /// Bytes of a cell's nodes, their `regions` and `edges` edges.
    fn bytes_of(nodes: usize, regions: &[Region], edges: usize) -> u64 {
        let per_node = std::mem::size_of::<usize>() + std::mem::size_of::<Region>();
        (nodes * per_node
            + regions.iter().map(Region::footprint).sum::<usize>()
            + edges * std::mem::size_of::<CellEdge>()) as u64
    }

    /// A cell of these parts, its bytes charged to the budget `self` is charged to.
    fn charged(
        &self,
        nodes: Vec<usize>,
        regions: Vec<Region>,
        edges: Vec<CellEdge>,
    ) -> Result<Cell<'b>, CellError> {
        let charge = Charge::new(self.charge.budget);
        charge.add(
            Cell::bytes_of(nodes.len(), &regions, edges.len()),
            nodes.len(),
            edges.len(),
        )?;
        Ok(Cell {
            nodes,
            regions,
            edges,
            charge,
        })
    }

    /// The part on the positive side of `p`, the last plane of `path` (the planes of the
    /// cell made): instances and edges whose regions reach there. An edge whose box lies on
    /// one side of `p` is kept as it is or dropped, as cutting its region would; the
    /// others' regions are computed ([`edge_region`], on the current rayon pool).
    fn cut(&self, g: &Graph, path: &[Plane]) -> Result<Cell<'b>, CellError> {
        use rayon::prelude::*;
        let p = *path.last().expect("a cut has a plane");
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
            .par_iter()
            .filter_map(|e| {
                let (i, j) = e.ends();
                if keep[i] == usize::MAX || keep[j] == usize::MAX {
                    return None;
                }
                let (lo, hi) = e.range(&p);
                // As `Region::cut` decides from the vertices: all inside, nothing changes;
                // all outside (beyond a sliver), nothing is left.
                if lo >= -EPS + BOX_SLACK {
                    return Some(CellEdge {
                        from: keep[i] as u32,
                        to: keep[j] as u32,
                        ..*e
                    });
                }
                if hi < MIN_WIDTH - BOX_SLACK {
                    return None;
                }
                let region = edge_region(g, self.nodes[i], self.nodes[j], path);
                (!region.is_empty()).then(|| CellEdge::new(keep[i], keep[j], &region))
            })
            .collect();
        self.charged(nodes, regions, edges)
    }
}

/// Resolves `cell` (the instances of one cyclic component, within the cell cut by
/// `planes`), appending its instances in draw order to `out`. `tri` names each graph
/// node's triangle (for errors).
fn subdivide(
    g: &Graph,
    mut cell: Cell<'_>,
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
        let (i, j) = e.ends();
        adj[i].push(j);
        eout[i].push(k);
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
        let regions: Vec<Region> = cycle
            .iter()
            .map(|&k| {
                let (i, j) = cell.edges[k].ends();
                edge_region(g, cell.nodes[i], cell.nodes[j], planes)
            })
            .collect();
        let regions: Vec<&Region> = regions.iter().collect();
        let Some((p, prefix)) = cutting_plane(&regions) else {
            let t: Vec<u32> = cycle
                .iter()
                .map(|&k| tri[cell.nodes[cell.edges[k].ends().0]])
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
        // The component alone (the cell itself when it is the only one: moved, not
        // copied), then each side of the plane.
        let sub = if comp.len() == m {
            let empty = Cell::empty(cell.charge.budget);
            reorder(std::mem::replace(&mut cell, empty), &comp)
        } else {
            restrict(&cell, &comp)?
        };
        for side in [p, p.flip()] {
            planes.push(side);
            stats.max_depth = stats.max_depth.max(planes.len() as u64);
            subdivide(g, sub.cut(g, planes)?, tri, planes, out, stats, limit)?;
            planes.pop();
        }
    }
    Ok(())
}

/// [`restrict`] to every instance of the cell (`comp` orders them all): the same cell,
/// reordered in place instead of copied (its bytes stay charged as they were).
fn reorder<'b>(cell: Cell<'b>, comp: &[usize]) -> Cell<'b> {
    let Cell {
        nodes,
        regions,
        mut edges,
        charge,
    } = cell;
    let mut keep = vec![usize::MAX; nodes.len()];
    for (k, &i) in comp.iter().enumerate() {
        keep[i] = k;
    }
    let mut regions: Vec<Option<Region>> = regions.into_iter().map(Some).collect();
    let regions = comp
        .iter()
        .map(|&i| regions[i].take().expect("comp names each instance once"))
        .collect();
    for e in &mut edges {
        let (i, j) = e.ends();
        (e.from, e.to) = (keep[i] as u32, keep[j] as u32);
    }
    Cell {
        nodes: comp.iter().map(|&i| nodes[i]).collect(),
        regions,
        edges,
        charge,
    }
}

/// The cell's instances `comp` (indices into the cell) with the edges among them.
fn restrict<'b>(cell: &Cell<'b>, comp: &[usize]) -> Result<Cell<'b>, CellError> {
    let mut keep = vec![usize::MAX; cell.nodes.len()];
    for (k, &i) in comp.iter().enumerate() {
        keep[i] = k;
    }
    cell.charged(
        comp.iter().map(|&i| cell.nodes[i]).collect(),
        comp.iter().map(|&i| cell.regions[i].clone()).collect(),
        cell.edges
            .iter()
            .filter_map(|e| {
                let (i, j) = e.ends();
                (keep[i] != usize::MAX && keep[j] != usize::MAX).then(|| CellEdge {
                    from: keep[i] as u32,
                    to: keep[j] as u32,
                    ..*e
                })
            })
            .collect(),
    )
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
            let w = edges[k].ends().1;
            if !member[w] {
                continue;
            }
            if w == start {
                let mut cycle = vec![k];
                let mut u = v;
                while u != start {
                    let e = via[u];
                    cycle.push(e);
                    u = edges[e].ends().0;
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
        let mut g = super::super::graph::tests::stacked_pair();
        let mut stats = CellStats::default();
        let out = resolve(&mut g, &MemoryBudget::new(None), &mut stats, &|_, _| {})
            .unwrap()
            .placed;
        // b (occluded) is drawn before a.
        let order: Vec<u32> = out.iter().map(|(x, _)| g.nodes[*x].tri).collect();
        assert_eq!(order, vec![1, 0]);
        assert!(out.iter().all(|(_, p)| p.is_empty()));
        assert_eq!(stats.cuts, 0);
    }

    #[test]
    fn the_cells_charge_what_they_hold_and_stop_at_the_budget() {
        use super::super::partition::{directions, partition_region};
        use std::f64::consts::TAU;
        // A torus of 12 x 6 quads (occlusion cycles across the viewpoints of a partition,
        // none seen whole from one), in the first partition whose graph has a cycle.
        let at = |i: usize, j: usize| {
            let (u, v) = (TAU * i as f64 / 12.0, TAU * j as f64 / 6.0);
            let r = 0.6 + 0.25 * v.cos();
            DVec3::new(r * u.cos(), r * u.sin(), 0.25 * v.sin()) * 0.8
        };
        let tris: std::sync::Arc<[[DVec3; 3]]> = (0..12)
            .flat_map(|i| {
                (0..6).flat_map(move |j| {
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    [[a, b, c], [a, c, d]]
                })
            })
            .collect();
        let dirs = directions(6).unwrap();
        let free = MemoryBudget::new(None);
        let found = (0..dirs.len()).find_map(|k| {
            let part = partition_region(&dirs, k);
            let (g, rows) = Graph::build(tris.clone(), &part, &free, &|_, _| {}).unwrap();
            let mut stats = CellStats::default();
            let mut h = g.clone();
            let r = resolve(&mut h, &free, &mut stats, &|_, _| {}).unwrap();
            (stats.cyclic_components > 0).then_some((g, rows.charged, r, stats))
        });
        let (g, charged, resolved, stats) = found.expect("a partition with a cycle");
        assert!(stats.cuts > 0 && resolved.placed.len() > g.nodes.len());
        // Every cell's bytes were given back; what is left charged is the graphs' (this
        // one's edges are returned as `freed` for the caller).
        let graphs = free.used();
        assert!(resolved.freed > 0 && resolved.freed < charged);
        // A budget the graph fills refuses the cells' first bytes, names the component,
        // and keeps nothing of the cells charged.
        let tight = MemoryBudget::new(Some(charged));
        tight.charge(charged).unwrap();
        let mut h = g.clone();
        let mut s = CellStats::default();
        let e = match resolve(&mut h, &tight, &mut s, &|_, _| {}) {
            Err(e) => e,
            Ok(_) => panic!("resolved within the graph's own bytes"),
        };
        let CellError::Memory {
            instances, limit, ..
        } = e
        else {
            panic!("{e}")
        };
        assert!(instances >= 2 && limit == charged);
        assert!(e.to_string().contains("memory limit"), "{e}");
        assert_eq!(tight.used(), charged);
        // With room for the cells, the same order as unbounded.
        let roomy = MemoryBudget::new(Some(charged + (64 << 20)));
        roomy.charge(charged).unwrap();
        let mut h = g.clone();
        let again = resolve(&mut h, &roomy, &mut CellStats::default(), &|_, _| {}).unwrap();
        assert_eq!(again.placed, resolved.placed);
        assert_eq!(roomy.used(), charged);
        assert_eq!(free.used(), graphs);
    }
}
