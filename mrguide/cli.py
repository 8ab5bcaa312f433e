"""The `mrguide` command."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from tqdm import tqdm

from mrguide.cli_args import ArgumentParser, nonnegative_int, positive_int
from mrguide.drivers.errors import DriverError
from mrguide.errors import InputError


#: Test seam: lets tests drive the real-robot path of `deploy` (--enable-drives) over a python-can virtual
#: channel with simulated devices on it. Users always get the refusal of the virtual interface; only a test
#: sets this.
ALLOW_VIRTUAL_REAL_BUS = False


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


def _bus_config(config_path: str | None, bus_config: str, robot):
    """The bus description named by [deploy] bus_config (relative to the config file), checked against `robot`."""
    from mrguide.drivers.config import load_cobot_bus_config

    if not bus_config:
        return load_cobot_bus_config(None, robot)
    base = Path(config_path).parent if config_path else Path.cwd()
    return load_cobot_bus_config(base / bus_config, robot)


def cmd_deploy(args: argparse.Namespace) -> int:
    """Run an exported policy on the cobot (real bus), or dry-run it against the simulated cell.

    Every input (configs, bus description, policy, run log location) is checked before anything is
    connected or enabled; the run log's header is on disk before the first frame is sent."""
    from mrguide.config import ConfigError, load_optional_section, load_section
    from mrguide.deploy.policy import ExportedPolicy, check_decision_period
    from mrguide.deploy.runlog import RunLog
    from mrguide.deploy.safety import SafetyConfig
    from mrguide.deploy.session import DeployConfig
    from mrguide.robot import load_robot, load_robot_config
    from mrguide.task import TaskConfig

    dcfg = load_section(DeployConfig, args.config, "deploy")
    safety = load_optional_section(SafetyConfig, args.config, "safety")
    episodes = args.episodes if args.episodes is not None else dcfg.episodes
    seed = args.seed if args.seed is not None else dcfg.seed
    spec = load_robot(load_robot_config(args.config))
    task = load_section(TaskConfig, args.config, "task")
    bus = _bus_config(args.config, dcfg.bus_config, spec)
    if args.dry_run and bus.bus.interface != "virtual":
        raise ConfigError(f"--dry-run needs the virtual CAN interface; the bus config names {bus.bus.interface!r}")
    policy = ExportedPolicy.load(args.policy, spec, task)
    if args.dry_run:
        from mrguide.twin.env import EnvConfig  # imports PyBullet: after the checks that need none

        env_cfg = EnvConfig.load(args.config)
        check_decision_period(policy, args.policy, bus.timing.control_period, env_cfg.twin.decision_period)
    else:
        check_decision_period(policy, args.policy, bus.timing.control_period)
        if bus.bus.interface == "virtual" and not ALLOW_VIRTUAL_REAL_BUS:
            raise ConfigError("the bus config names the virtual interface; use --dry-run, or configure the real bus")
        if not args.enable_drives:
            raise InputError(f"this will enable the drives on {bus.bus.interface}:{bus.bus.channel} and move the arm. "
                              "Clear the cell, keep the E-stop at hand, and re-run with --enable-drives to confirm.")
    log_path, where = _log_path(args, dcfg)
    header = {"command": "deploy", "dry_run": args.dry_run, "policy": str(args.policy), "config": args.config,
              "bus": f"{bus.bus.interface}:{bus.bus.channel}", "episodes": episodes, "seed": seed if args.dry_run else None,
              "decision_period": policy.decision_period, "pose_source": dcfg.pose_source,
              "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    camera = _camera(args, dcfg, task)
    try:
        with RunLog(log_path, header, where) as run_log, \
                tqdm(total=episodes, desc="deploy" + (" (dry run)" if args.dry_run else ""), unit="ep", disable=args.quiet) as bar:
            def tick(report) -> None:
                bar.update(1)
                bar.set_postfix(last=report.outcome, decisions=report.decisions)

            if args.dry_run:
                summary = _deploy_dry(args, policy, env_cfg, bus, episodes, seed, run_log, safety, dcfg, tick, camera)
            else:
                summary = _deploy_real(policy, bus, spec, task, dcfg, safety, episodes, run_log, tick, camera)
            camera_stats = _log_camera(camera, run_log)
    finally:
        if camera:
            camera.close()
    print(summary.text() + (f"\n{camera_stats.text()}" if camera_stats else ""))
    print(f"run log: {log_path}")
    return 0 if summary.stopped is None else 1


def _log_path(args: argparse.Namespace, dcfg) -> tuple[Path, str]:
    """The run log's path and how to name its origin in an error."""
    if args.log:
        return Path(args.log), "--log"
    return (Path(dcfg.log_dir) / f"deploy-{time.strftime('%Y%m%d-%H%M%S')}.jsonl",
            f"{args.config or 'default'} [deploy] log_dir:")


def _camera(args: argparse.Namespace, dcfg, task):
    """With `pose_source = "camera"`: the camera source (a dry run: the twin-rendered one), opened before the run
    log so that bad files or a camera that does not open are refused first; otherwise None."""
    if dcfg.pose_source != "camera":
        return None
    base = Path(args.config).parent if args.config else Path.cwd()
    if args.dry_run:
        from mrguide.twin.camera_feed import TwinCameraPoses

        return TwinCameraPoses(dcfg.camera, base, task.object_height)
    from mrguide.deploy.camera import open_camera_source

    return open_camera_source(dcfg.camera, base)


def _log_camera(camera, run_log):
    """The camera's statistics, also written to the run log (None without a camera)."""
    stats = camera.stats() if camera else None
    if stats:
        run_log.write("camera", **stats.as_dict())
    return stats


def _deploy_dry(args, policy, env_cfg, bus, episodes, seed, run_log, safety, dcfg, tick, camera):
    from mrguide.deploy.runtime import RuntimeConfig
    from mrguide.twin.dry_run import dry_run

    return dry_run(args.policy, env_cfg, bus, episodes, seed, run_log, safety, after_episode=tick, policy=policy,
                   runtime_cfg=RuntimeConfig(max_pose_misses=dcfg.max_pose_misses), pose_factory=camera,
                   on_placed=camera.refresh if camera else None)


def _deploy_real(policy, bus, spec, task, dcfg, safety, episodes, run_log, tick, camera):
    from mrguide.deploy.runtime import Runtime, RuntimeConfig
    from mrguide.deploy.session import FixedObjectPose, run_session
    from mrguide.drivers.cobot import Cobot
    from mrguide.drivers.realtime import freeze_heap

    rcfg = RuntimeConfig(decision_period=policy.decision_period, max_pose_misses=dcfg.max_pose_misses)
    goals = [dcfg.goals[i % len(dcfg.goals)] for i in range(episodes)]

    def place(i: int) -> None:
        if camera is None:
            input(f"episode {i}: place the object at {dcfg.object_position} and press Enter ")
            return
        input(f"episode {i}: place the object in view of the camera and press Enter ")
        camera.wait_for_pose(after=time.monotonic(), timeout=dcfg.camera.max_pose_age_s + 5.0)

    freeze_heap()
    with Cobot(bus, spec) as cobot:
        cobot.enable()
        pose = camera or FixedObjectPose(dcfg.object_position)
        with Runtime(cobot, policy, pose, spec, task, run_log, rcfg, safety) as rt:
            return run_session(rt, goals, before_episode=place, after_episode=tick)


def cmd_main(args: argparse.Namespace) -> int:
    """The Quick-start main job: train a guided policy briefly (or reuse it) → dry-run deploy → sim-to-real."""
    t0 = time.perf_counter()
    out = Path(args.out)
    policy = out / "train" / "policy.npz"
    if policy.exists():
        print(f"[1/3] using the policy trained before: {policy} (delete {out} to train again)")
    else:
        print(f"[1/3] training a guided DDPG policy in the twin (simulated MR annotator): the first {args.train_steps} "
              "steps of the 20k-step schedule")
        rc = main(["train", "--stop-after", str(args.train_steps), "--seed", str(args.seed), "--out", str(out / "train")]
                  + (["--quiet"] if args.quiet else []))
        if rc:
            return rc
    print("\n[2/3] dry run: deploying it over the virtual CAN bus to simulated drives on a twin with reality gap")
    rc = main(["deploy", "--policy", str(policy), "--config", args.real_config, "--dry-run", "--episodes", str(args.deploy_episodes),
               "--log", str(out / "deploy.jsonl")] + (["--quiet"] if args.quiet else []))
    print(f"\n[3/3] sim-to-real evaluation: {args.seeds} seeds x {args.episodes} episodes per condition")
    rc2 = main(["sim2real", "--policy", str(policy), "--real-config", args.real_config, "--seeds", str(args.seeds),
                "--episodes", str(args.episodes), "--out", str(out / "sim2real")] + (["--quiet"] if args.quiet else []))
    print(f"main job finished in {time.perf_counter() - t0:.0f} s")
    return rc or rc2


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
    sp.add_argument("--real-config", default=str(Path(__file__).resolve().parents[1] / "configs" / "real_cell.toml"))
    sp.add_argument("--quiet", action="store_true", help="no progress bars")
    sp.set_defaults(func=cmd_main)

    sp = sub.add_parser("expert", help="run the scripted expert in the twin")
    sp.add_argument("--config", help="TOML config ([robot], [twin], [task])")
    sp.add_argument("--episodes", type=positive_int, default=50)
    sp.add_argument("--seed", type=nonnegative_int, default=0, help="first seed; episode i uses seed + i")
    sp.add_argument("--quiet", action="store_true", help="no progress bar")
    sp.set_defaults(func=cmd_expert)
    sp = sub.add_parser("deploy", help="run an exported policy on the cobot, or --dry-run it against the simulated bus")
    sp.add_argument("--policy", required=True, help="exported policy file (.npz) from `mrguide train`")
    sp.add_argument("--config", help="TOML config ([deploy], [safety], [robot], [task]; [twin] for dry runs)")
    sp.add_argument("--dry-run", action="store_true", help="virtual CAN bus + simulated drives on a twin with reality gap")
    sp.add_argument("--enable-drives", action="store_true", help="confirm enabling the real drives (real bus only)")
    sp.add_argument("--episodes", type=positive_int, help="default: [deploy] episodes")
    sp.add_argument("--seed", type=nonnegative_int, help="dry run: object/goal layouts; default: [deploy] seed")
    sp.add_argument("--log", help="run log path (JSONL); default under [deploy] log_dir")
    sp.add_argument("--quiet", action="store_true")
    sp.set_defaults(func=cmd_deploy)

    from mrguide.calibration.commands import add_calibrate_command
    from mrguide.experiments.commands import add_experiment_command
    from mrguide.policies.commands import add_train_command

    add_calibrate_command(sub)
    from mrguide.deploy.camera_check import add_camera_command

    add_camera_command(sub)
    from mrguide.drivers.commands import add_bus_commands

    add_bus_commands(sub)
    from mrguide.experiments.commands import add_sim2real_command

    add_sim2real_command(sub)

    from mrguide.annotation.commands import LiveTrainPlugin, add_annotate_command

    add_train_command(sub, LiveTrainPlugin())
    add_annotate_command(sub)
    add_experiment_command(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input: one line on stderr, exit 2; driver faults: exit 1; Ctrl-C: exit 130."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    name = f"mrguide {getattr(args, 'command_name', args.command)}"

    def fail(message: str, code: int) -> int:
        # one line, whatever the message quotes (a TOML key or a file name may hold a line break)
        print(f"{name}: " + message.replace("\r", "\\r").replace("\n", "\\n"), file=sys.stderr)
        return code

    try:
        return int(args.func(args))
    except InputError as exc:
        return fail(str(exc), 2)
    except DriverError as exc:
        return fail(f"CAN driver error: {exc}", 1)
    except OSError as exc:  # a full disk, a vanished directory: the environment, not the input
        return fail((f"{exc.filename}: " if exc.filename else "") + str(exc.strerror or exc), 1)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
