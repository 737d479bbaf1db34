#!/usr/bin/env python3
"""Two commands timed against each other, run by run: A B A B ... after a warm-up.

    python3 bench/speed/ab.py -n 10 --vs "voxreg regularize in.npy -o b.ply -q" -- voxreg regularize in.npy -o a.ply -q

Prints, for A and B, the wall time, CPU time (user + system) and peak resident memory of
each run (min, median, max), and the A/B ratios taken pair by pair, so that the machine's
drift during the call cancels. Quote the medians. Standard library only (Linux: the peak
is the child's `ru_maxrss`).
"""

import argparse
import os
import shlex
import statistics
import subprocess
import time


def run(cmd):
    """Wall seconds, CPU seconds and peak MiB of one run of `cmd` (a list)."""
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{shlex.join(cmd)}: exit status {os.waitstatus_to_exitcode(status)}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def row(name, values, fmt):
    lo, med, hi = min(values), statistics.median(values), max(values)
    print(f"{name:<14}{fmt.format(lo):>10}{fmt.format(med):>10}{fmt.format(hi):>10}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=5, help="pairs (default 5)")
    ap.add_argument("--warmup", type=int, default=1, help="unmeasured pairs first (default 1)")
    ap.add_argument("--vs", required=True, help="command B, one string split as a shell would")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="command A, after --")
    args = ap.parse_args()
    a = args.command[1:] if args.command[:1] == ["--"] else args.command
    b = shlex.split(args.vs)
    if not a:
        ap.error("command A is missing (after --)")
    for _ in range(args.warmup):
        run(a)
        run(b)
    ra, rb = [], []
    for _ in range(args.n):
        ra.append(run(a))
        rb.append(run(b))
    print(f"{'':<14}{'min':>10}{'median':>10}{'max':>10}")
    for name, rs in (("A", ra), ("B", rb)):
        row(f"{name} wall s", [r[0] for r in rs], "{:.3f}")
        row(f"{name} cpu s", [r[1] for r in rs], "{:.3f}")
        row(f"{name} peak MiB", [r[2] for r in rs], "{:.1f}")
    row("A/B wall", [x[0] / y[0] for x, y in zip(ra, rb)], "{:.4f}")
    row("A/B cpu", [x[1] / y[1] for x, y in zip(ra, rb)], "{:.4f}")


if __name__ == "__main__":
    main()
