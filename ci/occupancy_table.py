#!/usr/bin/env python3
"""The occupancy-culling tables of docs/algorithms.md ("Improving k-buffer methods via
occupancy maps", Figures 4-5 analogues), measured with the release binary.

    cargo build --release && python3 ci/occupancy_table.py [--dragon PATH] > table.md

Each run's JSON is captured whole and parsed after the process has ended (a parser started
alongside would take a core from the timed frame)."""
import argparse, json, os, platform, subprocess, sys

BIN = os.path.join(os.path.dirname(__file__), "..", "target", "release", "fragrace")


def run(*args):
    out = subprocess.run([BIN, *args, "--json"], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"fragrace {' '.join(args)}: {out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def cpu():
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


def rmw_table(size):
    print(f"### kb-rmw with and without culling (hairball {size}x{size}, k = 8, d = 32, exact range)\n")
    print("| executor | EPR plain | EPR culled | lost updates plain / culled | races plain / culled | culled fraction |")
    print("|---|---|---|---|---|---|")
    common = ["--scene", "hairball", "--algo", "kb-rmw", "--width", str(size), "--height", str(size)]
    for ex in [["--exec", "scheduled", "--policy", "pct:3", "--schedules", "4"],
               ["--exec", "scheduled", "--policy", "warp:32", "--schedules", "4"],
               ["--exec", "scheduled", "--policy", "random", "--schedules", "4"],
               ["--exec", "parallel", "--threads", "2"]]:
        plain = run("check", *common, *ex)
        cull = run("check", *common, *ex, "--occupancy", "32")
        hz = lambda v: v.get("hazards_total", v["hazards"])
        sched = ex[1] == "scheduled"
        name = ex[3] if sched else "parallel (2 threads; the detector runs under scheduled only)"
        print(f"| {name} | {plain['epr_mean']:.4f} | {cull['epr_mean']:.4f} | "
              + (f"{hz(plain)['lost_updates']} / {hz(cull)['lost_updates']} | {hz(plain)['races']} / {hz(cull)['races']} | "
                 if sched else "- | - | ")
              + f"{cull['occupancy']['culled_fraction']:.3f} |")
    print()


def sweep(title, scene_args, algos, pairs, size):
    print(f"### {title}\n")
    print("| algorithm | d | k | culled fraction | k-buffer invocations culled / plain (ratio) | memory ops saved | frame ms culled / plain |")
    print("|---|---|---|---|---|---|---|")
    for algo in algos:
        for d, k in pairs:
            v = run("render", *scene_args, "--algo", algo, "--width", str(size), "--height", str(size),
                    "--exec", "parallel", "--threads", "2", "--k", str(k), "--occupancy", str(d))
            o = v["occupancy"]
            print(f"| {algo} | {d} | {k} | {o['culled_fraction']:.3f} | {o['with']['kbuffer_invocations']} / "
                  f"{o['without']['kbuffer_invocations']} ({o['saved']['invocation_ratio']:.3f}) | "
                  f"{o['saved']['memory_ops']} | {o['with']['wall_ms']:.0f} / {o['without']['wall_ms']:.0f} |")
    print()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dragon", default=os.path.join(os.path.dirname(__file__), "..", "..", "shared", "models", "dragon.obj.gz"))
    ap.add_argument("--size", type=int, default=256)
    a = ap.parse_args()
    print(f"Measured on {cpu()}, {os.cpu_count()} cores, with `python3 ci/occupancy_table.py` "
          f"(release build). Frame times are one run each, culled and plain back to back.\n")
    rmw_table(128)
    sweep(f"Against d at k = 8 on hairball {a.size}x{a.size} (Figure 5 analogue)", ["--scene", "hairball"],
          ["kplus", "kb-atomic64"], [(d, 8) for d in [1, 2, 4, 8, 16, 32, 64]], a.size)
    sweep(f"Against k at d = 32 on hairball {a.size}x{a.size} (Figure 4 analogue)", ["--scene", "hairball"],
          ["kplus", "kb-atomic64"], [(32, k) for k in [4, 8, 16, 32]], a.size)
    if os.path.exists(a.dragon):
        sweep(f"Against k at d = 32 on the 871K-triangle dragon {a.size}x{a.size}", ["--obj", a.dragon],
              ["kplus", "kb-atomic64"], [(32, k) for k in [4, 8, 16, 32]], a.size)
    sweep(f"The no-gain worst case: coplanar-stack:128 {a.size}x{a.size} (every layer at one depth)",
          ["--scene", "coplanar-stack:128"], ["kplus"], [(32, 8)], a.size)


main()
