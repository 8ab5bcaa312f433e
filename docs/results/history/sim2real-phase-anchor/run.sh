#!/usr/bin/env bash
# The phase_anchor actor under the three sim-to-real conditions: the final 20k-step guided policies of training
# seeds 0-2 of docs/results/learning-curves-phase-anchor (`mrguide experiment learning-curves --config
# configs/experiments/learning_curves_phase_anchor.toml`; policy.npz copied here), each for 3 evaluation seeds
# x 10 episodes in the real cell (configs/real_cell.toml is the default real config). Two policies at a time on
# the 2-core VM, 2026-11-30. Then: python docs/results/sim2real-main5k-v2/pool.py docs/results/sim2real-phase-anchor
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
for s in 0 1 2; do
  mrguide sim2real --policy $HERE/seed$s/policy.npz --seeds 3 --episodes 10 --out $HERE/seed$s/sim2real --quiet &
  if [ $s = 1 ]; then wait; fi
done
wait
