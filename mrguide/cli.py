"""The `mrguide` command."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mrguide.cli_args import ArgumentParser, nonnegative_int, positive_int
from mrguide.drivers.errors import DriverError
from mrguide.errors import InputError
from mrguide.install_profiles import missing_profile_message


def cmd_main(args: argparse.Namespace) -> int:
    """The Quick-start main job: train a guided policy briefly (or reuse it) → dry-run deploy → sim-to-real.

    Each step is its command's function, run as `mrguide <step>` would run it (its refusals and exit codes under its
    own name); a failed training ends the job, a failed dry run still leaves the sim-to-real step to run."""
    from mrguide.deploy.commands import cmd_deploy
    from mrguide.experiments.sim2real_command import cmd_sim2real
    from mrguide.policies.commands import cmd_train
    from mrguide.shipped_configs import shipped_config

    t0 = time.perf_counter()
    out = Path(args.out)
    real_config = str(args.real_config or shipped_config("cells", "real_cell.toml"))  # checked before training starts
    policy = out / "train" / "policy.npz"
    if policy.exists():
        print(f"[1/3] using the policy trained before: {policy} (delete {out} to train again)")
    else:
        print(
            f"[1/3] training a guided DDPG policy in the twin (simulated MR annotator): the first {args.train_steps} "
            "steps of the 20k-step schedule"
        )
        rc = run_command("mrguide train", cmd_train, _train_step(args, out / "train"))
        if rc:
            return rc
    print("\n[2/3] dry run: deploying it over the virtual CAN bus to simulated drives on a twin with reality gap")
    rc = run_command("mrguide deploy", cmd_deploy, _deploy_step(args, policy, real_config, out / "deploy.jsonl"))
    print(f"\n[3/3] sim-to-real evaluation: {args.seeds} seeds x {args.episodes} episodes per condition")
    rc2 = run_command("mrguide sim2real", cmd_sim2real, _sim2real_step(args, policy, real_config, out / "sim2real"))
    print(f"main job finished in {time.perf_counter() - t0:.0f} s")
    return rc or rc2


def _step_args(argv: list[str], **values: Any) -> argparse.Namespace:
    """A step's arguments: what `mrguide <argv>` parses to (every other option at its default), `values` over it."""
    args = build_parser().parse_args(argv)
    for name, value in values.items():
        setattr(args, name, value)
    return args


def _train_step(args: argparse.Namespace, out: Path) -> argparse.Namespace:
    """The main job's `mrguide train` arguments: the default config, `--stop-after` the main job's steps."""
    return _step_args(["train"], out=str(out), seed=args.seed, stop_after=args.train_steps, quiet=args.quiet)


def _deploy_step(args: argparse.Namespace, policy: Path, real_config: str, log: Path) -> argparse.Namespace:
    """The main job's `mrguide deploy --dry-run` arguments: the policy in the 'real' cell, its episodes, its log."""
    values = {"config": real_config, "episodes": args.deploy_episodes, "log": str(log), "quiet": args.quiet}
    return _step_args(["deploy", "--policy", str(policy), "--dry-run"], **values)


def _sim2real_step(args: argparse.Namespace, policy: Path, real_config: str, out: Path) -> argparse.Namespace:
    """The main job's `mrguide sim2real` arguments: the paper's conditions, its seeds and episodes."""
    values = {"real_config": real_config, "seeds": args.seeds, "episodes": args.episodes, "quiet": args.quiet}
    return _step_args(["sim2real", "--policy", str(policy), "--out", str(out)], **values)


def _cell_learner(*args: Any) -> Any:
    """`deploy --learn`'s learner (torch: imported only when asked for)."""
    from mrguide.policies.cell_learner import CellLearner

    return CellLearner(*args)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="mrguide", description=__doc__)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    sp = sub.add_parser("main", help="the Quick-start main job: train briefly -> dry-run deploy -> sim-to-real")
    sp.add_argument("--out", default="runs/main")
    sp.add_argument("--train-steps", type=positive_int, default=5000)
    sp.add_argument("--deploy-episodes", type=positive_int, default=3)
    sp.add_argument("--seeds", type=positive_int, default=2, help="sim-to-real seeds")
    sp.add_argument("--episodes", type=positive_int, default=5, help="sim-to-real episodes per seed and condition")
    sp.add_argument("--seed", type=nonnegative_int, default=0, help="training seed")
    sp.add_argument("--real-config", help="the 'real' cell (TOML); default: the shipped configs/cells/real_cell.toml")
    sp.add_argument("--quiet", action="store_true", help="no progress bars")
    sp.set_defaults(func=cmd_main)

    from mrguide.cell.commands import CellDryRun
    from mrguide.deploy.commands import add_deploy_command
    from mrguide.twin.commands import add_expert_command, run_twin_calibration

    add_expert_command(sub)
    from mrguide.annotation.commands import CellAnnotatePlugin

    add_deploy_command(sub, CellDryRun, _cell_learner, CellAnnotatePlugin())
    from mrguide.deploy.cycle_report import add_cycles_command

    add_cycles_command(sub)

    from mrguide.calibration.commands import add_calibrate_command
    from mrguide.experiments.commands import add_experiment_command
    from mrguide.policies.commands import add_config_command, add_train_command

    add_calibrate_command(sub, run_twin_calibration)
    from mrguide.deploy.camera_check import add_camera_command

    add_camera_command(sub)
    from mrguide.drivers.commands import add_bus_commands

    add_bus_commands(sub)
    from mrguide.experiments.sim2real_command import add_sim2real_command

    add_sim2real_command(sub)
    from mrguide.experiments.part_grasps import add_grasps_command

    add_grasps_command(sub)

    from mrguide.annotation.commands import LiveTrainPlugin, add_annotate_command

    add_train_command(sub, LiveTrainPlugin())
    add_config_command(sub)
    add_annotate_command(sub)
    add_experiment_command(sub)
    from mrguide.replay.commands import add_export_command, add_replay_command  # lazy: Rerun/pyarrow when run

    add_replay_command(sub)
    add_export_command(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one command (`run_command`)."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    return run_command(f"mrguide {getattr(args, 'command_name', args.command)}", args.func, args)


def run_command(name: str, func: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """`func(args)`, the command `name`. Bad input, or a package of the command's install profile missing: one line
    on stderr, exit 2; driver faults: exit 1; Ctrl-C: exit 130."""

    def fail(message: str, code: int) -> int:
        # one line, whatever the message quotes (a TOML key or a file name may hold a line break)
        print(f"{name}: " + message.replace("\r", "\\r").replace("\n", "\\n"), file=sys.stderr)
        return code

    try:
        return int(func(args))
    except InputError as exc:
        return fail(str(exc), 2)
    except ModuleNotFoundError as exc:  # e.g. `mrguide train` on a robot PC: which extra to install
        message = missing_profile_message(name, exc)
        if message is None:
            raise
        print(message, file=sys.stderr)
        return 2
    except DriverError as exc:
        return fail(f"CAN driver error: {exc}", 1)
    except OSError as exc:  # a full disk, a vanished directory: the environment, not the input
        return fail((f"{exc.filename}: " if exc.filename else "") + str(exc.strerror or exc), 1)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
