"""A live annotation session: the trainer's expert source is a person (or a bot) behind the broker and server.

`LiveSession` starts the server when the trainer builds its expert source (`source_factory(env)`), so the
page shows the same robot, task and workspace the twin runs; `LiveExpert` turns each expert request
into an `AnnotationRequest` and each answer into an `Annotation` tagged with who gave it and how fast.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.annotation.broker import CLAIM_TIMEOUT_S, AnnotationBroker, LiveAnswer
from mrguide.annotation.protocol import AnnotationRequest
from mrguide.annotation.server import AnnotationServer
from mrguide.calibration.calibration_file import load_calibration
from mrguide.calibration.errors import CalibrationError
from mrguide.config import ConfigError
from mrguide.parts import part_drawing, part_named
from mrguide.policies.annotations import Annotation
from mrguide.policies.experts import OracleExpert
from mrguide.robot import RobotSpec
from mrguide.task import OBS_GOAL, OBS_GRIP, OBS_OBJECT, OBS_PROGRESS, OBS_TCP, TaskConfig, phase_from_progress
from mrguide.twin.env import PickPlaceEnv

log = logging.getLogger(__name__)

ON_TIMEOUT = ("wait", "skip", "oracle")


@dataclass(frozen=True)
class LiveOptions:
    """How the live session serves and what it does when nobody answers."""

    host: str = "127.0.0.1"
    port: int = 8765
    cert: str | None = None
    key: str | None = None
    token: str | None = None  # default: a fresh random token per session
    on_timeout: str = "wait"  # "wait" (training pauses), "skip" (drop the demonstration), "oracle" (fallback)
    timeout_s: float = 30.0  # how long a request waits under "skip" and "oracle"
    claim_timeout_s: float = CLAIM_TIMEOUT_S  # a claimant that sends nothing for this long loses its claim
    registration: str | None = None  # calibration JSON of `mrguide calibrate`: places the scene in XR

    def __post_init__(self) -> None:
        if self.on_timeout not in ON_TIMEOUT:
            raise ValueError(f"on-timeout must be one of {', '.join(ON_TIMEOUT)}, got {self.on_timeout!r}")
        if not (self.timeout_s > 0 and np.isfinite(self.timeout_s)):
            raise ValueError(f"annotation timeout must be a positive number of seconds, got {self.timeout_s}")
        if not (self.claim_timeout_s > 0 and np.isfinite(self.claim_timeout_s)):
            raise ValueError(f"claim timeout must be a positive number of seconds, got {self.claim_timeout_s}")
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be in 0..65535, got {self.port}")


@dataclass
class LiveCounts:
    """What the live expert was given: answers by people/bots, oracle fallbacks, dropped requests."""

    answers: int = 0
    fallbacks: int = 0
    skipped: int = 0
    timeouts: int = 0


#: The scene a request shows beside the observation: the arm's joints (rad) and the part's orientation (xyzw).
Scene = Callable[[], tuple[np.ndarray, np.ndarray]]


def twin_scene(env: PickPlaceEnv) -> Scene:
    """The twin's exact joints and the part's orientation, as a request shows them in training."""
    return lambda: (env.scene.joint_positions(noisy=False), env.scene.object_pose()[1])


class LiveExpert:
    """Expert source that asks through the broker (ExpertSource protocol of mrguide.policies.experts); `scene` gives
    what a request shows beside the observation (the twin's in training, the cell's as the runtime senses it)."""

    def __init__(self, broker: AnnotationBroker, scene: Scene, task: TaskConfig, on_timeout: str, timeout_s: float):
        self.broker, self.scene = broker, scene
        self.on_timeout = on_timeout
        self.timeout_s = None if on_timeout == "wait" else timeout_s
        self.oracle = OracleExpert(task)
        self.counts = LiveCounts()
        self.unanswered: str | None = None  # why the last request ended without an answer ("timeout", "skipped", ...)
        self._unacknowledged: dict[str, LiveAnswer] = {}  # answers given out, acknowledged once recorded

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation | None:
        """Ask the person for the current phase's waypoint; None when the demonstration is to be dropped."""
        obs = np.asarray(obs)
        joints, orientation = self.scene()
        req = AnnotationRequest(
            phase=phase_from_progress(obs[OBS_PROGRESS]),
            joints=joints,
            tcp=obs[OBS_TCP],
            vacuum_on=bool(obs[OBS_GRIP] > 0),
            object_position=obs[OBS_OBJECT],
            object_orientation=orientation,
            goal=obs[OBS_GOAL],
            obs=obs,
            remark=previous is not None,
            previous_target=None if previous is None else np.asarray(previous.target),
        )
        res = self.broker.request(req, self.timeout_s, acknowledge=False)
        if isinstance(res, LiveAnswer):
            self.counts.answers += 1
            self._unacknowledged[res.request_id] = res
            return Annotation(
                res.target,
                1.0 if res.vacuum else -1.0,
                "live",
                {
                    "client": res.client,
                    "client_id": res.client_id,
                    "request": res.request_id,
                    "latency_s": round(res.latency_s, 4),
                },
                res.here,
            )
        if res.reason == "timeout":
            self.counts.timeouts += 1
            if self.on_timeout == "oracle":
                self.counts.fallbacks += 1
                exact = self.oracle.annotate(obs)
                return Annotation(
                    exact.target, exact.grip, "oracle", {"request": res.request_id, "fallback": "timeout"}
                )
        self.unanswered = res.reason
        if res.reason in ("timeout", "skipped"):
            self.counts.skipped += 1
        log.info("annotation request %s ended without an answer: %s", res.request_id, res.reason)
        return None

    def intervention_requested(self) -> bool:
        """Whether a person asked to step in since the last call (the trainer then demonstrates the episode)."""
        return self.broker.take_intervention() is not None

    def recorded(self, annotation: Annotation) -> None:
        """The trainer has the annotation on disk: acknowledge the answer to the client that gave it."""
        answer = self._unacknowledged.pop(annotation.info.get("request", ""), None)
        if answer is not None:
            self.broker.acknowledge(answer)


class LiveSession:
    """Broker + server + live expert for one training run; `close()` ends them."""

    def __init__(self, options: LiveOptions, on_waiting: Callable[[bool], None] | None = None):
        self.options = options
        self.on_waiting = on_waiting
        self.broker: AnnotationBroker | None = None
        self.server: AnnotationServer | None = None
        self.expert: LiveExpert | None = None
        self._registration = _load_registration(options.registration) if options.registration else None

    def source_factory(self, env: PickPlaceEnv) -> LiveExpert:
        """Start serving for `env` (its robot, task and workspace) and return the expert source."""
        o = self.options
        spec = env.robot_spec
        hello = hello_fields(spec, env.task_cfg, self._registration, o.on_timeout)
        self.broker = AnnotationBroker(spec.workspace, hello, o.claim_timeout_s)
        self.broker.on_waiting = self.on_waiting
        self.server = AnnotationServer(self.broker, spec, o.host, o.port, o.cert, o.key, o.token)
        self.server.start()
        self.expert = LiveExpert(self.broker, twin_scene(env), env.task_cfg, o.on_timeout, o.timeout_s)
        return self.expert

    @property
    def url(self) -> str:
        assert self.server is not None, "the session serves once the trainer has built its expert source"
        return self.server.url

    def publish(self, **status: Any) -> None:
        """Push the training status to every client."""
        if self.broker is not None and self.expert is not None:
            self.broker.publish_status(fallbacks=self.expert.counts.fallbacks, **status)

    def summary(self) -> str:
        """One line on what the people (and fallbacks) gave, for the end of a run."""
        if self.expert is None or self.broker is None:
            return "live annotation: no session"
        c, b = self.expert.counts, self.broker.stats
        refused = sum(b.refused.values())
        return (
            f"live annotation: {c.answers} answers from clients, {c.fallbacks} oracle fallbacks, {c.skipped} "
            f"demonstrations skipped ({c.timeouts} timeouts); {refused} client messages refused"
        )

    def interrupt(self) -> None:
        """End the outstanding request (the trainer is stopping)."""
        if self.broker is not None:
            self.broker.close()

    def close(self) -> None:
        if self.broker is not None:
            self.broker.close()
        if self.server is not None:
            self.server.stop()


def hello_fields(
    spec: RobotSpec, task: TaskConfig, registration: dict[str, Any] | None = None, on_timeout: str = "wait"
) -> dict[str, Any]:
    """What every client learns on connecting: the robot and its frame conventions, the task, the placement."""
    return {
        "robot": {
            "name": spec.name,
            "frame": spec.base_frame,
            "tcp_frame": "tcp",
            "units": "m",
            "angles": "rad",
            "quaternion": "xyzw",
            "up": "z",
            "urdf_url": "/robot/robot.urdf",
            "joint_names": list(spec.joint_names),
            "workspace": {"lo": spec.workspace.lo.tolist(), "hi": spec.workspace.hi.tolist()},
        },
        "task": asdict(task),
        "part": part_drawing(part_named(task.part)),
        "registration": registration,
        "on_timeout": on_timeout,
    }


def _load_registration(path: str) -> dict[str, Any]:
    """T_base_hmd of a calibration file, for placing the scene in the headset."""
    try:
        record = load_calibration(Path(path))
    except CalibrationError as exc:
        raise ConfigError(f"--registration: {exc}") from exc
    return {
        "T_base_hmd": np.asarray(record.T_base_hmd, dtype=float).tolist(),
        "method": record.method,
        "rms_residual_m": record.rms_residual_m,
    }
