//! Deciding a pair of nodes without clipping (section 4.1.1's reduced occlusion region,
//! eq. 1, is the exact test; [`super::Graph::occludes`] clips it): conservative rejections
//! that prove the region empty, and witness viewpoints that prove it has an interior.
//! Neither changes an answer: a pair neither rejects nor proves is clipped.

use glam::DVec3;

use super::super::geom::{verts_outside, Plane, Region, EPS, MIN_WIDTH};

/// A necessary condition for `a` to occlude `b` from a viewpoint of both regions, cheaper
/// than the occlusion region: when every direction `a_k - b_l` has a positive component
/// along `u` (from `b`'s centroid to `a`'s), `O_{a->b} = a + cone(a - b)` lies in the
/// half-space `u.x >= min_k u.a_k`, which both regions must reach into.
pub(super) fn may_occlude(a: &[DVec3; 3], b: &[DVec3; 3], ra: &[DVec3], rb: &[DVec3]) -> bool {
    let u = (a[0] + a[1] + a[2] - b[0] - b[1] - b[2]) / 3.0;
    if a.iter().any(|p| b.iter().any(|q| (*p - *q).dot(u) <= 0.0)) {
        return true;
    }
    let Some(h) = Plane::through(u, DVec3::ZERO) else {
        return true;
    };
    let lo = a.iter().map(|p| h.eval(*p)).fold(f64::INFINITY, f64::min);
    let bound = Plane {
        n: h.n,
        d: h.d - lo,
    };
    !(verts_outside(ra, &bound) || verts_outside(rb, &bound))
}

/// A sphere holding a triangle: its centroid and the distance to its farthest vertex.
pub(super) fn bounding_sphere(t: &[DVec3; 3]) -> (DVec3, f64) {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    let r = t.iter().map(|p| (*p - c).length()).fold(0.0, f64::max);
    (c, r * (1.0 + 1e-9) + EPS)
}

/// Whether a region (its vertices `region`) lies wholly outside a convex set holding `O_{a->b}` (a conservative
/// rejection, cheaper than the occlusion region): with `a` in the ball `(ca, ra)` and `b` in
/// `(cb, rb)` (disjoint), `O_{a->b} = a + cone(a - b)` lies in the ball of `a` plus the
/// circular cone of axis `w = (ca - cb)/|ca - cb|` and half-angle `asin((ra + rb)/|ca - cb|)`.
/// Every direction `n` within the dual cone (at most `90° - α` from `w`) has `n . d >= 0`
/// along that cone, so `O` lies in `n . (x - ca) >= -ra`; the test tries `w` itself and the
/// direction of the dual cone nearest to the region's centre as seen from `ca`.
pub(super) fn cone_misses(
    sa: (DVec3, f64),
    sb: (DVec3, f64),
    region: &[DVec3],
    centre: DVec3,
) -> bool {
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
    [w, toward]
        .iter()
        .any(|n| *n != DVec3::ZERO && region.iter().all(|v| n.dot(*v - ca) < -ra - MIN_WIDTH))
}

/// The mean of a region's vertices (the point [`cone_misses`] aims at).
pub(super) fn centre(region: &Region) -> DVec3 {
    region.verts.iter().copied().sum::<DVec3>() / region.verts.len() as f64
}

/// How far inside every half-space a witness viewpoint must lie ([`Witness`]): a
/// thousand times the tolerances of the clips ([`EPS`]) and ten times [`MIN_WIDTH`].
pub(super) const WITNESS_MARGIN: f64 = 1e-6;

/// Distances from `a`'s centroid, along the centroids' direction, at which [`Witness`]
/// looks for a witness (inside the viewpoint box, `FAR` = 64, from a centroid in the unit
/// ball).
pub(super) const WITNESS_REACH: [f64; 3] = [40.0, 12.0, 4.0];

/// Whether the reduced occlusion region `O_{a->b} ∩ E_from ∩ E_to` provably has an interior,
/// without clipping: a viewpoint `v` at least [`WITNESS_MARGIN`] inside every half-space of
/// `occl` (the facets of `O_{a->b}`) and of both rendering regions (each region is the
/// intersection of its faces' half-spaces) is the centre of a ball of that radius inside
/// the exact region. [`super::Graph::try_edge`]'s clips only ever drop what lies beyond a plane
/// by more than [`EPS`] (`1e-9`, rounding of the clipped vertices about `1e-13` in the
/// viewpoint box), so every region they produce on the way holds that ball too: no clip
/// finds every vertex within [`MIN_WIDTH`] of the outside (the ball reaches `2e-6` past
/// the plane), and the result spans more than `MIN_WIDTH` in every direction; the clip
/// would therefore have found the edge. Candidates: `c_a + s (c_a - c_b)/|c_a - c_b|` (in
/// `O_{a->b}` by its definition, `a + cone(a - b)`) for the distances of
/// [`WITNESS_REACH`]; when none is a witness, the clip decides. (The graph asks
/// [`Witness`] directly, which tries [`Witness::proven_by_cone`] before the facets; this
/// whole test is the tests' reference.)
#[cfg(test)]
pub(super) fn has_witness(
    ca: DVec3,
    cb: DVec3,
    occl: &[Plane],
    from: &Region,
    to: &Region,
) -> bool {
    Witness::new(ca, cb, from, to).is_some_and(|w| w.proven_by_planes(occl))
}

/// Whether `v` lies at least [`WITNESS_MARGIN`] inside every half-space of `planes`.
fn inside(v: DVec3, planes: &[Plane]) -> bool {
    planes.iter().all(|p| p.eval(v) >= WITNESS_MARGIN)
}

/// The candidate witness viewpoints of a pair that lie [`WITNESS_MARGIN`] inside both
/// rendering regions (the argument is `has_witness`'s): what remains to prove is that one of
/// them lies as deep inside the occlusion region `O_{a->b}`, which
/// [`Witness::proven_by_cone`] does from the triangles alone and
/// [`Witness::proven_by_planes`] from the region's facets (computing those costs more than
/// the rest of a pair's cheap tests together).
pub(super) struct Witness {
    points: [DVec3; 3],
    in_regions: [bool; 3],
    /// `|c_a - c_b|`.
    dist: f64,
}

impl Witness {
    /// The candidates for triangles of centroids `ca` and `cb` and rendering regions `from`
    /// and `to`; `None` when no candidate lies inside both regions (then no candidate is a
    /// witness).
    pub(super) fn new(ca: DVec3, cb: DVec3, from: &Region, to: &Region) -> Option<Witness> {
        let d = ca - cb;
        let w = d.normalize_or_zero();
        if w == DVec3::ZERO {
            return None;
        }
        let points = WITNESS_REACH.map(|s| ca + w * s);
        let in_regions = points.map(|v| inside(v, &from.planes) && inside(v, &to.planes));
        in_regions.contains(&true).then_some(Witness {
            points,
            in_regions,
            dist: d.length(),
        })
    }

    /// Whether a candidate inside both regions lies [`WITNESS_MARGIN`] inside the facets
    /// `occl` of the occlusion region.
    pub(super) fn proven_by_planes(&self, occl: &[Plane]) -> bool {
        (0..3).any(|k| self.in_regions[k] && inside(self.points[k], occl))
    }

    /// Whether a candidate inside both regions provably lies [`WITNESS_MARGIN`] inside
    /// `O_{a->b} = a + cone(a - b)` without its facets. With `r_kl = a_k - b_l`, the
    /// candidate at distance `s` is `c_a + (s / 9l) Σ r_kl` (`l = |c_a - c_b|`, and
    /// `c_a - c_b` is the mean of the nine `r_kl`). For three independent directions `M =
    /// [r_0 r_1 r_2]` among them, an offset `δ` is `M x` with `x_i = (r_j × r_k) . δ / det M`
    /// (cyclic `i, j, k`), so `|x_i| <= |r_j × r_k| |δ| / |det M|`; when `s / 9l` is at
    /// least that for `|δ| = ` [`WITNESS_MARGIN`], every coefficient of `c_a + δ + ...`
    /// stays non-negative and the whole ball lies in `O`. The bound is doubled against
    /// rounding; the triples tried are `(a_k - b_(k+t) mod 3)` for `t = 0, 1, 2`. A pair
    /// this does not prove goes on to [`Witness::proven_by_planes`], so the answer never
    /// depends on it.
    pub(super) fn proven_by_cone(&self, a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
        let mut worst = f64::INFINITY;
        for t in 0..3 {
            let r = [0, 1, 2].map(|k| a[k] - b[(k + t) % 3]);
            let c = [r[1].cross(r[2]), r[2].cross(r[0]), r[0].cross(r[1])];
            let det = r[0].dot(c[0]).abs();
            let most = c.iter().map(|x| x.length()).fold(0.0, f64::max);
            if det > 0.0 && (most / det).is_finite() {
                worst = worst.min(most / det);
            }
        }
        let reach = 2.0 * 9.0 * self.dist * WITNESS_MARGIN * worst;
        (0..3).any(|k| self.in_regions[k] && WITNESS_REACH[k] >= reach)
    }
}
