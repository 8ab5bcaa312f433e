#!/usr/bin/env bash
# Issue 17 item 4: the main job's policy (the first 5,000 steps of the default 20k-step guided schedule, as
# `./run.sh main` trains it) for training seeds 0-2, each under the three sim-to-real conditions for 3 evaluation
# seeds x 10 episodes, in the real cell of configs/real_cell.toml (12 mm cup level-compensator; the HMD draws
# the arm). 2026-11-30, 2-core VM, one other real-time dry run beside it. Then: python pool.py
set -euo pipefail
OUT=${OUT:-runs/main5k}
for s in 0 1 2; do
  mrguide train --stop-after 5000 --seed $s --out $OUT/seed$s --quiet
  mrguide sim2real --policy $OUT/seed$s/policy.npz --seeds 3 --episodes 10 --out $OUT/seed$s/sim2real --quiet
done
