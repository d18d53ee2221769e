#!/usr/bin/env bash
# Fuzzes one reader with AFL++ for a set time and prints what it found.
#
#   bash fuzz/run.sh TARGET SECONDS      TARGET: csv | mcap | model | run
#
# Needs AFL++ (`apt-get install afl++`) and cargo-afl (`cargo install cargo-afl`); builds the
# instrumented targets (`cargo afl build --release` in fuzz/), starts from fuzz/corpus/TARGET
# and writes findings to fuzz/out/TARGET (crashes/ and hangs/ hold the inputs to replay:
# `fuzz/target/release/TARGET < FILE`). Any crash found becomes a regression test.
set -euo pipefail
cd "$(dirname "$0")"
target="${1:?target: csv | mcap | model | run}"
seconds="${2:-3600}"
cargo afl build --release --quiet
mkdir -p out
export AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_NO_UI=1
# A fresh run, or a resumed one (`-i -`) when its output directory exists.
input="corpus/$target"
[ -d "out/$target/default" ] && input="-"
cargo afl fuzz -i "$input" -o "out/$target" -V "$seconds" -t 2000 -m none \
  "target/release/$target" >"out/$target.log" 2>&1 || true
stats="out/$target/default/fuzzer_stats"
awk -F' *: *' '/^(run_time|execs_done|execs_per_sec|corpus_count|saved_crashes|saved_hangs|bitmap_cvg|stability)/ { printf "%s=%s  ", $1, $2 } END { print "" }' "$stats"
