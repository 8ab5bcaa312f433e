"""How often one safety event ended or marked episodes, by outcome, from run logs (full or slim: the episode-end
records, which every copy keeps, count each episode's events):

    python -m mrguide.replay.event_counts LOG... [--event reseat]

One line per log (named as given): its episodes, those with the event and their outcomes, and the event's count.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from mrguide.deploy.runlog import RunLogError, read_log


def count(path: Path, event: str) -> str:
    """The log's line: episodes, those with `event` by outcome, the event's total."""
    ends = [r for r in read_log(path) if r.get("kind") == "episode_end"]
    marked = [r for r in ends if r.get("events", {}).get(event)]
    outcomes = Counter(r["outcome"] for r in marked)
    total = sum(r["events"][event] for r in marked)
    by_outcome = ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())) or "none"
    return f"{path}: {len(ends)} episodes; {len(marked)} with {event} ({by_outcome}); {event} {total} times"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrguide.replay.event_counts", description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", type=Path, help="run logs of deploy or sim2real (.jsonl or .jsonl.gz)")
    ap.add_argument("--event", default="reseat", help="a safety event's name (default: reseat)")
    args = ap.parse_args(argv)
    try:
        for path in args.logs:
            print(count(path, args.event))
    except (OSError, RunLogError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
