"""A checkout stays light: the tracked files (the work tree without `.git`) weigh at most 40 MB, so results are
committed compressed and slim (docs/results: "What a checkout weighs")."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
LIMIT_MB = 40.0


def tracked_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: nothing tracked to weigh")
    return [ROOT / name.decode() for name in out.split(b"\0") if name]


def test_the_tracked_files_weigh_at_most_40_mb() -> None:
    files = tracked_files()
    assert len(files) > 100
    present = [f for f in files if f.is_file()]  # a file deleted in the work tree but not yet in git weighs nothing
    total = sum(f.stat().st_size for f in present) / 1e6
    largest = sorted(present, key=lambda f: f.stat().st_size)[-3:]
    assert total <= LIMIT_MB, f"{total:.1f} MB tracked (limit {LIMIT_MB:g}); largest: {[str(f) for f in largest]}"
