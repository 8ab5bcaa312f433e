"""The shipped configs are found from any directory, and a plain (non-editable) wheel carries them."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from mrguide import shipped_configs
from mrguide.config import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_the_installed_copy_is_used_when_there_is_no_checkout(tmp_path, monkeypatch):
    installed = tmp_path / "share" / "mrguide" / "configs"
    (installed / "experiments").mkdir(parents=True)
    (installed / "experiments" / "x.toml").write_text("[experiment]\n")
    monkeypatch.setattr(shipped_configs, "CHECKOUT", tmp_path / "no-checkout")
    monkeypatch.setattr(shipped_configs, "INSTALLED", installed)
    assert shipped_configs.shipped_config("experiments", "x.toml") == installed / "experiments" / "x.toml"
    with pytest.raises(ConfigError, match=r"real_cell.toml is missing"):
        shipped_configs.shipped_config("real_cell.toml")


def test_defaults_resolve_outside_the_checkout(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert shipped_configs.shipped_config("real_cell.toml") == ROOT / "configs" / "real_cell.toml"


def test_a_plain_wheel_carries_the_configs_and_the_arm_files(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = tmp_path.glob("mrguide-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    data = next(n.split("/data/")[0] for n in names if ".data/data/" in n) + "/data/share/mrguide/configs/"
    shipped = {
        str(p.relative_to(ROOT / "configs")) for p in (ROOT / "configs").rglob("*") if p.suffix in (".toml", ".json")
    }
    assert {data + s for s in shipped} <= names
    assert {"mrguide/arms/ur5.toml", "mrguide/arms/ur10.toml"} <= names
