"""The run log reader fails closed: only a torn last line (the writer died mid-line) is skipped."""

from __future__ import annotations

import json

import pytest

from mrguide.deploy.runlog import RunLog, RunLogError, read_log


def _log(tmp_path, n=3):
    path = tmp_path / "run.jsonl"
    with RunLog(path, {"test": "runlog"}) as log:
        for t in range(n):
            log.write("decision", t=t)
    return path


def test_a_complete_log_reads_back_every_record(tmp_path):
    path = _log(tmp_path)
    records = read_log(path)
    assert [r["kind"] for r in records] == ["run", "decision", "decision", "decision"]
    assert [r.get("t") for r in records[1:]] == [0, 1, 2]


def test_a_torn_last_line_is_skipped(tmp_path):
    path = _log(tmp_path)
    with path.open("a") as fh:
        fh.write('{"kind": "decision", "t": 3, "obs": [0.1, 0.')  # the writer died here: no line break
    assert [r.get("t") for r in read_log(path)[1:]] == [0, 1, 2]


def test_a_complete_last_record_without_its_line_break_is_kept(tmp_path):
    path = _log(tmp_path)
    with path.open("a") as fh:
        fh.write(json.dumps({"kind": "decision", "t": 3}))
    assert [r.get("t") for r in read_log(path)[1:]] == [0, 1, 2, 3]


@pytest.mark.parametrize(
    "bad, line",
    [
        ('{"kind": "decision", "t": 1', 3),  # a torn line in the middle: the log was cut and appended to
        ("garbage", 3),
        ("", 3),  # an empty line in the middle
        ("[1, 2]", 3),  # JSON, but not a record
    ],
)
def test_a_corrupt_line_elsewhere_is_an_error_naming_file_and_line(tmp_path, bad, line):
    path = _log(tmp_path)
    lines = path.read_text().splitlines()
    lines.insert(line - 1, bad)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RunLogError, match=rf"{path.name}:{line}: "):
        read_log(path)


def test_a_corrupt_last_line_with_its_line_break_is_an_error(tmp_path):
    """A line that was written whole (it has its line break) but is not JSON was not torn: it is corrupt."""
    path = _log(tmp_path)
    with path.open("a") as fh:
        fh.write("not json\n")
    with pytest.raises(RunLogError, match=rf"{path.name}:5: corrupt run log record"):
        read_log(path)
