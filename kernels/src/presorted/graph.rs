//! The occlusion graph of one partition (sections 3.1 and 4.1.1): a node per triangle
//! instance (front copy, back-facing duplicate, and the copies the scan makes), each with
//! its rendering region `E`; an edge `i -> j` iff some viewpoint of the partition sees `i`
//! occlude `j` with both rendered, i.e. iff the reduced occlusion region
//! `O_{i->j} ∩ E_i ∩ E_j` (eq. 1) has an interior.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use glam::DVec3;

use super::geom::{occlusion_planes, verts_outside, OcclPlanes, Plane, Region, EPS};
use super::separate::Shape;

mod decide;
#[cfg(test)]
use decide::has_witness;
use decide::{bounding_sphere, centre, cone_misses, may_occlude, Witness};

/// One triangle instance.
#[derive(Clone, Debug)]
pub struct Node {
    /// Its triangle (a piece of the input: an index into [`Graph::tris`]).
    pub tri: u32,
    /// The back-facing duplicate (rendered from behind the triangle's plane).
    pub back: bool,
    /// Half-spaces the scan cut this instance's region with (its test planes).
    pub cuts: Vec<Plane>,
    /// Rendering region: facing half-space ∩ partition ∩ cuts.
    pub region: Region,
}

/// One occlusion edge: `from` occludes `to` from some viewpoint of both regions. Only the
/// endpoints are stored (the graph has up to n^2 edges, hundreds of millions on a 48K-
/// triangle mesh): the occlusion region and the reduced region are recomputed where needed
/// ([`Graph::occl`], [`Graph::edge_region`]), whether it is alive is a bit of
/// [`Graph::alive`], and node and edge ids are `u32` (at most [`MAX_IDS`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    pub from: u32,
    pub to: u32,
}

/// Most nodes, and most edges, of one graph (ids are `u32`).
pub const MAX_IDS: u64 = u32::MAX as u64;

/// Bytes a graph holds per edge with its in-edges not indexed ([`Graph::index_in_edges`],
/// which only the scan needs): the [`Edge`] and its id in its source's out-list; the
/// alive bit is counted by [`Graph::bytes_for`].
pub const EDGE_BYTES: u64 = (std::mem::size_of::<Edge>() + std::mem::size_of::<u32>()) as u64;

/// Bytes per edge the index of in-edges adds: an id in the target's in-list, counted twice
/// (the lists grow by doubling as edges arrive in any order).
pub const IN_EDGE_BYTES: u64 = 2 * std::mem::size_of::<u32>() as u64;

/// Bytes per node beyond its region's heap: the node, its out-list, and what building the
/// rows keeps per node (its facing plane, region centre and where its vertices start in
/// the rows' copy of them) and per triangle (bounding sphere and centroid, counted per
/// node).
pub const NODE_BYTES: u64 = (std::mem::size_of::<Node>()
    + std::mem::size_of::<usize>()
    + std::mem::size_of::<Vec<u32>>()
    + std::mem::size_of::<Plane>()
    + 2 * std::mem::size_of::<DVec3>()
    + std::mem::size_of::<(DVec3, f64)>()) as u64;

/// One bit per edge: whether it is alive (an edge dies when an endpoint is split).
#[derive(Clone, Debug, Default)]
pub struct Bits {
    words: Vec<u64>,
    len: usize,
}

impl Bits {
    pub fn push(&mut self, v: bool) {
        if self.len.is_multiple_of(64) {
            self.words.push(0);
        }
        self.len += 1;
        self.set(self.len - 1, v);
    }
    pub fn get(&self, i: usize) -> bool {
        self.words[i / 64] >> (i % 64) & 1 == 1
    }
    pub fn set(&mut self, i: usize, v: bool) {
        let (w, b) = (i / 64, 1u64 << (i % 64));
        if v {
            self.words[w] |= b;
        } else {
            self.words[w] &= !b;
        }
    }
    /// Bits set.
    pub fn count_ones(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }
}

/// The graph of one partition.
#[derive(Clone, Debug, Default)]
pub struct Graph {
    pub tris: Arc<[[DVec3; 3]]>,
    pub nodes: Vec<Node>,
    pub edges: Vec<Edge>,
    /// Whether each edge is alive.
    pub alive: Bits,
    /// Edges leaving each node (ids into `edges`, dead ones included until pruned).
    pub out: Vec<Vec<u32>>,
    /// Edges entering each node, once indexed ([`Graph::index_in_edges`]: the cells never
    /// need them, and they are a third of the graph's memory).
    inn: Option<Vec<Vec<u32>>>,
}

/// A bound on the bytes of the graphs being built at once (one per partition, as many at
/// once as the up-front estimate lets fit, at most `threads`): each graph charges its nodes
/// and every row of edges as it grows, and building stops with [`GraphError::Memory`]
/// rather than exceeding the bound.
#[derive(Debug)]
pub struct MemoryBudget {
    limit: Option<u64>,
    // (A plain atomic counter shared by the preprocessing threads on the CPU; the emulated
    // GPU is not involved.)
    used: AtomicU64,
}

impl MemoryBudget {
    /// A budget of `limit` bytes (`None`: unbounded).
    pub fn new(limit: Option<u64>) -> MemoryBudget {
        MemoryBudget {
            limit,
            used: AtomicU64::new(0),
        }
    }

    /// Takes `bytes` from the budget, or fails naming what all graphs would hold.
    pub fn charge(&self, bytes: u64) -> Result<(), GraphError> {
        let total = self.used.fetch_add(bytes, Ordering::Relaxed) + bytes;
        match self.limit {
            Some(limit) if total > limit => {
                self.used.fetch_sub(bytes, Ordering::Relaxed);
                Err(GraphError::Memory {
                    bytes: total,
                    limit,
                })
            }
            _ => Ok(()),
        }
    }

    /// Bytes charged now.
    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// Gives `bytes` back.
    pub fn release(&self, bytes: u64) {
        self.used.fetch_sub(bytes, Ordering::Relaxed);
    }
}

/// Building a graph stopped.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GraphError {
    #[error(
        "the occlusion graphs being built at once would hold {}, over the memory limit of \
         {} (more than the estimate from a sample of their rows): use --threads 1 (one graph \
         at a time), fewer partitions, or a simpler mesh",
        gib(*bytes),
        gib(*limit)
    )]
    Memory { bytes: u64, limit: u64 },
    #[error("more than {MAX_IDS} edges in one graph (edge ids are u32)")]
    TooManyEdges,
}

/// Bytes as GiB, for messages.
pub fn gib(bytes: u64) -> String {
    format!("{:.2} GiB", bytes as f64 / (1u64 << 30) as f64)
}

/// The facing half-space of a triangle (front copy), or its complement (back copy).
pub fn facing(t: &[DVec3; 3], back: bool) -> Plane {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let p = Plane::through(n, t[0]).unwrap_or(Plane {
        n: DVec3::Z,
        d: -t[0].z,
    });
    if back {
        p.flip()
    } else {
        p
    }
}

/// What building rows of a graph did ([`Graph::add_rows`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowStats {
    /// Pairs that passed the cheap rejections (a witness or the clip was needed).
    pub pairs: u64,
    /// Of those, edges proven by a witness viewpoint (`decide::Witness`).
    pub witnessed: u64,
    /// Edges found by clipping the reduced region.
    pub clipped: u64,
    /// Bytes charged to the [`MemoryBudget`] (the caller releases them with the graph).
    pub charged: u64,
}

/// How [`Graph::add_rows`] computes its rows: the edges and the order they are added in are
/// the same either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowWork {
    /// One row after another on the calling thread (a sample measured per partition).
    Sequential,
    /// Batches of rows on the current rayon pool's threads (a row's pairs depend only on
    /// the nodes, never on the edges found so far), the edges then added row by row in
    /// order: one graph uses every thread, so one graph at a time is enough to keep the
    /// cores busy when memory allows no more.
    Parallel,
}

/// The edges one row found ([`Graph::unit_rows`]): the nodes it occludes, in increasing
/// order, and how its pairs were decided (`charged` stays 0: the caller charges the row).
#[derive(Default)]
struct Row {
    to: Vec<u32>,
    stats: RowStats,
}

/// The occlusion planes of the last pair of triangles asked for: the copies of a triangle
/// are consecutive nodes, so the pairs of copies of two triangles come one after another
/// in [`Graph::unit_rows`] and share one computation.
#[derive(Default)]
struct OcclCache {
    key: Option<(u32, u32)>,
    planes: OcclPlanes,
}

impl OcclCache {
    /// The occlusion planes of triangles `ta` (`a`) and `tb` (`b`).
    fn get(&mut self, ta: u32, tb: u32, a: &[DVec3; 3], b: &[DVec3; 3]) -> &OcclPlanes {
        if self.key != Some((ta, tb)) {
            self.planes = occlusion_planes(a, b);
            self.key = Some((ta, tb));
        }
        &self.planes
    }
}

/// What every row reads besides the graph's nodes: per node its facing plane and region
/// centre, per triangle its bounding sphere and centroid.
struct RowInputs {
    planes: Vec<Plane>,
    spheres: Vec<(DVec3, f64)>,
    centroids: Vec<DVec3>,
    centres: Vec<DVec3>,
    /// Every node's region vertices, one node after another (`verts[at[x]..at[x + 1]]`): a
    /// row's cheap tests read every node's, and from scattered regions each node's first
    /// read missed the cache.
    verts: Vec<DVec3>,
    at: Vec<usize>,
}

impl RowInputs {
    /// The vertices of node `x`'s rendering region.
    fn verts_of(&self, x: usize) -> &[DVec3] {
        &self.verts[self.at[x]..self.at[x + 1]]
    }
}

/// Rows a thread takes at once under [`RowWork::Parallel`] (a row of the 48K dragon costs
/// tens of milliseconds, of a small mesh microseconds).
const ROWS_PER_TASK: usize = 16;

impl Graph {
    /// Nodes (front and back copy of every triangle whose copy can be rendered from the
    /// partition) and every edge, its rows on the current rayon pool ([`RowWork::Parallel`]).
    /// `tick(done, total)` reports progress over the nodes.
    /// Its bytes are charged to `budget` (released by the caller: [`RowStats::charged`]).
    pub fn build(
        tris: Arc<[[DVec3; 3]]>,
        partition: &Region,
        budget: &MemoryBudget,
        tick: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Graph, RowStats), GraphError> {
        let mut g = Graph::nodes_of(tris, partition);
        let n = g.nodes.len();
        let stats = g.add_rows(0..n, RowWork::Parallel, budget, tick)?;
        Ok((g, stats))
    }

    /// Bytes of the nodes (their regions included) and of `edges` edges (with the index of
    /// in-edges if `in_edges`): what [`Graph::add_rows`] charges, and the estimate of a
    /// graph from a sample of its rows.
    pub fn bytes_for(&self, edges: u64, in_edges: bool) -> u64 {
        let nodes: u64 = self
            .nodes
            .iter()
            .map(|x| {
                // (The rows' copy of the region's vertices too: RowInputs.)
                let copy = x.region.verts.len() * std::mem::size_of::<DVec3>();
                NODE_BYTES + (x.region.heap_bytes() + copy) as u64
            })
            .sum();
        let per_edge = EDGE_BYTES + if in_edges { IN_EDGE_BYTES } else { 0 };
        nodes + edges * per_edge + edges.div_ceil(8)
    }

    /// The nodes of the partition (front and back copy of every triangle whose copy can be
    /// rendered from it), without edges.
    pub fn nodes_of(tris: Arc<[[DVec3; 3]]>, partition: &Region) -> Graph {
        let mut g = Graph {
            tris: tris.clone(),
            ..Default::default()
        };
        for (t, tri) in tris.iter().enumerate() {
            for back in [false, true] {
                let region = partition.cut(&[facing(tri, back)]);
                if !region.is_empty() {
                    g.add_node(Node {
                        tri: t as u32,
                        back,
                        cuts: Vec::new(),
                        region,
                    });
                }
            }
        }
        g
    }

    /// Adds the edges leaving each node of `rows` (increasing; a row of the graph: every
    /// node `j` it may occlude is tried), computed as `work` says; the edges are added in
    /// row order either way. [`Graph::build`] runs every row; a sample of rows measures the
    /// cost of the graph ([`super::estimate_graph`]).
    /// Every row's bytes are charged to `budget` first; over it, what was charged is
    /// released and the error returned.
    pub fn add_rows(
        &mut self,
        rows: impl ExactSizeIterator<Item = usize>,
        work: RowWork,
        budget: &MemoryBudget,
        tick: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<RowStats, GraphError> {
        let mut stats = RowStats::default();
        match self.add_rows_charged(rows, work, budget, &mut stats, tick) {
            Ok(()) => Ok(stats),
            Err(e) => {
                budget.release(stats.charged);
                Err(e)
            }
        }
    }

    fn add_rows_charged(
        &mut self,
        rows: impl ExactSizeIterator<Item = usize>,
        work: RowWork,
        budget: &MemoryBudget,
        stats: &mut RowStats,
        tick: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(), GraphError> {
        let nodes = self.bytes_for(0, false);
        budget.charge(nodes)?;
        stats.charged = nodes;
        let in_bytes = if self.inn.is_some() { IN_EDGE_BYTES } else { 0 };
        let n = self.nodes.len();
        let total = rows.len() as u64;
        let inputs = self.row_inputs();
        // Units of work: the rows of one triangle's copies (consecutive), which share the
        // occlusion planes of their triangle's pairs.
        let rows: Vec<usize> = rows.collect();
        let units: Vec<&[usize]> = rows
            .chunk_by(|&a, &b| self.nodes[a].tri == self.nodes[b].tri)
            .collect();
        let per_batch = match work {
            RowWork::Sequential => 1,
            RowWork::Parallel => ROWS_PER_TASK * rayon::current_num_threads().max(1),
        };
        let mut done = 0u64;
        for batch in units.chunks(per_batch) {
            let unit_rows = |unit: &&[usize]| self.unit_rows(unit, &inputs);
            let found: Vec<Vec<Row>> = match work {
                RowWork::Sequential => batch.iter().map(unit_rows).collect(),
                RowWork::Parallel => {
                    use rayon::prelude::*;
                    batch.par_iter().map(unit_rows).collect()
                }
            };
            for (unit, found) in batch.iter().zip(found) {
                for (&i, row) in unit.iter().zip(found) {
                    if done.is_multiple_of(64) {
                        tick(done, total);
                    }
                    done += 1;
                    if self.edges.len() as u64 + n as u64 > MAX_IDS {
                        return Err(GraphError::TooManyEdges);
                    }
                    for &j in &row.to {
                        self.push_edge(i, j as usize);
                    }
                    stats.pairs += row.stats.pairs;
                    stats.witnessed += row.stats.witnessed;
                    stats.clipped += row.stats.clipped;
                    // The row's out-list at its length (it is complete), and its bytes
                    // charged.
                    self.out[i].shrink_to_fit();
                    let added = row.to.len() as u64;
                    let bytes = added * (EDGE_BYTES + in_bytes) + added.div_ceil(8);
                    budget.charge(bytes)?;
                    stats.charged += bytes;
                }
            }
        }
        tick(total, total);
        Ok(())
    }

    /// What every row reads ([`RowInputs`]).
    fn row_inputs(&self) -> RowInputs {
        let tris = &self.tris;
        RowInputs {
            planes: self
                .nodes
                .iter()
                .map(|x| facing(&tris[x.tri as usize], x.back))
                .collect(),
            spheres: tris.iter().map(bounding_sphere).collect(),
            centroids: tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect(),
            centres: self.nodes.iter().map(|x| centre(&x.region)).collect(),
            verts: self
                .nodes
                .iter()
                .flat_map(|x| x.region.verts.iter().copied())
                .collect(),
            at: std::iter::once(0)
                .chain(self.nodes.iter().scan(0, |end, x| {
                    *end += x.region.verts.len();
                    Some(*end)
                }))
                .collect(),
        }
    }

    /// The rows of one unit (the copies of one triangle, `unit`): for each, every node `j`
    /// it occludes from some viewpoint of both regions, in increasing order. The rows are
    /// walked together, so the occlusion planes of a pair of triangles are computed once for
    /// every pair of their copies ([`OcclCache`]).
    fn unit_rows(&self, unit: &[usize], inputs: &RowInputs) -> Vec<Row> {
        let mut rows: Vec<Row> = unit.iter().map(|_| Row::default()).collect();
        let mut cache = OcclCache::default();
        for j in 0..self.nodes.len() {
            for (row, &i) in rows.iter_mut().zip(unit) {
                if self.pair(i, j, inputs, &mut cache, &mut row.stats) {
                    row.to.push(j as u32);
                }
            }
        }
        rows
    }

    /// Whether `i -> j` is an edge: the cheap rejections, then a witness viewpoint or the
    /// clip of the reduced region (counted in `stats`).
    fn pair(
        &self,
        i: usize,
        j: usize,
        inputs: &RowInputs,
        cache: &mut OcclCache,
        stats: &mut RowStats,
    ) -> bool {
        let RowInputs {
            planes,
            spheres,
            centroids,
            centres,
            ..
        } = inputs;
        let tris = &self.tris;
        let (ti, tj) = (self.nodes[i].tri, self.nodes[j].tri);
        if ti == tj {
            return false;
        }
        let (a, b) = (&tris[ti as usize], &tris[tj as usize]);
        // j must reach behind i, and i in front of j (see module docs of geom).
        if !b.iter().any(|q| planes[i].eval(*q) < -EPS)
            || !a.iter().any(|p| planes[j].eval(*p) > EPS)
        {
            return false;
        }
        // Each region must reach into the other's facing half-space.
        let (ri, rj) = (&self.nodes[i].region, &self.nodes[j].region);
        let (vi, vj) = (inputs.verts_of(i), inputs.verts_of(j));
        if verts_outside(vi, &planes[j]) || verts_outside(vj, &planes[i]) {
            return false;
        }
        let (sa, sb) = (spheres[ti as usize], spheres[tj as usize]);
        if cone_misses(sa, sb, vi, centres[i])
            || cone_misses(sa, sb, vj, centres[j])
            || !may_occlude(a, b, vi, vj)
        {
            return false;
        }
        stats.pairs += 1;
        // A witness viewpoint, proven from the triangles alone where it can be (most edges),
        // else from the occlusion region's facets; then the clip.
        let witness = Witness::new(centroids[ti as usize], centroids[tj as usize], ri, rj);
        if witness.as_ref().is_some_and(|w| w.proven_by_cone(a, b)) {
            stats.witnessed += 1;
            return true;
        }
        let occl = cache.get(ti, tj, a, b);
        if witness.is_some_and(|w| w.proven_by_planes(occl)) {
            stats.witnessed += 1;
            true
        } else if self.occludes(i, j, occl) {
            stats.clipped += 1;
            true
        } else {
            false
        }
    }

    /// Whether each of `pairs` (`from`, `to`) is an edge, decided as building the graph
    /// decides it (on the current rayon pool): for a few pairs, where building every row
    /// would cost the whole graph.
    pub fn pair_edges(&self, pairs: &[(usize, usize)]) -> Vec<bool> {
        use rayon::prelude::*;
        let inputs = self.row_inputs();
        pairs
            .par_iter()
            .map_init(OcclCache::default, |cache, &(i, j)| {
                self.pair(i, j, &inputs, cache, &mut RowStats::default())
            })
            .collect()
    }

    pub fn add_node(&mut self, node: Node) -> usize {
        self.nodes.push(node);
        self.out.push(Vec::new());
        if let Some(inn) = &mut self.inn {
            inn.push(Vec::new());
        }
        self.nodes.len() - 1
    }

    /// Indexes the edges entering each node (the scan walks them; [`Graph::in_edges`] and
    /// [`Graph::split`] index them first if needed). Idempotent.
    pub fn index_in_edges(&mut self) {
        if self.inn.is_some() {
            return;
        }
        let mut inn: Vec<Vec<u32>> = vec![Vec::new(); self.nodes.len()];
        for (id, e) in self.edges.iter().enumerate() {
            if self.alive.get(id) {
                inn[e.to as usize].push(id as u32);
            }
        }
        self.inn = Some(inn);
    }

    /// The ids of the edges entering `x` (dead ones included until pruned), once indexed.
    pub fn in_ids(&self, x: usize) -> &[u32] {
        self.inn.as_ref().map_or(&[], |inn| &inn[x])
    }

    /// Adds `from -> to` if its reduced occlusion region has an interior (`occl`: the
    /// occlusion region of their triangles).
    pub fn try_edge(&mut self, from: usize, to: usize, occl: &[Plane]) -> bool {
        if !self.occludes(from, to, occl) {
            return false;
        }
        self.push_edge(from, to);
        true
    }

    /// Whether `from -> to` is an edge: its reduced occlusion region has an interior.
    fn occludes(&self, from: usize, to: usize, occl: &[Plane]) -> bool {
        !self.reduced(from, to, occl).is_empty()
    }

    /// Adds the edge `from -> to`.
    fn push_edge(&mut self, from: usize, to: usize) {
        // (add_rows refuses a row that could pass MAX_IDS edges; a split replaces a dead
        // edge by at most two.)
        let id = u32::try_from(self.edges.len()).expect("edge ids fit u32 (MAX_IDS)");
        let node = |x: usize| u32::try_from(x).expect("node ids fit u32 (MAX_IDS)");
        self.edges.push(Edge {
            from: node(from),
            to: node(to),
        });
        self.alive.push(true);
        self.out[from].push(id);
        if let Some(inn) = &mut self.inn {
            inn[to].push(id);
        }
    }

    /// Whether edge `e` is alive.
    pub fn is_alive(&self, e: usize) -> bool {
        self.alive.get(e)
    }

    /// Live edges leaving `x`.
    pub fn out_edges(&self, x: usize) -> impl Iterator<Item = &Edge> + '_ {
        self.out[x]
            .iter()
            .map(|&e| e as usize)
            .filter(|&e| self.alive.get(e))
            .map(|e| &self.edges[e])
    }

    /// Live edges entering `x` (from the index of in-edges, or a pass over every edge when
    /// they are not indexed: [`Graph::index_in_edges`]).
    pub fn in_edges(&self, x: usize) -> Box<dyn Iterator<Item = &Edge> + '_> {
        match &self.inn {
            Some(inn) => Box::new(
                inn[x]
                    .iter()
                    .map(|&e| e as usize)
                    .filter(|&e| self.alive.get(e))
                    .map(|e| &self.edges[e]),
            ),
            None => Box::new(
                self.live_edges()
                    .map(|(_, e)| e)
                    .filter(move |e| e.to as usize == x),
            ),
        }
    }

    /// Every live edge with its id.
    pub fn live_edges(&self) -> impl Iterator<Item = (usize, &Edge)> + '_ {
        self.edges
            .iter()
            .enumerate()
            .filter(|(id, _)| self.alive.get(*id))
    }

    /// The reduced occlusion region `O_{from->to} ∩ E_from ∩ E_to` (eq. 1), empty when
    /// either rendering region lies outside one of `occl`'s planes (the paper's cheap out).
    fn reduced(&self, from: usize, to: usize, occl: &[Plane]) -> Region {
        let (ef, et) = (&self.nodes[from].region, &self.nodes[to].region);
        if ef.outside_any(occl) || et.outside_any(occl) {
            return Region::default();
        }
        ef.cut(occl).intersect(et)
    }

    /// Drops every edge (the edges, their alive bits, the out-lists and any index of
    /// in-edges), keeping the nodes; returns the bytes [`Graph::add_rows`] charged for them.
    pub fn drop_edges(&mut self) -> u64 {
        let edges = self.edges.len() as u64;
        let in_edges = self.inn.is_some();
        let freed = self.bytes_for(edges, in_edges) - self.bytes_for(0, false);
        self.edges = Vec::new();
        self.alive = Bits::default();
        self.out = vec![Vec::new(); self.nodes.len()];
        self.inn = None;
        freed
    }

    /// The occlusion region of the triangles of an edge's endpoints (section 4.1.1).
    pub fn occl(&self, e: &Edge) -> OcclPlanes {
        let t = |x: u32| &self.tris[self.nodes[x as usize].tri as usize];
        occlusion_planes(t(e.from), t(e.to))
    }

    /// The reduced occlusion region of edge `e` (eq. 1), recomputed.
    pub fn edge_region(&self, e: usize) -> Region {
        let ed = &self.edges[e];
        self.reduced(ed.from as usize, ed.to as usize, &self.occl(ed))
    }

    /// The vertices of edge `e`'s reduced occlusion region.
    pub fn edge_verts(&self, e: usize) -> Vec<DVec3> {
        self.edge_region(e).verts
    }

    /// The reduced occlusion region of edge `e` (eq. 1) as the separating-axis test sees it.
    pub fn edge_shape(&self, e: usize) -> Shape {
        let r = self.edge_region(e);
        Shape {
            normals: r.normals(),
            edges: r.edge_dirs(),
            verts: r.verts,
        }
    }

    /// Live edge count.
    pub fn edge_count(&self) -> usize {
        self.alive.count_ones()
    }

    /// Splits node `x` by `p`: `x` keeps `E_x ∩ p`, a new node gets `E_x ∩ ¬p`; edges are
    /// redistributed to whichever copy still has a reduced region. Returns the new node
    /// (`None` if its region is empty) and whether `x` itself still has a region.
    pub fn split(&mut self, x: usize, p: Plane) -> (Option<usize>, bool) {
        let old = self.nodes[x].clone();
        let keep_region = old.region.cut(&[p]);
        let new_region = old.region.cut(&[p.flip()]);
        let keep_alive = !keep_region.is_empty();
        self.nodes[x].region = keep_region;
        self.nodes[x].cuts.push(p);
        let new = (!new_region.is_empty()).then(|| {
            let mut cuts = old.cuts.clone();
            cuts.push(p.flip());
            self.add_node(Node {
                tri: old.tri,
                back: old.back,
                cuts,
                region: new_region,
            })
        });
        self.index_in_edges();
        let outs: Vec<u32> = std::mem::take(&mut self.out[x]);
        let ins: Vec<u32> = self
            .inn
            .as_mut()
            .map(|inn| std::mem::take(&mut inn[x]))
            .unwrap_or_default();
        let mut touched: Vec<usize> = outs
            .iter()
            .map(|&e| self.edges[e as usize].to as usize)
            .chain(ins.iter().map(|&e| self.edges[e as usize].from as usize))
            .collect();
        for e in outs {
            let e = e as usize;
            if !self.alive.get(e) {
                continue;
            }
            self.alive.set(e, false);
            let (to, occl) = (self.edges[e].to as usize, self.occl(&self.edges[e]));
            if keep_alive {
                self.try_edge(x, to, &occl);
            }
            if let Some(n) = new {
                self.try_edge(n, to, &occl);
            }
        }
        for e in ins {
            let e = e as usize;
            if !self.alive.get(e) {
                continue;
            }
            self.alive.set(e, false);
            let (from, occl) = (self.edges[e].from as usize, self.occl(&self.edges[e]));
            if keep_alive {
                self.try_edge(from, x, &occl);
            }
            if let Some(n) = new {
                self.try_edge(from, n, &occl);
            }
        }
        // Drop the dead edge ids from the other endpoints' lists (the scan walks them).
        touched.sort_unstable();
        touched.dedup();
        for y in touched {
            let alive = &self.alive;
            self.out[y].retain(|&e| alive.get(e as usize));
            if let Some(inn) = &mut self.inn {
                inn[y].retain(|&e| alive.get(e as usize));
            }
        }
        (new, keep_alive)
    }
}

#[cfg(test)]
pub(super) mod tests;
