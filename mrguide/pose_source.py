"""The interface through which the task monitor learns where the object is, on the robot and in the twin."""

from __future__ import annotations

from typing import Protocol

import numpy as np


class PoseUnavailable(RuntimeError):
    """The source cannot give a pose right now (marker not visible, tracking lost, ...)."""


class ObjectPoseSource(Protocol):
    """Gives the object's position in the robot base frame (m)."""

    def object_position(self) -> np.ndarray:
        """Current object position, shape (3,); raises PoseUnavailable when there is none."""
        ...


class PoseDetails(Protocol):
    """Optional beside `ObjectPoseSource`: what the run log keeps with each decision about the pose it gave.

    `pose_details()` is called right after `object_position()` returned; e.g. `{"age_s": 0.08}` (how old the
    estimate is) and, in a simulated cell, `{"true": [x, y, z]}` (where the object really is). `mrguide replay`
    draws them."""

    def pose_details(self) -> dict: ...


class PoseAccuracy(Protocol):
    """Optional beside `ObjectPoseSource`: how far one of its positions may be off, per axis (m, about three
    standard deviations), from what the source knows of itself (e.g. its calibration's residual). A check of a
    position against a fixed height never asks for less than that (`deploy.cycles`: whether the part rests on the
    table)."""

    def accuracy_m(self) -> float: ...
