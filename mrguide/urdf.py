"""URDF files of the arm: where they are (example-robot-data or a file) and the kinematic chain they hold.

No PyBullet and no Pinocchio here: the chain is read with ElementTree, for the checks of an arm file
(its joints and frames exist and form one chain) and for the arm's fingerprint.
"""

from __future__ import annotations

import functools
import importlib.metadata
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from mrguide.errors import InputError

#: example-robot-data's robot descriptions, relative to the installed distribution.
EXAMPLE_ROBOT_DATA_ROBOTS = "cmeel.prefix/share/example-robot-data/robots"


class UrdfError(InputError):
    """A URDF that cannot be found or read, or that lacks a joint or frame the arm file names."""


@dataclass(frozen=True)
class ChainJoint:
    """One joint between the base and the flange: name, type, origin (xyz, rpy) and axis, as in the URDF."""

    name: str
    type: str
    origin: tuple[float, ...]
    axis: tuple[float, ...]

    @property
    def movable(self) -> bool:
        return self.type not in ("fixed", "floating", "planar")


def example_robot_data(relative: str) -> tuple[Path, Path]:
    """(URDF path, package dir) of `relative` (e.g. "ur_description/urdf/ur5_robot.urdf") in the installed
    example-robot-data; `package://example-robot-data/...` URIs resolve against the package dir."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise UrdfError(
            "package example-robot-data is not installed; it comes with the robot install: pip install 'mrguide[robot]'"
        ) from exc
    robots = Path(str(dist.locate_file(EXAMPLE_ROBOT_DATA_ROBOTS)))
    urdf = robots / relative
    if not urdf.is_file():
        raise UrdfError(f"{relative!r} is not a URDF of example-robot-data {dist.version} (looked at {urdf})")
    return urdf, robots.parents[1]  # .../share, against which package://example-robot-data/... resolves


def kinematic_chain(urdf: Path, base: str, flange: str) -> tuple[ChainJoint, ...]:
    """The joints from link `base` to link `flange`, base first; UrdfError naming what is missing."""
    return _chain(urdf, urdf.stat().st_mtime_ns, base, flange)


@functools.lru_cache(maxsize=32)
def _chain(urdf: Path, _mtime: int, base: str, flange: str) -> tuple[ChainJoint, ...]:
    try:
        root = ET.parse(urdf).getroot()
    except (OSError, ET.ParseError) as exc:
        raise UrdfError(f"{urdf}: not a readable URDF ({exc})") from exc
    links = {link.get("name") for link in root.iter("link")}
    for key, frame in (("base_frame", base), ("flange_frame", flange)):
        if frame not in links:
            raise UrdfError(f"{key} {frame!r} is not a link of {urdf}")
    parent_joint: dict[str | None, ET.Element] = {}  # the joint above each link (by its child element)
    for j in root.iter("joint"):
        child = j.find("child")
        if child is not None:
            parent_joint[child.get("link")] = j
    chain: list[ChainJoint] = []
    link: str | None = flange
    while link != base:
        joint = parent_joint.get(link)
        if joint is None or len(chain) > len(parent_joint):
            raise UrdfError(f"flange_frame {flange!r} is not below base_frame {base!r} in {urdf}")
        try:
            chain.append(_chain_joint(joint))
        except ValueError as exc:
            raise UrdfError(f"{urdf}: joint {joint.get('name')!r} has a malformed origin or axis ({exc})") from exc
        parent = joint.find("parent")
        link = parent.get("link") if parent is not None else None
    return tuple(reversed(chain))


def _chain_joint(joint: ET.Element) -> ChainJoint:
    origin, axis = joint.find("origin"), joint.find("axis")
    xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
    rpy = _floats(origin.get("rpy") if origin is not None else None, 3)
    return ChainJoint(
        joint.get("name", ""),
        joint.get("type", ""),
        xyz + rpy,
        _floats(axis.get("xyz") if axis is not None else "1 0 0", 3),
    )


def _floats(text: str | None, n: int) -> tuple[float, ...]:
    values = tuple(float(v) for v in (text or "").split()) or (0.0,) * n
    return tuple(round(v, 9) for v in values)
