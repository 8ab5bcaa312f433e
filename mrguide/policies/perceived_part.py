"""The part as the cell perceives it in the expert path: through the configured pose error, never the twin's exact
pose (`guidance.pose`), and averaged while it stands still as the cell averages its looks."""

from __future__ import annotations

import zlib

import numpy as np

from mrguide.part_perception import StillPartFilter
from mrguide.policies.guidance import PoseError
from mrguide.task import OBS_OBJECT, Phase

POSE_SEED_OFFSET = 15_485_863  # the perceived part's registration bias of training seed s: RNG seed (s, this)


class PerceivedPart:
    """The part's position as the cell perceives it: the observed one plus a registration bias drawn once per run
    and an error per look (guidance.pose: both zero, the pose as observed). A look's error is drawn from the run's
    seed and the observation itself, so the same observation is always seen alike: a resumed run, rebuilding its
    fused marks from the annotation file, sees every mark's part where the interrupted run saw it."""

    def __init__(self, error: PoseError, seed: int):
        self.error, self.seed = error, seed
        rng = np.random.default_rng([seed, POSE_SEED_OFFSET])
        self.bias = rng.normal(0.0, error.bias_sigma, 3) if error.bias_sigma > 0 else np.zeros(3)
        self._still = StillPartFilter()  # a demonstration's looks at its part before the seal

    @property
    def exact(self) -> bool:
        """The part seen where it is (no error set)."""
        return self.error.sigma == 0 and self.error.bias_sigma == 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """`obs` with the part where the cell sees it (a float64 copy)."""
        seen = np.array(obs, dtype=np.float64)
        seen[OBS_OBJECT] += self.bias
        if self.error.sigma > 0:
            look = np.random.default_rng([self.seed, zlib.crc32(np.asarray(obs, dtype=np.float32).tobytes())])
            seen[OBS_OBJECT] += look.normal(0.0, self.error.sigma, 3)
        return seen

    def new_part(self) -> None:
        """A demonstration begins: its part not looked at yet."""
        self._still.reset()

    def at_decision(self, obs: np.ndarray, phase: int) -> np.ndarray:
        """`obs` with the part where the cell sees it at this decision of a demonstration. Until the grasp ends the part
        stands still and the cell's estimate is the mean of the looks at it (`StillPartFilter`: the runtime's
        `ObjectTracker` and the twin's `PartPerception` average theirs alike), so a look's error shrinks as √n over
        the approach; from the lift on, this look."""
        seen = self(obs)
        if self.exact:
            return seen
        if phase <= Phase.GRASP:
            seen[OBS_OBJECT] = self._still.update(seen[OBS_OBJECT])
        else:
            self._still.reset()
        return seen
