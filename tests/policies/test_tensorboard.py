"""`mrguide train --tensorboard`: event files with the metrics, evaluations and annotation counters, read back
through tensorboard's EventAccumulator; the writer is closed on every exit path; a resume hides what an
interrupted process logged after its checkpoint; without the flag nothing changes."""

import csv
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from tensorboard.backend.event_processing.event_accumulator import (
    EventAccumulator,
)  # the dev extra installs tensorboard

from mrguide.cli import main
from mrguide.policies import tensorboard_log as tb_mod

TAGS = {
    *(f"train/{k}" for k in ("critic_loss", "actor_loss", "q_mean", "q_max", "bc_loss", "expert_ratio", "lambda")),
    *(f"annotations/{k}" for k in ("asked", "reused", "remarks", "skipped")),
    "eval/success_rate",
    "eval/mean_return",
}


@pytest.fixture
def tiny(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(
        "[train]\nlearning_starts = 64\nbatch_size = 32\neval_every = 150\neval_episodes = 2\ncheckpoint_every = 100\n"
        "[ddpg]\nhidden = [32, 32]\n[guidance]\nintake_steps = 300\n"
    )
    return cfg


def read_csv(path):
    with path.open() as fh:
        return list(csv.DictReader(fh))


def scalars(logdir):
    acc = EventAccumulator(str(logdir))
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def check_against_csv(out):
    """The event files say what metrics.csv and eval.csv say, once per step."""
    sc = scalars(out / "tensorboard")
    assert set(sc) == TAGS
    rows, evals = read_csv(out / "metrics.csv"), read_csv(out / "eval.csv")
    with_updates = [r for r in rows if r["critic_loss"] != ""]
    assert len(with_updates) >= 3
    for field in ("critic_loss", "actor_loss", "q_mean", "q_max", "bc_loss", "expert_ratio"):
        assert [s for s, _ in sc[f"train/{field}"]] == [int(r["step"]) for r in with_updates], field
        assert [v for _, v in sc[f"train/{field}"]] == pytest.approx([float(r[field]) for r in with_updates], rel=1e-6)
    steps = sorted({int(r["step"]) for r in rows})
    for tag, field in (("train/lambda", "lambda"), ("annotations/asked", "asked"), ("annotations/reused", "reused")):
        assert [s for s, _ in sc[tag]] == steps, tag
        last = {int(r["step"]): float(r[field]) for r in rows}
        assert [v for _, v in sc[tag]] == pytest.approx([last[s] for s in steps]), tag
    assert sc["annotations/asked"][-1][1] > 0
    for field in ("success_rate", "mean_return"):
        assert sc[f"eval/{field}"] == [(int(e["step"]), pytest.approx(float(e[field]))) for e in evals]
    return sc


def test_tensorboard_event_files_hold_the_training_metrics(tmp_path, tiny, capsys):
    out = tmp_path / "run"
    assert main(["train", "--config", str(tiny), "--steps", "300", "--out", str(out), "--quiet", "--tensorboard"]) == 0
    assert f"tensorboard --logdir {out / 'tensorboard'}" in capsys.readouterr().out
    sc = check_against_csv(out)
    assert (
        len(sc["eval/success_rate"]) == 2 and sc["eval/success_rate"][-1][0] == 300
    )  # every 150 steps, at an episode end


def test_writer_closed_on_crash_and_ctrl_c_and_resume_hides_what_ran_after_the_checkpoint(tmp_path, tiny, monkeypatch):
    out = tmp_path / "run"
    argv = ["train", "--config", str(tiny), "--steps", "400", "--out", str(out), "--quiet", "--tensorboard"]
    closed, row = [], tb_mod.TensorBoardLog.row
    close = tb_mod.TensorBoardLog.close
    monkeypatch.setattr(tb_mod.TensorBoardLog, "close", lambda self: closed.append(self) or close(self))

    def crash_after(step):
        def row_then_crash(self, r):
            row(self, r)
            if r["step"] > step:
                raise RuntimeError("crash")

        return row_then_crash

    monkeypatch.setattr(tb_mod.TensorBoardLog, "row", crash_after(180))  # checkpointed at 100-something
    with pytest.raises(RuntimeError, match="crash"):
        main(argv)
    assert len(closed) == 1
    logged = max(s for s, _ in scalars(out / "tensorboard")["train/lambda"])
    assert logged > 180  # logged past the checkpoint; those episodes run again on resume

    def row_then_ctrl_c(self, r):
        row(self, r)
        if r["step"] > 250:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(tb_mod.TensorBoardLog, "row", row_then_ctrl_c)
    assert main([*argv, "--resume"]) == 130
    assert len(closed) == 2
    monkeypatch.setattr(tb_mod.TensorBoardLog, "row", row)
    assert main([*argv, "--resume"]) == 0
    assert len(closed) == 3
    sc = check_against_csv(out)  # one value per step: the crashed process's steps after its checkpoint are purged
    assert max(s for s, _ in sc["train/lambda"]) == 400


def test_without_the_flag_nothing_changes(tmp_path, tiny, monkeypatch, capsys):
    def refuse():
        raise AssertionError("SummaryWriter requested without --tensorboard")

    monkeypatch.setattr(tb_mod, "summary_writer_class", refuse)
    out = tmp_path / "run"
    assert main(["train", "--config", str(tiny), "--steps", "100", "--out", str(out), "--quiet"]) == 0
    assert not (out / "tensorboard").exists() and "TensorBoard" not in capsys.readouterr().out
    code = (
        "import sys, mrguide.cli, mrguide.policies.commands, mrguide.policies.train; "
        "print(sorted(m for m in sys.modules if m.startswith(('tensorboard', 'torch.utils.tensorboard'))))"
    )
    env_path = str(Path(__file__).resolve().parents[2])
    res = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": env_path, "PATH": ""},
    )
    assert res.returncode == 0 and res.stdout.strip() == "[]", res


def test_missing_tensorboard_package_is_one_clear_refusal(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # as if tensorboard were not installed
    out = tmp_path / "run"
    assert main(["train", "--steps", "100", "--out", str(out), "--quiet", "--tensorboard"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mrguide train: --tensorboard needs the tensorboard package") and len(err.splitlines()) == 1
    assert not out.exists()
