"""What one finished training run says, read back from its files (eval.csv, metrics.csv, done)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mrguide.experiments.report import read_csv
from mrguide.experiments.stats import Convergence, convergence
from mrguide.experiments.train_runs import TrainRun, finished


@dataclass(frozen=True)
class RunRecord:
    """A run's evaluations, cumulative annotations, realized expert ratios and its convergence."""

    run: TrainRun
    eval_steps: np.ndarray
    eval_rates: np.ndarray
    eval_returns: np.ndarray
    row_steps: np.ndarray  # metrics.csv: one row per episode
    asked: np.ndarray  # cumulative annotations asked, per row
    ratio: np.ndarray  # realized expert ratio per row
    row_wall: np.ndarray  # training wall time (s) at each row
    converged: Convergence
    wall_s: float
    exploring_outcomes: Counter[str]  # how the agent's own episodes ended (metrics.csv `outcome` of `agent` rows)
    final_temperature: float | None  # SAC's entropy temperature at the last row that logged one (None: DDPG)
    robot_s: np.ndarray  # the robot's seconds so far, per row (NaN in a run from before metrics.csv counted them)
    resets: np.ndarray  # the part's resets so far, per row (NaN likewise)
    corrections: int  # a person's corrections over the run (0 in a run from before they were counted)
    probes: int  # the targets the demonstrations' searches tried over the run

    @property
    def annotations_until_convergence(self) -> int | None:
        c = self.converged.step
        if c is None:
            return None
        before = self.row_steps <= c
        return int(self.asked[before].max()) if before.any() else 0

    def _until_convergence(self, per_row: np.ndarray) -> float | None:
        """A cumulative metrics column at the last row up to convergence; None for a run that did not converge."""
        c = self.converged.step
        if c is None:
            return None
        before = self.row_steps <= c
        return float(per_row[before][-1] if before.any() else per_row[0])

    @property
    def robot_min_until_convergence(self) -> float | None:
        s = self._until_convergence(self.robot_s)
        return None if s is None else round(s / 60, 1)

    @property
    def resets_until_convergence(self) -> int | None:
        n = self._until_convergence(self.resets)
        return None if n is None else int(n)

    @property
    def annotations_total(self) -> int:
        return int(self.asked.max(initial=0))

    def returns_on(self, grid: np.ndarray, half: int) -> np.ndarray:
        """The latest evaluation return at each grid step (NaN before the first evaluation)."""
        out = []
        for g in grid:
            seen = self.eval_steps <= g + half
            out.append(float(self.eval_returns[seen][-1]) if seen.any() else np.nan)
        return np.array(out)

    def at_evaluations(self, per_row: np.ndarray) -> np.ndarray:
        """A metrics column (e.g. `asked`, `row_wall`) as it stood at each evaluation (its last row at or before it)."""
        return np.array(
            [per_row[self.row_steps <= s][-1] if (self.row_steps <= s).any() else 0 for s in self.eval_steps]
        )

    def asked_on(self, grid: np.ndarray) -> np.ndarray:
        return np.array([self.asked[self.row_steps <= g].max(initial=0) for g in grid], dtype=float)

    def ratio_on(self, grid: np.ndarray, step: int) -> np.ndarray:
        out = []
        for g in grid:
            sel = (self.row_steps > g - step) & (self.row_steps <= g)
            out.append(float(self.ratio[sel].mean()) if sel.any() else np.nan)
        return np.array(out)


def read_run(run: TrainRun, root: Path, episodes_per_eval: int) -> RunRecord:
    """The record of a finished run (its `done` marker must exist)."""
    out = run.directory(root)
    ev, rows = read_csv(out / "eval.csv"), read_csv(out / "metrics.csv")
    steps = np.array([int(r["step"]) for r in ev])
    rates = np.array([float(r["success_rate"]) for r in ev])
    return RunRecord(
        run,
        steps,
        rates,
        np.array([float(r["mean_return"]) for r in ev]),
        np.array([int(r["step"]) for r in rows]),
        np.array([int(r["asked"]) for r in rows]),
        np.array([float(r["expert_ratio"]) for r in rows]),
        np.array([float(r["wall_s"]) for r in rows]),
        convergence(steps.tolist(), rates.tolist(), episodes_per_eval),
        finished(run, root).wall_s,
        Counter(r["outcome"] for r in rows if r["kind"] == "agent" and r["outcome"]),
        next((float(r["temperature"]) for r in reversed(rows) if r.get("temperature")), None),
        np.array([float(r.get("robot_s") or np.nan) for r in rows]),
        np.array([float(r.get("resets") or np.nan) for r in rows]),
        int(rows[-1].get("corrections") or 0) if rows else 0,
        int(rows[-1].get("probes") or 0) if rows else 0,
    )
