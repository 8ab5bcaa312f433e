"""Pick and place marks fused over a run: every mark is a measurement of one offset in its anchor's frame.

A person's pick mark says where the cup should touch the part, relative to the part; the place mark where
the part should be set down, relative to the goal. Both offsets are the same in every episode, so each mark
measures one of two constant vectors. The fused mark of a demonstration is its anchor plus the
coordinate-wise median of all marks' offsets so far: the per-mark scatter averages out over the run, a slip
is outvoted, and what remains is what all marks share — what the person means, and the session's
registration bias, which no number of marks can reveal (the reward can: see the learner). A median needs no
bound to outvote a slip; Eq. 13 bounds the fused mark around the reference (GuidedExpert), not each mark
around the earlier ones, which would let an early wild mark hold every later one back.
"""

from __future__ import annotations

import numpy as np

from mrguide.task import OBS_GOAL, OBS_OBJECT, PICK_PHASE, PLACE_PHASE

KINDS = (PICK_PHASE, PLACE_PHASE)


def anchor(kind: int, obs: np.ndarray) -> np.ndarray:
    """The position a mark of `kind` is measured from: the part's centre (pick) or the goal (place)."""
    obs = np.asarray(obs, dtype=float)
    return obs[OBS_OBJECT].copy() if kind == PICK_PHASE else obs[OBS_GOAL].copy()


class MarkFusion:
    """The offsets of every pick and place mark from its anchor, and their fused value."""

    def __init__(self) -> None:
        self.offsets: dict[int, list[np.ndarray]] = {k: [] for k in KINDS}

    def estimate(self, kind: int) -> np.ndarray | None:
        """The fused offset of `kind` (coordinate-wise median), or None before its first mark."""
        offs = self.offsets[kind]
        return np.median(np.array(offs), axis=0) if offs else None

    def point(self, kind: int, at: np.ndarray) -> np.ndarray:
        """The fused mark (m) for an anchor at `at`; needs at least one mark of `kind`."""
        est = self.estimate(kind)
        if est is None:
            raise ValueError(f"no mark of phase {kind} to fuse yet")
        return np.asarray(at, dtype=float) + est

    def add(self, kind: int, at: np.ndarray, target: np.ndarray) -> None:
        """Record a mark made with its anchor at `at`."""
        self.offsets[kind].append(np.asarray(target, dtype=float) - np.asarray(at, dtype=float))

    def counts(self) -> dict[int, int]:
        return {k: len(v) for k, v in self.offsets.items()}
