#!/usr/bin/env bash
# Online identification (issue 18) against the batch output-error answer over more seeds than
# CI runs: each rigid-body profile (Pioneer-like 150 s, Khepera-like 60 s) driven on SEEDS
# seeds from FIRST (default 20 from 41: seeds 1–10 were looked at while building the jitter
# correction and the output-error form, 41–60 never before the report in the README), the
# host's stamps jittered by ± 10 % of the period; prints each seed's θ1, θ2, θ4, θ6 in per
# cent of the batch answer and in the online standard errors, and the worst |z| (the test
# asserts < 1.96). CI runs 3 seeds.
#   usage: scripts/online_spread.sh [SEEDS] [FIRST]   (about 80 s at 20 seeds)
set -euo pipefail
cd "$(dirname "$0")/.."
WHEELID_ONLINE_SEEDS="${1:-20}" WHEELID_ONLINE_FIRST_SEED="${2:-41}" \
  cargo test --release --locked --test online -- under_host_jitter --nocapture \
  --test-threads 1 2>&1 | grep -E "seed|worst|% of batch|test result|panicked"
