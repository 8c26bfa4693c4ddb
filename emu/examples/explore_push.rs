//! The explore bench's model (`benches/explore.rs`: a linked-list push of 4 invocations on
//! one pixel, detector and recording on) run for a fixed number of executions, printing a
//! digest of every recorded schedule and the hazard counts: a fixed workload to count
//! instructions on (callgrind) and to check that a change keeps every schedule.
//!
//! `cargo run --release -p fragrace-emu --example explore_push -- [POLICY] [EXECUTIONS]`

use fragrace_emu::{
    Buf, Device, FragInput, Fragment, FragmentKernel, KernelInfo, Policy, ScheduleConfig,
};

struct Push {
    counter: Buf<u32>,
    head: Buf<u32>,
    next: Buf<u32>,
}

impl FragmentKernel for Push {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-push")
    }
    async fn shade(&self, f: impl Fragment) {
        let node = f.atomic_add(self.counter, 0, 1).await;
        let mut old = f.atomic_load(self.head, 0).await;
        loop {
            f.store(self.next, node, old).await;
            match f.atomic_compare_exchange(self.head, 0, old, node).await {
                Ok(_) => break,
                Err(cur) => old = cur,
            }
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let policy: Policy = args
        .next()
        .unwrap_or_else(|| "pct:2".into())
        .parse()
        .expect("a policy");
    let n: u64 = args
        .next()
        .map_or(10_000, |a| a.parse().expect("a number of executions"));
    let mut dev = Device::new();
    let counter = dev.buffer::<u32>("counter", 1).unwrap();
    let head = dev.buffer::<u32>("head", 1).unwrap();
    let next = dev.buffer::<u32>("next", 5).unwrap();
    dev.memory.write(counter, 0, &[1]).unwrap();
    let kernel = Push {
        counter,
        head,
        next,
    };
    let frags: Vec<FragInput> = (0..4)
        .map(|i| FragInput {
            primitive_id: i,
            coverage: 1,
            ..Default::default()
        })
        .collect();
    let sc = ScheduleConfig {
        policy,
        seed: 0,
        window: 4,
        record: true,
        ..Default::default()
    };
    let mut digest = 0xcbf2_9ce4_8422_2325u64;
    let (mut steps, mut hazards) = (0u64, 0u64);
    let ran = dev.explore(1, 1, &frags, &kernel, &sc, 1 << 16, 0..n, |e, mem| {
        for &b in e.schedule {
            digest = (digest ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
        digest = (digest ^ 0xff).wrapping_mul(0x100_0000_01b3);
        steps += e.steps;
        hazards += e.hazards.total();
        mem.set(counter, 0, 1).unwrap();
        mem.set(head, 0, 0).unwrap();
        true
    });
    println!("executions {ran} steps {steps} hazards {hazards} schedule digest {digest:016x}");
}
