//! The explore bench's model (`benches/explore.rs`: a linked-list push of 4 invocations on
//! one pixel, detector and recording on) run for a fixed number of executions, printing a
//! digest of every recorded schedule and the hazard counts: a fixed workload to count
//! instructions on (callgrind) and to check that a change keeps every schedule.
//!
//! `cargo run --release -p fragrace-emu --example explore_push -- [POLICY] [EXECUTIONS]`

use fragrace_emu::{Policy, ScheduleConfig};

#[path = "common/push_model.rs"]
mod push_model;
use push_model::push_model;

fn main() {
    let mut args = std::env::args().skip(1);
    let policy_arg = args.next().unwrap_or_else(|| "pct:2".into());
    let policy: Policy = match policy_arg.parse() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("explore_push: {e}");
            std::process::exit(2);
        }
    };
    let n: u64 = match args.next().map(|a| (a.parse::<u64>(), a)) {
        None => 10_000,
        Some((Ok(n), _)) if n >= 1 => n,
        Some((_, a)) => {
            eprintln!(
                "explore_push: executions `{a}`: a whole number from 1 to {}",
                u64::MAX
            );
            std::process::exit(2);
        }
    };
    let (dev, kernel, frags) = push_model();
    let (counter, head) = (kernel.counter, kernel.head);
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
