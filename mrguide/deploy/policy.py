"""Exported policies: a small npz of actor weights + metadata, run with numpy alone on the robot PC.

The file is written by `mrguide.policies.export` and read here; loading checks the format, the
observation/action layout, the layer shapes, finiteness, (when given) that the workspace box and task
parameters match the configuration and that the policy was exported for the configured arm (name and
fingerprint, `mrguide.robot.RobotSpec`), and probes the policy on observations spanning its
workspace (every phase, both gripper states): finite weights can still overflow to a NaN/inf action.
So a wrong file is refused before any drive is enabled.
"""

from __future__ import annotations

import itertools
import json
import logging
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.config import ConfigError, to_dict
from mrguide.errors import InputError
from mrguide.parts import part_named
from mrguide.robot import RobotSpec, Workspace
from mrguide.task import (
    ACT_DIM,
    ACT_LAYOUT,
    N_PHASES,
    OBS_DIM,
    OBS_GOAL,
    OBS_GRIP,
    OBS_LAYOUT,
    OBS_OBJECT,
    OBS_PROGRESS,
    OBS_TCP,
    PHASES,
    TaskConfig,
    progress,
)

FORMAT = "mrguide-policy"
FORMAT_VERSION = 1
#: Longest decision period (s) a policy file may declare (the paper's policy acts every 0.1 s).
MAX_DECISION_PERIOD = 10.0
ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {"relu": lambda x: np.maximum(x, 0.0), "tanh": np.tanh}
#: The arm of policy files that record none (exported before arm identities): the only arm there was then.
LEGACY_ARM = "ur5"
#: The output head every policy file declares: target = anchor + max_offset · y, the part up to φ = carry_progress
#: and the goal beyond, with a second first layer (W0_carry, b0_carry) for the goal-anchored inputs. The heads of
#: earlier versions (absolute, tcp_offset, phase_anchor) are retired: their files are refused with the reason.
HEAD_KIND = "anchor_offset"
RETIRED_HEADS, RETIRED_IN = ("absolute", "tcp_offset", "phase_anchor"), "0.2.0"

log = logging.getLogger(__name__)


class PolicyFileError(InputError):
    """A policy file that cannot be used here; the message says why."""


@dataclass(frozen=True)
class OffsetHead:
    """The output head: target = anchor + max_offset · y (m), the part as anchor up to φ = `anchor_switch` and the
    goal beyond, normalized to the trained box."""

    max_offset: float
    centre: np.ndarray
    half: np.ndarray
    anchor_switch: float

    def __call__(self, obs: np.ndarray, y: np.ndarray) -> np.ndarray:
        base = np.where(
            obs[:, OBS_PROGRESS : OBS_PROGRESS + 1] > self.anchor_switch, obs[:, OBS_GOAL], obs[:, OBS_OBJECT]
        )
        pos = np.clip((base + self.max_offset * y[:, :3] - self.centre) / self.half, -1.0, 1.0)
        return np.column_stack([pos, y[:, 3:]])


@dataclass(frozen=True)
class CarryLayer:
    """The second first layer, used instead of layer 0 where φ > `progress` (transport and release: the
    goal-anchored inputs instead of the object-anchored ones; both maps folded into the weights)."""

    W: np.ndarray
    b: np.ndarray
    progress: float


@dataclass
class ExportedPolicy:
    """An MLP actor: obs (11,) → action (4,) in [-1, 1]; the MLP's output is an offset from the phase's anchor
    (`head`), and its first layer depends on the task phase (`carry`)."""

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    activations: list[str]
    metadata: dict[str, Any]
    head: OffsetHead
    carry: CarryLayer

    @property
    def decision_period(self) -> float:
        """The decision period (s) the policy was trained with: the runtime must act at the same rate."""
        return float(self.metadata["decision_period"])

    def with_grasp(self, task: TaskConfig) -> TaskConfig:
        """`task` with the grasp a person taught the policy (`TaskConfig.grasp`), where `task` sets none."""
        grasp = self.metadata.get("task", {}).get("grasp")
        return replace(task, grasp=tuple(grasp)) if task.grasp is None and grasp is not None else task

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.batch(np.asarray(obs, dtype=np.float64)[None])[0]

    def batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions (n, 4) for observations (n, 11)."""
        obs = np.asarray(obs, dtype=np.float64)
        x = obs
        for i, (W, b, act) in enumerate(zip(self.weights, self.biases, self.activations)):
            pre = x @ W.T + b
            if i == 0:
                pre = np.where(
                    obs[:, OBS_PROGRESS : OBS_PROGRESS + 1] > self.carry.progress,
                    x @ self.carry.W.T + self.carry.b,
                    pre,
                )
            x = ACTIVATIONS[act](pre)
        return self.head(obs, x).astype(np.float32)

    @classmethod
    def load(cls, path: str | Path, robot: RobotSpec | None = None, task: TaskConfig | None = None) -> ExportedPolicy:
        """Read and validate a policy file; with `robot`/`task`, also require its arm, workspace and task to match."""
        path = Path(path)
        if not path.is_file():
            raise PolicyFileError(f"policy file not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise PolicyFileError(f"{path}: not a readable policy file ({exc})") from exc
        meta = _metadata(path, arrays)
        acts = meta["activations"]
        weights = [_layer_array(path, arrays, f"W{i}") for i in range(len(acts))]
        biases = [_layer_array(path, arrays, f"b{i}") for i in range(len(acts))]
        width = OBS_DIM
        for i, (W, b) in enumerate(zip(weights, biases)):
            if W.ndim != 2 or W.shape[1] != width or b.shape != (W.shape[0],):
                raise PolicyFileError(
                    f"{path}: layer {i} has weights {W.shape} and bias {b.shape}; expected input width {width}"
                )
            if not (np.all(np.isfinite(W)) and np.all(np.isfinite(b))):
                raise PolicyFileError(f"{path}: layer {i} holds NaN or inf")
            width = W.shape[0]
        if width != ACT_DIM:
            raise PolicyFileError(f"{path}: output width {width}, expected {ACT_DIM}")
        trained = _trained_workspace(path, meta)
        if robot is not None:
            ws = robot.workspace
            if not (np.allclose(trained.lo, ws.lo) and np.allclose(trained.hi, ws.hi)):
                raise PolicyFileError(
                    f"{path}: trained for workspace {meta['workspace']}, the robot is configured for low={ws.low} high={ws.high}"
                )
            check_arm(path, meta, robot)
        if task is not None:
            theirs, ours = _task_fields(meta["task"]), to_dict(task)
            if task.grasp is None:  # the grasp a person taught the policy stands where the configuration sets none
                ours["grasp"] = theirs.get("grasp")
            diff = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
            if diff:
                raise PolicyFileError(f"{path}: task parameters differ from the configuration: {', '.join(diff)}")
        head = _head(path, meta, trained)
        carry = _carry_layer(path, meta, arrays, weights[0])
        policy = cls(weights, biases, acts, meta, head, carry)
        _refuse_non_finite_output(path, policy, trained)
        return policy


def check_decision_period(
    policy: ExportedPolicy, path: str | Path, control_period: float, configured: float | None = None
) -> None:
    """PolicyFileError unless the policy's decision period is `configured` (when given) and a whole number of
    control periods (s): the runtime acts at the rate the policy was trained for, or not at all."""
    period = policy.decision_period
    if configured is not None and abs(period - configured) > 1e-9:
        raise PolicyFileError(
            f"{path}: trained with a {period} s decision period, the configuration runs {configured} s"
        )
    ratio = period / control_period
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
        raise PolicyFileError(
            f"{path}: decision period {period} s is not a whole number of control periods ({control_period} s)"
        )


def check_arm(path: str | Path, meta: dict[str, Any], robot: RobotSpec) -> None:
    """PolicyFileError unless the policy file's metadata names `robot`'s arm with its fingerprint. A file that
    names no arm (exported before they were recorded) is taken for LEGACY_ARM, with a warning."""
    arm = meta.get("robot")
    if arm is None:
        if robot.name != LEGACY_ARM:
            raise PolicyFileError(
                f"{path}: records no arm (exported before arms were recorded, so for the {LEGACY_ARM}); "
                f"the configuration drives {robot.name!r}: train and export a policy for this arm"
            )
        log.warning(
            "%s: records no arm; taken for the %s it was trained on. Re-export it to record the arm", path, LEGACY_ARM
        )
        return
    if not isinstance(arm, dict) or not isinstance(arm.get("name"), str) or not isinstance(arm.get("fingerprint"), str):
        raise PolicyFileError(f"{path}: metadata robot {arm!r} is not an object with a name and a fingerprint")
    if arm["name"] != robot.name:
        raise PolicyFileError(
            f"{path}: exported for arm {arm['name']!r}, the configuration drives arm {robot.name!r} "
            f"({robot.arm_file}); a policy runs only on the arm it was trained for"
        )
    if arm["fingerprint"] != robot.fingerprint:
        raise PolicyFileError(
            f"{path}: exported for arm {arm['name']!r} with fingerprint {arm['fingerprint']}, the configured "
            f"{robot.name!r} has {robot.fingerprint}: its joints, frames, TCP offset, workspace box or URDF "
            "kinematics differ from the training arm's"
        )


def _metadata(path: Path, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """The file's metadata, every field checked for its type (PolicyFileError naming the field otherwise)."""
    if "metadata" not in arrays:
        raise PolicyFileError(f"{path}: no metadata in the file")
    try:
        meta = json.loads(str(arrays["metadata"]))
    except json.JSONDecodeError as exc:
        raise PolicyFileError(f"{path}: metadata is not valid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise PolicyFileError(f"{path}: metadata is a JSON {type(meta).__name__}, expected an object")
    if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
        raise PolicyFileError(
            f"{path}: format {meta.get('format')!r} v{meta.get('format_version')!r}, expected {FORMAT} v{FORMAT_VERSION}"
        )
    if meta.get("obs_layout") != list(OBS_LAYOUT) or meta.get("act_layout") != list(ACT_LAYOUT):
        raise PolicyFileError(
            f"{path}: observation/action layout {meta.get('obs_layout')!r} / {meta.get('act_layout')!r} differs from this stack's {OBS_LAYOUT} / {ACT_LAYOUT}"
        )
    period = meta.get("decision_period")
    if isinstance(period, bool) or not isinstance(period, (int, float)) or not 0 < period <= MAX_DECISION_PERIOD:
        raise PolicyFileError(
            f"{path}: metadata lacks a decision_period in (0, {MAX_DECISION_PERIOD:g}] s (got {period!r})"
        )
    acts = meta.get("activations")
    if not isinstance(acts, list) or not acts or any(not isinstance(a, str) or a not in ACTIVATIONS for a in acts):
        raise PolicyFileError(f"{path}: activations {acts!r} not understood (a list of {sorted(ACTIVATIONS)})")
    if not isinstance(meta.get("task", {}), dict):
        raise PolicyFileError(f"{path}: metadata task {meta['task']!r} is not an object of task parameters")
    meta.setdefault("task", {})
    return meta


def _head(path: Path, meta: dict[str, Any], trained: Workspace) -> OffsetHead:
    """The output head the metadata declares: HEAD_KIND with a max_offset (m) and a carry_progress in (0, 1)."""
    head = meta.get("head", {"kind": "absolute"})  # files without the field came before the output heads
    kind = head.get("kind") if isinstance(head, dict) else None
    if kind in RETIRED_HEADS:
        raise PolicyFileError(
            f"{path}: exported with the {kind!r} output head, which this version no longer runs (retired "
            f"in mrguide {RETIRED_IN}); train and export the policy again"
        )
    offset, switch = (_real(head.get(k)) if isinstance(head, dict) else None for k in ("max_offset", "carry_progress"))
    if kind != HEAD_KIND or offset is None or switch is None or not (0 < offset < 100 and 0 < switch < 1):
        raise PolicyFileError(
            f"{path}: metadata head {head!r} not understood ({HEAD_KIND} with a max_offset in m and a "
            "carry_progress in (0, 1))"
        )
    return OffsetHead(float(offset), 0.5 * (trained.lo + trained.hi), 0.5 * (trained.hi - trained.lo), float(switch))


def _real(value: object) -> float | None:
    """`value` if it is a real number (a JSON int or float; true and false are not), else None."""
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _carry_layer(path: Path, meta: dict[str, Any], arrays: dict[str, np.ndarray], W0: np.ndarray) -> CarryLayer:
    """W0_carry and b0_carry, shaped and checked as layer 0."""
    W, b = _layer_array(path, arrays, "W0_carry"), _layer_array(path, arrays, "b0_carry")
    if W.shape != W0.shape or b.shape != (W0.shape[0],):
        raise PolicyFileError(
            f"{path}: carry layer has weights {W.shape} and bias {b.shape}; expected those of layer 0, {W0.shape}"
        )
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(b))):
        raise PolicyFileError(f"{path}: carry layer holds NaN or inf")
    return CarryLayer(W, b, float(meta["head"]["carry_progress"]))


def _layer_array(path: Path, arrays: dict[str, np.ndarray], name: str) -> np.ndarray:
    """Layer array `name` as float64; only real numbers are weights (no strings, booleans, complex)."""
    if name not in arrays:
        raise PolicyFileError(f"{path}: layer array {name!r} missing")
    a = arrays[name]
    if a.dtype.kind not in "iuf":
        raise PolicyFileError(f"{path}: layer array {name} holds {a.dtype} values, expected real numbers")
    return a.astype(np.float64)


def _task_fields(theirs: dict) -> dict:
    """A policy file's task parameters as today's `TaskConfig` names them: a file from before the part library names
    its part by its edge (`object_height`), and every part then was the block."""
    if "part" in theirs or "object_height" not in theirs:
        return theirs
    fields = {k: v for k, v in theirs.items() if k != "object_height"}
    block = part_named("block")
    fields["part"] = block.name if theirs["object_height"] == block.height else f"a {theirs['object_height']} m cube"
    return fields


def _trained_workspace(path: Path, meta: dict[str, Any]) -> Workspace:
    ws = meta.get("workspace")
    corners = ws if isinstance(ws, dict) else {}  # no object: no corners (KeyError below)
    try:
        box = Workspace(low=_corner(corners["low"]), high=_corner(corners["high"]))
    except (TypeError, KeyError, ValueError, ConfigError) as exc:
        raise PolicyFileError(f"{path}: metadata workspace {ws!r} is not a box with low and high corners") from exc
    if not (np.all(np.isfinite(box.lo)) and np.all(np.isfinite(box.hi))):
        raise PolicyFileError(f"{path}: metadata workspace {ws!r} has non-finite corners")
    return box


def _corner(values: Any) -> tuple[float, float, float]:
    """A box corner (x, y, z); ValueError unless it is three numbers (TypeError if it is no sequence)."""
    x, y, z = map(float, values)
    return x, y, z


def probe_observations(workspace: Workspace) -> np.ndarray:
    """Deterministic observations spanning `workspace`, ordered by phase, then gripper state: TCP, object
    and goal each at the box's 8 corners and centre, every phase, g = -1 and +1 (9^3 x 5 x 2 = 7290 rows)."""
    lo, hi = workspace.lo, workspace.hi
    points = np.array([lo + (hi - lo) * np.array(c) for c in itertools.product((0.0, 1.0), repeat=3)] + [(lo + hi) / 2])
    idx = np.array(list(itertools.product(range(N_PHASES), (-1.0, 1.0), *[range(len(points))] * 3)))
    phi = np.array([progress(p) for p in range(N_PHASES)])
    tcp, obj, goal = (points[idx[:, k].astype(int)] for k in (2, 3, 4))
    return np.column_stack([tcp, idx[:, 1], phi[idx[:, 0].astype(int)], obj, goal])


def _refuse_non_finite_output(path: Path, policy: ExportedPolicy, workspace: Workspace) -> None:
    """PolicyFileError if the policy's action is NaN or inf anywhere on the probe observations."""
    obs = probe_observations(workspace)
    with np.errstate(over="ignore", invalid="ignore"):  # the overflow is what is being looked for
        actions = policy.batch(obs)
    bad = np.flatnonzero(~np.all(np.isfinite(actions), axis=1))
    if bad.size:
        bad_obs = obs[bad[0]]
        phase = round(bad_obs[OBS_PROGRESS] * N_PHASES)
        raise PolicyFileError(
            f"{path}: non-finite action for {bad.size} of {len(obs)} probe observations spanning the workspace, "
            f"e.g. {actions[bad[0]].tolist()} at tcp {np.round(bad_obs[OBS_TCP], 3).tolist()}, "
            f"g = {bad_obs[OBS_GRIP]:+.0f}, phase {phase} ({PHASES[phase]}), "
            f"object {np.round(bad_obs[OBS_OBJECT], 3).tolist()}, goal {np.round(bad_obs[OBS_GOAL], 3).tolist()}"
        )
