#!/usr/bin/env python3
"""Fits src/budget.rs's memory model of algorithms: per pixel a, per pixel and unit of k b,
per fragment c, for the direct executors (parallel) and the scheduled one.

Usage: python3 ci/memory_fit.py [ALGO ...]   (default: the algorithms budget.rs lacks)

Runs `fragrace render --json` on a scene of low depth complexity (cubes) and one of high
(hairball), at two sizes and, for the algorithms that read k, two values of k; subtracts the
parts of the estimate that do not depend on the algorithm (process, mesh, executor slots),
and fits the rest as pixels x (a + b k) + fragments x c by least squares (non-negative),
rounded up by a tenth as the existing rows are. Prints lines to paste into MODELS. Needs
the release binary (`cargo build --release`).
"""
import itertools
import json
import re
import subprocess
import sys

import numpy as np

F = __import__("os").environ.get("FRAGRACE", "target/release/fragrace")
ALGO_PARTS = ("per-pixel storage", "per-fragment storage")


def run(algo, scene, size, k, exec_, reads_k):
    cmd = [F, "render", "--scene", scene, "--algo", algo, "--width", str(size),
           "--height", str(size), "--exec", exec_, "--json"]
    if reads_k:
        cmd += ["--k", str(k)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    line = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
    try:
        v = json.loads(line)
    except json.JSONDecodeError:
        raise SystemExit(f"{' '.join(cmd)}: {out.stderr.strip()[-400:]}")
    fixed = sum(b for name, b in v["memory_estimate_parts"] if not name.startswith(ALGO_PARTS))
    return v["peak_rss_bytes"] - fixed, size * size, k, v["fragments_estimate"]


def fit(rows):
    a = np.array([[px, px * k, fr] for _, px, k, fr in rows], dtype=float)
    y = np.array([r for r, *_ in rows], dtype=float)
    best = None
    # Least squares over every subset of non-negative coefficients (3 unknowns: 8 subsets).
    for mask in itertools.product([0, 1], repeat=3):
        cols = [i for i in range(3) if mask[i]]
        if not cols:
            continue
        x, *_ = np.linalg.lstsq(a[:, cols], y, rcond=None)
        if (x < 0).any():
            continue
        coef = np.zeros(3)
        coef[cols] = x
        err = np.abs(a @ coef - y).max()
        if best is None or err < best[0]:
            best = (err, coef)
    coef = best[1] if best else np.zeros(3)
    return [round(1.1 * c, 1) for c in coef]


def main():
    algos = json.loads(subprocess.run([F, "list", "--json"], capture_output=True,
                                      text=True, check=True).stdout)["algorithms"]
    reads = {a["name"]: "k" in a["reads"] for a in algos}
    known = set(re.findall(r'^\s*\("([a-z0-9-]+)", \[', open("src/budget.rs").read(), re.M))
    wanted = sys.argv[1:] or [a for a in reads if a not in known]
    for algo in wanted:
        models = []
        for exec_ in ("parallel", "scheduled"):
            rows = []
            for scene, size in (("cubes", 192), ("cubes", 288), ("hairball", 192), ("hairball", 288)):
                for k in ((8, 16) if reads[algo] else (8,)):
                    rows.append(run(algo, scene, size, k, exec_, reads[algo]))
            models.append(fit(rows))
        d, s = models
        print(f'    ("{algo}", [{d[0]}, {d[1]}, {d[2]}], [{s[0]}, {s[1]}, {s[2]}]),', flush=True)


if __name__ == "__main__":
    main()
