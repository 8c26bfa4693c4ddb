//! Throughput benchmarks (criterion): the parallel executor on real meshes and the scheduled
//! executor's steps per second.
//!
//! `cargo bench --bench throughput` (the dragon benchmarks need `../shared/models`).

use std::path::Path;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};

fn dragon(c: &mut Criterion) {
    let path = Path::new("../shared/models/dragon.obj.gz");
    if !path.exists() {
        eprintln!(
            "skipping the dragon benchmarks: {} not found",
            path.display()
        );
        return;
    }
    let mut g = c.benchmark_group("count-dragon-871k");
    g.sample_size(10);
    for size in [512u32, 2048] {
        let mut spec = RunSpec::new(
            SceneSpec::Obj {
                path: path.into(),
                sha256: None,
            },
            "count",
        );
        spec.width = size;
        spec.height = size;
        let loaded = run::load(&spec).unwrap();
        let frags = run::render(&spec, &loaded)
            .unwrap()
            .result
            .report
            .stats
            .fragments_generated;
        g.throughput(Throughput::Elements(frags));
        for threads in [1usize, 2] {
            spec.exec = ExecConfig::parallel(threads);
            g.bench_with_input(
                BenchmarkId::new(format!("{size}px"), threads),
                &threads,
                |b, _| b.iter(|| run::render(&spec, &loaded).unwrap()),
            );
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
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy: Policy::Random,
            seed: 1,
            window: 64,
            record: true,
            ..Default::default()
        }),
        ..ExecConfig::default()
    };
    let loaded = run::load(&spec).unwrap();
    let steps = run::render(&spec, &loaded)
        .unwrap()
        .result
        .report
        .stats
        .steps;
    g.throughput(Throughput::Elements(steps));
    g.bench_function("count-plain-hairball-128", |b| {
        b.iter(|| run::render(&spec, &loaded).unwrap())
    });
    g.finish();
}

criterion_group!(benches, scheduled_steps, dragon);
criterion_main!(benches);
