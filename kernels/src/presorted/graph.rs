//! The occlusion graph of one partition (sections 3.1 and 4.1.1): a node per triangle
//! instance (front copy, back-facing duplicate, and the copies the scan makes), each with
//! its rendering region `E`; an edge `i -> j` iff some viewpoint of the partition sees `i`
//! occlude `j` with both rendered, i.e. iff the reduced occlusion region
//! `O_{i->j} ∩ E_i ∩ E_j` (eq. 1) has an interior.

use std::collections::HashMap;
use std::sync::Arc;

use glam::DVec3;

use super::geom::{occlusion_planes, Plane, Region, EPS};
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

/// One occlusion edge: `from` occludes `to` from the viewpoints of `region`.
#[derive(Clone, Debug)]
pub struct Edge {
    pub from: usize,
    pub to: usize,
    /// The unreduced occlusion region's half-spaces (shared by the copies of an edge).
    pub occl: Arc<[Plane]>,
    /// The reduced occlusion region's vertices (eq. 1).
    pub verts: Vec<DVec3>,
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

impl Graph {
    /// Nodes (front and back copy of every triangle whose copy can be rendered from the
    /// partition) and every edge. `tick(done, total)` reports progress over the nodes.
    pub fn build(tris: Arc<[[DVec3; 3]]>, partition: &Region, tick: &dyn Fn(u64, u64)) -> Graph {
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
        let n = g.nodes.len();
        let planes: Vec<Plane> = g
            .nodes
            .iter()
            .map(|x| facing(&tris[x.tri as usize], x.back))
            .collect();
        let mut occl_cache: HashMap<(u32, u32), Arc<[Plane]>> = HashMap::new();
        for i in 0..n {
            if i % 64 == 0 {
                tick(i as u64, n as u64);
            }
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
                if !may_occlude(a, b, &g.nodes[i].region, &g.nodes[j].region) {
                    continue;
                }
                let occl = occl_cache
                    .entry((ti, tj))
                    .or_insert_with(|| occlusion_planes(a, b).into())
                    .clone();
                g.try_edge(i, j, occl);
            }
            // Occlusion planes of pairs with node i's triangle are no longer needed once
            // both of its copies are done.
            if g.nodes[i].back || g.nodes.get(i + 1).is_none_or(|x| x.tri != ti) {
                occl_cache.retain(|k, _| k.0 != ti);
            }
        }
        tick(n as u64, n as u64);
        g
    }

    pub fn add_node(&mut self, node: Node) -> usize {
        self.nodes.push(node);
        self.out.push(Vec::new());
        self.inn.push(Vec::new());
        self.nodes.len() - 1
    }

    /// Adds `from -> to` if its reduced occlusion region has an interior.
    pub fn try_edge(&mut self, from: usize, to: usize, occl: Arc<[Plane]>) -> bool {
        let (ef, et) = (&self.nodes[from].region, &self.nodes[to].region);
        if ef.outside_any(&occl) || et.outside_any(&occl) {
            return false;
        }
        let reduced = self.nodes[from]
            .region
            .cut(&occl)
            .intersect(&self.nodes[to].region);
        if reduced.is_empty() {
            return false;
        }
        let id = self.edges.len();
        self.edges.push(Edge {
            from,
            to,
            occl,
            verts: reduced.verts,
            alive: true,
        });
        self.out[from].push(id);
        self.inn[to].push(id);
        true
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

    /// The reduced occlusion region of edge `e` (eq. 1) as the separating-axis test sees it
    /// (recomputed: edges keep only its vertices).
    pub fn edge_shape(&self, e: usize) -> Shape {
        let ed = &self.edges[e];
        let r = self.nodes[ed.from]
            .region
            .cut(&ed.occl)
            .intersect(&self.nodes[ed.to].region);
        Shape {
            normals: r.normals(),
            edges: r.edge_dirs(),
            verts: ed.verts.clone(),
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
            let (to, occl) = (self.edges[e].to, self.edges[e].occl.clone());
            if keep_alive {
                self.try_edge(x, to, occl.clone());
            }
            if let Some(n) = new {
                self.try_edge(n, to, occl);
            }
        }
        for e in ins {
            if !self.edges[e].alive {
                continue;
            }
            self.edges[e].alive = false;
            let (from, occl) = (self.edges[e].from, self.edges[e].occl.clone());
            if keep_alive {
                self.try_edge(from, x, occl.clone());
            }
            if let Some(n) = new {
                self.try_edge(from, n, occl);
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
