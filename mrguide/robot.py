"""Robot spec shared by the twin and the deploy stack, loaded from one arm file.

An arm file (`mrguide/arms/<name>.toml`, or any file given as `[robot] file`) holds everything about the
arm: its URDF (from the installed example-robot-data, or a file), joint names, base and flange frames,
the suction-cup (TCP) offset along the flange z-axis, joint limits, home configuration, the workspace box
and the joint <-> CAN node map. The twin, the IK, the bus and the policy export all read the `RobotSpec`
built from it. The TCP is the cup's lip, and the policy always commands it pointing down.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.resources
import json
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.config import ConfigError, ConfigFile, from_dict, load_toml, to_dict
from mrguide.urdf import UrdfError, example_robot_data, kinematic_chain

#: The arm of a run config without `[robot] name` or `file`.
DEFAULT_ARM = "ur5"

#: Orientation of the TCP frame in the base frame: z down, x along -y_base (the UR5 home yaw).
R_TOOL_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

#: Arm-file values a run config's [robot] may override.
OVERRIDABLE = ("tool_offset", "q_lower", "q_upper", "v_max", "a_max", "j_max", "q_home", "workspace")
LIMIT_KEYS = ("q_lower", "q_upper", "v_max", "a_max", "j_max", "q_home")


class RobotSpecError(ConfigError):
    """Unknown robot, unreadable arm file or URDF, or inconsistent arm values; names the file and key."""


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned box in the robot base frame that the normalized action [-1, 1]^3 maps onto (m)."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.high) > np.asarray(self.low)):
            raise ConfigError(f"workspace: high {self.high} must exceed low {self.low} on every axis")

    @property
    def lo(self) -> np.ndarray:
        return np.asarray(self.low, dtype=float)

    @property
    def hi(self) -> np.ndarray:
        return np.asarray(self.high, dtype=float)

    def to_cartesian(self, a: np.ndarray) -> np.ndarray:
        """Map a normalized target in [-1, 1]^3 to a point in the box."""
        return self.lo + (np.asarray(a, dtype=float) + 1.0) * 0.5 * (self.hi - self.lo)

    def to_normalized(self, p: np.ndarray) -> np.ndarray:
        """Inverse of `to_cartesian` (points outside the box map outside [-1, 1])."""
        return 2.0 * (np.asarray(p, dtype=float) - self.lo) / (self.hi - self.lo) - 1.0

    def clamp(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """Clamp a point into the box; returns (point, whether it was clamped)."""
        p = np.asarray(p, dtype=float)
        q = np.clip(p, self.lo, self.hi)
        return q, bool(np.any(q != p))

    def contains(self, p: np.ndarray, tol: float = 0.0) -> bool:
        p = np.asarray(p, dtype=float)
        return bool(np.all(p >= self.lo - tol) and np.all(p <= self.hi + tol))


@dataclass(frozen=True)
class UrdfSource:
    """[urdf] of an arm file: a URDF of example-robot-data (relative to its robots/ directory) or a file."""

    example_robot_data: str = ""
    #: URDF path, relative to the arm file (or absolute).
    file: str = ""
    #: Directory the URDF's package:// URIs resolve against, relative to the arm file; default: the URDF's.
    package_dir: str = ""

    def __post_init__(self) -> None:
        if bool(self.example_robot_data) == bool(self.file):
            raise ConfigError("urdf: give exactly one of example_robot_data and file")
        if self.package_dir and not self.file:
            raise ConfigError("urdf.package_dir: only with urdf.file (example-robot-data knows its own)")


@dataclass(frozen=True)
class ArmConfig:
    """An arm file: the arm, its tool, limits, home, workspace and drive node map (see mrguide/arms/ur5.toml)."""

    name: str
    urdf: UrdfSource
    joints: tuple[str, ...]
    base_frame: str
    flange_frame: str
    #: Suction cup length along the flange z-axis (m): flange to cup lip (the TCP).
    tool_offset: float
    #: Joint limits used by IK, trajectories and safety (rad, rad/s, rad/s^2, rad/s^3), in joint order.
    q_lower: tuple[float, ...]
    q_upper: tuple[float, ...]
    v_max: tuple[float, ...]
    a_max: tuple[float, ...]
    j_max: tuple[float, ...]
    q_home: tuple[float, ...]
    workspace: Workspace
    #: Joint name -> CANopen node ID of its drive.
    can_nodes: dict[str, int]


@dataclass(frozen=True)
class RobotConfig:
    """[robot] of a run config: the arm file (`name` of a shipped arm or a `file`) and overrides of its values."""

    #: A shipped arm, mrguide/arms/<name>.toml ("" = DEFAULT_ARM).
    name: str = ""
    #: Or an arm file; relative paths are relative to the run config's directory (`load_robot_config`).
    file: str = ""
    tool_offset: float | None = None
    q_lower: tuple[float, ...] | None = None
    q_upper: tuple[float, ...] | None = None
    v_max: tuple[float, ...] | None = None
    a_max: tuple[float, ...] | None = None
    j_max: tuple[float, ...] | None = None
    q_home: tuple[float, ...] | None = None
    #: Replaces the arm file's workspace box (both corners).
    workspace: Workspace | None = None

    def __post_init__(self) -> None:
        if self.name and self.file:
            raise ConfigError("robot: give name or file, not both")

    def overrides(self) -> dict[str, Any]:
        """The arm-file values this config replaces, as TOML-like values."""
        out = {}
        for key in OVERRIDABLE:
            value = getattr(self, key)
            if value is not None:
                out[key] = to_dict(value) if key == "workspace" else list(value) if isinstance(value, tuple) else value
        return out


@dataclass(frozen=True)
class RobotSpec:
    """Everything about the arm that both the twin and the real robot need."""

    name: str
    urdf_path: Path
    #: Directory that `package://` mesh URIs in the URDF resolve against.
    package_dir: Path
    joint_names: tuple[str, ...]
    base_frame: str
    flange_frame: str
    #: Flange-to-TCP transform (4x4).
    T_flange_tcp: np.ndarray
    q_lower: np.ndarray
    q_upper: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray
    q_home: np.ndarray
    workspace: Workspace
    #: CANopen node ID of each joint's drive, in joint order.
    node_ids: tuple[int, ...]
    #: The arm file it was loaded from.
    arm_file: Path
    #: Digest of what a policy depends on: joints, frames, TCP offset, workspace box, URDF chain.
    fingerprint: str

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(np.isfinite(q)) and np.all(q >= self.q_lower - tol) and np.all(q <= self.q_upper + tol))


def shipped_arms() -> dict[str, Path]:
    """Arm name -> arm file of the arms shipped with mrguide (package data, found from any directory)."""
    root = importlib.resources.files("mrguide").joinpath("arms")
    return {Path(str(p)).stem: Path(str(p)) for p in root.iterdir() if str(p).endswith(".toml")}


def arm_file(cfg: RobotConfig) -> Path:
    """The arm file `cfg` selects."""
    if cfg.file:
        path = Path(cfg.file)
        if not path.is_file():
            raise RobotSpecError(f"robot.file: arm file not found: {path}")
        return path
    name, arms = cfg.name or DEFAULT_ARM, shipped_arms()
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name) or name not in arms:
        raise RobotSpecError(f"unknown robot {name!r}; known robots: {', '.join(sorted(arms))} (or [robot] file = ...)")
    return arms[name]


def load_robot_config(path: str | Path | None) -> RobotConfig:
    """[robot] of run config `path`, with a relative `file` made relative to the config's directory."""
    return robot_config(ConfigFile.read(path))


def robot_config(file: ConfigFile) -> RobotConfig:
    """[robot] of a parsed run config, with a relative `file` made relative to the config's directory."""
    cfg = file.section(RobotConfig, "robot")
    if file.path is not None and cfg.file and not Path(cfg.file).is_absolute():
        cfg = dataclasses.replace(cfg, file=str(file.path.parent / cfg.file))
    return cfg


def load_robot(config: RobotConfig | None = None) -> RobotSpec:
    """Build the robot spec from its arm file and the config's overrides, checking them for consistency."""
    cfg = config or RobotConfig()
    path = arm_file(cfg)
    overrides = cfg.overrides()
    where = f"{path}" + (f" with [robot] overrides of {', '.join(overrides)}" if overrides else "")
    try:
        arm = from_dict(ArmConfig, {**_read_arm(path), **overrides}, where=where)
    except RobotSpecError:
        raise
    except ConfigError as exc:
        raise RobotSpecError(str(exc)) from exc
    return _build(arm, path, where)


def _read_arm(path: Path) -> dict[str, Any]:
    stat = path.stat()
    try:
        return dict(_read_toml(path.resolve(), stat.st_mtime_ns, stat.st_size))
    except ConfigError as exc:
        raise RobotSpecError(str(exc)) from exc


@functools.lru_cache(maxsize=32)
def _read_toml(path: Path, _mtime: int, _size: int) -> dict[str, Any]:
    return load_toml(path)


def _build(arm: ArmConfig, path: Path, where: str) -> RobotSpec:
    """The spec of a parsed arm file: URDF resolved, every array and the node map checked."""
    arrays = _limit_arrays(arm, where)
    if not 0 <= arm.tool_offset <= 2.0:
        raise RobotSpecError(f"{where}: tool_offset = {arm.tool_offset}: expected [0, 2] m")
    try:
        urdf, package_dir = _resolve_urdf(arm.urdf, path.parent)
        chain = kinematic_chain(urdf, arm.base_frame, arm.flange_frame)
    except UrdfError as exc:
        raise RobotSpecError(f"{where}: {exc}") from exc
    movable = tuple(j.name for j in chain if j.movable)
    if movable != arm.joints:
        raise RobotSpecError(
            f"{where}: joints {list(arm.joints)} differ from the URDF's movable joints from "
            f"{arm.base_frame} to {arm.flange_frame}: {list(movable)}"
        )
    if sorted(arm.can_nodes) != sorted(arm.joints):
        raise RobotSpecError(
            f"{where}: can_nodes names {sorted(arm.can_nodes)}, expected one node per joint {list(arm.joints)}"
        )
    nodes = tuple(arm.can_nodes[j] for j in arm.joints)
    if any(not 1 <= n <= 127 for n in nodes) or len(set(nodes)) != len(nodes):
        raise RobotSpecError(f"{where}: can_nodes {dict(arm.can_nodes)}: node IDs must be distinct, in 1..127")
    T = np.eye(4)
    T[2, 3] = arm.tool_offset
    payload = {
        "joints": arm.joints,
        "base_frame": arm.base_frame,
        "flange_frame": arm.flange_frame,
        "tool_offset": round(arm.tool_offset, 9),
        "workspace": to_dict(arm.workspace),
        "chain": [dataclasses.astuple(j) for j in chain],
    }
    fingerprint = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]
    return RobotSpec(
        name=arm.name,
        urdf_path=urdf,
        package_dir=package_dir,
        joint_names=arm.joints,
        base_frame=arm.base_frame,
        flange_frame=arm.flange_frame,
        T_flange_tcp=T,
        workspace=arm.workspace,
        node_ids=nodes,
        arm_file=path,
        fingerprint=fingerprint,
        **arrays,
    )


def _limit_arrays(arm: ArmConfig, where: str) -> dict[str, np.ndarray]:
    """Limits and home as arrays, one finite value per joint, positive rates, home within the limits."""
    arrays = {k: np.asarray(getattr(arm, k), dtype=float) for k in LIMIT_KEYS}
    for key, arr in arrays.items():
        if arr.shape != (len(arm.joints),) or not np.all(np.isfinite(arr)):
            raise RobotSpecError(
                f"{where}: {key}: expected {len(arm.joints)} finite values, got {list(getattr(arm, key))}"
            )
    if np.any(arrays["q_upper"] <= arrays["q_lower"]):
        raise RobotSpecError(f"{where}: q_upper must exceed q_lower for every joint")
    for key in ("v_max", "a_max", "j_max"):
        if np.any(arrays[key] <= 0):
            raise RobotSpecError(f"{where}: {key}: limits must be positive")
    if np.any(arrays["q_home"] < arrays["q_lower"]) or np.any(arrays["q_home"] > arrays["q_upper"]):
        raise RobotSpecError(f"{where}: q_home lies outside the joint limits")
    return arrays


def _resolve_urdf(source: UrdfSource, base: Path) -> tuple[Path, Path]:
    """(URDF path, package dir) of an arm file's [urdf]; relative paths are relative to the arm file."""
    if source.example_robot_data:
        return example_robot_data(source.example_robot_data)
    urdf = base / source.file
    if not urdf.is_file():
        raise UrdfError(f"urdf.file: {urdf} not found")
    package_dir = base / source.package_dir if source.package_dir else urdf.parent
    if not package_dir.is_dir():
        raise UrdfError(f"urdf.package_dir: {package_dir} is not a directory")
    return urdf, package_dir


def urdf_with_tool(spec: RobotSpec, mesh_root: str, cup_radius: float, stroke: float = 0.0) -> str:
    """The arm's URDF text with `package://` URIs rooted at `mesh_root` and the suction cup added.

    The cup is a cylinder link `suction_cup` on the flange, as long as the flange-to-TCP offset, and a
    massless `tcp` link sits at its lip. Used by the twin (file paths) and the annotation page (URLs).
    With `stroke` > 0 (m) the cup sits on a spring level-compensator: a prismatic joint along the tool axis
    that lets the cup retract by up to `stroke` towards the flange (0 = fully extended); else it is rigid.
    """
    root = ET.fromstring(spec.urdf_path.read_text().replace("package://", mesh_root))
    length = float(spec.T_flange_tcp[2, 3])
    cyl = f'<cylinder radius="{cup_radius}" length="{length}"/>'
    origin = f'<origin xyz="0 0 {length / 2}" rpy="0 0 0"/>'
    root.append(
        ET.fromstring(
            f'<link name="suction_cup"><inertial><mass value="0.1"/>{origin}'
            f'<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
            f'<visual>{origin}<geometry>{cyl}</geometry><material name="cup"><color rgba="0.15 0.15 0.15 1"/></material></visual>'
            f"<collision>{origin}<geometry>{cyl}</geometry></collision></link>"
        )
    )
    joint = (
        'type="fixed">'
        if stroke <= 0
        else f'type="prismatic"><axis xyz="0 0 1"/><limit lower="{-stroke}" upper="0" effort="1000" velocity="1"/>'
    )
    root.append(
        ET.fromstring(
            f'<joint name="flange_cup_joint" {joint}<parent link="{spec.flange_frame}"/><child link="suction_cup"/>'
            f'<origin xyz="0 0 0" rpy="0 0 0"/></joint>'
        )
    )
    root.append(
        ET.fromstring(
            '<link name="tcp"><inertial><mass value="0"/><origin xyz="0 0 0" rpy="0 0 0"/>'
            '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>'
        )
    )
    root.append(
        ET.fromstring(
            f'<joint name="cup_tcp_joint" type="fixed"><parent link="suction_cup"/><child link="tcp"/>'
            f'<origin xyz="0 0 {length}" rpy="0 0 0"/></joint>'
        )
    )
    return ET.tostring(root, encoding="unicode")
