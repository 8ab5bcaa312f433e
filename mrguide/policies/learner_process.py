"""The learner in a process of its own (`train.learner_process = true`): the actor and the learner apart.

The actor — the trainer's env loop with the guidance and the expert, in the trainer's process — gives every stored
transition with its tag ζ, and the count of its steps, to `LearnerProcess`, which sends them every `CHUNK_STEPS`
steps from a thread of its own and never waits for the learner. The learner's process (`learner_server`)
holds the tagged replay buffer and the configured learner (its class from `learners.LEARNERS`): it owes one `learn`
call for every environment step made once the buffer holds `learning_starts` transitions, as the in-process loop
makes them, each with λ_t of its step (Eq. 11), and makes them as fast as it can, never ahead of the data. Every
`publish_every` calls it publishes the weights `act` reads (the learner's `acting_modules`) with a version number,
the actor's step they are learned up to and the update statistics since its last publication; the actor acts with
the latest it has received, taken in after each of its steps. The run's periodic evaluations are made there too,
on the learner's core, with the weights learned so far (in an env of its own, from the same start states); the final
one, of the policy that is exported, by the actor.

Before the actor's first step the learner makes one update on random data and undoes it, so that TorchInductor's
build of the update (seconds) is not a lag the actor starts with; the trainer's wall time includes that start.

A learner whose process ends keeps the actor safe: the actor goes on with the last weights it has to the end of its
episode, the log and `learner.csv` say so, and `episode_end` raises `LearnerProcessError` there. One that falls
behind (the weights `BEHIND_STEPS` steps older than the actor's step) is said in the log, and the actor goes on. A
checkpoint asks the learner for its state (networks, optimizers, both pools, its RNG, the updates it still owes):
the one point where the actor waits, at most `ANSWER_TIMEOUT` s.

The messages are numpy arrays and Python numbers (torch only inside the learner's state for checkpoints), so an actor
that is not the twin's env loop (the deploy runtime on a cell) can feed the same learner.
"""

from __future__ import annotations

import logging
import multiprocessing
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mrguide.policies.learner_server import (
    CLOSE_TIMEOUT,
    POLL_S,
    Chunk,
    LearnerSetup,
    Message,
    Publication,
    Sender,
    serve,
)
from mrguide.policies.learners import Learner
from mrguide.policies.learning import UpdateStats
from mrguide.policies.train_counters import TrainerCounters
from mrguide.policies.train_log import LEARNER_FIELDS, append_csv
from mrguide.task import ACT_DIM, OBS_DIM

log = logging.getLogger(__name__)


CHUNK_STEPS = 16  # the actor sends what it stored every this many steps
BEHIND_STEPS = 1000  # the log says the learner is behind when the actor's weights are this many steps older
READY_TIMEOUT = 600.0  # s for the learner's process to start (torch's import, TorchInductor's build of the update)
ANSWER_TIMEOUT = 120.0  # s for it to answer a request (its state for a checkpoint, a checkpoint to load)


class LearnerProcessError(RuntimeError):
    """The learner's process ended, failed or did not answer: training cannot go on."""


def load_acting_weights(agent: Learner, weights: dict[str, np.ndarray]) -> None:
    """Set the weights `agent.act` reads from `acting_weights`' arrays."""
    for name in agent.acting_modules:
        prefix = name + "."
        own = {k[len(prefix) :]: torch.from_numpy(v) for k, v in weights.items() if k.startswith(prefix)}
        getattr(agent, name).load_state_dict(own)


def pack(rows: list[tuple], step: int) -> Chunk:
    """A chunk of stored transitions (s, a, r, s', done, ζ), float32 as the replay buffer keeps them."""
    cols: tuple[Any, ...] = tuple(zip(*rows)) if rows else ((),) * 6
    obs, act, rew, next_obs, done, zeta = (np.asarray(c, np.float32) for c in cols)
    return Chunk(
        obs.reshape(-1, OBS_DIM), act.reshape(-1, ACT_DIM), rew, next_obs.reshape(-1, OBS_DIM), done, zeta, step
    )


class LearnerProcess:
    """The actor's side of a learner in its own process (see the module's docstring); a `learning.Learning`."""

    #: The learner process's entry point (a test puts a slow or failing learner here).
    target = staticmethod(serve)

    def __init__(
        self,
        setup: LearnerSetup,
        agent: Learner,
        counters: TrainerCounters,
        out: Path,
        on_evaluation: Callable[[dict], Any],
    ):
        """Start the learner's process and wait until it is ready; `agent` is the actor's copy of the learner, which
        acts with the weights the learner publishes; `on_evaluation` records an evaluation's result as it comes."""
        ctx = multiprocessing.get_context("spawn")
        inbox_reader, inbox_writer = ctx.Pipe(duplex=False)
        outbox_reader, outbox_writer = ctx.Pipe(duplex=False)
        self.process = ctx.Process(
            target=self.target, args=(setup, inbox_reader, outbox_writer), name="mrguide-learner", daemon=True
        )
        self.process.start()
        inbox_reader.close()  # the learner's ends: once its process is gone, its pipes are at their end here
        outbox_writer.close()
        self._inbox, self._outbox = Sender(inbox_writer, "mrguide-learner-feed"), outbox_reader
        self.agent, self.counters, self.log_path = agent, counters, out / "learner.csv"
        self.on_evaluation = on_evaluation
        self._evaluating = 0  # evaluations asked for, not answered yet
        self.stats = UpdateStats()
        self.version = self.weights_step = self._sent_step = 0
        self._rows: list[tuple] = []
        self._latest: Publication | None = None  # taken in, its weights not yet acted with
        self._lost: str | None = None
        self._behind = False
        try:
            self._await("ready", "starting")
        except BaseException:
            self.close()
            raise

    def add(self, obs: np.ndarray, act: np.ndarray, rew: float, next_obs: np.ndarray, done: bool, zeta: int) -> None:
        self._rows.append((obs, act, rew, next_obs, done, zeta))

    def stepped(self, step: int) -> None:
        """Send what was stored every CHUNK_STEPS steps; take in what the learner sent. Never waits."""
        if step - self._sent_step >= CHUNK_STEPS:
            self._send(step)
        self.receive()

    def forget(self) -> None:
        """Send what was stored so far, then ask the learner to empty its pools (in that order: the pipe keeps it)."""
        self._send(self._sent_step)
        if self._lost is None:
            self._inbox.put(Message("forget"))

    def _send(self, step: int) -> None:
        rows, self._rows, self._sent_step = self._rows, [], step
        if self._lost is None and not self.process.is_alive():
            self._lose(self._ended())
        if self._lost is None:
            self._inbox.put(pack(rows, step))

    def receive(self) -> None:
        """Take in what the learner has sent, without waiting: act with its latest weights."""
        try:
            while self._lost is None and self._outbox.poll():
                message = self._outbox.recv()
                if isinstance(message, Publication):
                    self._take(message)
                elif message.kind == "evaluated":
                    self._evaluated(message)
                elif message.kind == "failed":
                    self._lose(f"the learner process failed: {message.error}")
        except (EOFError, OSError):
            self._lose(self._ended())
        if self._latest is not None:
            load_acting_weights(self.agent, self._latest.weights)
            self.version, self.weights_step = self._latest.version, self._latest.step
            self._latest = None

    def _take(self, publication: Publication) -> None:
        """Keep a publication's statistics for the next metrics row; its weights are acted with from the next
        `receive` on (not while a checkpoint waits: the weights evaluated at a run's end are the ones exported)."""
        self._latest = publication
        self.stats.merge(publication.stats)
        self.agent.updates = publication.updates
        self.counters.update_s, self.counters.last_ratio = publication.update_s, publication.last_ratio

    def _ended(self) -> str:
        self.process.join(POLL_S)  # an end of pipe is seen a moment before the process's exit code
        return f"the learner process ended (exit code {self.process.exitcode})"

    def _lose(self, reason: str) -> None:
        if self._lost is None:
            self._lost = (
                f"{reason} at step {self.counters.step}; the actor kept the weights of version {self.version} "
                f"(learned up to step {self.weights_step})"
            )
            log.error("%s and stops at the end of its episode", self._lost)

    def episode_end(self, step: int) -> None:
        """A row of learner.csv; the log says when the learner falls behind or catches up; LearnerProcessError if it
        was lost."""
        self.receive()
        if self._lost is None and not self.process.is_alive():
            self._lose(self._ended())
        lag = step - self.weights_step
        row = {"step": step, "weights_version": self.version, "weights_step": self.weights_step, "lag_steps": lag}
        append_csv(
            self.log_path, LEARNER_FIELDS, {**row, "learner_updates": self.agent.updates, "alive": int(not self._lost)}
        )
        if self._lost is not None:
            raise LearnerProcessError(f"{self._lost}; training stopped at the end of that episode, step {step}")
        if (lag > BEHIND_STEPS) != self._behind:
            self._behind = not self._behind
            say = "is behind: the actor goes on with" if self._behind else "caught up: the actor acts with"
            log.warning("the learner %s weights learned up to step %d at step %d", say, self.weights_step, step)

    def evaluate(self, step: int, seeds: list[int]) -> None:
        """Ask the learner's process to evaluate its policy from the start states `seeds` (the actor's evaluation at
        its step `step`), on its own core; the result goes to `on_evaluation` when it comes, before any later
        checkpoint's state."""
        if self._lost is None:
            self._inbox.put(Message("evaluate", state={"step": step, "seeds": seeds}))
            self._evaluating += 1

    def _evaluated(self, message: Message) -> None:
        self._evaluating -= 1
        assert message.state is not None
        self.on_evaluation(message.state)

    def settle(self) -> None:
        """Wait for the evaluations asked for and not answered yet (their rows come before a later one's)."""
        while self._evaluating and self._lost is None:
            self._await("evaluated", "evaluating")

    def state(self) -> dict:
        """The learner's state, once it has taken in every transition stored so far (waits for its answer)."""
        self._send(self.counters.step)
        if self._lost is not None:
            raise LearnerProcessError(f"{self._lost}: its state is lost, no checkpoint written")
        self._inbox.put(Message("state"))
        state = self._await("state", "writing a checkpoint").state
        assert state is not None
        return state

    def load(self, state: dict) -> None:
        """Restore a checkpoint's learner here (the actor's weights) and in the learner's process."""
        self.agent.load_state_dict(state["agent"])
        own = state["learner"]
        mine = {k: state[k] for k in ("agent", "agent_pool", "expert_pool", "learner")}
        self._inbox.put(Message("load", state=mine))
        error = self._await("loaded", "loading a checkpoint").error
        if error is not None:
            raise ValueError(f"the learner process could not load it: {error}")
        self.version, self._sent_step, self.weights_step = (
            own["version"],
            own["seen_step"],
            own["seen_step"] - own["owed"],
        )

    def _await(self, kind: str, doing: str) -> Message:
        """The learner's answer `kind`, taking in its publications meanwhile (LearnerProcessError: it ended, failed or
        did not answer within READY_TIMEOUT s for "ready", ANSWER_TIMEOUT s otherwise)."""
        timeout = READY_TIMEOUT if kind == "ready" else ANSWER_TIMEOUT
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                if not self._outbox.poll(POLL_S):
                    if not self.process.is_alive():
                        raise EOFError
                    continue
                message = self._outbox.recv()
            except (EOFError, OSError):
                raise LearnerProcessError(f"{self._ended()} while {doing}") from None
            if isinstance(message, Publication):
                self._take(message)
                continue
            if message.kind == "evaluated":
                self._evaluated(message)
            if message.kind == "failed":
                raise LearnerProcessError(f"the learner process failed while {doing}: {message.error}")
            if message.kind == kind:
                return message
        raise LearnerProcessError(f"the learner process did not answer within {timeout:.0f} s while {doing}")

    def close(self) -> None:
        """Stop the learner's process (it ends without its state: checkpoint before); killed after CLOSE_TIMEOUT s."""
        if self.process.is_alive():
            self._inbox.put(Message("stop"))
            deadline = time.monotonic() + CLOSE_TIMEOUT
            while self.process.is_alive() and time.monotonic() < deadline:
                self._discard()  # its publications: a full pipe would hold up its end
                self.process.join(POLL_S)
        if self.process.is_alive():
            log.warning("the learner process did not stop within %.0f s: killed", CLOSE_TIMEOUT)
            self.process.kill()
            self.process.join()
        self._inbox.close(POLL_S)
        self._outbox.close()

    def _discard(self) -> None:
        try:
            while self._outbox.poll():
                self._outbox.recv()
        except (EOFError, OSError):
            return
