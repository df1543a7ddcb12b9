#!/bin/bash
# Instructions per frame for each codec and operation on the same frames (bench/src/lib.rs),
# counted by callgrind inside the operation's own function only (set-up excluded), so the
# figures do not move with the machine's load as times do.
# usage: tools/codec_instructions.sh [ROUNDS]   (needs valgrind and the project's .venv)
set -euo pipefail
rounds=${1:-200}
cd "$(dirname "$0")/../bench"
cargo build --quiet --release --bin instructions
bin=target/release/instructions
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
printf '%-8s %-7s %12s %12s %12s\n' dbc op aer-codegen dbc-codegen cantools-c
for suite in aer vehicle; do
  for op in decode encode; do
    row=()
    for codec in ours peer c; do
      out="$work/$suite-$codec-$op.out"
      frames=$(valgrind --tool=callgrind --callgrind-out-file="$out" \
        --toggle-collect="*${suite}_suite::${codec}_${op}*" "$bin" "$suite" "${codec}_${op}" "$rounds" 2>/dev/null)
      total=$(awk '/^summary:/ {print $2}' "$out")
      row+=("$(awk -v t="$total" -v n="$((frames * rounds))" 'BEGIN {printf "%.1f", t / n}')")
    done
    printf '%-8s %-7s %12s %12s %12s\n' "$suite" "$op" "${row[@]}"
  done
done
