"""Which policy version a learning cell acts with: a newer version replaces the one in use only after it has placed
`trial` parts in a row on the cell.

A learner that goes on updating after its policy already does the task moves the policy with no signal to move it
by; measured, one of three fresh policies placed 99 of 100 parts frozen and 97 of the last 100 while it learned
(docs/results: learning on the cell). A production cell does not hand its parts to an untried program, so the
runtime keeps the version it trusts (*kept*) and tries the newest version the learner offered on the next episodes:

- a tried version that ends `trial` episodes in a row in success (the task model on the cell's sensed state) is
  kept from then on;
- one that fails an episode (no grasp, dropped, misplaced, knocked off, timeout) is dropped at once, and the kept
  version acts again; the next try waits `trial` episodes, twice as long after each version dropped in a row (so
  a learner that has gone astray costs the cell at most one part per try, and ever fewer tries), and starts again
  at `trial` after a version is kept;
- an episode the supervisor ended (pose lost, aborted, a safety stop) or a person's expert played judges nothing.

`trial = 0` takes each newer version at once. The state is a few integers (`state`/`restore`): `--resume` goes on
with the version kept and the waiting as they were.
"""

from __future__ import annotations

from dataclasses import dataclass

from mrguide.task import Outcome

#: The task's own ends of an episode: what a tried version is judged by.
FAILED = frozenset({Outcome.NO_GRASP, Outcome.DROPPED, Outcome.MISPLACED, Outcome.KNOCKED_OFF, Outcome.TIMEOUT})


@dataclass
class VersionGate:
    """The try-then-keep rule's state: whether a version is on trial, its successes, the wait before the next try."""

    trial: int
    trying: bool = False
    successes: int = 0
    wait: int = 0  # episodes the kept version still acts before the next try
    backoff: int = 0  # the wait after the next version dropped
    kept_count: int = 0
    dropped_count: int = 0

    def __post_init__(self) -> None:
        self.backoff = self.backoff or self.trial

    def may_try(self) -> bool:
        """At an episode's start with the kept version acting: whether a newer version may be tried now (counts one
        episode of the wait when not)."""
        if self.trial == 0:
            return True
        if self.wait > 0:
            self.wait -= 1
            return False
        return True

    def start(self) -> None:
        """A newer version acts from this episode on, on trial (nothing to try with `trial = 0`: it is kept)."""
        if self.trial > 0:
            self.trying, self.successes = True, 0
        else:
            self.kept_count += 1

    def judge(self, outcome: Outcome) -> str | None:
        """An episode of the version on trial ended: "kept", "dropped" or None (the trial goes on, or none runs)."""
        if not self.trying:
            return None
        if outcome is Outcome.SUCCESS:
            self.successes += 1
            if self.successes < self.trial:
                return None
            self.trying, self.backoff, self.kept_count = False, self.trial, self.kept_count + 1
            return "kept"
        if outcome in FAILED:
            self.trying, self.wait = False, self.backoff
            self.backoff, self.dropped_count = 2 * self.backoff, self.dropped_count + 1
            return "dropped"
        return None

    def state(self) -> dict[str, int]:
        """What `--resume` needs (a version on trial is not resumed: the kept version acts first)."""
        return {"wait": self.wait, "backoff": self.backoff, "kept": self.kept_count, "dropped": self.dropped_count}

    def restore(self, state: dict[str, int]) -> None:
        self.wait, self.backoff = int(state["wait"]), int(state["backoff"])
        self.kept_count, self.dropped_count = int(state["kept"]), int(state["dropped"])
