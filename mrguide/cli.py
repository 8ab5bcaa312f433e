"""The `mrguide` command."""

from __future__ import annotations

import argparse
import logging
import sys

from tqdm import tqdm

from mrguide.config import ConfigError


def cmd_expert(args: argparse.Namespace) -> int:
    """Run the scripted expert in the twin and report success rate and timing."""
    from mrguide.twin.env import EnvConfig, PickPlaceEnv
    from mrguide.twin.rollout import run_episodes

    env = PickPlaceEnv(EnvConfig.load(args.config))
    try:
        with tqdm(total=args.episodes, desc="scripted expert", unit="ep", disable=args.quiet) as bar:
            def tick(res):
                bar.update(1)
                bar.set_postfix(last=res.outcome)

            summary = run_episodes(env, lambda obs: env.expert_action(), range(args.seed, args.seed + args.episodes), tick)
    finally:
        env.close()
    sim_s = summary.decisions * env.twin_cfg.decision_period
    print(f"scripted expert: {summary.success_rate:.1%} success over {len(summary.episodes)} episodes "
          f"(seeds {args.seed}..{args.seed + args.episodes - 1}); outcomes {dict(summary.outcomes())}")
    print(f"timing: {summary.decisions} decisions in {summary.wall_s:.1f} s wall = "
          f"{summary.decisions / summary.wall_s:.0f} decisions/s, {sim_s / summary.wall_s:.1f}x real time")
    return 0


def cmd_main(args: argparse.Namespace) -> int:
    """The Quick-start main job."""
    return cmd_expert(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="mrguide", description=__doc__)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    for name, func, helptext in (
        ("main", cmd_main, "the Quick-start main job"),
        ("expert", cmd_expert, "run the scripted expert in the twin"),
    ):
        sp = sub.add_parser(name, help=helptext)
        sp.add_argument("--config", help="TOML config ([robot], [twin], [task])")
        sp.add_argument("--episodes", type=int, default=50)
        sp.add_argument("--seed", type=int, default=0)
        sp.add_argument("--quiet", action="store_true", help="no progress bar")
        sp.set_defaults(func=func)
    from mrguide.policies.commands import add_experiment_command, add_train_command

    add_train_command(sub)
    add_experiment_command(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"mrguide: config error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mrguide: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
