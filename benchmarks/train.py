"""Training benchmark: a guided 20k-step run on one core — steps/s, update time, wall time — and, in the same run on
the same core, the twin alone for as many decisions (the scripted expert acting), so that the cost of learning is a
ratio that a busier or quieter day of a shared machine changes less than it changes seconds.

The update is compiled by TorchInductor on its first call (`mrguide.policies.ddpg_update`), which costs ~30 s the
first time on a machine and ~5 s once its build is in TorchInductor's cache; the wall time includes it, and `--cold`
measures with an empty cache.

Run: python benchmarks/train.py [--steps N] [--config FILE] [--cold]. Prints a table; the last line is one JSON
object.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from torch._inductor.runtime.cache_dir_utils import cache_dir

from mrguide.policies.train import Trainer
from mrguide.policies.train_config import RunConfig
from mrguide.task import oracle_action
from mrguide.twin.env import EnvConfig, PickPlaceEnv


def twin_alone(ec: EnvConfig, decisions: int) -> float:
    """Wall time (s) of `decisions` steps of the twin driven by the scripted expert, episodes reset as they end."""
    env = PickPlaceEnv(ec)
    try:
        obs, _ = env.reset(seed=0)
        start = time.perf_counter()
        for k in range(decisions):
            obs, _, term, trunc, _ = env.step(oracle_action(obs, env.task_cfg, env.workspace.to_normalized))
            if term or trunc:
                obs, _ = env.reset(seed=k + 1)
        return time.perf_counter() - start
    finally:
        env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--config", help="training config (TOML); default: the built-in defaults")
    ap.add_argument("--cold", action="store_true", help="compile the update with an empty TorchInductor cache")
    args = ap.parse_args()
    scratch = tempfile.TemporaryDirectory() if args.cold else None
    if scratch:
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = scratch.name
    cache = cache_dir()  # made if missing
    warm = any(Path(cache).iterdir())
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    run = RunConfig.load(args.config)
    run = run.replace(train=dataclasses.replace(run.train, total_steps=args.steps, checkpoint_every=args.steps))
    tc, ec = run.train, run.env
    with tempfile.TemporaryDirectory() as out:
        tr = Trainer(run, out)
        try:
            tr.run()
        finally:
            tr.close()
    wall = tr.wall_s()
    twin = twin_alone(ec, tr.counters.step)
    res = {
        "learner": tc.learner,
        "steps": tr.counters.step,
        "steps_per_s": tr.counters.step / wall,
        "update_ms": tr.update_ms(),
        f"wall_s_{args.steps // 1000}k": wall,
        "wall_s_20k": wall * 20_000 / tr.counters.step,
        "twin_alone_s": twin,
        "ratio_to_twin": wall / twin,
        "final_eval_success": tr.last_eval.get("success_rate"),
        "annotations_asked": tr.counters.asked,
        "compile_cache": "not empty" if warm else "empty",
    }
    if scratch:
        scratch.cleanup()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, pinned to one core"
    )
    print(f"{'guided training steps':<40} {tr.counters.step}")
    print(f"{'TorchInductor cache at the start':<40} {res['compile_cache']} ({cache})")
    print(f"{'steps/s (env + update)':<40} {res['steps_per_s']:.1f}")
    hidden = "x".join(map(str, run.learner.hidden))
    print(f"{f'update (batch {tc.batch_size}, {hidden} MLPs)':<40} {res['update_ms']:.2f} ms")
    print(f"{'wall time, scaled to 20k steps':<40} {res['wall_s_20k']:.0f} s")
    print(f"{'the twin alone, as many decisions':<40} {twin:.0f} s")
    print(f"{'training / twin alone':<40} {res['ratio_to_twin']:.2f}   (target <= 2.5)")
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in res.items()}))


if __name__ == "__main__":
    main()
