#!/usr/bin/env python3
"""The instructions a loop runs once per item, from a callgrind profile with per-instruction
counts: for a function (or several), a histogram of execution counts (count, instructions run
that many times, their product), then the disassembly of the instructions run exactly N times
(N: a fragment count, a pixel count...), in address order.

This is how docs/performance.md ("2026-11-29, afternoon") says where the instructions of
`ll`'s insert and resolve go. Usage:

  valgrind --tool=callgrind --dump-instr=yes --dump-line=no --compress-pos=no \\
      --compress-strings=no --callgrind-out-file=cg.out --toggle-collect='*run_frame*' \\
      target/release/fragrace bench --obj ../shared/models/bunny.obj.gz --algo ll \\
      --threads 1 --width 2048 --height 2048 --frames 1 --warmup 0 --no-lockstep
  python3 ci/hot_path.py cg.out target/release/fragrace 'run_unit_counting' 1790978
  python3 ci/hot_path.py cg.out target/release/fragrace 'do_call|run_tile_fullscreen' 901888

FUNCTIONS is a `|`-separated list of substrings of callgrind's function names; COUNTS is a
comma-separated list of execution counts to disassemble (the histogram shows which to ask for).
Needs objdump.
"""
import collections
import subprocess
import sys


def counts_of(profile, patterns):
    """Execution count of every instruction address of the functions matching `patterns`."""
    counts = collections.Counter()
    fn, after_call = "", False
    for line in open(profile):
        line = line.rstrip("\n")
        if line.startswith("fn="):
            fn = line[3:]
        elif line.startswith("calls="):
            # The next cost line is the call's inclusive cost, not the instruction's own.
            after_call = True
        elif line.startswith("0x"):
            if after_call:
                after_call = False
                continue
            addr, count = line.split()[:2]
            if any(p in fn for p in patterns):
                counts[int(addr, 16)] += int(count)
    return counts


def disassemble(binary, addrs):
    """objdump's lines for `addrs`, grouped into the regions (functions) they lie in."""
    groups = [[addrs[0]]]
    for a in addrs[1:]:
        if a - groups[-1][-1] > 0x4000:
            groups.append([a])
        else:
            groups[-1].append(a)
    for g in groups:
        out = subprocess.run(
            ["objdump", "-d", "--no-show-raw-insn", "-C", binary,
             f"--start-address={g[0]}", f"--stop-address={g[-1] + 1}"],
            capture_output=True, text=True, check=True).stdout
        wanted = set(g)
        print(f"== {len(g)} instructions from {hex(g[0])}")
        for line in out.splitlines():
            head = line.strip().split(":", 1)[0]
            try:
                if int(head, 16) in wanted:
                    print(line.rstrip())
            except ValueError:
                pass


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    profile, binary, patterns = sys.argv[1], sys.argv[2], sys.argv[3].split("|")
    counts = counts_of(profile, patterns)
    print("instructions run:", sum(counts.values()))
    hist = collections.Counter(counts.values())
    print("count, instructions run that many times, product:")
    for c, n in sorted(hist.items(), key=lambda x: -x[0] * x[1])[:12]:
        print(f"  {c} {n} {c * n}")
    for want in (int(x) for x in sys.argv[4].split(",")) if len(sys.argv) > 4 else ():
        addrs = sorted(a for a, c in counts.items() if c == want)
        print(f"=== run {want} times: {len(addrs)} instructions")
        if addrs:
            disassemble(binary, addrs)


if __name__ == "__main__":
    main()
