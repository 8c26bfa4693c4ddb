//! `fragrace list`: the algorithms (with their declared properties), built-in scenes and
//! scheduling policies.

/// The scheduling policies `--policy` takes, as `list` names them.
const POLICIES: [&str; 7] = [
    "random",
    "pct:D",
    "warp:N",
    "reverse",
    "fifo",
    "far-first",
    "bytes:HEX",
];

/// Prints the table (or with `json`, one JSON object).
pub fn cmd_list(json: bool) {
    let mut algos = fragrace_kernels::algorithms();
    algos.extend(fragrace_kernels::registry::preprocessed());
    let infos: Vec<_> = algos
        .iter()
        .map(|a| {
            let mut v = serde_json::to_value(a.info()).expect("AlgoInfo serializes");
            v["occupancy"] = serde_json::json!(a.takes_occupancy());
            // The shared options it reads (`--k`, `--spin-cap`); the others are refused.
            v["reads"] = [fragrace_kernels::Param::K, fragrace_kernels::Param::SpinCap]
                .into_iter()
                .filter(|&p| a.reads(p))
                .map(|p| p.option())
                .collect();
            v
        })
        .collect();
    if json {
        println!(
            "{}",
            serde_json::json!({"algorithms": infos, "scenes": crate::scene::builtin_names(), "policies": POLICIES})
        );
        return;
    }
    println!(
        "{:<24} {:<12} {:<16} {:<26} memory per pixel",
        "algorithm", "family", "hazard class", "passes"
    );
    for a in &algos {
        let i = a.info();
        println!(
            "{:<24} {:<12} {:<16} {:<26} {}",
            i.name,
            i.family,
            i.hazard.name(),
            i.passes,
            i.memory
        );
    }
    let takers: Vec<_> = algos
        .iter()
        .filter(|a| a.takes_occupancy())
        .map(|a| a.info().name)
        .collect();
    println!("\noccupancy culling (--occupancy D): {}", takers.join(", "));
    println!("\nscenes: {}", crate::scene::builtin_names().join(", "));
    println!("policies: {}", POLICIES.join(", "));
}
