#!/usr/bin/env bash
# Experiment design (issue 18) over more seeds than CI runs: the D-optimal multisine of each
# rigid-body profile driven on SEEDS seeds from FIRST (default 80 from 41: seeds 1–6 were looked
# at while choosing the design's settings, 21–40 in the 20-seed proof), identified by output
# error; prints the designed drive, the worst error of θ1, θ2, θ4, θ6 against the map, and the
# spread over the seeds against the predicted standard errors (the test asserts each ratio
# within the 99.9 % sampling band of an exact prediction from 20 seeds on — 0.50–1.56 at 20 —
# and within 30 % from 65 seeds on). CI runs 6 seeds.
#   usage: scripts/design_spread.sh [SEEDS] [FIRST]   (about 2 min per profile at 80 seeds)
set -euo pipefail
cd "$(dirname "$0")/.."
WHEELID_DESIGN_SEEDS="${1:-80}" WHEELID_DESIGN_FIRST_SEED="${2:-41}" \
  cargo test --release --locked --test design -- a_designed_drive --nocapture \
  --test-threads 1 2>&1 | grep -E "lines to|spread|test result|panicked"
