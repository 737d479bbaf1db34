#!/usr/bin/env python3
"""Instructions a vertex of one multigrid-CG iteration, and of a whole solve, by cachegrind.

Runs `cg_iteration_cost RADIUS N` (exactly N iterations on a digitized sphere, exact
normals, default weights) single-threaded under `valgrind --tool=cachegrind --cache-sim=no`
for two iteration counts; the difference over the extra iterations and vertices is one
iteration's cost (the setup cancels). Then the default-tolerance solve: its iterations and
its total instructions a vertex (setup included).

    cargo build --release -p voxreg-regularize --example cg_iteration_cost
    python3 bench/speed/cg_iteration.py [--radius 60] [--iters 4,12] [--bin PATH]
"""
import argparse
import os
import re
import subprocess
import tempfile


def run(binary, args):
    with tempfile.NamedTemporaryFile(suffix=".cg") as out:
        env = dict(os.environ, RAYON_NUM_THREADS="1")
        p = subprocess.run(
            ["valgrind", "--tool=cachegrind", "--cache-sim=no", f"--cachegrind-out-file={out.name}", binary]
            + [str(a) for a in args],
            env=env, capture_output=True, text=True, check=True)
        refs = int(re.search(r"I\s+refs:\s+([\d,]+)", p.stderr).group(1).replace(",", ""))
        m = re.search(r"vertices (\d+) iterations (\d+) checksum (\S+)", p.stdout)
        return refs, int(m.group(1)), int(m.group(2)), m.group(3)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--radius", type=float, default=60.0)
    ap.add_argument("--iters", default="4,12")
    ap.add_argument("--bin", default="target/release/examples/cg_iteration_cost")
    a = ap.parse_args()
    lo, hi = (int(k) for k in a.iters.split(","))
    r_lo, n, it_lo, _ = run(a.bin, [a.radius, lo])
    r_hi, _, it_hi, _ = run(a.bin, [a.radius, hi])
    per = (r_hi - r_lo) / (it_hi - it_lo) / n
    r_solve, _, it_solve, checksum = run(a.bin, [a.radius])
    print(f"radius {a.radius:g}: {n} vertices")
    print(f"one iteration: {per:.0f} instructions a vertex ({it_lo} -> {it_hi} iterations)")
    print(f"default solve: {it_solve} iterations, {r_solve / n:.0f} instructions a vertex in all, "
          f"checksum {checksum}")


if __name__ == "__main__":
    main()
