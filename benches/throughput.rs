//! Throughput benchmarks (criterion): the parallel executor on real meshes, the scheduled
//! executor's steps per second, and executions per second of a linked-list push of 4
//! invocations on one pixel (the loom / shuttle yardstick of `../shared/peers/loom-shuttle`).
//!
//! `cargo bench --bench throughput` (the dragon benchmarks need `../shared/models`).

use std::path::Path;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace_emu::{Buf, Device, ExecConfig, ExecMode, Frag, FragInput, FragmentKernel, KernelInfo, Policy, ScheduleConfig};

fn dragon(c: &mut Criterion) {
    let path = Path::new("../shared/models/dragon.obj.gz");
    if !path.exists() {
        eprintln!("skipping the dragon benchmarks: {} not found", path.display());
        return;
    }
    let mut g = c.benchmark_group("count-dragon-871k");
    g.sample_size(10);
    for size in [512u32, 2048] {
        let mut spec = RunSpec::new(SceneSpec::Obj { path: path.into(), sha256: None }, "count");
        spec.width = size;
        spec.height = size;
        let loaded = run::load(&spec).unwrap();
        let frags = run::render(&spec, &loaded).unwrap().result.report.stats.fragments_generated;
        g.throughput(Throughput::Elements(frags));
        for threads in [1usize, 2] {
            spec.exec = ExecConfig::parallel(threads);
            g.bench_with_input(BenchmarkId::new(format!("{size}px"), threads), &threads, |b, _| {
                b.iter(|| run::render(&spec, &loaded).unwrap())
            });
        }
    }
    g.finish();
}

fn scheduled_steps(c: &mut Criterion) {
    let mut g = c.benchmark_group("scheduled-steps");
    g.sample_size(10);
    let mut spec = RunSpec::new(SceneSpec::Builtin("hairball".into()), "count-plain");
    spec.width = 128;
    spec.height = 128;
    spec.exec = ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig { policy: Policy::Random, seed: 1, window: 64, record: true }),
        ..ExecConfig::default()
    };
    let loaded = run::load(&spec).unwrap();
    let steps = run::render(&spec, &loaded).unwrap().result.report.stats.steps;
    g.throughput(Throughput::Elements(steps));
    g.bench_function("count-plain-hairball-128", |b| b.iter(|| run::render(&spec, &loaded).unwrap()));
    g.finish();
}

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
    async fn shade(&self, f: Frag<'_>) {
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
    let kernel = Push { counter, head, next };
    let frags: Vec<FragInput> = (0..4).map(|i| FragInput { primitive_id: i, coverage: 1, ..Default::default() }).collect();
    g.throughput(Throughput::Elements(1));
    for policy in [Policy::Random, Policy::Pct { depth: 2 }] {
        let mut seed = 0;
        g.bench_function(policy.to_string(), |b| {
            b.iter(|| {
                dev.memory.write(counter, 0, &[1]).unwrap();
                dev.memory.write(head, 0, &[0]).unwrap();
                seed += 1;
                let exec = ExecConfig {
                    mode: ExecMode::Scheduled(ScheduleConfig { policy: policy.clone(), seed, window: 4, record: true }),
                    ..ExecConfig::default()
                };
                let r = dev.invocations(1, 1, &frags, &kernel, &exec);
                // The invariant: the list holds exactly 4 distinct nodes.
                let nexts = dev.memory.read(next).unwrap();
                let mut p = dev.memory.read(head).unwrap()[0];
                let mut n = 0;
                while p != 0 && n < 8 {
                    n += 1;
                    p = nexts[p as usize];
                }
                assert_eq!(n, 4);
                r
            })
        });
    }
    g.finish();
}

criterion_group!(benches, ll_push, scheduled_steps, dragon);
criterion_main!(benches);
