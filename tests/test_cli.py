"""`mrguide main` runs its steps' command functions: each once, in order, with the arguments its own command line
would give, its refusals under its own name, and the job's exit code from theirs."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mrguide import cli
from mrguide.errors import InputError
from mrguide.shipped_configs import shipped_config

#: (module, function) of each step, in the order the main job runs them.
STEPS = {
    "train": ("mrguide.policies.commands", "cmd_train"),
    "deploy": ("mrguide.deploy.commands", "cmd_deploy"),
    "sim2real": ("mrguide.experiments.sim2real_command", "cmd_sim2real"),
}


@pytest.fixture
def steps(monkeypatch):
    """Each step's function replaced by a recorder: `calls` gets (step, args); `results[step]` is what it returns
    (an exit code, or an exception it raises)."""
    calls: list[tuple[str, argparse.Namespace]] = []
    results: dict[str, int | Exception] = dict.fromkeys(STEPS, 0)

    def recorder(step: str):
        def run(args: argparse.Namespace) -> int:
            calls.append((step, args))
            result = results[step]
            if isinstance(result, Exception):
                raise result
            return result

        return run

    for step, (module, name) in STEPS.items():
        monkeypatch.setattr(f"{module}.{name}", recorder(step))
    return calls, results


def _options(args: argparse.Namespace) -> dict:
    """A step's options: its arguments but the objects the parser hands the command (its function, its plugins)."""
    return {k: v for k, v in vars(args).items() if v is None or isinstance(v, str | int | float | list)}


def _parsed(argv: list[str]) -> dict:
    """The options `mrguide <argv>` parses to for one step's command."""
    return _options(cli.build_parser().parse_args(argv))


def test_main_job_runs_each_step_once_in_order_with_its_command_line(tmp_path, run_cli, steps):
    calls, _ = steps
    out = tmp_path / "main"
    argv = ["--train-steps", "7", "--deploy-episodes", "2", "--seeds", "3", "--episodes", "4", "--seed", "5"]
    run = run_cli(["main", "--out", out, *argv, "--quiet"])
    assert run.code == 0, run.err
    policy, real = str(out / "train" / "policy.npz"), str(shipped_config("cells", "real_cell.toml"))
    expected = [
        ("train", ["train", "--stop-after", "7", "--seed", "5", "--out", str(out / "train"), "--quiet"]),
        ("deploy", ["deploy", "--policy", policy, "--config", real, "--dry-run", "--episodes", "2", "--log"]),
        ("sim2real", ["sim2real", "--policy", policy, "--real-config", real, "--seeds", "3", "--episodes", "4"]),
    ]
    expected[1][1].extend([str(out / "deploy.jsonl"), "--quiet"])
    expected[2][1].extend(["--out", str(out / "sim2real"), "--quiet"])
    assert [step for step, _ in calls] == [step for step, _ in expected]
    for (step, args), (_, step_argv) in zip(calls, expected, strict=True):
        assert _options(args) == _parsed(step_argv), step


def test_main_job_reuses_a_trained_policy_and_passes_its_real_cell_on(tmp_path, run_cli, steps):
    calls, _ = steps
    out = tmp_path / "main"
    (out / "train").mkdir(parents=True)
    (out / "train" / "policy.npz").write_bytes(b"")
    real = tmp_path / "cell.toml"
    run = run_cli(["main", "--out", out, "--real-config", real])
    assert run.code == 0, run.err
    assert "using the policy trained before" in run.out
    assert [step for step, _ in calls] == ["deploy", "sim2real"]
    assert calls[0][1].config == calls[1][1].real_config == str(real)
    assert calls[0][1].quiet is calls[1][1].quiet is False


def test_failed_training_ends_the_job_with_its_exit_code(tmp_path, run_cli, steps):
    calls, results = steps
    results["train"] = InputError("the config has no [train]")
    run = run_cli(["main", "--out", tmp_path / "main"])
    assert run.code == 2
    assert run.err.strip().splitlines()[-1] == "mrguide train: the config has no [train]"
    assert [step for step, _ in calls] == ["train"]


@pytest.mark.parametrize(
    "deploy, sim2real, code, err",
    [
        (1, 0, 1, ""),  # the dry run stopped (a safety stop): the job's code, after sim-to-real ran
        (InputError("bad policy"), 0, 2, "mrguide deploy: bad policy"),
        (0, InputError("bad --out"), 2, "mrguide sim2real: bad --out"),
    ],
)
def test_a_failed_dry_run_still_leaves_sim_to_real_to_run(tmp_path, run_cli, steps, deploy, sim2real, code, err):
    calls, results = steps
    results["deploy"], results["sim2real"] = deploy, sim2real
    run = run_cli(["main", "--out", tmp_path / "main"])
    assert run.code == code
    assert run.err.strip() == err
    assert [step for step, _ in calls] == list(STEPS)
    assert Path(calls[2][1].out) == tmp_path / "main" / "sim2real"
