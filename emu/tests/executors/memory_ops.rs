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
