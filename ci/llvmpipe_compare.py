#!/usr/bin/env python3
"""Coverage fidelity against Mesa llvmpipe: per-pixel fragment counts of fragrace's `count`
and the llvmpipe peer's `--algo count` on the same mesh, camera and resolution.

    python3 ci/llvmpipe_compare.py ../shared/models/dragon_res3.obj.gz --views 0,45,90,135,180,270 [--size 512]

Needs the peer's dependencies (see ../shared/peers/llvmpipe/README.md) and a release build
(`cargo build --release`). Prints one line per view and a JSON summary last.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
PEER = os.path.join(ROOT, "..", "shared", "peers", "llvmpipe", "oit.py")
FRAGRACE = os.path.join(ROOT, "target", "release", "fragrace")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh")
    ap.add_argument("--views", default="0,45,90,135,180,270")
    ap.add_argument("--elevation", type=float, default=0.0)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for az in [float(v) for v in a.views.split(",")]:
            mine, theirs = os.path.join(d, "mine.u32"), os.path.join(d, "theirs.u32")
            subprocess.run([FRAGRACE, "render", "--obj", a.mesh, "--algo", "count", "--width", str(a.size),
                            "--height", str(a.size), "--azimuth", str(az), "--elevation", str(a.elevation),
                            "--threads", str(a.threads), "--raw-out", mine, "--json"],
                           check=True, stdout=subprocess.DEVNULL)
            env = dict(os.environ, LP_NUM_THREADS=str(a.threads))
            subprocess.run([sys.executable, PEER, a.mesh, "--algo", "count", "--width", str(a.size),
                            "--height", str(a.size), "--azimuth", str(az), "--elevation", str(a.elevation),
                            "--frames", "1", "--warmup", "0", "--raw-out", theirs],
                           check=True, stdout=subprocess.DEVNULL, env=env)
            m = np.fromfile(mine, dtype="<u4")
            t = np.fromfile(theirs, dtype="<u4")
            agree = float((m == t).mean())
            row = dict(azimuth=az, agree=agree, differing_pixels=int((m != t).sum()),
                       fragments_fragrace=int(m.sum()), fragments_llvmpipe=int(t.sum()),
                       covered_fragrace=int((m > 0).sum()), covered_llvmpipe=int((t > 0).sum()))
            rows.append(row)
            print(f"azimuth {az:6.1f}: {agree * 100:.4f}% of pixels agree ({row['differing_pixels']} differ); "
                  f"fragments {row['fragments_fragrace']} vs {row['fragments_llvmpipe']}")
    print(json.dumps(dict(mesh=a.mesh, size=a.size, views=rows, min_agree=min(r["agree"] for r in rows))))


if __name__ == "__main__":
    main()
