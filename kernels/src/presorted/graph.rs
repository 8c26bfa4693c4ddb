//! The occlusion graph of one partition (sections 3.1 and 4.1.1): a node per triangle
//! instance (front copy, back-facing duplicate, and the copies the scan makes), each with
//! its rendering region `E`; an edge `i -> j` iff some viewpoint of the partition sees `i`
//! occlude `j` with both rendered, i.e. iff the reduced occlusion region
//! `O_{i->j} ∩ E_i ∩ E_j` (eq. 1) has an interior.

use std::collections::HashMap;
use std::sync::Arc;

use glam::DVec3;

use super::geom::{occlusion_planes, Plane, Region, EPS, MIN_WIDTH};
use super::separate::Shape;

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
/// endpoints are stored (the graph has up to n^2 edges): the occlusion region and the
/// reduced region are recomputed where needed ([`Graph::occl`], [`Graph::edge_region`]).
#[derive(Clone, Copy, Debug)]
pub struct Edge {
    pub from: usize,
    pub to: usize,
    pub alive: bool,
}

/// The graph of one partition.
#[derive(Clone, Debug, Default)]
pub struct Graph {
    pub tris: Arc<[[DVec3; 3]]>,
    pub nodes: Vec<Node>,
    pub edges: Vec<Edge>,
    /// Edges leaving each node (ids into `edges`, dead ones included until pruned).
    pub out: Vec<Vec<usize>>,
    /// Edges entering each node.
    pub inn: Vec<Vec<usize>>,
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

/// A necessary condition for `a` to occlude `b` from a viewpoint of both regions, cheaper
/// than the occlusion region: when every direction `a_k - b_l` has a positive component
/// along `u` (from `b`'s centroid to `a`'s), `O_{a->b} = a + cone(a - b)` lies in the
/// half-space `u.x >= min_k u.a_k`, which both regions must reach into.
fn may_occlude(a: &[DVec3; 3], b: &[DVec3; 3], ra: &Region, rb: &Region) -> bool {
    let u = (a[0] + a[1] + a[2] - b[0] - b[1] - b[2]) / 3.0;
    if a.iter().any(|p| b.iter().any(|q| (*p - *q).dot(u) <= 0.0)) {
        return true;
    }
    let Some(h) = Plane::through(u, DVec3::ZERO) else {
        return true;
    };
    let lo = a.iter().map(|p| h.eval(*p)).fold(f64::INFINITY, f64::min);
    let bound = [Plane {
        n: h.n,
        d: h.d - lo,
    }];
    !(ra.outside_any(&bound) || rb.outside_any(&bound))
}

/// A sphere holding a triangle: its centroid and the distance to its farthest vertex.
fn bounding_sphere(t: &[DVec3; 3]) -> (DVec3, f64) {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    let r = t.iter().map(|p| (*p - c).length()).fold(0.0, f64::max);
    (c, r * (1.0 + 1e-9) + EPS)
}

/// Whether `region` lies wholly outside a convex set holding `O_{a->b}` (a conservative
/// rejection, cheaper than the occlusion region): with `a` in the ball `(ca, ra)` and `b` in
/// `(cb, rb)` (disjoint), `O_{a->b} = a + cone(a - b)` lies in the ball of `a` plus the
/// circular cone of axis `w = (ca - cb)/|ca - cb|` and half-angle `asin((ra + rb)/|ca - cb|)`.
/// Every direction `n` within the dual cone (at most `90° - α` from `w`) has `n . d >= 0`
/// along that cone, so `O` lies in `n . (x - ca) >= -ra`; the test tries `w` itself and the
/// direction of the dual cone nearest to the region's centre as seen from `ca`.
fn cone_misses(sa: (DVec3, f64), sb: (DVec3, f64), region: &Region, centre: DVec3) -> bool {
    let ((ca, ra), (cb, rb)) = (sa, sb);
    let w = ca - cb;
    let dist = w.length();
    if region.is_empty() || dist <= (ra + rb) * (1.0 + 1e-9) {
        return region.is_empty();
    }
    let w = w / dist;
    let sin_a = (ra + rb) / dist;
    let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
    let m = ca - centre;
    let along = m.dot(w);
    let perp = m - w * along;
    let pl = perp.length();
    let toward = if along >= m.length() * sin_a {
        m.normalize_or_zero()
    } else if pl > 1e-12 {
        w * sin_a + perp / pl * cos_a
    } else {
        w
    };
    [w, toward].iter().any(|n| {
        *n != DVec3::ZERO
            && region
                .verts
                .iter()
                .all(|v| n.dot(*v - ca) < -ra - MIN_WIDTH)
    })
}

/// The mean of a region's vertices (the point [`cone_misses`] aims at).
fn centre(region: &Region) -> DVec3 {
    region.verts.iter().copied().sum::<DVec3>() / region.verts.len() as f64
}

/// How far inside every half-space a witness viewpoint must lie ([`has_witness`]): a
/// thousand times the tolerances of the clips ([`EPS`]) and ten times [`MIN_WIDTH`].
const WITNESS_MARGIN: f64 = 1e-6;

/// Distances from `a`'s centroid, along the centroids' direction, at which [`has_witness`]
/// looks for a witness (inside the viewpoint box, `FAR` = 64, from a centroid in the unit
/// ball).
const WITNESS_REACH: [f64; 3] = [40.0, 12.0, 4.0];

/// Whether the reduced occlusion region `O_{a->b} ∩ E_from ∩ E_to` provably has an interior,
/// without clipping: a viewpoint `v` at least [`WITNESS_MARGIN`] inside every half-space of
/// `occl` (the facets of `O_{a->b}`) and of both rendering regions (each region is the
/// intersection of its faces' half-spaces) is the centre of a ball of that radius inside
/// the exact region. [`Graph::try_edge`]'s clips only ever drop what lies beyond a plane
/// by more than [`EPS`] (`1e-9`, rounding of the clipped vertices about `1e-13` in the
/// viewpoint box), so every region they produce on the way holds that ball too: no clip
/// finds every vertex within [`MIN_WIDTH`] of the outside (the ball reaches `2e-6` past
/// the plane), and the result spans more than `MIN_WIDTH` in every direction; the clip
/// would therefore have found the edge. Candidates: `c_a + s (c_a - c_b)/|c_a - c_b|` (in
/// `O_{a->b}` by its definition, `a + cone(a - b)`) for the distances of
/// [`WITNESS_REACH`]; when none is a witness, the clip decides.
fn has_witness(ca: DVec3, cb: DVec3, occl: &[Plane], from: &Region, to: &Region) -> bool {
    let w = (ca - cb).normalize_or_zero();
    if w == DVec3::ZERO {
        return false;
    }
    WITNESS_REACH.iter().any(|s| {
        let v = ca + w * *s;
        occl.iter()
            .chain(&from.planes)
            .chain(&to.planes)
            .all(|p| p.eval(v) >= WITNESS_MARGIN)
    })
}

/// What building rows of a graph did ([`Graph::add_rows`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowStats {
    /// Pairs that passed the cheap rejections (their occlusion region was needed).
    pub pairs: u64,
    /// Of those, edges proven by a witness viewpoint ([`has_witness`]).
    pub witnessed: u64,
    /// Edges found by clipping the reduced region.
    pub clipped: u64,
}

impl Graph {
    /// Nodes (front and back copy of every triangle whose copy can be rendered from the
    /// partition) and every edge. `tick(done, total)` reports progress over the nodes.
    pub fn build(tris: Arc<[[DVec3; 3]]>, partition: &Region, tick: &dyn Fn(u64, u64)) -> Graph {
        let mut g = Graph::nodes_of(tris, partition);
        let n = g.nodes.len();
        g.add_rows(0..n, tick);
        g
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
    /// node `j` it may occlude is tried). [`Graph::build`] runs every row; a sample of rows
    /// measures the cost of the graph ([`super::estimate_graph`]).
    pub fn add_rows(
        &mut self,
        rows: impl ExactSizeIterator<Item = usize>,
        tick: &dyn Fn(u64, u64),
    ) -> RowStats {
        let g = self;
        let tris = g.tris.clone();
        let n = g.nodes.len();
        let total = rows.len() as u64;
        let planes: Vec<Plane> = g
            .nodes
            .iter()
            .map(|x| facing(&tris[x.tri as usize], x.back))
            .collect();
        let spheres: Vec<(DVec3, f64)> = tris.iter().map(bounding_sphere).collect();
        let centroids: Vec<DVec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let centres: Vec<DVec3> = g.nodes.iter().map(|x| centre(&x.region)).collect();
        let mut stats = RowStats::default();
        let mut occl_cache: HashMap<(u32, u32), Vec<Plane>> = HashMap::new();
        let mut rows = rows.peekable();
        let mut done = 0u64;
        while let Some(i) = rows.next() {
            if done.is_multiple_of(64) {
                tick(done, total);
            }
            done += 1;
            let ti = g.nodes[i].tri;
            let a = &tris[ti as usize];
            for j in 0..n {
                let tj = g.nodes[j].tri;
                if ti == tj {
                    continue;
                }
                let b = &tris[tj as usize];
                // j must reach behind i, and i in front of j (see module docs of geom).
                if !b.iter().any(|q| planes[i].eval(*q) < -EPS)
                    || !a.iter().any(|p| planes[j].eval(*p) > EPS)
                {
                    continue;
                }
                // Each region must reach into the other's facing half-space.
                if g.nodes[i].region.outside_any(&planes[j..=j])
                    || g.nodes[j].region.outside_any(&planes[i..=i])
                {
                    continue;
                }
                let (sa, sb) = (spheres[ti as usize], spheres[tj as usize]);
                if cone_misses(sa, sb, &g.nodes[i].region, centres[i])
                    || cone_misses(sa, sb, &g.nodes[j].region, centres[j])
                    || !may_occlude(a, b, &g.nodes[i].region, &g.nodes[j].region)
                {
                    continue;
                }
                let occl = occl_cache
                    .entry((ti, tj))
                    .or_insert_with(|| occlusion_planes(a, b));
                stats.pairs += 1;
                let (ri, rj) = (&g.nodes[i].region, &g.nodes[j].region);
                if has_witness(centroids[ti as usize], centroids[tj as usize], occl, ri, rj) {
                    g.push_edge(i, j);
                    stats.witnessed += 1;
                } else if g.try_edge(i, j, occl) {
                    stats.clipped += 1;
                }
            }
            // Occlusion planes of pairs with node i's triangle are no longer needed once
            // its next row (its other copy, if any) is done.
            if rows.peek().is_none_or(|&x| g.nodes[x].tri != ti) {
                occl_cache.retain(|k, _| k.0 != ti);
            }
        }
        tick(total, total);
        stats
    }

    pub fn add_node(&mut self, node: Node) -> usize {
        self.nodes.push(node);
        self.out.push(Vec::new());
        self.inn.push(Vec::new());
        self.nodes.len() - 1
    }

    /// Adds `from -> to` if its reduced occlusion region has an interior (`occl`: the
    /// occlusion region of their triangles).
    pub fn try_edge(&mut self, from: usize, to: usize, occl: &[Plane]) -> bool {
        if self.reduced(from, to, occl).is_empty() {
            return false;
        }
        self.push_edge(from, to);
        true
    }

    /// Adds the edge `from -> to`.
    fn push_edge(&mut self, from: usize, to: usize) {
        let id = self.edges.len();
        self.edges.push(Edge {
            from,
            to,
            alive: true,
        });
        self.out[from].push(id);
        self.inn[to].push(id);
    }

    /// Live edges leaving `x`.
    pub fn out_edges(&self, x: usize) -> impl Iterator<Item = &Edge> + '_ {
        self.out[x]
            .iter()
            .map(|&e| &self.edges[e])
            .filter(|e| e.alive)
    }

    /// Live edges entering `x`.
    pub fn in_edges(&self, x: usize) -> impl Iterator<Item = &Edge> + '_ {
        self.inn[x]
            .iter()
            .map(|&e| &self.edges[e])
            .filter(|e| e.alive)
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

    /// The occlusion region of the triangles of an edge's endpoints (section 4.1.1).
    pub fn occl(&self, e: &Edge) -> Vec<Plane> {
        let t = |x: usize| &self.tris[self.nodes[x].tri as usize];
        occlusion_planes(t(e.from), t(e.to))
    }

    /// The reduced occlusion region of edge `e` (eq. 1), recomputed.
    pub fn edge_region(&self, e: usize) -> Region {
        let ed = &self.edges[e];
        self.reduced(ed.from, ed.to, &self.occl(ed))
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
        self.edges.iter().filter(|e| e.alive).count()
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
        let outs: Vec<usize> = std::mem::take(&mut self.out[x]);
        let ins: Vec<usize> = std::mem::take(&mut self.inn[x]);
        let mut touched: Vec<usize> = outs
            .iter()
            .map(|&e| self.edges[e].to)
            .chain(ins.iter().map(|&e| self.edges[e].from))
            .collect();
        for e in outs {
            if !self.edges[e].alive {
                continue;
            }
            self.edges[e].alive = false;
            let (to, occl) = (self.edges[e].to, self.occl(&self.edges[e]));
            if keep_alive {
                self.try_edge(x, to, &occl);
            }
            if let Some(n) = new {
                self.try_edge(n, to, &occl);
            }
        }
        for e in ins {
            if !self.edges[e].alive {
                continue;
            }
            self.edges[e].alive = false;
            let (from, occl) = (self.edges[e].from, self.occl(&self.edges[e]));
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
            let edges = &self.edges;
            self.out[y].retain(|&e| edges[e].alive);
            self.inn[y].retain(|&e| edges[e].alive);
        }
        (new, keep_alive)
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::partition::{directions, partition_region};
    use super::*;

    /// The graph of two horizontal triangles, a (tri 0) above b (tri 1), in the partition
    /// seen from above (+z).
    pub(in crate::presorted) fn stacked_pair() -> Graph {
        let b = [
            DVec3::new(-0.3, -0.3, -0.2),
            DVec3::new(0.4, -0.3, -0.2),
            DVec3::new(-0.3, 0.4, -0.2),
        ];
        let a = b.map(|p| p + DVec3::new(0.0, 0.0, 0.4));
        let tris: Arc<[[DVec3; 3]]> = vec![a, b].into();
        let dirs = directions(6).unwrap();
        let k = dirs.iter().position(|d| d.z > 0.5).unwrap();
        Graph::build(tris, &partition_region(&dirs, k), &|_, _| {})
    }

    #[test]
    fn the_cone_test_rejects_only_pairs_without_an_edge() {
        // Random small triangles in the unit ball (a fixed LCG), each pair against each
        // partition of the cube: a rejection must mean an empty reduced region, and it must
        // reject many pairs (else it prunes nothing).
        let mut rnd = super::super::test_lcg();
        let tris: Vec<[DVec3; 3]> = (0..40)
            .map(|_| {
                let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
                [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * 0.15)
            })
            .collect();
        let dirs = directions(6).unwrap();
        let (mut rejected, mut edges) = (0, 0);
        for k in 0..dirs.len() {
            let part = partition_region(&dirs, k);
            for (ia, a) in tris.iter().enumerate() {
                for (ib, b) in tris.iter().enumerate() {
                    if ia == ib {
                        continue;
                    }
                    let (ea, eb) = (part.cut(&[facing(a, false)]), part.cut(&[facing(b, true)]));
                    let occl = occlusion_planes(a, b);
                    let reduced = ea.cut(&occl).intersect(&eb);
                    let (sa, sb) = (bounding_sphere(a), bounding_sphere(b));
                    if cone_misses(sa, sb, &ea, centre(&ea))
                        || cone_misses(sa, sb, &eb, centre(&eb))
                    {
                        rejected += 1;
                        assert!(
                            reduced.is_empty(),
                            "pair {ia} -> {ib} rejected with an edge"
                        );
                    }
                    edges += usize::from(!reduced.is_empty());
                }
            }
        }
        assert!(edges > 0);
        assert!(rejected > 6 * 40 * 39 / 4, "only {rejected} pairs rejected");
    }

    #[test]
    fn a_witness_is_found_only_for_edges_and_for_most_of_them() {
        // Random small triangles in the unit ball (a fixed LCG), each ordered pair and
        // facing in each partition of the cube: a witness must mean a non-empty reduced
        // region (the clip's answer), and it must prove most edges (else it saves nothing).
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let tris: Vec<[DVec3; 3]> = (0..30)
            .map(|_| {
                let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
                [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * 0.1)
            })
            .collect();
        let dirs = directions(6).unwrap();
        let (mut witnessed, mut edges) = (0, 0);
        for k in 0..dirs.len() {
            let part = partition_region(&dirs, k);
            for (ia, a) in tris.iter().enumerate() {
                for (ib, b) in tris.iter().enumerate() {
                    for (fa, fb) in [(false, false), (false, true), (true, false), (true, true)] {
                        let (ea, eb) = (part.cut(&[facing(a, fa)]), part.cut(&[facing(b, fb)]));
                        if ia == ib || ea.is_empty() || eb.is_empty() {
                            continue;
                        }
                        let occl = occlusion_planes(a, b);
                        let edge = !ea.cut(&occl).intersect(&eb).is_empty();
                        let ca = (a[0] + a[1] + a[2]) / 3.0;
                        let cb = (b[0] + b[1] + b[2]) / 3.0;
                        if has_witness(ca, cb, &occl, &ea, &eb) {
                            witnessed += 1;
                            assert!(edge, "pair {ia} -> {ib} witnessed without an edge");
                        }
                        edges += usize::from(edge);
                    }
                }
            }
        }
        assert!(edges > 1000, "{edges} edges");
        assert!(
            witnessed * 2 > edges,
            "{witnessed} of {edges} edges witnessed"
        );
    }

    #[test]
    fn a_sample_of_rows_has_the_full_graphs_edges_of_those_rows() {
        // The estimate's rows (every third node) against the whole graph: the same edges
        // leave each sampled node, in the same order.
        let mut seed = 0x1234_5678_9abc_def1u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let tris: Arc<[[DVec3; 3]]> = (0..24)
            .map(|_| {
                let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
                [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * 0.1)
            })
            .collect();
        let dirs = directions(6).unwrap();
        let part = partition_region(&dirs, 0);
        let full = Graph::build(tris.clone(), &part, &|_, _| {});
        let mut sample = Graph::nodes_of(tris, &part);
        let rows: Vec<usize> = (0..sample.nodes.len()).step_by(3).collect();
        let stats = sample.add_rows(rows.iter().copied(), &|_, _| {});
        let pairs = |g: &Graph| -> Vec<(usize, usize)> {
            g.edges
                .iter()
                .filter(|e| rows.contains(&e.from))
                .map(|e| (e.from, e.to))
                .collect()
        };
        assert!(pairs(&full).len() > 10, "{} edges", pairs(&full).len());
        assert_eq!(pairs(&sample), pairs(&full));
        assert_eq!(sample.edges.len() as u64, stats.witnessed + stats.clipped);
    }

    #[test]
    fn two_stacked_triangles_have_the_expected_edges() {
        let g = stacked_pair();
        // From above both front copies are rendered; the back copies never are.
        assert_eq!(g.nodes.len(), 2);
        assert!(g.nodes.iter().all(|n| !n.back));
        // a (tri 0) occludes b (tri 1), never the reverse.
        assert_eq!(g.edge_count(), 1);
        let e = g.edges.iter().find(|e| e.alive).unwrap();
        assert_eq!((g.nodes[e.from].tri, g.nodes[e.to].tri), (0, 1));
    }
}
