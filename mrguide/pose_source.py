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
