//! Exploration speed: executions per second of the scheduled executor on a linked-list push
//! of 4 invocations on one pixel, with schedule recording and the hazard detector on (the
//! loom / shuttle yardstick of `../shared/peers/loom-shuttle`).
//!
//! `cargo bench --bench explore`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fragrace_emu::{
    Buf, Device, FragInput, Fragment, FragmentKernel, KernelInfo, Policy, ScheduleConfig,
};

/// The loom/shuttle peer's model: take a node with a counter `fetch_add`, publish it with a
/// compare-exchange loop on the pixel's head.
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

fn ll_push(c: &mut Criterion) {
    let mut g = c.benchmark_group("ll-push-4");
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
    const BATCH: u64 = 10_000;
    g.throughput(Throughput::Elements(BATCH));
    for policy in [Policy::Random, Policy::Pct { depth: 2 }] {
        let mut seed = 0;
        let sc = ScheduleConfig {
            policy: policy.clone(),
            seed: 0,
            window: 4,
            record: true,
            ..Default::default()
        };
        g.bench_function(policy.to_string(), |b| {
            b.iter(|| {
                let n = dev.explore(
                    1,
                    1,
                    &frags,
                    &kernel,
                    &sc,
                    1 << 16,
                    seed..seed + BATCH,
                    |e, mem| {
                        // The invariant: the list holds exactly 4 distinct nodes.
                        let mut p = mem.get(head, 0).unwrap();
                        let mut n = 0;
                        while p != 0 && n < 8 {
                            n += 1;
                            p = mem.get(next, p).unwrap();
                        }
                        assert_eq!(n, 4);
                        assert!(!e.schedule.is_empty());
                        mem.set(counter, 0, 1).unwrap();
                        mem.set(head, 0, 0).unwrap();
                        true
                    },
                );
                seed += BATCH;
                n
            })
        });
    }
    g.finish();
}

criterion_group!(benches, ll_push);
criterion_main!(benches);
