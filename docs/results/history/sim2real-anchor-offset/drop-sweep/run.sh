#!/usr/bin/env bash
# Which reality-gap parameter makes Fig. 7's configuration drop parts in the real cell's lift? The sim-to-real
# policy of training seed 2 (../guided/seed2/policy.npz: 3 of 30 dropped in condition 2), condition 2, 3
# evaluation seeds x 20 episodes per value, one parameter at a time (the others as in configs/real_cell.toml,
# whose values are object_mass 0.3, suction_break_force 25, actuator_lag 0.015, actuator_latency 2).
# The two commands ran side by side on the 2-core VM, 2026-11-30; the tables are sim2real.csv/.md in a/ and b/
# (the deploy run logs, 34 MB, are not committed).
set -euo pipefail
P=docs/results/sim2real-anchor-offset/guided/seed2/policy.npz
D=docs/results/sim2real-anchor-offset/drop-sweep
mrguide sim2real --policy $P --seeds 3 --episodes 20 --sweep object_mass=0.1,0.3 --sweep suction_break_force=25,50 --out $D/a --quiet &
mrguide sim2real --policy $P --seeds 3 --episodes 20 --sweep actuator_lag=0,0.015 --sweep actuator_latency=0,2 --out $D/b --quiet &
wait
