"""`mrguide replay` and `mrguide export lerobot`: the command-line wiring only. Everything they need is imported
when they run, so neither Rerun nor pyarrow is needed to build the `mrguide` parser (the robot-PC profile)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from mrguide.errors import InputError


def _run_spec(text: str) -> tuple[str, list[int] | None]:
    """RUN or RUN:EPISODES (comma-separated episode numbers)."""
    m = re.fullmatch(r"(.+?):(\d+(?:,\d+)*)", text)
    if m and not Path(text).exists():
        return m.group(1), [int(v) for v in m.group(2).split(",")]
    return text, None


def add_replay_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="turn run logs (deploy, dry run, sim2real, a training run recorded with --record) into a Rerun recording",
    )
    p.add_argument(
        "runs",
        nargs="+",
        metavar="RUN[:EPISODES]",
        help="a run log (.jsonl, .jsonl.gz) or a training run directory; :3,7 picks episodes 3 and 7",
    )
    p.add_argument("--save", metavar="FILE.rrd", help="write the recording to this file")
    p.add_argument("--spawn", action="store_true", help="open the Rerun viewer on the recording")
    p.add_argument("--outcome", action="append", help="only episodes that ended so (repeatable), e.g. dropped")
    p.add_argument("--limit", type=int, metavar="N", help="at most N episodes per run")
    p.add_argument("--no-arm", action="store_true", help="leave the arm meshes out (smaller files)")
    p.add_argument("--config", help="a run config whose [robot] names the arm (default: the shipped default arm)")
    p.set_defaults(func=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> int:
    from mrguide.replay.recording import write_recording
    from mrguide.replay.runs import RunError, load_run, select
    from mrguide.robot import load_robot, load_robot_config

    if not args.save and not args.spawn:
        raise InputError("say where the recording goes: --save FILE.rrd and/or --spawn")
    if args.limit is not None and args.limit < 1:
        raise InputError(f"--limit must be >= 1, got {args.limit}")
    spec = load_robot(load_robot_config(args.config))
    episodes = []
    for text in args.runs:
        path, indices = _run_spec(text)
        chosen = _with_decisions(path, select(load_run(path), indices, args.outcome), indices is not None)
        episodes += chosen[: args.limit] if args.limit else chosen
    if not episodes:
        raise RunError("no episode of the given runs matches the selection")
    dof = {len(f.q) for e in episodes for f in e.frames if f.q is not None}
    if dof - {spec.dof}:
        raise InputError(f"the runs' joints ({sorted(dof)}) are not those of {spec.name} ({spec.dof}); give --config")
    write_recording(episodes, spec, save=args.save, spawn=args.spawn, arms=not args.no_arm)
    frames = sum(len(e.frames) for e in episodes)
    print(f"{len(episodes)} episodes, {frames} decisions" + (f" -> {args.save}" if args.save else ""))
    return 0


def _with_decisions(path: str, chosen: list, named: bool) -> list:
    """The `chosen` episodes that hold decisions. A slim copy of a run log (the results keep those) has none for
    most successful episodes: asking for one by number is an error; otherwise they are left out, and said so."""
    from mrguide.replay.runs import RunError

    empty = [e.index for e in chosen if not e.frames]
    if empty and named:
        raise RunError(
            f"{path}: episode {', '.join(map(str, empty))} holds no decisions in this log (a slim copy keeps those of "
            "the failed episodes and of the first successful one)"
        )
    if empty:
        print(f"{path}: {len(empty)} episodes without decisions left out (a slim copy of the log)")
    return [e for e in chosen if e.frames]


def add_export_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a run's data in another format")
    kinds = p.add_subparsers(dest="format", required=True)
    lr = kinds.add_parser(
        "lerobot", help="a training run's demonstrations (or all recorded episodes) as a LeRobot dataset (v3.0)"
    )
    lr.add_argument("run", help="a training run directory recorded with `mrguide train --record`")
    lr.add_argument("--out", required=True, help="the dataset directory to create (must not exist or be empty)")
    lr.add_argument("--all-episodes", action="store_true", help="every recorded episode, not only the demonstrations")
    lr.add_argument("--task", default="pick the part and place it at the goal", help="the dataset's one task text")
    lr.set_defaults(func=cmd_export_lerobot, command_name="export lerobot")


def cmd_export_lerobot(args: argparse.Namespace) -> int:
    from mrguide.replay.lerobot import export_lerobot

    summary = export_lerobot(Path(args.run), Path(args.out), all_episodes=args.all_episodes, task=args.task)
    print(summary)
    return 0
