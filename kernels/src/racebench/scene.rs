//! The benchmark's tiny scene: five large triangles over a 4 x 2 pixel window, tilted at
//! different angles so that their depth order differs from pixel to pixel. Every pixel is
//! covered by all five, so five fragments of each pixel meet in every kernel. The scene is
//! rasterized once by the real rasterizer (a capture pass on the `ordered` executor); the
//! benchmark then runs its kernels on these fragments as explicit invocations, so that many
//! schedules cost no rasterization, and the loom checks take a few of them.

use fragrace_emu::{
    Buf, Device, Draw, ExecConfig, FragInput, Fragment, FragmentKernel, Framebuffer, KernelInfo,
    Mesh, PassState, SampleCount,
};
use glam::{Mat4, Vec3};

use super::run::read;

/// Fragments of a pass, in API order, with their ordered-interlock tickets.
#[derive(Clone, Debug)]
pub struct Fragments {
    pub width: u32,
    pub height: u32,
    pub inputs: Vec<FragInput>,
}

impl Fragments {
    pub fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// The pixel index of a fragment.
    pub fn pixel(&self, f: &FragInput) -> u32 {
        f.y * self.width + f.x
    }

    /// The fragments of pixel `p`, in API order.
    pub fn of_pixel(&self, p: u32) -> impl Iterator<Item = &FragInput> {
        self.inputs.iter().filter(move |f| self.pixel(f) == p)
    }

    /// The first `n` fragments of pixel 0 (of a one-pixel pass): a loom model's invocations.
    pub fn one_pixel(&self, n: usize) -> Fragments {
        let inputs = self
            .inputs
            .iter()
            .filter(|f| f.x == 0 && f.y == 0)
            .take(n)
            .enumerate()
            .map(|(i, f)| FragInput {
                seq: i as u64,
                ticket: i as u32,
                ..*f
            })
            .collect();
        Fragments {
            width: 1,
            height: 1,
            inputs,
        }
    }
}

pub const WIDTH: u32 = 4;
pub const HEIGHT: u32 = 2;

/// (NDC depth at x = 0, depth change per NDC x) of the five triangles.
const LAYERS: [(f32, f32); 5] = [
    (0.50, 0.30),
    (0.40, -0.25),
    (0.62, 0.10),
    (0.45, 0.35),
    (0.58, -0.30),
];

/// The five triangles (each covers the whole window).
pub fn mesh() -> Mesh {
    let mut mesh = Mesh::default();
    for (i, &(z, tilt)) in LAYERS.iter().enumerate() {
        let b = mesh.positions.len() as u32;
        for (x, y) in [(-1.5f32, -1.5f32), (3.5, -1.5), (-1.5, 3.5)] {
            mesh.positions.push(Vec3::new(x, y, z + tilt * x));
        }
        // Alternate the winding, so front and back faces both occur.
        mesh.indices.push(if i % 2 == 0 {
            [b, b + 1, b + 2]
        } else {
            [b, b + 2, b + 1]
        });
    }
    mesh
}

/// Records every fragment: (x, y, primitive, depth bits) at an atomically counted slot.
struct CaptureAll {
    count: Buf<u32>,
    out: Buf<u32>,
}

impl FragmentKernel for CaptureAll {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("racebench-capture")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.atomic_add(self.count, 0, 1).await;
        let rec = [f.x(), f.y(), f.primitive_id(), f.depth().to_bits()];
        f.store_record(self.out, 4 * i, &rec).await;
    }
}

/// The scene's fragments (rasterized once, on the `ordered` executor).
pub fn fragments() -> Fragments {
    let mesh = mesh();
    let mut dev = Device::new();
    let cap = 4 * LAYERS.len() as u32 * WIDTH * HEIGHT;
    let kernel = CaptureAll {
        count: dev.buffer("count", 1).expect("one word"),
        out: dev.buffer("out", cap as u64).expect("a small buffer"),
    };
    let mut fb = Framebuffer::new(WIDTH, HEIGHT, SampleCount::X1, 8, &[]).expect("4 x 2");
    let draw = Draw::new(&mesh, Mat4::IDENTITY);
    dev.draw(
        &mut fb,
        &draw,
        &PassState::default(),
        &kernel,
        &ExecConfig::ordered(),
    )
    .expect("a valid mesh");
    let n = read(&dev.memory, kernel.count)[0] as usize;
    let out = read(&dev.memory, kernel.out);
    let mut recs: Vec<[u32; 4]> = (0..n)
        .map(|i| [out[4 * i], out[4 * i + 1], out[4 * i + 2], out[4 * i + 3]])
        .collect();
    // API order: primitive, then pixel.
    recs.sort_by_key(|r| (r[2], r[1], r[0]));
    let mut tickets = vec![0u32; (WIDTH * HEIGHT) as usize];
    let inputs = recs
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let t = &mut tickets[(r[1] * WIDTH + r[0]) as usize];
            *t += 1;
            FragInput {
                seq: i as u64,
                x: r[0],
                y: r[1],
                tri: u32::MAX,
                primitive_id: r[2],
                coverage: 1,
                front_facing: true,
                depth: f32::from_bits(r[3]),
                ticket: *t - 1,
                ..Default::default()
            }
        })
        .collect();
    Fragments {
        width: WIDTH,
        height: HEIGHT,
        inputs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pixel_gets_five_fragments_in_differing_depth_orders() {
        let fr = fragments();
        assert_eq!(fr.inputs.len(), 5 * 8);
        let order = |p: u32| {
            let mut v: Vec<(f32, u32)> =
                fr.of_pixel(p).map(|f| (f.depth, f.primitive_id)).collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            v.iter().map(|x| x.1).collect::<Vec<_>>()
        };
        assert_ne!(
            order(0),
            order(3),
            "the tilts must reorder the layers across the row"
        );
        let one = fr.one_pixel(3);
        assert_eq!(one.inputs.len(), 3);
        assert!(one
            .inputs
            .iter()
            .enumerate()
            .all(|(i, f)| f.ticket == i as u32));
    }
}
