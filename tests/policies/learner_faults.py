"""Learners that misbehave, for the learner-process tests: each is a `LearnerProcess.target`, run in the learner's
spawned process (so they live in an importable module) and configured through the environment it inherits."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path

from mrguide.policies import learner_server

#: How many updates the misbehaving learner makes before it misbehaves.
AFTER = "MRGUIDE_TEST_LEARNER_AFTER"
#: A file: the stalling learner makes no update while it does not exist.
GATE = "MRGUIDE_TEST_LEARNER_GATE"


def _after_updates(then: Callable[[learner_server.LearnerServer], bool]) -> None:
    """From the update after $MRGUIDE_TEST_LEARNER_AFTER on, the learner makes an update only when `then` says so."""
    after = int(os.environ[AFTER])
    update = learner_server.LearnerServer._update

    def misbehaving(self: learner_server.LearnerServer) -> None:
        if self.calls < after or then(self):
            update(self)

    learner_server.LearnerServer._update = misbehaving  # type: ignore[method-assign]


def stalling(setup: learner_server.LearnerSetup, inbox: Connection, outbox: Connection) -> None:
    """Makes no update while the gate file does not exist; it takes in transitions and answers requests meanwhile."""
    gate = Path(os.environ[GATE])

    def gate_open(_: learner_server.LearnerServer) -> bool:
        if gate.exists():
            return True
        time.sleep(0.01)
        return False

    _after_updates(gate_open)
    learner_server.serve(setup, inbox, outbox)


def dying(setup: learner_server.LearnerSetup, inbox: Connection, outbox: Connection) -> None:
    """Its process ends (exit code 3, nothing said) where it would make its next update, as a crash would."""
    _after_updates(lambda _: os._exit(3))
    learner_server.serve(setup, inbox, outbox)
