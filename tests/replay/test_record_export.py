"""The per-step episode recorder (`mrguide train --record`) does not change training, keeps what the replay buffer
stored, and a recorded run exports to a LeRobot v3.0 dataset that reads back — with pyarrow and the meta JSON,
the format's own reader path (lerobot itself needs Python >= 3.12 and torch < 2.12: not installable here) —
matching the run's annotations.jsonl and demonstrations exactly."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from mrguide.cli import main
from mrguide.policies.episode_recorder import FILE_NAME, EpisodeRecorder, read_episodes
from mrguide.policies.train import Trainer
from mrguide.replay.runs import load_run
from tests.run_configs import run_config, sections

STEPS = 300


def _trainer(out, **guidance):
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=STEPS, learning_starts=64, batch_size=32, eval_every=150, checkpoint_every=10_000
    )
    dc = dataclasses.replace(dc, hidden=(32, 32))
    gc = dataclasses.replace(gc, intake_steps=STEPS, source="annotator", **guidance)
    return Trainer(run_config(tc, dc, gc, ec), out)


def _without_wall_clock(path):
    with path.open() as fh:
        return [{k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The same seed trained twice, once recorded: (plain run dir, recorded run dir, the recorded trainer)."""
    base = tmp_path_factory.mktemp("train")
    plain = _trainer(base / "plain")
    try:
        plain.run()
    finally:
        plain.close()
    tr = _trainer(base / "rec")
    tr.recorder = EpisodeRecorder(tr, base / "rec" / FILE_NAME)
    try:
        tr.run()
        tr.recorder.close()
        expert_pool = tr.replay.expert.state()
    finally:
        tr.close()
    return base / "plain", base / "rec", expert_pool


def test_recording_does_not_change_training(recorded):
    plain, rec, _ = recorded
    assert _without_wall_clock(plain / "metrics.csv") == _without_wall_clock(rec / "metrics.csv")
    assert (plain / "eval.csv").read_text() == (rec / "eval.csv").read_text()
    assert (plain / "annotations.jsonl").read_text() == (rec / "annotations.jsonl").read_text()
    assert not (plain / FILE_NAME).exists()


def test_the_recording_holds_every_step_and_the_replay_buffers_tags(recorded):
    _, rec, expert_pool = recorded
    header, episodes, truncated = read_episodes(rec / FILE_NAME)
    assert header["joint_names"][0] == "shoulder_pan_joint" and not truncated
    steps = [s for e in episodes for s in e["steps"]]
    assert [s["step"] for s in steps] == list(range(1, STEPS + 1))  # every training step, once, in order
    with (rec / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert sum(e["type"] == "expert" for e in episodes) == sum(r["kind"] == "expert" for r in rows)
    expert = [s for s in steps if s["zeta"] == 1]  # what the trainer stored as expert data, in order
    np.testing.assert_array_equal(np.array([s["obs"] for s in expert], np.float32), expert_pool["obs"])
    np.testing.assert_array_equal(np.array([s["stored"] for s in expert], np.float32), expert_pool["act"])
    np.testing.assert_array_equal(np.array([s["next_obs"] for s in expert], np.float32), expert_pool["next_obs"])
    # the replay's frames: one more than steps per episode, the arm at home first
    ep = load_run(rec)[0]
    assert len(ep.frames) == len(episodes[0]["steps"]) + 1
    np.testing.assert_allclose(ep.frames[0].q, header["q_home"])


def test_the_recording_is_bounded(tmp_path):
    tr = _trainer(tmp_path / "small")
    tr.recorder = EpisodeRecorder(tr, tmp_path / "small" / FILE_NAME, limit_mb=0.02)
    try:
        tr.run(stop_at=200)
        tr.recorder.close()
    finally:
        tr.close()
    path = tmp_path / "small" / FILE_NAME
    assert path.stat().st_size <= 0.02 * 1024 * 1024
    _, episodes, truncated = read_episodes(path)
    assert truncated and episodes  # whole episodes up to the bound, then the marker


def test_a_recorded_run_exports_to_a_lerobot_dataset(recorded, tmp_path):
    _, rec, expert_pool = recorded
    out = tmp_path / "dataset"
    assert main(["export", "lerobot", str(rec), "--out", str(out)]) == 0
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 10 and info["video_path"] is None
    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet").to_pylist()
    episodes = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    tasks = pq.read_table(out / "meta" / "tasks.parquet")
    stats = json.loads((out / "meta" / "stats.json").read_text())
    assert tasks.column("task").to_pylist() == ["pick the part and place it at the goal"]
    assert json.loads(tasks.schema.metadata[b"pandas"])["index_columns"] == ["task"]  # lerobot's index
    assert info["total_frames"] == len(data) and info["total_episodes"] == len(episodes)
    assert set(info["features"]) == set(data[0])
    # the demonstrations, exactly
    _, recorded_eps, _ = read_episodes(rec / FILE_NAME)
    demos = [e for e in recorded_eps if e["type"] == "expert"]
    assert len(episodes) == len(demos) > 0
    for k, (meta, demo) in enumerate(zip(episodes, demos)):
        frames = data[meta["dataset_from_index"] : meta["dataset_to_index"]]
        assert meta["episode_index"] == k and meta["length"] == len(demo["steps"]) == len(frames)
        assert [f["frame_index"] for f in frames] == list(range(len(frames)))
        assert all(f["episode_index"] == k and f["task_index"] == 0 for f in frames)
        np.testing.assert_array_equal(
            np.array([f["observation.state"] for f in frames], np.float32),
            np.array([s["obs"] for s in demo["steps"]], np.float32),
        )
        np.testing.assert_array_equal(
            np.array([f["action"] for f in frames], np.float32),
            np.array([s["stored"] for s in demo["steps"]], np.float32),
        )
        assert [f["zeta"] for f in frames] == [s["zeta"] for s in demo["steps"]]
    assert [f["index"] for f in data] == list(range(len(data)))
    zeta1 = [f for f in data if f["zeta"] == 1]
    np.testing.assert_array_equal(np.array([f["observation.state"] for f in zeta1], np.float32), expert_pool["obs"])
    np.testing.assert_array_equal(np.array([f["action"] for f in zeta1], np.float32), expert_pool["act"])
    # every demonstration frame names the annotation it followed, as annotations.jsonl has it, or -1 where it followed
    # what the cell measured (a seal, a placement) and no mark
    annotations = {r["id"]: r for r in map(json.loads, (rec / "annotations.jsonl").read_text().splitlines())}
    assert {f["annotation.id"] for f in data} - {-1} == set(annotations)
    for f in data:
        if f["annotation.id"] == -1:
            continue
        ann = annotations[f["annotation.id"]]
        assert f["annotation.source"] == ann["source"] == "simulated"
        assert f["annotation.latency_s"] == ann.get("latency_s", -1.0)
    assert stats["observation.state"]["count"] == [len(data)]
    np.testing.assert_allclose(stats["action"]["mean"], np.mean([f["action"] for f in data], axis=0), rtol=1e-6)


def test_all_episodes_and_refusals(recorded, tmp_path, run_cli):
    _, rec, _ = recorded
    out = tmp_path / "all"
    assert main(["export", "lerobot", str(rec), "--out", str(out), "--all-episodes"]) == 0
    _, recorded_eps, _ = read_episodes(rec / FILE_NAME)
    assert json.loads((out / "meta" / "info.json").read_text())["total_frames"] == sum(
        len(e["steps"]) for e in recorded_eps
    )
    run_cli(["export", "lerobot", rec, "--out", out]).assert_refused("not empty")
    run_cli(["export", "lerobot", tmp_path, "--out", tmp_path / "x"]).assert_refused("--record")
