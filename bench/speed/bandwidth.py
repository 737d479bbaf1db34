#!/usr/bin/env python3
"""The machine's streaming memory bandwidth: `b = 2 a` over float32 arrays far larger
than the caches, in one process per core at once, counting 12 bytes an element (the read
of `a`, the write of `b` and its read for ownership). The bound a memory-bound pass can
reach, for the bytes-moved bounds in docs/design/fast-preset.md.

    python3 bench/speed/bandwidth.py [--procs N] [--mib SIZE] [--rounds R]

Prints each round's total GB/s and the best.
"""

import argparse
import multiprocessing as mp
import os
import time

import numpy as np


def stream(mib, rounds, start, results):
    n = mib * (1 << 20) // 4
    a = np.arange(n, dtype=np.float32)
    b = np.zeros(n, dtype=np.float32)
    np.multiply(a, 2.0, out=b)  # pages touched before timing
    for r in range(rounds):
        start.wait()
        t = time.perf_counter()
        np.multiply(a, 2.0, out=b)
        results.put((r, 12 * n, time.perf_counter() - t))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--procs", type=int, default=os.cpu_count() or 1, help="processes at once (default: the cores)")
    ap.add_argument("--mib", type=int, default=200, help="MiB of each of a process's two arrays (default 200)")
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds (default 5)")
    args = ap.parse_args()
    start = mp.Barrier(args.procs)
    results = mp.Queue()
    procs = [mp.Process(target=stream, args=(args.mib, args.rounds, start, results)) for _ in range(args.procs)]
    for p in procs:
        p.start()
    rounds = {}
    for _ in range(args.procs * args.rounds):
        r, nbytes, secs = results.get()
        rounds.setdefault(r, []).append((nbytes, secs))
    for p in procs:
        p.join()
    best = 0.0
    for r in sorted(rounds):
        # The processes start together: the round lasts as long as its slowest one.
        total = sum(b for b, _ in rounds[r]) / max(s for _, s in rounds[r]) / 1e9
        best = max(best, total)
        print(f"round {r + 1}: {total:.1f} GB/s on {args.procs} processes")
    print(f"best: {best:.1f} GB/s")


if __name__ == "__main__":
    main()
