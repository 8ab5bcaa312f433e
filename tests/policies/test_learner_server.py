"""The learner process's loop (`LearnerServer`) in this process, its inbox scripted: what it does with the messages
in the order they come, without a process, a pipe or a clock."""

from __future__ import annotations

import dataclasses
from collections import deque

import numpy as np

from mrguide.policies.ddpg import DDPG
from mrguide.policies.learner_server import Chunk, LearnerServer, LearnerSetup, Message
from mrguide.policies.networks import obs_scaling
from mrguide.robot import load_robot
from mrguide.task import ACT_DIM, OBS_DIM
from tests.run_configs import run_config, sections


class ScriptedInbox:
    """The actor's messages in turn; once they are read, a wait for the next brings "stop" (the actor ending)."""

    def __init__(self, *messages: object):
        self.messages = deque(messages)

    def poll(self, timeout: float = 0.0) -> bool:
        if not self.messages and timeout > 0:
            self.messages.append(Message("stop"))
        return bool(self.messages)

    def recv(self) -> object:
        return self.messages.popleft()


class Outbox:
    def __init__(self) -> None:
        self.sent: list[object] = []

    def put(self, message: object) -> None:
        self.sent.append(message)


def chunk(n: int, step: int) -> Chunk:
    rng = np.random.default_rng(step)
    obs, act = rng.uniform(-1, 1, (n, OBS_DIM)), rng.uniform(-1, 1, (n, ACT_DIM))
    return Chunk(obs, act, np.zeros(n), obs, np.zeros(n, bool), np.arange(n) % 2, step)


def server(inbox: ScriptedInbox) -> tuple[LearnerServer, Outbox]:
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(tc, learning_starts=8, batch_size=4, publish_every=1)
    run = run_config(tc, dataclasses.replace(dc, hidden=(16, 16)), gc, ec)
    outbox = Outbox()
    return LearnerServer(LearnerSetup(DDPG, run, *obs_scaling(load_robot().workspace)), inbox, outbox), outbox


def test_a_correction_behind_the_transitions_drops_the_updates_they_were_owed():
    """A person's correction (`Learning.forget`) empties the pools while the learner owes updates for what they
    held: it owes none after it (an update owed sampled an empty pool, and the learner process crashed)."""
    learner, outbox = server(ScriptedInbox(chunk(12, 12), Message("forget")))
    learner._serve()
    assert learner.owed == 0 and len(learner.replay) == 0 and learner.calls == 0 and outbox.sent == []


def test_transitions_past_learning_starts_are_owed_and_made():
    learner, outbox = server(ScriptedInbox(chunk(12, 12)))
    learner._serve()
    assert learner.calls == 5 and learner.owed == 0 and len(outbox.sent) == 5  # 12 - 8 + 1, each published
