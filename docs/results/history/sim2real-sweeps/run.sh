#!/usr/bin/env bash
# Issue 17 item 4: one sweep each of actuator_lag (condition 2) and tracking_noise_m (condition 3) for the 20k-step
# guided policy of training seed 0 (docs/results/sim2real-v4-compliance/guided/seed0/policy.npz), 3 evaluation
# seeds x 10 episodes per value, in the real cell of configs/real_cell.toml. 2026-11-30, 2-core VM.
set -euo pipefail
P=docs/results/sim2real-v4-compliance/guided/seed0/policy.npz
mrguide sim2real --policy $P --sweep actuator_lag=0,0.015,0.03,0.06 --seeds 3 --episodes 10 --out runs/sweep-lag
mrguide sim2real --policy $P --sweep tracking_noise_m=0,0.003,0.01,0.02 --seeds 3 --episodes 10 --out runs/sweep-track
# where the lag sweep's drive faults happened:
python docs/results/sim2real-sweeps/fault_phases.py docs/results/sim2real-sweeps/actuator_lag
