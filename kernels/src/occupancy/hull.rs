//! Bounding volumes of a mesh for the range pass of occupancy culling ("Improving k-buffer
//! methods via occupancy maps", section 2: "a bounding box or a smaller representation as a
//! convex hull may be instead chosen to approximate the geometry"), built on the host.
//!
//! The convex hull comes from the `chull` crate (quickhull). Before it, the mesh's points
//! are thinned by the Akl-Toussaint heuristic: the hull of the extreme points along 13
//! directions is computed first, and points strictly inside it cannot be on the hull, so
//! only the others reach quickhull (on a dense scanned mesh most points are dropped).

use fragrace_emu::Mesh;
use glam::Vec3;

use crate::algo::AlgoError;

/// The mesh's axis-aligned bounding box as 12 triangles (none for an empty mesh).
pub fn bounding_box(mesh: &Mesh) -> Mesh {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for tri in &mesh.indices {
        for &i in tri {
            if let Some(p) = mesh.positions.get(i as usize) {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
    }
    if !(lo.cmple(hi).all()) {
        return Mesh {
            positions: Vec::new(),
            normals: None,
            indices: Vec::new(),
        };
    }
    let corner = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    // Two triangles per face; faces x-, x+, y-, y+, z-, z+.
    let faces = [
        [0, 2, 6, 4],
        [1, 5, 7, 3],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 1, 3, 2],
        [4, 6, 7, 5],
    ];
    let indices = faces
        .iter()
        .flat_map(|f| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]])
        .collect();
    Mesh {
        positions: (0..8).map(corner).collect(),
        normals: None,
        indices,
    }
}

/// The 13 directions of the Akl-Toussaint filter (axes, face diagonals, space diagonals).
fn directions() -> Vec<Vec3> {
    let mut v = Vec::new();
    for x in -1i32..=1 {
        for y in -1i32..=1 {
            for z in -1i32..=1 {
                let d = Vec3::new(x as f32, y as f32, z as f32);
                // One of each opposite pair.
                if d != Vec3::ZERO && (x, y, z) > (0, 0, 0) {
                    v.push(d);
                }
            }
        }
    }
    v
}

/// The points of the mesh that its triangles use (finite ones only).
fn used_points(mesh: &Mesh) -> Vec<Vec3> {
    let mut used = vec![false; mesh.positions.len()];
    for tri in &mesh.indices {
        for &i in tri {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
    }
    mesh.positions
        .iter()
        .zip(&used)
        .filter(|(p, &u)| u && p.is_finite())
        .map(|(p, _)| *p)
        .collect()
}

/// Quickhull of `points` as (vertices, triangles), or `None` when they are degenerate
/// (coplanar, collinear, fewer than 4).
fn quickhull(points: &[Vec3]) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
    let pts: Vec<Vec<f64>> = points
        .iter()
        .map(|p| vec![p.x as f64, p.y as f64, p.z as f64])
        .collect();
    let hull = chull::ConvexHull::try_new(&pts, 1e-9, None).ok()?;
    let (verts, idx) = hull.vertices_indices();
    let verts = verts
        .iter()
        .map(|v| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32))
        .collect();
    let tris = idx
        .chunks_exact(3)
        .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
        .collect();
    Some((verts, tris))
}

/// The points not strictly inside the hull of the extreme points (Akl-Toussaint).
fn thin(points: &[Vec3]) -> Vec<Vec3> {
    let mut extremes = Vec::new();
    for d in directions() {
        let by = |a: &&Vec3, b: &&Vec3| a.dot(d).total_cmp(&b.dot(d));
        if let (Some(lo), Some(hi)) = (points.iter().min_by(by), points.iter().max_by(by)) {
            extremes.push(*lo);
            extremes.push(*hi);
        }
    }
    let Some((verts, tris)) = quickhull(&extremes) else {
        return points.to_vec();
    };
    let centre = verts.iter().copied().sum::<Vec3>() / verts.len() as f32;
    // Outward planes (n, c) of the extremes' hull, with a margin for rounding.
    let planes: Vec<(Vec3, f32)> = tris
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| verts[i as usize]);
            let mut n = (b - a).cross(c - a);
            if n.length_squared() == 0.0 {
                return None;
            }
            if n.dot(centre - a) > 0.0 {
                n = -n;
            }
            let n = n.normalize();
            Some((n, n.dot(a)))
        })
        .collect();
    let scale = points
        .iter()
        .map(|p| p.abs().max_element())
        .fold(0.0, f32::max);
    let margin = 1e-4 * scale.max(1e-6);
    points
        .iter()
        .filter(|p| planes.iter().any(|(n, c)| n.dot(**p) > c - margin))
        .copied()
        .collect()
}

/// The mesh's convex hull as a triangle mesh; the bounding box when the mesh is flat (its
/// hull has no volume: quickhull cannot start), which bounds the same depths.
pub fn convex_hull(mesh: &Mesh) -> Result<Mesh, AlgoError> {
    let points = used_points(mesh);
    if points.len() < 4 {
        return Ok(bounding_box(mesh));
    }
    let candidates = thin(&points);
    Ok(match quickhull(&candidates) {
        Some((positions, indices)) => Mesh {
            positions,
            normals: None,
            indices,
        },
        None => bounding_box(mesh),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: u32) -> Mesh {
        // Points on and inside a sphere of radius 1, as degenerate triangles.
        let mut s = 12345u32;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s % 20001) as f32 / 10000.0 - 1.0
        };
        let positions: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(r(), r(), r()))
            .filter(|p| p.length() <= 1.0)
            .collect();
        let indices = (0..positions.len() as u32 / 3)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        Mesh {
            positions,
            normals: None,
            indices,
        }
    }

    /// Every point is inside (or on) every face plane of the hull.
    fn assert_contains(hull: &Mesh, points: &[Vec3]) {
        let centre = hull.positions.iter().copied().sum::<Vec3>() / hull.positions.len() as f32;
        for t in &hull.indices {
            let [a, b, c] = t.map(|i| hull.positions[i as usize]);
            let mut n = (b - a).cross(c - a);
            if n.dot(centre - a) > 0.0 {
                n = -n;
            }
            let n = n.normalize();
            for p in points {
                assert!(n.dot(*p - a) <= 1e-4, "point {p} outside a hull face");
            }
        }
    }

    #[test]
    fn the_box_of_a_mesh_holds_it() {
        let m = cloud(3000);
        let b = bounding_box(&m);
        assert_eq!(b.indices.len(), 12);
        assert_contains(&b, &m.positions);
    }

    #[test]
    fn the_hull_holds_every_point_and_is_smaller_than_the_box() {
        let m = cloud(6000);
        let h = convex_hull(&m).unwrap();
        assert!(h.indices.len() >= 4, "a hull of a 3D cloud has faces");
        assert_contains(&h, &m.positions);
        // Every hull vertex is a mesh point, and the hull drops most interior points.
        assert!(h.positions.iter().all(|v| m.positions.contains(v)));
        assert!(h.positions.len() < m.positions.len() / 4);
    }

    #[test]
    fn thinning_keeps_every_hull_vertex() {
        let m = cloud(4000);
        let pts = used_points(&m);
        let full = quickhull(&pts).unwrap().0;
        let thinned = thin(&pts);
        assert!(thinned.len() < pts.len());
        for v in full {
            assert!(thinned.contains(&v), "hull vertex {v} thinned away");
        }
    }

    #[test]
    fn a_flat_mesh_falls_back_to_its_box() {
        let m = Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
            ],
            normals: None,
            indices: vec![[0, 1, 2], [1, 3, 2]],
        };
        let h = convex_hull(&m).unwrap();
        assert_eq!(h.indices.len(), 12);
    }
}
