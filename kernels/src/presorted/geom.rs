//! Convex regions of viewpoint space ("Depth-Presorted Triangle Lists", section 4.1.2):
//! closed half-spaces, convex polyhedra kept both as half-spaces and as vertices, and the
//! occlusion region of a pair of triangles.
//!
//! All of preprocessing works in a normalized frame (the mesh's bounding sphere is the unit
//! sphere, see [`super::partition`]) and every region is bounded by the viewpoint box, so
//! one absolute tolerance, [`EPS`], serves every test.

use glam::DVec3;
use smallvec::SmallVec;

/// Distance below which a point counts as on a plane, in the normalized frame.
pub const EPS: f64 = 1e-9;
/// Smallest width a region must have in every direction to count as having an interior
/// (smaller regions are slivers of touching boundaries, viewpoints of measure zero).
pub const MIN_WIDTH: f64 = 1e-7;

/// The closed half-space `n . v + d >= 0` (`n` of unit length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub n: DVec3,
    pub d: f64,
}

impl Plane {
    /// The half-space on the side `n` points to, through `p`; `None` when `n` is too short
    /// to give a direction.
    pub fn through(n: DVec3, p: DVec3) -> Option<Plane> {
        let len = n.length();
        if len.is_nan() || len <= 1e-12 {
            return None;
        }
        let n = n / len;
        Some(Plane { n, d: -n.dot(p) })
    }
    /// Signed distance of `v` (positive inside).
    pub fn eval(&self, v: DVec3) -> f64 {
        self.n.dot(v) + self.d
    }
    /// The complementary half-space.
    pub fn flip(&self) -> Plane {
        Plane {
            n: -self.n,
            d: -self.d,
        }
    }
    fn same(&self, o: &Plane) -> bool {
        (self.n - o.n).length_squared() < 1e-18 && (self.d - o.d).abs() < EPS
    }
}

/// A bounded convex polyhedron as a boundary representation: its faces (each a half-space
/// and the loop of its vertices, in order) and its vertices. Empty when it has no interior
/// ([`MIN_WIDTH`]).
///
/// Intersections with half-spaces clip the faces (Sutherland-Hodgman) and close the cut
/// with a new face: O(vertices) per half-space, where enumerating the vertices of an
/// intersection of `m` half-spaces from plane triples costs O(m^4).
#[derive(Clone, Debug, Default)]
pub struct Region {
    /// The half-spaces of the faces (`planes[k]` bounds face `k`).
    pub planes: Vec<Plane>,
    /// Each face's vertices, in order around it, one face after another: face `k` is
    /// `rings[ends[k - 1]..ends[k]]` (one allocation for every face: a graph clips
    /// regions billions of times).
    rings: Vec<DVec3>,
    /// Where each face's vertices end in `rings`.
    ends: Vec<u32>,
    /// The vertices (each once).
    pub verts: Vec<DVec3>,
}

/// Points closer than this are one vertex.
const MERGE: f64 = 1e-9;

impl Region {
    /// The cube `|v|_inf <= half`.
    pub fn cube(half: f64) -> Region {
        let c = |i: usize| {
            DVec3::new(
                if i & 1 == 0 { -half } else { half },
                if i & 2 == 0 { -half } else { half },
                if i & 4 == 0 { -half } else { half },
            )
        };
        // Faces with their corners in order (any orientation: only the order matters).
        let faces: [(DVec3, [usize; 4]); 6] = [
            (DVec3::X, [0, 2, 6, 4]),
            (-DVec3::X, [1, 3, 7, 5]),
            (DVec3::Y, [0, 1, 5, 4]),
            (-DVec3::Y, [2, 3, 7, 6]),
            (DVec3::Z, [0, 1, 3, 2]),
            (-DVec3::Z, [4, 5, 7, 6]),
        ];
        Region {
            planes: faces
                .iter()
                .map(|(n, _)| Plane { n: *n, d: half })
                .collect(),
            rings: faces.iter().flat_map(|(_, l)| l.map(c)).collect(),
            ends: (1..=6).map(|k| 4 * k).collect(),
            verts: (0..8).map(c).collect(),
        }
    }

    /// The intersection of `planes`, which must bound it (callers include the viewpoint
    /// box): a large cube clipped by each.
    pub fn from_planes(planes: &[Plane]) -> Region {
        let mut r = Region::cube(1e4);
        for p in planes {
            r = r.clip(p);
            if r.is_empty() {
                break;
            }
        }
        r
    }

    /// Bytes the region holds on the heap (its planes, face loops and vertices).
    pub fn heap_bytes(&self) -> usize {
        self.planes.capacity() * std::mem::size_of::<Plane>()
            + self.rings.capacity() * std::mem::size_of::<DVec3>()
            + self.ends.capacity() * std::mem::size_of::<u32>()
            + self.verts.capacity() * std::mem::size_of::<DVec3>()
    }

    /// Bytes the region takes from the allocator: [`Region::heap_bytes`] and, per heap
    /// block, the allocator's own bookkeeping (16 bytes, glibc's on 64-bit).
    pub fn footprint(&self) -> usize {
        let blocks = [
            self.planes.capacity(),
            self.rings.capacity(),
            self.ends.capacity(),
            self.verts.capacity(),
        ]
        .into_iter()
        .filter(|&c| c > 0)
        .count();
        self.heap_bytes() + 16 * blocks
    }

    /// Each face's half-space and its vertices in order around it.
    fn faces(&self) -> impl Iterator<Item = (&Plane, &[DVec3])> + '_ {
        self.planes
            .iter()
            .zip(&self.ends)
            .scan(0, |start, (pl, &end)| {
                let face = &self.rings[*start..end as usize];
                *start = end as usize;
                Some((pl, face))
            })
    }

    /// Whether the region has an interior.
    pub fn is_empty(&self) -> bool {
        self.verts.is_empty()
    }

    /// The intersection with one half-space.
    fn clip(&self, h: &Plane) -> Region {
        if self.is_empty() {
            return Region::default();
        }
        let (lo, hi) = self.range(h);
        // The paper's cheap outs: a half-space holding every vertex changes nothing; one
        // holding none (beyond the width of a sliver) empties the region.
        if lo >= -EPS {
            return self.clone();
        }
        if hi < MIN_WIDTH {
            return Region::default();
        }
        let mut planes = Vec::with_capacity(self.planes.len() + 1);
        let mut rings: Vec<DVec3> = Vec::with_capacity(self.rings.len() + 2 * self.planes.len());
        let mut ends: Vec<u32> = Vec::with_capacity(self.planes.len() + 1);
        let mut cap: SmallVec<[DVec3; 16]> = SmallVec::new();
        let mut d: SmallVec<[f64; 16]> = SmallVec::new();
        for (pl, lp) in self.faces() {
            d.clear();
            d.extend(lp.iter().map(|v| h.eval(*v)));
            if d.iter().all(|x| x.abs() <= EPS) {
                // On the cutting plane: the cap replaces it.
                continue;
            }
            // The clipped face, at the end of `rings`.
            let start = rings.len();
            for i in 0..lp.len() {
                let j = (i + 1) % lp.len();
                let (a, b) = (lp[i], lp[j]);
                let (da, db) = (d[i], d[j]);
                if da >= -EPS {
                    rings.push(a);
                    if da <= EPS {
                        cap.push(a);
                    }
                }
                if (da > EPS && db < -EPS) || (da < -EPS && db > EPS) {
                    let x = a + (b - a) * (da / (da - db));
                    rings.push(x);
                    cap.push(x);
                }
            }
            dedup_loop(&mut rings, start);
            if rings.len() - start >= 3 {
                planes.push(*pl);
                ends.push(rings.len() as u32);
            } else {
                rings.truncate(start);
            }
        }
        dedup_small(&mut cap);
        if cap.len() >= 3 {
            // Order the cap's points around their centroid, in h's plane (by pseudo-angle,
            // monotonic in the angle).
            let c = cap.iter().copied().sum::<DVec3>() / cap.len() as f64;
            let u = h.n.any_orthonormal_vector();
            let w = h.n.cross(u);
            let key = |p: &DVec3| {
                let (x, y) = ((*p - c).dot(u), (*p - c).dot(w));
                let t = y / (x.abs() + y.abs()).max(f64::MIN_POSITIVE);
                if x < 0.0 {
                    2.0 - t
                } else if y < 0.0 {
                    4.0 + t
                } else {
                    t
                }
            };
            cap.sort_by(|a, b| key(a).total_cmp(&key(b)));
        }
        // The vertices: those kept (on the inner side or on the plane) and the new ones of
        // the cap.
        let mut verts: Vec<DVec3> = Vec::with_capacity(self.verts.len() + cap.len());
        verts.extend(self.verts.iter().filter(|v| h.eval(**v) >= -EPS));
        let kept = verts.len();
        for p in &cap {
            let old = verts[..kept]
                .iter()
                .any(|v| (*v - *p).length_squared() < MERGE * MERGE);
            if !old {
                verts.push(*p);
            }
        }
        if cap.len() >= 3 {
            planes.push(*h);
            rings.extend_from_slice(&cap);
            ends.push(rings.len() as u32);
        }
        if !spans_volume(&verts) {
            return Region::default();
        }
        Region {
            planes,
            rings,
            ends,
            verts,
        }
    }

    /// The intersection with more half-spaces.
    pub fn cut(&self, extra: &[Plane]) -> Region {
        let mut r: Option<Region> = None;
        for p in extra {
            let cur = r.as_ref().unwrap_or(self);
            if cur.is_empty() {
                return Region::default();
            }
            let (lo, hi) = cur.range(p);
            if lo >= -EPS {
                continue;
            }
            if hi < MIN_WIDTH {
                return Region::default();
            }
            r = Some(cur.clip(p));
        }
        r.unwrap_or_else(|| self.clone())
    }

    /// Whether the region lies entirely outside one of `planes` (beyond the width of a
    /// sliver): the paper's test before an intersection, "all vertices on the outside of
    /// one of the planes".
    pub fn outside_any(&self, planes: &[Plane]) -> bool {
        self.is_empty() || planes.iter().any(|p| verts_outside(&self.verts, p))
    }

    /// The smallest and largest value of `p` over the vertices.
    fn range(&self, p: &Plane) -> (f64, f64) {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for v in &self.verts {
            let d = p.eval(*v);
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (lo, hi)
    }

    /// The faces' unit normals.
    pub fn normals(&self) -> Vec<DVec3> {
        self.planes.iter().map(|p| p.n).collect()
    }

    /// The edges' unit directions, each once (an edge bounds two faces; parallel edges are
    /// one direction).
    pub fn edge_dirs(&self) -> Vec<DVec3> {
        let mut out: Vec<DVec3> = Vec::new();
        for (_, l) in self.faces() {
            for i in 0..l.len() {
                let d = (l[(i + 1) % l.len()] - l[i]).normalize_or_zero();
                if d != DVec3::ZERO && !out.iter().any(|e| e.cross(d).length_squared() < 1e-20) {
                    out.push(d);
                }
            }
        }
        out
    }

    /// The intersection with another region.
    pub fn intersect(&self, o: &Region) -> Region {
        if self.is_empty() || o.is_empty() {
            return Region::default();
        }
        self.cut(&o.planes)
    }
}

/// Whether a region, given by its vertices `verts`, lies wholly outside `p` (beyond the
/// width of a sliver; no vertices: outside): [`Region::outside_any`] with one plane, for
/// callers that hold the vertices apart from their region (the graph's rows read every
/// node's from one array).
pub fn verts_outside(verts: &[DVec3], p: &Plane) -> bool {
    let hi = verts
        .iter()
        .map(|v| p.eval(*v))
        .fold(f64::NEG_INFINITY, f64::max);
    hi < MIN_WIDTH
}

/// Removes consecutive (cyclically) points closer than [`MERGE`] from the loop that
/// makes up `ring[start..]`.
fn dedup_loop(ring: &mut Vec<DVec3>, start: usize) {
    let close = |a: DVec3, b: DVec3| (a - b).length_squared() < MERGE * MERGE;
    // (Vec::dedup_by on the loop's part: each point against the last one kept.)
    let mut kept = start;
    for k in start..ring.len() {
        if k == start || !close(ring[k], ring[kept - 1]) {
            ring[kept] = ring[k];
            kept += 1;
        }
    }
    ring.truncate(kept);
    while ring.len() - start > 1 && close(ring[start], ring[ring.len() - 1]) {
        ring.pop();
    }
}

/// Removes points closer than [`MERGE`] to an earlier one (few points: quadratic).
fn dedup_small(v: &mut SmallVec<[DVec3; 16]>) {
    let mut kept = 0;
    for k in 0..v.len() {
        let p = v[k];
        if !v[..kept]
            .iter()
            .any(|q| (p - *q).length_squared() < MERGE * MERGE)
        {
            v[kept] = p;
            kept += 1;
        }
    }
    v.truncate(kept);
}

/// Whether points span a solid at least [`MIN_WIDTH`] thick.
fn spans_volume(pts: &[DVec3]) -> bool {
    if pts.len() < 4 {
        return false;
    }
    let p0 = pts[0];
    let Some(p1) = farthest(pts, |p| (p - p0).length()) else {
        return false;
    };
    let axis = (p1 - p0).normalize_or_zero();
    if (p1 - p0).length() < MIN_WIDTH {
        return false;
    }
    let off_line = |p: DVec3| {
        let w = p - p0;
        (w - axis * w.dot(axis)).length()
    };
    let Some(p2) = farthest(pts, off_line) else {
        return false;
    };
    if off_line(p2) < MIN_WIDTH {
        return false;
    }
    let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
    pts.iter().any(|p| (*p - p0).dot(n).abs() >= MIN_WIDTH)
}

fn farthest(pts: &[DVec3], f: impl Fn(DVec3) -> f64) -> Option<DVec3> {
    pts.iter().copied().max_by(|a, b| f(*a).total_cmp(&f(*b)))
}

/// Facets an occlusion region keeps without touching the heap: its generators (three
/// points, nine directions) give at most about twenty, near-coincident planes apart.
pub const OCCL_INLINE: usize = 24;

/// The half-spaces of an occlusion region ([`occlusion_planes`]).
pub type OcclPlanes = SmallVec<[Plane; OCCL_INLINE]>;

/// The directions `p - q` (normalized) from every vertex `q` of `b` to every vertex `p` of
/// `a`, leaving out coincident vertices: the generators of the occlusion cone.
fn occlusion_rays(a: &[DVec3; 3], b: &[DVec3; 3]) -> SmallVec<[DVec3; 9]> {
    let mut rays: SmallVec<[DVec3; 9]> = SmallVec::new();
    for p in a {
        for q in b {
            let r = *p - *q;
            if r.length_squared() > 1e-24 {
                rays.push(r.normalize());
            }
        }
    }
    rays
}

/// The occlusion region `O_{a->b}`: the viewpoints from which triangle `a` hides part of
/// triangle `b` (section 4.1.1). A viewpoint `v` sees `a` in front of `b` iff
/// `v = p + s (p - q)` for some `p` in `a`, `q` in `b`, `s > 0`; that set is convex and its
/// closure is `a + cone(a - b)`: generated by the three vertices of `a` and the nine
/// directions `a_k - b_l`. Its facets are among the planes spanned by three points, two
/// points and a direction, or a point and two directions; those with every generator on
/// one side are kept. Unbounded: the caller intersects it with bounded regions.
///
/// Computed for every pair of triangles that passes the graph's cheap tests (billions on a
/// 48K-triangle mesh), so nothing here touches the heap unless a region has more than
/// [`OCCL_INLINE`] facets.
pub fn occlusion_planes(a: &[DVec3; 3], b: &[DVec3; 3]) -> OcclPlanes {
    let rays = occlusion_rays(a, b);
    let mut out = OcclPlanes::new();
    // A candidate half-space is kept iff every generator lies on one side of it: `lo` and
    // `hi` are the extreme values of the plane over the generators (0 included), and a
    // candidate with values beyond EPS on both sides is a facet of nothing.
    let keep = |out: &mut OcclPlanes, pl: Plane, lo: f64, hi: f64| {
        let k = if lo >= -EPS {
            pl
        } else if hi <= EPS {
            pl.flip()
        } else {
            return;
        };
        if !out.iter().any(|q| q.same(&k)) {
            out.push(k);
        }
    };
    // The extreme values of `pl` over the generators (`a`'s vertices when `pts`, and the
    // directions), or `None` when generators lie on both sides (most candidates). Straight
    // loops without an early exit: 12 dot products cost less than a test after each.
    let span = |pl: &Plane, pts: bool| -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (0.0f64, 0.0f64);
        if pts {
            for v in a {
                let s = pl.eval(*v);
                lo = lo.min(s);
                hi = hi.max(s);
            }
        }
        for r in &rays {
            let s = pl.n.dot(*r);
            lo = lo.min(s);
            hi = hi.max(s);
        }
        (lo >= -EPS || hi <= EPS).then_some((lo, hi))
    };
    let consider = |out: &mut OcclPlanes, n: DVec3, p: DVec3| {
        let Some(pl) = Plane::through(n, p) else {
            return;
        };
        if let Some((lo, hi)) = span(&pl, true) {
            keep(out, pl, lo, hi);
        }
    };
    consider(&mut out, (a[1] - a[0]).cross(a[2] - a[0]), a[0]);
    // Planes of two directions: their normal, and the directions' side of it, do not depend
    // on the vertex the plane goes through (computed once per pair of directions, not once
    // per vertex; the planes and their order are those of trying every vertex with every
    // pair).
    // (Only the pairs with every direction on one side: the others make no facet.)
    let mut pairs: SmallVec<[(DVec3, f64, f64); 36]> = SmallVec::new();
    for (i, r1) in rays.iter().enumerate() {
        for r2 in &rays[i + 1..] {
            if let Some(pl) = Plane::through(r1.cross(*r2), DVec3::ZERO) {
                if let Some((lo, hi)) = span(&pl, false) {
                    pairs.push((pl.n, lo, hi));
                }
            }
        }
    }
    for k in 0..3 {
        for l in k + 1..3 {
            for r in &rays {
                consider(&mut out, (a[l] - a[k]).cross(*r), a[k]);
            }
        }
        for (n, rlo, rhi) in &pairs {
            let pl = Plane {
                n: *n,
                d: -n.dot(a[k]),
            };
            let (mut lo, mut hi) = (*rlo, *rhi);
            for v in a {
                let s = pl.eval(*v);
                lo = lo.min(s);
                hi = hi.max(s);
            }
            if !(lo < -EPS && hi > EPS) {
                keep(&mut out, pl, lo, hi);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxed(half: f64) -> Vec<Plane> {
        let mut v = Vec::new();
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            v.push(Plane::through(-axis, axis * half).unwrap());
            v.push(Plane::through(axis, -axis * half).unwrap());
        }
        v
    }

    /// The occlusion region's planes the direct way: every candidate plane tested against
    /// every generator (the planes of two directions once per vertex).
    fn occlusion_planes_direct(a: &[DVec3; 3], b: &[DVec3; 3]) -> Vec<Plane> {
        let rays = occlusion_rays(a, b);
        let mut out: Vec<Plane> = Vec::new();
        let mut consider = |n: DVec3, p: DVec3| {
            let Some(pl) = Plane::through(n, p) else {
                return;
            };
            let vals = a.iter().map(|v| pl.eval(*v));
            let vals: Vec<f64> = vals.chain(rays.iter().map(|r| pl.n.dot(*r))).collect();
            let lo = vals.iter().copied().fold(0.0, f64::min);
            let hi = vals.iter().copied().fold(0.0, f64::max);
            let k = if lo >= -EPS {
                pl
            } else if hi <= EPS {
                pl.flip()
            } else {
                return;
            };
            if !out.iter().any(|q| q.same(&k)) {
                out.push(k);
            }
        };
        consider((a[1] - a[0]).cross(a[2] - a[0]), a[0]);
        for k in 0..3 {
            for l in k + 1..3 {
                for r in &rays {
                    consider((a[l] - a[k]).cross(*r), a[k]);
                }
            }
            for (i, r1) in rays.iter().enumerate() {
                for r2 in &rays[i + 1..] {
                    consider(r1.cross(*r2), a[k]);
                }
            }
        }
        out
    }

    #[test]
    fn occlusion_planes_match_the_direct_enumeration() {
        // Random triangles (a fixed LCG), some sharing a vertex or an edge: the same planes,
        // bit for bit, in the same order.
        let mut rnd = super::super::test_lcg();
        let mut planes = 0;
        for case in 0..600 {
            let mut p = || DVec3::new(rnd(), rnd(), rnd()) * 0.5;
            let a = [p(), p(), p()];
            let mut b = [p(), p(), p()];
            match case % 3 {
                1 => b[0] = a[1],
                2 => (b[0], b[1]) = (a[2], a[0]),
                _ => {}
            }
            let (got, want) = (occlusion_planes(&a, &b), occlusion_planes_direct(&a, &b));
            assert_eq!(got.as_slice(), want.as_slice(), "case {case}");
            planes += got.len();
        }
        assert!(planes > 600 * 2, "{planes} planes");
    }

    #[test]
    fn a_box_has_eight_vertices_and_six_faces() {
        let r = Region::from_planes(&boxed(2.0));
        assert_eq!(r.verts.len(), 8);
        assert_eq!(r.planes.len(), 6);
        let half = r.cut(&[Plane::through(DVec3::X, DVec3::ZERO).unwrap()]);
        assert_eq!(half.verts.len(), 8);
        assert!(half.verts.iter().all(|v| v.x >= -EPS));
        let flat = r.cut(&[
            Plane::through(DVec3::X, DVec3::ZERO).unwrap(),
            Plane::through(-DVec3::X, DVec3::ZERO).unwrap(),
        ]);
        assert!(flat.is_empty());
    }

    #[test]
    fn occlusion_region_of_two_stacked_triangles() {
        // a above b (z = 1 and z = 0): only viewpoints above a see a in front of b.
        let b = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let a = b.map(|p| p + DVec3::Z);
        let mut planes = occlusion_planes(&a, &b);
        planes.extend(boxed(10.0));
        let r = Region::from_planes(&planes);
        assert!(!r.is_empty());
        assert!(r.verts.iter().all(|v| v.z >= 1.0 - 1e-9));
        let inside = |v: DVec3| r.planes.iter().all(|p| p.eval(v) >= -EPS);
        assert!(inside(DVec3::new(0.2, 0.2, 5.0)));
        assert!(!inside(DVec3::new(0.2, 0.2, -5.0)));
        // From far to the side, the projections do not overlap.
        assert!(!inside(DVec3::new(9.0, 0.2, 1.5)));
        // And b never occludes a from above.
        let mut rev = occlusion_planes(&b, &a);
        rev.extend(boxed(10.0));
        rev.push(Plane::through(DVec3::Z, DVec3::new(0.0, 0.0, 1.0)).unwrap());
        assert!(Region::from_planes(&rev).is_empty());
    }

    #[test]
    fn side_by_side_triangles_never_occlude() {
        // Two triangles in one plane, sharing an edge: no viewpoint sees one over the other.
        let a = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let b = [
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let mut planes = occlusion_planes(&a, &b);
        planes.extend(boxed(10.0));
        assert!(Region::from_planes(&planes).is_empty());
    }
}
