//! Faults and misuse are reported, never a crash or a hang: out-of-bounds accesses, panics,
//! a spinning kernel stopped by the watchdog, undeclared interlock or interpolants, bad meshes;
//! in full-screen passes and in draws under every executor.

use fragrace_emu::{
    Buf, Device, ExecConfig, FaultKind, Format, Fragment, FragmentKernel, FragmentState,
    Framebuffer, KernelInfo, SampleCount, TargetState,
};

use super::common::*;

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

/// An invocation that faults makes no access after the faulting one (the fused path leaves
/// the kernel there, as the others drop it): the adds before the fault land for every
/// fragment, those after it only for the fragments that did not fault.
#[test]
fn an_invocation_that_faults_makes_no_access_after_it() {
    struct AddOobAdd {
        counters: Buf<u32>,
        buf: Buf<u32>,
    }
    impl FragmentKernel for AddOobAdd {
        fn info(&self) -> KernelInfo {
            KernelInfo::new("add-oob-add")
        }
        async fn shade(&self, f: impl Fragment) {
            f.atomic_add(self.counters, 0, 1).await;
            f.store(self.buf, f.pixel_index() + 100, 1).await;
            f.atomic_add(self.counters, 1, 1).await;
            f.output(0, [1.0; 4]);
        }
    }
    for e in direct_execs() {
        let mut dev = Device::new();
        let counters = dev.buffer::<u32>("counters", 2).unwrap();
        let buf = dev.buffer::<u32>("small", 120).unwrap();
        let (_, r) = draw_with(&dev, &AddOobAdd { counters, buf }, &e);
        // Pixel indices + 100 >= 120 fault: the last 108 pixels of 128, both layers.
        assert_eq!(r.stats.faulted, 2 * 108, "{e:?}");
        assert_eq!(
            dev.memory.read(counters).unwrap(),
            vec![256, 256 - 2 * 108],
            "{e:?}"
        );
    }
}

/// A misuse outside an access (an output to a target that does not exist, an interpolated
/// value read by a kernel declared without them) ends the invocation as an access fault
/// does: the add before it lands for every fragment, the add after it for none (the
/// invocation stops at its next access at the latest).
#[test]
fn an_invocation_that_misuses_the_api_makes_no_access_after_it() {
    #[derive(Clone, Copy)]
    enum Misuse {
        Target,
        Interpolant,
    }
    struct AddMisuseAdd {
        counters: Buf<u32>,
        misuse: Misuse,
    }
    impl FragmentKernel for AddMisuseAdd {
        fn info(&self) -> KernelInfo {
            let info = KernelInfo::new("add-misuse-add");
            match self.misuse {
                Misuse::Target => info,
                Misuse::Interpolant => info.without_interpolants(),
            }
        }
        async fn shade(&self, f: impl Fragment) {
            f.atomic_add(self.counters, 0, 1).await;
            let red = match self.misuse {
                Misuse::Target => {
                    f.output(9, [1.0; 4]);
                    1.0
                }
                Misuse::Interpolant => f.depth(),
            };
            f.atomic_add(self.counters, 1, 1).await;
            f.output(0, [red, 0.0, 0.0, 1.0]);
        }
    }
    for e in all_execs().into_iter().chain(direct_execs()) {
        for misuse in [Misuse::Target, Misuse::Interpolant] {
            let mut dev = Device::new();
            let counters = dev.buffer::<u32>("counters", 2).unwrap();
            let (_, r) = draw_with(&dev, &AddMisuseAdd { counters, misuse }, &e);
            let what = format!(
                "{e:?}, {}",
                match misuse {
                    Misuse::Target => "target 9",
                    Misuse::Interpolant => "interpolant",
                }
            );
            assert_eq!(r.stats.faulted, 256, "{what}");
            assert!(
                r.faults
                    .iter()
                    .all(|f| matches!(f.kind, FaultKind::Misuse { .. })),
                "{what}"
            );
            assert_eq!(dev.memory.read(counters).unwrap(), vec![256, 0], "{what}");
        }
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

/// Every pixel stores a three-word record at `3 * pixel + shift` and loads it back into its
/// output: with `shift = 1` on a buffer of `3 * pixels` words, the last pixel's record
/// crosses the buffer's end after two words.
struct Records {
    buf: Buf<u32>,
    shift: u32,
}

impl FragmentKernel for Records {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("records")
    }
    async fn shade(&self, f: impl Fragment) {
        let at = f.pixel_index() * 3 + self.shift;
        let v = f.pixel_index() + 1;
        f.store_record(self.buf, at, &[v, v + 100, v + 200]).await;
        let mut r = [0u32; 3];
        f.load_record(self.buf, at, &mut r).await;
        f.output(0, [r[0] as f32, r[1] as f32, r[2] as f32, 1.0]);
    }
}

#[test]
fn a_record_faults_at_the_word_a_word_by_word_access_would() {
    // Records are performed word by word: a record that leaves its buffer, or meets the
    // step limit, has its earlier words stored and faults at the first word it cannot
    // perform, whatever the executor (the fused path claims a whole record at once only
    // when every word would succeed).
    let run = |e: &ExecConfig| {
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("rec", 48).unwrap();
        let mut fb = Framebuffer::new(4, 4, SampleCount::X1, 8, &[Format::RGBA32F]).unwrap();
        let mut st = FragmentState::new();
        st.targets = vec![TargetState::new(Format::RGBA32F)];
        let r = dev
            .fullscreen(&mut fb, &st, &Records { buf, shift: 1 }, e)
            .unwrap();
        (r, dev.memory.read(buf).unwrap(), fb.color(0, 1, 1, 0))
    };
    for e in all_execs().iter().chain(&direct_execs()) {
        let (r, words, texel) = run(e);
        assert_eq!(r.stats.faulted, 1, "{e:?}");
        assert!(
            matches!(&r.faults[0].kind, FaultKind::OutOfBounds { buffer, len: 48, .. } if buffer == "rec"),
            "{e:?}: {:?}",
            r.faults[0]
        );
        // Pixel 15's record: words 46 and 47 stored, the third (48) out of bounds.
        assert_eq!(&words[46..], &[16, 116], "{e:?}");
        assert_eq!(words[1..4], [1, 101, 201], "{e:?}");
        assert_eq!(
            r.stats.ops.of(fragrace_emu::memory::OpKind::Store),
            15 * 3 + 2,
            "{e:?}"
        );
        assert_eq!(
            r.stats.ops.of(fragrace_emu::memory::OpKind::Load),
            15 * 3,
            "{e:?}"
        );
        assert_eq!(
            texel,
            [
                6f32.to_bits(),
                106f32.to_bits(),
                206f32.to_bits(),
                1f32.to_bits()
            ]
        );
    }
    // The step limit falls inside the load: four words performed, the fifth faults.
    for mut e in all_execs().into_iter().chain(direct_execs()) {
        e.max_steps = 4;
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("rec", 64).unwrap();
        let r = dev
            .fullscreen(
                &mut fb(4, 4),
                &FragmentState::new(),
                &Records { buf, shift: 0 },
                &e,
            )
            .unwrap();
        assert_eq!(r.stats.faulted, 16, "{e:?}");
        assert!(r
            .faults
            .iter()
            .all(|f| matches!(f.kind, FaultKind::Watchdog { .. })));
        assert_eq!(
            r.stats.ops.of(fragrace_emu::memory::OpKind::Store),
            16 * 3,
            "{e:?}"
        );
        // The direct executors count an operation once performed (the scheduled one when
        // issued, the faulting word's included).
        if !matches!(e.mode, fragrace_emu::ExecMode::Scheduled(_)) {
            let loads = r.stats.ops.of(fragrace_emu::memory::OpKind::Load);
            assert_eq!(loads, 16, "{e:?}");
        }
        assert_eq!(
            dev.memory.read(buf).unwrap()[45..48],
            [16, 116, 216],
            "{e:?}"
        );
    }
}
