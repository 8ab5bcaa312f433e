"""What a simulated person knows of a part that the learner must not: where it may be gripped.

A person who handles a plate with a hole in its middle, or a part with a label the cup must not touch, knows where to
grip it; the learner, the expert path and the task model do not (`mrguide.parts`: they never read `judge_only`). The
simulated person (`SimulatedAnnotator`, and `mrguide annotate bot` through it) asks here, once, and teaches the
answer ("not there — here"), and the bot asks whether the grip the cell shows (the status's `grasp`) is one the
person lets stand; nothing else imports this module (tests/test_parts.py).
"""

from __future__ import annotations

import numpy as np

from mrguide.part_judge import grasp_acceptable, intended_grasp
from mrguide.parts import part_named

#: m: a person lets a grip stand where the cup, moved this much either way along the part's axes, still grips it
#: acceptably: the wobble of a policy's grasp about the grip it learned (ours: the grid of `intended_grasp`).
SPARE = 0.0025


def person_grasp(part: str) -> tuple[float, float, float] | None:
    """Where a person who knows part `part` grips it (m, in the part's frame, on its top there); None where they grip
    it at the middle of its top, as the centre prior does."""
    grasp = intended_grasp(part_named(part))
    return None if grasp is None else (float(grasp[0]), float(grasp[1]), float(grasp[2]))


def accepts(part: str, grasp: tuple[float, float, float] | list[float]) -> bool:
    """Whether a person who knows part `part` lets the cell grip it at `grasp` (m, part frame): acceptable there and
    `SPARE` either way along x and y; a grip on or beside a keep-out window or off the grip region they correct."""
    p = part_named(part)
    xy = np.asarray(grasp, dtype=float)[:2]
    shifts = ((0.0, 0.0), (SPARE, 0.0), (-SPARE, 0.0), (0.0, SPARE), (0.0, -SPARE))
    return all(grasp_acceptable(p, xy + np.asarray(d)) for d in shifts)
