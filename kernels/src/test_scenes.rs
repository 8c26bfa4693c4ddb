//! Scene pieces the unit tests of every family build their meshes and frames from (one copy,
//! so that a test scene means the same thing in every module).

use fragrace_emu::Mesh;
use glam::{Mat4, Vec3};

use crate::algo::Frame;

/// `mesh` through the identity view-projection (NDC = clip) at `width` x `height` pixels.
pub fn frame(mesh: &Mesh, width: u32, height: u32) -> Frame<'_> {
    Frame {
        mesh,
        objects: &[],
        view_proj: Mat4::IDENTITY,
        width,
        height,
    }
}

/// Appends a quad of two triangles over NDC `[x0, x1] x [y0, y1]` (`r = [x0, x1, y0, y1]`)
/// at NDC depth `z + tilt * x`.
pub fn tilted_quad(mesh: &mut Mesh, r: [f32; 4], z: f32, tilt: f32) {
    let b = mesh.positions.len() as u32;
    for (x, y) in [(r[0], r[2]), (r[1], r[2]), (r[1], r[3]), (r[0], r[3])] {
        mesh.positions.push(Vec3::new(x, y, z + tilt * x));
    }
    mesh.indices.push([b, b + 1, b + 2]);
    mesh.indices.push([b, b + 2, b + 3]);
}

/// `n` identical quads: one layer of `n` coplanar fragments per covered pixel.
pub fn coplanar_stack(n: usize) -> Mesh {
    let mut mesh = Mesh::default();
    for _ in 0..n {
        tilted_quad(&mut mesh, [-0.8, 0.8, -0.8, 0.8], 0.1, 0.0);
    }
    mesh
}
