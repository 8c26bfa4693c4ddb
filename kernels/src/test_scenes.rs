//! Scene pieces the unit tests of every family build their meshes and frames from (one copy,
//! so that a test scene means the same thing in every module).

use fragrace_emu::Mesh;
use glam::Mat4;

use crate::algo::Frame;

/// `mesh` through the identity view-projection (NDC = clip) at `width` x `height` pixels.
pub fn frame(mesh: &Mesh, width: u32, height: u32) -> Frame<'_> {
    Frame {
        mesh,
        view_proj: Mat4::IDENTITY,
        width,
        height,
    }
}
