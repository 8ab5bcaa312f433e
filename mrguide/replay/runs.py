"""A run's logs as episodes of frames, whatever wrote them: `mrguide deploy` (real bus or `--dry-run`),
`mrguide sim2real` (its per-condition, per-seed run logs, also gzipped) and `mrguide train --record` (a run
directory's episodes.jsonl.gz). No Rerun, no PyBullet, no torch here.

A frame is the state at one decision t of an episode: the measured joints and TCP, the object as the policy
saw it (and, where the log has it, where it really was and how old the estimate was), the gripper, the
vacuum level and the part signal, the phase and φ; and what was decided from it: the action, the commanded
TCP target, the joint target and the setpoints streamed until the next decision, the decision's latency.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.errors import InputError
from mrguide.task import OBS_GRIP, OBS_OBJECT, OBS_PROGRESS, OBS_TCP, phase_from_progress


class RunError(InputError):
    """A run that cannot be read: not found, not a run log or training run, no episodes."""


def _arr(value: Any) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


@dataclass
class Frame:
    """One decision's state and what was decided from it (None where the log does not say)."""

    t: int
    phase: int
    phi: float | None = None
    g: int | None = None
    tcp: np.ndarray | None = None
    q: np.ndarray | None = None
    obj: np.ndarray | None = None  # as the policy saw it (its observation)
    obj_true: np.ndarray | None = None  # where it was (a simulated cell's ground truth)
    object_from: str | None = None  # "source" (the pose source), "carried" (under the cup), "released", "last"
    pose_age_s: float | None = None  # how old the pose source's estimate was
    vacuum_kpa: float | None = None
    part: bool | None = None
    action: np.ndarray | None = None
    target: np.ndarray | None = None  # commanded TCP target (the clamped action in the workspace box)
    q_target: np.ndarray | None = None
    setpoints: np.ndarray | None = None  # joint setpoints streamed until the next decision (cycles × dof)
    latency_ms: float | None = None
    inference_ms: float | None = None
    reward: float | None = None
    outcome: str | None = None  # on the frame that ended the episode
    zeta: int | None = None  # training: the step's tag in the replay buffer (1: expert data)
    annotation: int | None = None  # training: the annotations.jsonl record the expert followed


@dataclass
class Episode:
    """One episode of a run: where it came from, its goal and outcome, its frames and its safety events."""

    run: str  # the run's file or directory, as given
    index: int  # the episode's number in its run
    kind: str  # "deploy" (a run log's episode), "agent" or "expert" (a training episode)
    goal: np.ndarray | None
    outcome: str | None
    frames: list[Frame] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)  # {"t", "event", "reaction", "detail"}
    meta: dict = field(default_factory=dict)  # the run's header (command, condition, seed, ...)
    decision_period: float = 0.1

    @property
    def label(self) -> str:
        """A short name for entity paths: the run file's stem and the episode number."""
        stem = Path(self.run).name
        for suffix in (".gz", ".jsonl", ".json"):
            stem = stem.removesuffix(suffix)
        if stem in ("episodes", ""):
            stem = Path(self.run).parent.name or "train"
        parent = Path(self.run).parent
        prefix = f"{parent.parent.name}-" if parent.name == "sim2real" else ""
        return re.sub(r"[^A-Za-z0-9_-]+", "_", f"{prefix}{stem}-{self.kind[0]}{self.index}")

    def drop_frame(self) -> Frame | None:
        """The frame at which the part was found lost (outcome dropped), if it was."""
        for f in self.frames:
            if f.outcome == "dropped":
                return f
        return None


def load_run(path: str | Path) -> list[Episode]:
    """Every episode of the run at `path`: a run log (.jsonl or .jsonl.gz) or a training run directory (or its
    episodes.jsonl.gz). RunError if it is neither or holds no episode."""
    path = Path(path)
    if path.is_dir():
        recorded = path / "episodes.jsonl.gz"
        if not recorded.is_file():
            hint = (
                " (train with --record to keep the per-step data a replay needs)"
                if (path / "metrics.csv").exists()
                else ""
            )
            raise RunError(f"{path}: a directory without episodes.jsonl.gz{hint}")
        return training_episodes(recorded)
    if not path.is_file():
        raise RunError(f"{path}: no such run log or training run")
    if path.name.startswith("episodes.jsonl"):
        return training_episodes(path)
    return log_episodes(path)


# -- deploy / dry-run / sim-to-real run logs ---------------------------------------------------------------


def log_episodes(path: Path) -> list[Episode]:
    """The episodes of a deploy run log (dry run and sim-to-real logs are deploy run logs)."""
    from mrguide.deploy.runlog import read_log

    records = read_log(path)
    if not records or records[0].get("kind") != "run":
        raise RunError(f"{path}: not a run log (no 'run' record first)")
    header = records[0]
    period = float(header.get("decision_period") or 0.1)
    episodes: list[Episode] = []
    current: Episode | None = None
    for rec in records[1:]:
        kind = rec.get("kind")
        if kind == "episode_start":
            current = Episode(str(path), int(rec["episode"]), "deploy", _arr(rec.get("goal")), None, meta=header)
            current.decision_period = period
            episodes.append(current)
        elif kind in ("retry", "alarm") and episodes and episodes[-1].frames:
            _cycle_event(episodes[-1], rec)
        elif current is None:
            continue
        elif kind == "decision":
            current.frames.append(_decision_frame(rec))
        elif kind == "safety":
            current.events.append({k: rec.get(k) for k in ("t", "event", "reaction", "detail")})
        elif kind == "recovered":
            current.events.append({"t": rec.get("t"), "event": "recovered", "reaction": None, "detail": ""})
        elif kind == "episode_end":
            current.outcome = rec.get("outcome")
            if current.frames and current.frames[-1].outcome is None and current.outcome not in (None, "success"):
                current.frames[-1].outcome = current.outcome  # ended by the supervisor, not the task model
            current = None
    if not episodes:
        raise RunError(f"{path}: a run log without episodes")
    return episodes


def _cycle_event(episode: Episode, rec: dict) -> None:
    """A production cycle's retry or alarm, shown at the last frame of the attempt it followed."""
    if rec["kind"] == "retry":
        detail = f"cycle {rec.get('cycle')}: attempt ended {rec.get('cause')}, the part is picked again where it lies"
    else:
        detail = f"cycle {rec.get('cycle')}: {rec.get('reason')} ({rec.get('action')})"
    episode.events.append({"t": episode.frames[-1].t, "event": rec["kind"], "reaction": None, "detail": detail})


def _decision_frame(rec: dict) -> Frame:
    obs = _arr(rec.get("obs"))
    pose = rec.get("pose") or {}
    frame = Frame(
        t=int(rec["t"]),
        phase=int(rec.get("phase", 0)),
        tcp=obs[OBS_TCP] if obs is not None else _arr(rec.get("tcp")),
        g=int(obs[OBS_GRIP]) if obs is not None else rec.get("g"),
        phi=float(obs[OBS_PROGRESS]) if obs is not None else None,
        obj=obs[OBS_OBJECT] if obs is not None else None,
        obj_true=_arr(pose.get("true")),
        object_from=rec.get("object_from"),
        pose_age_s=pose.get("age_s"),
        q=_arr(rec.get("q")),
        vacuum_kpa=rec.get("vacuum_kpa"),
        part=rec.get("part"),
        action=_arr(rec.get("action")),
        target=_arr(rec.get("target")),
        q_target=_arr(rec.get("q_target")),
        setpoints=_arr(rec.get("setpoints")),
        latency_ms=rec.get("latency_ms"),
        inference_ms=rec.get("inference_ms"),
        reward=rec.get("reward"),
        outcome=rec.get("outcome"),
    )
    if frame.phi is None:
        frame.phi = frame.phase / 5
    return frame


# -- training runs (mrguide train --record) ----------------------------------------------------------------


def training_episodes(path: Path) -> list[Episode]:
    """The recorded episodes of a training run (see mrguide.policies.episode_recorder), as frames at the
    decisions' states: frame 0 is the episode's start (the arm at home), frame t+1 what step t reached."""
    from mrguide.policies.episode_recorder import read_episodes

    try:
        header, recorded, _ = read_episodes(path)
    except (OSError, ValueError) as exc:
        raise RunError(f"{path}: not a readable episode recording ({exc})") from exc
    if not recorded:
        raise RunError(f"{path}: no recorded episode")
    from mrguide.robot import RobotConfig, load_robot

    spec = load_robot(RobotConfig(name=header.get("robot", "")))
    q_home = _arr(header.get("q_home"))
    period = float(header.get("decision_period") or 0.1)
    out = []
    for rec in recorded:
        ep = Episode(str(path), int(rec["episode"]), rec["type"], _arr(rec.get("goal")), rec.get("outcome"))
        ep.meta = {**header, "trainer_episode": rec.get("trainer_episode")}
        ep.decision_period = period
        steps = rec["steps"]
        # the start state: the observation before the first step (the twin observes exactly), the arm at home
        first = np.asarray(steps[0]["obs"], dtype=float)
        ep.frames.append(_training_frame(0, first, q_home, first[OBS_OBJECT], 0.0, False))
        for k, s in enumerate(steps):
            frame = ep.frames[k]
            frame.action = np.asarray(s["action"], dtype=float)
            clipped = np.clip(frame.action, -1.0, 1.0)
            frame.target = spec.workspace.to_cartesian(clipped[:3])
            frame.zeta, frame.annotation = s.get("zeta"), s.get("annotation")
            nxt = np.asarray(s["next_obs"], dtype=float)
            after = _training_frame(k + 1, nxt, _arr(s["q"]), _arr(s["object"]), s["vacuum_kpa"], s["part"])
            after.reward = s["reward"]
            ep.frames.append(after)
        ep.frames[-1].outcome = ep.outcome
        out.append(ep)
    return out


def _training_frame(t: int, obs: np.ndarray, q, obj_true, vacuum_kpa: float, part: bool) -> Frame:
    return Frame(
        t=t,
        phase=phase_from_progress(obs[OBS_PROGRESS]),
        phi=float(obs[OBS_PROGRESS]),
        g=int(obs[OBS_GRIP]),
        tcp=obs[OBS_TCP],
        q=q,
        obj=obs[OBS_OBJECT],
        obj_true=obj_true,
        object_from="source",
        pose_age_s=0.0,
        vacuum_kpa=float(vacuum_kpa),
        part=bool(part),
    )


def select(episodes: list[Episode], indices: list[int] | None, outcomes: list[str] | None) -> list[Episode]:
    """The episodes with the given numbers (all if None) whose outcome is one of `outcomes` (any if None)."""
    chosen = [e for e in episodes if indices is None or e.index in indices]
    if outcomes:
        chosen = [e for e in chosen if e.outcome in outcomes]
    return chosen
