#!/usr/bin/env bash
# Runs every fuzz target for a bounded time: SECONDS each (default 10), libFuzzer's memory
# limit 2 GiB, seeded from fuzz/seeds/<target>/ with the dictionary fuzz/dict/<target>.dict.
# New inputs go to fuzz/corpus/<target>/ (ignored by git); a crash stops the run, leaves its
# input in fuzz/artifacts/<target>/ and should be copied to fuzz/seeds/<target>/ as a
# regression (crates/io's `fuzz_corpora_replay_without_panic` replays the seeds).
# Needs a nightly toolchain and cargo-fuzz.
set -euo pipefail
cd "$(dirname "$0")"
SECONDS_EACH="${1:-10}"
TOOLCHAIN="${FUZZ_TOOLCHAIN:-nightly}"
targets=$(sed -n 's/^name = "\(.*\)"$/\1/p' Cargo.toml | grep -v '^voxreg-fuzz$')
cargo +"$TOOLCHAIN" fuzz build --release
mkdir -p logs
for t in $targets; do
    mkdir -p "corpus/$t"
    echo "== fuzz $t (${SECONDS_EACH}s)"
    status=0
    cargo +"$TOOLCHAIN" fuzz run --release "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time="$SECONDS_EACH" -rss_limit_mb=2048 -dict="dict/$t.dict" -print_final_stats=1 \
        >"logs/$t.log" 2>&1 || status=$?
    grep -E "^(stat::number_of_executed_units|stat::peak_rss_mb|SUMMARY)" "logs/$t.log" || true
    if [ "$status" -ne 0 ]; then
        tail -n 30 "logs/$t.log"
        echo "fuzz $t failed (exit $status): the input is in fuzz/artifacts/$t"
        exit 1
    fi
done
