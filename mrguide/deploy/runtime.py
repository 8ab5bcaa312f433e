"""The deploy runtime: an exported policy driving the cobot through the CAN driver layer.

Each decision: joint state → FK → TCP; vacuum signal → g; object pose from the pose source (or, while
the part hangs under the cup, from the TCP); then the `DecisionStep` the twin trains with (decision.py):
task model → phase, φ, reward, outcome; observation; policy (numpy) → action; clamp; IK warm-started at
the measured joints; a Ruckig stream handed to the driver one control period at a time; vacuum command
from g'. The safety supervisor (`safety.py`) watches every step and decides how to react. No PyBullet, no
torch.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from typing import NoReturn

import numpy as np

from mrguide.config import ConfigError
from mrguide.deploy.cell_learning import LearningActor
from mrguide.deploy.cell_rules import CellRules
from mrguide.deploy.episode import HOME_SETTLE_S, EpisodeReport, RunStopped
from mrguide.deploy.following import FollowingMonitor
from mrguide.deploy.interventions import sense_start
from mrguide.deploy.object_tracking import ObjectStartUnknown, ObjectTracker
from mrguide.deploy.runlog import RunLog
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.safety import Event, Reaction, SafetyConfig, Supervisor, Watchdog
from mrguide.drivers.cobot_state import JointState, VacuumState
from mrguide.drivers.errors import DriverError
from mrguide.drivers.interface import CobotInterface
from mrguide.motion.decision import NON_FINITE, ActionError, DecisionStep
from mrguide.motion.kinematics import IKError
from mrguide.motion.trajectory import TrajectoryError
from mrguide.pose_source import ObjectPoseSource
from mrguide.robot import RobotSpec
from mrguide.task import Outcome, TaskConfig

log = logging.getLogger(__name__)

#: m: a cup with the vacuum on this far above where it grips a part on the table may carry one (`_set_down`).
SET_DOWN_RAISED = 0.01
#: m above the table's grip height that a part carried back travels at (at least) and the cup rises to after it.
SET_DOWN_CLEAR = 0.05
#: The share of the arm's joint limits (velocity, acceleration, jerk) a part is carried back at: a part the episode
#: failed with may be held badly (carried back at full speed, one in the MuJoCo cell tore off half-way).
SET_DOWN_SPEED = 0.25


class Runtime:
    """Runs episodes of an exported policy on a connected, enabled cobot (any `CobotInterface`).

    `policy` maps an observation to an action: an `ExportedPolicy`, or any such callable (a scripted expert).
    ConfigError unless `decision_period` is a whole number of the cobot's control periods. With `learning` set,
    it is the actor of on-cell learning (`cell_learning`): its decisions become transitions."""

    learning: LearningActor | None = None

    def __init__(
        self,
        cobot: CobotInterface,
        policy: Callable[[np.ndarray], np.ndarray],
        pose: ObjectPoseSource,
        spec: RobotSpec,
        task: TaskConfig,
        run_log: RunLog,
        decision_period: float,
        config: RuntimeConfig | None = None,
        safety: SafetyConfig | None = None,
    ):
        self.cobot, self.policy, self.pose, self.spec, self.task, self.log = cobot, policy, pose, spec, task, run_log
        self.cfg = config or RuntimeConfig()
        period = cobot.period
        ratio = decision_period / period
        if abs(ratio - round(ratio)) > 1e-6 or ratio < 1 - 1e-9:  # the tolerances of check_decision_period
            raise ConfigError(
                f"decision period {decision_period} s is not a whole number of control periods ({period} s)"
            )
        self.cycles = round(ratio)
        self.decision = DecisionStep(spec, task, period)
        self.kin, self.streamer = self.decision.kin, self.decision.streamer
        self.supervisor = Supervisor(spec, safety or SafetyConfig(), self._on_event)
        # setpoints of the last 100 ms (at 4 ms) of servo lag, or as far back as the driver lets feedback lag
        # before it calls it lost (a real bus: 5 cycles; simulated devices on a shared PC: 1 s)
        self.following = FollowingMonitor(
            depth=max(25, 2 * cobot.setpoint_queue_depth, cobot.feedback_tolerance_cycles)
        )
        self.watchdog = Watchdog(self.supervisor.cfg.stall_timeout, self._on_stall)
        self._episode_events: Counter[str] = Counter()
        self._t = 0
        misses = (self.cfg.max_pose_misses, self.cfg.max_pose_misses_before_grasp)
        self.objects = ObjectTracker(pose, self.supervisor, task, self.cfg.track_carried_object, *misses)
        self.rules = CellRules(spec.workspace, decision_period, self.cfg, task, type(pose).__name__, self.supervisor)

    # -- lifecycle ----------------------------------------------------------------------------------
    def __enter__(self) -> Runtime:
        self.cobot.add_cycle_observer(self.following)
        self.watchdog.start()
        return self

    def __exit__(self, *exc) -> None:
        self.watchdog.close()
        self.cobot.remove_cycle_observer(self.following)

    def _on_event(self, event: Event, reaction: Reaction, detail: str) -> None:
        self._episode_events[event.value] += 1
        self.log.write("safety", t=self._t, event=event.value, reaction=reaction.value, detail=detail)

    def _on_stall(self, age: float) -> None:
        """Watchdog thread: the decision loop stopped feeding setpoints; stop the drives."""
        self.cobot.stop()
        self.supervisor.report(Event.STALL, f"no setpoint for {age * 1000:.0f} ms")

    # -- streaming ----------------------------------------------------------------------------------
    def _stream_cycle(self) -> tuple[np.ndarray, np.ndarray, bool]:
        """One control period of the current trajectory, checked and handed to the driver."""
        try:
            sp = self.streamer.step()
        except TrajectoryError as exc:
            self._quick_stop(Event.TRAJECTORY, str(exc))
        problem = self.supervisor.check_setpoint(sp.q, sp.dq, sp.ddq)
        if problem:
            self._quick_stop(Event.JOINT_LIMIT, problem)
        problem = self.supervisor.check_following(self.following.error, self.following.joint)
        if problem:
            self._quick_stop(Event.FOLLOWING_ERROR, problem)
        if not self.watchdog.alive:
            self._quick_stop(Event.STALL, "the watchdog thread is not running: no stall supervision")
        try:
            self.cobot.stream(sp.q)
        except DriverError as exc:
            if self.watchdog.fired:
                raise RunStopped("stopped by the watchdog: the decision loop stalled") from exc
            self._quick_stop(Event.DRIVE_FAULT, str(exc))
        self.watchdog.feed()
        return sp.q, sp.dq, sp.finished

    def _quick_stop(self, event: Event, detail: str) -> NoReturn:
        self.cobot.stop()
        self.supervisor.report(event, detail)
        raise RunStopped(f"{event.value}: {detail}")

    def _settle(self, max_cycles: int = 2000) -> None:
        """Stream until the current trajectory (or brake ramp) has come to rest."""
        for _ in range(max_cycles):
            _, dq, finished = self._stream_cycle()
            if finished or np.max(np.abs(dq)) < 1e-6:
                return

    def home(self) -> None:
        """Move to the home configuration (jerk-limited) with the vacuum off."""
        self._move(self.spec.q_home, arrive=True)
        if self._home_error() > self.cfg.home_tolerance:
            q = self.cobot.joint_state().positions
            raise RunStopped(
                f"arm did not reach home within {HOME_SETTLE_S:g} s of its last setpoint: "
                f"{np.round(q - self.spec.q_home, 4).tolist()} rad off"
            )

    def depart(self, height: float) -> bool:
        """Rise `height` m above where the TCP stands (jerk-limited, the vacuum off), clear of a part just placed;
        False, the arm not moved, when no joint configuration reaches that point."""
        q = self.cobot.joint_state().positions
        try:
            target = self.decision.kin.ik(self.decision.tcp(q) + np.array([0.0, 0.0, height]), q)
        except IKError as exc:
            log.info("no depart move: %s", exc)
            return False
        self._move(target, arrive=False)
        return True

    def _set_down(self) -> None:
        """After an episode that did not place the part: a cup that may hold it (the vacuum on, raised above where it
        grips a part on the table) carries it back over where the episode first saw it, lowers it onto the table and
        lets go: a part is never dropped where the horizon ran out. Without a joint configuration for either point
        the vacuum goes off where the cup stands (the run log says why)."""
        start, q = self.objects.start, self.cobot.joint_state().positions
        tcp = self.decision.tcp(q)
        down = None if start is None else start + self.objects.hang  # the TCP gripping the part at the start
        if down is None or not self.cobot.vacuum_state().vacuum_on or tcp[2] < down[2] + SET_DOWN_RAISED:
            return
        above = np.array([down[0], down[1], max(float(tcp[2]), down[2] + SET_DOWN_CLEAR)])
        try:
            with self.streamer.slowed(SET_DOWN_SPEED):
                for point in (above, down):
                    q = self.decision.kin.ik(self.spec.workspace.clamp(point)[0], q)
                    self._move(q, arrive=False, vacuum=True)
        except IKError as exc:
            self.log.write("set_down", t=self._t, tcp=tcp, to=down, done=False, reason=str(exc))
            return
        self.log.write("set_down", t=self._t, tcp=tcp, to=down, done=True)
        self._let_go()
        self.depart(SET_DOWN_CLEAR)

    def _let_go(self) -> None:
        """The vacuum off, with a blow-off pulse for one decision period while the arm stands if it was on: a cup
        whose valve only closes stays evacuated for a second, and the move that follows carried the part off
        (the MuJoCo cell: a part that had not sealed hung under the cup at home, 0.2 m from the pick region)."""
        if self.cobot.vacuum_state().vacuum_on:
            self.cobot.set_vacuum(False, blow_off=True)
            for _ in range(self.cycles):
                self._stream_cycle()
        self.cobot.set_vacuum(False)

    def _move(self, q: np.ndarray, arrive: bool, vacuum: bool = False) -> None:
        """Stream a jerk-limited move to the joint configuration `q` until it is at rest, the vacuum off (or kept on,
        carrying a part); with `arrive`, then hold `q` until the joints are within `home_tolerance` of it (servo
        lag), HOME_SETTLE_S at most."""
        self.cobot.set_vacuum(vacuum)
        self.streamer.reset(self.cobot.setpoint)
        self.streamer.set_target(q)
        self.watchdog.arm(True)
        try:
            self._settle(max_cycles=int(30 / self.cobot.period))
            if arrive:  # the setpoints are at q; the joints follow with the servos' lag: hold q until they arrive
                for _ in range(int(HOME_SETTLE_S / self.cobot.period)):
                    if np.max(np.abs(self.cobot.joint_state().positions - q)) <= self.cfg.home_tolerance:
                        break
                    self._stream_cycle()
        finally:
            self.watchdog.arm(False)

    def _home_error(self) -> float:
        return float(np.max(np.abs(self.cobot.joint_state().positions - self.spec.q_home)))

    def recover(self) -> None:
        """Acknowledge a safety stop: fault reset and re-enable where the arm stands (`home()` comes next).

        For evaluations in the simulated cell, where the operator's acknowledgement is implied. Raises
        DriverError if the cause persists (a silent node, a drive that stays in FAULT)."""
        self.cobot.reset_faults()
        self.cobot.enable()
        self.log.write("recovered", t=self._t)

    # -- one episode --------------------------------------------------------------------------------
    def run_episode(self, goal: np.ndarray, index: int) -> EpisodeReport:
        """One episode toward `goal` from the home pose; returns its report (RunStopped ends the run)."""
        goal = np.asarray(goal, dtype=float)
        self._episode_events = Counter()
        report = EpisodeReport(index, Outcome.ABORTED, 0, {})
        t0 = time.perf_counter()
        self.log.write("episode_start", episode=index, goal=goal)
        self.decision.reset(self.cobot.setpoint)
        self.objects.reset()
        self.rules.reset(self.objects)
        if self.learning is not None:  # between episodes: new weights, a person stepping in (interventions.py)
            self.learning.episode_start(
                index, self.log.write, lambda: sense_start(self.cobot, self.decision, self.objects, goal)
            )
        self.watchdog.arm(True)
        try:
            outcome = self._decisions(goal, index, report)
            report.outcome = outcome
            if self.learning is not None:
                self.learning.episode_end(index, outcome, self.log.write)
            self.streamer.brake()
            self._settle()
            if outcome is not Outcome.SUCCESS:
                self._set_down()
                self._let_go()
        except KeyboardInterrupt:
            self.cobot.stop()
            self.supervisor.report(Event.INTERRUPT, "Ctrl-C")
            report.outcome = Outcome.SAFETY_STOP
            raise
        except RunStopped as exc:
            report.outcome = Outcome.SAFETY_STOP
            exc.report = report
            raise
        except DriverError:  # a fault surfaced outside the streaming (reading the state, the vacuum command)
            report.outcome = Outcome.SAFETY_STOP
            raise
        finally:
            self.watchdog.arm(False)
            report.events = dict(self._episode_events)
            report.wall_s = time.perf_counter() - t0
            self.log.write(
                "episode_end",
                episode=index,
                outcome=report.outcome.value,
                decisions=report.decisions,
                events=report.events,
                wall_s=report.wall_s,
            )
            self.log.sync()
        return report

    def _decisions(self, goal: np.ndarray, index: int, report: EpisodeReport) -> Outcome:
        """The episode's decisions until an outcome: the task's, or the supervisor's (aborted, pose lost)."""
        for t in range(self.task.horizon + 1):
            self._t = t
            t_read = time.perf_counter()
            js, vac = self.cobot.joint_state(), self.cobot.vacuum_state()
            tcp = self.decision.tcp(js.positions)
            g = 1 if vac.vacuum_on else -1
            try:
                obj = self.objects.position(tcp, vac, self.decision.phase)
            except ObjectStartUnknown as exc:
                raise RunStopped(str(exc)) from exc
            if obj is None:
                self.log.write(
                    "decision", t=t, tcp=tcp, g=g, phase=self.decision.phase, outcome=Outcome.POSE_LOST.value
                )
                return Outcome.POSE_LOST
            reward = None
            if t > 0:
                res = self.decision.judge(tcp, g, vac.part_gripped, obj, goal)
                reward = res.reward
                if res.outcome is Outcome.DROPPED:
                    self.supervisor.report(
                        Event.VACUUM_LOST, f"part lost in phase {res.phase} (vacuum {vac.level_kpa:.0f} kPa)"
                    )
                if res.outcome is not None:
                    if self.learning is not None:
                        terminal = self.decision.observe(tcp, g, obj, goal, res.outcome is Outcome.SUCCESS)
                        self.learning.tap.judged(terminal, reward, res.outcome)
                    self.log.write(
                        "decision", t=t, tcp=tcp, g=g, phase=res.phase, reward=reward, outcome=res.outcome.value
                    )
                    return res.outcome
            obs = self.decision.observe(tcp, g, obj, goal)
            if self.learning is not None:
                self.learning.tap.judged(obs, reward, None)
            if (ended := self._decide(t, t_read, js, vac, tcp, obs, index, reward, report)) is not None:
                return ended
        raise AssertionError("the task model ends every episode at its horizon")  # pragma: no cover

    def _decide(
        self,
        t: int,
        t_read: float,
        js: JointState,
        vac: VacuumState,
        tcp: np.ndarray,  # the forward kinematics of `js` that `obs` was made from
        obs: np.ndarray,
        index: int,
        reward: float | None,
        report: EpisodeReport,
    ) -> Outcome | None:
        """Policy → decision step → one decision period streamed; an outcome if the supervisor ends the episode."""
        t_inf = time.perf_counter()
        action = self.policy(obs)
        inference_ms = (time.perf_counter() - t_inf) * 1e3
        executed, notes = self.rules.apply(action, tcp, obs, vac, self.decision.phase, self.objects)
        if self.learning is not None:
            self.learning.tap.acted(obs, executed)
        record = {
            "episode": index,
            "t": t,
            "obs": obs,
            "action": action,
            "phase": self.decision.phase,
            "reward": reward,
            "q": js.positions,
            "vacuum_kpa": vac.level_kpa,
            "part": vac.part_gripped,
            "object_from": self.objects.source,
            **notes,
        }
        details = getattr(self.pose, "pose_details", None)  # optional (PoseDetails): the estimate's age, the truth
        if details is not None:
            record["pose"] = details()
        try:
            cmd = self.decision.act(executed, js.positions)
        except ActionError as exc:
            event = Event.NON_FINITE_ACTION if exc.kind == NON_FINITE else Event.INVALID_ACTION
            self.supervisor.report(event, f"policy output: {exc}")
            self.log.write("decision", **record)
            return Outcome.ABORTED
        if cmd.clamped:
            self.supervisor.report(
                Event.WORKSPACE,
                f"action {np.asarray(action)[:3].tolist()} outside [-1, 1]: "
                f"target clamped to {np.round(cmd.target, 4).tolist()}",
            )
        record["target"] = cmd.target
        if cmd.q_target is None:
            if self.supervisor.ik_result(False, cmd.ik_error or "") is Reaction.ABORT:
                self.log.write("decision", **record)
                return Outcome.ABORTED
        else:
            self.supervisor.ik_result(True)
            record["q_target"] = cmd.q_target
        # every release with a blow-off pulse (one decision): a cup whose valve only closes stays evacuated for a second
        self.cobot.set_vacuum(cmd.vacuum, blow_off=not cmd.vacuum and (vac.vacuum_on or self.rules.blow_off))
        self._stream_decision(t, t_read, inference_ms, record, report)
        return None

    def _stream_decision(self, t: int, t_read: float, inference_ms: float, record: dict, report: EpisodeReport) -> None:
        """One decision period streamed; its timing and setpoints go to `report` and the run log's `record`."""
        latency_ms = (time.perf_counter() - t_read) * 1e3
        setpoints = [self._stream_cycle()[0] for _ in range(self.cycles)]
        record["latency_ms"], record["inference_ms"] = latency_ms, inference_ms
        record["setpoints"] = np.round(np.array(setpoints), 7)
        report.latency_ms.append(latency_ms)
        report.inference_ms.append(inference_ms)
        report.decisions = t + 1
        self.log.write("decision", **record)
