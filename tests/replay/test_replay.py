"""`mrguide replay`: a dry run's log (the scripted expert through the whole deploy stack against the simulated
cell) replays into an .rrd whose entities and row counts, read back with Rerun's own reader
(`rerun.chunk.RrdReader`), are what the log holds."""

from __future__ import annotations

import itertools
from collections import Counter
from pathlib import Path

import pytest

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run
from mrguide.cli import main
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.replay.runs import load_run
from tests.deploy.conftest import Expert, bus_config

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def dry_log(tmp_path_factory) -> Path:
    """Two episodes of the scripted expert, dry-run; the exact pose source logs the truth and its age."""
    log = tmp_path_factory.mktemp("dry") / "deploy.jsonl"
    cfg = CellConfig()
    with RunLog(log, {"command": "deploy", "dry_run": True, "decision_period": cfg.twin.decision_period}) as run_log:
        dry_run(None, cfg, bus_config(), 2, 0, run_log, policy=Expert(cfg))
    return log


def _rows(rrd: Path) -> tuple[Counter, set[str]]:
    """Rows per temporal entity (on the `decision` timeline) and every entity path, as Rerun reads the file."""
    from rerun.chunk import RrdReader

    rows: Counter = Counter()
    entities = set()
    for chunk in RrdReader(rrd).stream():
        entities.add(chunk.entity_path)
        if not chunk.is_static and "decision" in chunk.timeline_names:
            rows[chunk.entity_path] += chunk.num_rows
    return rows, entities


def test_a_dry_run_replays_into_a_recording_of_what_the_log_holds(dry_log, tmp_path):
    rrd = tmp_path / "run.rrd"
    assert main(["replay", str(dry_log), "--save", str(rrd)]) == 0
    by_episode: dict[int, list[dict]] = {}
    for r in read_log(dry_log):  # the last decision of an episode (it only judges) names no episode
        if r["kind"] == "episode_start":
            current = by_episode.setdefault(r["episode"], [])
        elif r["kind"] == "decision":
            current.append(r)
    decisions = [r for rs in by_episode.values() for r in rs]
    assert all("pose" in r and "object_from" in r for r in decisions if "obs" in r)  # the truth is in the log
    episodes = load_run(dry_log)
    assert [e.index for e in episodes] == [0, 1] and all(e.outcome == "success" for e in episodes)
    rows, entities = _rows(rrd)
    for ep in episodes:
        mine = by_episode[ep.index]
        acting = [r for r in mine if "obs" in r]  # the last record only judges (tcp, outcome)
        b = f"/{ep.label}"
        assert rows[f"{b}/tcp"] == len(mine)
        assert rows[f"{b}/trail"] == len(mine)
        assert rows[f"{b}/joints"] == 6 * len(acting)  # the measured joints pose the arm, joint by joint
        assert rows[f"{b}/target"] == sum("target" in r for r in mine)
        assert rows[f"{b}/object/seen"] == len(acting)
        assert rows[f"{b}/object/true"] == len(acting)
        assert rows[f"/plots/vacuum_kpa/{ep.label}"] == len(acting)
        assert rows[f"/plots/part/{ep.label}"] == len(acting)
        assert rows[f"/plots/latency_ms/{ep.label}"] == sum("latency_ms" in r for r in mine)
        assert rows[f"/plots/phi/{ep.label}"] == len(mine)
        phases = [r["phase"] for r in mine]
        changes = 1 + sum(a != b_ for a, b_ in itertools.pairwise(phases))
        assert rows[f"/phase/{ep.label}"] == changes
        # the outcome, and one per safety event: the lift rule's break-away in these episodes, and the descent rule's
        # where the arm came down before it was over the part (timing decides)
        assert {"break_away"} <= {e["event"] for e in ep.events} <= {"break_away", "descent"}
        assert rows[f"{b}/markers"] == 1 + len(ep.events)
        # the arm: its URDF frames and link meshes (static), its goal
        assert f"{b}/tf_static" in entities and f"{b}/goal" in entities
        assert {f"{b}/ur5/meshes/{link}" for link in ("base_link", "forearm_link", "wrist_3_link")} <= entities
        assert f"{b}/ur5/visual_geometries/suction_cup/visual_0" in entities


def test_episode_and_outcome_selection(dry_log, tmp_path):
    rrd = tmp_path / "one.rrd"
    assert main(["replay", f"{dry_log}:1", "--save", str(rrd), "--no-arm"]) == 0
    _, entities = _rows(rrd)
    labels = {p.split("/")[1] for p in entities if p.endswith("/tcp")}
    assert labels == {load_run(dry_log)[1].label}
    assert not any("/meshes/" in p for p in entities)


def test_replay_refuses_a_selection_that_matches_nothing(dry_log, tmp_path, run_cli):
    run_cli(["replay", dry_log, "--outcome", "dropped", "--save", tmp_path / "x.rrd"]).assert_refused("no episode")
    run_cli(["replay", dry_log]).assert_refused("--save")
    run_cli(["replay", tmp_path / "missing.jsonl", "--save", tmp_path / "x.rrd"]).assert_refused("missing.jsonl")


def test_a_slim_copy_keeps_the_first_success_and_replays_what_it_holds(dry_log, tmp_path, run_cli, capsys):
    """The results keep slim copies of run logs (`python -m mrguide.deploy.runlog_slim`): of two successful
    episodes the second loses its decisions, every other record stays, and slimming again changes no byte."""
    from mrguide.deploy.runlog_slim import main as slim_main

    log = tmp_path / "copy.jsonl"
    log.write_bytes(dry_log.read_bytes())
    assert slim_main([str(log)]) == 0
    slim = tmp_path / "copy.jsonl.gz"
    assert not log.exists() and slim.exists()
    full, kept = read_log(dry_log), read_log(slim)
    assert [r for r in full if r["kind"] != "decision"] == [r for r in kept if r["kind"] != "decision"]
    second = next(i for i, r in enumerate(full) if r["kind"] == "episode_start" and r["episode"] == 1)
    assert [r for r in kept if r["kind"] == "decision"] == [r for r in full[:second] if r["kind"] == "decision"]
    assert 0 < len(kept) < len(full)
    packed = slim.read_bytes()
    assert slim_main([str(slim)]) == 0 and slim.read_bytes() == packed
    assert [len(e.frames) > 0 for e in load_run(slim)] == [True, False]
    rrd = tmp_path / "slim.rrd"
    assert main(["replay", str(slim), "--save", str(rrd), "--no-arm"]) == 0
    assert "1 episodes without decisions left out" in capsys.readouterr().out
    labels = {p.split("/")[1] for p in _rows(rrd)[1] if p.endswith("/tcp")}
    assert labels == {load_run(slim)[0].label}
    run_cli(["replay", f"{slim}:1", "--save", tmp_path / "x.rrd"]).assert_refused("holds no decisions")


def test_a_copy_without_decisions_keeps_every_other_record(dry_log, tmp_path):
    """`runlog_slim --no-decisions`: a long run's cycles and episodes without its decisions (the on-cell results)."""
    from mrguide.deploy.runlog_slim import main as slim_main

    log = tmp_path / "copy.jsonl"
    log.write_bytes(dry_log.read_bytes())
    assert slim_main(["--no-decisions", str(log)]) == 0
    full, kept = read_log(dry_log), read_log(tmp_path / "copy.jsonl.gz")
    assert kept == [r for r in full if r["kind"] != "decision"] and len(kept) < len(full)
