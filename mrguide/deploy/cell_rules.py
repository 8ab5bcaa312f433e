"""The cell's rules on every action the policy gives, on the robot and in every dry run, and the registration they
feed: the descent rule (descent_rule.py), the lift rules (lift_rule.py), the seal search (seal_search.py), and the
pose source's registration bias estimated from each press (bias_estimate.py). The twin trains without them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mrguide.deploy.bias_estimate import Registration, SealWindow
from mrguide.deploy.descent_rule import DescentRule
from mrguide.deploy.lift_rule import LiftRule, hold_in_transit
from mrguide.deploy.object_tracking import ObjectTracker
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.safety import Event, Supervisor
from mrguide.deploy.seal_search import SealSearch
from mrguide.drivers.cobot_state import VacuumState
from mrguide.grasp_margin import seal_window
from mrguide.parts import part_named
from mrguide.robot import Workspace
from mrguide.task import OBS_GOAL, OBS_OBJECT, Phase, TaskConfig


class CellRules:
    """One per runtime; `reset()` per episode, `apply()` per decision."""

    def __init__(
        self,
        workspace: Workspace,
        decision_period: float,
        cfg: RuntimeConfig,
        task: TaskConfig,
        source: str,
        supervisor: Supervisor,
    ):
        self.supervisor = supervisor
        self.lift = LiftRule(workspace, decision_period, cfg.break_away_distance, cfg.break_away_speed)
        self.seal = SealSearch(workspace, cfg.reseat_wait, cfg.seal_search)
        self.descent = DescentRule(workspace, task.place_tolerance)
        self.grasp = grasp = task.grasp_offset  # where the lip rests whole on the part's face, per axis, about it
        window = SealWindow((float(grasp[0]), float(grasp[1])), seal_window(part_named(task.part), grasp[:2]))
        where = Path(cfg.bias_estimate_file) if cfg.bias_estimate_file else None
        self.registration = Registration(window, source, where)

    def reset(self, objects: ObjectTracker) -> None:
        """A new episode: `objects` sees through the registration as it stands."""
        objects.correction = self.registration.correction
        self.registration.reset()
        self.lift.reset()
        self.seal.reset()

    def apply(
        self, action: np.ndarray, tcp: np.ndarray, obs: np.ndarray, vac: VacuumState, phase: int, objects: ObjectTracker
    ) -> tuple[np.ndarray, dict]:
        """The action after the rules (descent and carry, lift, seal search), and what they did for the run log; a press
        updates the registration and `objects`' correction."""
        notes: dict = {}
        done = vac.part_gripped or self.seal.reseats > 0
        executed, descent = self.descent.apply(action, tcp, obs[OBS_OBJECT] + self.grasp, phase, done)
        if descent is not None:
            self.supervisor.report(Event(descent), f"kept the cup off the part in phase {phase}")
            notes["descent_rule"] = descent
        executed, carry = self.descent.carry(executed, obs[OBS_GOAL] + self.grasp, phase, vac.part_gripped)
        if carry is not None:
            self.supervisor.report(Event(carry), f"kept the part above the table in phase {phase}")
            notes["descent_rule"] = carry
        executed, rule = self.lift.apply(executed, tcp, phase, vac)
        if rule is not None:
            self.supervisor.report(Event(rule), f"height target lowered in phase {phase}")
            notes["lift_rule"] = rule
        executed, held = hold_in_transit(executed, phase, vac)
        if held is not None:
            self.supervisor.report(Event(held), f"release refused in phase {phase}: the part is held")
            notes["hold_rule"] = held
        seen, looks = objects.seen, objects.filter.looks
        aim = self.registration.aim(seen, looks) if seen is not None and self.seal.wants_aim else None
        executed, reseat = self.seal.apply(executed, tcp, aim, phase, vac)
        if reseat is not None:
            self.supervisor.report(Event.RESEAT, f"no seal at {vac.level_kpa:.0f} kPa: re-seat {self.seal.reseats}")
            notes["reseat"] = self.seal.reseats
        grasping = phase in (Phase.GRASP, Phase.LIFT)
        if self.registration.after_decision(tcp, seen, looks, grasping, vac.part_gripped, reseat is not None):
            objects.correction = self.registration.correction  # the cell's registration, improved by this press
            notes["bias_estimate"] = objects.correction[:2]
        return executed, notes

    @property
    def blow_off(self) -> bool:
        """The seal search just released the cup: its vacuum-off command goes with a blow-off pulse."""
        return self.seal.blow_off
