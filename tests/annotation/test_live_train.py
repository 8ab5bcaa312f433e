"""Training with a live expert: a bot over the wire equals the in-process annotator; timeouts; Ctrl-C."""

from __future__ import annotations

import asyncio
import csv
import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import aiohttp
import numpy as np
import pytest

from mrguide.annotation.bot import AnnotationBot, BotOptions
from mrguide.annotation.live import LiveOptions, LiveSession
from mrguide.policies.annotations import anchor_key
from mrguide.policies.experts import AnnotatorNoise
from mrguide.policies.guidance import LIVE_POSE
from mrguide.policies.train import Trainer
from tests.annotation.conftest import Client
from tests.run_configs import run_config, sections

SIGMA = 0.02


def trainer(out: Path, source: str = "annotator", factory=None) -> Trainer:
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=600, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=10_000
    )
    dc = dataclasses.replace(dc, hidden=(32, 32))
    # the pose as a person's run perceives it by default, set for both sides alike (the in-process default is exact)
    gc = dataclasses.replace(gc, intake_steps=400, source=source, noise=AnnotatorNoise(sigma=SIGMA), pose=LIVE_POSE)
    return Trainer(run_config(tc, dc, gc, ec), out, factory)


def rows(path: Path) -> list[dict]:
    with path.open() as fh:
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(fh)]


def records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_bot_over_the_wire_trains_exactly_like_the_in_process_annotator(tmp_path):
    local = trainer(tmp_path / "local")
    try:
        local.run(stop_at=350)
    finally:
        local.close()
    session = LiveSession(LiveOptions(port=0))
    live = trainer(tmp_path / "live", "live", session.source_factory)
    bot = AnnotationBot(BotOptions(session.url, AnnotatorNoise(sigma=SIGMA), seed=0))
    thread = threading.Thread(target=bot.run, daemon=True)
    thread.start()
    try:
        live.run(stop_at=350)
    finally:
        live.close()
        session.close()
    thread.join(10)
    a, b = records(tmp_path / "local" / "annotations.jsonl"), records(tmp_path / "live" / "annotations.jsonl")
    assert len(a) == len(b) > 5
    assert [r["target"] for r in a] == [r["target"] for r in b]  # bit for bit, through JSON
    assert {r["source"] for r in a} == {"simulated"} and {(r["source"], r["client"]) for r in b} == {("live", "bot")}
    assert all(r["latency_s"] >= 0 for r in b)
    assert rows(tmp_path / "local" / "metrics.csv") == rows(tmp_path / "live" / "metrics.csv")
    assert bot.report.answers == len(b) and bot.report.refused == 0


@pytest.mark.parametrize("policy", ["skip", "oracle"])
def test_nobody_answers_skip_drops_demonstrations_oracle_answers_tagged(tmp_path, policy):
    session = LiveSession(LiveOptions(port=0, on_timeout=policy, timeout_s=0.05))
    tr = trainer(tmp_path / policy, "live", session.source_factory)
    try:
        tr.run(stop_at=150)
    finally:
        tr.close()
        session.close()
    assert tr.counters.interventions > 0 and session.expert.counts.answers == 0
    ann = tmp_path / policy / "annotations.jsonl"
    if policy == "skip":
        assert (
            tr.counters.skipped == tr.counters.interventions and tr.replay.expert.size == 0
        )  # no ζ = 1 transition without a person
        assert not ann.exists()
    else:
        assert tr.counters.skipped == 0 and tr.replay.expert.size > 0
        recs = records(ann)
        assert recs and {r["source"] for r in recs} == {"oracle"} and all(r["fallback"] == "timeout" for r in recs)
        assert session.expert.counts.fallbacks == len(recs)


async def _answer_requests(url: str, n: int, seen: list[dict]) -> None:
    """Answer `n` requests with the object/goal-based waypoint, then watch the next one without answering."""
    ws_url = url.replace("http", "ws", 1).replace("/?token=", "/ws?token=")
    async with aiohttp.ClientSession() as http:
        ws = await http.ws_connect(ws_url)
        c = Client(ws)
        hello = await c.recv("hello", timeout=180)
        await c.send({"type": "hello", "protocol": 1, "client": "test"})
        early = hello.get("request")  # asked before we connected: it came in the server's hello, as the bot reads it
        for _ in range(n + 1):
            req, early = early or await c.recv("request", timeout=180), None  # generous: a busy machine
            seen.append(req)
            if len(seen) > n:
                return
            s = req["state"]
            anchor = s["object"]["position"] if req["phase_index"] <= 2 else s["goal"]
            z = {0: 0.13, 1: 0.047, 2: 0.15, 3: 0.15, 4: 0.05}[req["phase_index"]]
            await c.send(
                {
                    "type": "answer",
                    "id": req["id"],
                    "target": [anchor[0], anchor[1], z],
                    "vacuum": req["suggested_vacuum"],
                }
            )


def _start_train(out: Path, *extra: str) -> subprocess.Popen:
    cmd = [
        sys.executable,
        "-m",
        "mrguide.cli",
        "train",
        "--expert",
        "live",
        "--port",
        "0",
        "--steps",
        "3000",
        "--quiet",
        "--out",
        str(out),
        *extra,
    ]
    return subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
    )


def _page_url(proc: subprocess.Popen) -> str:
    for line in proc.stdout:
        if line.startswith("annotation page: "):
            return line.split(": ", 1)[1].strip()
    raise AssertionError(f"no URL printed; stderr: {proc.stderr.read()}")


def test_ctrl_c_while_waiting_checkpoints_and_resume_asks_nothing_twice(tmp_path):
    out = tmp_path / "run"
    proc = _start_train(out)
    try:
        seen: list[dict] = []
        try:
            asyncio.run(_answer_requests(_page_url(proc), 1, seen))  # the pick answered, the place left waiting
        except TimeoutError:
            proc.kill()
            raise AssertionError(f"{len(seen)} requests seen; the trainer's stderr: {proc.communicate()[1]}") from None
        proc.send_signal(signal.SIGINT)
        _stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    assert "checkpoint" in stderr and (out / "checkpoint.pt").exists()
    first = records(out / "annotations.jsonl")
    assert [r["request"] for r in first] == [r["id"] for r in seen[:1]]  # every answer on disk, nothing else
    proc = _start_train(out, "--resume", "--stop-after", "600")
    try:
        url = _page_url(proc)
        bot = subprocess.run(
            [sys.executable, "-m", "mrguide.cli", "annotate", "bot", "--url", url],
            capture_output=True,
            text=True,
            timeout=240,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
        )
        proc.wait(timeout=240)
    finally:
        proc.kill()
    assert proc.returncode == 0 and bot.returncode == 0, (proc.stderr.read(), bot.stderr)
    after = records(out / "annotations.jsonl")
    assert after[:1] == first and len(after) > 1
    keys = [anchor_key(np.array(r["obs"])) for r in after if r["supersedes"] is None]
    for i, k in enumerate(keys):  # no waypoint asked twice (re-marks aside)
        assert all(np.abs(k - other).max() > 0.005 for other in keys[:i])


PERSON = AnnotatorNoise(bias_sigma=0.007, sigma_across=0.01, sigma_along=0.02, outlier_rate=0.03, outlier_scale=0.1)


def test_a_persons_marks_over_the_wire_in_pick_place_equal_the_in_process_person(tmp_path):
    """The experiments' BotSession: the headset error model and two marks per demonstration, bit for bit over the wire."""
    from mrguide.annotation.bot_session import BotSession

    def person_trainer(out: Path, source: str, factory=None) -> Trainer:
        tc, dc, gc, ec = sections()
        tc = dataclasses.replace(
            tc, total_steps=600, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=10_000
        )
        dc = dataclasses.replace(dc, hidden=(32, 32))
        gc = dataclasses.replace(gc, intake_steps=400, source=source, noise=PERSON, marks="pick_place", pose=LIVE_POSE)
        return Trainer(run_config(tc, dc, gc, ec), out, factory)

    local = person_trainer(tmp_path / "local", "annotator")
    try:
        local.run(stop_at=300)
    finally:
        local.close()
    bot = BotSession(PERSON, seed=0)
    live = person_trainer(tmp_path / "live", "live", bot.source_factory)
    try:
        live.run(stop_at=300)
    finally:
        live.close()
        bot.close()
    a, b = records(tmp_path / "local" / "annotations.jsonl"), records(tmp_path / "live" / "annotations.jsonl")
    # a pick and a place at least; then the cell's measurements (a seal, a placement) stand for them
    assert len(a) == len(b) >= 2 and bot.error is None and bot.report.answers == len(b)
    assert [r["target"] for r in a] == [r["target"] for r in b]
    assert {round(r["obs"][4] * 5) for r in b} == {1, 4}  # only pick (grasp) and place (release) marks were asked
    assert rows(tmp_path / "local" / "metrics.csv") == rows(tmp_path / "live" / "metrics.csv")


def test_an_experiment_run_over_the_wire_stops_with_the_reason_when_the_bot_fails(tmp_path, monkeypatch):
    """A bot that cannot go on stops the run (no `done`, no policy) instead of leaving it waiting forever."""
    from mrguide.annotation import bot_session
    from mrguide.experiments.train_runs import TrainRun, train

    def broken(self):
        raise bot_session.BotError("the server refused the connection (403: Forbidden)")

    monkeypatch.setattr(bot_session.AnnotationBot, "run", broken)
    run = TrainRun("seed0", 0, 300, True, None, {"train.learning_starts": 64, "ddpg.hidden": [32, 32]}, "bot")
    with pytest.raises(RuntimeError, match="annotation bot stopped: the server refused"):
        train(run, str(tmp_path))
    assert not (tmp_path / "seed0" / "done").exists() and not (tmp_path / "seed0" / "policy.npz").exists()


def test_annotate_bot_takes_its_error_model_from_a_training_config(tmp_path, capsys, monkeypatch):
    """`--config` gives the bot the config's [guidance.noise] (`--noise` overrides its sigma); a bad one is refused."""
    from mrguide.annotation import bot as bot_module
    from mrguide.cli import main

    seen = []
    monkeypatch.setattr(
        bot_module.AnnotationBot, "run", lambda self: seen.append(self.options) or bot_module.BotReport(0, 0, [])
    )
    url = "http://127.0.0.1:1/?token=t"
    person = Path(__file__).resolve().parents[2] / "configs" / "runs" / "person.toml"
    assert main(["annotate", "bot", "--url", url, "--config", str(person)]) == 0
    assert main(["annotate", "bot", "--url", url, "--config", str(person), "--noise", "0.03"]) == 0
    assert (seen[0].noise.bias_sigma, seen[0].noise.sigma_along, seen[0].noise.sigma) == (0.007, 0.02, 0.0)
    assert (seen[1].noise.bias_sigma, seen[1].noise.sigma) == (0.007, 0.03)
    bad = tmp_path / "bad.toml"
    bad.write_text("[guidance.noise]\nsigma_along = -1\n")
    assert main(["annotate", "bot", "--url", url, "--config", str(bad)]) == 2
    assert "guidance.noise.sigma_along" in capsys.readouterr().err and len(seen) == 2


def test_a_bot_whose_person_sees_the_grip_on_the_label_steps_in_and_corrects_it(tmp_path):
    """An experiment's run over the wire on the keep-out block: the person's registration bias puts the grip they
    teach on the label; shown it in the status, they step in, and their `here` answer is recorded and counted as a
    correction (the annotation file, metrics.csv and the bot agree)."""
    from mrguide.experiments.train_runs import TrainRun, train

    config = Path(__file__).resolve().parents[2] / "configs" / "parts" / "keepout_block.toml"
    overrides = {"guidance.noise.bias": [0.03, 0.0, 0.0], "guidance.intake_steps": 700, "train.eval_every": 10_000}
    overrides |= {"train.learning_starts": 64, "train.batch_size": 32, "ddpg.hidden": [32, 32]}
    run = TrainRun("keepout", 0, 800, True, str(config), overrides, "bot")
    train(run, str(tmp_path))
    recs = records(tmp_path / "keepout" / "annotations.jsonl")
    corrections = [r for r in recs if r.get("correction")]
    assert corrections and all(r["here"] and r["grip"] > 0 for r in corrections)
    assert int(rows(tmp_path / "keepout" / "metrics.csv")[-1]["corrections"]) == len(corrections)


def test_a_correction_moves_the_shown_grip_with_the_judging_error_only():
    """A correction is the grip moved on the part as drawn: its error is `sigma_correction` across the part's top, not
    the marks' registration bias and line of sight."""
    from mrguide.policies.experts import SimulatedAnnotator
    from mrguide.robot import load_robot
    from mrguide.simulated_person import person_grasp
    from mrguide.task import GRASP_PRESS, TaskConfig
    from tests.policies.mark_scene import scene_obs

    noise = dataclasses.replace(PERSON, bias=(0.03, 0.0, 0.0), sigma_correction=0.0033)
    person = SimulatedAnnotator(TaskConfig(part="keepout_block"), noise, load_robot().workspace, seed=1)
    part = np.array([0.5, -0.1, 0.03])  # its grip above the default workspace's floor
    obs = scene_obs(1, obj=part)
    meant = part + person_grasp("keepout_block") - [0.0, 0.0, GRASP_PRESS]
    marks = np.array([person.annotate(obs).target - meant for _ in range(200)])
    fixes = np.array([person.correct(obs).target - meant for _ in range(200)])
    assert abs(np.median(marks[:, 0]) - 0.03) < 0.006 and np.std(marks[:, 0]) > 0.01  # bias and line of sight
    assert np.all(np.abs(np.median(fixes, axis=0)) < 0.001) and np.allclose(fixes[:, 2], 0.0, atol=1e-6)
    assert np.std(fixes[:, 0]) == pytest.approx(0.0033, rel=0.2) and all(person.correct(obs).here for _ in range(3))
