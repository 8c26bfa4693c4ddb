//! The example of docs/kernels.md: a kernel of your own, run under every executor and
//! checked. It keeps each pixel's two nearest depths with a plain read-modify-write (racy
//! on purpose), then shows the scheduled executor catching the race.
//!
//! `cargo run --release --example custom_kernel`

use fragrace::scene::{Camera, Scene};
use fragrace_emu::{
    Buf, Device, Draw, ExecConfig, Fragment, FragmentKernel, Framebuffer, KernelInfo, PassState,
    Policy, SampleCount,
};

/// Per pixel: the two nearest depths seen so far (slot 0 nearest). Two words per pixel.
struct TwoNearest {
    slots: Buf<f32>,
}

impl FragmentKernel for TwoNearest {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("two-nearest")
    }

    async fn shade(&self, f: impl Fragment) {
        let base = 2 * f.pixel_index();
        let z = f.depth();
        // Every `.await` is a place where another invocation may run: between this load and
        // the stores below, a fragment of the same pixel can write the slots too.
        let a = f.load(self.slots, base).await;
        let b = f.load(self.slots, base + 1).await;
        if z < a {
            f.store(self.slots, base, z).await;
            f.store(self.slots, base + 1, a).await;
        } else if z < b {
            f.store(self.slots, base + 1, z).await;
        }
    }
}

fn run(scene: &Scene, exec: &ExecConfig) -> (Vec<f32>, fragrace_emu::PassReport) {
    let (w, h) = (128, 128);
    let mut device = Device::new();
    let slots = device
        .buffer::<f32>("slots", 2 * w as u64 * h as u64)
        .unwrap();
    device.memory.fill(slots, f32::INFINITY).unwrap();
    let mut fb = Framebuffer::new(w, h, SampleCount::X1, 64, &[]).unwrap();
    let draw = Draw::new(&scene.mesh, scene.view_proj(&Camera::default(), w, h));
    let report = device
        .draw(
            &mut fb,
            &draw,
            &PassState::default(),
            &TwoNearest { slots },
            exec,
        )
        .unwrap();
    (device.memory.read(slots).unwrap(), report)
}

fn main() {
    let scene = Scene::builtin("hairball").unwrap();
    let (reference, _) = run(&scene, &ExecConfig::ordered());
    for exec in [
        ExecConfig::parallel(2),
        ExecConfig::scheduled(Policy::Random, 1),
        ExecConfig::scheduled(Policy::Pct { depth: 3 }, 1),
    ] {
        let (slots, report) = run(&scene, &exec);
        let wrong = slots
            .chunks(2)
            .zip(reference.chunks(2))
            .filter(|(a, b)| a != b)
            .count();
        println!(
            "{:<10} pixels differing from ordered: {wrong:>5}   hazards: {} lost updates, {} races",
            exec.mode.name(),
            report.hazards.lost_updates,
            report.hazards.races
        );
        if let Some(h) = report.hazard_list.first() {
            println!(
                "           first: {} on {}[{}], pixel ({}, {}), primitives {} and {}, step {}",
                h.kind.name(),
                h.buffer,
                h.index,
                h.victim.x,
                h.victim.y,
                h.victim.primitive,
                h.other.primitive,
                h.step
            );
        }
    }
}
