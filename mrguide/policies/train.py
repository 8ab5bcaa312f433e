"""Training: guided DDPG (or the SAC peer) in the twin, with MR-style expert guidance injected into a tagged
replay buffer.

Read top to bottom: `TrainConfig` says what can be set; `Trainer.run` is the loop. One agent episode
runs with exploration noise; if its running reward drops below R_th (Eq. 12) while expert intake is
open, the episode is cut, its start state restored in the twin and the expert demonstrates it; the
demonstration's steps are stored with ζ = 1 phase by phase as it completes them. Every env step (agent or
expert) counts as a training step and is followed by the learner's update (DDPG: one, on a minibatch
mixed by λ_t, Eq. 9, 11): in this thread (`learning.LocalLearning`), or, with `train.learner_process`, in the
learner's own process while the env loop goes on with the latest weights it has (`learner_process`).

Files in the run directory: `metrics.csv` (a row per agent or expert episode), `eval.csv` (a row per evaluation),
`annotations.jsonl`, `checkpoint.pt`, with a learner process `learner.csv` (its weights' version and lag at every agent
episode's end); with a `TensorBoardLog` (`mrguide train --tensorboard`), the same figures in `tensorboard/`.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import dacite
import numpy as np
import torch

from mrguide import __version__
from mrguide.policies.annotations import AnnotationCache
from mrguide.policies.checkpoint import CheckpointError, read_checkpoint, with_defaults, write_checkpoint
from mrguide.policies.experts import ExpertSource
from mrguide.policies.guidance import REFERENCE_POSES, ThresholdTrigger
from mrguide.policies.guided_expert import GuidedExpert, make_expert_source
from mrguide.policies.learner_process import LearnerProcess
from mrguide.policies.learner_server import LearnerSetup
from mrguide.policies.learners import LEARNERS, Learner, make_learner
from mrguide.policies.learning import Learning, LocalLearning, evaluate_policy, lam_at
from mrguide.policies.networks import obs_scaling
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.train_config import RunConfig, TrainConfig, arm_record
from mrguide.policies.train_counters import TrainerCounters
from mrguide.policies.train_log import EVAL_FIELDS, METRIC_FIELDS, UPDATE_FIELDS, MetricSink, append_csv, truncate_logs
from mrguide.task import ACT_DIM, OBS_DIM, OBS_PROGRESS, phase_from_progress
from mrguide.twin.env import PickPlaceEnv

log = logging.getLogger(__name__)


EVAL_SEED_BASE = 1_000_000  # evaluation env seeds start here (training seeds come from the run's RNG)
#: A transition τ without its tag ζ: (s, a, r, s', done) (Eq. 7).
Transition = tuple[np.ndarray, np.ndarray, float, np.ndarray, bool]


class Trainer:
    """One seed's training run, resumable from its checkpoint."""

    #: Off by default; `mrguide train --record` attaches one (policies/episode_recorder.py): it sees every step.
    recorder: Any = None

    def __init__(
        self,
        run: RunConfig,
        out_dir: str | Path,
        source_factory: Callable[[PickPlaceEnv], ExpertSource] | None = None,
    ):
        """`source_factory` builds the expert source from the env (a live annotation session); default: the config's."""
        self.run_cfg = run
        self.cfg, self.guidance = cfg, guidance = run.train, run.guidance
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        torch.set_num_threads(cfg.torch_threads)
        self.env = PickPlaceEnv(run.env)
        scaling = obs_scaling(self.env.workspace)
        self.agent: Learner = make_learner(cfg.learner, run.learner, *scaling, ACT_DIM, cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.source = source_factory(self.env) if source_factory else make_expert_source(guidance, self.env, cfg.seed)
        reference = REFERENCE_POSES[guidance.reference](self.env.task_cfg)
        self.cache = AnnotationCache(guidance.cache_tolerance, self.out / "annotations.jsonl")
        self.counters = TrainerCounters(next_eval=cfg.eval_every)
        self.expert = GuidedExpert(
            self.source,
            reference,
            self.cache,
            guidance.delta,
            self.env.task_cfg,
            self.env.workspace.to_normalized,
            reask_after=guidance.reask_after,
            action_noise=guidance.action_noise,
            seed=cfg.seed,
            marks=guidance.marks,
            counts=self.counters,
            pose_error=guidance.pose_error,
            mark_precision=guidance.mark_precision,
        )
        self.trigger = ThresholdTrigger(guidance.r_threshold)
        self.stop_requested = threading.Event()  # set (e.g. on Ctrl-C) to stop at the next step
        self._segment: list[Transition] = []  # the demonstration's steps held until their phase completes
        self.sinks: list[MetricSink] = []  # also receive every metrics row and evaluation
        self._next_checkpoint = cfg.checkpoint_every
        self.last_eval: dict = {}
        self._t0 = time.perf_counter()  # a learner process's start-up counts in the wall time
        self.learning: Learning = (
            LearnerProcess(
                LearnerSetup(LEARNERS[cfg.learner].cls, run, *scaling),
                self.agent,
                self.counters,
                self.out,
                self.record_evaluation,
            )
            if cfg.learner_process
            else LocalLearning(self.agent, cfg, self.lam, self.rng, self.counters, OBS_DIM, ACT_DIM)
        )

    @property
    def replay(self) -> TaggedReplay:
        """The tagged replay buffer, where the updates run in this process (AttributeError otherwise)."""
        if not isinstance(self.learning, LocalLearning):
            raise AttributeError("the replay buffer is in the learner's process")
        return self.learning.replay

    # -- the loop --------------------------------------------------------------------------------
    def run(self, progress: Callable[[dict], None] | None = None, stop_at: int | None = None) -> None:
        """Train until `total_steps`, checkpointing and evaluating on the way.

        With `stop_at`, stop (and checkpoint) at the first episode end at or after that step, as an
        interrupted run would: resuming from there restores every counter, pool and RNG, but a resumed process
        starts with fresh PyBullet solver caches, so its states differ from the uninterrupted run's by float noise
        that a contact can grow (tests/policies/test_train.py), and a long run may then take another course.
        """
        end = self.cfg.total_steps
        stop = min(end, stop_at or end)
        while self.counters.step < stop and not self.stop_requested.is_set():
            row = self._agent_episode(end)
            self._log(row)
            if progress:
                progress(row)
            self.learning.episode_end(self.counters.step)  # LearnerProcessError if its learner is lost
            if self.stop_requested.is_set():
                break  # the caller checkpoints the state as it is
            if self.counters.step >= self.counters.next_eval:
                if self.counters.step < stop:
                    self._evaluate_beside()
                else:
                    self.evaluate()  # at the stop, by the actor: that of the policy exported
                self.counters.next_eval += self.cfg.eval_every
            if self.counters.step >= end and self.last_eval.get("step") != self.counters.step:
                self.evaluate()  # the final policy is always evaluated, by the actor: the exported one
            if self.counters.step >= self._next_checkpoint or self.counters.step >= stop:
                self.save_checkpoint()
                every = self.cfg.checkpoint_every
                self._next_checkpoint = (self.counters.step // every + 1) * every

    def _intake_open(self) -> bool:
        return self.guidance.enabled and self.counters.step < self.guidance.intake_steps

    def lam(self) -> float:
        return lam_at(self.counters.step, self.cfg, self.guidance)

    def _env_step(self, action: np.ndarray, zeta: int | None, obs: np.ndarray, stored: np.ndarray | None = None):
        """Execute `action`; store the transition with `stored` as its action (default: the executed one), tagged
        `zeta` — or, with zeta None, hold it in the demonstration's current phase (see `_expert_episode`)."""
        next_obs, r, term, trunc, info = self.env.step(action)
        if self.recorder is not None:
            self.recorder.step(self, obs, action, stored, zeta, r, next_obs, term, trunc, info)
        transition = (obs, action if stored is None else stored, r, next_obs, term)
        if zeta is None:
            self._segment.append(transition)
        else:
            self.learning.add(*transition, zeta)
        self.counters.step += 1
        self.learning.stepped(self.counters.step)
        return next_obs, r, term, trunc, info

    def _flush_segment(self, zeta: int) -> None:
        for obs, act, rew, next_obs, done in self._segment:
            self.learning.add(obs, act, rew, next_obs, done, zeta)
        self._segment = []

    def _agent_episode(self, end: int) -> dict:
        seed = int(self.rng.integers(2**31))
        obs, _ = self.env.reset(seed=seed)
        guided = self._intake_open()
        start = self.env.snapshot() if guided else None
        self.trigger.reset()
        ret, length, info, triggered, stepped_in = 0.0, 0, {"outcome": None, "is_success": False}, False, False
        person = getattr(self.source, "intervention_requested", None) if guided else None
        try:
            while self.counters.step < end and not self.stop_requested.is_set():
                action = self.agent.act(obs, self.rng)
                obs, r, term, trunc, info = self._env_step(action, 0, obs)
                ret += r
                length += 1
                if guided and not (term or trunc):
                    fired = self.trigger.update(r)
                    stepped_in = not fired and person is not None and person()  # a person stepped in: as Eq. 12 would
                    if fired or stepped_in:
                        triggered = True
                        break
                if term or trunc:
                    break
            if triggered:
                self.counters.interventions += 1
                self.counters.person_interventions += int(stepped_in)
                if start is not None:
                    obs = self.env.restore(start)
                self._expert_episode(obs, end, stepped_in)
        finally:
            if start is not None:
                self.env.discard(start)
        self.counters.episode += 1
        success = bool(info["is_success"]) and not triggered
        return self._row(
            "agent", ret, success, info["outcome"] if not triggered else "guided", length, triggered, stepped_in
        )

    def _expert_episode(self, obs: np.ndarray, end: int, person: bool = False) -> None:
        """The expert demonstrates from `obs` (ζ = 1); a waypoint nobody annotates ends the demonstration there.

        A demonstration's steps are held per phase and stored as expert data (ζ = 1) once the phase is completed;
        the steps of a phase it did not complete, and those after a mark that was marked again, go to the agent pool
        (ζ = 0): the critic learns from them, nothing clones them (ours: a mark the arm cannot complete is none)."""
        ret, length = 0.0, 0
        info: dict[str, Any] = {"outcome": None, "is_success": False}
        self.expert.begin_demonstration(person)
        attempt = self._attempt()
        while self.counters.step < end and not self.stop_requested.is_set():
            step = self.expert.action(obs)
            if (task := self.expert.retasked()) is not None:  # a person taught the grasp: the reward follows it
                self.env.teach(task)
            if self.expert.corrected():  # and corrected it: what was learned from (the old grasp's) is forgotten
                self.learning.forget()
            if step is None:
                self.counters.skipped += int(not self.stop_requested.is_set())
                info = {"outcome": "skipped", "is_success": False}
                break
            if self._attempt() != attempt:  # the earlier mark or probe did not complete the phase
                self._flush_segment(0)
                attempt = self._attempt()
            phase = phase_from_progress(obs[OBS_PROGRESS])
            obs, r, term, trunc, info = self._env_step(step.executed, None, obs, step.stored)
            if info["is_success"] or phase_from_progress(obs[OBS_PROGRESS]) > phase:
                self._flush_segment(1)
            ret += r
            length += 1
            if term or trunc:
                break
        self._flush_segment(0)
        self.expert.end_demonstration(bool(info["is_success"]))
        self._log(self._row("expert", ret, bool(info["is_success"]), info["outcome"], length, False))

    def _attempt(self) -> tuple[int, int]:
        """Which attempt at its phase the demonstration is on: a new mark or a new probe of the search starts one."""
        return self.counters.remarks, self.counters.probes

    # -- bookkeeping -----------------------------------------------------------------------------
    def update_ms(self) -> float:
        """Mean wall time of one update (minibatch sampling included), ms."""
        return self.counters.update_s / max(self.agent.updates, 1) * 1e3

    def wall_s(self) -> float:
        return self.counters.wall_s + time.perf_counter() - self._t0

    def _row(
        self, kind: str, ret: float, success: bool, outcome, length: int, triggered: bool, intervened: bool = False
    ) -> dict:
        """A metrics row; `expert_ratio` and the UPDATE_FIELDS are means over the updates since the last row."""
        ratio, means = self.learning.stats.take(self.counters.last_ratio)
        return {
            "step": self.counters.step,
            "episode": self.counters.episode,
            "kind": kind,
            "return": round(ret, 4),
            "success": int(success),
            "outcome": outcome,
            "length": length,
            "triggered": int(triggered),
            "lambda": round(self.lam(), 4),
            "expert_ratio": round(ratio, 4),
            "asked": self.counters.asked,
            "reused": self.counters.reused,
            "remarks": self.counters.remarks,
            "skipped": self.counters.skipped,
            "wall_s": round(self.wall_s(), 2),
            **{k: means.get(k, "") for k in UPDATE_FIELDS},
            "intervened": int(intervened),
            **self.counters.session_cost(self.env.twin_cfg.decision_period),
        }

    def _log(self, row: dict) -> None:
        append_csv(self.out / "metrics.csv", METRIC_FIELDS, row)
        for sink in self.sinks:
            sink.row(row)

    def evaluate(self) -> dict:
        """Deterministic policy from start states that differ from one evaluation to the next.

        Evaluation i uses env seeds 1e6 + i·n … 1e6 + i·n + n − 1 (n = eval_episodes), disjoint from the
        training stream, so a window of two evaluations covers 2n distinct start states and the same
        seed's evaluations are comparable across variants and runs.
        """
        if isinstance(self.learning, LearnerProcess):
            self.learning.settle()  # the evaluations asked of it first
        success_rate, mean_return = evaluate_policy(self.env, self.agent.act, self._eval_seeds())
        return self.record_evaluation(
            {"step": self.counters.step, "success_rate": success_rate, "mean_return": mean_return}
        )

    def _eval_seeds(self) -> list[int]:
        n = self.cfg.eval_episodes
        self.counters.evaluations += 1
        return [EVAL_SEED_BASE + (self.counters.evaluations - 1) * n + k for k in range(n)]

    def _evaluate_beside(self) -> None:
        """A periodic evaluation: by the learner's process, beside the actor, where it has one (its result is recorded
        when it comes); by the actor otherwise."""
        if isinstance(self.learning, LearnerProcess):
            self.learning.evaluate(self.counters.step, self._eval_seeds())
        else:
            self.evaluate()

    def record_evaluation(self, res: dict) -> dict:
        """An evaluation's result ({step, success_rate, mean_return}) to eval.csv, the sinks and the log."""
        append_csv(self.out / "eval.csv", EVAL_FIELDS, res)
        for sink in self.sinks:
            sink.evaluation(res)
        log.info("eval at step %d: success %.0f%%", res["step"], 100 * res["success_rate"])
        self.last_eval = res
        return res

    # -- checkpoints -----------------------------------------------------------------------------
    def _fingerprint(self) -> dict:
        return self.run_cfg.fingerprint(arm_record(self.env.robot_spec))

    def save_checkpoint(self) -> Path:
        """Everything to resume: networks, optimizers, both pools, RNG states, counters. Written atomically."""
        source_rng = self._source_rng()
        state = {
            "version": __version__,
            "config": self._fingerprint(),
            **self.learning.state(),  # the learner's networks and optimizers, both pools
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "annotator_rng": None if source_rng is None else source_rng.bit_generator.state,
            "expert_noise_rng": self.expert.rng.bit_generator.state,
            "measured": {str(k): [m.tolist() for m in v] for k, v in self.expert.fusion.measured.items()},
            "counters": dataclasses.asdict(dataclasses.replace(self.counters, wall_s=self.wall_s())),
        }
        return write_checkpoint(self.out / "checkpoint.pt", state)

    def _source_rng(self) -> Any:
        """The expert source's random stream (the simulated annotator's; checkpointed with the run), or None."""
        return getattr(self.source, "rng", None)

    def load_checkpoint(self, path: str | Path | None = None) -> None:
        """Resume from a checkpoint; a corrupt or mismatched file raises CheckpointError."""
        path = Path(path) if path else self.out / "checkpoint.pt"
        state = read_checkpoint(path)
        default_run = RunConfig(train=dataclasses.replace(TrainConfig(), learner=self.cfg.learner))
        stored = with_defaults(state["config"], default_run.fingerprint(arm_record(self.env.robot_spec)))
        if stored != self._fingerprint():
            diff = [k for k in stored if stored[k] != self._fingerprint().get(k)]
            raise CheckpointError(
                f"{path}: written with a different configuration (sections differ: {', '.join(diff)})"
            )
        try:
            self.learning.load(state)
            self.rng.bit_generator.state = state["rng"]
            torch.set_rng_state(state["torch_rng"])
            if state["annotator_rng"] is not None:
                self._source_rng().bit_generator.state = state["annotator_rng"]
            self.expert.rng.bit_generator.state = state["expert_noise_rng"]
            self.expert.fusion.measured = {
                int(k): [np.array(m, dtype=float) for m in v] for k, v in state["measured"].items()
            }
            self.counters.restore(state["counters"])
        except (KeyError, TypeError, RuntimeError, ValueError, AttributeError, dacite.DaciteError) as exc:
            raise CheckpointError(f"{path}: does not fit this trainer: {type(exc).__name__}: {exc}") from exc
        self._t0 = time.perf_counter()
        self._next_checkpoint = (self.counters.step // self.cfg.checkpoint_every + 1) * self.cfg.checkpoint_every
        self._reload_annotations()
        truncate_logs(self.out, self.counters.step)

    def _reload_annotations(self) -> None:
        """All annotations on disk, including those after the checkpoint: none is asked twice."""
        path = self.out / "annotations.jsonl"
        if path.exists():
            n = self.cache.load(path, repair=True)
            self.expert.reload()
            if (task := self.expert.retasked()) is not None:
                self.env.teach(task)
            log.info("reloaded %d annotations from %s", n, path)

    def close(self) -> None:
        try:
            self.learning.close()
        finally:
            self.env.close()
