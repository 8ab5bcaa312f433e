"""The learner's process of a run with `train.learner_process = true` (`learner_process` is the actor's side and
says how the two work together): the messages between them, and `serve`, which builds the learner and the tagged
replay buffer, makes the updates the actor's steps owe and publishes the weights the actor acts with.

The messages are numpy arrays and Python numbers (torch only inside the learner's state for checkpoints), so an actor
that is not the twin's env loop (the deploy runtime on a cell) can feed the same learner.
"""

from __future__ import annotations

import copy
import queue
import signal
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import torch

from mrguide.policies.learners import Learner
from mrguide.policies.learning import UpdateStats, evaluate_policy, lam_at
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.train_config import RunConfig
from mrguide.task import ACT_DIM, OBS_DIM
from mrguide.twin.env import PickPlaceEnv

CLOSE_TIMEOUT = 30.0  # s for a process or thread to end when asked to (the actor kills the learner's after it)
POLL_S = 0.2  # s between the checks of a wait
LEARNER_STREAM = 1  # the learner's minibatch RNG is seeded (train.seed, this)


@dataclass(frozen=True)
class LearnerSetup:
    """What the learner's process builds its learner from: the learner's class, the run's config, the obs scaling."""

    cls: type
    run: RunConfig
    obs_offset: np.ndarray
    obs_scale: np.ndarray


@dataclass(frozen=True)
class Chunk:
    """Transitions the actor stored (stacked, with their tags ζ) and its step count after them."""

    obs: np.ndarray
    act: np.ndarray
    rew: np.ndarray
    next_obs: np.ndarray
    done: np.ndarray
    zeta: np.ndarray
    step: int


@dataclass(frozen=True)
class Publication:
    """Weights for the actor: `version` counts publications; `step` is the actor's step they are learned up to."""

    version: int
    step: int
    updates: int  # the learner's `updates`
    update_s: float  # wall time of its `learn` calls so far
    last_ratio: float  # the expert share of its last minibatch
    weights: dict[str, np.ndarray]
    stats: UpdateStats  # since the previous publication


@dataclass(frozen=True)
class Message:
    """A request to the learner ("state", "load" with `state`, "evaluate" with {step, seeds}, "forget", "stop") or its
    answer ("ready", "state", "loaded", "evaluated" with {step, success_rate, mean_return}, "failed" with `error`)."""

    kind: str
    state: dict | None = None
    error: str | None = None


def acting_weights(agent: Learner) -> dict[str, np.ndarray]:
    """Copies of the weights `agent.act` reads, as numpy arrays named module.parameter."""
    return {
        f"{name}.{key}": value.detach().numpy().copy()
        for name in agent.acting_modules
        for key, value in getattr(agent, name).state_dict().items()
    }


class Sender:
    """Sends messages down a pipe from a thread of its own: a full pipe (a busy reader) never holds up the caller.
    The thread ends at `close` or when the reader's end is gone."""

    def __init__(self, conn: Connection, name: str):
        self.conn = conn
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, message: Any) -> None:
        self._queue.put(message)

    def _run(self) -> None:
        while (message := self._queue.get()) is not None:
            try:
                self.conn.send(message)
            except (OSError, ValueError):  # the reader is gone
                return

    def close(self, timeout: float) -> None:
        """Send what was put, then end; the pipe is closed once the thread has ended (within `timeout` s)."""
        self._queue.put(None)
        self._thread.join(timeout)
        if not self._thread.is_alive():
            self.conn.close()


class LearnerServer:
    """The learner's process: the replay buffer, the learner, the updates it owes, its publications."""

    def __init__(self, setup: LearnerSetup, inbox: Connection, outbox: Sender):
        self.run = run = setup.run
        self.train, self.guidance = run.train, run.guidance
        self.env: PickPlaceEnv | None = None  # for the evaluations the actor asks for
        torch.set_num_threads(self.train.torch_threads)
        self.agent: Learner = setup.cls(setup.obs_offset, setup.obs_scale, ACT_DIM, run.learner, seed=self.train.seed)
        self.replay = TaggedReplay(self.train.buffer_size, OBS_DIM, ACT_DIM)
        self.rng = np.random.default_rng([self.train.seed, LEARNER_STREAM])
        self.inbox, self.outbox = inbox, outbox
        self.seen_step = self.owed = self.version = self.calls = 0
        self.update_s, self.last_ratio = 0.0, 0.0
        self.stats = UpdateStats()

    def serve(self) -> None:
        """Warm up, say so, then take in messages and make the updates owed until told to stop."""
        self._warm_up()
        self.outbox.put(Message("ready"))
        try:
            self._serve()
        finally:
            if self.env is not None:
                self.env.close()

    def _serve(self) -> None:
        while True:
            while self.owed == 0 or self.inbox.poll():
                if not self.inbox.poll(POLL_S):
                    continue
                message = self.inbox.recv()  # EOFError: the actor's end is gone
                if isinstance(message, Chunk):
                    self._store(message)
                elif message.kind == "stop":
                    return
                elif message.kind == "forget":  # a person corrected the grasp (`Learning.forget`)
                    # the updates owed were the emptied pools': as in the actor's process, the next comes once the
                    # pools hold learning_starts transitions again (an update owed here sampled an empty pool)
                    self.replay.clear()
                    self.owed = 0
                else:
                    self.outbox.put(self._answer(message))
            self._update()

    def _warm_up(self) -> None:
        """One `learn` call on random data, undone: TorchInductor builds the update before the actor's first step."""
        saved, torch_rng = copy.deepcopy(self.agent.state_dict()), torch.get_rng_state()
        rng = np.random.default_rng(0)
        n = self.train.batch_size
        dummy = TaggedReplay(n, OBS_DIM, ACT_DIM)
        obs, act = rng.uniform(-1.0, 1.0, (2 * n, OBS_DIM)), rng.uniform(-1.0, 1.0, (2 * n, ACT_DIM))
        for i in range(2 * n):  # both pools
            dummy.add(obs[i], act[i], 0.0, obs[i], False, i % 2)
        self.agent.learn(dummy, 0.5, n, rng)
        self.agent.load_state_dict(saved)
        torch.set_rng_state(torch_rng)

    def _store(self, chunk: Chunk) -> None:
        for i in range(len(chunk.rew)):
            self.replay.add(chunk.obs[i], chunk.act[i], chunk.rew[i], chunk.next_obs[i], chunk.done[i], chunk.zeta[i])
        new = chunk.step - self.seen_step
        self.seen_step = chunk.step
        self.owed += min(new, max(0, len(self.replay) - self.train.learning_starts + 1))

    def _update(self) -> None:
        """The oldest update owed, with λ_t of its step; a publication every `publish_every` calls."""
        lam = lam_at(self.seen_step - self.owed + 1, self.train, self.guidance)
        t = time.perf_counter()
        stats, ratio = self.agent.learn(self.replay, lam, self.train.batch_size, self.rng)
        self.update_s += time.perf_counter() - t
        self.owed -= 1
        self.calls += 1
        self.last_ratio = ratio
        self.stats.add(stats, ratio)
        if self.calls % self.train.publish_every == 0:
            self.version += 1
            weights = acting_weights(self.agent)
            step = self.seen_step - self.owed
            self.outbox.put(
                Publication(self.version, step, self.agent.updates, self.update_s, ratio, weights, self.stats)
            )
            self.stats = UpdateStats()

    #: The learner's own counters in its state, beside its RNGs.
    COUNTERS = ("seen_step", "owed", "version", "calls", "update_s", "last_ratio")

    def _answer(self, request: Message) -> Message:
        if request.kind == "state":
            return Message("state", state=self.state())
        if request.kind == "evaluate":
            assert request.state is not None
            return Message("evaluated", state=self._evaluate(request.state["step"], request.state["seeds"]))
        assert request.kind == "load" and request.state is not None, request.kind
        try:
            self.load(request.state)
        except (KeyError, TypeError, RuntimeError, ValueError) as exc:
            return Message("loaded", error=f"{type(exc).__name__}: {exc}")
        return Message("loaded")

    def _evaluate(self, step: int, seeds: list[int]) -> dict:
        """The actor's evaluation at its step `step`, made here with the weights learned so far (in an env of this
        process's own, built at the first request: a learner fed by another actor never builds one)."""
        if self.env is None:
            self.env = PickPlaceEnv(self.run.env)
        success_rate, mean_return = evaluate_policy(self.env, self.agent.act, seeds)
        return {"step": step, "success_rate": success_rate, "mean_return": mean_return}

    def state(self) -> dict:
        """What a checkpoint saves of the learner (copies: the sender pickles them later)."""
        own = {k: getattr(self, k) for k in self.COUNTERS}
        return {
            "agent": copy.deepcopy(self.agent.state_dict()),
            "agent_pool": self.replay.agent.state(),
            "expert_pool": self.replay.expert.state(),
            "learner": {**own, "rng": self.rng.bit_generator.state, "torch_rng": torch.get_rng_state()},
        }

    def load(self, state: dict) -> None:
        self.agent.load_state_dict(state["agent"])
        self.replay.agent.load(state["agent_pool"])
        self.replay.expert.load(state["expert_pool"])
        own = state["learner"]
        self.rng.bit_generator.state = own["rng"]
        torch.set_rng_state(own["torch_rng"])
        for k in self.COUNTERS:
            setattr(self, k, own[k])


def serve(setup: LearnerSetup, inbox: Connection, outbox: Connection) -> None:
    """The learner's process: build, warm up and serve; a failure is sent to the actor before the process ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the actor's: it checkpoints, then stops this process
    sender = Sender(outbox, "mrguide-learner-publish")
    try:
        LearnerServer(setup, inbox, sender).serve()
    except EOFError:  # the actor's process is gone: nobody to learn for
        pass
    except BaseException as exc:  # said to the actor in one line; the traceback goes to this process's stderr
        sender.put(Message("failed", error=f"{type(exc).__name__}: {exc}"))
        raise
    finally:
        sender.close(CLOSE_TIMEOUT)
