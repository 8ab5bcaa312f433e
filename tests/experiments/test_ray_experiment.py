"""A tiny experiment on a local Ray: runs in parallel, a finished run is skipped, a killed one resumes."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from mrguide.cli import main
from mrguide.policies.checkpoint import read_checkpoint
from mrguide.policies.ddpg_update import update_build

REPO = Path(__file__).resolve().parents[2]


def steps_of(run: Path) -> list[int]:
    with (run / "metrics.csv").open() as fh:
        return [int(r["step"]) for r in csv.DictReader(fh)]


def rows_up_to(run: Path, step: int) -> list[str]:
    """metrics.csv lines (wall_s included, which a re-run would not reproduce) up to `step`."""
    lines = (run / "metrics.csv").read_text().splitlines()
    return [line for line in lines[1:] if int(line.split(",")[0]) <= step]


def test_tiny_learning_curves_on_local_ray_then_report_again(tiny_experiment, capsys):
    write, out = tiny_experiment
    cfg = write("lc", "seeds = 2\nsteps = 300\n")
    assert (
        main(["experiment", "learning-curves", "--config", str(cfg), "--out", str(out), "--workers", "2", "--quiet"])
        == 0
    )
    for v in ("baseline", "guided"):
        for s in (0, 1):
            run = out / v / f"seed{s}"
            assert (run / "done").exists() and steps_of(run)[-1] == 300
            record = json.loads((run / "run.json").read_text())  # the whole configuration the run trained with, first
            assert next(iter(record)) == "effective_config" and record["seed"] == s
            assert record["update"] == update_build()  # the build the run's process used (the tests': eager)
            assert record["effective_config"]["guidance"]["enabled"] is (v == "guided")
            assert record["effective_config"]["guidance"]["reference"] == "running_median"
    summary = (out / "summary.csv").read_text().splitlines()
    assert (
        summary[0]
        == "variant,seeds,converged_4k,converged_5k,converged_20k,median_step,median_annotations,median_person_minutes"
    )
    assert len(summary) == 3 and (out / "fig3_learning_curves.png").stat().st_size > 10_000
    mtime = (out / "guided" / "seed0" / "done").stat().st_mtime
    capsys.readouterr()
    # a second start trains nothing (every run is done) and rebuilds the same report
    assert main(["experiment", "learning-curves", "--config", str(cfg), "--out", str(out), "--quiet"]) == 0
    assert (out / "guided" / "seed0" / "done").stat().st_mtime == mtime
    assert main(["experiment", "report", "learning-curves", "--config", str(cfg), "--out", str(out)]) == 0
    assert (out / "summary.csv").read_text().splitlines() == summary


def test_a_killed_experiment_resumes_from_checkpoints(tiny_experiment):
    write, out = tiny_experiment
    total = 600
    cfg = write("lb", f'seeds = 2\nsteps = {total}\nvariants = ["baseline"]\n')
    cmd = [
        sys.executable,
        "-m",
        "mrguide.cli",
        "experiment",
        "long-baseline",
        "--config",
        str(cfg),
        "--out",
        str(out),
        "--workers",
        "2",
        "--quiet",
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    # SIGINT back to its default in the child: a test run started in the background of a non-interactive shell
    # inherits SIGINT ignored, and Python then never installs its Ctrl-C handler
    proc = subprocess.Popen(
        cmd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and not all(
            (out / "baseline" / f"seed{s}" / "checkpoint.pt").exists() for s in (0, 1)
        ):
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)  # Ctrl-C: the tasks are cancelled, the checkpoints stay
        proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130
    runs = [out / "baseline" / f"seed{s}" for s in (0, 1)]
    assert all(not (run / "done").exists() for run in runs)
    checkpointed = [read_checkpoint(run / "checkpoint.pt")["counters"]["step"] for run in runs]
    kept = [rows_up_to(run, step) for run, step in zip(runs, checkpointed)]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    for run, step, before in zip(runs, checkpointed, kept):
        steps = steps_of(run)
        assert steps[-1] == total and steps == sorted(set(steps))  # no row twice, no step going back
        assert 0 < step < total and before and rows_up_to(run, step) == before  # resumed, not trained again
    assert f"| baseline | 2 | {total} |" in res.stdout
