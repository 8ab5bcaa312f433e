"""The failed episodes of run logs, one line each: the outcome, the phase it ended in, and the vacuum level and TCP
height over its last decisions — where a part was lost, and whether the seal broke at once or leaked away.

    python -m mrguide.replay.failures LOG...

Prints a line per failed episode and, per log, the outcomes of all its episodes. A slim log (`runlog_slim`) keeps
every failed episode's decisions. Replay them with `mrguide replay LOG --outcome dropped --save drops.rrd`.
"""

from __future__ import annotations

import sys
from collections import Counter

from mrguide.replay.runs import Episode, RunError, load_run
from mrguide.task import Phase

#: Decisions at the end of a failed episode that its line shows.
TAIL = 5


def failure_line(ep: Episode) -> str:
    """`ep`'s outcome, the phase of its last decision, and its last vacuum levels (kPa) and TCP heights (mm)."""
    frames = ep.frames[-TAIL:]
    phase = Phase(frames[-1].phase).name.lower() if frames else "?"
    vacuum = " ".join("?" if f.vacuum_kpa is None else f"{f.vacuum_kpa:.0f}" for f in frames)
    height = " ".join("?" if f.tcp is None else f"{1e3 * f.tcp[2]:.0f}" for f in frames)
    return f"{ep.label}: {ep.outcome} in {phase}; vacuum {vacuum} kPa; TCP z {height} mm"


def main(argv: list[str] | None = None) -> int:
    logs = sys.argv[1:] if argv is None else argv
    if not logs or logs[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if logs else 2
    for path in logs:
        try:
            episodes = load_run(path)
        except RunError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        for ep in episodes:
            if ep.outcome != "success":
                print(failure_line(ep))
        outcomes = Counter(str(ep.outcome) for ep in episodes)
        print(f"{path}: {len(episodes)} episodes, " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
