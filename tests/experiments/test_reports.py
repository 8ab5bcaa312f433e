"""Reports built from run directories: the summary columns issue 16 asks for, the convergence rule, figures."""

import csv
import dataclasses

from mrguide.experiments import learning_curves as lc
from mrguide.experiments import noise_robustness as nr
from tests.experiments.conftest import write_run


def read(path):
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_learning_curves_summary(tmp_path):
    cfg = lc.CurvesConfig(seeds=2, steps=5000)
    for s in range(2):
        write_run(tmp_path / "baseline" / f"seed{s}", [0.0] * 5, [0] * 10)
    # seed 0 reaches the window at 3000 (0.9, 1.0) having asked 40 by then; seed 1 only at the end
    write_run(tmp_path / "guided" / "seed0", [0.5, 0.9, 1.0, 1.0, 0.9], [10, 20, 25, 30, 40, 40, 40, 40, 40, 40])
    write_run(tmp_path / "guided" / "seed1", [0.5, 0.9, 0.6, 0.6, 1.0], [10, 20, 30, 50, 60, 60, 60, 60, 60, 60], wall=300.0)
    files = lc.learning_curves_report(cfg, lc.records(cfg, None, tmp_path, 10))
    (tmp_path / "summary.csv").write_bytes(files["summary.csv"])
    (tmp_path / "runs.csv").write_bytes(files["runs.csv"])
    table = {r["variant"]: r for r in read(tmp_path / "summary.csv")}
    assert list(table["guided"]) == ["variant", "seeds", "converged_4k", "converged_5k", "converged_20k", "median_step",
                                     "median_annotations"]
    assert table["guided"] == {"variant": "guided", "seeds": "2", "converged_4k": "1", "converged_5k": "1",
                               "converged_20k": "1", "median_step": "3000", "median_annotations": "40"}
    assert table["baseline"]["converged_20k"] == "0" and table["baseline"]["median_step"] == ""
    runs = {(r["variant"], r["seed"]): r for r in read(tmp_path / "runs.csv")}
    assert runs["guided", "1"]["convergence_step"] == "" and runs["guided", "1"]["reached_at_end"] == "1"
    assert "reached only at the end" in files["summary.md"].decode()
    for fig in ("fig3_learning_curves.png", "fig5_convergence.png", "fig9_expert_effort.png"):
        assert files[fig][:4] == b"\x89PNG" and len(files[fig]) > 10_000


def test_long_baseline_summary(tmp_path):
    cfg = lc.CurvesConfig(seeds=3, steps=5000, variants=("baseline",))
    write_run(tmp_path / "baseline" / "seed0", [0.0, 0.0, 0.9, 0.9, 1.0], [0] * 10)
    write_run(tmp_path / "baseline" / "seed1", [0.0] * 5, [0] * 10)
    write_run(tmp_path / "baseline" / "seed2", [0.0, 0.9, 0.9, 0.9, 0.9], [0] * 10)
    files = lc.long_baseline_report(cfg, lc.records(cfg, None, tmp_path, 10))
    (tmp_path / "s.csv").write_bytes(files["summary.csv"])
    assert read(tmp_path / "s.csv") == [{"variant": "baseline", "seeds": "3", "steps": "5000", "converged": "2",
                                         "median_step": "3500"}]
    assert "fig4_long_baseline.png" in files


def test_noise_summary_with_wilson_intervals(tmp_path):
    cfg = nr.NoiseConfig(seeds=2, steps=5000, sigmas=(0.0, 0.05))
    names = [r.name for r in nr.runs(cfg, None)]
    assert names == ["sigma_0.000/seed0", "sigma_0.050/seed0", "sigma_0.000/seed1", "sigma_0.050/seed1"]
    assert cfg.reading == "marks" and nr.runs(cfg, None)[3].overrides == {"guidance.noise.sigma": 0.05}
    stored = dataclasses.replace(cfg, reading="stored")
    assert nr.runs(stored, None)[1].overrides == {"guidance.action_noise": 0.05}
    for name, rates in zip(names, ([0.5, 0.9, 1.0, 1.0, 1.0], [0.0, 0.5, 0.9, 0.9, 0.9], [0.6, 0.9, 0.9, 0.8, 0.9], [0.0] * 5)):
        write_run(tmp_path / name, rates, list(range(10)))
    files = nr.noise_report(cfg, nr.records(cfg, None, tmp_path, 10))
    (tmp_path / "s.csv").write_bytes(files["summary.csv"])
    rows = read(tmp_path / "s.csv")
    assert list(rows[0]) == ["sigma_m", "seeds", "converged", "probability", "median_annotations"]
    assert [(r["sigma_m"], r["converged"], r["probability"]) for r in rows] == [("0.0", "2", "1.0"), ("0.05", "1", "0.5")]
    md = files["summary.md"].decode()
    assert "| 0.05 | 2 | 1 | 0.5 | 0.095 | 0.905 |" in md  # Wilson interval of 1/2
    assert files["fig7_noise_robustness.png"][:4] == b"\x89PNG"
