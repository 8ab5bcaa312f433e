"""`mrguide sim2real --set`: keys of the played cells reach the conditions that play them."""

from __future__ import annotations

from pathlib import Path

from mrguide.experiments import sim2real as s2r

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"


def test_set_reaches_the_played_cell_its_safety_and_its_hmd(tmp_path, run_cli, policy_file, monkeypatch):
    played = []

    def run_real(policy, cfg, bus, seed, episodes, log, path, safety, **kw):
        played.append((kw["condition"], cfg, safety, kw["hmd_overrides"]))
        return ["success"] * episodes

    monkeypatch.setattr(s2r, "run_real", run_real)
    sets = [
        "twin.reality_gap.object_mass=0.35",
        "safety.following_error=0.08",
        "calibration.hmd.tracking_noise_m=0.004",
    ]
    res = run_cli(
        ["sim2real", "--policy", policy_file(tmp_path / "p.npz"), "--real-config", REAL, "--out", tmp_path / "o"]
        + ["--conditions", "real_exact,real_hmd", "--seeds", "1", "--episodes", "2", "--quiet"]
        + [a for s in sets for a in ("--set", s)]
    )
    assert res.code == 0, res.err
    assert [p[0] for p in played] == ["real_exact", "real_hmd"]
    for _, cfg, safety, _ in played:
        assert cfg.twin.reality_gap.object_mass == 0.35 and safety.following_error == 0.08
    assert played[1][3] == {"tracking_noise_m": 0.004}
    assert "object 0.35 kg" in res.out  # the report's description of the cell played
