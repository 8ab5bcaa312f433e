"""The annotation page beside a learning cell (`deploy --learn --annotate`): a client's Intervene is taken up, both
marks are asked with the cell's state through the broker, recorded before use, and the expert of training follows
them; a skip or a timeout gives no expert, with the reason."""

from __future__ import annotations

import asyncio
import json
import threading
from concurrent.futures import Future

import aiohttp
import numpy as np
import pytest

from mrguide.annotation.cell_interventions import CellInterventions
from mrguide.annotation.live import LiveOptions
from mrguide.deploy.interventions import CellStart
from mrguide.motion.kinematics import Kinematics
from mrguide.policies.guidance import GuidanceConfig
from mrguide.robot import load_robot
from mrguide.task import GRASP_PRESS, TaskConfig, observation
from tests.annotation.conftest import GOAL, OBJ, connect, wait_until

PICK, PLACE = [0.5, -0.08, 0.047], [0.48, 0.2, 0.05]


@pytest.fixture
def cell(tmp_path):
    """A served CellInterventions (any free port, a 0.5 s timeout per mark) and the cell's start to mark on."""
    spec, task = load_robot(), TaskConfig()
    ci = CellInterventions(LiveOptions(port=0, timeout_s=0.5), spec, task, GuidanceConfig(), tmp_path, seed=0)
    tcp = Kinematics(spec).tcp_position(spec.q_home)
    start = CellStart(spec.q_home.copy(), observation(tcp, -1, 0.0, OBJ, GOAL))
    yield ci, start
    ci.close()


def _in_thread(fn, *args) -> Future:
    fut: Future = Future()
    threading.Thread(target=lambda: fut.set_result(fn(*args)), daemon=True).start()
    return fut


async def _step_in(ci: CellInterventions, http: aiohttp.ClientSession, start: CellStart):
    """Connect, press Intervene, and have the cell take it up: (client, who, the demonstration's future)."""
    c = await connect(http, ci.server)
    await c.send({"type": "intervene"})
    assert (await c.recv("ack"))["accepted"]
    taken: list[str] = []

    def took() -> bool:
        who = ci.requested()
        taken.extend([who] if who else [])
        return bool(taken)

    assert wait_until(took)
    return c, taken[0], _in_thread(ci.demonstration, 3, start)


def test_an_intervention_asks_both_marks_on_the_cell_and_the_expert_follows_them(cell, tmp_path):
    ci, start = cell

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c, who, fut = await _step_in(ci, http, start)
            asked = []
            for target, vacuum in ((PICK, True), (PLACE, False)):
                req = await c.recv("request")
                asked.append(req)
                await c.send({"type": "answer", "id": req["id"], "target": target, "vacuum": vacuum})
                ack = await c.recv("ack")
                assert ack["accepted"] and ack["for"] == "answer"
            return who, asked, fut.result(5)

    who, asked, (demo, record) = asyncio.run(scenario())
    spec, task = load_robot(), TaskConfig()
    assert who.startswith("c") and [r["phase"] for r in asked] == ["grasp", "release"]
    state = asked[0]["state"]  # the cell as the runtime senses it
    assert np.allclose(state["joints"], spec.q_home) and np.allclose(state["object"]["position"], OBJ)
    assert np.allclose(state["tcp"], start.obs[:3], atol=1e-6) and state["vacuum_on"] is False
    assert [(m["phase"], m["client"]) for m in record["marks"]] == [("grasp", "bot"), ("release", "bot")]
    on_disk = [json.loads(line) for line in (tmp_path / "annotations.jsonl").read_text().splitlines()]
    assert np.allclose([r["target"] for r in on_disk], [PICK, PLACE])  # each mark on disk, acknowledged after
    hover = np.array(PICK) + [0.0, 0.0, GRASP_PRESS + task.approach_height]
    action = demo.act(start.obs)  # training's expert of the two marks: the approach hovers over the pick mark
    assert np.allclose(action, np.r_[spec.workspace.to_normalized(hover), -1.0], atol=1e-6)


def test_a_skipped_or_unanswered_mark_leaves_the_episode_to_the_policy(cell):
    ci, start = cell

    async def scenario(skip: bool):
        async with aiohttp.ClientSession() as http:
            c, _, fut = await _step_in(ci, http, start)
            req = await c.recv("request")
            if skip:
                await c.send({"type": "skip", "id": req["id"]})
            return fut.result(5)

    assert asyncio.run(scenario(skip=True)) == (None, {"marks": [], "reason": "skipped"})
    assert asyncio.run(scenario(skip=False)) == (None, {"marks": [], "reason": "timeout"})
