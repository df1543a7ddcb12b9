#!/bin/bash
# Bytes the Pi service writes to disk per minute, and how fast its store and raw log grow, at
# the car's traffic (the bundled session replayed in a loop: 100 telemetry packets/s with both
# buses' frames, as the CCM's logic sent them in the car model).
# usage: tools/store_writes.sh AER_RAW_BINARY WORK_DIR SECONDS
# Reads /proc/<pid>/io write_bytes (what reached the block layer, WAL and checkpoints included)
# over SECONDS after a 10 s warm-up, then stops the service with SIGINT.
set -euo pipefail
bin=$(realpath "$1"); dir=$2; secs=$3
mkdir -p "$dir"; dir=$(realpath "$dir"); rm -rf "${dir:?}"/*
source "$(dirname "$0")/pi_measure.sh"
measure_config "$dir"
size() { du -cb "$@" 2>/dev/null | tail -1 | awk '{print $1}'; }
"$bin" --config "$dir/cfg.toml" replay --loop > "$dir/run.log" 2>&1 &
pid=$!
sleep 10
w0=$(awk '/^write_bytes/ {print $2}' "/proc/$pid/io")
s0=$(size "$dir"/store.sqlite*); r0=$(size "$dir/raw")
sleep "$secs"
w1=$(awk '/^write_bytes/ {print $2}' "/proc/$pid/io")
s1=$(size "$dir"/store.sqlite*); r1=$(size "$dir/raw")
kill -INT "$pid"; wait "$pid" || true
awk -v w=$((w1 - w0)) -v s=$((s1 - s0)) -v r=$((r1 - r0)) -v t="$secs" 'BEGIN {
  printf "written %.1f MiB/min, store %.1f MB/h, raw log %.1f MB/h\n",
    w / t * 60 / 1048576, s / t * 3600 / 1e6, r / t * 3600 / 1e6 }'
