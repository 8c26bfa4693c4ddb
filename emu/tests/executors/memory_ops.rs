//! Every memory operation on every word type, and buffers of absurd sizes or wrong types refused.

use fragrace_emu::{
    Buf, Device, ExecConfig, Format, Fragment, FragmentKernel, FragmentState, Framebuffer,
    KernelInfo, Policy, SampleCount, TargetState,
};

use super::common::*;

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

/// Adds 1 to its pixel's word of `words`, after prefetching `hints` (ranges of every kind:
/// in bounds, past the end, empty, reversed, and of a 64-bit buffer) when `prefetch` is set.
struct Prefetching {
    words: Buf<u32>,
    wide: Buf<u64>,
    prefetch: bool,
}

impl FragmentKernel for Prefetching {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("prefetching")
    }
    async fn shade(&self, f: impl Fragment) {
        if self.prefetch {
            let p = f.pixel_index();
            f.prefetch(self.words, 0..self.words.len());
            f.prefetch(self.words, p..p + 1);
            f.prefetch(self.words, self.words.len() - 1..u32::MAX);
            f.prefetch(self.words, u32::MAX - 1..u32::MAX);
            // A reversed range is an empty one: nothing.
            #[allow(clippy::reversed_empty_ranges)] // the case under test
            f.prefetch(self.words, 9..3);
            f.prefetch(self.words, 5..5);
            f.prefetch(self.wide, 0..u32::MAX);
        }
        let p = f.pixel_index();
        f.atomic_add(self.words, p, 1).await;
        f.output(0, [f.x() as f32, 0.0, 0.0, 1.0]);
    }
}

/// A prefetch is a hint, not an access: under every executor a kernel that prefetches
/// (in range or not, of any buffer) computes, counts and reports exactly what the same kernel
/// without its hints does, and never faults.
#[test]
fn a_prefetch_is_no_access() {
    for e in all_execs() {
        let run = |prefetch: bool| {
            let mut dev = Device::new();
            let words = dev.buffer::<u32>("words", 6 * 5).unwrap();
            let wide = dev.buffer::<u64>("wide", 7).unwrap();
            let mut fb = Framebuffer::new(6, 5, SampleCount::X1, 8, &[Format::RGBA32F]).unwrap();
            let mut st = FragmentState::new();
            st.targets = vec![TargetState::new(Format::RGBA32F)];
            let kernel = Prefetching {
                words,
                wide,
                prefetch,
            };
            let r = dev.fullscreen(&mut fb, &st, &kernel, &e).unwrap();
            let image: Vec<_> = (0..5)
                .flat_map(|y| (0..6).map(move |x| (x, y)))
                .map(|(x, y)| fb.color(0, x, y, 0))
                .collect();
            (dev.memory.read(words).unwrap(), image, r.stats)
        };
        let (with, without) = (run(true), run(false));
        assert_eq!(with.0, vec![1; 30], "{e:?}");
        assert_eq!(with.0, without.0, "{e:?}");
        assert_eq!(with.1, without.1, "{e:?}");
        assert_eq!(with.2.faulted, 0, "{e:?}");
        assert_eq!(
            (with.2.steps, with.2.ops, with.2.shaded),
            (without.2.steps, without.2.ops, without.2.shaded),
            "{e:?}"
        );
    }
}
