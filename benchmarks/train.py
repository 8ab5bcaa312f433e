"""Training benchmark: a guided 20k-step run on one core — steps/s, update time, wall time — and, in the same run on
the same core, the twin alone for as many decisions (the scripted expert acting), so that the cost of learning is a
ratio that a busier or quieter day of a shared machine changes less than it changes seconds.

The update is compiled by TorchInductor on its first call (`mrguide.policies.ddpg_update`), which costs ~30 s the
first time on a machine and ~5 s once its build is in TorchInductor's cache; the wall time includes it, and `--cold`
measures with an empty cache.

`--learner-process` trains with the learner in a process of its own (`train.learner_process = true`) on the
machine's second core, the actor (env loop, guidance) on the first; the wall time includes the learner's start
(its process, torch's import, the update's build), and the twin alone runs on the first core as before.

Run: python benchmarks/train.py [--steps N] [--config FILE] [--cold] [--learner-process]. Prints a table; the last
line is one JSON object.
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

from mrguide.policies.learner_process import LearnerProcess
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


class TimedTrainer(Trainer):
    """A trainer that sums the wall time of its evaluations (part of training's wall time, not of the twin's)."""

    evaluation_s = 0.0

    def evaluate(self) -> dict:
        t = time.perf_counter()
        try:
            return super().evaluate()
        finally:
            self.evaluation_s += time.perf_counter() - t


def pin_process(pid: int, core: int) -> None:
    """Every thread of process `pid` onto `core` (an affinity is a thread's: those already started keep theirs)."""
    for tid in os.listdir(f"/proc/{pid}/task"):
        os.sched_setaffinity(int(tid), {core})


def train_run(run: RunConfig, cores: list[int]) -> tuple[TimedTrainer, float]:
    """The run, in a scratch directory; (its trainer, the seconds it took to start: a learner process's included, put
    on the second of `cores`)."""
    with tempfile.TemporaryDirectory() as out:
        t = time.perf_counter()
        tr = TimedTrainer(run, out)
        start = time.perf_counter() - t
        try:
            if isinstance(tr.learning, LearnerProcess) and tr.learning.process.pid and len(cores) > 1:
                pin_process(tr.learning.process.pid, cores[1])
            tr.run()
        finally:
            tr.close()
    return tr, start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--config", help="training config (TOML); default: the built-in defaults")
    ap.add_argument("--cold", action="store_true", help="compile the update with an empty TorchInductor cache")
    ap.add_argument("--learner-process", action="store_true", help="the learner in its own process, on the second core")
    args = ap.parse_args()
    scratch = tempfile.TemporaryDirectory() if args.cold else None
    if scratch:
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = scratch.name
    cache = cache_dir()  # made if missing
    warm = any(Path(cache).iterdir())
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_setaffinity") else []
    if cores:
        os.sched_setaffinity(0, {cores[0]})
    run = RunConfig.load(args.config)
    train = dataclasses.replace(
        run.train, total_steps=args.steps, checkpoint_every=args.steps, learner_process=args.learner_process
    )
    run = run.replace(train=train)
    tc, ec = run.train, run.env
    tr, start = train_run(run, cores)
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
        "start_s": start,
        "evaluation_s": tr.evaluation_s,
        "final_eval_success": tr.last_eval.get("success_rate"),
        "learner_process": args.learner_process,
        "learner_updates": tr.agent.updates,
        "weights_version": tr.learning.version if isinstance(tr.learning, LearnerProcess) else None,
        "annotations_asked": tr.counters.asked,
        "compile_cache": "not empty" if warm else "empty",
    }
    if scratch:
        scratch.cleanup()
    where = "the actor on one core, the learner on another" if args.learner_process else "pinned to one core"
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, {where}")
    print(f"{'guided training steps':<40} {tr.counters.step}")
    print(f"{'TorchInductor cache at the start':<40} {res['compile_cache']} ({cache})")
    print(f"{'steps/s (env + update)':<40} {res['steps_per_s']:.1f}")
    print(f"{'learner updates':<40} {tr.agent.updates}")
    hidden = "x".join(map(str, run.learner.hidden))
    print(f"{f'update (batch {tc.batch_size}, {hidden} MLPs)':<40} {res['update_ms']:.2f} ms")
    print(f"{'wall time, scaled to 20k steps':<40} {res['wall_s_20k']:.0f} s")
    print(f"{'of which: the start / the evaluations':<40} {start:.1f} s / {tr.evaluation_s:.1f} s")
    print(f"{'the twin alone, as many decisions':<40} {twin:.0f} s")
    target = 1.5 if args.learner_process else 2.5
    print(f"{'training / twin alone':<40} {res['ratio_to_twin']:.2f}   (target <= {target})")
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in res.items()}))


if __name__ == "__main__":
    main()
