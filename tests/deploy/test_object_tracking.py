"""Where the runtime puts the object per decision (deploy/object_tracking.py): the pose source, its last pose, or
under the cup once the vacuum says the part is held."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.object_tracking import ObjectTracker
from mrguide.drivers.cobot_state import VacuumState
from mrguide.pose_source import PoseUnavailable
from mrguide.task import Phase, TaskConfig

HEIGHT = 0.05


class _Source:
    """A pose source that saw the part once, then lost it (its marker under the cup)."""

    def __init__(self, seen: list[float]):
        self.seen: np.ndarray | None = np.array(seen)

    def object_position(self) -> np.ndarray:
        if self.seen is None:
            raise PoseUnavailable("marker hidden")
        seen, self.seen = self.seen, None
        return seen


class _Supervisor:
    def __init__(self) -> None:
        self.events: list[str] = []

    def report(self, event, message: str) -> None:
        self.events.append(event)


def _vacuum(gripped: bool) -> VacuumState:
    return VacuumState(75.0 if gripped else 8.0, gripped, False, True, False, 0.0)


def _tracker(track: bool = True) -> tuple[ObjectTracker, _Supervisor]:
    sup = _Supervisor()
    return ObjectTracker(_Source([0.50, -0.15, 0.025]), sup, TaskConfig(), track, 3, 30), sup  # type: ignore[arg-type]


def test_a_seal_in_the_grasp_puts_the_part_under_the_cup_not_where_it_was_last_seen():
    """The HMD lost the marker as the cup came down; the cup sealed 15 cm away, having dragged the part there."""
    tracker, sup = _tracker()
    first = tracker.position(np.array([0.50, -0.15, 0.20]), _vacuum(False), Phase.APPROACH)
    assert np.allclose(first, [0.50, -0.15, 0.025]) and tracker.source == "source"
    pressed = tracker.position(np.array([0.51, -0.16, 0.05]), _vacuum(False), Phase.GRASP)
    assert np.allclose(pressed, first) and tracker.source == "last" and len(sup.events) == 1
    sealed = tracker.position(np.array([0.65, -0.20, 0.05]), _vacuum(True), Phase.GRASP)
    assert np.allclose(sealed, [0.65, -0.20, 0.05 - HEIGHT / 2]) and tracker.source == "carried"
    assert len(sup.events) == 1  # nothing missing while the part is on the cup


@pytest.mark.parametrize(
    ("track", "gripped", "phase"),
    [(True, False, Phase.GRASP), (False, True, Phase.GRASP), (True, True, Phase.APPROACH)],
    ids=["no seal", "tracking off", "sealed before the grasp phase"],
)
def test_otherwise_the_last_pose_stands(track, gripped, phase):
    tracker, _ = _tracker(track)
    tracker.position(np.array([0.50, -0.15, 0.20]), _vacuum(False), Phase.APPROACH)
    got = tracker.position(np.array([0.65, -0.20, 0.05]), _vacuum(gripped), phase)
    assert np.allclose(got, [0.50, -0.15, 0.025]) and tracker.source == "last"


class _Looks:
    """A pose source giving the listed poses in turn."""

    def __init__(self, looks: list[list[float]]):
        self.looks = [np.array(p) for p in looks]

    def object_position(self) -> np.ndarray:
        return self.looks.pop(0)


def test_the_poses_of_a_part_standing_still_are_averaged_and_a_moved_part_starts_afresh():
    looks = [[0.50, -0.15, 0.025], [0.504, -0.15, 0.025], [0.502, -0.146, 0.025], [0.55, -0.15, 0.025]]
    tracker = ObjectTracker(_Looks(looks), _Supervisor(), TaskConfig(), True, 3, 30)  # type: ignore[arg-type]
    seen = [tracker.position(np.array([0.5, 0.1, 0.3]), _vacuum(False), Phase.APPROACH) for _ in looks]
    assert np.allclose(seen[2], [0.502, -0.148667, 0.025], atol=1e-6)  # the mean of three looks
    assert np.allclose(seen[3], looks[3])  # 5 cm away: the part was moved, the mean starts from it
    tracker.reset()  # the next part
    tracker.pose = _Looks([[0.45, -0.1, 0.025]])
    assert np.allclose(tracker.position(np.array([0.5, 0.1, 0.3]), _vacuum(False), Phase.APPROACH), [0.45, -0.1, 0.025])


def test_the_cells_registration_correction_is_subtracted_from_the_sources_poses():
    tracker = ObjectTracker(_Looks([[0.50, -0.15, 0.025]]), _Supervisor(), TaskConfig(), True, 3, 30)  # type: ignore[arg-type]
    tracker.correction = np.array([0.004, -0.002, 0.0])
    seen = tracker.position(np.array([0.5, 0.1, 0.3]), _vacuum(False), Phase.APPROACH)
    assert np.allclose(seen, [0.496, -0.148, 0.025]) and np.allclose(tracker.seen, [0.50, -0.15, 0.025])
