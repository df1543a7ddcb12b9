#!/bin/bash
# Bytes on disk per hour of driving: the store and the raw log, at the bundled session's
# traffic (the demo: the session replayed at recorded speed through the whole pipeline).
# usage: tools/disk_per_hour.sh AER_RAW_BINARY WORK_DIR [SECONDS]
# Runs the demo for SECONDS (default 45, one pass of the session), stops it with SIGINT, then
# measures the raw log folder and the store as recorded and after `aer-raspi compact` (what
# the running service does to every closed session), each less an empty store. A binary from
# before `compact` existed reports the store as recorded only.
set -euo pipefail
bin=$(realpath "$1"); dir=$2; secs=${3:-45}
mkdir -p "$dir"; dir=$(realpath "$dir"); rm -rf "${dir:?}"/*
source "$(dirname "$0")/pi_measure.sh"
measure_config "$dir"
sed "s|$dir/store.sqlite|$dir/empty.sqlite|" "$dir/cfg.toml" > "$dir/empty.toml"
"$bin" --config "$dir/empty.toml" session list > /dev/null
sqlite3 "$dir/empty.sqlite" "PRAGMA wal_checkpoint(TRUNCATE)" > /dev/null
empty=$(stat -c %s "$dir/empty.sqlite")
timeout -s INT "$secs" "$bin" --config "$dir/cfg.toml" demo > "$dir/run.log" 2>&1 || true
sqlite3 "$dir/store.sqlite" "PRAGMA wal_checkpoint(TRUNCATE)" > /dev/null
recorded=$(stat -c %s "$dir/store.sqlite")
raw=$(du -cb "$dir"/raw/* | tail -1 | awk '{print $1}')
compacted=""
if "$bin" --config "$dir/cfg.toml" compact > "$dir/compact.log" 2>&1; then
  compacted=$(stat -c %s "$dir/store.sqlite")
fi
awk -v t="$secs" -v e="$empty" -v s="$recorded" -v c="$compacted" -v r="$raw" 'BEGIN {
  h = 3600 / t / 1e6
  printf "store as recorded %.1f MB/h", (s - e) * h
  if (c != "") printf ", compacted %.1f MB/h", (c - e) * h
  printf "; raw log %.1f MB/h\n", r * h }'
