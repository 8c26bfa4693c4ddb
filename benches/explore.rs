//! Exploration speed: executions per second of the scheduled executor on a linked-list push
//! of 4 invocations on one pixel, with schedule recording and the hazard detector on (the
//! loom / shuttle yardstick of `../shared/peers/loom-shuttle`).
//!
//! `cargo bench --bench explore`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fragrace_emu::{Policy, ScheduleConfig};

#[path = "../emu/examples/common/push_model.rs"]
mod push_model;
use push_model::push_model;

fn ll_push(c: &mut Criterion) {
    let mut g = c.benchmark_group("ll-push-4");
    let (dev, kernel, frags) = push_model();
    let (counter, head, next) = (kernel.counter, kernel.head, kernel.next);
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
