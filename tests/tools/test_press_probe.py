"""The pressing probe of docs/sim2real.md runs from the package on the shipped real cell and writes its table."""

from __future__ import annotations

import csv
from pathlib import Path

from tests.tools.conftest import load_tool

press_probe = load_tool("press_probe")

ROOT = Path(__file__).parents[2]


def test_the_press_probe_presses_each_case_rigid_and_compliant(tmp_path, capsys):
    assert (
        press_probe.main(
            ["--episodes", "1", "--cell", str(ROOT / "configs/cells/real_cell.toml"), "--out", str(tmp_path)]
        )
        == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == [
        f"stroke {stroke} mm | {case}" for stroke in (0, 12) for case in press_probe.CASES
    ]
    rows = list(csv.DictReader((tmp_path / "press_probe.csv").open()))
    assert [(r["stroke_m"], r["case"]) for r in rows] == [
        (stroke, case) for stroke in ("0.0", "0.012") for case in press_probe.CASES
    ]
    assert all(r["outcome"] for r in rows)
