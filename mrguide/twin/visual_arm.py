"""The arm as the render processes draw it (HMD, twin camera): so it hides the object's marker as on a cell.

A render process has a PyBullet world of its own (table, marked cube); it loads the arm with its cup from
the twin's URDF, visual only, and sets its joints to the twin's true ones before every frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as pb

from mrguide.robot import RobotSpec
from mrguide.twin.scene import urdf_with_cup


@dataclass(frozen=True)
class ArmDrawing:
    """What a render process needs to draw the arm (picklable): the URDF with the cup, the joint names."""

    urdf: str
    joints: tuple[str, ...]

    @classmethod
    def of(cls, spec: RobotSpec) -> ArmDrawing:
        return cls(str(urdf_with_cup(spec)), tuple(spec.joint_names))


class VisualArm:
    """The arm in a render process's world; `set(q)` poses it."""

    def __init__(self, client: int, drawing: ArmDrawing):
        self.client = client
        self.body = pb.loadURDF(drawing.urdf, useFixedBase=True, physicsClientId=client)
        by_name = {
            pb.getJointInfo(self.body, j, physicsClientId=client)[1].decode(): j
            for j in range(pb.getNumJoints(self.body, physicsClientId=client))
        }
        self.joint_ids = [by_name[name] for name in drawing.joints]

    def set(self, q: np.ndarray) -> None:
        for j, qj in zip(self.joint_ids, q):
            pb.resetJointState(self.body, j, float(qj), physicsClientId=self.client)
