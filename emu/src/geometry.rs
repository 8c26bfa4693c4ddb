//! Geometry input: indexed triangle meshes and draws.

use std::ops::Range;

use glam::{Mat4, Vec3};

/// Why a mesh cannot be drawn.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    #[error("vertex {index} has a non-finite coordinate {value:?}")]
    NonFinite { index: usize, value: [f32; 3] },
    #[error("triangle {tri} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        tri: usize,
        index: u32,
        vertices: usize,
    },
    #[error("normals: {normals} given for {vertices} vertices")]
    NormalCount { normals: usize, vertices: usize },
}

/// An indexed triangle mesh. Triangle `i` is primitive id `i` of every draw of it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Optional per-vertex normals (same length as `positions`).
    pub normals: Option<Vec<Vec3>>,
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// Checks that every position is finite and every index in range.
    pub fn validate(&self) -> Result<(), MeshError> {
        // Fast paths first (this runs on every draw of an 871K-triangle mesh); the slow
        // loops below only run to name the culprit.
        // Branch-free folds (the compiler vectorizes them): a float is not finite iff its
        // exponent bits are all ones, and then adding one to the exponent carries into bit 31.
        let not_finite = |v: f32| ((v.to_bits() & 0x7f80_0000) + 0x0080_0000) >> 31;
        let finite = self.positions.iter().fold(0u32, |bad, p| {
            bad | not_finite(p.x) | not_finite(p.y) | not_finite(p.z)
        }) == 0;
        let max_index = self
            .indices
            .iter()
            .fold(0u32, |m, t| m.max(t[0]).max(t[1]).max(t[2]));
        let in_range = self.indices.is_empty() || (max_index as usize) < self.positions.len();
        let normals_ok = self
            .normals
            .as_ref()
            .is_none_or(|n| n.len() == self.positions.len());
        if finite && in_range && normals_ok {
            return Ok(());
        }
        for (index, p) in self.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(MeshError::NonFinite {
                    index,
                    value: p.to_array(),
                });
            }
        }
        if let Some(n) = &self.normals {
            if n.len() != self.positions.len() {
                return Err(MeshError::NormalCount {
                    normals: n.len(),
                    vertices: self.positions.len(),
                });
            }
        }
        let vertices = self.positions.len();
        for (tri, t) in self.indices.iter().enumerate() {
            for &index in t {
                if index as usize >= vertices {
                    return Err(MeshError::IndexOutOfRange {
                        tri,
                        index,
                        vertices,
                    });
                }
            }
        }
        Ok(())
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// Axis-aligned bounds `(min, max)`; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
        )
    }

    /// Appends another mesh (indices rebased).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        match (&mut self.normals, &other.normals) {
            (Some(a), Some(b)) => a.extend_from_slice(b),
            _ => self.normals = None,
        }
        self.indices
            .extend(other.indices.iter().map(|t| t.map(|i| i + base)));
    }
}

/// One draw: a mesh, drawn once per instance with that instance's model matrix, through a
/// view-projection matrix (OpenGL conventions: clip space z in [-w, w]).
#[derive(Clone, Debug)]
pub struct Draw<'m> {
    pub mesh: &'m Mesh,
    /// One model matrix per instance (instance id = position in this list).
    pub instances: Vec<Mat4>,
    pub view_proj: Mat4,
    /// The triangles drawn: a range of the mesh's (a draw of part of an index buffer, as
    /// `glDrawElements` with an offset). Triangle `i` keeps primitive id `i` (its index in
    /// the mesh) whatever range draws it.
    pub triangles: Range<u32>,
}

impl<'m> Draw<'m> {
    /// One instance with the identity model matrix, every triangle.
    pub fn new(mesh: &'m Mesh, view_proj: Mat4) -> Draw<'m> {
        Draw {
            mesh,
            instances: vec![Mat4::IDENTITY],
            view_proj,
            triangles: 0..mesh.indices.len() as u32,
        }
    }

    /// The same draw of `triangles` only (a range of the mesh's triangles, clamped to them).
    pub fn part(&self, triangles: Range<u32>) -> Draw<'m> {
        let n = self.mesh.indices.len() as u32;
        Draw {
            triangles: triangles.start.min(n)..triangles.end.min(n),
            ..self.clone()
        }
    }

    /// The index triples drawn.
    pub fn indices(&self) -> &'m [[u32; 3]] {
        let n = self.mesh.indices.len();
        let end = (self.triangles.end as usize).min(n);
        &self.mesh.indices[(self.triangles.start as usize).min(end)..end]
    }
}
