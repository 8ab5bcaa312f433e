"""Pick and place marks fused over a run: every mark is a measurement of one offset in its anchor's frame.

A person's pick mark says where the cup should touch the part, relative to the part; the place mark where
the part should be set down, relative to the goal. Both offsets are the same in every episode, so each mark
measures one of two constant vectors. The fused mark of a demonstration is its anchor plus the
coordinate-wise median of all marks' offsets so far: the per-mark scatter averages out over the run, a slip
is outvoted, and what remains is what all marks share — what the person means, and the session's
registration bias, which no number of marks can reveal (the reward can: see the learner). A median needs no
bound to outvote a slip; Eq. 13 bounds the fused mark around the reference (GuidedExpert), not each mark
around the earlier ones, which would let an early wild mark hold every later one back.

Two things end the need for more marks of a kind. A grasp that sealed (`add_seal`) measures the pick offset
without the person's bias, a part set down where the episode succeeded (`add_placement`) the place offset: from
then on the pick or the place is the median of those measurements. And once the median of the marks
is known to within `precision` per axis (its standard error, from the marks' own spread), another mark of that
kind tells the learner nothing new: `settled` says so, and the person is not asked. A measurement can be wrong — a
part the cup dragged along before it sealed is measured against where it lay before — and a demonstration whose
search finds nothing around it says so: `withdraw` drops it, and the marks decide again.

A mark is read under the centre prior: the person meant the middle of the part, and the cell's measurements find it
(a seal is measured over the part's centre). A person who answers with `here` (`teach`) teaches where the part is
gripped or set down: the taught points' median is the person's intent, and the cell's measurements refine it only
within `REFINE_RADIUS` of it; they never move it where the person did not point. A person who steps in and says
"not there — here" corrects it: the correction replaces what was taught and outranks every measurement made before.
"""

from __future__ import annotations

import numpy as np

from mrguide.task import OBS_GOAL, OBS_OBJECT, PICK_PHASE, PLACE_PHASE

KINDS = (PICK_PHASE, PLACE_PHASE)
#: Marks of a kind before its median may count as settled, however tight they are.
MIN_MARKS = 3
#: m: how far the cell may move a taught point to where a seal has room (`GuidedExpert`, `grasp_margin`): the
#: diagonal of one pitch of the grasp's search grid (`waypoint_search`), as far as its nearest probes reach.
INTENT_RADIUS = 0.0085
#: m: a measurement refines the intent only this close to it, laterally: a probe of the search about a point the cell
#: moved, a pitch and a half from it, with the intent moved by another taught point since (ours: twice the above).
REFINE_RADIUS = 2 * INTENT_RADIUS
#: Standard error of a median per standard deviation per √n (normal errors: √(π/2)), and the normal-consistent
#: MAD scale: SE ≈ 1.2533 · 1.4826 · MAD / √n.
_MEDIAN_SE, _MAD_SIGMA = 1.2533, 1.4826


def anchor(kind: int, obs: np.ndarray) -> np.ndarray:
    """The position a mark of `kind` is measured from: the part's centre (pick) or the goal (place)."""
    obs = np.asarray(obs, dtype=float)
    return obs[OBS_OBJECT].copy() if kind == PICK_PHASE else obs[OBS_GOAL].copy()


class MarkFusion:
    """The offsets of every pick and place mark from its anchor, and their fused value."""

    def __init__(self) -> None:
        self.offsets: dict[int, list[np.ndarray]] = {k: [] for k in KINDS}
        #: Offsets of what the cell measured: the grasp targets that sealed (from the part), the set-down points of
        #: successful placements (from the goal).
        self.measured: dict[int, list[np.ndarray]] = {k: [] for k in KINDS}
        #: Offsets a person taught ("not there — here"), in the order given.
        self.taught: dict[int, list[np.ndarray]] = {k: [] for k in KINDS}

    def intent(self, kind: int) -> np.ndarray | None:
        """The taught offset of `kind` (the median of what the person taught), or None: the centre prior."""
        return np.median(np.array(self.taught[kind]), axis=0) if self.taught[kind] else None

    def estimate(self, kind: int) -> np.ndarray | None:
        """The fused offset of `kind`, or None before its first mark. Taught: the median of the measurements within
        REFINE_RADIUS of the intent, else the intent. Otherwise: the median of the measurements once there are any,
        else of the marks."""
        intent = self.intent(kind)
        if intent is not None:
            near = [m for m in self.measured[kind] if np.linalg.norm(m[:2] - intent[:2]) <= REFINE_RADIUS]
            return np.median(np.array(near), axis=0) if near else intent
        offs = self.measured[kind] or self.offsets[kind]
        return np.median(np.array(offs), axis=0) if offs else None

    def teach(self, kind: int, at: np.ndarray, target: np.ndarray, correction: bool = False) -> None:
        """A person taught `kind` at `target` with its anchor at `at`: one more sample of their intent, or, a
        `correction` ("not there — here"), the intent itself, every measurement made so far dropped."""
        offset = np.asarray(target, dtype=float) - np.asarray(at, dtype=float)
        if correction:
            self.taught[kind], self.measured[kind] = [], []
        self.taught[kind].append(offset)

    def settled(self, kind: int, precision: float) -> bool:
        """Whether another mark of `kind` would tell nothing new: once a person taught it or the cell measured it; or once
        MIN_MARKS marks put the median's standard error within `precision` (m) on every axis."""
        if self.measured[kind] or self.taught[kind]:
            return True
        offs = np.array(self.offsets[kind])
        if len(offs) < MIN_MARKS:
            return False
        mad = np.median(np.abs(offs - np.median(offs, axis=0)), axis=0)
        return bool(np.all(_MEDIAN_SE * _MAD_SIGMA * mad / np.sqrt(len(offs)) <= precision))

    def add_measurement(self, kind: int, at: np.ndarray, point: np.ndarray) -> None:
        """Record where the cell found the pick (a grasp target that sealed, the part's centre at `at`) or the place
        (a set-down point of a success, the goal at `at`)."""
        self.measured[kind].append(np.asarray(point, dtype=float) - np.asarray(at, dtype=float))

    def withdraw(self, kind: int) -> int:
        """Drop the measurements of `kind` (a demonstration planned from them found nothing around them): the marks
        stand for it again. Returns how many were dropped."""
        dropped = len(self.measured[kind])
        self.measured[kind] = []
        return dropped

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
