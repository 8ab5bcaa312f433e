"""Shared by the CLI tests: run `mrguide.cli.main` in-process and check how a bad input was refused."""

from __future__ import annotations

from dataclasses import dataclass

import pytest


@dataclass
class CliRun:
    """Exit code (argparse's SystemExit included) and output of one `mrguide` command."""

    code: int
    out: str
    err: str

    def assert_refused(self, *words: str) -> str:
        """Exit 2, no traceback, and one line on stderr naming each of `words` (argparse may print its usage
        lines before it). Returns that line."""
        assert self.code == 2, (self.code, self.err)
        assert "Traceback" not in self.err and "Traceback" not in self.out
        lines = self.err.strip().splitlines()
        assert lines, "nothing on stderr"
        usage = lines[:-1]
        if usage:  # argparse: "usage: mrguide ..." (wrapped lines indented), then "mrguide ...: error: ..."
            assert usage[0].startswith("usage: ") and all(line.startswith(" ") for line in usage[1:]), lines
            assert ": error: argument " in lines[-1], lines
        assert lines[-1].startswith("mrguide "), lines
        for word in words:
            assert word in lines[-1], (word, lines[-1])
        return lines[-1]


@pytest.fixture
def run_cli(capsys):
    """run_cli(argv) -> CliRun: `mrguide.cli.main(argv)` in-process."""
    from mrguide.cli import main

    def run(argv: list) -> CliRun:
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
        out, err = capsys.readouterr()
        return CliRun(code, out, err)

    return run
