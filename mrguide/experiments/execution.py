"""Run many training runs on Ray: one task per run, 1 CPU each, on this machine or a cluster.

Locally `ray.init(num_cpus=workers)` starts a private Ray instance that ends with the experiment; with
`address` ("auto" on a cluster node, or "ray://head:10001" from outside) the runs go to an existing
cluster, whose nodes need the same mrguide installed. Finished runs are skipped before anything is
submitted; interrupted ones resume from their checkpoints (see `runs`). Ctrl-C cancels the tasks: what
they checkpointed stays.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tqdm import tqdm

from mrguide.experiments.train_runs import RunResult, TrainRun, finished, is_done, progress_steps, train

log = logging.getLogger(__name__)


class ExperimentError(RuntimeError):
    """One or more runs failed; the message names them and their errors."""


def run_all(
    runs: list[TrainRun], root: Path, workers: int = 2, address: str | None = None, show_progress: bool = True
) -> list[RunResult]:
    """Train every run not done yet (in parallel on Ray) and return the results of all of them."""
    import ray

    root.mkdir(parents=True, exist_ok=True)
    todo = [r for r in runs if not is_done(r, root)]
    if todo:
        with ray_session(workers, address):
            _execute(ray, todo, root, show_progress)
    return [finished(r, root) for r in runs]


def map_tasks(
    fn: Callable[..., Any],
    calls: list[tuple],
    workers: int = 2,
    address: str | None = None,
    desc: str = "tasks",
    show_progress: bool = True,
) -> list[Any]:
    """`fn(*args)` for every args tuple of `calls`, one Ray task each (1 CPU); results in order."""
    import ray

    if not calls:
        return []
    with ray_session(workers, address):
        task = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = [task.remote(*args) for args in calls]
        results: dict[Any, Any] = {}
        with tqdm(total=len(refs), desc=desc, disable=not show_progress) as bar:
            try:
                pending = list(refs)
                while pending:
                    ready, pending = ray.wait(pending, num_returns=1, timeout=2.0)
                    for ref in ready:
                        try:
                            results[ref] = ray.get(ref)
                        except Exception as exc:
                            raise ExperimentError(f"{desc}: a task failed: {_cause(exc)}") from None
                        bar.update(1)
            except KeyboardInterrupt:
                for ref in refs:
                    ray.cancel(ref, force=True)
                raise
        return [results[r] for r in refs]


@contextmanager
def ray_session(workers: int, address: str | None):
    """A private local Ray with `workers` CPUs, or a connection to the cluster at `address`; shut down after.
    Inside a session already open (an experiment's training and then its evaluations) it is that session: one
    Ray start and one pool of worker processes for both."""
    import ray

    if ray.is_initialized():
        yield
        return
    env = {"env_vars": {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "RAY_DEDUP_LOGS": "0"}}
    if address:
        ray.init(address=address, runtime_env=env, log_to_driver=False)
    else:
        os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a private instance on this machine
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, runtime_env=env)
    try:
        yield
    finally:
        ray.shutdown()


def _execute(ray, todo: list[TrainRun], root: Path, show_progress: bool) -> None:
    task = ray.remote(num_cpus=1, max_retries=0)(train)
    pending = {task.remote(run, str(root)): run for run in todo}
    total = sum(r.steps for r in todo)
    failures: list[str] = []
    with tqdm(total=total, unit="step", desc=f"{len(todo)} runs", disable=not show_progress) as bar:
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
                for ref in ready:
                    run = pending.pop(ref)
                    try:
                        ray.get(ref)
                    except Exception as exc:  # a run's own error: report it, let the others finish
                        failures.append(f"{run.name}: {_cause(exc)}")
                        log.error("run %s failed: %s", run.name, _cause(exc))
                bar.n = sum(min(progress_steps(r, root), r.steps) for r in todo)
                bar.refresh()
        except KeyboardInterrupt:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
    if failures:
        raise ExperimentError(f"{len(failures)} of {len(todo)} runs failed: " + "; ".join(failures))


def _cause(exc: Exception) -> str:
    """The original error inside a Ray task error, on one line."""
    cause = getattr(exc, "cause", None) or exc
    return f"{type(cause).__name__}: {cause}".replace("\n", " ")[:300]
