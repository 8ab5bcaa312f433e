"""`PickPlaceEnv`: the paper's pick-and-place MDP as a Gymnasium env on the PyBullet twin.

One step is one policy decision, made by the deploy stack's `DecisionStep` (motion/decision.py), the same
code the robot runs: the normalized action is clamped and mapped into the workspace box, solved by
Pinocchio IK (warm-started at the measured joints) and executed as a Ruckig stream through the twin's
joint servos for one decision period; the task model then gives the reward, phase and outcome.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from mrguide.config import ConfigFile
from mrguide.motion.decision import ActionError, DecisionState, DecisionStep
from mrguide.part_perception import PartPerception
from mrguide.parts import part_named
from mrguide.robot import RobotConfig, RobotSpec, load_robot, robot_config
from mrguide.task import ACT_DIM, OBS_DIM, OBS_GRIP, OBS_OBJECT, OBS_PROGRESS, Outcome, TaskConfig, oracle_action
from mrguide.twin.camera import Camera
from mrguide.twin.config import Region, TwinConfig
from mrguide.twin.scene import Scene, SceneSnapshot

log = logging.getLogger(__name__)


__all__ = ["ActionError", "EnvConfig", "EnvSnapshot", "PickPlaceEnv"]


@dataclass(frozen=True)
class EnvConfig:
    """Robot, twin and task configuration of one env (TOML sections [robot], [twin], [task])."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    twin: TwinConfig = field(default_factory=TwinConfig)
    task: TaskConfig = field(default_factory=TaskConfig)

    @classmethod
    def load(cls, path: str | Path | None) -> EnvConfig:
        return cls.from_file(ConfigFile.read(path))

    @classmethod
    def from_file(cls, file: ConfigFile) -> EnvConfig:
        return cls(robot_config(file), file.section(TwinConfig, "twin"), file.section(TaskConfig, "task"))


@dataclass
class EnvSnapshot:
    """A restorable env state (see `PickPlaceEnv.snapshot`)."""

    scene: SceneSnapshot
    decision: tuple[DecisionState, tuple[list[float], ...]]
    vacuum: bool
    obs: np.ndarray
    state_obs: np.ndarray
    perception: PartPerception


def _sample(rng: np.random.Generator, region: Region) -> np.ndarray:
    return rng.uniform(region.low, region.high)


class PickPlaceEnv(gym.Env):
    """Five-phase vacuum pick-and-place in the twin (observation and action as in DESIGN.md)."""

    # gymnasium annotates Env.metadata as an instance attribute, though it is read from the class (gym.make)
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}  # type: ignore[misc]

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None, spec: RobotSpec | None = None):
        self.config = config or EnvConfig()
        self.robot_spec = spec or load_robot(self.config.robot)
        self.task_cfg = self.config.task
        self.twin_cfg = self.config.twin
        self.workspace = self.robot_spec.workspace
        self.render_mode = render_mode
        self.scene = Scene(
            self.robot_spec, self.twin_cfg, part_named(self.task_cfg.part), visuals=render_mode == "rgb_array"
        )
        self.decision = DecisionStep(self.robot_spec, self.task_cfg, self.twin_cfg.control_period)
        self.kin, self.streamer = self.decision.kin, self.decision.streamer
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)
        lim = np.full(OBS_DIM, 5.0, np.float32)
        lim[OBS_GRIP], lim[OBS_PROGRESS] = 1.0, 1.0
        low = -lim.copy()
        low[OBS_PROGRESS] = 0.0
        self.observation_space = gym.spaces.Box(low, lim, (OBS_DIM,), np.float32)
        self.vacuum = False
        #: what the policy sees of the part (the pose source's errors, the runtime's rules: `part_perception`)
        half = 0.5 * self.task_cfg.object_height
        self.perception = PartPerception(self.twin_cfg.perception, half, self.task_cfg.grasp_offset)
        self._obs = np.zeros(OBS_DIM, np.float32)  # the observation, the part as perceived
        self._state_obs = self._obs.copy()  # the same with the part where it is: the scripted expert's
        self._camera: Camera | None = None

    # -- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """New episode; `options` may fix `object` and/or `goal` (xy or xyz, base frame)."""
        super().reset(seed=seed)
        options = options or {}
        h = 0.5 * self.task_cfg.object_height
        obj = self._position(options.get("object"), self.twin_cfg.object_region, h)
        goal = self._position(options.get("goal"), self.twin_cfg.goal_region, h)
        self.scene.reseed(int(self.np_random.integers(2**63)))
        if not self.twin_cfg.perception.exact:
            self.perception.reset(int(self.np_random.integers(2**63)))
        self.scene.place(self.robot_spec.q_home, obj, goal)
        self.decision.reset(self.robot_spec.q_home)
        self.vacuum = False
        self._observe()
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
        """One decision (see `DecisionStep`); ActionError for a misshaped or non-finite action."""
        decision = self.decision
        cmd = decision.act(action, self.scene.joint_positions())
        if cmd.clamped:
            log.debug("action %s outside [-1, 1]: target clamped to the workspace box", np.asarray(action)[:3])
        if cmd.ik_error:
            log.debug("IK failed, holding (braking to rest): %s", cmd.ik_error)
        self.vacuum = cmd.vacuum
        self.scene.set_vacuum(self.vacuum)
        for _ in range(self.twin_cfg.cycles_per_decision):
            sp = decision.streamer.step()
            self.scene.command(sp.q, sp.dq)
            self.scene.step()
        tcp = decision.tcp(self.scene.joint_positions())
        g = 1 if self.vacuum else -1
        part = self.scene.suction.part_present(self.scene.vacuum_level())
        obj = self.scene.object_position()
        res = decision.judge(tcp, g, part, obj, self.scene.goal)
        success = res.outcome is Outcome.SUCCESS
        self._state_obs = decision.observe(tcp, g, obj, self.scene.goal, success)
        self._obs = self._perceived(self._state_obs, obj, tcp, part)
        state = decision.state
        info = {
            "phase": state.phase,
            "outcome": res.outcome.value if res.outcome else None,
            "is_success": success,
            "reward_terms": res.terms,
            "distance": res.distance,
            "part_present": part,
            "clamped": cmd.clamped,
            "clamped_total": state.clamped,
            "ik_failed": cmd.q_target is None,
            "ik_failures_total": state.ik_failures,
        }
        terminated = res.outcome is not None and res.outcome.terminated
        truncated = res.outcome is not None and res.outcome.truncated
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
    def teach(self, task: TaskConfig) -> None:
        """Judge from now on by `task`: the same task with a grasp a person taught (`TaskConfig.grasp`)."""
        if replace(task, grasp=self.task_cfg.grasp) != self.task_cfg:
            raise ValueError("a taught task may differ from the env's only in its grasp")
        self.task_cfg = self.decision.task = task
        self.perception.hang = task.grasp_offset

    @property
    def phase(self) -> int:
        """Current task phase (0..4)."""
        return self.decision.state.phase

    @property
    def t(self) -> int:
        """Decisions taken in this episode."""
        return self.decision.state.t

    @property
    def clamped(self) -> int:
        """Decisions of this episode whose action was clamped."""
        return self.decision.state.clamped

    @property
    def ik_failures(self) -> int:
        """Decisions of this episode whose IK failed (the arm held)."""
        return self.decision.state.ik_failures

    def _observe(self) -> None:
        """The episode's first observation, and the state's."""
        tcp = self.decision.tcp(self.scene.joint_positions())
        g, obj = 1 if self.vacuum else -1, self.scene.object_position()
        self._state_obs = self.decision.observe(tcp, g, obj, self.scene.goal)
        self._obs = self._perceived(self._state_obs, obj, tcp, False)

    def _perceived(self, state_obs: np.ndarray, obj: np.ndarray, tcp: np.ndarray, held: bool) -> np.ndarray:
        """The observation with the part as the policy sees it: `state_obs` itself when it sees it exactly."""
        if self.twin_cfg.perception.exact:
            return state_obs
        seen = state_obs.copy()
        seen[OBS_OBJECT] = self.perception.see(obj, tcp, held)
        return seen

    def expert_action(self) -> np.ndarray:
        """The scripted expert's action: the task model's, on the twin's true state (the part where it is)."""
        return oracle_action(self._state_obs, self.task_cfg, self.workspace.to_normalized)

    def snapshot(self) -> EnvSnapshot:
        """Capture the full state (physics, suction, trajectory, task, RNGs); `discard` it when done."""
        return EnvSnapshot(
            self.scene.snapshot(),
            self.decision.snapshot(),
            self.vacuum,
            self._obs.copy(),
            self._state_obs.copy(),
            copy.deepcopy(self.perception),
        )

    def restore(self, snap: EnvSnapshot) -> np.ndarray:
        """Return to a snapshot; the same actions from here reproduce the same observations."""
        self.scene.restore(snap.scene)
        self.decision.restore(snap.decision)
        self.vacuum = snap.vacuum
        self._obs, self._state_obs = snap.obs.copy(), snap.state_obs.copy()
        self.perception = copy.deepcopy(snap.perception)
        return self._obs.copy()

    def discard(self, snap: EnvSnapshot) -> None:
        self.scene.discard(snap.scene)
