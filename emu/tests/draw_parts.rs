//! A draw of part of a mesh's triangles (`Draw::part`) rasterizes exactly those triangles'
//! fragments, with the primitive ids they have in the whole mesh, under every executor and
//! binning path: the parts of a mesh together give the whole draw's fragments.

use fragrace_emu::{
    Binning, Buf, Device, Draw, ExecConfig, Fragment, FragmentKernel, Framebuffer, KernelInfo,
    Mesh, PassState, Policy, SampleCount,
};
use glam::{Mat4, Vec3};

/// Every fragment adds one to its (pixel, primitive) counter.
struct Tally {
    counts: Buf<u32>,
    prims: u32,
}

impl FragmentKernel for Tally {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("tally")
    }
    async fn shade(&self, f: impl Fragment) {
        let at = f.pixel_index() * self.prims + f.primitive_id();
        f.atomic_add(self.counts, at, 1).await;
    }
}

/// Six overlapping quads (12 triangles) over a 12 x 12 viewport.
fn quads() -> Mesh {
    let mut m = Mesh::default();
    for i in 0..6 {
        let o = i as f32 * 0.1;
        let b = m.positions.len() as u32;
        for (x, y) in [(-0.9, -0.8), (0.5, -0.8), (0.5, 0.7), (-0.9, 0.7)] {
            m.positions.push(Vec3::new(x + o, y + o * 0.5, -0.5 + o));
        }
        m.indices.push([b, b + 1, b + 2]);
        m.indices.push([b, b + 2, b + 3]);
    }
    m
}

fn tally(draws: &[Draw<'_>], exec: &ExecConfig) -> Vec<u32> {
    let prims = draws[0].mesh.indices.len() as u32;
    let mut dev = Device::new();
    let counts = dev.buffer::<u32>("counts", 144 * prims as u64).unwrap();
    let mut fb = Framebuffer::new(12, 12, SampleCount::X1, 8, &[]).unwrap();
    for d in draws {
        dev.draw(
            &mut fb,
            d,
            &PassState::default(),
            &Tally { counts, prims },
            exec,
        )
        .unwrap();
    }
    dev.memory.read(counts).unwrap()
}

#[test]
fn parts_keep_their_primitive_ids_and_add_up_to_the_whole() {
    let mesh = quads();
    let whole = Draw::new(&mesh, Mat4::IDENTITY);
    let parts = [whole.part(0..3), whole.part(3..8), whole.part(8..12)];
    for exec in [
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig {
            binning: Binning::Always,
            ..ExecConfig::parallel(2)
        },
        ExecConfig::scheduled(Policy::Random, 0),
    ] {
        let want = tally(std::slice::from_ref(&whole), &exec);
        assert!(want.iter().any(|&c| c > 0));
        assert_eq!(tally(&parts, &exec), want, "{:?}", exec.mode);
        // One part alone: only its primitives.
        let one = tally(&parts[1..2], &exec);
        for (i, &c) in one.iter().enumerate() {
            let prim = i as u32 % 12;
            if (3..8).contains(&prim) {
                assert_eq!(c, want[i]);
            } else {
                assert_eq!(c, 0, "primitive {prim} drawn by the part 3..8");
            }
        }
    }
    // A range past the mesh is clamped to it: nothing drawn.
    assert_eq!(whole.part(20..30).indices().len(), 0);
}
