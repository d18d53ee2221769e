#!/usr/bin/env bash
# Identification on the rigid-body backend over more seeds than CI runs: every profile, every
# stamping convention (a)-(c), with and without ±10 % host jitter, encoders on, timing metadata
# removed; prints one line per run (θ1, θ2, θ4, θ6 error in % of the map's θ, and the timing the
# default identify reported) and fails on the first run outside the test's tolerance.
#   usage: scripts/physics_accuracy.sh [SEEDS]   (default 5; CI runs 1)
set -euo pipefail
cd "$(dirname "$0")/.."
seeds="${1:-5}"
WHEELID_PHYSICS_SEEDS="$seeds" cargo test --release --locked --test physics_identify -- \
  --nocapture --test-threads 2 2>&1 | grep -E "seed|error θ|test result|panicked"
