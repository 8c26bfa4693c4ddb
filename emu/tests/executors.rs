//! Executors, faults and the hazard detector, mostly on full-screen passes (one invocation
//! per pixel, no rasterizer involved); draws for the fused path of the direct executors.

use fragrace_emu::{
    Buf, Device, ExecConfig, ExecMode, FaultKind, Format, Fragment, FragmentKernel, FragmentState,
    Framebuffer, KernelInfo, Policy, SampleCount, ScheduleConfig, TargetState,
};

fn fb(w: u32, h: u32) -> Framebuffer {
    Framebuffer::new(w, h, SampleCount::X1, 8, &[]).unwrap()
}

/// Every invocation increments one global counter.
struct GlobalCounter {
    counter: Buf<u32>,
    atomic: bool,
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

fn run_counter(exec: &ExecConfig, atomic: bool) -> (u32, fragrace_emu::PassReport) {
    let mut dev = Device::new();
    let counter = dev.buffer::<u32>("counter", 1).unwrap();
    let mut fb = fb(16, 16);
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &GlobalCounter { counter, atomic },
            exec,
        )
        .unwrap();
    (dev.memory.read(counter).unwrap()[0], r)
}

fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
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

#[test]
fn atomic_counter_is_exact_under_every_executor() {
    let mut execs = vec![
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig::parallel(4),
    ];
    for p in Policy::all() {
        for seed in 0..3 {
            execs.push(scheduled(p.clone(), seed));
        }
    }
    for e in &execs {
        let (v, r) = run_counter(e, true);
        assert_eq!(v, 256, "{e:?}");
        assert_eq!(r.hazards.total(), 0, "{e:?}");
        assert_eq!(r.stats.shaded, 256);
        assert_eq!(r.stats.ops.get("add"), Some(&256));
    }
}

#[test]
fn plain_counter_loses_updates_and_the_detector_sees_them() {
    let (v, _) = run_counter(&ExecConfig::ordered(), false);
    assert_eq!(v, 256, "ordered is the reference: no loss");
    for p in [
        Policy::Random,
        Policy::Pct { depth: 3 },
        Policy::Warp { lanes: 4 },
    ] {
        let (v, r) = run_counter(&scheduled(p.clone(), 7), false);
        assert!(v < 256, "{p}: {v}");
        assert!(r.hazards.lost_updates > 0, "{p}: {:?}", r.hazards);
        assert!(r.hazards.races > 0, "{p}");
        let h = &r.hazard_list[0];
        assert_eq!(h.buffer, "counter");
        assert!(h.victim.seq != h.other.seq);
    }
}

#[test]
fn scheduled_runs_are_bit_identical_per_seed_and_differ_across_seeds() {
    let a = run_counter(&scheduled(Policy::Random, 42), false);
    let b = run_counter(&scheduled(Policy::Random, 42), false);
    assert_eq!(a.0, b.0);
    assert_eq!(a.1.schedule, b.1.schedule);
    assert_eq!(a.1.hazards, b.1.hazards);
    let schedules: std::collections::HashSet<_> = (0..8)
        .map(|s| {
            run_counter(&scheduled(Policy::Random, s), false)
                .1
                .schedule
                .unwrap()
        })
        .collect();
    assert!(
        schedules.len() > 1,
        "different seeds should give different schedules"
    );
}

#[test]
fn recorded_schedule_replays_exactly() {
    let (v, r) = run_counter(&scheduled(Policy::Pct { depth: 3 }, 5), false);
    let bytes = r.schedule.clone().unwrap();
    let (v2, r2) = run_counter(&scheduled(Policy::Bytes(bytes.clone()), 99), false);
    assert_eq!(v, v2);
    assert_eq!(r2.schedule.unwrap(), bytes);
    assert_eq!(r.hazards, r2.hazards);
}

#[test]
fn any_byte_string_is_a_valid_schedule() {
    for bytes in [vec![], vec![0xff; 3], (0..=255u8).collect::<Vec<_>>()] {
        let (v, r) = run_counter(&scheduled(Policy::Bytes(bytes), 0), false);
        assert!((1..=256).contains(&v));
        assert_eq!(r.stats.shaded, 256);
    }
}

#[test]
fn policies_parse_and_print() {
    for s in [
        "random",
        "pct:3",
        "warp:32",
        "reverse",
        "fifo",
        "far-first",
        "bytes:00ff10",
    ] {
        let p: Policy = s.parse().unwrap();
        assert_eq!(p.to_string(), s);
    }
    use fragrace_emu::exec::PolicyParseError;
    // A known policy with a bad value is a bad value, not an unknown policy.
    assert!(matches!(
        "pct:0".parse::<Policy>(),
        Err(PolicyParseError::BadValue {
            name: "depth",
            min: 1,
            ..
        })
    ));
    assert!(matches!(
        "bytes:0".parse::<Policy>(),
        Err(PolicyParseError::BadHex(_))
    ));
    // Not a char boundary at an even offset: an error, not a panic.
    assert!(matches!(
        "bytes:\u{e9}1".parse::<Policy>(),
        Err(PolicyParseError::BadHex(_))
    ));
    assert!(matches!(
        "nope".parse::<Policy>(),
        Err(PolicyParseError::Unknown(_))
    ));
}

#[test]
fn exec_settings_out_of_range_are_refused_by_name() {
    use fragrace_emu::exec::{ExecConfigError, MAX_WINDOW};
    use fragrace_emu::{ExecMode, ScheduleConfig};
    let name_of = |c: &ExecConfig| match c.validate() {
        Err(ExecConfigError::OutOfRange { name, .. }) => name,
        Ok(()) => "ok",
    };
    let sched = |window, policy| ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            window,
            ..ScheduleConfig::default()
        }),
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&ExecConfig::default()), "ok");
    assert_eq!(name_of(&sched(MAX_WINDOW, Policy::Random)), "ok");
    assert_eq!(name_of(&sched(0, Policy::Random)), "window (--window)");
    assert_eq!(
        name_of(&sched(MAX_WINDOW + 1, Policy::Random)),
        "window (--window)"
    );
    assert_eq!(
        name_of(&sched(8, Policy::Pct { depth: 0 })),
        "pct depth (--policy pct:D)"
    );
    let threads = ExecConfig {
        threads: fragrace_emu::exec::max_threads() + 1,
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&threads), "threads (--threads)");
    let lanes = ExecConfig {
        batch: 0,
        ..ExecConfig::default()
    };
    assert_eq!(
        name_of(&lanes),
        "lanes per warp (--lanes, `batch` in case files)"
    );
    let steps = ExecConfig {
        max_steps: 0,
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&steps), "max_steps");
}

struct OutOfBounds {
    buf: Buf<u32>,
}
impl FragmentKernel for OutOfBounds {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("oob")
    }
    async fn shade(&self, f: impl Fragment) {
        f.store(self.buf, f.pixel_index() + 10, 1).await;
        f.output(0, [1.0; 4]);
    }
}

struct Panics;
impl FragmentKernel for Panics {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("panics")
    }
    async fn shade(&self, f: impl Fragment) {
        if f.x() == 3 {
            panic!("kernel bug at x=3");
        }
    }
}

struct SpinsForever {
    lock: Buf<u32>,
}
impl FragmentKernel for SpinsForever {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("spins")
    }
    async fn shade(&self, f: impl Fragment) {
        // The lock is never released: every invocation but possibly one spins forever.
        while f.atomic_compare_exchange(self.lock, 0, 7, 1).await.is_err() {}
    }
}

fn all_execs() -> Vec<ExecConfig> {
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

/// Writes a colour per pixel to two targets, discards on some pixels, and adds to a
/// per-pixel counter: what a resolve does, with the cases its write path distinguishes.
struct TwoTargets {
    seen: Buf<u32>,
}

impl FragmentKernel for TwoTargets {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("two-targets").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_add(self.seen, f.pixel_index(), 1).await;
        if (f.x() + f.y()).is_multiple_of(5) {
            f.discard();
            return;
        }
        let v = f.pixel_index() as f32 / 64.0;
        f.output(0, [v, 0.5, f.x() as f32, 1.0]);
        if f.y().is_multiple_of(2) {
            f.output(1, [0.25, v, 0.0, 0.5]);
        }
    }
}

#[test]
fn full_screen_writes_are_the_same_under_every_executor() {
    // Target 0 a plain write, target 1 blended; one sample and four.
    for samples in [SampleCount::X1, SampleCount::X4] {
        let mut st = FragmentState::new();
        st.targets = vec![
            TargetState::new(Format::RGBA32F),
            TargetState {
                blend: Some(fragrace_emu::BlendState::equation(
                    fragrace_emu::BlendEquation::Add,
                )),
                ..TargetState::new(Format::RGBA32F)
            },
        ];
        let run = |e: &ExecConfig| {
            let mut dev = Device::new();
            let seen = dev.buffer::<u32>("seen", 13 * 9).unwrap();
            let mut fb =
                Framebuffer::new(13, 9, samples, 8, &[Format::RGBA32F, Format::RGBA32F]).unwrap();
            fb.clear_color(1, [1f32.to_bits(), 0, 0, 0]);
            let r = dev
                .fullscreen(&mut fb, &st, &TwoTargets { seen }, e)
                .unwrap();
            let counts = dev.memory.read(seen).unwrap();
            (fb.image(0).texels, fb.image(1).texels, counts, r)
        };
        let (t0, t1, counts, r) = run(&ExecConfig::ordered());
        assert!(counts.iter().all(|&c| c == 1));
        let discarded = (0..9u32)
            .flat_map(|y| (0..13u32).map(move |x| (x, y)))
            .filter(|(x, y)| (x + y).is_multiple_of(5))
            .count() as u64;
        assert_eq!(r.stats.discarded, discarded);
        assert_eq!(
            r.stats.samples_passed,
            (13 * 9 - discarded) * samples.count() as u64
        );
        // The plain target holds each kept pixel's output on every sample.
        assert_eq!(
            t0[samples.count()],
            [1.0f32 / 64.0, 0.5, 1.0, 1.0].map(f32::to_bits)
        );
        for e in all_execs().iter().chain(&direct_execs()) {
            let (u0, u1, c, q) = run(e);
            assert_eq!((&u0, &u1, &c), (&t0, &t1, &counts), "{samples:?} {e:?}");
            assert_eq!(
                (q.stats.shaded, q.stats.discarded, q.stats.samples_passed),
                (r.stats.shaded, r.stats.discarded, r.stats.samples_passed),
                "{samples:?} {e:?}"
            );
        }
    }
}

#[test]
fn out_of_bounds_access_is_a_reported_fault() {
    for e in all_execs() {
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("small", 20).unwrap();
        let mut fb = Framebuffer::new(4, 4, SampleCount::X1, 8, &[Format::RGBA32F]).unwrap();
        let mut st = FragmentState::new();
        st.targets = vec![TargetState::new(Format::RGBA32F)];
        let r = dev
            .fullscreen(&mut fb, &st, &OutOfBounds { buf }, &e)
            .unwrap();
        assert_eq!(r.stats.faulted, 6, "{e:?}"); // pixel indices 10..16 + 10 >= 20
        let f = &r.faults[0];
        assert!(
            matches!(&f.kind, FaultKind::OutOfBounds { buffer, len: 20, .. } if buffer == "small"),
            "{f:?}"
        );
        // A faulted invocation writes nothing: its pixel keeps the clear colour.
        let (x, y) = (f.invocation.x, f.invocation.y);
        assert_eq!(fb.color(0, x, y, 0), [0; 4]);
        assert_eq!(fb.color(0, 0, 0, 0), [1f32.to_bits(); 4]);
    }
}

#[test]
fn a_panicking_kernel_is_a_reported_fault() {
    for e in all_execs() {
        let dev = Device::new();
        let mut fb = fb(8, 4);
        let r = dev
            .fullscreen(&mut fb, &FragmentState::new(), &Panics, &e)
            .unwrap();
        assert_eq!(r.stats.faulted, 4, "{e:?}");
        assert!(
            matches!(&r.faults[0].kind, FaultKind::Panic { message } if message.contains("x=3"))
        );
        assert_eq!(r.stats.shaded, 32);
    }
}

#[test]
fn a_kernel_that_spins_forever_is_stopped_by_the_watchdog() {
    for e in all_execs() {
        let mut dev = Device::new();
        let lock = dev.buffer::<u32>("lock", 1).unwrap();
        let mut fb = fb(4, 4);
        let r = dev
            .fullscreen(&mut fb, &FragmentState::new(), &SpinsForever { lock }, &e)
            .unwrap();
        assert!(r.stats.faulted >= 15, "{e:?}: {}", r.stats.faulted);
        assert!(
            r.faults
                .iter()
                .all(|f| matches!(f.kind, FaultKind::Watchdog { .. })),
            "{:?}",
            r.faults
        );
    }
}

struct UndeclaredInterlock;
impl FragmentKernel for UndeclaredInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("undeclared")
    }
    async fn shade(&self, f: impl Fragment) {
        f.interlock_begin().await;
    }
}

#[test]
fn interlock_without_declaring_it_is_misuse() {
    for e in all_execs() {
        let dev = Device::new();
        let mut fb = fb(2, 2);
        let r = dev
            .fullscreen(&mut fb, &FragmentState::new(), &UndeclaredInterlock, &e)
            .unwrap();
        assert_eq!(r.stats.faulted, 4);
        assert!(matches!(r.faults[0].kind, FaultKind::Misuse { .. }));
    }
}

struct Record {
    buf: Buf<u32>,
    write: bool,
}
impl FragmentKernel for Record {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record")
    }
    async fn shade(&self, f: impl Fragment) {
        if self.write && f.x().is_multiple_of(2) {
            f.store_record(self.buf, 0, &[f.x(), f.x(), f.x()]).await;
        } else {
            let mut r = [0u32; 3];
            f.load_record(self.buf, 0, &mut r).await;
        }
    }
}

#[test]
fn torn_records_are_detected() {
    let mut torn = 0;
    for seed in 0..10 {
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("rec", 3).unwrap();
        let mut fb = fb(8, 1);
        let r = dev
            .fullscreen(
                &mut fb,
                &FragmentState::new(),
                &Record { buf, write: true },
                &scheduled(Policy::Random, seed),
            )
            .unwrap();
        torn += r.hazards.torn;
    }
    assert!(torn > 0);
    // Readers only: nothing to tear.
    let mut dev = Device::new();
    let buf = dev.buffer::<u32>("rec", 3).unwrap();
    let mut fb = fb(8, 1);
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &Record { buf, write: false },
            &scheduled(Policy::Random, 3),
        )
        .unwrap();
    assert_eq!(r.hazards.total(), 0);
}

/// Every memory operation on every word type, checked against a host model.
struct AllOps {
    u: Buf<u32>,
    i: Buf<i32>,
    f: Buf<f32>,
    w: Buf<u64>,
}
impl FragmentKernel for AllOps {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("all-ops")
    }
    async fn shade(&self, f: impl Fragment) {
        assert_eq!(f.atomic_add(self.u, 0, 5).await, 10);
        assert_eq!(f.atomic_sub(self.u, 0, 3).await, 15);
        assert_eq!(f.atomic_min(self.u, 0, 4).await, 12);
        assert_eq!(f.atomic_max(self.u, 0, 9).await, 4);
        assert_eq!(f.atomic_and(self.u, 0, 0b1100).await, 9);
        assert_eq!(f.atomic_or(self.u, 0, 0b0011).await, 8);
        assert_eq!(f.atomic_xor(self.u, 0, 0b1111).await, 11);
        assert_eq!(f.atomic_exchange(self.u, 0, 100).await, 4);
        assert_eq!(f.atomic_compare_exchange(self.u, 0, 1, 2).await, Err(100));
        assert_eq!(f.atomic_compare_exchange(self.u, 0, 100, 2).await, Ok(100));
        assert_eq!(f.atomic_load(self.u, 0).await, 2);
        assert_eq!(f.atomic_min(self.i, 0, -7).await, 3);
        assert_eq!(f.atomic_max(self.i, 0, -9).await, -7);
        assert_eq!(f.load(self.i, 0).await, -7);
        assert_eq!(f.atomic_min(self.f, 0, -0.5).await, 1.5);
        assert_eq!(f.atomic_max(self.f, 0, 2.5).await, -0.5);
        assert_eq!(f.atomic_add(self.f, 0, 0.25).await, 2.5);
        assert_eq!(f.load(self.f, 0).await, 2.75);
        assert_eq!(f.atomic_min(self.w, 0, 1 << 40).await, u64::MAX);
        assert_eq!(f.atomic_add(self.w, 0, 1).await, 1 << 40);
        assert_eq!(
            f.atomic_compare_exchange(self.w, 0, (1 << 40) + 1, 3).await,
            Ok((1 << 40) + 1)
        );
        f.atomic_store(self.w, 0, 9).await;
        f.output(0, [1.0; 4]);
    }
}

#[test]
fn every_operation_on_every_word_type() {
    for e in [ExecConfig::ordered(), scheduled(Policy::Random, 0)] {
        let mut dev = Device::new();
        let u = dev.buffer::<u32>("u", 1).unwrap();
        let i = dev.buffer::<i32>("i", 1).unwrap();
        let f = dev.buffer::<f32>("f", 1).unwrap();
        let w = dev.buffer::<u64>("w", 1).unwrap();
        dev.memory.write(u, 0, &[10]).unwrap();
        dev.memory.write(i, 0, &[3]).unwrap();
        dev.memory.write(f, 0, &[1.5]).unwrap();
        dev.memory.write(w, 0, &[u64::MAX]).unwrap();
        let mut fb = Framebuffer::new(1, 1, SampleCount::X1, 8, &[Format::R32F]).unwrap();
        let mut st = FragmentState::new();
        st.targets = vec![TargetState::new(Format::R32F)];
        let r = dev
            .fullscreen(&mut fb, &st, &AllOps { u, i, f, w }, &e)
            .unwrap();
        assert_eq!(r.stats.faulted, 0, "{:?}", r.faults);
        assert_eq!(dev.memory.read(w).unwrap(), vec![9]);
        assert_eq!(fb.color(0, 0, 0, 0)[0], 1f32.to_bits());
    }
}

#[test]
fn buffers_reject_absurd_sizes_and_wrong_types() {
    let mut dev = Device::new();
    assert!(dev.buffer::<u32>("huge", 1 << 40).is_err());
    let b = dev.buffer::<u32>("b", 4).unwrap();
    assert!(dev.memory.write(b, 2, &[1, 2, 3]).is_err());
    assert!(dev.memory.read(b).is_ok());
}

#[test]
fn contention_names_the_hottest_address() {
    let mut dev = Device::new();
    let counter = dev.buffer::<u32>("counter", 1).unwrap();
    let mut fb = fb(32, 32);
    let e = ExecConfig {
        contention: true,
        ..ExecConfig::parallel(2)
    };
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &GlobalCounter {
                counter,
                atomic: true,
            },
            &e,
        )
        .unwrap();
    let h = &r.stats.hotspots[0];
    assert_eq!(
        (h.buffer.as_str(), h.index, h.accesses),
        ("counter", 0, 1024)
    );
    assert!(h.peak_concurrent >= 1);
    // Scheduled runs report contention from the detector.
    let (_, r) = run_counter(&scheduled(Policy::Random, 1), false);
    assert_eq!(r.stats.hotspots[0].accesses, 512);
    assert!(r.stats.hotspots[0].peak_concurrent > 1);
}

/// Increments a counter with a weak compare-exchange: retrying (correct) or not (drops an
/// increment on every spurious failure).
struct WeakCas {
    counter: Buf<u32>,
    retry: bool,
}
impl FragmentKernel for WeakCas {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("weak-cas")
    }
    async fn shade(&self, f: impl Fragment) {
        let mut old = f.atomic_load(self.counter, 0).await;
        loop {
            match f
                .atomic_compare_exchange_weak(self.counter, 0, old, old + 1)
                .await
            {
                Ok(_) => break,
                Err(cur) if self.retry => old = cur,
                Err(_) => break,
            }
        }
    }
}

#[test]
fn weak_compare_exchange_fails_spuriously_when_asked() {
    let run = |retry: bool, per_mille: u32, exec: ExecConfig| {
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let mut fb = fb(16, 16);
        let e = ExecConfig {
            spurious_cas_per_mille: per_mille,
            ..exec
        };
        let r = dev
            .fullscreen(
                &mut fb,
                &FragmentState::new(),
                &WeakCas { counter, retry },
                &e,
            )
            .unwrap();
        (dev.memory.read(counter).unwrap()[0], r)
    };
    for exec in [ExecConfig::ordered(), scheduled(Policy::Random, 2)] {
        // No spurious failures: both forms count exactly under ordered.
        assert_eq!(run(false, 0, ExecConfig::ordered()).0, 256);
        // Retrying loops survive spurious failures.
        let (v, r) = run(true, 300, exec.clone());
        assert_eq!(v, 256, "{exec:?}");
        assert!(
            r.stats.ops.of(fragrace_emu::memory::OpKind::AtomicLoad) > 256,
            "spurious failures read the word"
        );
        // A single attempt loses increments to spurious failures (deterministically).
        let (v1, _) = run(false, 300, exec.clone());
        let (v2, _) = run(false, 300, exec.clone());
        assert!(v1 < 256, "{exec:?}");
        assert_eq!(v1, v2);
    }
}

#[test]
fn reduction_keeps_every_step_and_still_finds_lost_updates() {
    let plain = |reduce: bool| {
        let e = ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy: Policy::Random,
                seed: 5,
                window: 16,
                record: true,
                reduce,
                ..Default::default()
            }),
            ..ExecConfig::default()
        };
        run_counter(&e, false)
    };
    let (v_full, r_full) = plain(false);
    let (v_red, r_red) = plain(true);
    assert_eq!(r_full.stats.steps, r_red.stats.steps);
    assert!(v_full < 256 && v_red < 256);
    assert!(r_red.hazards.lost_updates > 0);
}

/// Two full-screen quads (four triangles) in NDC: a draw, so the ordered and parallel
/// executors take the fused path (rasterize and shade per tile) rather than the
/// full-screen one.
fn two_layers() -> fragrace_emu::Mesh {
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
fn direct_execs() -> Vec<ExecConfig> {
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

fn draw_with<K: FragmentKernel>(
    dev: &Device,
    kernel: &K,
    e: &ExecConfig,
) -> (Framebuffer, fragrace_emu::PassReport) {
    let mesh = two_layers();
    let mut fb = Framebuffer::new(16, 8, SampleCount::X1, 8, &[Format::RGBA32F]).unwrap();
    let mut st = FragmentState::new();
    st.targets = vec![TargetState::new(Format::RGBA32F)];
    let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
    let state = fragrace_emu::PassState {
        fragment: st,
        ..Default::default()
    };
    let r = dev.draw(&mut fb, &draw, &state, kernel, e).unwrap();
    (fb, r)
}

struct PanicsInDraw {
    counter: Buf<u32>,
}
impl FragmentKernel for PanicsInDraw {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("panics-in-draw")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_add(self.counter, 0, 1).await;
        if f.x() == 3 {
            panic!("kernel bug at x=3");
        }
        f.output(0, [1.0; 4]);
    }
}

#[test]
fn faults_in_draws_are_reported_under_the_direct_executors() {
    for e in direct_execs() {
        // Panics: the fragments of column 3 (8 rows x 2 layers) fault, the others finish.
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let (fb, r) = draw_with(&dev, &PanicsInDraw { counter }, &e);
        assert_eq!(r.stats.fragments_generated, 256, "{e:?}");
        assert_eq!(r.stats.shaded, 256, "{e:?}");
        assert_eq!(r.stats.faulted, 16, "{e:?}");
        assert!(r.faults.iter().all(
            |f| matches!(&f.kind, FaultKind::Panic { message } if message.contains("x=3"))
                && f.invocation.x == 3
        ));
        assert_eq!(dev.memory.read(counter).unwrap()[0], 256, "{e:?}");
        assert_eq!(fb.color(0, 3, 2, 0), [0; 4], "{e:?}");
        assert_eq!(fb.color(0, 4, 2, 0), [1f32.to_bits(); 4], "{e:?}");

        // Out of bounds: pixel indices + 100 >= 120 fault (the last 28 pixels, both layers).
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("small", 120).unwrap();
        struct Oob {
            buf: Buf<u32>,
        }
        impl FragmentKernel for Oob {
            fn info(&self) -> KernelInfo {
                KernelInfo::new("oob-draw")
            }
            async fn shade(&self, f: impl Fragment) {
                f.store(self.buf, f.pixel_index() + 100, 1).await;
                f.output(0, [1.0; 4]);
            }
        }
        let (_, r) = draw_with(&dev, &Oob { buf }, &e);
        assert_eq!(r.stats.faulted, 2 * 108, "{e:?}");
        assert!(r
            .faults
            .iter()
            .all(|f| matches!(f.kind, FaultKind::OutOfBounds { .. })));

        // A spin that never ends: every fragment but the lock's taker is stopped.
        let mut dev = Device::new();
        let lock = dev.buffer::<u32>("lock", 1).unwrap();
        let (_, r) = draw_with(&dev, &SpinsForever { lock }, &e);
        assert!(r.stats.faulted >= 255, "{e:?}: {}", r.stats.faulted);
        assert!(r
            .faults
            .iter()
            .all(|f| matches!(f.kind, FaultKind::Watchdog { .. })));
    }
}

/// The same faults in a pass with nothing to write after shading (no targets: the direct
/// path retires each fragment as soon as it is shaded, and a span's later pixels write only
/// their position into the slot): each fault names its own invocation, and the others
/// count as passing samples.
#[test]
fn faults_in_capture_passes_name_their_invocation_under_the_direct_executors() {
    for e in direct_execs() {
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let mesh = two_layers();
        let mut fb = Framebuffer::new(16, 8, SampleCount::X1, 8, &[]).unwrap();
        let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
        let state = fragrace_emu::PassState::default();
        let r = dev
            .draw(&mut fb, &draw, &state, &PanicsInDraw { counter }, &e)
            .unwrap();
        assert_eq!(r.stats.shaded, 256, "{e:?}");
        assert_eq!(r.stats.faulted, 16, "{e:?}");
        let mut seen: Vec<(u32, u32)> = r
            .faults
            .iter()
            .map(|f| {
                assert!(matches!(&f.kind, FaultKind::Panic { message } if message.contains("x=3")));
                (f.invocation.x, f.invocation.y)
            })
            .collect();
        seen.sort();
        seen.dedup();
        // Both layers of column 3, every row: 8 distinct pixels, all in column 3.
        assert_eq!(seen, (0..8).map(|y| (3, y)).collect::<Vec<_>>(), "{e:?}");
        assert_eq!(r.query().samples_passed, 256 - 16, "{e:?}");
        assert_eq!(dev.memory.read(counter).unwrap()[0], 256, "{e:?}");
    }
}

/// A counting pass (no test, no target) whose kernel discards, faults and takes a varying
/// number of steps: the tallies the counting loop keeps per span (shaded, discarded,
/// passing samples, steps) are those of every fragment, under every executor, with and
/// without 4x MSAA.
#[test]
fn counting_passes_tally_discards_faults_and_steps_per_fragment() {
    struct Mixed {
        counter: Buf<u32>,
    }
    impl FragmentKernel for Mixed {
        fn info(&self) -> KernelInfo {
            KernelInfo::new("mixed")
        }
        async fn shade(&self, f: impl Fragment) {
            // x + 1 steps: 1 to 16.
            for _ in 0..=f.x() {
                f.atomic_add(self.counter, 0, 1).await;
            }
            if f.x() == 5 {
                panic!("kernel bug at x=5");
            }
            if f.x().is_multiple_of(3) {
                f.discard();
            }
        }
    }
    // Per row of 16 pixels: x = 5 faults; x in {0, 3, 6, 9, 12, 15} discards. With one
    // sample the quads cover 8 full rows each; with four, edge rows add partial coverage,
    // so every executor is compared with the scheduled one (which shades invocation by
    // invocation through the slots, not the counting loop).
    for samples in [SampleCount::X1, SampleCount::X4] {
        let run = |e: &ExecConfig| {
            let mut dev = Device::new();
            let counter = dev.buffer::<u32>("counter", 1).unwrap();
            let mesh = two_layers();
            let mut fb = Framebuffer::new(16, 8, samples, 8, &[]).unwrap();
            let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
            let mut state = fragrace_emu::PassState::default();
            state.raster.samples = samples;
            let r = dev
                .draw(&mut fb, &draw, &state, &Mixed { counter }, e)
                .unwrap();
            let s = &r.stats;
            let counted = u64::from(dev.memory.read(counter).unwrap()[0]);
            assert_eq!(counted, s.steps, "{e:?}");
            (
                s.fragments_generated,
                s.shaded,
                s.faulted,
                s.discarded,
                s.steps,
                s.max_steps_per_invocation,
                r.query().samples_passed,
            )
        };
        let reference = run(&scheduled(Policy::Random, 1));
        if samples == SampleCount::X1 {
            let rows = 8u64 * 2;
            let steps: u64 = (1..=16).sum::<u64>() * rows;
            let passing = (16 - 1 - 6) * rows;
            let n = 16 * rows;
            assert_eq!(reference, (n, n, rows, 6 * rows, steps, 16, passing));
        }
        for e in direct_execs().iter().chain(&all_execs()) {
            assert_eq!(run(e), reference, "{e:?} {samples:?}");
        }
    }
}

/// A draw whose triangles use a non-finite position or an index out of range fails with a
/// mesh error naming the culprit, before anything is shaded (the full check runs only when
/// binning rejected triangles); an unused non-finite vertex is not an error.
#[test]
fn bad_meshes_fail_the_draw_before_shading() {
    use fragrace_emu::{Draw, MeshError, PassError, PassState};
    let run = |mesh: &fragrace_emu::Mesh, e: &ExecConfig| {
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let mut fb = fb(16, 8);
        let draw = Draw::new(mesh, glam::Mat4::IDENTITY);
        let kernel = GlobalCounter {
            counter,
            atomic: true,
        };
        let r = dev.draw(&mut fb, &draw, &PassState::default(), &kernel, e);
        (r, dev.memory.read(counter).unwrap()[0])
    };
    for e in direct_execs().iter().chain(&all_execs()) {
        let mut nan = two_layers();
        nan.positions[5].y = f32::NAN;
        let (r, shaded) = run(&nan, e);
        assert!(
            matches!(
                r,
                Err(PassError::Mesh(MeshError::NonFinite { index: 5, .. }))
            ),
            "{r:?}"
        );
        assert_eq!(shaded, 0, "{e:?}");

        let mut bad_index = two_layers();
        bad_index.indices[3][1] = 99;
        let (r, shaded) = run(&bad_index, e);
        assert!(
            matches!(
                r,
                Err(PassError::Mesh(MeshError::IndexOutOfRange {
                    tri: 3,
                    index: 99,
                    ..
                }))
            ),
            "{r:?}"
        );
        assert_eq!(shaded, 0, "{e:?}");

        let mut unused = two_layers();
        unused.positions.push(glam::Vec3::splat(f32::INFINITY));
        let (r, shaded) = run(&unused, e);
        assert!(r.is_ok(), "{r:?}");
        assert_eq!(shaded, 2 * 16 * 8, "{e:?}");
    }
}

/// Reads an interpolated value in column 3 after declaring that it reads none.
struct ReadsUndeclaredInterpolants {
    counter: Buf<u32>,
}
impl FragmentKernel for ReadsUndeclaredInterpolants {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("reads-undeclared-interpolants").without_interpolants()
    }
    async fn shade(&self, f: impl Fragment) {
        if f.x() == 3 {
            let v = match f.primitive_id() % 3 {
                0 => f.depth(),
                1 => f.barycentrics()[0],
                _ => f.sample_depth(0),
            };
            std::hint::black_box(v);
        }
        f.atomic_add(self.counter, 0, 1).await;
    }
}

/// A kernel declared `without_interpolants` gets a misuse fault for reading one, under every
/// executor, with or without a depth test (so with and without the planes set up), and the
/// fragments that read none run as usual; without the declaration nothing faults.
#[test]
fn reading_undeclared_interpolants_is_misuse_under_every_executor() {
    use fragrace_emu::{CompareFunc, PassState};
    for e in direct_execs().iter().chain(&all_execs()) {
        for depth_test in [false, true] {
            let mut dev = Device::new();
            let counter = dev.buffer::<u32>("counter", 1).unwrap();
            let mesh = two_layers();
            let mut fb = Framebuffer::new(16, 8, SampleCount::X1, 8, &[]).unwrap();
            let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
            let mut state = PassState::default();
            if depth_test {
                state.fragment.depth.test = true;
                state.fragment.depth.func = CompareFunc::Always;
            }
            let kernel = ReadsUndeclaredInterpolants { counter };
            let r = dev.draw(&mut fb, &draw, &state, &kernel, e).unwrap();
            let what = format!("{e:?}, depth test {depth_test}");
            assert_eq!(r.stats.shaded, 256, "{what}");
            assert_eq!(r.stats.faulted, 16, "{what}");
            for f in &r.faults {
                assert_eq!(f.invocation.x, 3, "{what}");
                assert!(
                    matches!(&f.kind, FaultKind::Misuse { message }
                        if message.contains("without_interpolants")),
                    "{what}: {:?}",
                    f.kind
                );
            }
            // A faulted invocation ends at its next access.
            assert_eq!(dev.memory.read(counter).unwrap()[0], 240, "{what}");
        }
    }
}

/// Per pixel: the number of fragments, a hash of their invocation ids, their primitive
/// ids, coverage, facing and interpolated depth and barycentrics: what the kernel saw.
struct Fingerprint {
    out: Buf<u32>,
    width: u32,
    /// The kernel's per-pixel array hint, right or wrong: a hint changes no result.
    hint: Option<fragrace_emu::PixelArray>,
}

impl FragmentKernel for Fingerprint {
    fn info(&self) -> KernelInfo {
        KernelInfo {
            pixel_array: self.hint,
            ..KernelInfo::new("fingerprint")
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let p = (f.y() * self.width + f.x()) * 4;
        let id = f.invocation_id();
        let b = f.barycentrics();
        let seen = f.primitive_id().wrapping_mul(2_654_435_761)
            ^ u32::from(f.coverage()) << 24
            ^ u32::from(f.front_facing()) << 31
            ^ f.depth().to_bits()
            ^ b[0].to_bits().rotate_left(7)
            ^ b[1].to_bits().rotate_left(13);
        f.atomic_add(self.out, p, 1).await;
        f.atomic_xor(self.out, p + 1, (id ^ (id >> 32)) as u32)
            .await;
        f.atomic_add(self.out, p + 2, seen).await;
        f.atomic_xor(self.out, p + 3, seen.rotate_left(5)).await;
    }
}

/// A kernel's per-pixel array hint ([`KernelInfo::with_pixel_array`]) in a test.
#[derive(Clone, Copy, Debug)]
enum Hint {
    None,
    Right,
    Wrong,
    PastTheEnd,
}

/// Passes that need nothing of the framebuffer run unbinned under the parallel executor:
/// every fragment reaches the kernel exactly as through the tile-binned path and the
/// ordered executor (same invocation ids, inputs and interpolants, same statistics), with
/// near-plane clipping, culling and several samples; with or without a per-pixel array
/// hint, right or wrong (the executor prefetches by it, and nothing else).
#[test]
fn unbinned_draws_match_binned_and_ordered_ones() {
    use fragrace_emu::{Binning, Draw, Mesh, PassState, RasterState};
    use glam::{Mat4, Vec3};
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for t in 0..3000u32 {
        // Mostly small triangles in front of the camera, some large ones crossing the
        // near plane (clipped into fan pieces).
        let c = Vec3::new(
            rng.gen_range(-2.0..2.0),
            rng.gen_range(-2.0..2.0),
            rng.gen_range(-6.0..-0.5),
        );
        let size = if t % 50 == 0 { 2.0 } else { 0.08 };
        for _ in 0..3 {
            positions.push(
                c + Vec3::new(
                    rng.gen_range(-size..size),
                    rng.gen_range(-size..size),
                    rng.gen_range(-size..size),
                ),
            );
        }
        indices.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    let mesh = Mesh {
        positions,
        normals: None,
        indices,
    };
    let proj = Mat4::perspective_rh_gl(1.0, 1.0, 0.3, 10.0);
    let (w, h) = (96, 80);
    for (samples, cull) in [
        (SampleCount::X1, fragrace_emu::CullMode::None),
        (SampleCount::X4, fragrace_emu::CullMode::Back),
    ] {
        let run = |e: &ExecConfig, hint: Hint| {
            let mut dev = Device::new();
            let out = dev.buffer::<u32>("out", (w * h * 4) as u64).unwrap();
            let mut fb = Framebuffer::new(w, h, samples, 16, &[]).unwrap();
            let state = PassState {
                raster: RasterState {
                    samples,
                    cull,
                    ..Default::default()
                },
                ..Default::default()
            };
            let draw = Draw::new(&mesh, proj);
            let hint = match hint {
                Hint::None => None,
                // The slots of `out`: four words a pixel.
                Hint::Right => Some(fragrace_emu::PixelArray {
                    buffer: out.id(),
                    stride: 4,
                }),
                // No such buffer, or slots far past the end: ignored.
                Hint::Wrong => Some(fragrace_emu::PixelArray {
                    buffer: out.id() + 7,
                    stride: 1,
                }),
                Hint::PastTheEnd => Some(fragrace_emu::PixelArray {
                    buffer: out.id(),
                    stride: 1 << 20,
                }),
            };
            let kernel = Fingerprint {
                out,
                width: w,
                hint,
            };
            let r = dev.draw(&mut fb, &draw, &state, &kernel, e).unwrap();
            (dev.memory.read(out).unwrap(), r)
        };
        let (want, wr) = run(&ExecConfig::ordered(), Hint::None);
        assert!(
            wr.stats.fragments_generated > 5000,
            "{}",
            wr.stats.fragments_generated
        );
        for e in [
            ExecConfig::parallel(2),
            ExecConfig {
                lockstep: false,
                ..ExecConfig::parallel(3)
            },
            ExecConfig {
                lockstep: false,
                binning: Binning::Always,
                ..ExecConfig::parallel(2)
            },
        ] {
            for hint in [Hint::None, Hint::Right, Hint::Wrong, Hint::PastTheEnd] {
                let (got, _) = run(&e, hint);
                assert!(
                    got == want,
                    "{samples:?} {e:?} {hint:?}: the kernels saw different fragments"
                );
            }
            let (_, r) = run(&e, Hint::Right);
            let (a, b) = (&r.stats, &wr.stats);
            assert_eq!(a.fragments_generated, b.fragments_generated, "{e:?}");
            assert_eq!(a.shaded, b.shaded, "{e:?}");
            assert_eq!(a.samples_passed, b.samples_passed, "{e:?}");
        }
    }
}

/// `PassReport::imbalance`: zero when nothing runs beside the caller (one thread, the
/// ordered and scheduled executors); with two threads, at most what the threads could have
/// waited (each at most the pass's wall time), on the unbinned and the binned fused paths.
#[test]
fn imbalance_is_zero_without_threads_and_bounded_with_them() {
    let mesh = two_layers();
    let draw = fragrace_emu::Draw::new(&mesh, glam::Mat4::IDENTITY);
    let state = fragrace_emu::PassState::default();
    let unbinned = |threads| ExecConfig {
        lockstep: false,
        ..ExecConfig::parallel(threads)
    };
    let binned = ExecConfig {
        binning: fragrace_emu::Binning::Always,
        ..unbinned(2)
    };
    let cases = [
        (ExecConfig::ordered(), false),
        (scheduled(Policy::Random, 1), false),
        (unbinned(1), false),
        (unbinned(2), true),
        (binned, true),
    ];
    for (e, threaded) in cases {
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let mut fb = Framebuffer::new(64, 64, SampleCount::X1, 8, &[]).unwrap();
        let kernel = GlobalCounter {
            counter,
            atomic: true,
        };
        let r = dev.draw(&mut fb, &draw, &state, &kernel, &e).unwrap();
        // Both layers cover every pixel.
        assert_eq!(dev.memory.read(counter).unwrap()[0], 2 * 64 * 64, "{e:?}");
        if threaded {
            assert!(
                r.imbalance <= r.wall * 2,
                "{e:?}: {:?} of {:?}",
                r.imbalance,
                r.wall
            );
        } else {
            assert_eq!(r.imbalance, std::time::Duration::ZERO, "{e:?}");
        }
    }
}
