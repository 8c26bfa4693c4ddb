//! Which shared parameters each algorithm reads: the declaration the CLI refuses `--k` and
//! `--spin-cap` by (`Algorithm::reads`), held against what the algorithms do.

use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace_kernels::Param;

/// The digest of a run of `algo` with `set` applied to its parameters, on scenes deep
/// enough that k fragments per pixel (and the spin lock's give-ups) matter, under the
/// ordered executor: whether an algorithm reads a parameter is a property of the algorithm,
/// and the parallel executor's arrival order would make racy ones differ run to run.
fn digests(algo: &str, set: impl Fn(&mut fragrace_kernels::Params)) -> Vec<String> {
    digests_under(algo, false, set)
}

/// [`digests`], under the `scheduled` executor (a fixed seed) when `scheduled`.
fn digests_under(
    algo: &str,
    scheduled: bool,
    set: impl Fn(&mut fragrace_kernels::Params),
) -> Vec<String> {
    ["hairball", "coplanar-stack:12"]
        .into_iter()
        .map(|scene| {
            let mut s = RunSpec::new(SceneSpec::Builtin(scene.into()), algo);
            s.width = 24;
            s.height = 24;
            set(&mut s.params);
            s.exec = if scheduled {
                fragrace_emu::ExecConfig::scheduled(fragrace_emu::Policy::Random, 0)
            } else {
                fragrace_emu::ExecConfig::ordered()
            };
            let loaded = run::load(&s).unwrap();
            run::digest(&run::render(&s, &loaded).unwrap().result)
        })
        .collect()
}

#[test]
fn every_algorithm_reads_k_exactly_when_it_says_so() {
    let mut wrong = Vec::new();
    for a in fragrace_kernels::algorithms() {
        let name = a.info().name;
        let differs = digests(name, |p| p.k = 2) != digests(name, |p| p.k = 8);
        eprintln!(
            "{name}: k changes the result: {differs}; declared {}",
            a.reads(Param::K)
        );
        if differs != a.reads(Param::K) {
            wrong.push(format!(
                "{name}: declared {}, measured {differs}",
                a.reads(Param::K)
            ));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn every_algorithm_reads_spin_cap_exactly_when_it_says_so() {
    // Under a schedule where fragments of one pixel interleave, a cap of 1 makes a spin
    // lock give up at once.
    let scheduled = |p: &mut fragrace_kernels::Params, cap: u32| {
        p.spin_cap = cap;
    };
    let mut wrong = Vec::new();
    for a in fragrace_kernels::algorithms() {
        let name = a.info().name;
        let differs = digests_under(name, true, |p| scheduled(p, 1))
            != digests_under(name, true, |p| scheduled(p, 100_000));
        if differs != a.reads(Param::SpinCap) {
            wrong.push(format!(
                "{name}: declared {}, measured {differs}",
                a.reads(Param::SpinCap)
            ));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

#[test]
fn the_cli_refuses_k_and_spin_cap_where_they_have_no_effect() {
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_fragrace"))
            .args(args)
            .output()
            .unwrap()
    };
    let small = ["--scene", "cubes", "--width", "16", "--height", "16"];
    for (algo, option, value) in [("ll", "--k", "4"), ("kb-rmw", "--spin-cap", "8")] {
        let mut args = vec!["render", "--algo", algo, option, value];
        args.extend_from_slice(&small);
        let o = run(&args);
        assert!(!o.status.success(), "{args:?} ran");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("{option} has no effect on {algo}")),
            "{args:?}: {err}"
        );
    }
    // Where they are read, they are accepted.
    for (algo, option, value) in [("kb-rmw", "--k", "4"), ("kb-spinlock", "--spin-cap", "8")] {
        let mut args = vec!["render", "--algo", algo, option, value];
        args.extend_from_slice(&small);
        let o = run(&args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}
