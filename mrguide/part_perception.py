"""The part's position as a cell program uses it, the same while the policy trains in the twin and on the robot.

A pose source (an HMD, a camera) gives one look per decision, each off by its own error and all off by the
registration's bias. While the part stands still — from the episode's start until the cup seals on it — the
looks are averaged (`StillPartFilter`): a look farther than `JUMP` from the mean says the part moved (pushed,
knocked), and the average starts afresh from it. So the per-look error shrinks as √n over the approach and only
the bias remains, which the cell estimates from its seals (`deploy.bias_estimate`).

In the twin, `PartPerception` draws the looks through `PerceptionConfig`'s errors and applies the runtime's rules:
the filter, the part's height that of a part on the table, the marker hidden under the arm (`occluded`: the last
estimate stands), and the part held on the cup where the TCP and the grasp say (the runtime's `ObjectTracker`). The
policy observes what it gives; the reward and the phases read the twin's truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from mrguide.config import Range, check_ranges

#: m: a look this far from the running mean says the part moved: the mean starts afresh (ours: over 4 σ of a
#: 5 mm per-axis look error in 3-D, under the 3 cm of a part knocked aside).
JUMP = 0.025
#: m: the arm hides the part's marker while the TCP is within this of the part laterally and `OCCLUSION_HEIGHT`
#: above its top (ours: the 2 cm cup's lip over the 5 cm part, with the wrist around it).
OCCLUSION_RADIUS = 0.045
OCCLUSION_HEIGHT = 0.10


class StillPartFilter:
    """The mean of the looks since the part last moved. A look equal to the one before is the same frame given again
    (a source slower than the decisions: the cells' HMD renders 3-4 frames a second): it is not counted twice."""

    def __init__(self) -> None:
        self._sum = np.zeros(3)
        self._n = 0
        self._previous: np.ndarray | None = None

    def reset(self) -> None:
        """A new part: nothing seen of it yet."""
        self._sum, self._n, self._previous = np.zeros(3), 0, None

    @property
    def looks(self) -> int:
        """Looks in the current mean."""
        return self._n

    def update(self, look: np.ndarray) -> np.ndarray:
        """Add one look (m); the mean of the looks since the part last moved."""
        look = np.asarray(look, dtype=float)
        if self._previous is not None and np.array_equal(look, self._previous):
            return self._sum / self._n
        self._previous = look.copy()
        if self._n and np.linalg.norm(look - self._sum / self._n) > JUMP:
            self.reset()
            self._previous = look.copy()
        self._sum = self._sum + look
        self._n += 1
        return self._sum / self._n


def occluded(tcp: np.ndarray, part: np.ndarray, half_height: float) -> bool:
    """Whether the arm at `tcp` hides the marker on top of the part at `part` (centre, m)."""
    lateral = float(np.hypot(tcp[0] - part[0], tcp[1] - part[1]))
    return lateral < OCCLUSION_RADIUS and tcp[2] - (part[2] + half_height) < OCCLUSION_HEIGHT


@dataclass(frozen=True)
class PerceptionConfig:
    """[twin.perception]: the pose source's errors the policy trains through; both zero (the default): the twin's
    exact part. `configs/runs/perception.toml` sets the real cells' HMD at the part as the runtime uses it: 5 mm per
    axis per look (head tracking of 3 mm and 0.3° per frame, 0.3° at 0.8 m being 4 mm), and 1.5 mm per axis of
    registration bias, what remains of the HMD's 3.5 mm once the cell estimated it from its seals
    (`deploy.bias_estimate`). Trained so, the main job's 5k-step policy placed 60 % in the twin where the default
    places 100 % (docs/twin.md)."""

    #: m, std per axis of the registration's bias, drawn per episode (a calibration draw, less the cell's estimate)
    bias: Annotated[float, Range(0.0, 0.05, " m")] = 0.0
    #: m, std per axis of each look's own error
    noise: Annotated[float, Range(0.0, 0.05, " m")] = 0.0

    def __post_init__(self) -> None:
        check_ranges(self, "twin.perception")

    @property
    def exact(self) -> bool:
        return self.bias == 0.0 and self.noise == 0.0


class PartPerception:
    """The part's position the policy observes in the twin, one look per decision (module docstring)."""

    def __init__(self, cfg: PerceptionConfig, half_height: float, hang: np.ndarray) -> None:
        """`half_height`: the part's (m; its top above its centre); `hang`: where the cup grips it (m, part frame;
        the task's `grasp_offset`: the part hangs this far below the TCP while held)."""
        self.cfg, self.half, self.hang = cfg, half_height, np.asarray(hang, dtype=float)
        self.rng = np.random.default_rng(0)
        self.bias = np.zeros(3)
        self.filter = StillPartFilter()
        self._seen: np.ndarray | None = None  # the last estimate from the looks
        self._carried: np.ndarray | None = None  # where the part hung under the cup, last held

    def reset(self, seed: int) -> None:
        """A new episode: a calibration draw of its own, nothing seen yet."""
        self.rng = np.random.default_rng(seed)
        self.bias = self.rng.normal(0.0, self.cfg.bias, 3) if self.cfg.bias > 0 else np.zeros(3)
        self.filter.reset()
        self._seen = self._carried = None

    def see(self, part: np.ndarray, tcp: np.ndarray, held: bool) -> np.ndarray:
        """Where the policy sees the part at `part` (its true centre, m) with the TCP at `tcp` and the vacuum's
        part signal `held`."""
        if self.cfg.exact:
            return np.asarray(part, dtype=float)
        if held:
            self._carried = np.asarray(tcp, dtype=float) - self.hang
            return self._carried
        if self._carried is not None:  # let go: where the cup released it
            return self._carried
        if self._seen is not None and occluded(tcp, self._seen, self.half):
            return self._seen
        look = np.asarray(part, dtype=float) + self.bias + self.rng.normal(0.0, self.cfg.noise, 3)
        self._seen = self.filter.update(look)
        self._seen[2] = part[2]  # on the table, as the runtime takes it (`ObjectTracker`)
        return self._seen
