"""On-cell learning, the learner's side: the learner of a training run goes on learning from a cell's decisions.

`mrguide deploy --cycles N --learn RUN_DIR` (a dry run or the robot): the deploy runtime is the actor
(`deploy.cell_learning`: the transitions of what the cell sensed, the newest policy version taken in between
episodes). `CellLearner` starts the learner of the training run in RUN_DIR in a process of its own (`LearnerProcess`,
as `train.learner_process` runs it in the twin) from that run's checkpoint — its networks, its optimizers and both
replay pools: the twin's transitions stay as prior data, the cell's join the agent pool, a person's intervention the
expert pool — and between episodes hands it the episode's transitions and exports each version it publishes as a
policy file for the runtime. The learner owes one update per cell decision (as in training) and the schedule of the
expert share λ_t goes on from the training run's last step.

Files in RUN_DIR/on-cell/: `policy-v<N>.npz` (each version the learner published), `learner.csv` (the learner per
episode: its weights' version and lag, its updates), `learner-state.pt` (the learner's state after each cycle run
and every `CHECKPOINT_EPISODES` episodes, which `--resume` goes on from).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mrguide.config import from_dict
from mrguide.deploy.cell_learning import LearningActor, LearningConfig, PolicyVersions, Transition, TransitionTap
from mrguide.deploy.policy import ExportedPolicy
from mrguide.errors import InputError
from mrguide.policies.checkpoint import read_checkpoint
from mrguide.policies.export import export_actor
from mrguide.policies.guidance import GuidanceConfig
from mrguide.policies.learner_process import LearnerProcess, LearnerProcessError
from mrguide.policies.learner_server import LearnerSetup
from mrguide.policies.learners import LEARNERS, make_learner
from mrguide.policies.networks import obs_scaling
from mrguide.policies.train_config import RunConfig, TrainConfig
from mrguide.policies.train_counters import TrainerCounters
from mrguide.robot import RobotSpec
from mrguide.task import ACT_DIM, TaskConfig

log = logging.getLogger(__name__)

ON_CELL = "on-cell"
STATE = "learner-state.pt"
#: The learner's state is written every this many episodes (and when the run ends).
CHECKPOINT_EPISODES = 50
#: The on-cell learner's minibatch RNG: seeded (train.seed, this).
ON_CELL_STREAM = 2


def _training_run(run_dir: Path) -> tuple[RunConfig, dict]:
    """The training run's configuration (as its checkpoint records what training read) and its checkpoint."""
    state = read_checkpoint(run_dir / "checkpoint.pt")
    record = state["config"]
    train = from_dict(TrainConfig, record["train"], f"{run_dir} checkpoint [train]")
    entry = LEARNERS[train.learner]
    learner: Any = from_dict(entry.config, record[entry.section], f"{run_dir} checkpoint [{entry.section}]")
    guidance = from_dict(GuidanceConfig, record["guidance"], f"{run_dir} checkpoint [guidance]")
    run = RunConfig(train=train, guidance=guidance).replace(**{entry.section: learner})
    return run, state


def _no_evaluation(result: dict) -> None:
    """The cell asks its learner for no evaluation in the twin: the cell's cycles are its evaluation."""


class CellLearner:
    """The learner of the training run in `run_dir`, learning from the cell `actor` acts on (`close` when done)."""

    def __init__(
        self,
        run_dir: Path,
        policy: ExportedPolicy,
        spec: RobotSpec,
        task: TaskConfig,
        learning: LearningConfig,
        seed: int,
        resume: bool,
    ):
        """`learning`: [deploy.learning] (the noise on the cell's actions, drawn from `seed`; the versions' trial)."""
        self.out = run_dir / ON_CELL
        if self.out.exists() and not resume:
            raise InputError(f"{self.out} exists: --resume to go on learning from it, or remove it")
        run, state = _training_run(run_dir)
        self.guidance = run.guidance  # how a person's marks become an expert (`deploy --annotate`)
        self.spec, self.task, self.decision_period = spec, task, policy.decision_period
        self.out.mkdir(parents=True, exist_ok=True)
        offset, scale = obs_scaling(spec.workspace)
        agent = make_learner(run.train.learner, run.learner, offset, scale, ACT_DIM, run.train.seed)
        self.counters = TrainerCounters(step=state["counters"]["step"])
        setup = LearnerSetup(type(agent), run, offset, scale)
        self.learner = LearnerProcess(setup, agent, self.counters, self.out, on_evaluation=_no_evaluation)
        self.lost: str | None = None
        self.episodes = 0
        saved = self.out / STATE
        try:
            gate = self._load(saved if resume and saved.exists() else None, state, run.train.seed)
            kept = int(gate.get("kept_version", 0))
            first = ExportedPolicy.load(self.out / f"policy-v{kept}.npz", spec, task) if kept else policy
        except BaseException:
            self.learner.close()
            raise
        versions = PolicyVersions(first, spec, task, learning, seed, version=kept)
        if gate:
            versions.gate.restore(gate)
        self._offered = kept
        self._rows: list[Transition] = []
        self.actor = LearningActor(versions, TransitionTap(self._rows.append), self.between_episodes)
        self._offer_newest()  # on --resume, the version the learner had

    def _load(self, saved: Path | None, training: dict, seed: int) -> dict:
        """The learner from its on-cell state (`saved`), else from the training run's checkpoint (its minibatches
        drawn from `seed`'s stream of its own); the versions' gate as saved ({} for a new session)."""
        gate: dict = {}
        if saved is not None:
            state = torch.load(saved, weights_only=False)
            self.counters.step, gate = state["step"], state.get("gate", {})
        else:
            rng = np.random.default_rng([seed, ON_CELL_STREAM]).bit_generator.state
            own: dict[str, Any] = {"seen_step": self.counters.step, "owed": 0, "version": 0, "calls": 0}
            own |= {"update_s": 0.0, "last_ratio": 0.0, "rng": rng, "torch_rng": torch.get_rng_state()}
            state = {k: training[k] for k in ("agent", "agent_pool", "expert_pool")} | {"learner": own}
        self.learner.load(state)
        return gate

    def between_episodes(self) -> None:
        """Hand the learner the last episode's transitions, take in its newest weights as a policy version."""
        rows, self._rows[:] = list(self._rows), []
        if self.lost is not None or not rows:
            return
        for t in rows:
            self.learner.add(t.obs, t.action, t.reward, t.next_obs, t.done, int(t.expert))
        self.counters.step += len(rows)
        self.learner.stepped(self.counters.step)  # the episode in one chunk: it owes one update per decision
        try:
            self.learner.episode_end(self.counters.step)
        except LearnerProcessError as exc:
            self.lost = str(exc)
            log.error("on-cell learning stopped, the cell acts on with policy version %d: %s", self.version, exc)
            return
        self.episodes += 1
        self._offer_newest()
        if self.episodes % CHECKPOINT_EPISODES == 0:
            self.save()

    def _offer_newest(self) -> None:
        """The learner's newest version, exported as a policy file and offered to the cell (once per version)."""
        if self.learner.version > self._offered:
            self._offered = self.learner.version
            self.actor.versions.offer(self.learner.version, self._export())

    @property
    def version(self) -> int:
        return self.actor.versions.version

    def _export(self) -> Path:
        """The learner's current weights (the actor's copy) as the policy file of their version."""
        path = self.out / f"policy-v{self.learner.version}.npz"
        extra = {"on_cell": {"version": self.learner.version, "step": self.counters.step}}
        return export_actor(self.learner.agent.policy_actor, path, self.spec, self.task, self.decision_period, extra)

    def status(self) -> dict[str, Any]:
        """For the progress line and the run log: the version acted with, the learner's updates, whether it is lost,
        the interventions (episodes a person's expert played, and those asked for that the policy played)."""
        counts = self.actor.counts.as_dict()
        gate = self.actor.versions.gate
        versions = {"version": self.version, "kept_version": self.actor.versions.kept_version}
        tried = {"versions_kept": gate.kept_count, "versions_dropped": gate.dropped_count}
        return versions | tried | {"updates": self.learner.agent.updates, "lost": self.lost, **counts}

    def save(self) -> None:
        """The learner's state, atomically (`--resume` goes on from it); nothing if the learner is lost."""
        if self.lost is not None:
            return
        gate = self.actor.versions.gate.state() | {"kept_version": self.actor.versions.kept_version}
        state = self.learner.state() | {"step": self.counters.step, "gate": gate}
        tmp = self.out / (STATE + ".tmp")
        torch.save(state, tmp)
        os.replace(tmp, self.out / STATE)

    def close(self) -> None:
        """Hand the learner the last episode's transitions, save its state, then stop its process."""
        try:
            self.between_episodes()
            self.save()
        except LearnerProcessError as exc:
            log.error("the on-cell learner's state could not be saved: %s", exc)
        finally:
            self.learner.close()
