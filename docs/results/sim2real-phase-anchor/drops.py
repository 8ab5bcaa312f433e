"""The dropped episodes of conditions 2 and 3 in this directory's run logs: for each, how far the cup's centre
(TCP) was from the part's centre in x/y at the first lift decision (the grasp that just sealed), the vacuum then,
and the supervisor's vacuum_lost detail.

    python docs/results/sim2real-phase-anchor/drops.py
"""
import gzip
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

offsets = []
for log in sorted(HERE.glob("seed*/sim2real/log-*.jsonl.gz")):
    rows = [json.loads(line) for line in gzip.open(log, "rt")]
    dropped = {r["episode"] for r in rows if r["kind"] == "episode_end" and r.get("outcome") == "dropped"}
    for ep in sorted(dropped):
        lift = next(r for r in rows if r["kind"] == "decision" and r.get("episode") == ep and r["phase"] == 2)
        obs = np.array(lift["obs"])
        off = 1000 * np.abs(obs[:2] - obs[5:7])
        offsets.append(off.max())
        print(f"{log.parent.parent.name}/{log.name[4:-9]} episode {ep}: cup off the part's centre by "
              f"{off[0]:.0f} / {off[1]:.0f} mm (x / y), vacuum {lift['vacuum_kpa']:.0f} kPa at the first lift decision")
print(f"{len(offsets)} drops; larger axis offset median {np.median(offsets):.0f} mm, range {min(offsets):.0f}-{max(offsets):.0f} mm")
