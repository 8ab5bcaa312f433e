"""What an episode of the runtime reports, and how a run that cannot go on ends."""

from __future__ import annotations

from dataclasses import dataclass, field

from mrguide.task import Outcome


class RunStopped(RuntimeError):
    """The run cannot go on (quick stop after a fault, a stall or an interrupt).

    `report` is the report of the episode it stopped, if it stopped one (outcome `Outcome.SAFETY_STOP`)."""

    report: EpisodeReport | None = None


#: s: an episode or cycle whose simulated cell ran further behind the clock than this (`cell_backlog_s`) is not one a
#: cell on time would have played (on time: about 10 ms at most, the SYNCs' jitter).
MAX_CELL_BACKLOG_S = 0.1

#: How long the arm may take to arrive home after its last setpoint was home (s): servo lag, settling.
HOME_SETTLE_S = 1.0


@dataclass
class EpisodeReport:
    index: int
    outcome: Outcome
    decisions: int
    events: dict[str, int]
    latency_ms: list[float] = field(default_factory=list)
    inference_ms: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    #: s, dry runs only: how far the simulated cell's world ran behind the wall clock at most (`sync_backlog`)
    cell_backlog_s: float = 0.0
