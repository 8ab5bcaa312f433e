"""Where the object is for each decision of an episode: the pose source, the last pose, or under the cup."""

from __future__ import annotations

import numpy as np

from mrguide.deploy.safety import Event, Supervisor
from mrguide.drivers.cobot_state import VacuumState
from mrguide.part_perception import StillPartFilter
from mrguide.pose_source import ObjectPoseSource, PoseUnavailable
from mrguide.task import Phase, TaskConfig


class ObjectStartUnknown(RuntimeError):
    """The pose source has no pose at the start of an episode."""


class ObjectTracker:
    """The object's position per decision, and where it came from (`source`: for the run log).

    The source's poses are averaged while the part stands still (`StillPartFilter`, as the twin the policy trained
    in averages its looks): each decision's pose is the mean of the poses since the part last moved, less the
    registration bias the cell estimated (`correction`), at the height of a part on the table.

    While the vacuum says the part is held (from the grasp on) it is under the cup, where the TCP is; just
    released, where the cup let it go. A source that lost sight of the part as the cup came down (its marker under
    the cup) would otherwise keep the task model in the grasp, far from where the part was sealed and dragged. Otherwise the pose source says; when it has no pose, the last one is used for at most `max_misses`
    decisions in a row (`max_misses_before_grasp` before the grasp, when the arm hides the part as it reaches for
    it), each reported to the supervisor; then None (the episode ends)."""

    def __init__(
        self,
        pose: ObjectPoseSource,
        supervisor: Supervisor,
        task: TaskConfig,
        track_carried: bool,
        max_misses: int,
        max_misses_before_grasp: int,
    ):
        self.pose, self.supervisor = pose, supervisor
        self.hang = task.grasp_offset  # from the part's centre to the TCP gripping it (the taught grasp, or the top)
        self.rest_z = 0.5 * task.object_height  # the centre of a part standing on the table
        self.filter = StillPartFilter()
        #: m, subtracted from the source's poses: the registration bias the cell estimated (`bias_estimate`)
        self.correction = np.zeros(3)
        self.track_carried, self.max_misses, self.max_misses_before_grasp = (
            track_carried,
            max_misses,
            max_misses_before_grasp,
        )
        self.reset()

    def reset(self) -> None:
        """A new episode: nothing seen yet."""
        self._last: np.ndarray | None = None  # last pose the source gave in this episode
        self._misses = 0  # decisions in a row without a pose from the source
        self._carried: np.ndarray | None = None  # where the part hung under the cup, last seen
        #: where the episode's first pose put the part on the table (corrected): where a part carried back goes
        self.start: np.ndarray | None = None
        self.filter.reset()
        self.source = "source"  # where the last position came from

    def position(self, tcp: np.ndarray, vac: VacuumState, phase: int) -> np.ndarray | None:
        """The object's position for this decision; None once the pose has been missing for too long.
        ObjectStartUnknown if the source has none before the first pose of the episode."""
        if self.track_carried and phase >= Phase.GRASP:
            if vac.part_gripped:  # sealed: the part is on the cup, wherever the pose source last saw it
                self._carried = tcp - self.hang
                self.source = "carried"
                return self._carried
            if self._carried is not None and phase == Phase.RELEASE:
                self.source = "released"
                return self._carried
        self.source = "source"
        try:
            obj = self.pose.object_position()
        except PoseUnavailable as exc:
            return self._missing(exc, phase)
        self._last, self._misses = self.filter.update(obj), 0
        out = self._on_table(self._last)
        if self.start is None:
            self.start = out.copy()
        return out

    def first_look(self) -> np.ndarray:
        """Where an episode's first decision will see the part (a look of the source, corrected, on the table),
        without counting the look; PoseUnavailable if the source has none."""
        return self._on_table(np.asarray(self.pose.object_position(), dtype=float))

    def _on_table(self, seen: np.ndarray) -> np.ndarray:
        """The part before the grasp: where the source saw it less the registration's correction, at the height of a
        part standing on the table (z = 0 is its top), whatever height the source gave: the policy trained on parts on
        the table, and an HMD's depth is its least certain axis."""
        out = seen - self.correction
        out[2] = self.rest_z
        return out

    @property
    def seen(self) -> np.ndarray | None:
        """The source's mean pose of the part this episode, uncorrected (None before the first)."""
        return self._last

    def _missing(self, exc: PoseUnavailable, phase: int) -> np.ndarray | None:
        if self._last is None:
            raise ObjectStartUnknown(f"no object pose at the start of the episode: {exc}") from exc
        self._misses += 1
        allowed = self.max_misses_before_grasp if phase <= Phase.GRASP else self.max_misses
        if self._misses > allowed:
            self.supervisor.report(
                Event.POSE_LOST,
                f"no object pose for {self._misses} decisions in a row (at most {allowed} may use the last one): {exc}",
            )
            return None
        self.supervisor.report(
            Event.POSE_UNAVAILABLE, f"{exc}; using the last pose ({self._misses} of at most {allowed})"
        )
        self.source = "last"
        return self._on_table(self._last)
