"""`mrguide deploy`: an exported policy on the cobot over the real bus, or (`--dry-run`) over the virtual bus
to simulated drives on a simulated cell. The dry run itself belongs to the cell harness (`mrguide.cell`), which hands
it in as a `DryRunBackend` (deploy does not import the cell)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from tqdm import tqdm

from mrguide.cli_args import add_set_argument, nonnegative_int, positive_int
from mrguide.config import ConfigFile
from mrguide.deploy.deploy_inputs import DeployInputs
from mrguide.errors import InputError

if TYPE_CHECKING:
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.deploy.session import DeployConfig
    from mrguide.drivers.config import CobotBusConfig

#: Test seam: lets tests drive the real-robot path of `deploy` (--enable-drives) over a python-can virtual
#: channel with simulated devices on it. Users always get the refusal of the virtual interface; only a test
#: sets this.
ALLOW_VIRTUAL_REAL_BUS = False


class DryRunBackend(Protocol):
    """What `deploy --dry-run` needs from the twin: its decision period, twin-rendered camera or HMD poses, the run."""

    decision_period: float

    def camera(self, camera_cfg: Any, base: Path, object_height: float) -> Any: ...

    def hmd(self, seed: int) -> Any: ...

    def run_cycles(self, inputs: DeployInputs, run: Any) -> Any: ...

    def run(
        self,
        policy_path: str,
        policy: Any,
        bus: Any,
        episodes: int,
        seed: int,
        run_log: Any,
        safety: Any,
        runtime: Any,
        tick: Any,
        camera: Any,
    ) -> Any: ...


class CellLearning(Protocol):
    """What `deploy --learn` needs from on-cell learning's learner side: the runtime's actor, its state, an end."""

    actor: Any  # cell_learning.LearningActor

    def status(self) -> dict[str, Any]: ...

    def close(self) -> None: ...


class AnnotationPlugin(Protocol):
    """The annotation page beside a learning cell (`--annotate`): its options, and the session they open."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def open(self, args: argparse.Namespace, learner: CellLearning | None, seed: int) -> Any:
        """The `interventions.Interventions` of the page (with `url` and `close()`), or None if not asked for."""
        ...


def add_deploy_command(
    sub: argparse._SubParsersAction,
    dry_run_factory: Callable[[ConfigFile], DryRunBackend],
    learning_factory: Callable[..., CellLearning],
    annotation: AnnotationPlugin,
) -> None:
    """Register `mrguide deploy`; `dry_run_factory(config_file)` builds the simulated cell's DryRunBackend,
    `learning_factory(run_dir, policy, robot, task, learning, seed, resume)` the learner of `--learn`, `annotation`
    the page through which a person steps in while it learns."""
    sp = sub.add_parser("deploy", help="run an exported policy on the cobot, or --dry-run it against the simulated bus")
    sp.add_argument("--policy", required=True, help="exported policy file (.npz) from `mrguide train`")
    sp.add_argument("--config", help="TOML config ([deploy], [safety], [robot], [task]; [twin] for dry runs)")
    sp.add_argument(
        "--dry-run", action="store_true", help="virtual CAN bus + simulated drives on a twin with reality gap"
    )
    sp.add_argument("--enable-drives", action="store_true", help="confirm enabling the real drives (real bus only)")
    sp.add_argument("--episodes", type=positive_int, help="default: [deploy] episodes")
    sp.add_argument(
        "--cycles",
        type=positive_int,
        help="production: this many parts, one after another, lost ones picked again (with --resume: in all, "
        "the log's cycles counted)",
    )
    sp.add_argument(
        "--resume", action="store_true", help="with --cycles and --log: go on from that run log's count up to --cycles"
    )
    sp.add_argument("--seed", type=nonnegative_int, help="dry run: object/goal layouts; default: [deploy] seed")
    sp.add_argument("--log", help="run log path (JSONL); default under [deploy] log_dir")
    sp.add_argument(
        "--learn",
        metavar="RUN_DIR",
        help="with --cycles: learn on the cell, the learner of the training run in RUN_DIR (its checkpoint) beside "
        "the runtime; versions, learner.csv and its state in RUN_DIR/on-cell (--resume goes on from it)",
    )
    add_set_argument(
        sp,
        "set a [deploy] or [safety] key for this run, after --config (e.g. --set deploy.cycles.max_retries=1 "
        "--set safety.stall_timeout=0.3); repeatable",
    )
    annotation.add_arguments(sp)
    sp.add_argument("--quiet", action="store_true")
    sp.set_defaults(
        func=cmd_deploy, dry_run_factory=dry_run_factory, learning_factory=learning_factory, annotation=annotation
    )


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
    from mrguide.config import ConfigError
    from mrguide.deploy.policy import ExportedPolicy, check_decision_period
    from mrguide.deploy.runlog import RunLog
    from mrguide.deploy.safety import SafetyConfig
    from mrguide.deploy.session import DeployConfig
    from mrguide.robot import load_robot, robot_config
    from mrguide.task import TaskConfig

    file = ConfigFile.read(args.config)  # every section of the run from one parse
    dcfg, safety = _overridden(file.section(DeployConfig, "deploy"), file.optional(SafetyConfig, "safety"), args.set)
    episodes = args.episodes if args.episodes is not None else dcfg.episodes
    seed = args.seed if args.seed is not None else dcfg.seed
    spec = load_robot(robot_config(file))
    task = file.section(TaskConfig, "task")
    bus = _bus_config(args.config, dcfg.bus_config, spec)
    if args.dry_run and bus.bus.interface != "virtual":
        raise ConfigError(f"--dry-run needs the virtual CAN interface; the bus config names {bus.bus.interface!r}")
    policy = ExportedPolicy.load(args.policy, spec, task)
    task = policy.with_grasp(task)
    if args.dry_run:
        dry: DryRunBackend = args.dry_run_factory(file)
        check_decision_period(policy, args.policy, bus.timing.control_period, dry.decision_period)
    else:
        _check_real_bus(args, policy, bus)
    log_path, where = _log_path(args, dcfg)
    start = _first_cycle(args, log_path)
    header = _run_header(args, dcfg, bus, policy, episodes, seed) | {"cycles": args.cycles, "first_cycle": start[0]}
    learner = _cell_learner(args, dcfg, policy, spec, task, seed)
    camera = page = None
    try:
        page = _annotation_page(args, learner, seed)
        camera = _pose_feed(args, dcfg, task, seed, dry if args.dry_run else None)
        with RunLog(log_path, header, where) as run_log:
            actor = learner.actor if learner else None
            inputs = DeployInputs(args.policy, policy, bus, spec, task, safety, dcfg, camera, run_log, actor)
            summary = _run(args, inputs, dry if args.dry_run else None, episodes, seed, start)
            camera_stats = _log_pose_feed(camera, run_log, dcfg.pose_source)
            if learner:
                run_log.write("learning", **learner.status())
    finally:
        for opened in (camera, page, learner):
            if opened:
                opened.close()
    print(summary.text() + (f"\n{camera_stats.text()}" if camera_stats else ""))
    if learner:
        print(f"on-cell learning: {learner.status()}")
    print(f"run log: {log_path}")
    return 0 if summary.stopped is None else 1


#: The sections `deploy --set` sets.
SET_SECTIONS = ("deploy", "safety")


def _overridden(dcfg: DeployConfig, safety: Any, overrides: list[tuple[str, Any]]) -> tuple[DeployConfig, Any]:
    """[deploy] and [safety] with each `--set` override applied, checked as a value in the file would be."""
    from mrguide.config import ConfigError, replace_path
    from mrguide.deploy.safety import SafetyConfig

    for key, value in overrides:
        section, _, path = key.partition(".")
        if section == "deploy":
            dcfg = replace_path(dcfg, path, value, f"--set {key}")
        elif section == "safety":
            safety = replace_path(safety or SafetyConfig(), path, value, f"--set {key}")
        else:
            raise ConfigError(f"--set {key}: deploy sets keys of {' and '.join(SET_SECTIONS)}, not [{section}]")
    return dcfg, safety


def _cell_learner(args: argparse.Namespace, dcfg, policy, spec, task, seed: int) -> CellLearning | None:
    """With --learn: the training run's learner, started beside the runtime (InputError without --cycles)."""
    if not args.learn:
        return None
    if args.cycles is None:
        raise InputError("--learn needs --cycles: the cell learns over production cycles")
    return args.learning_factory(Path(args.learn), policy, spec, task, dcfg.learning, seed, args.resume)


def _annotation_page(args: argparse.Namespace, learner: CellLearning | None, seed: int) -> Any:
    """With --annotate: the page through which a person steps in, its URL printed, the learner's actor taking its
    interventions; otherwise None."""
    page = args.annotation.open(args, learner, seed)
    if page is not None and learner is not None:
        learner.actor.interventions = page
        print(f"annotation page: {page.url}", flush=True)
    return page


def _first_cycle(args: argparse.Namespace, log_path: Path) -> tuple[int, int]:
    """The first cycle to run and its first attempt's episode index: (0, 0), or with --resume where the run log
    being continued left off; InputError if that log already holds the --cycles asked for."""
    from mrguide.deploy.cycle_commands import cycles_done

    if args.cycles is not None and args.episodes is not None:
        raise InputError("--cycles and --episodes: a run is either production cycles or episodes, not both")
    if not args.resume:
        return 0, 0
    if args.cycles is None or not args.log:
        raise InputError("--resume needs --cycles and --log (the run log whose count it goes on from)")
    start = cycles_done(log_path)
    if start[0] >= args.cycles:
        raise InputError(
            f"--resume {log_path}: the log already holds {start[0]} cycles, --cycles {args.cycles} asks for "
            f"{args.cycles} in all; ask for more to go on"
        )
    return start


def _run(
    args: argparse.Namespace,
    inputs: DeployInputs,
    dry: DryRunBackend | None,
    episodes: int,
    seed: int,
    start: tuple[int, int],
):
    """The episodes, or with --cycles the production cycles, with a progress bar; their summary."""
    from mrguide.deploy.cycle_commands import cycle_run, run_cycles

    desc = "deploy" + (" (dry run)" if dry else "")
    total, unit = (args.cycles, "part") if args.cycles else (episodes, "ep")
    first = start[0] if args.cycles else 0  # a resumed run's bar counts the log's cycles
    with tqdm(total=total, initial=first, desc=desc, unit=unit, disable=args.quiet) as bar:
        if args.cycles:
            return run_cycles(cycle_run(args, inputs.dcfg, seed, start, bar, inputs.learning), dry, inputs)

        def tick(report) -> None:
            bar.update(1)
            bar.set_postfix(last=report.outcome, decisions=report.decisions)

        i = inputs
        if dry is not None:
            return dry.run(
                args.policy, i.policy, i.bus, episodes, seed, i.run_log, i.safety, i.dcfg.runtime, tick, i.camera
            )
        return _deploy_real(i.policy, i.bus, i.spec, i.task, i.dcfg, i.safety, episodes, i.run_log, tick, i.camera)


def _check_real_bus(args: argparse.Namespace, policy: ExportedPolicy, bus: CobotBusConfig) -> None:
    """ConfigError or InputError unless the real bus may be driven: the policy's timing, a real interface, and
    --enable-drives given."""
    from mrguide.config import ConfigError
    from mrguide.deploy.policy import check_decision_period

    check_decision_period(policy, args.policy, bus.timing.control_period)
    if bus.bus.interface == "virtual" and not ALLOW_VIRTUAL_REAL_BUS:
        raise ConfigError("the bus config names the virtual interface; use --dry-run, or configure the real bus")
    if not args.enable_drives:
        raise InputError(
            f"this will enable the drives on {bus.bus.interface}:{bus.bus.channel} and move the arm. "
            "Clear the cell, keep the E-stop at hand, and re-run with --enable-drives to confirm."
        )


def _run_header(
    args: argparse.Namespace, dcfg: DeployConfig, bus: CobotBusConfig, policy: ExportedPolicy, episodes: int, seed: int
) -> dict[str, Any]:
    """The run log's header: the command line's inputs, the bus, the policy's timing, the start time."""
    return {
        "command": "deploy",
        "dry_run": args.dry_run,
        "policy": str(args.policy),
        "config": args.config,
        "bus": f"{bus.bus.interface}:{bus.bus.channel}",
        "episodes": None if args.cycles else episodes,
        "seed": seed if args.dry_run else None,
        "decision_period": policy.decision_period,
        "pose_source": dcfg.pose_source,
        "set": dict(args.set),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def _log_path(args: argparse.Namespace, dcfg) -> tuple[Path, str]:
    """The run log's path and how to name its origin in an error."""
    if args.log:
        return Path(args.log), "--log"
    return (
        Path(dcfg.log_dir) / f"deploy-{time.strftime('%Y%m%d-%H%M%S')}.jsonl",
        f"{args.config or 'default'} [deploy] log_dir:",
    )


def _pose_feed(args: argparse.Namespace, dcfg, task, seed: int, dry: DryRunBackend | None):
    """With `pose_source = "camera"`: the camera source (a dry run: the twin-rendered one); "hmd": the dry run's
    simulated headset, calibrated, its errors drawn from `seed`. Opened before the run log so that bad files or a
    camera that does not open are refused first; otherwise None."""
    if dcfg.pose_source == "hmd":
        from mrguide.config import ConfigError

        if dry is None:
            raise ConfigError('deploy.pose_source = "hmd" runs only with --dry-run (the cell\'s simulated headset)')
        return dry.hmd(seed)
    if dcfg.pose_source != "camera":
        return None
    base = Path(args.config).parent if args.config else Path.cwd()
    if dry is not None:
        return dry.camera(dcfg.camera, base, task.object_height)
    from mrguide.deploy.camera import open_camera_source

    return open_camera_source(dcfg.camera, base)


def _log_pose_feed(feed, run_log, kind: str):
    """The camera's or the headset's statistics, also written to the run log as `kind` (None without either)."""
    stats = feed.stats() if feed else None
    if stats:
        run_log.write(kind, **stats.as_dict())
    return stats


def _deploy_real(policy, bus, spec, task, dcfg, safety, episodes, run_log, tick, camera):
    from mrguide.deploy.runtime import Runtime
    from mrguide.deploy.session import FixedObjectPose, run_session
    from mrguide.drivers.cobot import Cobot
    from mrguide.drivers.realtime import settled_heap

    goals = [dcfg.goals[i % len(dcfg.goals)] for i in range(episodes)]

    def place(i: int) -> None:
        if camera is None:
            input(f"episode {i}: place the object at {dcfg.object_position} and press Enter ")
            return
        input(f"episode {i}: place the object in view of the camera and press Enter ")
        camera.wait_for_pose(after=time.monotonic(), timeout=dcfg.camera.max_pose_age_s + 5.0)

    with settled_heap(), Cobot(bus, spec) as cobot:
        cobot.enable()
        pose = camera or FixedObjectPose(dcfg.object_position)
        with Runtime(cobot, policy, pose, spec, task, run_log, policy.decision_period, dcfg.runtime, safety) as rt:
            return run_session(rt, goals, before_episode=place, after_episode=tick)
