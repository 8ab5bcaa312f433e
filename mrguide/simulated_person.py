"""What a simulated person knows of a part that the learner must not: where it may be gripped.

A person who handles a plate with a hole in its middle, or a part with a label the cup must not touch, knows where to
grip it; the learner, the expert path and the task model do not (`mrguide.parts`: they never read `judge_only`). The
simulated person (`SimulatedAnnotator`, and `mrguide annotate bot` through it) asks here, once, and teaches the
answer ("not there — here"); nothing else imports this module (tests/test_parts.py).
"""

from __future__ import annotations

from mrguide.part_judge import intended_grasp
from mrguide.parts import part_named


def person_grasp(part: str) -> tuple[float, float, float] | None:
    """Where a person who knows part `part` grips it (m, in the part's frame, on its top there); None where they grip
    it at the middle of its top, as the centre prior does."""
    grasp = intended_grasp(part_named(part))
    return None if grasp is None else (float(grasp[0]), float(grasp[1]), float(grasp[2]))
