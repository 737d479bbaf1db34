#!/usr/bin/env python3
"""Two voxreg binaries interleaved (A B A B ...) on one input: the medians of their
`--report` stage times and of their sum (the compute of `vs_vtk.py`), and the per-pair
ratio of the sums.

    python3 bench/speed/stages_ab.py NEW OLD INPUT [voxreg options...] [--pairs N]

Where `ab.py` times whole processes, this reads each run's own stage times, so that a
change to one stage is seen without the reading and writing around it.
"""

import json
import os
import statistics as st
import subprocess
import sys
import tempfile


def main():
    args = sys.argv[1:]
    pairs = 6
    if "--pairs" in args:
        i = args.index("--pairs")
        pairs = int(args[i + 1])
        del args[i : i + 2]
    if len(args) < 3:
        raise SystemExit(__doc__)
    a, b, inp, extra = args[0], args[1], args[2], args[3:]
    runs = {a: [], b: []}
    with tempfile.TemporaryDirectory() as tmp:
        out, rep = os.path.join(tmp, "out.ply"), os.path.join(tmp, "report.json")
        for _ in range(pairs):
            for exe in (a, b):
                cmd = [exe, "regularize", inp, "-o", out, "-q", "--report", rep] + extra
                subprocess.run(cmd, check=True)
                with open(rep) as f:
                    runs[exe].append(json.load(f)["stages"])
    for exe in (a, b):
        rs = runs[exe]
        stages = {k: round(st.median(r[k] for r in rs), 3) for k in rs[0]}
        print(f"{exe}: sum {st.median(sum(r.values()) for r in rs):.3f} s, stages {stages}")
    ratios = [sum(x.values()) / sum(y.values()) for x, y in zip(runs[a], runs[b])]
    print(f"A/B compute per pair: median {st.median(ratios):.3f}, min {min(ratios):.3f}, max {max(ratios):.3f}")


if __name__ == "__main__":
    main()
