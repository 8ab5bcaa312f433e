"""Dry run: the real deploy stack over the virtual CAN bus to simulated drives whose plant is a twin.

The twin here plays the robot: it runs with its own (reality-gap) parameters, receives only CSP
setpoints and vacuum commands over CANopen, and answers with encoder positions and the vacuum signal.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mrguide.cell.cell_process import cell_process
from mrguide.cell.config import CellConfig
from mrguide.cell.plants import build_plant
from mrguide.cell.twin_plant import TwinObjectPose
from mrguide.config import ConfigError
from mrguide.deploy.cell_learning import LearningActor
from mrguide.deploy.cycles import CycleReport, CycleRun, CycleRunner, CycleSummary
from mrguide.deploy.episode import MAX_CELL_BACKLOG_S, EpisodeReport
from mrguide.deploy.policy import ExportedPolicy, check_decision_period
from mrguide.deploy.runlog import RunLog
from mrguide.deploy.runtime import Runtime
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.safety import SafetyConfig
from mrguide.deploy.session import DeploySummary, run_session
from mrguide.drivers.cobot import Cobot
from mrguide.drivers.config import CobotBusConfig
from mrguide.drivers.mock.sim_cobot import SimulatedCobot, shared_pc_config
from mrguide.drivers.realtime import settled_heap
from mrguide.plant import FedCell
from mrguide.pose_source import ObjectPoseSource
from mrguide.robot import RobotSpec, load_robot
from mrguide.task import TaskConfig, placed_at_goal
from mrguide.twin.env import EnvConfig
from mrguide.twin.scene import Scene

log = logging.getLogger(__name__)


@dataclass
class SimulatedCell:
    """A plant behind simulated devices, with the master-side `Cobot` connected and enabled. In one process
    (the virtual bus): `scene` is the PyBullet twin's scene when the engine is PyBullet, else None, and `sim` the
    devices. With the cell in a process of its own (`cell_process`), `plant` is its proxy, `scene` and `sim` None."""

    scene: Scene | None
    plant: FedCell
    sim: SimulatedCobot | None
    cobot: Cobot
    #: s: how far the simulated world ran behind the wall clock at most since the last call (`sync_backlog`)
    backlog: Callable[[], float]


@contextlib.contextmanager
def simulated_cell(
    env_cfg: CellConfig, bus_cfg: CobotBusConfig, seed: int = 0, own_process: bool = False
) -> Iterator[SimulatedCell]:
    """Start the cell's plant ([plant] engine) + simulated devices, connect and enable the cobot; tear everything
    down on exit. `own_process`: the plant and the devices in a process of their own (`cell_process`), so that
    their work does not run in the deploy stack's interpreter; else in this one, on the virtual bus."""
    if bus_cfg.bus.interface != "virtual":
        raise ConfigError(f"a dry run needs the virtual CAN interface, the bus config says {bus_cfg.bus.interface!r}")
    bus_cfg = shared_pc_config(bus_cfg)
    spec = load_robot(env_cfg.robot)
    if own_process:
        with (
            cell_process(env_cfg, bus_cfg, seed) as (proxy, master_cfg),
            settled_heap(),
            Cobot(master_cfg, spec) as cobot,
        ):
            cobot.enable()
            yield SimulatedCell(None, proxy, None, cobot, proxy.sync_backlog)
        return
    with settled_heap():
        plant, scene = build_plant(env_cfg, bus_cfg, spec, seed)
        sim = SimulatedCobot(bus_cfg, plant, seed=seed)
        sim.start()
        try:
            with Cobot(bus_cfg, spec) as cobot:
                cobot.enable()
                yield SimulatedCell(scene, plant, sim, cobot, sim.backlog.take)
        finally:
            sim.stop()
            if scene is not None:
                scene.close()


def episode_layouts(
    env_cfg: EnvConfig | CellConfig, episodes: int, seed: int | list[int]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(object, goal) per episode, drawn from the twin's object and goal regions (`seed`: numpy's seed entropy)."""
    rng = np.random.default_rng(seed)
    h = 0.5 * env_cfg.task.object_height
    out = []
    for _ in range(episodes):
        o = rng.uniform(env_cfg.twin.object_region.low, env_cfg.twin.object_region.high)
        g = rng.uniform(env_cfg.twin.goal_region.low, env_cfg.twin.goal_region.high)
        out.append((np.array([o[0], o[1], h]), np.array([g[0], g[1], h])))
    return out


def _checked_policy(
    policy_path: str | Path | None, policy, spec: RobotSpec, env_cfg: CellConfig, bus_cfg: CobotBusConfig
) -> Callable[[np.ndarray], np.ndarray]:
    """The policy to run: `policy` if given, else the file's; an exported one checked against the cell's timing."""
    if policy is None:
        if policy_path is None:
            raise ValueError("dry_run needs a policy file or a policy")
        policy = ExportedPolicy.load(policy_path, spec, env_cfg.task)
    if isinstance(policy, ExportedPolicy):
        label = policy_path if policy_path is not None else "the given policy"
        check_decision_period(policy, label, bus_cfg.timing.control_period, env_cfg.twin.decision_period)
    return policy


def dry_run(
    policy_path: str | Path | None,
    env_cfg: CellConfig,
    bus_cfg: CobotBusConfig,
    episodes: int,
    seed: int,
    run_log: RunLog,
    safety: SafetyConfig | None = None,
    pose_factory: Callable[[SimulatedCell], ObjectPoseSource] | None = None,
    after_episode: Callable[[EpisodeReport], None] | None = None,
    policy=None,
    on_placed: Callable[[], None] | None = None,
    max_recoveries: int = 0,
    runtime_cfg: RuntimeConfig | None = None,
    own_process: bool = False,
) -> DeploySummary:
    """Run `episodes` seeded episodes of a policy through the whole stack against the simulated cell.

    The policy file is loaded (unless `policy` is given) and checked before any drive is enabled. `policy`
    may also be any callable obs → action (the scripted expert in tests). `run_log` is the caller's open
    log (its header written; the caller closes it). `on_placed` runs after the object was put in place for
    an episode (e.g. to wait for a fresh HMD estimate). `max_recoveries` safety stops may be followed by a fault
    reset and the next episode (see `run_session`). `runtime_cfg` sets the runtime (its decision period is
    the twin's). The pose source `pose_factory` gives is closed, if it can be, before the cell is torn down.
    `own_process`: the cell in a process of its own (`simulated_cell`).
    """
    spec = load_robot(env_cfg.robot)
    policy = _checked_policy(policy_path, policy, spec, env_cfg, bus_cfg)
    layouts = episode_layouts(env_cfg, episodes, seed)
    with (
        simulated_cell(env_cfg, bus_cfg, seed, own_process) as cell,
        _cell_runtime(cell, env_cfg, spec, policy, run_log, pose_factory, safety, runtime_cfg) as runtime,
    ):

        def place(i: int) -> None:
            cell.plant.place_objects(*layouts[i])
            if on_placed:
                on_placed()
            cell.backlog()  # each episode's backlog from its start

        def judged(report: EpisodeReport) -> None:
            report.cell_backlog_s = _logged_backlog(cell, run_log, f"episode {report.index}", episode=report.index)
            if after_episode:
                after_episode(report)

        return run_session(
            runtime,
            [g for _, g in layouts],
            before_episode=place,
            after_episode=judged,
            max_recoveries=max_recoveries,
        )


@contextlib.contextmanager
def _cell_runtime(
    cell: SimulatedCell,
    env_cfg: CellConfig,
    spec: RobotSpec,
    policy: Callable[[np.ndarray], np.ndarray],
    run_log: RunLog,
    pose_factory: Callable[[SimulatedCell], ObjectPoseSource] | None,
    safety: SafetyConfig | None,
    runtime_cfg: RuntimeConfig | None,
) -> Iterator[Runtime]:
    """The deploy runtime on a simulated cell, its pose source closed (if it can be) before the cell is torn down."""
    pose = pose_factory(cell) if pose_factory else TwinObjectPose(cell.plant)
    # Without a [safety] config the simulated cell allows 0.1 rad of following error (robot: 0.05):
    # on a loaded PC the simulated arm can fall behind for lack of CPU, not of torque.
    runtime = Runtime(
        cell.cobot,
        policy,
        pose,
        spec,
        policy.with_grasp(env_cfg.task) if isinstance(policy, ExportedPolicy) else env_cfg.task,
        run_log,
        env_cfg.twin.decision_period,
        runtime_cfg,
        safety or SafetyConfig(following_error=0.1),
    )
    with contextlib.ExitStack() as stack:
        # the pose source stops before the cell does (a camera whose world closed mid-frame would report itself lost)
        if callable(close := getattr(pose, "close", None)):
            stack.callback(close)
        stack.enter_context(runtime)
        yield runtime


class TwinFeeder:
    """A dry run's part feeder: each cycle a new part at a seeded random pose in the twin's object region, and the
    cycle's goal from its goal region (as `episode_layouts` draws them; cycle `c` of seed `s` is always the same)."""

    tracks_part = True  # the dry run's pose sources (exact, camera, HMD) see the part wherever it lies

    def __init__(self, cell: SimulatedCell, env_cfg: CellConfig, seed: int, on_placed: Callable[[], None] | None):
        self.cell, self.env_cfg, self.seed, self.on_placed = cell, env_cfg, seed, on_placed

    def layout(self, cycle: int) -> tuple[np.ndarray, np.ndarray]:
        """(part, goal) of `cycle`."""
        return episode_layouts(self.env_cfg, 1, [self.seed, cycle])[0]

    def goal(self, cycle: int) -> np.ndarray:
        return self.layout(cycle)[1]

    def next_part(self, cycle: int) -> None:
        """The placed (or skipped) part leaves the cell; the next one lies in the pick region."""
        self.cell.plant.place_objects(*self.layout(cycle))
        if self.on_placed:
            self.on_placed()

    def clear_part(self, cycle: int) -> None:
        """Nothing to do: `next_part` takes the simulated part away as it feeds the next one."""


def dry_run_cycles(
    policy_path: str | Path | None,
    env_cfg: CellConfig,
    bus_cfg: CobotBusConfig,
    run: CycleRun,
    run_log: RunLog,
    safety: SafetyConfig | None = None,
    pose_factory: Callable[[SimulatedCell], ObjectPoseSource] | None = None,
    policy=None,
    on_placed: Callable[[], None] | None = None,
    runtime_cfg: RuntimeConfig | None = None,
    own_process: bool = False,
    learning: LearningActor | None = None,
) -> CycleSummary:
    """Production cycles `run.start` .. of a policy through the whole stack against the simulated cell, parts fed
    by a `TwinFeeder` of seed `run.seed` (the arguments otherwise as `dry_run`'s); with `learning`, the runtime is
    the actor of on-cell learning (`policy` the actor itself)."""
    spec = load_robot(env_cfg.robot)
    policy = _checked_policy(policy_path, policy, spec, env_cfg, bus_cfg)
    with (
        simulated_cell(env_cfg, bus_cfg, run.seed, own_process) as cell,
        _cell_runtime(cell, env_cfg, spec, policy, run_log, pose_factory, safety, runtime_cfg) as runtime,
    ):
        runtime.learning = learning
        feeder = TwinFeeder(cell, env_cfg, run.seed, on_placed)
        scored = _scored(run.after_cycle, cell, feeder, env_cfg.task, run_log)
        runner = CycleRunner(runtime, feeder, feeder.goal, run.config, scored)
        cell.backlog()  # each cycle's backlog from the first cycle's start (`_scored`)
        summary = runner.run(run.start, run.count, run.interrupt, run.first_attempt)
        if summary.stopped:  # the cycle the stop ended is not scored: its backlog, for whoever asks why it stopped
            _logged_backlog(cell, run_log, "the cycle the run stopped in", stopped=True)
        return summary


def _logged_backlog(cell: SimulatedCell, run_log: RunLog, what: str, **where: int | bool) -> float:
    """How far the simulated cell ran behind the clock since the last reading (s), written to the run log
    (`cell_backlog`, with `where`) and warned of, for `what`, beyond `MAX_CELL_BACKLOG_S`."""
    seconds = cell.backlog()
    run_log.write("cell_backlog", **where, seconds=round(seconds, 4))
    if seconds > MAX_CELL_BACKLOG_S:
        log.warning(
            "%s: the simulated cell ran %.2f s behind the clock (this PC was too busy to keep its time): not a "
            "measurement of the policy",
            what,
            seconds,
        )
    return seconds


#: m: a scored part lies on the table when its centre is this close to its resting height (not carried off by the cup).
REST_TOLERANCE = 0.01


def _scored(
    after_cycle: Callable[[CycleReport], None] | None,
    cell: SimulatedCell,
    feeder: TwinFeeder,
    task: TaskConfig,
    run_log: RunLog,
) -> Callable[[CycleReport], None]:
    """`after_cycle`, first writing the dry run's score of the cycle to the run log (`scored`): whether the part
    truly lies at its goal, resting on the table (within `REST_TOLERANCE` of its height there), read from the
    simulated cell's state — which nothing the runtime or a learner reads — and how far the simulated cell's world
    ran behind the wall clock during the cycle at most (`cell_backlog_s`: a cycle the cell played late is not one a
    cell on time would have played)."""

    def after(report: CycleReport) -> None:
        part = cell.plant.object_position()
        resting = abs(part[2] - 0.5 * task.object_height) <= REST_TOLERANCE
        at_goal = report.placed and resting and placed_at_goal(task, part, feeder.goal(report.cycle))
        backlog = round(cell.backlog(), 4)
        run_log.write("scored", cycle=report.cycle, at_goal=bool(at_goal), part=part, cell_backlog_s=backlog)
        if after_cycle:
            after_cycle(report)

    return after
