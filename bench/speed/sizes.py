#!/usr/bin/env python3
"""How the default run's cost grows with the input: time and memory per surfel.

Runs the release CLI with its default options on the ``synth-labels`` tissue (25 labels)
scaled from about 50k to about 5M surfels (the same body and organs, the volume's three
dimensions scaled by one factor), one child process per run, smallest first, and prints
per size the surfels, the compute time (the report's stages without reading and
writing), microseconds and bytes of peak memory per surfel, and the largest over the
smallest time per surfel. Standard library only (no numpy: the volumes are made by
``cargo xtask synth-labels`` under target/bench/ when missing).

    cargo build --release -p voxreg-cli
    python3 bench/speed/sizes.py                 # factors 0.22 0.5 1 1.83 (46k to 5.3M surfels), one run each
    python3 bench/speed/sizes.py --runs 3 --factors 0.22,0.25
"""

import argparse
import os
import statistics
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from vs_vtk import ROOT, tissue, voxreg_run  # noqa: E402

BASE = (500, 470, 136)  # the synth-labels default: 1.52M surfels


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--factors", default="0.22,0.5,1,1.83", help="scale factors of the dimensions")
    ap.add_argument("--runs", type=int, default=1, help="runs per size (medians are printed)")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "voxreg"))
    args = ap.parse_args()
    rows = []
    for f in (float(x) for x in args.factors.split(",")):
        dims = ",".join(str(max(8, round(d * f))) for d in BASE)
        path = tissue(dims)
        runs = []
        with tempfile.TemporaryDirectory() as tmp:
            for _ in range(args.runs):
                runs.append(voxreg_run(args.exe, path, False, tmp))
        compute = statistics.median(r["compute"] for r in runs)
        peak = statistics.median(r["peak"] for r in runs)
        surfels = runs[0]["faces"]
        rows.append((dims, surfels, compute, peak))
        print(
            f"{dims}: {surfels} surfels, compute {compute:.2f} s ({1e6 * compute / surfels:.1f} us/surfel), "
            f"peak {peak:.0f} MiB ({peak * 1048576 / surfels:.0f} B/surfel)",
            file=sys.stderr,
        )
    print("| tissue dims | surfels | compute | per surfel | peak | peak per surfel |")
    print("|---|---|---|---|---|---|")
    for dims, surfels, compute, peak in rows:
        print(
            f"| {dims.replace(',', ' x ')} | {surfels:,} | {compute:.2f} s | {1e6 * compute / surfels:.1f} us | "
            f"{peak:,.0f} MiB | {peak * 1048576 / surfels:,.0f} B |"
        )
    per = [c / s for _, s, c, _ in rows]
    print(f"\nlargest / smallest time per surfel: {max(per) / min(per):.2f}")


if __name__ == "__main__":
    main()
