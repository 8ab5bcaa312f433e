"""[deploy.runtime]: how the runtime treats the arm, the object pose and the cup (its lift rules and seal search)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from mrguide.config import Range, check_ranges


@dataclass(frozen=True)
class RuntimeConfig:
    """How the runtime treats the arm and the object pose ([deploy.runtime] in a TOML config). The decision
    period is not set here: it is the one the policy was trained with (its metadata)."""

    home_tolerance: Annotated[float, Range(1e-4, 0.5, " rad")] = 0.01  # the arm counts as home within this
    #: While the vacuum generator reports a part (from the grasp on), the object is under the cup: take its
    #: position from the TCP (forward kinematics) instead of the pose source, which may lag (an HMD does) or
    #: not see it (its marker under the cup).
    track_carried_object: bool = True
    #: Decisions in a row that may use the last object pose when the pose source has none (a marker out of
    #: view, a dead HMD process); one more ends the episode as `pose_lost` with the arm held. In [0, 1000].
    max_pose_misses: Annotated[int, Range(0, 1000)] = 3
    #: The same before the grasp (approach and grasp phases), when the arm over the part hides its marker from
    #: the camera or HMD while the part lies still where it was last seen. In [0, 1000].
    max_pose_misses_before_grasp: Annotated[int, Range(0, 1000)] = 30
    #: The lift's first part at a bounded speed, so that a cup's level-compensator reaches its end stop gently
    #: (lift_rule.py): how far (m, in [0, 0.1]; 0 = off) and how fast (m/s, in [0.005, 1]).
    break_away_distance: Annotated[float, Range(0.0, 0.1, " m")] = 0.015
    break_away_speed: Annotated[float, Range(0.005, 1.0, " m/s")] = 0.1
    #: The seal search (seal_search.py): a cup pressed without "vacuum OK" for `reseat_wait` decisions is re-seated
    #: where a press most likely seals, as the registration's posterior says (bias_estimate.py); false turns it off.
    seal_search: bool = True
    reseat_wait: Annotated[int, Range(1, 50)] = 1
    #: Where the cell keeps its estimate of the pose source's registration bias (bias_estimate.py) across runs: a
    #: JSON file read at the start and written after every press; "" keeps it for the run only.
    bias_estimate_file: str = ""

    def __post_init__(self) -> None:
        check_ranges(self, "deploy.runtime")
