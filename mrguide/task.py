"""The paper's five-phase pick-and-place task model and reward (Sec. III-A/B, Eq. 4-6). No PyBullet here.

Everything is a pure function of (tcp, gripper, object, goal, phase), so the twin and the robot's task
monitor run the same code. Positions are in the robot base frame (m); `object` is the centre of the
object, `goal` the centre the object should end at.

Interpretation notes (the paper leaves these open):
- The gripper state g is +1 when the vacuum is on, -1 when off (Eq. 2). Eq. 6 writes the success
  condition as "g_t = 0"; with g in {-1, +1} we read it as "open" (g = -1, the release state ḡ_4).
- The grasp phase completes only when the vacuum generator reports a part (the real cell's signal),
  and losing the part during lift or transport ends the episode as a drop.
- Success also requires the released object to lie within `place_tolerance` of the goal (xy).
- An object that is not held and whose centre is below the table surface was pushed off the table:
  the episode ends as a failure (`knocked_off`); the paper's task model does not cover it.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass

import numpy as np

from mrguide.config import ConfigError
from mrguide.parts import Part, part_named


class Phase(enum.IntEnum):
    """The task's five phases κ in order (Sec. III-A). An int: phases travel as their index (protocol, logs, JSON)."""

    APPROACH = 0
    GRASP = 1
    LIFT = 2
    TRANSPORT = 3
    RELEASE = 4


PHASES: tuple[str, ...] = tuple(p.name.lower() for p in Phase)  # ("approach", "grasp", "lift", "transport", "release")
#: Required gripper state per phase, ḡ = [-1, 1, 1, 1, -1] (paper, Eq. 5).
G_REQUIRED: tuple[int, ...] = (-1, 1, 1, 1, -1)
N_PHASES = len(PHASES)


class Outcome(str, enum.Enum):
    """How an episode ended: every outcome of the twin and of the robot, in one enum.

    The task model (`task_step`) gives the first six; the deploy runtime adds the ones only a robot has
    (its safety supervisor ended the episode). `terminated`/`truncated` are the Gymnasium reading. A member is a
    str, so JSON and CSV write its value; str() and f-strings give its name (`Outcome.SUCCESS`): write `.value`."""

    SUCCESS = "success"
    NO_GRASP = "no_grasp"  # horizon reached before the object was grasped
    DROPPED = "dropped"  # part lost during lift or transport (or before release)
    MISPLACED = "misplaced"  # released outside the tolerance region
    KNOCKED_OFF = "knocked_off"  # the object, not held, fell below the table surface (pushed off the table)
    TIMEOUT = "timeout"  # horizon reached after the grasp
    ABORTED = "aborted"  # deploy: the supervisor ended the episode (non-finite action, repeated IK failures)
    POSE_LOST = "pose_lost"  # deploy: no object pose for more decisions than allowed; the arm held still
    SAFETY_STOP = "safety_stop"  # deploy: quick stop (fault, limit, following error, stall, Ctrl-C)

    @property
    def terminated(self) -> bool:
        """The task itself ended (success or failure): no bootstrapping past it."""
        return self in _TERMINATED

    @property
    def truncated(self) -> bool:
        """The horizon cut the episode short."""
        return self in _TRUNCATED

    @property
    def from_task(self) -> bool:
        """Judged by the task model (as opposed to ended by the deploy runtime's supervisor)."""
        return self in _TERMINATED or self in _TRUNCATED


_TERMINATED = frozenset({Outcome.SUCCESS, Outcome.DROPPED, Outcome.MISPLACED, Outcome.KNOCKED_OFF})
_TRUNCATED = frozenset({Outcome.NO_GRASP, Outcome.TIMEOUT})


@dataclass(frozen=True)
class TaskConfig:
    """Reward weights and task geometry. The paper gives the form of Eq. 4-6 but no values."""

    alpha: float = 1.0  # α, weight of the tracking error d_t (Eq. 4; value ours)
    eta: float = 1.0  # η, premature-closure penalty (Eq. 4; value ours)
    step_penalty: float = 0.1  # λ, constant step penalty (Eq. 4; value ours)
    epsilon: float = 0.02  # ε, phase tolerance radius (m) (Eq. 5; value ours)
    r_success: float = 20.0  # R_success (Eq. 6; value ours)
    r_fail: float = 10.0  # R_fail (Eq. 6; value ours)
    #: the part picked and placed: a name in the part library (`mrguide.parts.PARTS`)
    part: str = "block"
    approach_height: float = 0.08  # pre-grasp height of the TCP above the object top (m)
    lift_height: float = 0.15  # TCP height of the lift and transport targets (m)
    place_tolerance: float = 0.03  # success radius of the placed object around the goal, xy (m)
    horizon: int = 60  # T, decisions per episode
    table_height: float = 0.0  # z of the surface the object rests on (m); a free object below it fell off
    #: m, the grasp a person taught: where the cup's axis meets the part, in the part's frame (x, y, z); None: the
    #: centre prior (`centre_prior`), what a part without teaching falls back to. A guided run sets it from the
    #: person's marks (`GuidedExpert.taught_grasp`), and the exported policy carries it to the runtime.
    grasp: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        part = part_named(self.part)
        if self.grasp is not None:
            _check_grasp(self.grasp, part)
        for name in ("alpha", "eta", "step_penalty", "epsilon", "place_tolerance"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"task.{name} must be > 0 (paper: α, η, λ, ε > 0), got {getattr(self, name)}")
        for name in ("r_success", "r_fail", "approach_height", "lift_height"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"task.{name} must be >= 0, got {getattr(self, name)}")
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or not 1 <= self.horizon <= 10_000:
            raise ConfigError(f"task.horizon must be an integer in [1, 10000], got {self.horizon!r}")

    @property
    def object_height(self) -> float:
        """m from the part's bottom to its top (its origin stands at half of it above the table)."""
        return part_named(self.part).height

    @property
    def grasp_offset(self) -> np.ndarray:
        """m from the part's origin to where the cup grips it: the taught grasp, else the centre prior."""
        return np.asarray(self.grasp, dtype=float) if self.grasp is not None else centre_prior(self.part)

    @property
    def bonuses(self) -> tuple[float, ...]:
        """Phase bonuses b_κ = κ + 1 (paper, Eq. 5)."""
        return tuple(float(k + 1) for k in range(N_PHASES))


@functools.cache
def _centre_prior(part: str) -> tuple[float, float, float]:
    p = part_named(part)
    z = p.surface_height(np.zeros(2))
    return (0.0, 0.0, 0.5 * p.height if z is None else z)


def centre_prior(part: str) -> np.ndarray:
    """The centre prior: a part nobody taught is gripped at the middle of its top, on the face there seen from above
    (m, in the part's frame; over a hole, at the part's top: no cup seals there, and the part needs teaching)."""
    return np.array(_centre_prior(part))


def _check_grasp(grasp: tuple[float, float, float], part: Part) -> None:
    """ConfigError unless `grasp` is three finite numbers within the part's bounding box."""
    g = np.asarray(grasp, dtype=float)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ConfigError(f"task.grasp must be three finite numbers (m, in the part's frame), got {grasp!r}")
    low, high = part.bounds
    if np.any(g < np.asarray(low) - 1e-9) or np.any(g > np.asarray(high) + 1e-9):
        raise ConfigError(f"task.grasp = {list(grasp)} lies outside the {part.name}'s bounding box {low} .. {high}")


def phase_target(phase: int, obj: np.ndarray, goal: np.ndarray, cfg: TaskConfig) -> np.ndarray:
    """TCP target p^tar_κ of a phase (Eq. 4): pre-grasp, the grasp, lift, above goal, place pose. They follow the
    grasp (`TaskConfig.grasp_offset`): the cup meets the part there, and holds it there until the part stands at
    the goal; with the centre prior, the object's top centre."""
    grip = cfg.grasp_offset
    at = np.asarray(obj, dtype=float) + grip
    placed = np.asarray(goal, dtype=float) + grip
    if phase == Phase.APPROACH:
        return at + np.array([0.0, 0.0, cfg.approach_height])
    if phase == Phase.GRASP:
        return at
    if phase == Phase.LIFT:
        return np.array([at[0], at[1], cfg.lift_height])
    if phase == Phase.TRANSPORT:
        return np.array([placed[0], placed[1], cfg.lift_height])
    if phase == Phase.RELEASE:
        return placed
    raise ValueError(f"phase must be in 0..{N_PHASES - 1}, got {phase}")


def progress(phase: int, success: bool = False) -> float:
    """Task-progress indicator φ ∈ [0, 1]: completed phases / 5 (1.0 once released at the goal)."""
    return 1.0 if success else phase / N_PHASES


def phase_from_progress(phi: float) -> int:
    """Inverse of `progress` for observations (φ = 1 maps to the release phase)."""
    return int(min(N_PHASES - 1, max(0, round(float(phi) * N_PHASES))))


def placed_at_goal(cfg: TaskConfig, obj: np.ndarray, goal: np.ndarray) -> bool:
    """The success rule's placement test: the object centre within `place_tolerance` of the goal (xy)."""
    return float(np.linalg.norm(np.asarray(obj)[:2] - np.asarray(goal)[:2])) < cfg.place_tolerance


@dataclass(frozen=True)
class StepResult:
    """Outcome of one task-model step: reward and its terms, the next phase, and the episode outcome."""

    reward: float
    terms: dict[str, float]
    phase: int
    outcome: Outcome | None
    distance: float

    @property
    def done(self) -> bool:
        return self.outcome is not None


def task_step(
    cfg: TaskConfig,
    phase: int,
    tcp: np.ndarray,
    g: int,
    part_present: bool,
    obj: np.ndarray,
    goal: np.ndarray,
    t: int,
) -> StepResult:
    """Evaluate Eq. 4-6 for the state reached after decision `t` (0-based) in phase κ = `phase`.

    `g` is the gripper state (+1 vacuum on, -1 off); `part_present` the vacuum generator's part signal.
    """
    if g not in (-1, 1):
        raise ValueError(f"gripper state must be -1 or +1, got {g}")
    tcp = np.asarray(tcp, dtype=float)
    d = float(np.linalg.norm(tcp - phase_target(phase, obj, goal, cfg)))
    terms = {
        "tracking": -cfg.alpha * d,
        "premature_close": -cfg.eta if (phase == Phase.APPROACH and g == 1) else 0.0,
        "phase_bonus": 0.0,
        "step": -cfg.step_penalty,
        "terminal": 0.0,
    }
    outcome: Outcome | None = None
    next_phase = phase
    reached = d < cfg.epsilon and g == G_REQUIRED[phase]
    holding_needed = phase in (Phase.LIFT, Phase.TRANSPORT) or (phase == Phase.RELEASE and g == 1)
    if holding_needed and not part_present:
        outcome = Outcome.DROPPED
    elif not part_present and np.asarray(obj)[2] < cfg.table_height:
        outcome = Outcome.KNOCKED_OFF  # no phase target can be reached any more: end it, don't track a falling object
    elif phase == Phase.RELEASE and g == -1:
        if reached and placed_at_goal(cfg, obj, goal):
            terms["phase_bonus"] = cfg.bonuses[phase]
            terms["terminal"] = cfg.r_success
            outcome = Outcome.SUCCESS
        else:
            outcome = Outcome.MISPLACED
    elif reached and (phase != Phase.GRASP or part_present):
        terms["phase_bonus"] = cfg.bonuses[phase]
        next_phase = phase + 1
    if outcome is None and t + 1 >= cfg.horizon:
        outcome = Outcome.NO_GRASP if next_phase <= Phase.GRASP else Outcome.TIMEOUT
    if outcome is not None and outcome is not Outcome.SUCCESS:
        terms["terminal"] = -cfg.r_fail
    return StepResult(float(sum(terms.values())), terms, next_phase, outcome, d)


# The observation and action layouts: the one place that knows where each number sits. Index an observation only
# by these names (tests/test_contracts.py refuses a literal index into one anywhere else).
OBS_LAYOUT = ("tcp_x", "tcp_y", "tcp_z", "g", "phi", "obj_x", "obj_y", "obj_z", "goal_x", "goal_y", "goal_z")
OBS_DIM = len(OBS_LAYOUT)  # 11
OBS_TCP = slice(0, 3)  # TCP position (m)
OBS_GRIP = 3  # gripper state g: +1 vacuum on, -1 off
OBS_PROGRESS = 4  # task progress φ ∈ [0, 1] (`progress`)
OBS_OBJECT = slice(5, 8)  # object centre (m)
OBS_GOAL = slice(8, 11)  # goal centre (m)
ACT_LAYOUT = ("target_x", "target_y", "target_z", "gripper")
ACT_DIM = len(ACT_LAYOUT)  # 4


def observation(tcp: np.ndarray, g: int, phi: float, obj: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The policy's observation [tcp xyz, g, φ, object xyz, goal xyz] (float32, shape (OBS_DIM,), OBS_LAYOUT)."""
    return np.concatenate(
        [np.asarray(tcp, float), [float(g), float(phi)], np.asarray(obj, float), np.asarray(goal, float)]
    ).astype(np.float32)


#: m: the scripted expert's grasp target lies this far into the object top so the cup seals.
GRASP_PRESS = 0.003
#: The phases whose marks stand for a whole demonstration when a person gives two marks (guidance.marks =
#: "pick_place"): the grasp point (the pick mark) and the set-down point (the place mark).
PICK_PHASE, PLACE_PHASE = Phase.GRASP, Phase.RELEASE


def oracle_target(obs: np.ndarray, cfg: TaskConfig) -> tuple[np.ndarray, float]:
    """The scripted expert's annotation: the current phase's target (m) and required gripper state ḡ_κ.

    In the grasp phase the target lies GRASP_PRESS into the object top so the cup seals.
    """
    obs = np.asarray(obs, dtype=float)
    phase = phase_from_progress(obs[OBS_PROGRESS])
    target = phase_target(phase, obs[OBS_OBJECT], obs[OBS_GOAL], cfg)
    if phase == Phase.GRASP:
        target = target - np.array([0.0, 0.0, GRASP_PRESS])
    return target, float(G_REQUIRED[phase])


def mark_phase(phase: int) -> int:
    """The phase whose mark a pick-and-place demonstration follows in `phase`: the pick up to the lift, then the place."""
    return PICK_PHASE if phase <= Phase.LIFT else PLACE_PHASE


def waypoint_from_mark(phase: int, mark: np.ndarray, cfg: TaskConfig) -> np.ndarray:
    """The TCP waypoint of `phase` (m) that follows from its pick or place mark (see `mark_phase`).

    The approach hovers `approach_height` above the part's top (GRASP_PRESS above the pick mark), the lift and
    the transport rise to `lift_height` straight above the pick and the place marks, grasp and release are the
    marks themselves. With exact marks these are the task model's phase targets (Eq. 4), except that the lift
    stays above the grasp point instead of following the part.
    """
    mark = np.asarray(mark, dtype=float)
    if phase == Phase.APPROACH:
        return mark + np.array([0.0, 0.0, GRASP_PRESS + cfg.approach_height])
    if phase in (Phase.LIFT, Phase.TRANSPORT):
        return np.array([mark[0], mark[1], cfg.lift_height])
    if phase in (Phase.GRASP, Phase.RELEASE):
        return mark.copy()
    raise ValueError(f"phase must be in 0..{N_PHASES - 1}, got {phase}")


def annotation_action(obs: np.ndarray, target: np.ndarray, grip: float, cfg: TaskConfig, to_normalized) -> np.ndarray:
    """Turn an annotated waypoint (target in m, gripper state) into a normalized action.

    A release annotation (release phase, gripper open) is executed as "carry there, then open": the
    vacuum stays on until the TCP is within ε/2 of the marked pose.
    """
    obs = np.asarray(obs, dtype=float)
    release = phase_from_progress(obs[OBS_PROGRESS]) == Phase.RELEASE
    if release and grip < 0 and np.linalg.norm(obs[OBS_TCP] - target) > 0.5 * cfg.epsilon:
        grip = 1.0
    return np.concatenate([np.clip(to_normalized(target), -1.0, 1.0), [grip]]).astype(np.float32)


def oracle_action(obs: np.ndarray, cfg: TaskConfig, to_normalized) -> np.ndarray:
    """The scripted expert as a normalized action; `to_normalized` is the workspace's map from metres."""
    target, grip = oracle_target(obs, cfg)
    return annotation_action(obs, target, grip, cfg, to_normalized)
