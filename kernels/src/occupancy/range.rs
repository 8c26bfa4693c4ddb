//! The depth-range pass of occupancy culling ("Improving k-buffer methods via occupancy
//! maps", section 2 and Figure 3): per pixel, the nearest and farthest depth `[zn, zf]` that
//! the fill pass cuts into sub-intervals.
//!
//! - `exact`: a geometry pass of the scene itself, `atomicMin` / `atomicMax` of every
//!   fragment's depth (the paper's "additional geometry pass", exact but as costly as the
//!   scene);
//! - `bbox`: the same kernel over the mesh's axis-aligned bounding box (12 triangles);
//! - `hull`: over its convex hull ([`super::hull`]), tighter than the box.
//!
//! A bounding volume contains the mesh, so the ray through a pixel centre crosses it over an
//! interval that holds every fragment of the pixel; where rasterization rounding or near-plane
//! clipping makes it miss, the fill clamps ([`super::bits::bucket`]), which costs culling,
//! never correctness. Pixels the volume does not cover keep `zn = +inf`, `zf = -inf` (an
//! empty range: one sub-interval).

use fragrace_emu::{Buf, Device, ExecConfig, Fragment, FragmentKernel, KernelInfo, Mesh};

use super::{hull, RangeSource};
use crate::algo::{AlgoError, Frame};
use crate::common::{capture_state, framebuffer, geometry_pass, pixels};

/// `atomicMin` and `atomicMax` of the fragment's depth into its pixel's range.
pub(super) struct RangeKernel {
    pub near: Buf<f32>,
    pub far: Buf<f32>,
}

impl FragmentKernel for RangeKernel {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("occupancy-range")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z = f.depth();
        f.atomic_min(self.near, p, z).await;
        f.atomic_max(self.far, p, z).await;
    }
}

/// The bounding volume drawn by a range pass (`None`: the scene itself).
pub fn volume(mesh: &Mesh, source: RangeSource) -> Result<Option<Mesh>, AlgoError> {
    Ok(match source {
        RangeSource::Exact => None,
        RangeSource::Bbox => Some(hull::bounding_box(mesh)),
        RangeSource::Hull => Some(hull::convex_hull(mesh)?),
    })
}

/// Runs the range pass: returns the near and far buffers and the pass's report.
pub fn pass(
    device: &mut Device,
    frame: &Frame<'_>,
    source: RangeSource,
    exec: &ExecConfig,
) -> Result<(Buf<f32>, Buf<f32>, fragrace_emu::PassReport), AlgoError> {
    let n = pixels(frame) as u64;
    let near = device.buffer::<f32>("occupancy-near", n)?;
    let far = device.buffer::<f32>("occupancy-far", n)?;
    device.memory.fill(near, f32::INFINITY)?;
    device.memory.fill(far, f32::NEG_INFINITY)?;
    let volume = volume(frame.mesh, source)?;
    let drawn = Frame {
        mesh: volume.as_ref().unwrap_or(frame.mesh),
        objects: &[],
        ..*frame
    };
    let mut fb = framebuffer(frame, fragrace_emu::SampleCount::X1, &[])?;
    let report = geometry_pass(
        device,
        &mut fb,
        &drawn,
        &capture_state(),
        &RangeKernel { near, far },
        exec,
    )?;
    Ok((near, far, report))
}
