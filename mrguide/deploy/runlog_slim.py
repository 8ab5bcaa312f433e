"""Slim copies of run logs for the results: every record but the decisions of successful episodes, those of the
first successful episode of each run kept (a clean one to replay beside the failures). A run log's decisions are
most of its bytes, and every figure of the results is computed from the per-episode outcomes, not from them.

    python -m mrguide.deploy.runlog_slim [--no-decisions] LOG...

With `--no-decisions`, no decision record is kept at all: the episodes', cycles' and safety records only (a long
production or learning run whose figures come from its cycles, whose decisions would outweigh the checkout). Each LOG (.jsonl or .jsonl.gz) is replaced by its slim copy LOG.jsonl.gz (a .jsonl input is removed once the copy is
written). Slimming a slim copy changes nothing. Production logs are slimmed by `mrguide cycles report --out`, without
a clean episode (a cycle's attempts are what its replay shows).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mrguide.deploy.runlog import RunLogError, read_log, slim_records, write_gzipped

#: Successful episodes per run whose decisions a slim copy keeps.
CLEAN_EPISODES = 1


def slim_log(path: Path, decisions: bool = True) -> tuple[int, int]:
    """Replace run log `path` by its slim gzipped copy (without `decisions`, none of its decision records); (bytes
    before, bytes after)."""
    before = path.stat().st_size
    records = read_log(path)
    if not records or records[0].get("kind") != "run":
        raise RunLogError(f"{path}: not a run log (no 'run' record first)")
    target = path if path.suffix == ".gz" else path.with_name(path.name + ".gz")
    kept = slim_records(records, keep_successes=CLEAN_EPISODES)
    write_gzipped(target, kept if decisions else [r for r in kept if r.get("kind") != "decision"])
    if target != path:
        path.unlink()
    return before, target.stat().st_size


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", type=Path, help="run logs of deploy or sim2real (.jsonl or .jsonl.gz)")
    ap.add_argument("--no-decisions", action="store_true", help="keep no decision record at all")
    args = ap.parse_args(argv)
    total = [0, 0]
    for path in args.logs:
        try:
            before, after = slim_log(path, decisions=not args.no_decisions)
        except RunLogError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        total[0] += before
        total[1] += after
    print(f"{len(args.logs)} logs: {total[0] / 1e6:.2f} MB -> {total[1] / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
