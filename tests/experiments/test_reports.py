"""Reports built from run directories: the summary columns, the convergence rule, figures."""

import csv
import dataclasses

from mrguide.experiments import learning_curves as lc
from mrguide.experiments import noise_robustness as nr
from mrguide.experiments.train_runs import run_config
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
    write_run(
        tmp_path / "guided" / "seed1", [0.5, 0.9, 0.6, 0.6, 1.0], [10, 20, 30, 50, 60, 60, 60, 60, 60, 60], wall=300.0
    )
    files = lc.learning_curves_report(cfg, lc.records(cfg, None, tmp_path, 10))
    (tmp_path / "summary.csv").write_bytes(files["summary.csv"])
    (tmp_path / "runs.csv").write_bytes(files["runs.csv"])
    table = {r["variant"]: r for r in read(tmp_path / "summary.csv")}
    assert list(table["guided"]) == [
        "variant",
        "seeds",
        "converged_4k",
        "converged_5k",
        "converged_20k",
        "median_step",
        "median_annotations",
        "median_person_minutes",
    ]
    assert table["guided"] == {
        "variant": "guided",
        "seeds": "2",
        "converged_4k": "1",
        "converged_5k": "1",
        "converged_20k": "1",
        "median_step": "3000",
        "median_annotations": "40",
        "median_person_minutes": "2.7",
    }  # 40 marks at 4 s
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
    assert read(tmp_path / "s.csv") == [
        {"variant": "baseline", "seeds": "3", "steps": "5000", "converged": "2", "median_step": "3500"}
    ]
    assert "fig4_long_baseline.png" in files


def test_noise_summary_with_wilson_intervals(tmp_path):
    cfg = nr.NoiseConfig(seeds=2, steps=5000, sigmas=(0.0, 0.05))
    names = [r.name for r in nr.runs(cfg, None)]
    assert names == ["sigma_0.000/seed0", "sigma_0.050/seed0", "sigma_0.000/seed1", "sigma_0.050/seed1"]
    assert cfg.reading == "marks" and nr.runs(cfg, None)[3].overrides == {"guidance.noise.sigma": 0.05}
    stored = dataclasses.replace(cfg, reading="stored")
    assert nr.runs(stored, None)[1].overrides == {"guidance.action_noise": 0.05}
    for name, rates in zip(
        names, ([0.5, 0.9, 1.0, 1.0, 1.0], [0.0, 0.5, 0.9, 0.9, 0.9], [0.6, 0.9, 0.9, 0.8, 0.9], [0.0] * 5)
    ):
        write_run(tmp_path / name, rates, list(range(10)), rows=[{"kind": "agent", "outcome": "no_grasp"}] * 10)
    files = nr.noise_report(cfg, nr.records(cfg, None, tmp_path, 10))
    (tmp_path / "r.csv").write_bytes(files["runs.csv"])
    assert {(r["exploring_no_grasp"], r["exploring_dropped"]) for r in read(tmp_path / "r.csv")} == {("10", "0")}
    (tmp_path / "s.csv").write_bytes(files["summary.csv"])
    rows = read(tmp_path / "s.csv")
    assert list(rows[0]) == [
        "sigma_m",
        "seeds",
        "converged",
        "probability",
        "median_annotations",
        "median_person_minutes",
        "median_marks_total",
        "median_person_minutes_total",
    ]
    assert [(r["sigma_m"], r["converged"], r["probability"]) for r in rows] == [
        ("0.0", "2", "1.0"),
        ("0.05", "1", "0.5"),
    ]
    md = files["summary.md"].decode()
    assert "| 0.05 | 2 | 1 | 0.5 | 0.095 | 0.905 |" in md  # Wilson interval of 1/2
    assert files["fig7_noise_robustness.png"][:4] == b"\x89PNG"


def test_person_report_counts_marks_and_person_minutes_and_the_fresh_episodes(tmp_path):
    from mrguide.experiments import person

    cfg = person.PersonConfig(seeds=2, steps=5000, episodes=4)
    write_run(
        tmp_path / "seed0", [0.5, 0.9, 1.0, 1.0, 0.9], [10, 20, 25, 30, 45, 45, 45, 45, 45, 45]
    )  # converged at 3000
    write_run(tmp_path / "seed1", [0.0, 0.1, 0.0, 0.2, 0.1], [30, 60, 90, 120, 150, 180, 210, 240, 270, 300])
    for s, outcomes in ((0, ["success"] * 3 + ["dropped"]), (1, ["no_grasp"] * 4)):
        (tmp_path / f"seed{s}" / "fresh.csv").write_text(
            "seed,outcome,return,steps\n" + "".join(f"{k},{o},1.0,30\n" for k, o in enumerate(outcomes))
        )
    files = person.person_report(cfg, tmp_path, person.runs(cfg, None), 10)
    (tmp_path / "s.csv").write_bytes(files["summary.csv"])
    (summary,) = read(tmp_path / "s.csv")
    assert (
        summary["converged"],
        summary["median_step"],
        summary["median_marks"],
        summary["median_person_minutes"],
    ) == ("1", "3000", "45", "3.0")  # 45 marks by step 3000, at 4 s each
    assert (summary["median_marks_total"], summary["fresh_success_min"], summary["fresh_success_max"]) == (
        "172",
        "0.0",
        "0.75",
    )
    assert all(r.client == "bot" for r in person.runs(cfg, None)) and files["person_marks.png"][:4] == b"\x89PNG"


def test_peers_report_compares_at_equal_marks_and_equal_wall_time(tmp_path):
    from mrguide.experiments import peers

    cfg = peers.PeersConfig(seeds=1, steps=5000, marks_budget=25, time_budget_s=150.0)
    assert [r.overrides["train.learner"] for r in peers.runs(cfg, None)] == ["ddpg", "sac"]
    # ddpg: cheap per step, many marks; sac: few marks, slow (wall time 5x)
    write_run(
        tmp_path / "ddpg" / "seed0",
        [0.5, 0.9, 1.0, 1.0, 1.0],
        [10, 20, 25, 30, 45, 45, 45, 45, 45, 45],
        wall=100.0,
        rows=[{"temperature": ""}] * 10,  # DDPG logs none
    )
    # how the exploring episodes ended, and the temperature (blank before the first update, as SAC logs it)
    ends = ["no_grasp", "dropped", "no_grasp", "success", "guided", "no_grasp", "dropped", "success", "", ""]
    sac_rows = [
        {"kind": "agent", "outcome": o, "temperature": t} for o, t in zip(ends, [""] * 2 + ["0.2"] * 7 + ["0.05"])
    ]
    sac_rows[3]["kind"] = "expert"  # an expert episode's outcome is not the agent's
    write_run(
        tmp_path / "sac" / "seed0",
        [0.0, 0.2, 0.6, 0.9, 1.0],
        [5, 8, 10, 12, 14, 15, 15, 15, 15, 15],
        wall=500.0,
        rows=sac_rows,
    )
    files = peers.peers_report(cfg, peers.records(cfg, None, tmp_path, 10))
    (tmp_path / "r.csv").write_bytes(files["runs.csv"])
    per_run = {r["learner"]: r for r in read(tmp_path / "r.csv")}
    assert (per_run["sac"]["exploring_no_grasp"], per_run["sac"]["exploring_dropped"]) == ("3", "2")
    assert per_run["sac"]["final_temperature"] == "0.05" and per_run["ddpg"]["final_temperature"] == ""
    (tmp_path / "s.csv").write_bytes(files["summary.csv"])
    rows = {r["learner"]: r for r in read(tmp_path / "s.csv")}
    # after 25 marks: ddpg at its 1k evaluation (20 asked there, 30 by 2k), sac at its last (it never asked 25)
    assert rows["ddpg"]["mean_success_at_25_marks"] == "0.5" and rows["sac"]["mean_success_at_25_marks"] == "1.0"
    # after 150 s: ddpg is done (final 1.0), sac is at its first evaluation (100 s per 1000 steps)
    assert rows["ddpg"]["mean_success_at_150_s"] == "1.0" and rows["sac"]["mean_success_at_150_s"] == "0.0"
    assert rows["ddpg"]["median_wall_s_per_run"] == "100.0" and rows["sac"]["median_wall_s_per_run"] == "500.0"
    assert files["peers.png"][:4] == b"\x89PNG"


def test_the_bias_reading_reports_the_bias_each_person_drew(tmp_path):
    """runs.csv of the registration-bias sweep names each run's drawn bias: the one its trainer's annotator holds."""
    from mrguide.policies.guided_expert import make_expert_source
    from mrguide.twin.env import PickPlaceEnv

    shipped = "configs/runs/person.toml"
    cfg = nr.NoiseConfig(seeds=2, steps=5000, sigmas=(0.0, 0.012), reading="bias")
    runs = nr.runs(cfg, shipped)
    for run in runs:
        write_run(tmp_path / run.name, [0.5, 0.9, 1.0, 1.0, 1.0], list(range(10)))
    files = nr.noise_report(cfg, nr.records(cfg, shipped, tmp_path, 10))
    (tmp_path / "r.csv").write_bytes(files["runs.csv"])
    rows = {(r["sigma_m"], r["seed"]): r["registration_bias_mm"] for r in read(tmp_path / "r.csv")}
    run = runs[3]  # 12 mm, seed 1
    cfg = run_config(run)
    gc, ec = cfg.guidance, cfg.env
    env = PickPlaceEnv(ec)
    try:
        drawn = 1e3 * make_expert_source(gc, env, run.seed).run_bias
    finally:
        env.close()
    assert rows[("0.012", "1")] == " ".join(f"{b:.1f}" for b in drawn) and abs(drawn).max() > 0.5
    assert rows[("0.012", "0")] != rows[("0.012", "1")]  # each seed's person draws their own
    assert rows[("0.0", "0")] == "0.0 0.0 0.0"


def test_a_report_reads_run_files_stored_compressed_as_it_reads_them_plain(tmp_path):
    """docs/results keeps metrics.csv and eval.csv of its runs gzip-compressed: the same report either way."""
    import gzip
    import shutil

    cfg = nr.NoiseConfig(seeds=2, steps=5000, sigmas=(0.0,))
    for name, rates in zip(["sigma_0.000/seed0", "sigma_0.000/seed1"], ([0.5, 0.9, 1.0, 1.0, 1.0], [0.0] * 5)):
        write_run(tmp_path / name, rates, list(range(10)), rows=[{"kind": "agent", "outcome": "dropped"}] * 10)
    plain = nr.noise_report(cfg, nr.records(cfg, None, tmp_path, 10))
    for path in tmp_path.glob("sigma_0.000/seed0/*.csv"):
        with path.open("rb") as src, gzip.open(path.with_name(path.name + ".gz"), "wb") as dst:
            shutil.copyfileobj(src, dst)
        path.unlink()
    packed = nr.noise_report(cfg, nr.records(cfg, None, tmp_path, 10))
    assert packed["summary.csv"] == plain["summary.csv"] and packed["runs.csv"] == plain["runs.csv"]
