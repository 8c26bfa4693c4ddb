//! What preprocessing accepts (section 4: "we assume intersecting triangles have been split
//! prior to invocation"), and the mesh hash that ties a stored result to its mesh.
//!
//! Refused, with the triangle named: a mesh without triangles, non-finite positions or
//! indices out of range ([`Mesh::validate`]), degenerate triangles (no plane, so no facing
//! and no occlusion region) and duplicate triangles (the same three points, whatever the
//! order: two coplanar copies occlude each other from every viewpoint, a cycle no order
//! can break). [`dedupe`] removes them for those who ask (`fragrace presort --dedupe-to
//! MESH`, which writes the mesh without them: the lists are that mesh's, and the truth is
//! computed from it).
//!
//! Accepted: non-manifold edges (one edge shared by three or more triangles) and unwelded
//! vertices. The method treats every triangle on its own (section 4: the occlusion graph
//! has a node per triangle copy, whatever the connectivity), so manifoldness is not among
//! its assumptions. What a fan around an edge changes is geometric: the occlusion regions
//! of its triangles are wedges around the edge's line, which leaves the bounding
//! polyhedron, so they touch there and only a plane through that line separates them
//! ([`super::separate::separate_touching`]); the same holds, two wedges at a time, for the
//! two triangles of an ordinary edge. [`non_manifold_edges`] counts them for the record.
//! Intersecting triangles are not looked for (that needs a pairwise test as costly as the
//! graph); they surface as a [`super::scan::ScanError`] or as errors of the run-time check.

use std::collections::HashMap;

use fragrace_emu::{Mesh, MeshError};

/// Why a mesh cannot be preprocessed.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("the mesh has no triangles: nothing to presort")]
    Empty,
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(
        "triangle {tri} is degenerate (area {area:e}, below {min:e} of the squared bounding \
         radius): remove it before presorting"
    )]
    Degenerate { tri: usize, area: f64, min: f64 },
    #[error(
        "triangles {first} and {second} have the same three vertices: remove the duplicate \
         before presorting (coplanar copies occlude each other from every viewpoint); \
         `fragrace presort MESH --dedupe-to NEW.obj` removes every such copy and writes the \
         mesh to render"
    )]
    Duplicate { first: usize, second: usize },
}

/// Relative area below which a triangle counts as degenerate.
pub const MIN_AREA: f64 = 1e-12;

/// Checks `mesh` (see the module documentation).
pub fn check(mesh: &Mesh) -> Result<(), InputError> {
    mesh.validate()?;
    if mesh.indices.is_empty() {
        return Err(InputError::Empty);
    }
    let frame = super::partition::Frame3::of(&mesh.positions);
    let min = MIN_AREA * frame.radius * frame.radius;
    let mut seen: HashMap<[[u32; 3]; 3], usize> = HashMap::new();
    for (tri, t) in mesh.indices.iter().enumerate() {
        let p = t.map(|i| mesh.positions[i as usize]);
        let d = p.map(|q| q.as_dvec3());
        let area = 0.5 * (d[1] - d[0]).cross(d[2] - d[0]).length();
        if area.is_nan() || area <= min {
            return Err(InputError::Degenerate { tri, area, min });
        }
        let mut key = p.map(|q| [q.x.to_bits(), q.y.to_bits(), q.z.to_bits()]);
        key.sort();
        if let Some(&first) = seen.get(&key) {
            return Err(InputError::Duplicate { first, second: tri });
        }
        seen.insert(key, tri);
    }
    Ok(())
}

/// A mesh without its duplicate triangles ([`dedupe`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Deduped {
    /// The mesh: the same positions (and normals), the triangles that are not a later copy
    /// of an earlier one, in their order.
    pub mesh: Mesh,
    /// Each removed triangle `(kept, removed)` as indices of the input: `removed` has the
    /// three points of the earlier triangle `kept` (in any order, so the other winding too).
    pub removed: Vec<(usize, usize)>,
}

/// Removes every triangle whose three points (by their bits, in any order) are those of an
/// earlier triangle; the first in index order is kept. Triangle ids after a removed one
/// shift down, so a renderer that colours by primitive id must draw the returned mesh, and
/// so must the truth it is compared with.
pub fn dedupe(mesh: &Mesh) -> Deduped {
    let mut seen: HashMap<[[u32; 3]; 3], usize> = HashMap::new();
    let mut indices = Vec::with_capacity(mesh.indices.len());
    let mut removed = Vec::new();
    for (tri, t) in mesh.indices.iter().enumerate() {
        let Some(p) = t
            .iter()
            .map(|&i| mesh.positions.get(i as usize))
            .collect::<Option<Vec<_>>>()
        else {
            // Out of range: kept for `check` to refuse with its message.
            indices.push(*t);
            continue;
        };
        let mut key = [p[0], p[1], p[2]].map(|q| [q.x.to_bits(), q.y.to_bits(), q.z.to_bits()]);
        key.sort();
        match seen.get(&key) {
            Some(&first) => removed.push((first, tri)),
            None => {
                seen.insert(key, tri);
                indices.push(*t);
            }
        }
    }
    Deduped {
        mesh: Mesh {
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            indices,
        },
        removed,
    }
}

/// Edges shared by more than two triangles (edges by their end points' bits, so that
/// unwelded copies of a vertex count as one).
pub fn non_manifold_edges(mesh: &Mesh) -> usize {
    type Point = [u32; 3];
    let bits = |i: u32| {
        let p = mesh.positions[i as usize];
        [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
    };
    let mut edges: HashMap<(Point, Point), u32> = HashMap::new();
    for t in &mesh.indices {
        for k in 0..3 {
            let (a, b) = (bits(t[k]), bits(t[(k + 1) % 3]));
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    edges.values().filter(|&&c| c > 2).count()
}

/// FNV-1a (64 bits) of the positions' bits and the indices: ties a stored result to the
/// exact mesh it was made from (not a cryptographic hash).
pub fn mesh_hash(mesh: &Mesh) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |w: u32| {
        for b in w.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    eat(mesh.positions.len() as u32);
    for p in &mesh.positions {
        eat(p.x.to_bits());
        eat(p.y.to_bits());
        eat(p.z.to_bits());
    }
    eat(mesh.indices.len() as u32);
    for t in &mesh.indices {
        t.iter().for_each(|&i| eat(i));
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            normals: None,
            indices: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn accepts_a_quad_and_refuses_bad_triangles() {
        assert_eq!(check(&quad()), Ok(()));
        let mut m = quad();
        m.indices.push([0, 1, 1]);
        assert!(matches!(
            check(&m),
            Err(InputError::Degenerate { tri: 2, .. })
        ));
        let mut m = quad();
        m.indices.push([2, 0, 1]);
        assert_eq!(
            check(&m),
            Err(InputError::Duplicate {
                first: 0,
                second: 2
            })
        );
        // The same points through other vertex indices are a duplicate too.
        let mut m = quad();
        m.positions.push(Vec3::new(1.0, 1.0, 0.0));
        m.indices.push([4, 3, 0]);
        assert!(matches!(check(&m), Err(InputError::Duplicate { .. })));
        let empty = Mesh::default();
        assert_eq!(check(&empty), Err(InputError::Empty));
        let mut m = quad();
        m.indices.push([0, 1, 9]);
        assert!(matches!(check(&m), Err(InputError::Mesh(_))));
        // A fin on the quad's diagonal: three triangles share the edge 0-2, accepted.
        let mut m = quad();
        m.positions.push(Vec3::new(0.5, 0.5, 1.0));
        m.indices.push([0, 2, 4]);
        assert_eq!(check(&m), Ok(()));
        assert_eq!(non_manifold_edges(&m), 1);
        assert_eq!(non_manifold_edges(&quad()), 0);
    }

    #[test]
    fn dedupe_keeps_the_first_copy_of_each_triangle() {
        let mut m = quad();
        m.indices.push([2, 1, 0]); // triangle 0, other winding
        m.indices.push([0, 1, 3]);
        m.positions.push(Vec3::new(0.0, 1.0, 0.0)); // vertex 4: vertex 3's point
        m.indices.push([4, 0, 2]); // triangle 1 through another index
        let d = dedupe(&m);
        assert_eq!(d.removed, vec![(0, 2), (1, 4)]);
        assert_eq!(d.mesh.indices, vec![[0, 1, 2], [0, 2, 3], [0, 1, 3]]);
        assert_eq!(d.mesh.positions, m.positions);
        assert_eq!(check(&d.mesh), Ok(()));
        assert_eq!(dedupe(&quad()).mesh, quad());
        assert!(dedupe(&quad()).removed.is_empty());
    }

    #[test]
    fn hash_sees_every_change() {
        let a = quad();
        let mut b = quad();
        b.positions[2].x = 1.0 + f32::EPSILON;
        let mut c = quad();
        c.indices[1] = [0, 3, 2];
        let h = mesh_hash(&a);
        assert_eq!(h, mesh_hash(&quad()));
        assert_ne!(h, mesh_hash(&b));
        assert_ne!(h, mesh_hash(&c));
    }
}
