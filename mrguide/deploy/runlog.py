"""The run log: one JSON object per line, flushed as written, so a crash loses at most the line in flight.

The first record ("run") holds the run's metadata; it is on disk before the log is handed out, so a log
that cannot be written is refused before any drive is enabled, and no run leaves an empty log behind.
"""

from __future__ import annotations

import contextlib
import gzip
import json
import os
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.errors import InputError


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class RunLogError(InputError):
    """The run log cannot be created or written where it was asked for."""


class RunLog:
    """Append-only JSONL file; `sync()` forces it to disk (called at episode ends). A context manager."""

    def __init__(self, path: str | Path, header: dict[str, Any], where: str = "run log"):
        """Open the log at `path` (given by `where`, e.g. "--log") and write the header record `header` to disk;
        RunLogError if that fails (a file created for it is removed again)."""
        self.path = Path(path)
        created = not self.path.exists()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = self.path.open("a", buffering=1)
        except OSError as exc:
            raise RunLogError(f"{where} {self.path}: cannot create the run log: {exc.strerror or exc}") from exc
        try:
            self.write("run", **header)
            self.sync()
        except OSError as exc:
            with contextlib.suppress(OSError):  # closing flushes the failed line once more
                self._fh.close()
            if created:
                self.path.unlink(missing_ok=True)
            raise RunLogError(f"{where} {self.path}: cannot write the run log: {exc.strerror or exc}") from exc

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def write(self, kind: str, **fields: Any) -> None:
        self._fh.write(json.dumps({"kind": kind, **_plain(fields)}) + "\n")

    def sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if not self._fh.closed:
            self.sync()
            self._fh.close()


def read_log(path: str | Path) -> list[dict]:
    """All records of a run log (also a gzipped one, `*.gz`, as the results store them). Only a torn last line
    (the one in flight when the writer died: no line break after it) is skipped; any other line that is not a
    JSON object raises RunLogError naming file:line."""
    path = Path(path)
    try:
        text = gzip.decompress(path.read_bytes()).decode() if path.suffix == ".gz" else path.read_text()
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise RunLogError(f"{path}: cannot read the run log: {exc}") from exc
    lines = text.split("\n")  # the last element is "" when the log ends with a line break
    records = []
    for number, line in enumerate(lines, start=1):
        torn = number == len(lines)
        if torn and line == "":
            break
        try:
            record = json.loads(line)
        except json.JSONDecodeError as exc:
            if torn:
                break
            raise RunLogError(f"{path}:{number}: corrupt run log record ({exc.msg} at column {exc.colno})") from exc
        if not isinstance(record, dict):
            if torn:
                break
            raise RunLogError(f"{path}:{number}: a run log record must be a JSON object, got {type(record).__name__}")
        records.append(record)
    return records


def slim_records(records: list[dict], keep_successes: int = 0) -> list[dict]:
    """The records without the decisions of episodes that succeeded (the bulk of a long run's log), except those of
    the first `keep_successes` successful episodes of each segment (a clean one to replay beside the failures).
    Episodes are told apart per segment of the log (a `run` record starts one), as a resumed run may count them
    anew; a decision that names no episode (the last one, which only judges) belongs to the episode it is in."""
    owners = list(_episode_owners(records))
    kept: Counter[int] = Counter()
    left_out = set()
    for owner, r in zip(owners, records, strict=True):
        if r.get("kind") == "episode_end" and r.get("outcome") == "success":
            if kept[owner[0]] < keep_successes:
                kept[owner[0]] += 1
            else:
                left_out.add(owner)
    return [
        r for owner, r in zip(owners, records, strict=True) if not (r.get("kind") == "decision" and owner in left_out)
    ]


def _episode_owners(records: list[dict]) -> Iterator[tuple[int, Any]]:
    """(segment, episode) of each record: its own episode number, else that of the episode it is in."""
    segment, episode = 0, None
    for r in records:
        if r.get("kind") == "run":
            segment, episode = segment + 1, None
        elif r.get("kind") == "episode_start":
            episode = r.get("episode")
        yield segment, r.get("episode", episode)


def write_gzipped(path: Path, records: list[dict]) -> None:
    """`records` as a gzipped run log at `path` (no time stamp in the gzip header: the same records, the same bytes)."""
    text = "".join(json.dumps(r) + "\n" for r in records)
    path.write_bytes(gzip.compress(text.encode(), mtime=0))
