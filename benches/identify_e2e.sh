#!/usr/bin/env bash
# Whole-process benchmark of what a user runs (issue 17): `wheelid identify FILE --estimator ls`
# and the default estimator, against the thesis pipeline in scipy (benches/identify_scipy.py
# --once: loadtxt, butter + sosfiltfilt, gradient, lstsq), each a fresh process that parses the
# file, on a 1,000,000-row recording (50 Hz, 48 MB CSV) of the simulated Khepera III. Runs are
# paired and repeated; prints median wall times, the ratio, and peak resident memory.
#
#   bash benches/identify_e2e.sh [ROWS] [REPEATS]      (defaults 1000000, 3)
#
# Needs python3 with numpy and scipy (installed with pip into a venv under target/ if absent).
set -euo pipefail
cd "$(dirname "$0")/.."
rows="${1:-1000000}"
repeats="${2:-3}"
work="target/bench-e2e"
mkdir -p "$work"
cargo build --release --locked --quiet
bin="target/release/wheelid"

py=python3
if ! $py -c "import numpy, scipy" 2>/dev/null; then
  if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install --quiet numpy scipy
  fi
  py="$work/venv/bin/python"
fi

csv="$work/rec_${rows}.csv"
if [ ! -s "$csv" ]; then
  seconds=$(awk -v n="$rows" 'BEGIN { printf "%.2f", (n - 1) * 0.02 }')
  "$bin" simulate --robot khepera3 --excitation multisine --duration "$seconds" --seed 7 \
    --out "$csv" >/dev/null
fi
echo "recording: $csv, $(($(grep -vc '^#' "$csv") - 1)) rows, $(du -m "$csv" | cut -f1) MB"

# run NAME CMD…: wall seconds and peak RSS (MiB) of one process, appended to $work/NAME.
run() {
  local name="$1"
  shift
  /usr/bin/time -f "%e %M" -o "$work/$name.last" "$@" >/dev/null
  read -r wall kb <"$work/$name.last"
  echo "$wall $((kb / 1024))" >>"$work/$name.runs"
}

rm -f "$work"/*.runs
for _ in $(seq "$repeats"); do
  run scipy "$py" benches/identify_scipy.py "$csv" --once
  run ls "$bin" identify "$csv" --estimator ls
  run oe "$bin" identify "$csv"
done

median() { sort -n | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }'; }
peak() { awk '{ if ($2 > m) m = $2 } END { print m }'; }
for name in scipy ls oe; do
  printf "%-6s wall median %6.2f s  peak RSS %5d MiB  (runs: %s)\n" "$name" \
    "$(cut -d' ' -f1 "$work/$name.runs" | median)" "$(peak <"$work/$name.runs")" \
    "$(cut -d' ' -f1 "$work/$name.runs" | paste -sd' ')"
done
s=$(cut -d' ' -f1 "$work/scipy.runs" | median)
l=$(cut -d' ' -f1 "$work/ls.runs" | median)
o=$(cut -d' ' -f1 "$work/oe.runs" | median)
awk -v s="$s" -v l="$l" -v o="$o" -v ms="$(peak <"$work/scipy.runs")" -v ml="$(peak <"$work/ls.runs")" 'BEGIN {
  printf "ls: %.2f× faster than scipy (goal ≥ 10×), peak memory %.2f of scipy'"'"'s (goal ≤ 0.33)\n", s / l, ml / ms
  printf "default (oe): %.2f s (goal ≤ 2 s)\n", o
}'
