//! Pixel and sample interlock through the whole pipeline: mutual exclusion (no lost
//! update inside the critical section) and, when ordered, entry in primitive order, under
//! every executor.

use fragrace_emu::{
    Buf, Device, Draw, ExecConfig, ExecMode, Fragment, FragmentKernel, Framebuffer, InterlockMode,
    KernelInfo, Mesh, PassReport, PassState, Policy, RasterState, SampleCount, ScheduleConfig,
};
use glam::{Mat4, Vec3};

/// Inside the critical section, per covered sample (or per pixel): a plain
/// read-modify-write of a counter and a log of the primitives in entry order.
struct Logger {
    count: Buf<u32>,
    log: Buf<u32>,
    mode: InterlockMode,
    depth: u32,
}

impl FragmentKernel for Logger {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("logger").with_interlock(self.mode)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.interlock_begin().await;
        for s in 0..8u32 {
            let slot = if self.mode.per_sample {
                p * 8 + s
            } else {
                p * 8
            };
            if self.mode.per_sample && f.coverage() & (1 << s) == 0 {
                continue;
            }
            let n = f.load(self.count, slot).await;
            f.store(
                self.log,
                slot * self.depth + n.min(self.depth - 1),
                f.primitive_id(),
            )
            .await;
            f.store(self.count, slot, n + 1).await;
            if !self.mode.per_sample {
                break;
            }
        }
        f.interlock_end().await;
    }
}

/// `layers` full-viewport quads whose diagonals differ, so edge pixels are covered
/// partially (8 samples) by different triangles.
fn scene(layers: usize) -> Mesh {
    let mut m = Mesh::default();
    for l in 0..layers {
        let b = m.positions.len() as u32;
        let z = 0.1 * l as f32 - 0.3;
        let o = 0.37 * l as f32;
        m.positions.extend([
            Vec3::new(-1.0, -1.0 + o * 0.1, z),
            Vec3::new(1.0, -1.0, z),
            Vec3::new(1.0, 1.0, z),
            Vec3::new(-1.0, 1.0, z),
        ]);
        if l % 2 == 0 {
            m.indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        } else {
            m.indices.extend([[b, b + 1, b + 3], [b + 1, b + 2, b + 3]]);
        }
    }
    m
}

fn execs() -> Vec<ExecConfig> {
    let mut v = vec![
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig {
            lockstep: false,
            ..ExecConfig::parallel(2)
        },
    ];
    for p in Policy::all() {
        for seed in 0..2 {
            v.push(ExecConfig {
                mode: ExecMode::Scheduled(ScheduleConfig {
                    policy: p.clone(),
                    seed,
                    window: 16,
                    record: false,
                    ..Default::default()
                }),
                ..ExecConfig::default()
            });
        }
    }
    v
}

fn run(
    mode: InterlockMode,
    exec: &ExecConfig,
    samples: SampleCount,
) -> (Vec<u32>, Vec<u32>, u32, fragrace_emu::PassReport) {
    let (w, h, depth) = (6u32, 5u32, 8u32);
    let mesh = scene(4);
    let mut dev = Device::new();
    let count = dev.buffer::<u32>("count", (w * h * 8) as u64).unwrap();
    let log = dev
        .buffer::<u32>("log", (w * h * 8 * depth) as u64)
        .unwrap();
    let mut fb = Framebuffer::new(w, h, samples, 8, &[]).unwrap();
    let state = PassState {
        raster: RasterState {
            samples,
            ..RasterState::default()
        },
        ..PassState::default()
    };
    let r = dev
        .draw(
            &mut fb,
            &Draw::new(&mesh, Mat4::IDENTITY),
            &state,
            &Logger {
                count,
                log,
                mode,
                depth,
            },
            exec,
        )
        .unwrap();
    (
        dev.memory.read(count).unwrap(),
        dev.memory.read(log).unwrap(),
        depth,
        r,
    )
}

#[test]
fn pixel_and_sample_interlock_exclude_and_order() {
    for samples in [SampleCount::X1, SampleCount::X8] {
        for mode in [
            InterlockMode::ORDERED,
            InterlockMode::UNORDERED,
            InterlockMode::SAMPLE_ORDERED,
            InterlockMode::SAMPLE_UNORDERED,
        ] {
            let (reference, _, _, _) = run(mode, &ExecConfig::ordered(), samples);
            for e in execs() {
                let (count, log, depth, r) = run(mode, &e, samples);
                assert_eq!(r.stats.faulted, 0, "{mode:?} {e:?}: {:?}", r.faults);
                assert_eq!(r.hazards.lost_updates, 0, "{mode:?} {e:?}");
                assert_eq!(
                    count, reference,
                    "{mode:?} {samples:?} {e:?}: a lost update inside the critical section"
                );
                if mode.ordered {
                    for (slot, &n) in count.iter().enumerate() {
                        let entries =
                            &log[slot * depth as usize..slot * depth as usize + n as usize];
                        assert!(
                            entries.windows(2).all(|w| w[0] <= w[1]),
                            "{mode:?} {e:?}: slot {slot} entered out of order: {entries:?}"
                        );
                    }
                }
            }
        }
    }
}

/// Counts how many invocations are inside the critical section of a pixel at once.
struct Inside {
    inside: Buf<u32>,
    peak: Buf<u32>,
    mode: InterlockMode,
}

impl FragmentKernel for Inside {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("inside").with_interlock(self.mode)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.interlock_begin().await;
        let before = f.atomic_add(self.inside, p, 1).await;
        f.atomic_max(self.peak, p, before + 1).await;
        f.atomic_sub(self.inside, p, 1).await;
        f.interlock_end().await;
    }
}

fn peak(mode: InterlockMode, seed: u64) -> u32 {
    let mut dev = Device::new();
    let inside = dev.buffer::<u32>("inside", 30).unwrap();
    let peak = dev.buffer::<u32>("peak", 30).unwrap();
    let r = split_pixels(&dev, &Inside { inside, peak, mode }, seed);
    assert_eq!(r.stats.faulted, 0);
    dev.memory.read(peak).unwrap().into_iter().max().unwrap()
}

/// Draws `scene(4)` into 6x5 pixels of 8 samples (triangles that split pixels, so
/// fragments of one pixel cover disjoint samples) under a random schedule.
fn split_pixels<K: FragmentKernel>(dev: &Device, kernel: &K, seed: u64) -> PassReport {
    let mesh = scene(4);
    let mut fb = Framebuffer::new(6, 5, SampleCount::X8, 8, &[]).unwrap();
    let state = PassState {
        raster: RasterState {
            samples: SampleCount::X8,
            ..RasterState::default()
        },
        ..PassState::default()
    };
    let e = ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy: Policy::Random,
            seed,
            window: 32,
            record: false,
            ..Default::default()
        }),
        ..ExecConfig::default()
    };
    dev.draw(
        &mut fb,
        &Draw::new(&mesh, Mat4::IDENTITY),
        &state,
        kernel,
        &e,
    )
    .unwrap()
}

/// Inside the section, a plain read-modify-write of one word per pixel.
struct PixelRmw {
    count: Buf<u32>,
    mode: InterlockMode,
}

impl FragmentKernel for PixelRmw {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("pixel-rmw").with_interlock(self.mode)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.interlock_begin().await;
        let c = f.load(self.count, p).await;
        f.store(self.count, p, c + 1).await;
        f.interlock_end().await;
    }
}

#[test]
fn the_detector_knows_sample_sections_of_disjoint_coverage_run_together() {
    let races = |mode: InterlockMode, seed: u64| {
        let mut dev = Device::new();
        let count = dev.buffer::<u32>("count", 30).unwrap();
        let r = split_pixels(&dev, &PixelRmw { count, mode }, seed);
        assert_eq!(r.stats.faulted, 0);
        r.hazards.races
    };
    // Per-pixel sections order every access to the pixel's word.
    for mode in [InterlockMode::ORDERED, InterlockMode::UNORDERED] {
        for seed in 0..8 {
            assert_eq!(races(mode, seed), 0, "{mode:?} seed {seed}");
        }
    }
    // Per-sample sections of fragments covering disjoint samples do not: the per-pixel
    // word is raced on (a kernel bug the detector must show).
    for mode in [
        InterlockMode::SAMPLE_ORDERED,
        InterlockMode::SAMPLE_UNORDERED,
    ] {
        assert!(
            (0..8).any(|seed| races(mode, seed) > 0),
            "{mode:?}: no race reported"
        );
    }
}

#[test]
fn sample_interlock_lets_disjoint_coverage_in_together() {
    // With 8 samples, two triangles that split a pixel cover disjoint samples of it: their
    // per-sample critical sections need not exclude each other, per-pixel ones must.
    for mode in [InterlockMode::ORDERED, InterlockMode::UNORDERED] {
        assert!(
            (0..8).all(|seed| peak(mode, seed) == 1),
            "{mode:?}: two invocations inside one pixel's section"
        );
    }
    for mode in [
        InterlockMode::SAMPLE_ORDERED,
        InterlockMode::SAMPLE_UNORDERED,
    ] {
        assert!(
            (0..8).any(|seed| peak(mode, seed) >= 2),
            "{mode:?}: disjoint coverage never overlapped"
        );
    }
}

struct PanicsInside {
    count: Buf<u32>,
}

impl FragmentKernel for PanicsInside {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("panics-inside").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        if f.primitive_id() == 1 {
            // Dies before its turn: its turn must still be passed on.
            panic!("early death");
        }
        f.interlock_begin().await;
        let n = f.load(self.count, f.pixel_index()).await;
        if f.primitive_id() == 0 {
            panic!("death inside the critical section");
        }
        f.store(self.count, f.pixel_index(), n + 1).await;
        f.interlock_end().await;
    }
}

#[test]
fn a_fragment_that_dies_releases_its_interlock_and_turn() {
    let mesh = scene(4); // primitives 0..8, two per layer
    for e in execs() {
        let mut dev = Device::new();
        let count = dev.buffer::<u32>("count", 30).unwrap();
        let mut fb = Framebuffer::new(6, 5, SampleCount::X1, 8, &[]).unwrap();
        let r = dev
            .draw(
                &mut fb,
                &Draw::new(&mesh, Mat4::IDENTITY),
                &PassState::default(),
                &PanicsInside { count },
                &e,
            )
            .unwrap();
        assert!(
            r.faults
                .iter()
                .all(|f| matches!(f.kind, fragrace_emu::FaultKind::Panic { .. })),
            "{e:?}: {:?}",
            r.faults
        );
        // Layers 1..4 (primitives 2..8) all got through on every pixel.
        let c = dev.memory.read(count).unwrap();
        assert!(c.iter().all(|&v| v == 3), "{e:?}: {c:?}");
    }
}

struct Enters;
impl FragmentKernel for Enters {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("enters").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        f.interlock_begin().await;
        f.interlock_end().await;
    }
}

#[test]
fn invocations_that_can_never_enter_are_reported_as_deadlocked() {
    // Two fragments of one pixel whose tickets skip 0: nobody's turn ever comes.
    let frags: Vec<fragrace_emu::FragInput> = (1..3)
        .map(|t| fragrace_emu::FragInput {
            ticket: t,
            coverage: 1,
            primitive_id: t,
            ..Default::default()
        })
        .collect();
    for e in [
        ExecConfig {
            max_waits: 1000,
            ..ExecConfig::ordered()
        },
        ExecConfig {
            max_waits: 1000,
            ..ExecConfig::parallel(2)
        },
        ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy: Policy::Random,
                seed: 0,
                window: 4,
                record: false,
                ..Default::default()
            }),
            ..ExecConfig::default()
        },
    ] {
        let dev = Device::new();
        let r = dev.invocations(1, 1, &frags, &Enters, &e);
        assert_eq!(r.stats.faulted, 2, "{e:?}");
        assert!(
            r.faults
                .iter()
                .all(|f| matches!(f.kind, fragrace_emu::FaultKind::Deadlock { .. })),
            "{:?}",
            r.faults
        );
    }
}
