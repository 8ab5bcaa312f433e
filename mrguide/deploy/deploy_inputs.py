"""What a deploy run was given, checked: one record handed from the command to the episode or cycle runner."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.deploy.session import DeployConfig
    from mrguide.drivers.config import CobotBusConfig


@dataclass
class DeployInputs:
    """Everything a deploy run was given, checked: the policy and the cell's description, and the open run log."""

    policy_path: str
    policy: ExportedPolicy
    bus: CobotBusConfig
    spec: Any  # RobotSpec
    task: Any  # TaskConfig
    safety: Any  # SafetyConfig | None
    dcfg: DeployConfig
    camera: Any  # the camera pose source, or None
    run_log: Any  # RunLog
    learning: Any = None  # on-cell learning's actor side (cell_learning.LearningActor), or None
