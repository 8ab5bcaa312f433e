"""The expert sees the part as the cell does: each look off by the pose source's error, the looks averaged while
the part stands still (until the grasp ends), so a demonstration's pick steadies as the arm approaches."""

import numpy as np

from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.guidance import NominalReference, PoseError
from mrguide.policies.guided_expert import GuidedExpert
from mrguide.policies.perceived_part import PerceivedPart
from mrguide.robot import load_robot
from mrguide.task import OBS_OBJECT, Phase, TaskConfig, oracle_target
from tests.policies.mark_scene import OBJ, scene_obs

LOOK = PoseError(sigma=0.003)  # the HMD's tracking noise per look, no registration bias


def _approach(decisions):
    """The observations of an approach over the standing part, the TCP 1 mm lower at each decision."""
    return [scene_obs(Phase.APPROACH, tcp=(0.5, 0.1, 0.3 - 0.001 * k)) for k in range(decisions)]


def test_the_looks_at_a_standing_part_are_averaged_until_the_grasp_ends_then_each_look_stands_alone():
    errors = {1: [], 25: []}
    for seed in range(20):
        part = PerceivedPart(LOOK, seed)
        part.new_part()
        for k, obs in enumerate(_approach(25), start=1):
            seen = part.at_decision(obs, Phase.APPROACH)
            if k in errors:
                errors[k].append(np.linalg.norm(seen[OBS_OBJECT] - OBJ))
    assert np.sqrt(np.mean(np.square(errors[25]))) < 0.4 * np.sqrt(np.mean(np.square(errors[1])))
    lifted = scene_obs(Phase.LIFT, tcp=(0.5, -0.1, 0.1))
    assert np.array_equal(part.at_decision(lifted, Phase.LIFT), part(lifted))  # held, the part moves: this look
    exact = PerceivedPart(PoseError(), 0)
    obs = _approach(1)[0]
    assert np.array_equal(exact.at_decision(obs, Phase.APPROACH), obs)  # no error set: the observation itself


class _Oracle:
    def annotate(self, obs, previous=None):
        target, grip = oracle_target(obs, TaskConfig())
        return Annotation(target, grip, "annotator")


def _approach_actions(tmp_path, seed, pose_error):
    task = TaskConfig()
    cache = AnnotationCache(0.005, tmp_path / f"ann-{seed}-{pose_error.sigma}.jsonl")
    to_normalized = load_robot().workspace.to_normalized
    expert = GuidedExpert(
        _Oracle(), NominalReference(task), cache, 0.05, task, to_normalized, pose_error=pose_error, seed=seed
    )
    expert.begin_demonstration()
    return [expert.action(obs).executed[:3] for obs in _approach(25)]


def test_a_demonstrations_pick_follows_the_averaged_looks_as_the_arm_approaches(tmp_path):
    first, last = [], []
    for seed in range(12):
        exact = _approach_actions(tmp_path, seed, PoseError())
        seen = _approach_actions(tmp_path, seed, LOOK)
        first.append(np.linalg.norm(seen[0] - exact[0]))
        last.append(np.linalg.norm(seen[-1] - exact[-1]))
    assert np.sqrt(np.mean(np.square(last))) < 0.4 * np.sqrt(np.mean(np.square(first)))
