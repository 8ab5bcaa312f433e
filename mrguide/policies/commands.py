"""`mrguide train`: argument parsing, progress display, Ctrl-C handling and the live-session hook."""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
from collections.abc import Callable
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from tqdm import tqdm

from mrguide.cli_args import add_set_argument, nonnegative_int, positive_int
from mrguide.policies.choices import EXPERT_SOURCES

#: What a training run's config holds (`policies.train_config.RunConfig`), for the help texts (no torch imported).
SECTIONS_HELP = "train, guidance, robot, twin, task and each registered learner's (ddpg, sac, ...)"

if TYPE_CHECKING:
    from mrguide.policies.guidance import GuidanceConfig
    from mrguide.policies.train import Trainer
    from mrguide.policies.train_config import RunConfig, TrainConfig


class LiveSessionLike(Protocol):
    """What `mrguide train --expert live` needs from a live annotation session (mrguide.annotation.live)."""

    url: str

    def source_factory(self, env: Any) -> Any: ...

    def publish(self, **status: Any) -> None: ...

    def interrupt(self) -> None: ...

    def close(self) -> None: ...

    def summary(self) -> str: ...


class LivePlugin(Protocol):
    """Adds the live-session options to `train` and opens the session (provided by the annotation package)."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def open_session(self, args: argparse.Namespace, on_waiting: Callable[[bool], None]) -> LiveSessionLike: ...


def add_train_command(sub: argparse._SubParsersAction, live: LivePlugin | None = None) -> None:
    """`mrguide train`; with `live`, also `--expert live` and its server options."""
    p = sub.add_parser("train", help="train DDPG in the twin, with or without MR-style expert guidance")
    p.add_argument("--config", help="TOML config ([train], [ddpg], [guidance], [robot], [twin], [task])")
    p.add_argument("--out", default="runs/train", help="run directory: checkpoint, metrics, annotations, policy")
    p.add_argument("--steps", type=positive_int, help="override train.total_steps")
    p.add_argument("--seed", type=nonnegative_int, help="override train.seed")
    p.add_argument(
        "--stop-after",
        type=positive_int,
        metavar="N",
        help="stop (checkpoint, export) after N steps, keeping the schedule of total_steps; --resume continues",
    )
    add_set_argument(
        p,
        "set any config key for this run, after --config (e.g. --set ddpg.lr_actor=0.001 --set "
        "guidance.noise.sigma=0.02); repeatable; sections: " + SECTIONS_HELP,
    )
    p.add_argument("--no-guidance", action="store_true", help="baseline DDPG (guidance.enabled = false)")
    p.add_argument(
        "--expert",
        choices=EXPERT_SOURCES if live else tuple(s for s in EXPERT_SOURCES if s != "live"),
        help="override guidance.source: the scripted oracle, the simulated MR annotator, a recorded "
        "annotation file (guidance.annotation_file), or a person through the live annotation page",
    )
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--tensorboard",
        action="store_true",
        help="also write TensorBoard event files to OUT/tensorboard/: losses, Q, BC term, λ_t, expert ratio, "
        "annotation counters, evaluations (needs the tensorboard package: pip install 'mrguide[tensorboard]')",
    )
    p.add_argument(
        "--record",
        nargs="?",
        const=256.0,
        type=_megabytes,
        metavar="MB",
        help="also record every training step (arm, object, cup, actions, ζ, annotation) to OUT/episodes.jsonl.gz, "
        "for `mrguide replay` and `mrguide export lerobot`; recording stops when the file reaches MB (default 256)",
    )
    if live is not None:
        live.add_arguments(p)
    p.set_defaults(func=partial(cmd_train, live=live))


def _megabytes(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value <= 1e6:
        raise argparse.ArgumentTypeError(f"expected a size in MB in (0, 1e6], got {text!r}")
    return value


def _refuse(message: str) -> int:
    print(f"mrguide train: {message}", file=sys.stderr)
    return 2


def cmd_train(args: argparse.Namespace, live: LivePlugin | None = None) -> int:
    """Train (or resume), show progress, export the policy; Ctrl-C checkpoints and exits 130."""
    from mrguide.policies.learner_process import LearnerProcessError
    from mrguide.policies.tensorboard_log import summary_writer_class
    from mrguide.policies.train import Trainer
    from mrguide.policies.train_config import RunConfig

    if args.tensorboard:
        try:
            summary_writer_class()
        except ImportError as exc:
            return _refuse(f"--tensorboard needs the tensorboard package (pip install 'mrguide[tensorboard]'): {exc}")
    run = _with_command_line(args, RunConfig.load(args.config).with_overrides(dict(args.set), "--set"))
    tc, gc = run.train, run.guidance
    out = Path(args.out)
    refusal = _output_refusal(out, args.resume)
    if refusal:
        return _refuse(refusal)
    bar = tqdm(
        total=min(tc.total_steps, args.stop_after or tc.total_steps), desc="train", unit="step", disable=args.quiet
    )
    session = None
    if gc.enabled and gc.source == "live":
        assert live is not None
        session = live.open_session(
            args, lambda waiting: bar.set_description_str("train | waiting for an annotation" if waiting else "train")
        )
    try:
        tr = Trainer(run, out, session.source_factory if session else None)
    except BaseException as exc:
        if session:
            session.close()
        bar.close()
        if isinstance(exc, LearnerProcessError):
            return _learner_lost(exc, out)
        raise
    if session:
        bar.write(f"annotation page: {session.url}")
    try:
        return _train_and_export(args, tr, tc, gc, out, bar, session)
    except LearnerProcessError as exc:
        return _learner_lost(exc, out)


def _learner_lost(exc: Exception, out: Path) -> int:
    """The learner's process ended, failed or hung (train.learner_process): say so and what resumes, exit 1."""
    checkpoint = out / "checkpoint.pt"
    resume = (
        f"`mrguide train --out {out} --resume` continues from its last checkpoint"
        if checkpoint.exists()
        else "no checkpoint was written"
    )
    print(f"mrguide train: {exc}; {resume}", file=sys.stderr)
    return 1


def _train_and_export(
    args: argparse.Namespace,
    tr: Trainer,
    tc: TrainConfig,
    gc: GuidanceConfig,
    out: Path,
    bar: tqdm,
    session: LiveSessionLike | None,
) -> int:
    """Resume, attach the recorder and TensorBoard as asked, train and export; what was opened is closed after."""
    from mrguide.policies.tensorboard_log import TensorBoardLog
    from mrguide.policies.train import CheckpointError

    tb = None
    try:
        if args.resume:
            try:
                tr.load_checkpoint()
            except CheckpointError as exc:
                return _refuse(str(exc))
        if args.record is not None:  # after a resume: the recording is cut back to the checkpoint
            from mrguide.policies.episode_recorder import FILE_NAME, EpisodeRecorder

            tr.recorder = EpisodeRecorder(tr, out / FILE_NAME, args.record)
        if args.tensorboard:  # on a resume, what was logged after the checkpoint is purged (it runs again)
            tb = TensorBoardLog(out / "tensorboard", purge_step=tr.counters.step + 1 if args.resume else None)
            tr.sinks.append(tb)
        bar.n = tr.counters.step
        bar.refresh()
        with _stop_on_sigint(tr, session, bar):
            _run(tr, args.stop_after, bar, session)
        if tr.stop_requested.is_set():
            return _interrupted(tr, out, bar)
        bar.close()
        _finish(tr, tc, gc, out)
        if tb is not None:
            print(f"TensorBoard: tensorboard --logdir {out / 'tensorboard'}")
        if session:
            print(session.summary())
    finally:
        bar.close()
        if tb is not None:
            tb.close()
        if tr.recorder is not None:
            tr.recorder.close()
        tr.close()
        if session:
            session.close()
    return 0


def _interrupted(tr, out: Path, bar: tqdm) -> int:
    """Ctrl-C: checkpoint where training stopped, say how to continue, exit status 130."""
    tr.save_checkpoint()
    bar.close()
    print(
        f"interrupted at step {tr.counters.step}: checkpoint {out / 'checkpoint.pt'} written; "
        f"`mrguide train --out {out} --resume` continues",
        file=sys.stderr,
    )
    return 130


def _with_command_line(args: argparse.Namespace, run: RunConfig) -> RunConfig:
    """The loaded config with the command line's --steps, --seed, --no-guidance, --expert."""
    tc, gc = run.train, run.guidance
    if args.steps is not None:
        tc = dataclasses.replace(tc, total_steps=args.steps)
    if args.seed is not None:
        tc = dataclasses.replace(tc, seed=args.seed)
    if args.no_guidance:
        gc = dataclasses.replace(gc, enabled=False)
    if args.expert:
        gc = dataclasses.replace(gc, source=args.expert)
    return run.replace(train=tc, guidance=gc)


def _output_refusal(out: Path, resume: bool) -> str | None:
    """Why `out` cannot take a new run (a checkpoint, or files of a run that never checkpointed), or None."""
    if resume:
        return None
    if (out / "checkpoint.pt").exists():
        return f"{out} already holds a run; use --resume or another --out"
    leftovers = [n for n in ("metrics.csv", "eval.csv", "annotations.jsonl") if (out / n).exists()]
    if leftovers:
        return (
            f"{out} holds {', '.join(leftovers)} of a run that never checkpointed: use another --out, or move "
            "them away (a recorded annotations.jsonl replays with guidance.source = 'file')"
        )
    return None


def _run(tr, stop_after: int | None, bar: tqdm, session: LiveSessionLike | None) -> None:
    from mrguide.policies.session_status import SessionStatus

    status = SessionStatus(tr)

    def progress(row: dict) -> None:
        status.episode(row)
        bar.update(row["step"] - bar.n)
        bar.set_postfix(
            ret=f"{row['return']:.1f}",
            succ20=f"{status.success_rate():.0%}",
            lam=f"{row['lambda']:.2f}",
            interv=tr.counters.interventions,
            asked=row["asked"],
        )
        if session:
            session.publish(**status.fields())

    if session:
        session.publish(**status.fields())
    tr.run(progress, stop_at=stop_after)


def _finish(tr, tc, gc, out: Path) -> None:
    from mrguide.policies.export import export_actor

    final = tr.last_eval or tr.evaluate()
    policy = export_actor(
        tr.agent.policy_actor,
        out / "policy.npz",
        tr.env.robot_spec,
        tr.env.task_cfg,
        tr.env.twin_cfg.decision_period,
        {"trained": {"steps": tr.counters.step, "seed": tc.seed, "guidance": gc.enabled}},
    )
    print(
        f"trained {tr.counters.step} steps in {tr.wall_s():.0f} s ({tr.counters.step / max(tr.wall_s(), 1e-9):.0f} steps/s); "
        f"expert interventions {tr.counters.interventions}, annotations asked {tr.counters.asked} / reused {tr.counters.reused}"
        f" / re-marked {tr.counters.remarks}, demonstrations skipped {tr.counters.skipped}"
    )
    print(f"deterministic evaluation: {final['success_rate']:.0%} success over {tc.eval_episodes} episodes")
    print(f"policy: {policy}   metrics: {out / 'metrics.csv'}   checkpoint: {out / 'checkpoint.pt'}")


@contextmanager
def _stop_on_sigint(tr, session: LiveSessionLike | None, bar: tqdm):
    """First Ctrl-C: stop at the next step (and end a pending annotation request); a second one aborts."""

    def handler(signum, frame) -> None:
        if tr.stop_requested.is_set():
            raise KeyboardInterrupt
        tr.stop_requested.set()
        if session:
            session.interrupt()
        bar.write("stopping at the next step to write a checkpoint (Ctrl-C again to abort without one)")

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def add_config_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help="the effective configuration of a training run")
    csub = p.add_subparsers(dest="config_command", required=True)
    show = csub.add_parser(
        "show",
        help="print every section (" + SECTIONS_HELP + ") as JSON: the defaults, then --config's values, then --set's",
    )
    show.add_argument("--config", help="TOML config, as `mrguide train --config` takes it")
    add_set_argument(
        show,
        "as `mrguide train --set`; repeatable",
    )
    show.set_defaults(func=cmd_config_show)


def cmd_config_show(args: argparse.Namespace) -> int:
    from mrguide.config import to_dict
    from mrguide.policies.train_config import RunConfig

    run = RunConfig.load(args.config).with_overrides(dict(args.set), "--set")
    print(json.dumps({name: to_dict(section) for name, section in run.sections().items()}, indent=1))
    return 0
