//! What the executor tests share: framebuffers, executor lists, a two-layer mesh and a
//! draw with a kernel.

use fragrace_emu::{
    Buf, ExecConfig, ExecMode, Fragment, FragmentKernel, Framebuffer, KernelInfo, Policy,
    SampleCount, ScheduleConfig,
};

pub fn fb(w: u32, h: u32) -> Framebuffer {
    Framebuffer::new(w, h, SampleCount::X1, 8, &[]).unwrap()
}

/// Every invocation increments one global counter.
pub struct GlobalCounter {
    pub counter: Buf<u32>,
    pub atomic: bool,
}

impl FragmentKernel for GlobalCounter {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("global-counter")
    }
    async fn shade(&self, f: impl Fragment) {
        if self.atomic {
            f.atomic_add(self.counter, 0, 1).await;
        } else {
            let v = f.load(self.counter, 0).await;
            f.store(self.counter, 0, v + 1).await;
        }
    }
}

pub fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
    ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed,
            window: 16,
            record: true,
            ..Default::default()
        }),
        ..ExecConfig::default()
    }
}

pub fn all_execs() -> Vec<ExecConfig> {
    let small = |mut e: ExecConfig| {
        e.max_steps = 10_000;
        e
    };
    vec![
        small(ExecConfig::ordered()),
        small(ExecConfig::parallel(2)),
        // Independent lanes: full-screen passes shade and write pixel by pixel.
        small(ExecConfig {
            lockstep: false,
            ..ExecConfig::parallel(2)
        }),
        small(scheduled(Policy::Random, 1)),
        small(scheduled(Policy::Pct { depth: 2 }, 1)),
    ]
}

/// Two full-screen quads (four triangles) in NDC: a draw, so the ordered and parallel
/// executors take the fused path (rasterize and shade per tile) rather than the
/// full-screen one.
pub fn two_layers() -> fragrace_emu::Mesh {
    use glam::Vec3;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for z in [0.2f32, 0.4] {
        let b = positions.len() as u32;
        positions.extend([
            Vec3::new(-1.0, -1.0, z),
            Vec3::new(1.0, -1.0, z),
            Vec3::new(1.0, 1.0, z),
            Vec3::new(-1.0, 1.0, z),
        ]);
        indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
    }
    fragrace_emu::Mesh {
        positions,
        normals: None,
        indices,
    }
}

/// The direct executors in every shape the fused path has: one lane, lockstep warps,
/// independent lanes, several threads on one tile (segments of one triangle).
pub fn direct_execs() -> Vec<ExecConfig> {
    let mut v = Vec::new();
    for (threads, lockstep, segment) in
        [(2, true, 128), (2, false, 128), (3, true, 1), (2, false, 1)]
    {
        let mut e = ExecConfig::parallel(threads);
        e.lockstep = lockstep;
        e.segment = segment;
        e.batch = 5;
        v.push(e);
    }
    // The tile-binned path for passes that would otherwise run unbinned.
    v.push(ExecConfig {
        lockstep: false,
        binning: fragrace_emu::Binning::Always,
        ..ExecConfig::parallel(2)
    });
    v.push(ExecConfig::ordered());
    for e in &mut v {
        e.max_steps = 10_000;
    }
    v
}
