"""What a guided run tells the people at the annotation page after every episode (protocol `status`): the same from
`mrguide train --expert live` and from an experiment's run over the wire (`BotSession`)."""

from __future__ import annotations

from collections import deque
from typing import Any


class SessionStatus:
    """The status of trainer `tr` (a `Trainer`), with the success rate over its last 20 agent episodes."""

    def __init__(self, tr: Any):
        self.tr = tr
        self.recent: deque[int] = deque(maxlen=20)

    def episode(self, row: dict) -> None:
        """Count a metrics row's outcome (each row `Trainer.run` hands its `on_episode`)."""
        self.recent.append(int(row["success"]))

    def success_rate(self) -> float | None:
        return sum(self.recent) / len(self.recent) if self.recent else None

    def fields(self) -> dict[str, Any]:
        """The status's training fields (docs/annotation-protocol.md)."""
        tr, grasp = self.tr, self.tr.expert.task.grasp
        return {
            "step": tr.counters.step,
            "total_steps": tr.cfg.total_steps,
            "episode": tr.counters.episode,
            "lambda": round(tr.lam(), 4),
            "success_rate": self.success_rate(),
            "asked": tr.counters.asked,
            "reused": tr.counters.reused,
            "remarks": tr.counters.remarks,
            "skipped": tr.counters.skipped,
            "interventions": tr.counters.interventions,
            "person_interventions": tr.counters.person_interventions,
            **tr.counters.session_cost(tr.env.twin_cfg.decision_period),
            # where the cell grips the part as taught (m, part frame, to 0.1 mm); None: the centre prior
            "grasp": None if grasp is None else [round(float(v), 4) for v in grasp],
        }
