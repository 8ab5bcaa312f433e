"""`PickPlaceEnv`: the paper's pick-and-place MDP as a Gymnasium env on the PyBullet twin.

One step is one policy decision: the normalized action is mapped into the workspace box, solved by
Pinocchio IK (warm-started at the measured joints) and executed as a Ruckig stream through the twin's
joint servos for one decision period. The reward, phases and outcomes come from `mrguide.task`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mrguide.config import load_section
from mrguide.motion.kinematics import IKError, Kinematics
from mrguide.motion.trajectory import JointStreamer
from mrguide.robot import RobotConfig, RobotSpec, load_robot
from mrguide.task import ACT_DIM, OBS_DIM, Outcome, TaskConfig, observation, oracle_action, progress, task_step
from mrguide.twin.config import Region, TwinConfig
from mrguide.twin.scene import Scene, SceneSnapshot

log = logging.getLogger(__name__)


class ActionError(ValueError):
    """An action that cannot be executed (wrong shape, NaN or inf)."""


@dataclass(frozen=True)
class EnvConfig:
    """Robot, twin and task configuration of one env (TOML sections [robot], [twin], [task])."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    twin: TwinConfig = field(default_factory=TwinConfig)
    task: TaskConfig = field(default_factory=TaskConfig)

    @classmethod
    def load(cls, path: str | Path | None) -> "EnvConfig":
        return cls(
            robot=load_section(RobotConfig, path, "robot"),
            twin=load_section(TwinConfig, path, "twin"),
            task=load_section(TaskConfig, path, "task"),
        )


@dataclass
class EnvSnapshot:
    """A restorable env state (see `PickPlaceEnv.snapshot`)."""

    scene: SceneSnapshot
    streamer: tuple[list[float], ...]
    phase: int
    t: int
    vacuum: bool
    obs: np.ndarray
    clamped: int


def _sample(rng: np.random.Generator, region: Region) -> np.ndarray:
    return rng.uniform(region.low, region.high)


class PickPlaceEnv(gym.Env):
    """Five-phase vacuum pick-and-place in the twin (observation and action as in DESIGN.md)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None, spec: RobotSpec | None = None):
        self.config = config or EnvConfig()
        self.robot_spec = spec or load_robot(self.config.robot)
        self.task_cfg = self.config.task
        self.twin_cfg = self.config.twin
        self.workspace = self.robot_spec.workspace
        self.render_mode = render_mode
        self.scene = Scene(self.robot_spec, self.twin_cfg, self.task_cfg.object_height)
        self.kin = Kinematics(self.robot_spec)
        self.streamer = JointStreamer(self.robot_spec, self.twin_cfg.control_period)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)
        lim = np.full(OBS_DIM, 5.0, np.float32)
        lim[3], lim[4] = 1.0, 1.0
        low = -lim.copy()
        low[4] = 0.0
        self.observation_space = gym.spaces.Box(low, lim, (OBS_DIM,), np.float32)
        self.phase = 0
        self.t = 0
        self.vacuum = False
        self.clamped = 0
        self.ik_failures = 0
        self._obs = np.zeros(OBS_DIM, np.float32)
        self._camera = None

    # -- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """New episode; `options` may fix `object` and/or `goal` (xy or xyz, base frame)."""
        super().reset(seed=seed)
        options = options or {}
        h = 0.5 * self.task_cfg.object_height
        obj = self._position(options.get("object"), self.twin_cfg.object_region, h)
        goal = self._position(options.get("goal"), self.twin_cfg.goal_region, h)
        self.scene.reseed(int(self.np_random.integers(2**63)))
        self.scene.place(self.robot_spec.q_home, obj, goal)
        self.streamer.reset(self.robot_spec.q_home)
        self.phase, self.t, self.vacuum, self.clamped, self.ik_failures = 0, 0, False, 0, 0
        self._obs = self._observe()
        return self._obs.copy(), {"phase": 0, "object": obj, "goal": goal}

    def _position(self, given: Any, region: Region, h: float) -> np.ndarray:
        if given is None:
            xy = _sample(self.np_random, region)
        else:
            xy = np.asarray(given, dtype=float)[:2]
            if not np.all(np.isfinite(xy)):
                raise ValueError(f"reset option position must be finite, got {given}")
        return np.array([xy[0], xy[1], h])

    def step(self, action: np.ndarray):
        a = np.asarray(action, dtype=float)
        if a.shape != (ACT_DIM,):
            raise ActionError(f"action must have shape ({ACT_DIM},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ActionError(f"action contains NaN or inf: {a.tolist()}")
        clipped = np.clip(a, -1.0, 1.0)
        was_clamped = bool(np.any(clipped[:3] != a[:3]))
        self.clamped += int(was_clamped)
        if was_clamped:
            log.debug("action %s outside [-1, 1]: target clamped to the workspace box", a[:3])
        target = self.workspace.to_cartesian(clipped[:3])
        ik_failed = False
        try:
            q_target = self.kin.ik(target, self.scene.joint_positions())
            self.streamer.set_target(q_target)
        except IKError as exc:
            ik_failed = True
            self.ik_failures += 1
            log.debug("IK failed, holding the previous target: %s", exc)
        self.vacuum = bool(clipped[3] > 0)
        self.scene.set_vacuum(self.vacuum)
        for _ in range(self.twin_cfg.cycles_per_decision):
            sp = self.streamer.step()
            self.scene.command(sp.q, sp.dq)
            self.scene.step()
        tcp = self.kin.tcp_position(self.scene.joint_positions())
        g = 1 if self.vacuum else -1
        part = self.scene.suction.part_present(self.scene.vacuum_level())
        obj = self.scene.object_position()
        res = task_step(self.task_cfg, self.phase, tcp, g, part, obj, self.scene.goal, self.t)
        self.t += 1
        self.phase = res.phase
        success = res.outcome is Outcome.SUCCESS
        self._obs = observation(tcp, g, progress(self.phase, success), obj, self.scene.goal)
        terminated = res.outcome in (Outcome.SUCCESS, Outcome.DROPPED, Outcome.MISPLACED, Outcome.KNOCKED_OFF)
        truncated = res.outcome in (Outcome.NO_GRASP, Outcome.TIMEOUT)
        info = {
            "phase": self.phase,
            "outcome": res.outcome.value if res.outcome else None,
            "is_success": success,
            "reward_terms": res.terms,
            "distance": res.distance,
            "part_present": part,
            "clamped": was_clamped,
            "clamped_total": self.clamped,
            "ik_failed": ik_failed,
            "ik_failures_total": self.ik_failures,
        }
        return self._obs.copy(), res.reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        if self._camera is None:
            self._camera = self.scene.camera()
        return self._camera.render()

    def close(self) -> None:
        self.scene.close()

    # -- beyond gymnasium ------------------------------------------------------------------------
    def _observe(self) -> np.ndarray:
        tcp = self.kin.tcp_position(self.scene.joint_positions())
        return observation(tcp, 1 if self.vacuum else -1, progress(self.phase), self.scene.object_position(), self.scene.goal)

    def expert_action(self) -> np.ndarray:
        """The scripted expert's action for the current observation."""
        return oracle_action(self._obs, self.task_cfg, self.workspace.to_normalized)

    def snapshot(self) -> EnvSnapshot:
        """Capture the full state (physics, suction, trajectory, task, RNGs); `discard` it when done."""
        return EnvSnapshot(self.scene.snapshot(), self.streamer.snapshot(), self.phase, self.t, self.vacuum, self._obs.copy(), self.clamped)

    def restore(self, snap: EnvSnapshot) -> np.ndarray:
        """Return to a snapshot; the same actions from here reproduce the same observations."""
        self.scene.restore(snap.scene)
        self.streamer.restore(snap.streamer)
        self.phase, self.t, self.vacuum, self.clamped = snap.phase, snap.t, snap.vacuum, snap.clamped
        self._obs = snap.obs.copy()
        return self._obs.copy()

    def discard(self, snap: EnvSnapshot) -> None:
        self.scene.discard(snap.scene)
