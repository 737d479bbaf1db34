#!/usr/bin/env python3
"""Where a run leaves one of its two busiest threads idle, from a `perf` profile.

    perf record -F 4000 --call-graph dwarf,8192 -o perf.data voxreg regularize IN -o out.ply -q
    perf script -i perf.data -F tid,time,ip,sym > samples.txt
    python3 bench/speed/idle_threads.py samples.txt [--bucket 0.003]

The samples are cut into time buckets (a few sampling periods each: 3 ms at 4000 Hz,
20 ms at 500 Hz); in a bucket where one of the two threads with the most samples has none,
the other thread's samples are charged to the innermost voxreg function of their stacks.
Prints the seconds of such buckets per function, largest first: serial work, or the tail
of a parallel pass that one thread finishes alone.
"""

import argparse
import collections
import re


def read_samples(path):
    """(tid, time, frames innermost first) per sample of `perf script -F tid,time,ip,sym`."""
    samples, current = [], None
    with open(path) as f:
        for line in f:
            header = re.match(r"\s*(\d+)\s+([\d.]+):", line)
            if not line.strip():
                if current:
                    samples.append(current)
                current = None
            elif header and not line.startswith("\t"):
                current = (int(header.group(1)), float(header.group(2)), [])
            elif current is not None:
                parts = line.strip().split(None, 1)
                if len(parts) == 2:
                    current[2].append(parts[1])
    if current:
        samples.append(current)
    return samples


def innermost_voxreg(frames):
    for f in frames:
        if "voxreg" in f and "call_mut" not in f and "closure" not in f:
            return f[:100]
    return "(outside voxreg)"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("samples")
    ap.add_argument("--bucket", type=float, default=0.003, help="seconds (default 0.003)")
    ap.add_argument("--top", type=int, default=20)
    args = ap.parse_args()
    samples = read_samples(args.samples)
    busiest = [t for t, _ in collections.Counter(s[0] for s in samples).most_common(2)]
    if len(busiest) < 2:
        raise SystemExit("fewer than two threads sampled")
    buckets = collections.defaultdict(lambda: ([0, 0], collections.Counter()))
    for tid, time, frames in samples:
        if tid in busiest:
            counts, where = buckets[int(time / args.bucket)]
            counts[busiest.index(tid)] += 1
            where[innermost_voxreg(frames)] += 1
    alone = collections.Counter()
    for counts, where in buckets.values():
        if 0 in counts:
            alone[where.most_common(1)[0][0]] += args.bucket
    total = sum(alone.values())
    span = (max(s[1] for s in samples) - min(s[1] for s in samples)) if samples else 0.0
    print(f"one thread idle: {total:.2f} s of {span:.2f} s sampled")
    for name, seconds in alone.most_common(args.top):
        print(f"{seconds:7.3f} s  {name}")


if __name__ == "__main__":
    main()
