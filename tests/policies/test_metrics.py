"""metrics.csv's update statistics: means over the updates since the previous row, empty before updates
start; the BC term only with expert samples; resume keeps (and upgrades) the file."""

import csv
import dataclasses
import math

import pytest

from mrguide.policies.train import Trainer
from mrguide.policies.train_log import METRIC_FIELDS, UPDATE_FIELDS
from tests.run_configs import run_config, sections

OLD_FIELDS = (
    "step",
    "episode",
    "kind",
    "return",
    "success",
    "outcome",
    "length",
    "triggered",
    "lambda",
    "expert_ratio",
    "asked",
    "reused",
    "remarks",
    "skipped",
    "wall_s",
)  # metrics.csv before the update statistics


def make(tmp_path, name, guided=True, **train):
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=600, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=10_000, **train
    )
    dc = dataclasses.replace(dc, hidden=(32, 32))
    gc = dataclasses.replace(gc, intake_steps=400, enabled=guided)
    return Trainer(run_config(tc, dc, gc, ec), tmp_path / name)


def read(path):
    with path.open() as fh:
        return list(csv.DictReader(fh))


class Recorder:
    """Records, in order, every update's statistics and every metrics row (as a MetricSink)."""

    def __init__(self, tr):
        self.events = []
        update = tr.agent.update
        tr.agent.update = lambda batch: self.events.append(("update", update(batch))) or self.events[-1][1]
        tr.sinks.append(self)

    def row(self, row):
        self.events.append(("row", row))

    def evaluation(self, res):
        pass


@pytest.mark.parametrize("guided", [True, False])
def test_rows_hold_the_means_of_the_updates_since_the_previous_row(tmp_path, guided):
    tr = make(tmp_path, "run", guided)
    rec = Recorder(tr)
    try:
        tr.run(stop_at=300)
    finally:
        tr.close()
    since, rows, n_updates = [], 0, 0
    for kind, payload in rec.events:
        if kind == "update":
            since.append(payload)
            n_updates += 1
            continue
        rows += 1
        for field in UPDATE_FIELDS:
            values = [u[field] for u in since if field in u]
            if values:
                assert payload[field] == pytest.approx(sum(values) / len(values), rel=1e-5), (field, payload)
            else:
                assert payload[field] == "", (field, payload)
        since = []
    # updates start at the 64th stored transition (a demonstration's steps are stored as its phases complete)
    assert n_updates == tr.agent.updates and 0 < tr.agent.updates <= tr.counters.step - 63 and rows >= 5
    csv_rows = read(tmp_path / "run" / "metrics.csv")
    assert tuple(csv_rows[0]) == METRIC_FIELDS and len(csv_rows) == rows
    assert [r["step"] for r in csv_rows] == [str(p["step"]) for k, p in rec.events if k == "row"]
    before = [r for r in csv_rows if int(r["step"]) < 64]
    after = [r for r in csv_rows if r["critic_loss"] != ""]
    assert before and all(r[f] == "" for r in before for f in UPDATE_FIELDS)
    mine = [
        f for f in UPDATE_FIELDS if f in tr.agent.CRITIC_STATS + tr.agent.ACTOR_STATS
    ]  # DDPG's; SAC fills "temperature"
    assert mine == ["critic_loss", "actor_loss", "q_mean", "q_max", "bc_loss"]
    assert len(after) >= 3 and all(math.isfinite(float(r[f])) for r in after for f in mine)
    assert all(r["temperature"] == "" for r in csv_rows)
    assert all(float(r["q_max"]) >= float(r["q_mean"]) and float(r["critic_loss"]) >= 0 for r in after)
    bc = [float(r["bc_loss"]) for r in after]
    if guided:  # expert rows carry updates whose batches hold expert samples
        assert {r["kind"] for r in after} >= {"expert"} and min(bc) > 0
    else:
        assert bc == [0.0] * len(bc)
        assert all(r["kind"] == "agent" for r in after) and len(after) == len(
            [r for r in csv_rows if int(r["step"]) >= 64]
        )


def test_resume_keeps_earlier_rows_and_upgrades_an_old_metrics_file(tmp_path):
    first = make(tmp_path, "run")
    first.run(stop_at=250)
    first.close()
    path = tmp_path / "run" / "metrics.csv"
    kept = read(path)
    # as written by the previous version: without the update columns; plus a row after the checkpoint
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, OLD_FIELDS, extrasaction="ignore")
        w.writeheader()
        w.writerows(kept + [{**kept[-1], "step": str(first.counters.step + 7)}])
    resumed = make(tmp_path, "run")
    resumed.load_checkpoint()
    try:
        resumed.run(stop_at=350)
    finally:
        resumed.close()
    rows = read(path)
    assert tuple(rows[0]) == METRIC_FIELDS
    old, new = rows[: len(kept)], rows[len(kept) :]
    assert [r["step"] for r in old] == [r["step"] for r in kept]  # the row after the checkpoint is gone
    assert all(r[f] == "" for r in old for f in UPDATE_FIELDS)
    assert new and int(new[0]["step"]) > first.counters.step
    assert all(
        math.isfinite(float(r[f])) for r in new if r["critic_loss"] != "" for f in UPDATE_FIELDS if f != "temperature"
    )
    assert any(r["critic_loss"] != "" for r in new)


@pytest.mark.parametrize("fails", ["writing", "renaming"])
def test_an_interrupted_truncation_leaves_the_log_as_it_was(tmp_path, monkeypatch, fails):
    """Resuming rewrites metrics.csv without the rows after the checkpoint through a temporary file renamed over
    it: a failure while writing the new one, or between writing and renaming, leaves the old file whole."""
    import os

    first = make(tmp_path, "run", guided=False)
    first.run(stop_at=150)
    first.close()
    path = tmp_path / "run" / "metrics.csv"
    kept = read(path)
    with path.open("a", newline="") as fh:  # a row after the checkpoint: the resume drops it
        csv.DictWriter(fh, METRIC_FIELDS).writerow({**kept[-1], "step": str(first.counters.step + 7)})
    before = path.read_bytes()

    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device")

    if fails == "writing":
        monkeypatch.setattr(csv.DictWriter, "writerows", fail)
    else:
        monkeypatch.setattr(os, "replace", fail)
    resumed = make(tmp_path, "run", guided=False)
    try:
        with pytest.raises(OSError, match="No space left"):
            resumed.load_checkpoint()
    finally:
        resumed.close()
    assert path.read_bytes() == before
    assert not (tmp_path / "run" / "metrics.csv.tmp").exists()  # the partial file is gone
    monkeypatch.undo()
    again = make(tmp_path, "run", guided=False)
    try:
        again.load_checkpoint()
    finally:
        again.close()
    assert read(path) == kept  # the truncation, done


def test_rows_count_the_sessions_cost_beside_the_marks(tmp_path):
    """probes, robot seconds (every decision for the twin's decision period) and part resets (each agent episode,
    each demonstration put back to its start), as the counters have them when the row is written."""
    tr = make(tmp_path, "cost")
    try:
        tr.run(stop_at=300)
        rows = read(tmp_path / "cost" / "metrics.csv")
        last = rows[-1]
        assert float(last["robot_s"]) == pytest.approx(tr.counters.step * 0.1, abs=0.05)
        assert int(last["resets"]) == tr.counters.episode + tr.counters.interventions > tr.counters.episode
        assert int(last["probes"]) == tr.counters.probes
        assert [float(r["robot_s"]) for r in rows] == sorted(float(r["robot_s"]) for r in rows)
    finally:
        tr.close()
