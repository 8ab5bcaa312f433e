"""The replay page's analysis (docs/replay.md): the lift-drop numbers recompute from the committed run logs exactly,
and the viewer screenshot tool photographs a recording."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from pathlib import Path

import pytest

from mrguide.replay import lift_drops

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def drops(tmp_path_factory) -> tuple[Path, str]:
    """`lift_drops` run once on the committed logs: (its output directory, what it printed)."""
    out = tmp_path_factory.mktemp("drops")
    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        mp.setattr(sys, "argv", ["lift_drops", str(ROOT / lift_drops.RUN), str(out)])
        assert lift_drops.main() == 0
    return out, printed.getvalue()


def test_the_lift_drop_numbers_recompute_from_the_committed_logs(drops):
    out, printed = drops
    assert printed == (ROOT / "docs/results/replay/drops.txt").read_text()
    assert (out / "drops.rrd").stat().st_size > 0 and (out / "lifts.png").stat().st_size > 0


def test_an_empty_run_directory_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["lift_drops", str(tmp_path), str(tmp_path / "out")])
    assert lift_drops.main() == 2
    assert "no seed*/sim2real/log-*.jsonl.gz" in capsys.readouterr().err


def test_the_screenshot_tool_photographs_a_recording(drops, tmp_path):
    rrd = drops[0] / "drops.rrd"
    png = tmp_path / "shot.png"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "mrguide.replay.screenshot",
            str(rrd),
            str(png),
            "--wait",
            "5",
            "--width",
            "640",
            "--height",
            "400",
            "--web-port",
            "9291",
            "--grpc-port",
            "9878",
        ],
        check=True,
        capture_output=True,
        cwd=ROOT,
        timeout=300,
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png.read_bytes()[16:20], "big"), int.from_bytes(png.read_bytes()[20:24], "big")
    assert (width, height) == (640, 400)
