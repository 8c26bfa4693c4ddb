//! Draws and full-screen passes on the direct executors' fused path: the same writes under
//! every executor, counting passes' tallies, unbinned draws equal to binned ones, imbalance.

use fragrace_emu::{
    Buf, Device, ExecConfig, Format, Fragment, FragmentKernel, FragmentState, Framebuffer,
    KernelInfo, Policy, SampleCount, TargetState,
};

use super::common::*;

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
