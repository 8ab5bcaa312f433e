"""Sim-to-real evaluation (`mrguide sim2real`, `mrguide experiment sim2real`): the paper's three sim-to-real conditions (Fig. 8) for one exported policy.

1. sim: the training twin with ground-truth object poses, the policy stepped directly (ideal execution);
2. real_exact: the full deploy stack over the virtual CAN bus to simulated drives whose plant is a
   second twin with reality-gap parameters; object pose from the environment model;
3. real_hmd: as 2, with the object pose from the HMD pipeline (twin-rendered HMD images → ArUco →
   registration), with configurable tracking noise and calibration error.
Every episode is judged on the ground truth of the twin that played the robot.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import SimulatedCell, dry_run, episode_layouts
from mrguide.cell.hmd_feed import HmdFeed
from mrguide.cell.hmd_stream import HmdPoseStream, HmdStartError
from mrguide.cell.twin_plant import TwinObjectPose
from mrguide.config import to_dict
from mrguide.deploy.episode import MAX_CELL_BACKLOG_S, EpisodeReport
from mrguide.deploy.policy import ExportedPolicy, check_arm, check_decision_period
from mrguide.deploy.runlog import RunLog
from mrguide.deploy.safety import SafetyConfig
from mrguide.deploy.session import DeploySummary
from mrguide.drivers.config import CobotBusConfig
from mrguide.drivers.errors import DriverError
from mrguide.experiments.stats import wilson
from mrguide.robot import load_robot
from mrguide.task import Outcome, TaskConfig, placed_at_goal
from mrguide.twin.env import EnvConfig, PickPlaceEnv

log = logging.getLogger(__name__)

#: The conditions a simulated cell plays: which cell ("real": PyBullet with the reality gap, "mujoco": the cell on
#: the second engine) and whether the object poses come from the HMD.
CELL_CONDITIONS = {
    "real_exact": ("real", False),
    "real_hmd": ("real", True),
    "mujoco_exact": ("mujoco", False),
    "mujoco_hmd": ("mujoco", True),
}
#: Failure causes as reported: the task model's failures, and "safety_stop" for every episode the deploy
#: runtime's supervisor ended (safety stops, aborted episodes, a lost object pose).
CAUSES = tuple(o.value for o in Outcome if o.from_task and o is not Outcome.SUCCESS) + (Outcome.SAFETY_STOP.value,)
#: An episode during which the simulated cell's world ran more than `MAX_CELL_BACKLOG_S` behind the wall clock
#: (`mrguide.drivers.mock.sync_backlog`): the arm the runtime read stood where it had been, as no cell's arm does. It
#: is not the policy's outcome: counted apart and left out of the success rates, as are the episodes of the draw
#: left unplayed after it stopped the run.
CELL_BEHIND = "cell_behind"


@dataclass(frozen=True)
class RealCell:
    """The 'real' cell of conditions 2 and 3, all from one TOML: twin with its reality gap, bus, safety, HMD."""

    path: Path
    env: CellConfig
    bus: CobotBusConfig
    safety: SafetyConfig | None
    hmd: Any


def load_real_cell(path: str | Path) -> RealCell:
    """[twin.reality_gap], [deploy] bus_config, [safety], [calibration.hmd] and [calibration_twin] of `path`, checked."""
    from mrguide.calibration.config import CalibrationConfig
    from mrguide.config import ConfigFile
    from mrguide.deploy.session import DeployConfig
    from mrguide.drivers.config import load_cobot_bus_config
    from mrguide.twin.markers import TwinCalibrationConfig

    path = Path(path)
    file = ConfigFile.read(path)  # every section of the cell from one parse
    env = CellConfig.from_file(file)
    dcfg = file.section(DeployConfig, "deploy")
    bus = load_cobot_bus_config(path.parent / dcfg.bus_config if dcfg.bus_config else None, load_robot(env.robot))
    safety = file.optional(SafetyConfig, "safety")
    hmd = file.section(CalibrationConfig, "calibration").hmd
    file.section(TwinCalibrationConfig, "calibration_twin")
    return RealCell(path, env, bus, safety, hmd)


def load_policy(policy_path: str | Path, train_cfg: EnvConfig, cell: RealCell) -> ExportedPolicy:
    """The exported policy, checked against the training twin and the 'real' cell (arm, workspace, task, timing)."""
    policy = ExportedPolicy.load(policy_path, load_robot(train_cfg.robot), train_cfg.task)
    check_arm(
        policy_path, policy.metadata, load_robot(cell.env.robot)
    )  # the "real" cell's arm must be the training arm
    check_decision_period(policy, policy_path, train_cfg.twin.control_period, train_cfg.twin.decision_period)
    check_decision_period(policy, policy_path, cell.bus.timing.control_period, cell.env.twin.decision_period)
    return policy


@dataclass
class ConditionResult:
    condition: str
    outcomes: dict[int, list[str]]  # seed -> outcome per episode

    def rates(self) -> np.ndarray:
        """Per seed, the share of its judged episodes placed (an episode the cell's lag voided is not judged)."""
        judged = ([o for o in v if o != CELL_BEHIND] for v in self.outcomes.values())
        return np.array([np.mean([o == "success" for o in v]) for v in judged if v])

    def summary(self) -> dict:
        """Pooled success rate with its 95 % Wilson interval, the spread over seeds (the least and the median seed's
        rate), failures by cause; episodes voided by the cell's lag (`CELL_BEHIND`) are counted, not judged."""
        pooled = Counter(o for v in self.outcomes.values() for o in v)
        total = sum(pooled.values()) - pooled.get(CELL_BEHIND, 0)
        lo, hi = wilson(pooled.get("success", 0), total)
        rates = self.rates()
        return {
            "condition": self.condition,
            "seeds": len(self.outcomes),
            "episodes": total,  # judged: those the cell's lag voided are counted under CELL_BEHIND
            "success_rate": pooled.get("success", 0) / max(total, 1),
            "ci95_low": lo,
            "ci95_high": hi,
            "seed_std": float(rates.std(ddof=1)) if len(rates) > 1 else 0.0,
            "seed_min": float(rates.min()) if len(rates) else 0.0,  # a seed is a calibration draw of the played cell
            "seed_median": float(np.median(rates)) if len(rates) else 0.0,
            **{c: pooled.get(c, 0) for c in (*CAUSES, CELL_BEHIND)},
        }


def _cause(outcome: Outcome) -> str:
    """What the report counts: the task model's outcome, or a safety stop for an episode the supervisor ended."""
    return outcome.value if outcome.from_task else Outcome.SAFETY_STOP.value


def run_sim(policy: ExportedPolicy, env_cfg: EnvConfig, seed: int, episodes: int) -> list[str]:
    """Condition 1 in the (ideal) training twin, same layouts as the other conditions."""
    env = PickPlaceEnv(env_cfg)
    out = []
    try:
        for i, (obj, goal) in enumerate(episode_layouts(env_cfg, episodes, seed)):
            obs, _ = env.reset(seed=seed * 10_000 + i, options={"object": obj, "goal": goal})
            while True:
                obs, _, term, trunc, info = env.step(policy(obs))
                if term or trunc:
                    break
            out.append(info["outcome"])
    finally:
        env.close()
    return out


def run_real(
    policy_path: Path,
    real_cfg: CellConfig,
    bus_cfg: CobotBusConfig,
    seed: int,
    episodes: int,
    log_path: Path,
    hmd_config: Path | None,
    safety: SafetyConfig | None,
    on_episode: Callable[[str], None] | None = None,
    use_hmd: bool = False,
    hmd_overrides: dict | None = None,
    policy=None,
    condition: str | None = None,
) -> list[str]:
    """Conditions 2 and 3 (`use_hmd`): a dry run whose outcomes are re-judged on the twin's ground truth.

    `hmd_config` is the TOML with `[calibration]` (and its `[calibration.hmd]` noise) for the HMD; `policy`
    (any obs → action callable) replaces the policy file, as in `dry_run`. A safety stop fails its
    episode; the drives are fault-reset and the next episode runs (as an operator would after acknowledging)."""
    condition = condition or ("real_hmd" if use_hmd else "real_exact")
    header = _run_header(policy_path, real_cfg, seed, episodes, condition, hmd_overrides)
    try:
        streams = _hmd_streams(real_cfg, hmd_config, seed, use_hmd, hmd_overrides)
    except HmdStartError as exc:  # e.g. too much tracking noise to calibrate: no episode can run, none is lost
        with RunLog(log_path, header) as run_log:
            return _unplayed(run_log, seed, episodes, f"the HMD could not start: {exc}", on_episode)
    hooks = _SeedHooks(real_cfg.task, [g for _, g in episode_layouts(real_cfg, episodes, seed)], streams, on_episode)
    try:
        with RunLog(log_path, header) as run_log:
            try:
                summary = dry_run(
                    policy_path,
                    real_cfg,
                    bus_cfg,
                    episodes,
                    seed,
                    run_log,
                    safety,
                    pose_factory=hooks.pose_factory,
                    after_episode=hooks.judge,
                    on_placed=hooks.refresh,
                    policy=policy,
                    max_recoveries=episodes,
                    # the cell in a process of its own, as `mrguide deploy --dry-run` runs it: in the runtime's, its
                    # physics waited for the GIL behind the decisions and ran up to a second behind the clock
                    own_process=True,
                )
            except DriverError as exc:  # the cell did not start (drives not enabled in time on a starved PC)
                if hooks.outcomes:
                    raise
                return _unplayed(run_log, seed, episodes, f"the simulated cell did not start: {exc}", on_episode)
    finally:
        for s in streams:
            s.close()
    return hooks.finish(summary, seed, episodes)


def _run_header(
    policy_path: Path, real_cfg: CellConfig, seed: int, episodes: int, condition: str, hmd_overrides: dict | None
) -> dict[str, Any]:
    """The run log's header for one seed of conditions 2 and 3 in the 'real' cell `real_cfg`."""
    return {
        "command": "sim2real",
        "condition": condition,
        "policy": str(policy_path),
        "seed": seed,
        "episodes": episodes,
        "hmd_overrides": hmd_overrides or {},
        "reality_gap": to_dict(real_cfg.twin.reality_gap),
        "plant": to_dict(real_cfg.plant),
    }


def _hmd_streams(
    real_cfg: CellConfig, hmd_config: Path | None, seed: int, use_hmd: bool, hmd_overrides: dict | None
) -> list[HmdPoseStream]:
    """With `use_hmd`, the HMD's pose stream, calibrated; otherwise none. HmdStartError if the HMD cannot start.
    The HMD draws the cell with the cell's engine: PyBullet, or MuJoCo's offscreen renderer for the MuJoCo cell."""
    # the HMD process calibrates (seconds of rendering) before the simulated cell's control loop starts
    if not use_hmd:
        return []
    return [HmdFeed(real_cfg, hmd_config, seed, hmd_overrides).stream]


@dataclass
class _SeedHooks:
    """The dry run's hooks for one seed of conditions 2 and 3; `outcomes` gathers the episodes' outcomes as judged."""

    task: TaskConfig
    goals: list[np.ndarray]
    streams: list[HmdPoseStream]  # condition 3: the HMD's pose stream; condition 2: none
    on_episode: Callable[[str], None] | None
    cells: list[SimulatedCell] = field(default_factory=list)
    outcomes: list[str] = field(default_factory=list)

    def pose_factory(self, cell: SimulatedCell) -> HmdPoseStream | TwinObjectPose:
        """The object pose source in `cell`: the HMD's stream attached to it, or the twin's ground truth."""
        self.cells.append(cell)
        return self.streams[0].attach(cell.plant) if self.streams else TwinObjectPose(cell.plant)

    def refresh(self) -> None:
        """A person moved the object: wait until the HMD has seen it again."""
        for s in self.streams:
            s.invalidate()
            s.wait_fresh()

    def judge(self, report: EpisodeReport) -> None:
        """Record the episode's outcome, judged on the ground truth of the twin that played the robot."""
        outcome = _cause(report.outcome)
        if report.cell_backlog_s > MAX_CELL_BACKLOG_S:
            log.warning(
                "episode %d: the simulated cell ran %.2f s behind: not judged", report.index, report.cell_backlog_s
            )
            outcome = CELL_BEHIND
        elif outcome in (Outcome.SUCCESS, Outcome.MISPLACED):
            # released at the goal pose: the task model's placement rule decides, on the ground truth of the
            # twin that played the robot (the runtime judged on its pose source or the tracked TCP)
            placed = placed_at_goal(self.task, self.cells[0].plant.object_position(), self.goals[report.index])
            outcome = (Outcome.SUCCESS if placed else Outcome.MISPLACED).value
        self.outcomes.append(outcome)
        if self.on_episode:
            self.on_episode(outcome)

    def finish(self, summary: DeploySummary, seed: int, episodes: int) -> list[str]:
        """The seed's outcomes: a run stopped early leaves its remaining episodes unplayed, counted as safety stops."""
        behind = self.outcomes[-1:] == [CELL_BEHIND]  # the stop came in an episode the cell's lag voided
        self.outcomes += [CELL_BEHIND if behind else "safety_stop"] * (episodes - len(self.outcomes))
        if summary.recoveries:
            log.warning("seed %d: %d safety stop(s) recovered from", seed, summary.recoveries)
        if summary.stopped:
            log.warning("seed %d stopped: %s", seed, summary.stopped)
        return self.outcomes


def _unplayed(
    run_log: RunLog, seed: int, episodes: int, reason: str, on_episode: Callable[[str], None] | None
) -> list[str]:
    """A seed whose run could not start: its episodes count as safety stops (as a run stopped early does), each
    handed to `on_episode` (the progress bar) first, and the run log says why."""
    run_log.write("run_stopped", reason=reason)
    log.warning("seed %d not run: %s", seed, reason)
    outcomes = [Outcome.SAFETY_STOP.value] * episodes
    if on_episode:
        for outcome in outcomes:
            on_episode(outcome)
    return outcomes


def replace_gap(cfg: CellConfig, **changes) -> CellConfig:
    """`cfg` with some reality-gap parameters changed (for sweeps)."""
    return cfg.with_twin(replace(cfg.twin, reality_gap=replace(cfg.twin.reality_gap, **changes)))
