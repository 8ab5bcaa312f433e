"""A person steps in while the cell learns (`mrguide deploy --dry-run --cycles N --learn RUN_DIR --annotate PORT`): the
bot of `mrguide annotate bot` presses Intervene over the wire, the runtime takes it up at the next episode's start and
asks for the pick and the place mark through the broker, the episode is played by the expert of those marks, its
transitions reach the learner's expert pool, the run log has the intervention; a client's malformed messages are
refused with the protocol's codes and the run goes on."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from pathlib import Path

import aiohttp
import numpy as np
import pytest
import torch

from mrguide.annotation.bot import AnnotationBot, BotError, BotOptions, ws_url
from mrguide.annotation.cell_interventions import CellInterventions
from mrguide.cli import main
from mrguide.deploy.runlog import read_log
from mrguide.policies.cell_learner import ON_CELL, STATE
from mrguide.policies.checkpoint import read_checkpoint
from mrguide.robot import load_robot
from mrguide.task import GRASP_PRESS, Outcome, TaskConfig
from tests.cell.test_learn_on_cell import REAL, run_dir
from tests.deploy.test_cell_learning import _policy_file

__all__ = ["run_dir"]

TOKEN = "interventions-test-token"
#: s: generous bounds for the clients to connect and be heard (events, not speed)
DEADLINE_S = 120.0
#: What a careless client sends: a torn `intervene`, an answer with a bad target, one without an id, not an object.
BAD = {
    '{"type": "intervene"': "malformed",
    '{"type": "answer", "id": "x", "target": [0.5, "a", 0.1], "vacuum": true}': "bad_target",
    '{"type": "answer", "target": [0.5, 0.0, 0.1], "vacuum": true}': "no_id",
    '["intervene"]': "not_an_object",
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class _Bot(threading.Thread):
    """`mrguide annotate bot --intervene` in a thread: connects once the page serves, steps in, marks."""

    def __init__(self, url: str):
        super().__init__(daemon=True)
        self.bot = AnnotationBot(BotOptions(url, intervene=True, max_answers=2))

    def run(self) -> None:
        end = time.monotonic() + DEADLINE_S
        while time.monotonic() < end:
            try:
                self.bot.run()
                return
            except BotError:  # not serving yet
                time.sleep(0.05)


class _Careless(threading.Thread):
    """A client that sends the malformed messages of BAD, then listens until the server goes away."""

    def __init__(self, url: str):
        super().__init__(daemon=True)
        self.url = ws_url(url)
        self.refusals: list[dict] = []
        self.statuses: list[dict] = []
        self.refused = threading.Event()  # every BAD message was answered with a refusal

    def run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        end = time.monotonic() + DEADLINE_S
        async with aiohttp.ClientSession() as http:
            while True:
                try:
                    ws = await http.ws_connect(self.url)
                    break
                except aiohttp.ClientConnectionError:
                    if time.monotonic() > end:
                        raise
                    await asyncio.sleep(0.05)
            async with ws:
                await ws.send_json({"type": "hello", "protocol": 1, "client": "test"})
                for text in BAD:
                    await ws.send_str(text)
                async for msg in ws:
                    data = msg.json()
                    if data["type"] == "ack" and not data["accepted"]:
                        self.refusals.append(data)
                        if len(self.refusals) == len(BAD):
                            self.refused.set()
                    elif data["type"] == "status":
                        self.statuses.append(data)


def test_a_person_steps_in_and_the_episode_is_expert_data(run_dir: Path, tmp_path, monkeypatch, capsys):
    port = _free_port()
    url = f"http://127.0.0.1:{port}/?token={TOKEN}"
    bot, careless = _Bot(url), _Careless(url)
    requested = CellInterventions.requested

    def heard_first(self: CellInterventions) -> str | None:
        """The first episode's start waits until the clients were heard (the run's speed decides nothing)."""
        end = time.monotonic() + DEADLINE_S
        while not (bot.bot.report.intervened and careless.refused.is_set()) and time.monotonic() < end:
            time.sleep(0.05)
        monkeypatch.setattr(CellInterventions, "requested", requested)
        return requested(self)

    monkeypatch.setattr(CellInterventions, "requested", heard_first)
    bot.start()
    careless.start()
    log = tmp_path / "cycles.jsonl"
    args = ["deploy", "--dry-run", "--config", str(REAL), "--policy", str(run_dir / "policy.npz"), "--quiet"]
    args += ["--set", "deploy.cycles.max_retries=0", "--set", "deploy.cycles.on_alarm=skip", "--log", str(log)]
    args += ["--cycles", "2", "--learn", str(run_dir), "--annotate", str(port), "--token", TOKEN]
    code = main(args)
    bot.join(DEADLINE_S)
    careless.join(DEADLINE_S)
    out = capsys.readouterr()
    assert code == 0, out.err
    assert f"annotation page: {url}" in out.out and "Traceback" not in out.err

    # The careless client's messages: each refused with its reason, none an intervention, the run went on.
    assert sorted(r["code"] for r in careless.refusals) == sorted(BAD.values())
    assert all(r["reason"] for r in careless.refusals)

    records = read_log(log)
    (intervention,) = [r for r in records if r["kind"] == "intervention"]
    assert intervention["episode"] == 0 and intervention["played_by"] == "expert"
    pick, place = intervention["marks"]
    assert (pick["phase"], place["phase"]) == ("grasp", "release")
    assert pick["client"] == place["client"] == "bot"
    (learning,) = [r for r in records if r["kind"] == "learning"]
    assert learning["interventions"] == learning["interventions_asked"] == 1 and learning["lost"] is None
    assert any(s.get("cycle") == 0 and s.get("interventions") == 1 for s in careless.statuses)  # the page's status

    # The episode was played by the expert of the bot's marks: its first target hovers over the pick mark.
    acted = [r for r in records if r["kind"] == "decision" and r.get("episode") == 0 and "action" in r]
    spec, task = load_robot(), TaskConfig()
    hover = np.array(pick["target"]) + [0.0, 0.0, GRASP_PRESS + task.approach_height]
    assert np.allclose(acted[0]["action"][:3], spec.workspace.to_normalized(hover), atol=1e-5)

    # Its transitions went to the learner's expert pool: one per decision the task judged.
    (end,) = [r for r in records if r["kind"] == "episode_end" and r["episode"] == 0]
    ended_by_task = end["outcome"] not in (Outcome.ABORTED.value, Outcome.POSE_LOST.value)
    before = len(read_checkpoint(run_dir / "checkpoint.pt")["expert_pool"]["rew"])
    after = len(torch.load(run_dir / ON_CELL / STATE, weights_only=False)["expert_pool"]["rew"])
    assert after - before == len(acted) - (0 if ended_by_task else 1) > 0
    assert len((run_dir / ON_CELL / "annotations.jsonl").read_text().splitlines()) == 2  # on disk before use


@pytest.mark.parametrize("argv", [["--annotate", "8765"], ["--annotate", "host:port"], ["--annotate", "70000"]])
def test_annotate_without_learning_or_with_a_bad_port_is_refused(argv, run_cli, tmp_path):
    policy = _policy_file(tmp_path / "p.npz", 0, TaskConfig())
    args = ["deploy", "--dry-run", "--config", str(REAL), "--policy", str(policy), "--cycles", "1"]
    run_cli([*args, *argv]).assert_refused("--annotate")
