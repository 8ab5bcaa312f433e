"""A person teaches where the part is gripped ("not there — here"): the fusion, the demonstration and the task follow.

A mark is read under the centre prior (the person meant the middle of the part); a taught answer (`here`) is the
person's intent, which outranks the measurements made before it and which the cell's seals refine only near it."""

import numpy as np
import pytest

from mrguide.policies import waypoint_search as ws
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.guidance import NominalReference
from mrguide.policies.guided_expert import GuidedExpert
from mrguide.policies.mark_fusion import REFINE_RADIUS, MarkFusion
from mrguide.robot import load_robot
from mrguide.task import PICK_PHASE, Phase, TaskConfig, oracle_target, phase_from_progress, phase_target
from tests.policies.mark_scene import GOAL, OBJ, scene_obs
from tests.run_configs import TEST_EVAL_EPISODES

#: m, a grasp 3.7 cm off the centre of the keep-out block's top (clear of its label), in the part's frame
TAUGHT = np.array([0.037, 0.0, 0.02])
KEEPOUT_OBJ = np.array([0.5, -0.1, 0.02])


class _Person:
    """Answers every pick request with a point `offset` from the part as shown, taught (`here`) or not; every place
    request at the oracle's release point."""

    def __init__(self, offset, here: bool, task: TaskConfig):
        self.offset, self.here, self.task = np.asarray(offset, dtype=float), here, task

    def annotate(self, obs, previous=None):
        if phase_from_progress(obs[4]) == PICK_PHASE:
            return Annotation(np.asarray(obs[5:8], dtype=float) + self.offset, 1.0, "live", here=self.here)
        target, grip = oracle_target(obs, self.task)
        return Annotation(target, grip, "live")


def _expert(source, tmp_path, task):
    cache = AnnotationCache(0.005, tmp_path / "ann.jsonl")
    return GuidedExpert(
        source, NominalReference(task), cache, 0.05, task, load_robot().workspace.to_normalized, 15, marks="pick_place"
    )


def _target_m(action):
    return load_robot().workspace.to_cartesian(action[:3])


def test_the_phase_targets_follow_the_grasp_and_the_centre_prior_is_the_top_centre():
    block = TaskConfig()
    assert np.allclose(phase_target(Phase.GRASP, OBJ, GOAL, block), OBJ + [0, 0, 0.025])  # the centre prior
    keep = TaskConfig(part="keepout_block", grasp=tuple(TAUGHT))
    obj, goal = KEEPOUT_OBJ, np.array([0.5, 0.2, 0.02])
    assert np.allclose(phase_target(Phase.APPROACH, obj, goal, keep), obj + TAUGHT + [0, 0, keep.approach_height])
    assert np.allclose(phase_target(Phase.GRASP, obj, goal, keep), obj + TAUGHT)
    assert np.allclose(phase_target(Phase.LIFT, obj, goal, keep)[:2], (obj + TAUGHT)[:2])
    assert np.allclose(phase_target(Phase.TRANSPORT, obj, goal, keep)[:2], (goal + TAUGHT)[:2])
    assert np.allclose(phase_target(Phase.RELEASE, obj, goal, keep), goal + TAUGHT)  # the part's centre at the goal


def test_a_grasp_outside_the_part_is_refused():
    from mrguide.config import ConfigError

    with pytest.raises(ConfigError, match="outside the keepout_block's bounding box"):
        TaskConfig(part="keepout_block", grasp=(0.08, 0.0, 0.02))


def test_measurements_refine_a_taught_point_only_near_it_and_a_correction_outranks_them():
    fusion = MarkFusion()
    at = np.zeros(3)
    fusion.add(PICK_PHASE, at, [0.01, 0.0, 0.02])
    fusion.add_measurement(PICK_PHASE, at, [0.0, 0.0, 0.02])  # the centre prior's seal
    assert np.allclose(fusion.estimate(PICK_PHASE), [0.0, 0.0, 0.02]) and fusion.intent(PICK_PHASE) is None
    fusion.teach(PICK_PHASE, at, TAUGHT)  # taught 3.7 cm away: the seal at the centre is not what the person means
    assert np.allclose(fusion.estimate(PICK_PHASE), TAUGHT) and fusion.settled(PICK_PHASE, 0.0)
    near = TAUGHT + [0.5 * REFINE_RADIUS, 0.0, -0.001]
    fusion.add_measurement(PICK_PHASE, at, near)  # a seal beside the taught point refines it
    assert np.allclose(fusion.estimate(PICK_PHASE), near)
    fusion.teach(PICK_PHASE, at, TAUGHT + [0.004, 0.0, 0.0])  # another sample of the intent: the seal still counts
    assert np.allclose(fusion.estimate(PICK_PHASE), near) and len(fusion.taught[PICK_PHASE]) == 2
    corrected = TAUGHT + [0.0, 0.012, 0.0]
    fusion.teach(PICK_PHASE, at, corrected, correction=True)  # "not there — here"
    assert fusion.measured[PICK_PHASE] == [] and np.allclose(fusion.intent(PICK_PHASE), corrected)
    assert np.allclose(fusion.estimate(PICK_PHASE), corrected)


@pytest.mark.parametrize("here", [True, False])
def test_a_taught_grasp_is_searched_about(tmp_path, here):
    """The same answer 3.7 cm beside the centre of the keep-out block's top, taught or marked, that does not seal
    where it points: taught, the grasp search is laid about it; marked, about the part's centre (the centre prior)."""
    task = TaskConfig(part="keepout_block")
    expert = _expert(_Person(TAUGHT, here, task), tmp_path, task)
    expert.begin_demonstration()
    grasp = ws.PATTERNS[Phase.GRASP]
    targets = [_target_m(expert.action(scene_obs(1, obj=KEEPOUT_OBJ)).executed) for _ in range(grasp.first_dwell + 1)]
    assert np.allclose(targets[0][:2], (KEEPOUT_OBJ + TAUGHT)[:2])  # the mark, taught or not
    laid_about = (KEEPOUT_OBJ + TAUGHT)[:2] if here else KEEPOUT_OBJ[:2]
    assert np.linalg.norm(targets[-1][:2] - laid_about) < 1.5 * grasp.pitch  # the grid's first probe


@pytest.mark.parametrize("here", [True, False])
def test_a_taught_grasp_is_measured_where_taught_a_marked_one_over_the_centre(tmp_path, here):
    """The answer seals where it points and the lift shows the part hanging 3.7 cm off the cup's axis: taught, the
    seal is measured where it sealed and the task's grasp follows it; marked, the centre prior moves the measurement
    over the part's centre and the task keeps the centre prior."""
    task = TaskConfig(part="keepout_block")
    expert = _expert(_Person(TAUGHT, here, task), tmp_path, task)
    expert.begin_demonstration()
    for _ in range(ws.PATTERNS[Phase.GRASP].first_dwell):  # sealed on the mark itself
        sealed = _target_m(expert.action(scene_obs(1, obj=KEEPOUT_OBJ)).executed)
    for dz in (0.0, 0.03, 0.06):  # the lift: the part hangs where the cup holds it
        expert.action(scene_obs(2, obj=KEEPOUT_OBJ + [0, 0, dz], tcp=sealed + [0, 0, dz], g=1))
    expert.action(scene_obs(3, obj=KEEPOUT_OBJ + [0, 0, 0.1], tcp=sealed + [0, 0, 0.1], g=1))
    measured = expert.fusion.measured[PICK_PHASE][0]
    assert np.allclose(measured[:2], TAUGHT[:2] if here else [0.0, 0.0], atol=1e-4)
    retasked = expert.retasked()
    if here:
        assert retasked is not None and np.allclose(retasked.grasp, TAUGHT, atol=1e-4)  # z: the face's height
        assert expert.retasked() is None  # unchanged since
    else:
        assert retasked is None and expert.task.grasp is None


def test_a_taught_answer_survives_the_annotation_file(tmp_path):
    task = TaskConfig(part="keepout_block")
    expert = _expert(_Person(TAUGHT, True, task), tmp_path, task)
    expert.begin_demonstration()
    expert.action(scene_obs(1, obj=KEEPOUT_OBJ))
    resumed = _expert(_Person(TAUGHT, True, task), tmp_path, task)
    resumed.cache.load(tmp_path / "ann.jsonl")
    resumed.reload()
    assert np.allclose(resumed.fusion.intent(PICK_PHASE), TAUGHT) and resumed.fusion.offsets[PICK_PHASE] == []


def test_the_env_judges_by_the_taught_grasp():
    from mrguide.twin.env import PickPlaceEnv

    env = PickPlaceEnv()
    try:
        env.reset(seed=3)
        with pytest.raises(ValueError, match="only in its grasp"):
            env.teach(TaskConfig(horizon=10))
        taught = TaskConfig(grasp=(0.02, 0.0, 0.025))
        env.teach(taught)
        assert env.task_cfg.grasp == taught.grasp and env.decision.task is env.task_cfg
        _, _, _, _, info = env.step(np.zeros(4, np.float32))
        tcp = env.decision.tcp(env.scene.joint_positions())
        target = phase_target(Phase.APPROACH, env.scene.object_position(), env.scene.goal, taught)
        assert info["distance"] == pytest.approx(float(np.linalg.norm(tcp - target)), abs=1e-9)
    finally:
        env.close()


class _Tripwire:
    """A part's hidden record that fails whoever reads it."""

    def __getattr__(self, name):
        raise AssertionError(f"the learner's path read the part's hidden record ({name})")


def test_a_run_on_the_keepout_block_learns_the_taught_grasp_without_reading_the_hidden_record(tmp_path, monkeypatch):
    """A short guided run on the keep-out block whose person teaches the grasp beside the label: the part's hidden
    record is a tripwire for the whole run (the trainer, the expert path, the env, the export), the task's grasp
    follows what was taught, and the exported policy carries it to the runtime's task."""
    import dataclasses
    from pathlib import Path

    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.parts import PARTS
    from mrguide.policies.commands import _finish
    from mrguide.policies.train import Trainer
    from mrguide.policies.train_config import RunConfig

    config = Path(__file__).resolve().parents[2] / "configs" / "parts" / "keepout_block.toml"
    run = RunConfig.load(config)
    train = dataclasses.replace(
        run.train, total_steps=800, eval_every=10_000, checkpoint_every=10_000, eval_episodes=TEST_EVAL_EPISODES
    )
    run = run.replace(train=train)
    monkeypatch.setitem(PARTS, "keepout_block", dataclasses.replace(PARTS["keepout_block"], judge_only=_Tripwire()))
    tr = Trainer(run, tmp_path, source_factory=lambda env: _Person(TAUGHT + [0, 0, -0.003], True, env.task_cfg))
    try:
        tr.run()
        _finish(tr, run.train, run.guidance, tmp_path)
    finally:
        tr.close()
    assert tr.counters.interventions > 3 and tr.counters.measured > 0
    assert np.allclose(tr.env.task_cfg.grasp, TAUGHT, atol=0.006)  # taught, then refined by seals near it
    assert tr.expert.fusion.intent(PICK_PHASE) is not None
    policy = ExportedPolicy.load(tmp_path / "policy.npz", tr.env.robot_spec, run.env.task)
    assert policy.with_grasp(run.env.task).grasp == tr.env.task_cfg.grasp


def test_a_person_who_steps_in_is_asked_again_and_corrects_the_grasp(tmp_path):
    """Taught once, the pick is settled and not asked again; a demonstration a person stepped in for asks it anyway,
    and their taught answer corrects the grasp ("not there — here"): it replaces what was taught."""
    task = TaskConfig(part="keepout_block")
    person = _Person(TAUGHT + [0.0, 0.008, 0.0], True, task)
    expert = _expert(person, tmp_path, task)
    expert.begin_demonstration()
    expert.action(scene_obs(1, obj=KEEPOUT_OBJ))
    expert.begin_demonstration()
    expert.action(scene_obs(1, obj=KEEPOUT_OBJ + [0.01, 0.0, 0.0]))
    assert expert.counts.asked == 1  # settled: not asked again
    person.offset = TAUGHT - [0.0, 0.0, 0.003]
    expert.begin_demonstration(person=True)
    expert.action(scene_obs(1, obj=KEEPOUT_OBJ + [0.02, 0.0, 0.0]))
    assert expert.counts.asked == 2
    assert np.allclose(expert.fusion.intent(PICK_PHASE), TAUGHT - [0.0, 0.0, 0.003])  # the correction replaced it
    assert expert.cache.get(1).info["correction"] is True  # and says so in the annotation file (a resume reads it)
    assert expert.counts.corrections == 1


def test_a_correction_in_a_run_forgets_what_was_learned_from_before_it(tmp_path):
    """A person teaches a grasp on the label, then steps in and corrects it: the trainer forgets every transition of
    the wrong grasp (its demonstrations aimed elsewhere, its rewards were for it) the moment the correction is
    recorded, and counts it."""
    import dataclasses
    from pathlib import Path

    from mrguide.policies.train import Trainer
    from mrguide.policies.train_config import RunConfig

    class StepsIn(_Person):
        """Teaches `offset`; at the 30th agent step after its first answer steps in, and teaches TAUGHT from then."""

        polls = 0

        def intervention_requested(self) -> bool:
            self.polls += 1
            if self.polls == 30:
                self.offset = TAUGHT - [0.0, 0.0, 0.003]
                return True
            return False

    config = Path(__file__).resolve().parents[2] / "configs" / "parts" / "keepout_block.toml"
    run = RunConfig.load(config)
    train = dataclasses.replace(
        run.train, total_steps=600, eval_every=10_000, checkpoint_every=10_000, eval_episodes=TEST_EVAL_EPISODES
    )
    run = run.replace(train=train)
    tr = Trainer(run, tmp_path, source_factory=lambda env: StepsIn([0.0, 0.0, 0.017], True, env.task_cfg))
    pool: list[tuple[int, int]] = []  # the pools' size before and after each forgetting
    forget = tr.learning.forget

    def spy() -> None:
        before = len(tr.replay)
        forget()
        pool.append((before, len(tr.replay)))

    tr.learning.forget = spy
    try:
        tr.run(stop_at=600)
    finally:
        tr.close()
    assert tr.counters.corrections == 1 and tr.counters.person_interventions == 1
    assert len(pool) == 1 and pool[0][0] > 0 and pool[0][1] == 0
    assert np.allclose(tr.env.task_cfg.grasp[:2], TAUGHT[:2], atol=0.006)
