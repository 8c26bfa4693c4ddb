#!/usr/bin/env python3
"""Instructions per path of one function, from a callgrind profile taken with
`--dump-instr=yes`: each instruction's execution count (its own cost, calls excluded),
the disassembly annotated with it, and the runs of consecutive instructions that share a
count, largest first (a path through a loop body, e.g. "561959 x 114" is a path taken
561 959 times, 114 instructions long). docs/performance.md, section "2026-11-26, late".

Usage (models in ../shared/models):
  valgrind --tool=callgrind --dump-instr=yes --callgrind-out-file=/tmp/cg.out \\
      ./target/release/fragrace bench --obj ../shared/models/dragon.obj.gz --algo count \\
      --threads 1 --width 2048 --height 2048 --frames 1 --warmup 0 --no-lockstep
  python3 ci/callgrind_paths.py /tmp/cg.out ./target/release/fragrace \\
      'fragrace_emu::raster::setup::Prepared::setup_flat' [--annotate FILE]
"""
import argparse
import re
import subprocess
from collections import Counter


def self_counts(profile, function):
    """Execution count per instruction address of `function` (its own instructions)."""
    names, counts = {}, Counter()
    current, addr, skip_next = None, 0, False
    for line in open(profile):
        line = line.rstrip("\n")
        m = re.match(r"^(c?fn)=\((\d+)\)(?: (.*))?$", line)
        if m:
            if m.group(3):
                names[m.group(2)] = m.group(3)
            if m.group(1) == "fn":
                current = names.get(m.group(2))
            continue
        if line.startswith("calls="):
            skip_next = True  # the next cost line is the call's inclusive cost
            continue
        if not line or line[0] not in "+-0123456789*":
            continue
        parts = line.split()
        a = parts[0]
        if a.startswith("0x"):
            addr = int(a, 16)
        elif a[0] == "+":
            addr += int(a[1:])
        elif a[0] == "-":
            addr -= int(a[1:])
        if skip_next:
            skip_next = False
            continue
        if current == function and len(parts) >= 3:
            counts[addr] += int(parts[2])
    return counts


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("profile")
    ap.add_argument("binary")
    ap.add_argument("function", help="demangled name, as callgrind prints it")
    ap.add_argument("--annotate", help="write the annotated disassembly here")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    counts = self_counts(args.profile, args.function)
    if not counts:
        raise SystemExit(f"no instructions of {args.function} in {args.profile}")
    lo, hi = min(counts), max(counts)
    disasm = subprocess.run(
        ["objdump", "-d", "--no-show-raw-insn", "-C",
         f"--start-address={lo:#x}", f"--stop-address={hi + 16:#x}", args.binary],
        check=True, capture_output=True, text=True).stdout
    rows = []
    for line in disasm.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s*(.*)", line)
        if m:
            rows.append((counts.get(int(m.group(1), 16), 0), m.group(1), m.group(2)))
    if args.annotate:
        with open(args.annotate, "w") as f:
            for n, a, text in rows:
                f.write(f"{n:10d} {a}: {text}\n")
    runs, prev = [], None
    for n, a, _ in rows:
        if n and n == prev:
            runs[-1][1] += 1
        elif n:
            runs.append([n, 1, a])
        prev = n
    print(f"{args.function}: {sum(counts.values())} instructions executed")
    for n, length, a in sorted(runs, key=lambda r: -r[0] * r[1])[: args.top]:
        print(f"{n:9d} x {length:4d} = {n * length / 1e6:6.1f} M  at {a}")


if __name__ == "__main__":
    main()
