"""DDPG update benchmark: one `DDPG.update` of the default learner (batch 256, the default widths) alone, on one core,
on random batches — the time of its first call (where the compiled update is built), the median of the next ones,
and the PyTorch operations one update runs (`torch.profiler`). It imports only `DDPG.update`, so the same file
measures an older checkout's update too (PYTHONPATH=that checkout).

Run: python benchmarks/update.py [--updates N]. Prints a table; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile

from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.networks import obs_scaling
from mrguide.policies.replay_buffer import Batch
from mrguide.robot import Workspace
from mrguide.task import ACT_DIM, OBS_DIM

BATCH = 256
EXPERT = 30  # expert samples per batch: the BC term acts


def batches(n: int, rng: np.random.Generator) -> list[Batch]:
    out = []
    for _ in range(n):
        obs = rng.normal(size=(BATCH, OBS_DIM)).astype(np.float32)
        act = rng.uniform(-1, 1, (BATCH, ACT_DIM)).astype(np.float32)
        rew = rng.normal(size=BATCH).astype(np.float32)
        expert = np.arange(BATCH) < EXPERT
        out.append(Batch(obs, act, rew, obs + 0.01, np.zeros(BATCH, np.float32), expert, EXPERT / BATCH))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--updates", type=int, default=2000)
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    torch.set_num_threads(1)
    ws = Workspace(np.array([0.3, -0.3, 0.0]), np.array([0.8, 0.3, 0.5]))
    agent = DDPG(*obs_scaling(ws), ACT_DIM, DDPGConfig(), seed=0)
    data = batches(50, np.random.default_rng(0))
    start = time.perf_counter()
    agent.update(data[0])
    first = time.perf_counter() - start
    for b in data[1:20]:
        agent.update(b)
    times = []
    for k in range(args.updates):
        start = time.perf_counter()
        agent.update(data[k % len(data)])
        times.append(time.perf_counter() - start)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for b in data:
            agent.update(b)
    ops = sum(e.count for e in prof.key_averages() if e.key.startswith("aten::")) / len(data)
    res = {"first_update_s": first, "update_ms_median": float(np.median(times)) * 1e3, "aten_ops_per_update": ops}
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, one core")
    print(f"{'first update (builds the compiled one)':<42} {first:.2f} s")
    print(f"{'update, median of ' + str(args.updates):<42} {res['update_ms_median']:.2f} ms")
    print(f"{'PyTorch (aten) operations per update':<42} {ops:.0f}")
    print(json.dumps({k: round(v, 4) for k, v in res.items()}))


if __name__ == "__main__":
    main()
