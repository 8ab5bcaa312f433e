"""The names a training config chooses between: each a `Literal` type (for the reader and mypy) and the tuple of its
values (for the config dataclasses' own checks, which refuse anything else with a message naming the key).

Nothing heavy is imported here: the CLI builds its `--expert` choices from it, and the experiment configs check
their learners against it, without loading torch.
"""

from __future__ import annotations

from typing import Literal, get_args

#: guidance.source: the scripted oracle, the simulated MR annotator (oracle + noise), a recorded annotation file,
#: or a person through the live annotation page (`mrguide train --expert live`) — and any source a module registered
#: (`policies.guided_expert.register_expert_source`).
ExpertSourceName = Literal["oracle", "annotator", "file", "live"]
EXPERT_SOURCES: list[str] = list(get_args(ExpertSourceName))

#: guidance.reference: a^e of Eq. 13, the task model's target or a running median of the marks (no ground truth).
ReferenceName = Literal["nominal", "running_median"]
REFERENCES: tuple[ReferenceName, ...] = get_args(ReferenceName)

#: guidance.marks: a mark per phase (the paper's protocol) or a pick and a place mark per demonstration (ours).
MarksMode = Literal["phases", "pick_place"]
MARKS_MODES: tuple[MarksMode, ...] = get_args(MarksMode)
