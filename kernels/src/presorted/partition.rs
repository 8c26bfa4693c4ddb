//! Viewpoint-space partitions (section 4.2): the mesh is enclosed in a bounding polyhedron
//! of 4, 6, 16 or 64 faces; partition `k` is the set of viewpoints outside it that lie
//! farther beyond face `k`'s plane than beyond any other face's.
//!
//! The faces are tangent planes of the mesh's bounding sphere: the regular tetrahedron's
//! and the cube's face normals for 4 and 6, a Fibonacci sphere of directions for 16 and 64.
//! Partition `k` is then the convex region `u_k . v >= 1` and `(u_k - u_j) . v >= 0` for
//! every `j` (in the normalized frame where the bounding sphere is the unit sphere). It is
//! cut at the viewpoint box `|v|_inf <= FAR`: farther viewpoints are refused at run time
//! (an orthographic-like view from far away is the only thing lost).

use glam::{DVec3, Vec3};

use super::geom::{Plane, Region};

/// Half-width of the viewpoint box, in bounding-sphere radii.
pub const FAR: f64 = 64.0;

/// The face counts the paper experiments with.
pub const FACE_COUNTS: [u32; 4] = [4, 6, 16, 64];

/// The normalized frame: `v_n = (v - center) / radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame3 {
    pub center: DVec3,
    pub radius: f64,
}

impl Frame3 {
    /// The bounding sphere (box centre, farthest point) of `positions`, slightly enlarged
    /// so that no vertex lies on the polyhedron.
    pub fn of(positions: &[Vec3]) -> Frame3 {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in positions {
            lo = lo.min(p.as_dvec3());
            hi = hi.max(p.as_dvec3());
        }
        let center = (lo + hi) * 0.5;
        let r = positions
            .iter()
            .map(|p| (p.as_dvec3() - center).length())
            .fold(0.0f64, f64::max);
        Frame3 {
            center,
            radius: (r * 1.001).max(1e-12),
        }
    }
    pub fn to_local(&self, v: DVec3) -> DVec3 {
        (v - self.center) / self.radius
    }
    pub fn to_world(&self, v: DVec3) -> DVec3 {
        v * self.radius + self.center
    }
    /// A plane of the normalized frame as a plane of world space, `[n, e]` with
    /// `n . v - e` of the sign of the normalized plane's value (the run-time test
    /// `dot(p, [v, -1]) > 0`).
    pub fn world_plane(&self, p: &Plane) -> [f64; 4] {
        // n.(v - c)/s + d >= 0  <=>  n.v - (n.c - d s) >= 0
        let e = p.n.dot(self.center) - p.d * self.radius;
        [p.n.x, p.n.y, p.n.z, e]
    }
}

/// Face normals of the bounding polyhedron with `faces` faces.
pub fn directions(faces: u32) -> Result<Vec<DVec3>, String> {
    match faces {
        4 => Ok([
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(-1.0, -1.0, 1.0),
        ]
        .map(|d| d.normalize())
        .to_vec()),
        6 => Ok(vec![
            DVec3::X,
            -DVec3::X,
            DVec3::Y,
            -DVec3::Y,
            DVec3::Z,
            -DVec3::Z,
        ]),
        16 | 64 => {
            let n = faces as usize;
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            Ok((0..n)
                .map(|i| {
                    let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                    let r = (1.0 - y * y).sqrt();
                    let th = golden * i as f64;
                    DVec3::new(r * th.cos(), y, r * th.sin())
                })
                .collect())
        }
        other => Err(format!(
            "--partitions {other}: the bounding polyhedron has 4, 6, 16 or 64 faces"
        )),
    }
}

/// The viewpoint box `|v|_inf <= FAR`.
pub fn far_box() -> Vec<Plane> {
    let mut v = Vec::new();
    for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
        v.push(Plane { n: -axis, d: FAR });
        v.push(Plane { n: axis, d: FAR });
    }
    v
}

/// Partition `k` of the directions `dirs`, as a region of the normalized frame.
pub fn partition_region(dirs: &[DVec3], k: usize) -> Region {
    let mut planes = far_box();
    planes.push(Plane {
        n: dirs[k],
        d: -1.0,
    });
    for (j, u) in dirs.iter().enumerate() {
        if j != k {
            if let Some(p) = Plane::through(dirs[k] - *u, DVec3::ZERO) {
                planes.push(p);
            }
        }
    }
    Region::from_planes(&planes)
}

/// Why a viewpoint has no partition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewpointError {
    #[error(
        "viewpoint {v:?} is inside the bounding polyhedron of the presorted lists (only \
         viewpoints outside it, at least {reach:.4} from the mesh's centre along the nearest \
         face normal, are sorted); move the camera out"
    )]
    Inside { v: [f64; 3], reach: f64 },
    #[error(
        "viewpoint {v:?} is farther than {far} bounding-sphere radii ({limit:.4}) from the \
         mesh's centre along an axis: outside the viewpoint box of the presorted lists"
    )]
    TooFar { v: [f64; 3], far: f64, limit: f64 },
}

/// The partition of a world-space viewpoint (the CPU's coarse selection of section 4.2).
pub fn locate(frame: &Frame3, dirs: &[DVec3], v: DVec3) -> Result<usize, ViewpointError> {
    let l = frame.to_local(v);
    if l.abs().max_element() > FAR {
        return Err(ViewpointError::TooFar {
            v: v.to_array(),
            far: FAR,
            limit: FAR * frame.radius,
        });
    }
    let (k, best) = dirs
        .iter()
        .enumerate()
        .map(|(k, u)| (k, u.dot(l)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NEG_INFINITY));
    if best <= 1.0 {
        return Err(ViewpointError::Inside {
            v: v.to_array(),
            reach: frame.radius,
        });
    }
    Ok(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partitions_are_nonempty_and_cover_their_face() {
        for faces in FACE_COUNTS {
            let dirs = directions(faces).unwrap();
            assert_eq!(dirs.len(), faces as usize);
            for k in 0..dirs.len() {
                let r = partition_region(&dirs, k);
                assert!(!r.is_empty(), "{faces} faces, partition {k}");
                let probe = dirs[k] * 3.0;
                assert!(r.planes.iter().all(|p| p.eval(probe) >= 0.0));
                let frame = Frame3 {
                    center: DVec3::ZERO,
                    radius: 1.0,
                };
                assert_eq!(locate(&frame, &dirs, probe), Ok(k));
            }
        }
        assert!(directions(5).is_err());
    }

    #[test]
    fn inside_and_far_viewpoints_are_refused() {
        let dirs = directions(6).unwrap();
        let frame = Frame3 {
            center: DVec3::ZERO,
            radius: 1.0,
        };
        assert!(matches!(
            locate(&frame, &dirs, DVec3::new(0.5, 0.2, 0.1)),
            Err(ViewpointError::Inside { .. })
        ));
        assert!(matches!(
            locate(&frame, &dirs, DVec3::new(100.0, 0.0, 0.0)),
            Err(ViewpointError::TooFar { .. })
        ));
    }
}
